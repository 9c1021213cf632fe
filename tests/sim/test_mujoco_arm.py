"""The physics-simulated robot of interprim.sim.mujoco_arm: MJCF model, joint controller, the live high five."""

from __future__ import annotations

import mujoco  # the [mujoco] extra, part of the test extra
import numpy as np
import pytest

from interprim.sim import controlled_arm, observed_arm
from interprim.sim.mujoco_arm import (
    HUMAN_JOINTS,
    ROBOT_JOINTS,
    ArmSim,
    draw_mujoco_highfive,
    fit_highfive_model,
    load_arms,
    mjcf_path,
    run_mujoco_highfive,
    track_reference,
)


def test_mjcf_is_package_data_with_the_expected_joints():
    assert mjcf_path().is_file()
    m = load_arms()
    names = [m.joint(i).name for i in range(m.njnt)]
    assert names == list(ROBOT_JOINTS) + list(HUMAN_JOINTS)
    assert m.nu == 3 and [m.actuator(i).name for i in range(m.nu)] == list(ROBOT_JOINTS)
    for arm, joints in ((controlled_arm(), ROBOT_JOINTS), (observed_arm(), HUMAN_JOINTS)):
        for j, name in enumerate(joints):
            jid = m.joint(name).id
            assert m.jnt_type[jid] == mujoco.mjtJoint.mjJNT_HINGE
            np.testing.assert_allclose(m.jnt_range[jid], arm.joint_limits[j], rtol=0, atol=1e-12)
    assert m.opt.gravity[2] < 0  # gravity acts: the controller has something to compensate


def test_mjcf_hand_sites_are_the_planar_arms_hands():
    """The MJCF chains are interprim.sim's planar arms in the x-z plane: the same hands for any posture."""
    sim = ArmSim()
    ca, oa = controlled_arm(), observed_arm()
    rng = np.random.default_rng(0)
    for _ in range(20):
        qc = rng.uniform(ca.joint_limits[:, 0], ca.joint_limits[:, 1])
        qo = rng.uniform(oa.joint_limits[:, 0], oa.joint_limits[:, 1])
        sim.set_human(qo)
        sim.set_robot(qc)
        robot, human = sim.hands()
        np.testing.assert_allclose(robot, ca.hand(qc), atol=1e-12)
        np.testing.assert_allclose(human, oa.hand(qo), atol=1e-12)
        assert abs(sim.data.site_xpos[sim.model.site("robot_hand").id][1]) < 1e-12  # in the plane y = 0


def _min_jerk(q0, q1, duration):
    d = np.asarray(q1) - np.asarray(q0)

    def ref(t):
        if t >= duration:
            return q0 + d, np.zeros(3), np.zeros(3)
        s = max(t, 0.0) / duration
        h = 10 * s**3 - 15 * s**4 + 6 * s**5
        hd = (30 * s**2 - 60 * s**3 + 30 * s**4) / duration
        hdd = (60 * s - 180 * s**2 + 120 * s**3) / duration**2
        return q0 + h * d, hd * d, hdd * d

    return ref


def test_controller_tracks_a_known_reference_under_gravity():
    """Computed torque (PD + mj_inverse) on a minimum-jerk reach, then a hold.

    Bounds from the design, not from a run: a PD with gravity compensation but *without* the acceleration
    feedforward lags a reference by qdd_ref / K_p = max|qdd_ref| / omega^2 in steady tracking; the
    feedforward must do at least that well during the motion.  Afterwards the error of a critically damped
    loop decays like (1 + omega t) exp(-omega t), so after the hold it is below that bound times this factor.
    """
    omega, duration, hold = 30.0, 1.0, 0.5
    q0 = controlled_arm().rest
    q1 = np.array([-0.3, 1.2, 0.8])
    ref = _min_jerk(q0, q1, duration)
    t, q, q_ref, tau = track_reference(ref, duration + hold, omega=omega)
    bound = 5.7735 * np.max(np.abs(q1 - q0)) / duration**2 / omega**2  # max|h''| = 10 / sqrt(3) for min-jerk
    err = np.abs(q - q_ref)
    assert err[t <= duration].max() < bound
    decay = (1 + omega * hold) * np.exp(-omega * hold)
    assert err[-1].max() < bound * decay + 1e-10
    assert np.abs(q[-1] - q1).max() < bound * decay + 1e-10
    # it needed torque against gravity: a static posture with the arm out holds only with a non-zero torque
    assert np.abs(tau[-1, 0]) > 1.0


def test_controller_rejects_bad_gains():
    with pytest.raises(ValueError, match="omega"):
        track_reference(_min_jerk(np.zeros(3), np.zeros(3), 1.0), 0.01, omega=0.0)


@pytest.fixture(scope="module")
def model():
    return fit_highfive_model(n_train=40, seed=0)


@pytest.fixture(scope="module")
def result(model):
    return run_mujoco_highfive(model, seed=0)


@pytest.mark.slow  # the physics-simulated interaction (module fixture)
def test_hands_meet_within_the_movement(result):
    """A held-out partner (goal in the held-out cells), the robot driven online by model.stream(): the hands
    meet before the partner's movement ends and stay together, with a margin of 2x on the distance."""
    r = result
    assert r.met, r.summary()
    assert r.meet_time < r.movement_duration, r.summary()
    assert r.final_distance < r.threshold / 2, r.summary()
    assert r.closest_distance <= r.final_distance
    assert not r.out_of_range
    # the robot really moved there under physics: tracking error small against the movement itself
    travel = np.abs(r.q_robot[-1] - r.q_robot[0]).max()
    assert np.sqrt(np.mean((r.q_robot - r.q_ref) ** 2)) < 0.1 * travel
    # the hand at the true high-five point, and the prediction's final posture near it
    assert np.linalg.norm(r.robot_hand[-1] - r.goal) < r.threshold / 2
    assert np.linalg.norm(r.predicted_hand - r.goal) < r.threshold / 2
    # one prediction per partner frame, phases increasing to the end of the movement
    n_frames = int(round(r.movement_duration / 0.01)) + 1
    assert r.phase.shape == r.latency.shape == (n_frames,)
    assert r.phase[-1] > 0.95 and np.all(r.latency > 0)


@pytest.mark.slow
def test_run_is_deterministic(model, result):
    again = run_mujoco_highfive(model, seed=0)
    np.testing.assert_array_equal(again.q_robot, result.q_robot)
    assert again.meet_time == result.meet_time


def test_a_partner_that_never_comes_is_not_met(model):
    """The partner stays at rest: the hands must not be reported as meeting."""
    rest = np.tile(observed_arm().rest, (60, 1))
    r = run_mujoco_highfive(model, partner=rest, hold=0.2)
    assert not r.met and np.isnan(r.meet_time)
    assert r.closest_distance > r.threshold


def test_bad_inputs(model):
    with pytest.raises(ValueError, match="partner"):
        run_mujoco_highfive(model, partner=np.zeros((10, 3)))
    with pytest.raises(ValueError, match="physics steps"):
        run_mujoco_highfive(model, physics_dt=0.003)


@pytest.mark.slow
def test_figure_is_written(result, tmp_path):
    path = draw_mujoco_highfive(result, tmp_path / "highfive_mujoco.png")
    assert path.is_file() and path.stat().st_size > 10_000
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"

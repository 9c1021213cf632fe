"""Tests of the simulated high-five: kinematics, optimal control, data generator."""

import numpy as np
import pytest

from interprim.sim import (
    GOAL_BOX,
    PlanarArm,
    TrajectoryBasis,
    controlled_arm,
    generate_highfive,
    highfive_split,
    in_test_region,
    observed_arm,
    solve_reach,
)

ARMS = [observed_arm(), controlled_arm()]


def _random_q(arm, rng, n):
    lo, hi = arm.joint_limits[:, 0], arm.joint_limits[:, 1]
    return rng.uniform(lo, hi, size=(n, arm.n_joints))


# ---------------------------------------------------------------- kinematics
@pytest.mark.parametrize("arm", ARMS, ids=lambda a: a.name)
def test_jacobian_matches_finite_differences(arm):
    rng = np.random.default_rng(1)
    Q = _random_q(arm, rng, 25)
    J = arm.jacobian(Q)
    h = 1e-6
    for j in range(arm.n_joints):
        e = np.zeros(arm.n_joints)
        e[j] = h
        fd = (arm.hand(Q + e) - arm.hand(Q - e)) / (2 * h)
        np.testing.assert_allclose(J[:, :, j], fd, atol=1e-8)
    hand, J2 = arm.hand_and_jacobian(Q)
    np.testing.assert_allclose(hand, arm.hand(Q), atol=1e-14)
    np.testing.assert_allclose(J2, J, atol=1e-14)


@pytest.mark.parametrize("arm", ARMS, ids=lambda a: a.name)
def test_forward_kinematics_geometry(arm):
    rng = np.random.default_rng(2)
    Q = _random_q(arm, rng, 10)
    P = arm.forward_kinematics(Q)
    assert P.shape == (10, arm.n_joints + 1, 2)
    np.testing.assert_allclose(P[:, 0], np.broadcast_to(arm.base, (10, 2)))
    np.testing.assert_allclose(P[:, -1], arm.hand(Q), atol=1e-12)
    seg = np.linalg.norm(np.diff(P, axis=1), axis=-1)
    np.testing.assert_allclose(seg, np.broadcast_to(arm.link_lengths, seg.shape), atol=1e-12)


def test_arm_conventions_and_mirroring():
    oa, ca = observed_arm(), controlled_arm()
    assert oa.n_joints == 2 and ca.n_joints == 3
    # zero angles: observed arm points to +x, controlled arm (mirrored) to -x
    np.testing.assert_allclose(oa.hand([0, 0]), [oa.reach, 0.0], atol=1e-12)
    np.testing.assert_allclose(ca.hand([0, 0, 0]), [ca.base[0] - ca.reach, 0.0], atol=1e-12)
    # positive shoulder angle raises both hands
    assert oa.hand([0.3, 0])[1] > 0 and ca.hand([0.3, 0, 0])[1] > 0
    # a single link at 90 degrees
    arm = PlanarArm([2.0], base=(1.0, 1.0))
    np.testing.assert_allclose(arm.hand([np.pi / 2]), [1.0, 3.0], atol=1e-12)


def test_arm_input_validation():
    with pytest.raises(ValueError, match="link_lengths"):
        PlanarArm([1.0, -0.5])
    with pytest.raises(ValueError, match="joint_limits"):
        PlanarArm([1.0], joint_limits=[[1.0, 0.0]])
    with pytest.raises(ValueError, match=r"shape \(\.\.\., 2\)"):
        observed_arm().hand([0.1, 0.2, 0.3])


@pytest.mark.parametrize("arm", ARMS, ids=lambda a: a.name)
def test_inverse_kinematics_reaches_goals_within_limits(arm):
    rng = np.random.default_rng(3)
    (x0, x1), (y0, y1) = GOAL_BOX
    for _ in range(10):
        goal = rng.uniform([x0, y0], [x1, y1])
        q = arm.inverse_kinematics(goal)
        assert np.linalg.norm(arm.hand(q) - goal) < 1e-6
        assert arm.within_limits(q)


def test_inverse_kinematics_respects_limits_for_unreachable_goal():
    arm = observed_arm()
    q = arm.inverse_kinematics([5.0, 5.0])  # far out of reach
    assert arm.within_limits(q)
    # best effort: hand as close as the arm can get (stretched towards the goal)
    assert np.linalg.norm(arm.hand(q) - [5.0, 5.0]) < np.hypot(5, 5) - arm.reach + 1e-3


# ------------------------------------------------------------ optimal control
def test_trajectory_basis_boundary_conditions():
    M0, M1, M2 = TrajectoryBasis(6).matrices([0.0, 1.0])
    np.testing.assert_allclose(M0[0], 0, atol=1e-12)
    np.testing.assert_allclose(M0[1], [1] + [0] * 6, atol=1e-10)
    np.testing.assert_allclose(M1, 0, atol=1e-9)
    np.testing.assert_allclose(M2, 0, atol=1e-9)
    # derivative matrices are consistent with finite differences
    s = np.linspace(0.1, 0.9, 7)
    h = 1e-5
    A0p, _, _ = TrajectoryBasis(6).matrices(s + h)
    A0m, _, _ = TrajectoryBasis(6).matrices(s - h)
    _, A1, _ = TrajectoryBasis(6).matrices(s)
    np.testing.assert_allclose((A0p - A0m) / (2 * h), A1, atol=1e-6)


@pytest.mark.slow  # SLSQP per arm
@pytest.mark.parametrize("arm", ARMS, ids=lambda a: a.name)
def test_optimiser_reaches_goal_and_starts_at_rest(arm):
    rng = np.random.default_rng(4)
    (x0, x1), (y0, y1) = GOAL_BOX
    for _ in range(5):
        goal = rng.uniform([x0, y0], [x1, y1])
        attractor = 0.5 * (arm.hand(arm.rest) + goal) + rng.uniform(-0.2, 0.2, 2)
        sol = solve_reach(arm, goal, attractor[None])
        assert sol.success
        q = sol.sample(151)
        assert np.linalg.norm(arm.hand(q[-1]) - goal) < 1e-3  # < 1 mm (hard constraint)
        assert sol.hand_error < 1e-6
        np.testing.assert_allclose(q[0], arm.rest, atol=1e-12)
        # starts and ends at rest: zero velocity at both ends
        assert np.abs(q[1] - q[0]).max() < 1e-4 and np.abs(q[-1] - q[-2]).max() < 1e-4
        assert arm.within_limits(q, tol=1e-6)


def test_optimiser_attractor_pulls_the_hand():
    arm = observed_arm()
    goal = np.array([0.8, 0.45])
    free = solve_reach(arm, goal, None)
    mid_free = arm.hand(free(np.array([0.5])))[0]
    attractor = mid_free + np.array([-0.3, 0.0])
    pulled = solve_reach(arm, goal, attractor[None], w_attractor=3000.0)
    mid_pulled = arm.hand(pulled(np.array([0.5])))[0]
    d_free = np.linalg.norm(mid_free - attractor)
    d_pulled = np.linalg.norm(mid_pulled - attractor)
    assert d_pulled < 0.7 * d_free
    # the attractor costs effort, the free solution is the effort optimum
    assert pulled.effort > free.effort
    assert np.linalg.norm(arm.hand(pulled.q_final) - goal) < 1e-6


def test_optimiser_minimises_effort_without_attractor():
    """Without attractors the solution is a local minimum of effort: perturbations
    that keep the boundary conditions and the goal posture cost more."""
    arm = controlled_arm()
    goal = np.array([0.8, 0.5])
    sol = solve_reach(arm, goal, None)
    basis = TrajectoryBasis(5)
    rng = np.random.default_rng(5)
    xg, wg = np.polynomial.legendre.leggauss(12)
    _, _, G2 = basis.matrices(0.5 * (xg + 1))
    W = np.array([2.0, 1.0, 0.5])

    def effort(coef):
        acc = G2 @ coef
        return float(np.sum(0.5 * wg[:, None] * acc**2 * W))

    assert abs(effort(sol.coef) - sol.effort) < 1e-8 * max(1.0, sol.effort)
    for _ in range(10):
        pert = sol.coef.copy()
        pert[1:] += 0.05 * rng.standard_normal(pert[1:].shape)
        assert effort(pert) > sol.effort


def test_optimiser_enforces_joint_limits_when_they_bind():
    arm = controlled_arm()
    tight = PlanarArm(
        arm.link_lengths,
        base=arm.base,
        base_angle=arm.base_angle,
        mirror=True,
        joint_limits=[[-1.8, 1.9], [0.0, 2.6], [-0.05, 0.3]],  # wrist nearly frozen
        rest=arm.rest,
    )
    goal = np.array([0.8, 0.5])
    # the attractor asks for a strong wrist motion
    sol = solve_reach(tight, goal, np.array([[1.3, 0.2]]), w_attractor=5000.0)
    q = sol.sample(200)
    assert tight.within_limits(q, tol=1e-3)
    assert sol.hand_error < 1e-3


# ------------------------------------------------------------------ generator
@pytest.fixture(scope="module")
def small_data():
    return generate_highfive(12, seed=7, progress=False)


def test_generator_shapes_and_goal_reached(small_data):
    d = small_data
    assert len(d.demos) == 12 and d.goals.shape == (12, 2) and d.attractors.shape == (12, 2, 2)
    oa, ca = d.observed_arm, d.controlled_arm
    for i, demo in enumerate(d.demos):
        assert demo.ndim == 2 and demo.shape[1] == 5 and np.all(np.isfinite(demo))
        assert demo.shape[0] == int(round(d.durations[i] / d.dt)) + 1
        # both hands at the shared high-five point at the end (< 1 mm)
        assert np.linalg.norm(oa.hand(demo[-1, :2]) - d.goals[i]) < 1e-3
        assert np.linalg.norm(ca.hand(demo[-1, 2:]) - d.goals[i]) < 1e-3
        np.testing.assert_allclose(demo[0, :2], oa.rest, atol=1e-12)
        np.testing.assert_allclose(demo[0, 2:], ca.rest, atol=1e-12)
        assert oa.within_limits(demo[:, :2]) and ca.within_limits(demo[:, 2:])
    assert d.hand_errors.max() < 1e-3


def test_generator_duration_variation(small_data):
    d = small_data
    lengths = np.array([len(x) for x in d.demos])
    assert len(set(lengths.tolist())) > 5
    rel = d.durations / 1.5
    assert rel.min() >= 0.75 - 1e-9 and rel.max() <= 1.25 + 1e-9
    assert rel.max() - rel.min() > 0.2  # spread actually present


def test_generator_is_deterministic(small_data):
    again = generate_highfive(12, seed=7, progress=False)
    for a, b in zip(small_data.demos, again.demos):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(small_data.goals, again.goals)
    other = generate_highfive(12, seed=8, progress=False)
    assert not np.allclose(other.goals, small_data.goals)
    assert any(a.shape != b.shape or not np.allclose(a, b) for a, b in zip(small_data.demos, other.demos))


def test_generator_prefix_is_stable():
    """Interaction i does not depend on how many interactions are generated."""
    a = generate_highfive(3, seed=11, progress=False)
    b = generate_highfive(5, seed=11, progress=False)
    for x, y in zip(a.demos, b.demos[:3]):
        np.testing.assert_array_equal(x, y)


@pytest.mark.slow  # optimal control of many interactions
def test_split_holds_out_goal_region():
    train, test = highfive_split(30, 8, seed=3, progress=False)
    assert not in_test_region(train.goals).any()
    assert in_test_region(test.goals).all()
    (x0, x1), (y0, y1) = GOAL_BOX
    for g in np.vstack([train.goals, test.goals]):
        assert x0 <= g[0] <= x1 and y0 <= g[1] <= y1
    # test goals lie between training goals (interpolation, not extrapolation)
    assert (test.goals[:, 0] > train.goals[:, 0].min()).all() and (test.goals[:, 0] < train.goals[:, 0].max()).all()
    # nearest training goal is not trivially close for most test goals
    d = np.linalg.norm(test.goals[:, None] - train.goals[None], axis=-1).min(axis=1)
    assert np.median(d) > 0.01


def test_generator_validation():
    with pytest.raises(ValueError, match="region"):
        generate_highfive(2, region="nowhere", progress=False)
    with pytest.raises(ValueError, match="n must be"):
        generate_highfive(0, progress=False)
    with pytest.raises(ValueError, match="duration_jitter"):
        generate_highfive(2, duration_jitter=1.5, progress=False)

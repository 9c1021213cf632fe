"""A physics-simulated robot arm that answers a replayed partner live: the high five in MuJoCo.

The step beyond the kinematic arms of :mod:`interprim.sim`: the robot (the controlled agent) is a
rigid-body arm with masses, gravity, joint damping and torque-limited motors, simulated by MuJoCo
(``pip install "interprim[mujoco]"``), and it only moves through the torques of a joint-space controller.
The partner (the observed agent) is replayed from a recording: its joint angles are set at every physics
step.  At every frame of the partner (the model's ``dt``, 100 Hz for the simulated high five) the frame goes
to ``model.stream()`` (paper Sec. III-B-D online: phase, Eq. 5-9 or the likelihood phase; conditioning,
Eq. 16-18), and the posterior-mean response of the controlled agent (Eq. 1 rolled out from the posterior,
:class:`interprim.models.primitive.prediction.MeanRollout`) becomes the controller's reference.

The model (``highfive_arms.xml``, shipped beside this module) is the pair of planar chains of
:mod:`interprim.sim.arm` placed in MuJoCo's x-z plane (x towards the partner, z up): the simulated plane's
``(x, y)`` is MuJoCo's ``(x, z)``, joint names are the columns :data:`interprim.sim.COLUMNS`, and the hand
sites sit exactly where :meth:`interprim.sim.PlanarArm.hand` puts the hands (tested).  Because the model's
controlled DoFs are the robot's joint angles, the predicted trajectory maps one to one onto the MuJoCo
joints; no inverse kinematics is needed.  (A model whose controlled DoFs are hand positions would need a
differential IK step, ``dq = J^+ dx`` with ``mujoco.mj_jacSite``; not done here.)

Controller (:class:`JointController`), run at the physics rate (500 Hz by default) on a reference updated at
the partner's frame rate:

    qdd_cmd = qdd_ref + K_p (q_ref - q) + K_d (qd_ref - qd),   K_p = omega^2,  K_d = 2 zeta omega
    tau     = M(q) qdd_cmd + c(q, qd) + g(q) - (passive forces)      (``mujoco.mj_inverse``)

i.e. PD with gravity, Coriolis and damping compensation and inertia-weighted feedforward (computed torque),
clipped to the motors' torque limits.  With a perfect model the joint error obeys
``e'' + 2 zeta omega e' + omega^2 e = 0``: critically damped with ``zeta = 1``.

The reference at time ``t`` after the partner's frame ``k`` (seen at ``t_k``) is the latest prediction at
normalised time ``s = s_k + (t - t_k) / D_k`` (its phase ``s_k`` and duration ``D_k``), with velocity
``dq/ds / D_k`` and acceleration ``d2q/ds2 / D_k^2``; past ``s = 1`` it holds the predicted final posture.
When the partner's recording ends, the partner holds its last posture and the stream gets no more frames
(as in ``interprim demo``'s animation): the robot finishes the movement of the last prediction.

Whether the hands meet: the distance between the two hand sites (palm centres) against ``threshold``
(default 8 cm, about the width of a palm: two palms that touch, at least partly overlapping, have their centres
closer than that).  The meeting time is the first time from which the distance stays below the threshold to
the end of the run: the two planar arms move in one plane, and their hands can pass through each other on the
way up (the optimal-control demonstrations themselves come within 2 cm mid-movement), which is not a high five.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..core.preprocessing import interp_columns

__all__ = ["MJCF_FILE", "ROBOT_JOINTS", "HUMAN_JOINTS", "mjcf_path", "load_arms", "JointController", "ArmSim",
           "track_reference", "fit_highfive_model", "run_mujoco_highfive", "MujocoResult",
           "draw_mujoco_highfive"]

#: The MJCF file shipped with the package (``interprim/sim/highfive_arms.xml``).
MJCF_FILE = "highfive_arms.xml"
#: Joints of the robot (the controlled agent), in the order of the model's controlled columns.
ROBOT_JOINTS = ("ctrl_shoulder", "ctrl_elbow", "ctrl_wrist")
#: Joints of the replayed partner (the observed agent), in the order of the model's observed columns.
HUMAN_JOINTS = ("obs_shoulder", "obs_elbow")


def _mujoco():
    try:
        import mujoco
    except ImportError:
        raise ImportError("the MuJoCo simulation needs the 'mujoco' package: pip install 'interprim[mujoco]'") from None
    return mujoco


def mjcf_path() -> Path:
    """Path of the shipped MJCF model of the two arms."""
    return Path(__file__).resolve().with_name(MJCF_FILE)


def load_arms(physics_dt: float | None = None):
    """The ``mujoco.MjModel`` of the two arms (``physics_dt``: the integration step, default the file's 2 ms)."""
    mujoco = _mujoco()
    model = mujoco.MjModel.from_xml_path(str(mjcf_path()))
    if physics_dt is not None:
        if not physics_dt > 0:
            raise ValueError(f"physics_dt must be positive, got {physics_dt!r}")
        model.opt.timestep = float(physics_dt)
    return model


def _indices(mjmodel, names):
    """``(qpos addresses, dof addresses)`` of the named hinge joints."""
    ids = [mjmodel.joint(n).id for n in names]
    return (np.array([mjmodel.jnt_qposadr[i] for i in ids]), np.array([mjmodel.jnt_dofadr[i] for i in ids]))


class JointController:
    """Joint-space PD with inverse-dynamics compensation (computed torque) for the robot's joints.

    Parameters
    ----------
    mjmodel : mujoco.MjModel
    joints : sequence of str
        The controlled joints (each driven by a motor of the same name).
    omega : float
        Natural frequency of the closed-loop joint error, rad/s (``K_p = omega^2``).
    zeta : float
        Damping ratio (``K_d = 2 zeta omega``); 1 = critically damped.
    """

    def __init__(self, mjmodel, joints=ROBOT_JOINTS, omega: float = 30.0, zeta: float = 1.0):
        mujoco = _mujoco()
        if not (omega > 0 and zeta > 0):
            raise ValueError(f"omega and zeta must be positive, got {omega!r}, {zeta!r}")
        self.model = mjmodel
        self.qadr, self.dadr = _indices(mjmodel, joints)
        self.act = np.array([mjmodel.actuator(n).id for n in joints])
        self.kp = float(omega) ** 2
        self.kd = 2.0 * float(zeta) * float(omega)
        rng = mjmodel.actuator_ctrlrange[self.act]
        self.tau_min, self.tau_max = rng[:, 0].copy(), rng[:, 1].copy()
        self._inv = mujoco.MjData(mjmodel)  # scratch data for mj_inverse (the simulation's is not touched)
        self._mj_inverse = mujoco.mj_inverse

    def torque(self, data, q_ref, qd_ref, qdd_ref) -> np.ndarray:
        """Motor torques for the current state of ``data`` and the reference position, velocity, acceleration."""
        inv = self._inv
        inv.qpos[:] = data.qpos
        inv.qvel[:] = data.qvel
        inv.qacc[:] = 0.0
        e = q_ref - data.qpos[self.qadr]
        ed = qd_ref - data.qvel[self.dadr]
        inv.qacc[self.dadr] = qdd_ref + self.kp * e + self.kd * ed
        self._mj_inverse(self.model, inv)
        return np.clip(inv.qfrc_inverse[self.dadr], self.tau_min, self.tau_max)


class ArmSim:
    """The two arms in MuJoCo: a torque-controlled robot and a replayed partner.

    Parameters
    ----------
    omega, zeta : float
        Gains of the :class:`JointController`.
    physics_dt : float
        Integration step, seconds (the controller runs at every step).
    """

    def __init__(self, omega: float = 30.0, zeta: float = 1.0, physics_dt: float = 0.002):
        mujoco = _mujoco()
        self._mj = mujoco
        self.model = load_arms(physics_dt)
        self.data = mujoco.MjData(self.model)
        self.controller = JointController(self.model, ROBOT_JOINTS, omega, zeta)
        self.robot_q, self.robot_v = _indices(self.model, ROBOT_JOINTS)
        self.human_q, self.human_v = _indices(self.model, HUMAN_JOINTS)
        self._robot_site = self.model.site("robot_hand").id
        self._human_site = self.model.site("human_hand").id
        lim = self.model.jnt_range[[self.model.joint(n).id for n in ROBOT_JOINTS]]
        self.robot_limits = lim.copy()

    @property
    def dt(self) -> float:
        """The physics time step, seconds (the MJCF's ``timestep``)."""
        return float(self.model.opt.timestep)

    def set_robot(self, q, qd=None):
        """Place the robot at joint angles ``q`` (velocity ``qd``, default 0) and recompute the kinematics."""
        self.data.qpos[self.robot_q] = q
        self.data.qvel[self.robot_v] = 0.0 if qd is None else qd
        self._mj.mj_forward(self.model, self.data)

    def set_human(self, q, qd=None):
        """Replay the partner: set its joint angles (and velocity) without simulating its dynamics."""
        self.data.qpos[self.human_q] = q
        self.data.qvel[self.human_v] = 0.0 if qd is None else qd

    def step(self, q_ref, qd_ref, qdd_ref) -> np.ndarray:
        """One physics step with the controller's torques; returns the torques."""
        tau = self.controller.torque(self.data, q_ref, qd_ref, qdd_ref)
        self.data.ctrl[self.controller.act] = tau
        self._mj.mj_step(self.model, self.data)
        return tau

    def kinematics(self):
        """Recompute positions for the current joint angles (after :meth:`set_human`)."""
        self._mj.mj_kinematics(self.model, self.data)

    @property
    def q(self) -> np.ndarray:
        """The robot's joint angles now, radians (a copy)."""
        return self.data.qpos[self.robot_q].copy()

    def hands(self):
        """``(robot hand, partner hand)``: the hand sites' ``(x, z)`` in metres (the simulated plane's ``(x, y)``)."""
        r = self.data.site_xpos[self._robot_site]
        h = self.data.site_xpos[self._human_site]
        return np.array([r[0], r[2]]), np.array([h[0], h[2]])


def track_reference(reference, t_end: float, q0=None, omega: float = 30.0, zeta: float = 1.0,
                    physics_dt: float = 0.002):
    """Run the robot alone under :class:`JointController` on a known reference (for tests and tuning).

    Parameters
    ----------
    reference : callable
        ``reference(t) -> (q, qd, qdd)`` arrays of shape ``(3,)``.
    t_end : float
        Simulated seconds.
    q0 : array_like, optional
        Start posture (default ``reference(0)[0]``, at rest).

    Returns
    -------
    t : ndarray (n,), q : ndarray (n, 3), q_ref : ndarray (n, 3), tau : ndarray (n, 3)
        Times, joint angles after each step, the reference at those times, the torques applied.
    """
    sim = ArmSim(omega, zeta, physics_dt)
    sim.set_robot(reference(0.0)[0] if q0 is None else np.asarray(q0, dtype=float))
    n = int(round(t_end / sim.dt))
    t = np.arange(1, n + 1) * sim.dt
    q = np.empty((n, 3))
    q_ref = np.empty((n, 3))
    tau = np.empty((n, 3))
    for i in range(n):
        tau[i] = sim.step(*reference(i * sim.dt))
        q[i] = sim.q
        q_ref[i] = reference(t[i])[0]
    return t, q, q_ref, tau


def fit_highfive_model(n_train: int = 40, seed: int = 0, n_basis: int = 10, input_noise: float | None = 0.01,
                       **kwargs):
    """An :class:`~interprim.InteractionPrimitive` of the simulated high five (``n_train`` interactions by optimal
    control with goals outside the held-out cells, :func:`interprim.sim.generate_highfive`).

    ``input_noise=0.01`` rad: the demonstrations are noise-free, so the cross-validated noise (Eq. 16) is tiny
    (~1e-6 rad^2) and the conditioning trusts every frame exactly; online, an error of 1-2 % in the estimated
    phase then bends the prediction far off (the predicted high-five point moved 12-41 cm in the second half
    of the six held-out movements we tried, against 2-8 cm with ``input_noise=0.01``).
    """
    from ..models.primitive.estimator import InteractionPrimitive
    from .highfive import generate_highfive

    train = generate_highfive(n_train, seed=seed, region="train", progress=False)
    return InteractionPrimitive(observed_dofs=[0, 1], n_basis=n_basis, input_noise=input_noise,
                                **kwargs).fit(train.demos, dt=train.dt)


@dataclass
class MujocoResult:
    """What happened in :func:`run_mujoco_highfive`.

    Attributes
    ----------
    t : ndarray (n,)
        Time of every physics step, seconds from the partner's first frame.
    q_robot, q_ref : ndarray (n, 3)
        The robot's joint angles and the controller's reference (the IP's prediction), radians.
    q_human : ndarray (n, 2)
        The replayed partner's joint angles.
    robot_hand, human_hand : ndarray (n, 2)
        Hand sites, ``(x, z)`` in metres.
    distance : ndarray (n,)
        Distance between the hands, metres.
    threshold : float
        Distance below which the hands meet.
    met : bool
        Whether the distance ends below ``threshold`` (the hands came together and stayed).
    meet_time : float
        First time from which the distance stays below ``threshold`` to the end (NaN if it does not end below).
    closest_distance, closest_time : float
        The smallest distance and when (a pass of one hand through the other included).
    final_distance : float
        The distance at the end of the run (``hold`` seconds after the partner's last frame).
    movement_duration : float
        Duration of the partner's recorded movement, seconds.
    frame_time, phase, latency : ndarray (K,)
        Per partner frame: its time, the estimated phase, the wall-clock seconds of ``stream.update`` plus the
        reference's rollout.
    out_of_range : bool
        Whether any prediction flagged its input as out of range.
    goal : ndarray (2,) or None
        The true high-five point of the recording, when known.
    predicted_hand : ndarray (2,)
        The robot's hand at the final posture of the last prediction.
    """

    t: np.ndarray
    q_robot: np.ndarray
    q_ref: np.ndarray
    q_human: np.ndarray
    robot_hand: np.ndarray
    human_hand: np.ndarray
    distance: np.ndarray
    threshold: float
    met: bool
    meet_time: float
    closest_distance: float
    closest_time: float
    final_distance: float
    movement_duration: float
    frame_time: np.ndarray
    phase: np.ndarray
    latency: np.ndarray
    out_of_range: bool
    predicted_hand: np.ndarray
    goal: np.ndarray | None = None
    extra: dict = field(default_factory=dict)

    def summary(self) -> str:
        """One line: whether and when the hands met, the closest distance, the update latency."""
        lat = 1e3 * self.latency
        met = (f"hands met at t = {self.meet_time:.3f} s (movement {self.movement_duration:.3f} s)" if self.met
               else f"hands did not meet (threshold {100 * self.threshold:.1f} cm)")
        return (f"{met}; closest {100 * self.closest_distance:.2f} cm at t = {self.closest_time:.3f} s, "
                f"final {100 * self.final_distance:.2f} cm; "
                f"joint tracking RMS {np.sqrt(np.mean((self.q_robot - self.q_ref) ** 2)):.4f} rad; "
                f"update latency median {np.median(lat):.2f} ms, p99 {np.percentile(lat, 99):.2f} ms")


def _ds_derivatives(Y, n):
    """First and second derivatives along the normalised-time grid ``linspace(0, 1, n)`` of ``Y (n, d)``."""
    h = 1.0 / (n - 1)
    d1 = np.gradient(Y, h, axis=0)
    return d1, np.gradient(d1, h, axis=0)


def run_mujoco_highfive(model=None, partner=None, *, goal=None, seed: int = 0, n_train: int = 40,
                        hold: float = 0.5, threshold: float = 0.08, omega: float = 30.0, zeta: float = 1.0,
                        physics_dt: float = 0.002, sensor_noise: float = 0.0, n_grid: int = 201) -> MujocoResult:
    """Simulate the high five in MuJoCo: a replayed partner and a torque-controlled robot driven by the IP online.

    Parameters
    ----------
    model : InteractionPrimitive, optional
        A fitted model of the simulated high five (observed columns: the partner's 2 joints; controlled: the
        robot's 3 joints, :data:`interprim.sim.COLUMNS`).  Default: :func:`fit_highfive_model` with ``seed``.
    partner : array_like (T, 2), optional
        The partner's joint angles sampled at ``model.dt_``.  Default: a held-out interaction of
        :func:`interprim.sim.highfive_split`'s test region drawn with ``seed`` (its goal is reported).
    goal : array_like (2,), optional
        The true high-five point of ``partner``, reported in the result and the figure.
    seed : int
        Seeds the training data (when ``model`` is None), the partner (when ``partner`` is None) and the
        sensor noise.  The simulation itself is deterministic.
    n_train : int
        Training interactions when ``model`` is None.
    hold : float
        Seconds simulated after the partner's last frame (the partner holds its last posture).
    threshold : float
        Distance of the hands (metres) below which they meet (default: about a palm's width).
    omega, zeta : float
        Controller gains (see :class:`JointController`).
    physics_dt : float
        Physics step, seconds; ``model.dt_`` must be a whole number of steps.
    sensor_noise : float
        Standard deviation (radians) of Gaussian noise added to the frames given to the model (not to the
        replayed partner): a tracker's noise.
    n_grid : int
        Points of the normalised-time grid on which each prediction is rolled out.

    Returns
    -------
    MujocoResult
    """
    from .arm import controlled_arm
    from .highfive import generate_highfive

    if model is None:
        model = fit_highfive_model(n_train, seed)
    if not hasattr(model, "prior_"):
        raise ValueError("model is not fitted: call fit() first or pass model=None")
    if len(model.observed_dofs_) != 2 or len(model.controlled_dofs_) != 3:
        raise ValueError(f"the model must observe 2 DoFs (the partner's joints) and control 3 (the robot's joints), "
                         f"got {len(model.observed_dofs_)} and {len(model.controlled_dofs_)}")
    if partner is None:
        test = generate_highfive(1, seed=seed + 1_000_003, region="test", progress=False, dt=model.dt_)
        partner, goal = test.observed(0), test.goals[0]
    partner = np.asarray(partner, dtype=np.float64)
    if partner.ndim != 2 or partner.shape[1] != 2 or partner.shape[0] < 3 or not np.all(np.isfinite(partner)):
        raise ValueError("partner must be a finite (T, 2) array of joint angles with T >= 3, "
                         f"got shape {partner.shape}")
    dt = float(model.dt_)
    substeps = int(round(dt / physics_dt))
    if substeps < 1 or abs(substeps * physics_dt - dt) > 1e-9 * dt:
        raise ValueError(f"the model's dt ({dt} s) must be a whole number of physics steps ({physics_dt} s)")
    rng = np.random.default_rng(seed)
    sim = ArmSim(omega, zeta, physics_dt)
    lo, hi = sim.robot_limits[:, 0], sim.robot_limits[:, 1]
    q0 = controlled_arm().rest
    sim.set_robot(q0)
    sim.set_human(partner[0])
    stream = model.stream(robot_state=q0)
    rollout = None
    ctrl_cols = list(model.controlled_dofs_)
    T = partner.shape[0]
    n_frames = T + int(round(hold / dt))
    n = n_frames * substeps
    rec = {k: np.empty((n, w)) for k, w in (("q", 3), ("ref", 3), ("qh", 2), ("rh", 2), ("hh", 2))}
    t_all = np.arange(n) * physics_dt
    frame_time, phase, latency = [], [], []
    out_of_range = False
    Y = dY = ddY = np.empty((0, 3))  # set at the partner's first frame
    s_k = D_k = t_k = 0.0
    grid = np.linspace(0.0, 1.0, n_grid)
    i = 0
    for k in range(n_frames):
        if k < T:  # the partner's frame k is seen at t_k = k dt: update the prediction
            frame = partner[k] + (sensor_noise * rng.standard_normal(2) if sensor_noise > 0 else 0.0)
            tic = time.perf_counter()
            p = stream.update(frame)
            if rollout is None:
                rollout = p.mean_rollout(n_grid, ctrl_cols)
            Y = rollout(p)
            latency.append(time.perf_counter() - tic)
            dY, ddY = _ds_derivatives(Y, n_grid)
            s_k, D_k, t_k = p.normalised_time, p.duration, k * dt
            frame_time.append(t_k)
            phase.append(p.phase)
            out_of_range |= bool(p.out_of_range)
        for j in range(substeps):
            t = t_all[i]
            a = j / substeps  # the partner between frames k and k + 1, then holding its last posture
            qh = partner[min(k, T - 1)] if k >= T - 1 else (1 - a) * partner[k] + a * partner[k + 1]
            qhd = np.zeros(2) if k >= T - 1 else (partner[k + 1] - partner[k]) / dt
            sim.set_human(qh, qhd)
            s = s_k + (t - t_k) / D_k
            if s >= 1.0:
                ref: tuple = (Y[-1], np.zeros(3), np.zeros(3))
            else:
                sc = max(s, 0.0)
                ref = tuple(interp_columns(sc, grid, A[:, :3]) * f
                            for A, f in ((Y, 1.0), (dY, 1.0 / D_k), (ddY, 1.0 / D_k ** 2)))
            q_ref = np.clip(ref[0], lo, hi)
            sim.step(q_ref, ref[1], ref[2])
            sim.kinematics()
            rec["q"][i] = sim.q
            rec["ref"][i] = q_ref
            rec["qh"][i] = qh
            rec["rh"][i], rec["hh"][i] = sim.hands()
            i += 1
    t_all = t_all + physics_dt  # the state after each step
    dist = np.linalg.norm(rec["rh"] - rec["hh"], axis=1)
    above = np.flatnonzero(dist >= threshold)
    met = above.size == 0 or above[-1] < dist.size - 1
    i_meet = 0 if above.size == 0 else above[-1] + 1
    j_min = int(np.argmin(dist))
    return MujocoResult(
        t=t_all, q_robot=rec["q"], q_ref=rec["ref"], q_human=rec["qh"], robot_hand=rec["rh"],
        human_hand=rec["hh"], distance=dist, threshold=float(threshold), met=bool(met),
        meet_time=float(t_all[i_meet]) if met else float("nan"), closest_distance=float(dist[j_min]),
        closest_time=float(t_all[j_min]), final_distance=float(dist[-1]), movement_duration=(T - 1) * dt,
        frame_time=np.array(frame_time), phase=np.array(phase), latency=np.array(latency),
        out_of_range=out_of_range, predicted_hand=controlled_arm().hand(Y[-1]),
        goal=None if goal is None else np.asarray(goal, dtype=float).reshape(2))


def draw_mujoco_highfive(result: MujocoResult, path, n_snapshots: int = 5):
    """Draw ``result`` to ``path`` (PNG, matplotlib with the Agg backend; no display or GL context needed).

    Top row: the two arms at ``n_snapshots`` instants from the start to the meeting, and at the end (the kinematics of
    :mod:`interprim.sim.arm`, the same chains as the MJCF model), with the partner's hand path so far and the robot's
    reference posture (dashed). Bottom: the distance between the hands over time, the threshold and the meeting time;
    the joint angles against the reference.
    """
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    from .arm import controlled_arm, observed_arm

    ca, oa = controlled_arm(), observed_arm()
    r = result
    fig = plt.figure(figsize=(12, 6.2))
    gs = fig.add_gridspec(2, n_snapshots, height_ratios=[1.15, 1.0])
    end = r.t[-1]
    last = r.meet_time if r.met else min(end, r.movement_duration)
    moments = np.append(np.linspace(0.0, last, n_snapshots - 1), end)  # up to the meeting, and the end
    labels = [""] * (n_snapshots - 2) + (["hands meet: "] if r.met else [""]) + ["end: "]
    for c, tm in enumerate(moments):
        ax = fig.add_subplot(gs[0, c])
        i = int(np.clip(np.searchsorted(r.t, tm), 0, len(r.t) - 1))
        ph = oa.forward_kinematics(r.q_human[i])
        pr = ca.forward_kinematics(r.q_robot[i])
        pref = ca.forward_kinematics(r.q_ref[i])
        ax.plot(r.human_hand[: i + 1, 0], r.human_hand[: i + 1, 1], color="tab:blue", lw=0.8, alpha=0.6)
        ax.plot(ph[:, 0], ph[:, 1], "o-", color="tab:blue", lw=3, ms=3)
        ax.plot(pref[:, 0], pref[:, 1], "--", color="tab:red", lw=1, alpha=0.7)
        ax.plot(pr[:, 0], pr[:, 1], "o-", color="tab:red", lw=3, ms=3)
        if r.goal is not None:
            ax.plot(*r.goal, "o", mfc="none", mec="k", ms=9)
        ax.set_xlim(-0.3, 1.9)
        ax.set_ylim(-1.4, 1.2)
        ax.set_aspect("equal")
        ax.set_xticks([])
        ax.set_yticks([])
        ax.set_title(f"{labels[c]}t = {r.t[i]:.2f} s, d = {100 * r.distance[i]:.1f} cm", fontsize=8)
    ax = fig.add_subplot(gs[1, : max(1, n_snapshots - 2)])
    ax.plot(r.t, 100 * r.distance, color="k", lw=1.2, label="distance between the hands")
    ax.axhline(100 * r.threshold, color="tab:green", ls="--", lw=1, label=f"meeting threshold {100 * r.threshold:g} cm")
    ax.axvline(r.movement_duration, color="tab:blue", ls=":", lw=1, label="partner's movement ends")
    if r.met:
        ax.axvline(r.meet_time, color="tab:green", lw=1, label=f"hands meet, t = {r.meet_time:.2f} s")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("distance [cm]")
    ax.set_yscale("log")
    ax.legend(fontsize=7)
    ax.set_title(f"closest {100 * r.closest_distance:.2f} cm at t = {r.closest_time:.2f} s", fontsize=9)
    ax2 = fig.add_subplot(gs[1, max(1, n_snapshots - 2):])
    for c, name in enumerate(ROBOT_JOINTS):
        line, = ax2.plot(r.t, r.q_robot[:, c], lw=1.2, label=name)
        ax2.plot(r.t, r.q_ref[:, c], "--", lw=0.8, color=line.get_color())
    ax2.set_xlabel("time [s]")
    ax2.set_ylabel("robot joints [rad] (dashed: IP reference)")
    ax2.legend(fontsize=7)
    fig.suptitle("MuJoCo: the robot (red, torque-controlled) answers the replayed partner (blue) "
                 "through model.stream()", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return Path(path)

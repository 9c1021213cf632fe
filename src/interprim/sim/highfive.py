"""The simulated high-five of the paper (Sec. IV, Fig. 5): training and test interactions.

Each interaction has

* a shared **goal** ``g`` (the high-five point) in the common workspace of the
  two arms, drawn from :data:`GOAL_BOX`;
* one **attractor** point per arm, drawn around the midpoint between the arm's
  rest hand position and the goal, displaced towards the arm's own body and
  upwards, so that the hands rise in an arc (Fig. 5);
* a **duration** ``T = duration * (1 + u)``, ``u ~ U(-jitter, +jitter)``,
  shared by both arms (they move in synchrony, as in the paper).

Each arm's joint trajectory is the optimal-control solution of
:func:`interprim.sim.optimal_control.solve_reach` (minimum squared joint
accelerations + attractor cost, hand exactly at the goal at the end), sampled
at ``dt``.  A demonstration is the ``(T_i, 5)`` array
``[obs_shoulder, obs_elbow, ctrl_shoulder, ctrl_elbow, ctrl_wrist]`` (radians).

Train/test split (:func:`highfive_split`): the goal box is cut into a
``5 x 4`` grid of cells; three interior cells form a checkerboard-like
**held-out region**.  Training goals are drawn outside it, test goals inside it,
so test interactions go to "goal positions that were not part of the original
training data" (paper Sec. IV), yet lie between training goals.

Everything is deterministic given ``seed``: interaction ``i`` draws its random
numbers from its own ``numpy.random.SeedSequence(seed).spawn`` child.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..core.blas import single_thread
from .arm import PlanarArm, controlled_arm, observed_arm

__all__ = [
    "GOAL_BOX",
    "HighFiveData",
    "generate_highfive",
    "highfive_split",
    "in_test_region",
    "COLUMNS",
    "RECORDING_COLUMNS",
    "highfive_recordings",
]

#: Goal (high-five point) box, metres: ``((x_min, x_max), (y_min, y_max))``.
GOAL_BOX = ((0.60, 1.00), (0.20, 0.70))
#: Grid of cells over the goal box and the held-out (test) cells ``(ix, iy)``.
GRID = (5, 4)
TEST_CELLS = ((1, 2), (2, 1), (3, 2))
#: Column names of a demonstration.
COLUMNS = ["obs_shoulder", "obs_elbow", "ctrl_shoulder", "ctrl_elbow", "ctrl_wrist"]
#: Column names of :func:`highfive_recordings`: the partner's hand (metres), the robot's joints (radians).
RECORDING_COLUMNS = ["human_x", "human_y", "robot_shoulder", "robot_elbow", "robot_wrist"]

# Attractor offsets from the midpoint (rest hand, goal), in the arm's own
# "forward" frame: x towards the partner, y up.  Metres.
_ATTRACTOR_FORWARD = (-0.20, 0.05)
_ATTRACTOR_UP = (-0.05, 0.15)


def _cell_of(goals):
    goals = np.atleast_2d(goals)
    (x0, x1), (y0, y1) = GOAL_BOX
    ix = np.clip(((goals[:, 0] - x0) / (x1 - x0) * GRID[0]).astype(int), 0, GRID[0] - 1)
    iy = np.clip(((goals[:, 1] - y0) / (y1 - y0) * GRID[1]).astype(int), 0, GRID[1] - 1)
    return ix, iy


def in_test_region(goals) -> np.ndarray:
    """Boolean mask: which goals ``(n, 2)`` lie in the held-out test cells."""
    ix, iy = _cell_of(goals)
    mask = np.zeros(ix.shape, dtype=bool)
    for cx, cy in TEST_CELLS:
        mask |= (ix == cx) & (iy == cy)
    return mask


def _sample_goal(rng, region: str):
    (x0, x1), (y0, y1) = GOAL_BOX
    cw, ch = (x1 - x0) / GRID[0], (y1 - y0) / GRID[1]
    if region == "test":
        cx, cy = TEST_CELLS[rng.integers(len(TEST_CELLS))]
        return np.array([x0 + (cx + rng.uniform()) * cw, y0 + (cy + rng.uniform()) * ch])
    while True:  # rejection sampling ("train": outside the test cells; "all": anywhere)
        g = np.array([rng.uniform(x0, x1), rng.uniform(y0, y1)])
        if region == "all" or not in_test_region(g)[0]:
            return g


@dataclass
class HighFiveData:
    """A set of simulated high-five interactions.

    Attributes
    ----------
    demos : list of ndarray, shape (T_i, 5)
        Joint trajectories, columns :data:`COLUMNS` (radians), sampled at ``dt``.
    goals : ndarray, shape (n, 2)
        High-five points, metres.
    attractors : ndarray, shape (n, 2, 2)
        ``attractors[i, 0]`` for the observed arm, ``attractors[i, 1]`` for the
        controlled arm, metres.
    durations : ndarray, shape (n,)
        Durations in seconds (``(T_i - 1) * dt``).
    dt : float
        Sampling interval, seconds.
    observed_arm, controlled_arm : PlanarArm
    observed_dofs : list of int
        ``[0, 1]``: the columns of the observed agent.
    hand_errors : ndarray, shape (n, 2)
        Final distance of each hand from the goal (observed, controlled), metres.
    costs : ndarray, shape (n, 2)
        Optimal-control objective of each arm.
    seed : int or None
    region : str
    """

    demos: list
    goals: np.ndarray
    attractors: np.ndarray
    durations: np.ndarray
    dt: float
    observed_arm: PlanarArm
    controlled_arm: PlanarArm
    hand_errors: np.ndarray
    costs: np.ndarray
    seed: int | None = None
    region: str = "all"
    observed_dofs: list = field(default_factory=lambda: [0, 1])

    def __len__(self) -> int:
        return len(self.demos)

    @property
    def controlled_dofs(self) -> list:
        """``[2, 3, 4]``: the columns of the controlled agent."""
        return [2, 3, 4]

    def observed(self, i: int) -> np.ndarray:
        """Observed-agent joint trajectory of interaction ``i``, ``(T_i, 2)``."""
        return self.demos[i][:, self.observed_dofs]

    def controlled(self, i: int) -> np.ndarray:
        """Controlled-agent joint trajectory of interaction ``i``, ``(T_i, 3)``."""
        return self.demos[i][:, self.controlled_dofs]

    def hands(self, i: int):
        """Task-space hand trajectories ``(T_i, 2)`` of both arms (observed, controlled)."""
        return self.observed_arm.hand(self.observed(i)), self.controlled_arm.hand(self.controlled(i))

    def subset(self, idx) -> HighFiveData:
        """A new :class:`HighFiveData` with the interactions ``idx``."""
        idx = np.asarray(idx, dtype=int)
        return HighFiveData(
            demos=[self.demos[i] for i in idx],
            goals=self.goals[idx],
            attractors=self.attractors[idx],
            durations=self.durations[idx],
            dt=self.dt,
            observed_arm=self.observed_arm,
            controlled_arm=self.controlled_arm,
            hand_errors=self.hand_errors[idx],
            costs=self.costs[idx],
            seed=self.seed,
            region=self.region,
        )


def _sample_attractor(rng, arm: PlanarArm, goal, forward_sign: float):
    mid = 0.5 * (arm.hand(arm.rest) + goal)
    fwd = rng.uniform(*_ATTRACTOR_FORWARD)
    up = rng.uniform(*_ATTRACTOR_UP)
    return mid + np.array([forward_sign * fwd, up])


def _solve_one(args):
    """Worker: one interaction (both arms).  ``args`` = (seed_seq, region, duration, jitter, dt, kwargs)."""
    from .optimal_control import solve_reach

    ss, region, duration, jitter, dt, kw, cache = args
    rng = np.random.default_rng(ss)
    oa, ca = observed_arm(), controlled_arm()
    goal = _sample_goal(rng, region)
    a_obs = _sample_attractor(rng, oa, goal, +1.0)
    a_ctrl = _sample_attractor(rng, ca, goal, -1.0)
    T = duration * (1.0 + rng.uniform(-jitter, jitter))
    n_frames = int(round(T / dt)) + 1
    with single_thread():  # tiny problems: one BLAS thread is fastest (SLSQP up to 20x slower with two)
        sol_o = solve_reach(oa, goal, a_obs[None], _basis_cache=cache, **kw)
        sol_c = solve_reach(ca, goal, a_ctrl[None], _basis_cache=cache, **kw)
    qo = np.clip(sol_o.sample(n_frames), oa.joint_limits[:, 0], oa.joint_limits[:, 1])
    qc = np.clip(sol_c.sample(n_frames), ca.joint_limits[:, 0], ca.joint_limits[:, 1])
    demo = np.hstack([qo, qc])
    return (
        demo,
        goal,
        np.stack([a_obs, a_ctrl]),
        (n_frames - 1) * dt,
        (sol_o.hand_error, sol_c.hand_error),
        (sol_o.cost, sol_c.cost),
        sol_o.success and sol_c.success,
    )


def generate_highfive(
    n: int,
    seed: int | None = 0,
    dt: float = 0.01,
    duration: float = 1.5,
    duration_jitter: float = 0.25,
    region: str = "all",
    progress: bool = True,
    n_jobs: int = 1,
    **solver_kwargs,
) -> HighFiveData:
    """Synthesise ``n`` high-five interactions by optimal control (paper Sec. IV, Fig. 5).

    Parameters
    ----------
    n : int
        Number of interactions.
    seed : int or None
        Seed of the random goals, attractors and durations; the same seed
        gives identical data.
    dt : float
        Sampling interval, seconds (default 0.01 s = 100 Hz).
    duration : float
        Mean duration of a movement, seconds.
    duration_jitter : float
        Relative spread of the duration: ``T ~ duration * U(1 - j, 1 + j)``
        (default 0.25, i.e. +-25 %), so demonstrations differ in length and
        speed and phase estimation matters.
    region : {"all", "train", "test"}
        Where goals are drawn: anywhere in :data:`GOAL_BOX`, outside the
        held-out cells, or inside them (see :func:`in_test_region`).
    progress : bool
        Show a tqdm progress bar.
    n_jobs : int
        Worker processes (joblib); ``1`` runs in this process.  Results do not
        depend on ``n_jobs``.
    **solver_kwargs
        Passed to :func:`~interprim.sim.optimal_control.solve_reach`
        (e.g. ``w_attractor``, ``n_basis``, ``n_knots``).

    Returns
    -------
    HighFiveData
    """
    if progress:  # the bar needs the experiments extra; without it, plain iteration
        from tqdm.auto import tqdm
    else:
        def tqdm(it, **_):
            return it

    n = int(n)
    if n < 1:
        raise ValueError(f"n must be >= 1, got {n}")
    if region not in ("all", "train", "test"):
        raise ValueError(f"region must be 'all', 'train' or 'test', got {region!r}")
    if not (dt > 0):
        raise ValueError(f"dt must be positive, got {dt}")
    if not (0 <= duration_jitter < 1):
        raise ValueError(f"duration_jitter must be in [0, 1), got {duration_jitter}")
    if not (duration > 2 * dt):
        raise ValueError(f"duration must be longer than two frames, got {duration}")
    children = np.random.SeedSequence(seed).spawn(n)
    cache: dict = {}
    tasks = [(c, region, duration, duration_jitter, dt, solver_kwargs, cache) for c in children]
    desc = f"simulating high-fives ({region})"
    if n_jobs == 1:
        results = [_solve_one(t) for t in tqdm(tasks, desc=desc, disable=not progress, leave=False)]
    else:
        from joblib import Parallel, delayed

        tasks = [t[:-1] + ({},) for t in tasks]  # no cache shared across processes
        results = Parallel(n_jobs=n_jobs, return_as="generator")(delayed(_solve_one)(t) for t in tasks)
        results = list(tqdm(results, total=n, desc=desc, disable=not progress, leave=False))
    n_fail = sum(not r[6] for r in results)
    if n_fail:
        import warnings

        warnings.warn(f"{n_fail} of {n} optimal-control problems did not report convergence", RuntimeWarning,
                      stacklevel=2)
    return HighFiveData(
        demos=[r[0] for r in results],
        goals=np.array([r[1] for r in results]),
        attractors=np.array([r[2] for r in results]),
        durations=np.array([r[3] for r in results]),
        dt=float(dt),
        observed_arm=observed_arm(),
        controlled_arm=controlled_arm(),
        hand_errors=np.array([r[4] for r in results]),
        costs=np.array([r[5] for r in results]),
        seed=seed,
        region=region,
    )


def highfive_split(n_train: int, n_test: int, seed: int = 0, **kwargs):
    """Training interactions with goals outside the held-out region and test interactions inside it.

    Parameters
    ----------
    n_train, n_test : int
    seed : int
        Training data uses ``seed``, test data ``seed + 1_000_003`` (independent streams).
    **kwargs
        Passed to :func:`generate_highfive`.

    Returns
    -------
    train, test : HighFiveData
    """
    train = generate_highfive(n_train, seed=seed, region="train", **kwargs)
    test = generate_highfive(n_test, seed=seed + 1_000_003, region="test", **kwargs)
    return train, test


def highfive_recordings(n: int = 40, seed: int = 0, noise: float = 0.002, region: str = "train", **kwargs):
    """The simulated high five as a set of recordings, the way a lab records one (for tutorials and examples).

    The partner is tracked in task space, its hand ``(human_x, human_y)`` in metres in the robot's world
    frame (x towards the partner, y up; the partner's shoulder at the origin, the robot's at x = 1.6 m) with
    Gaussian tracker noise of standard deviation ``noise`` metres; the robot is recorded in joint space
    (``robot_shoulder``, ``robot_elbow``, ``robot_wrist``, radians, noise-free, as its encoders give them).
    100 Hz, time stamps from 0.

    Parameters
    ----------
    n, seed, region, **kwargs
        As for :func:`generate_highfive` (``region="train"``: goals outside the held-out cells).
    noise : float
        Tracker noise of the partner's hand, metres.

    Returns
    -------
    interprim.datasets.Demonstrations
        Columns :data:`RECORDING_COLUMNS`; ``observed_dofs = [0, 1]``.
    """
    from ..datasets import Demonstrations

    data = generate_highfive(n, seed=seed, region=region, progress=False, **kwargs)
    rng = np.random.default_rng(np.random.SeedSequence(seed).spawn(n + 1)[-1])
    demos = []
    for i in range(len(data)):
        hand = data.observed_arm.hand(data.observed(i))
        if noise > 0:
            hand = hand + noise * rng.standard_normal(hand.shape)
        demos.append(np.hstack([hand, data.controlled(i)]))
    times = [np.arange(len(d)) * data.dt for d in demos]
    return Demonstrations(demos=demos, times=times, columns=list(RECORDING_COLUMNS), dt=data.dt,
                          observed_dofs=[0, 1], name="simulated high five", source=f"highfive_recordings(seed={seed})")

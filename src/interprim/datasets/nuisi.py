"""Loader for the NuiSI human-human interaction data set.

Source: NuiSI dataset v1 (Nuitrack Skeleton Interaction dataset) by V. Prasad, D. Koert,
R. Stock-Homburg, J. Peters and G. Chalvatzaki, "MILD: Multimodal Interactive Latent
Dynamics for Learning Human-Robot Interaction", Humanoids 2022.  Licence AGPL-3.0.
The data is read from a path; it is never copied into this package.

Each demonstration holds two skeletons (10 joints, x/y/z in metres, each in its own torso
frame) tracked at low, irregular rates (agent 1 about 8-11 Hz, agent 2 about 6 Hz) on one
shared clock.  :func:`load_nuisi` pairs the two agents by time stamp: both are linearly
interpolated onto one uniform grid over the time span where both were tracked.
"""

from __future__ import annotations

import numpy as np

from ..core.errors import DataFileError
from ..core.preprocessing import interp_columns, step_grid
from ._base import Demonstrations, RawStream, resolve_data_path

__all__ = ["load_nuisi", "nuisi_actions", "NUISI_JOINTS", "JOINT_GROUPS", "NUISI_DEFAULT_PATH"]

#: Path of the NuiSI file relative to the data folder (see :func:`interprim.datasets.data_dir`).
NUISI_DEFAULT_PATH = "nuisi_v1/nuisi_v1_segmented.npz"

#: Joint order of the data set (axis 1 of ``agent1``/``agent2``).
NUISI_JOINTS = (
    "head", "neck", "torso", "waist",
    "left_shoulder", "left_elbow", "left_hand",
    "right_shoulder", "right_elbow", "right_hand",
)  # fmt: skip

#: Named groups of joints accepted by ``observed=``/``controlled=``.  ``upper_body`` leaves out
#: ``torso`` and ``waist``, which barely move in the agent's own torso frame.
JOINT_GROUPS = {
    "all": NUISI_JOINTS,
    "upper_body": (
        "head", "neck", "left_shoulder", "left_elbow", "left_hand",
        "right_shoulder", "right_elbow", "right_hand",
    ),
    "arms": ("left_shoulder", "left_elbow", "left_hand", "right_shoulder", "right_elbow", "right_hand"),
    "right_arm": ("right_shoulder", "right_elbow", "right_hand"),
    "left_arm": ("left_shoulder", "left_elbow", "left_hand"),
    "right_hand": ("right_hand",),
    "left_hand": ("left_hand",),
}  # fmt: skip


def _open(path):
    p = resolve_data_path(path, NUISI_DEFAULT_PATH, "NuiSI")
    try:
        data = np.load(p, allow_pickle=False)
    except Exception as exc:  # noqa: BLE001 - any failure to open is a bad file
        raise DataFileError(f"{p}: not a readable NuiSI .npz file ({exc})") from None
    if "joints" not in data.files:
        raise DataFileError(f"{p}: no 'joints' key; is this the NuiSI segmented .npz file?")
    return p, data


def _index(data):
    """{action: sorted list of demo numbers} from the keys ``{action}/{nn}/agent1``."""
    out: dict = {}
    for k in data.files:
        parts = k.split("/")
        if len(parts) == 3 and parts[2] == "agent1":
            out.setdefault(parts[0], []).append(parts[1])
    return {a: sorted(v, key=int) for a, v in sorted(out.items())}


def nuisi_actions(path=None) -> dict:
    """The interactions in the NuiSI file and how many demonstrations each has.

    Parameters
    ----------
    path : str or Path, optional
        The ``.npz`` file (or the folder holding it); defaults to
        ``<data>/nuisi_v1/nuisi_v1_segmented.npz``.

    Returns
    -------
    dict
        ``{action: n_demos}``, e.g. ``{"highfive1": 30, ...}``.
    """
    _, data = _open(path)
    with data:
        return {a: len(v) for a, v in _index(data).items()}


def _joints(spec, what: str) -> tuple:
    if spec is None:
        return ()
    if isinstance(spec, str):
        if spec in JOINT_GROUPS:
            return tuple(JOINT_GROUPS[spec])
        spec = [s.strip() for s in spec.split(",") if s.strip()]
    out: list = []
    for j in spec:
        if j in JOINT_GROUPS and j not in NUISI_JOINTS:
            out.extend(JOINT_GROUPS[j])
        elif j in NUISI_JOINTS:
            out.append(j)
        else:
            raise ValueError(
                f"{what}: unknown joint or group {j!r}; joints: {', '.join(NUISI_JOINTS)}; "
                f"groups: {', '.join(JOINT_GROUPS)}"
            )
    if len(set(out)) != len(out):
        raise ValueError(f"{what}: joint listed twice in {spec!r}")
    return tuple(out)


def _interp(t_src, y, t_new):
    out = interp_columns(t_new, t_src, y.reshape(y.shape[0], -1))
    return out.reshape((t_new.shape[0],) + y.shape[1:])


def load_nuisi(
    path=None,
    action: str = "highfive1",
    *,
    observed="upper_body",
    controlled="right_hand",
    dt: float = 0.05,
    demos=None,
) -> Demonstrations:
    """Load one interaction of the NuiSI data set as paired, uniformly resampled demonstrations.

    Agent 1 is the observed human, agent 2 the partner whose movement a robot should learn
    to produce.  For every demonstration both agents' frames are linearly interpolated onto
    the grid ``t0, t0 + dt, ...`` covering ``[t0, t1]``, the span in which *both* agents were
    tracked (``t0`` = the later first time stamp, ``t1`` = the earlier last one).  No
    smoothing is applied here (the tracking is noisy: smooth before differentiating, e.g.
    with ``InteractionPrimitive(smoothing_window=...)``).

    Parameters
    ----------
    path : str or Path, optional
        ``nuisi_v1_segmented.npz`` (or the folder holding it).  Defaults to
        ``<data>/nuisi_v1/nuisi_v1_segmented.npz`` with ``<data>`` from
        :func:`interprim.datasets.data_dir` (``$INTERPRIM_DATA`` or ``../shared/data``).
    action : str
        Interaction key, one of :func:`nuisi_actions` (``highfive1``, ``handshake2``,
        ``fistbump2``, ``clapfist2``, ``rocket1``, ``wave1``).
    observed : str or sequence of str
        Joints of agent 1 to include (the observed agent): a group name from
        :data:`JOINT_GROUPS` (default ``"upper_body"``: head, neck, both shoulders, elbows
        and hands, 8 joints = 24 columns) or a list of joint names.
    controlled : str or sequence of str or None
        Joints of agent 2 to include (default ``"right_hand"``, 3 columns; ``"right_arm"``
        gives 9).  ``None`` loads agent 1 only.
    dt : float
        Resampling interval in seconds (default 0.05 s = 20 Hz, about twice agent 1's
        rate and three times agent 2's, so interpolation adds frames but loses none).
    demos : sequence of int, optional
        Demonstration numbers to load (default all).

    Returns
    -------
    Demonstrations
        ``demos``: one ``(T_i, D)`` array per demonstration, columns
        ``agent1_<joint>_<x|y|z>`` for the observed joints then ``agent2_<joint>_<x|y|z>``;
        ``times``: grid times in seconds from the start of the overlap; ``dt``;
        ``observed_dofs``: the agent-1 column indices; ``labels``: demo numbers; ``raw``: each agent's
        recorded samples (:class:`~interprim.datasets.RawStream`, on the grid's clock), from which an
        evaluation builds causal prefixes.

    Raises
    ------
    DataNotFoundError
        If the file does not exist.
    DataFileError
        If the file is not the NuiSI file or a demonstration is malformed.
    ValueError
        For an unknown action or joint, or a non-positive ``dt``.
    """
    if not (isinstance(dt, (int, float)) and np.isfinite(dt) and dt > 0):
        raise ValueError(f"dt must be a positive number of seconds, got {dt!r}")
    j1 = _joints(observed, "observed")
    j2 = _joints(controlled, "controlled")
    if not j1:
        raise ValueError("observed must name at least one joint of agent 1")
    p, data = _open(path)
    with data:
        index = _index(data)
        if action not in index:
            raise ValueError(f"unknown NuiSI action {action!r}; available: {', '.join(index)}")
        file_joints = [str(j) for j in data["joints"]]
        if tuple(file_joints) != NUISI_JOINTS:
            raise DataFileError(f"{p}: unexpected joint list {file_joints}")
        i1 = [NUISI_JOINTS.index(j) for j in j1]
        i2 = [NUISI_JOINTS.index(j) for j in j2]
        numbers = index[action]
        if demos is not None:
            wanted = [f"{int(n):02d}" for n in demos]
            missing = [w for w in wanted if w not in numbers]
            if missing:
                raise ValueError(f"{action} has no demonstration(s) {missing}; it has {numbers[0]}..{numbers[-1]}")
            numbers = wanted
        out, times, raw = [], [], []
        for nn in numbers:
            key = f"{action}/{nn}"
            try:
                a1, t1 = data[f"{key}/agent1"], data[f"{key}/t1"]
                a2, t2 = data[f"{key}/agent2"], data[f"{key}/t2"]
            except KeyError as exc:
                raise DataFileError(f"{p}: demonstration {key} is incomplete ({exc})") from None
            for name, a, t in (("agent1", a1, t1), ("agent2", a2, t2)):
                if a.ndim != 3 or a.shape[1:] != (10, 3) or t.shape != (a.shape[0],):
                    raise DataFileError(f"{p}: {key}/{name} has shape {a.shape} with times {t.shape}")
                if not np.all(np.isfinite(a)) or not np.all(np.isfinite(t)):
                    raise DataFileError(f"{p}: {key}/{name} contains NaN or inf")
                if np.any(np.diff(t) <= 0):
                    r = int(np.argmax(np.diff(t) <= 0)) + 1
                    raise DataFileError(f"{p}: {key}/{name} time stamps do not increase at row {r}")
            origin = max(t1[0], t2[0])
            end = min(t1[-1], t2[-1])
            if end - origin < 2 * dt:
                raise DataFileError(f"{p}: in {key} the two agents overlap for only {end - origin:.3f} s")
            grid = step_grid(end - origin, dt)
            n = grid.shape[0]
            cols = [_interp(t1 - origin, a1[:, i1, :], grid).reshape(n, -1)]
            streams = [RawStream(t1 - origin, tuple(range(3 * len(i1))), a1[:, i1, :].reshape(len(t1), -1))]
            if i2:
                cols.append(_interp(t2 - origin, a2[:, i2, :], grid).reshape(n, -1))
                streams.append(RawStream(t2 - origin, tuple(range(3 * len(i1), 3 * (len(i1) + len(i2)))),
                                         a2[:, i2, :].reshape(len(t2), -1)))
            out.append(np.ascontiguousarray(np.concatenate(cols, axis=1)))
            times.append(grid)
            raw.append(streams)
    columns = [f"agent1_{j}_{c}" for j in j1 for c in "xyz"] + [f"agent2_{j}_{c}" for j in j2 for c in "xyz"]
    return Demonstrations(
        demos=out,
        times=times,
        columns=columns,
        dt=float(dt),
        observed_dofs=list(range(3 * len(j1))),
        name=action,
        source=str(p),
        labels=list(numbers),
        raw=raw,
    )

"""Shared pieces of the data loaders: the :class:`Demonstrations` container and data paths."""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..core.errors import DataFileError

__all__ = ["Demonstrations", "RawStream", "DataNotFoundError", "data_dir", "resolve_data_path", "sampling", "Sampling",
           "UNIFORM_TOLERANCE"]

#: Environment variable naming the folder that holds the shared data sets
#: (``nuisi_v1/``, ``character_trajectories/``).
DATA_ENV = "INTERPRIM_DATA"


class DataNotFoundError(DataFileError, FileNotFoundError):
    """A data set file or folder does not exist (both a :class:`DataFileError` and a ``FileNotFoundError``)."""


@dataclass(frozen=True)
class RawStream:
    """Samples of some columns as they were recorded, before interpolation onto a uniform grid.

    Parameters
    ----------
    times : ndarray, shape (M,)
        Strictly increasing time stamps in seconds, on the clock of the demonstration's ``times``.
    columns : tuple of int
        The demonstration's columns these samples hold.
    values : ndarray, shape (M, len(columns))
        The recorded values.
    """

    times: np.ndarray
    columns: tuple
    values: np.ndarray

    def select(self, idx) -> RawStream:
        """The same samples re-indexed for the column selection ``idx`` (columns not selected are dropped)."""
        pos = {c: k for k, c in enumerate(idx)}
        keep = [j for j, c in enumerate(self.columns) if c in pos]
        return RawStream(self.times, tuple(pos[self.columns[j]] for j in keep), self.values[:, keep])


@dataclass
class Demonstrations(Sequence):
    """A set of demonstrations with their time stamps and column names.

    It behaves like a read-only list of the ``(T_i, D)`` arrays, so it can be
    passed where a list of demonstrations is expected; ``demos`` is that list.

    Parameters
    ----------
    demos : list of ndarray, shape (T_i, D)
        The demonstrations, time on axis 0, one column per degree of freedom.
    times : list of ndarray, shape (T_i,)
        Time stamps in seconds, strictly increasing within each demonstration.
    columns : list of str
        Name of each of the ``D`` columns.
    dt : float or None
        The common sampling interval in seconds when every demonstration is
        uniformly sampled with the same interval (up to 1 % jitter and the
        rounding of the written stamps: :func:`sampling`), else ``None`` (then
        use ``times``).
    observed_dofs : list of int or None
        Indices of the columns that belong to the observed agent, when the
        source says so (NuiSI, or an ``observed`` entry in a file).
    name : str
        What the set is (an action, a letter, a shape, a file name).
    source : str
        Where it was loaded from.
    labels : list of str
        One identifier per demonstration (demo number, file name, ...).
    units : list of (str or None) or None
        The unit of each column when the source says it (``"m"`` for motion-capture
        markers converted from the file's unit, ``"rad"`` for joint angles, ``""`` for
        unitless quaternion components); ``None`` for a column (or for the whole set)
        whose unit is not known.
    raw : list of (list of RawStream) or None
        What was recorded, before any interpolation onto ``times``: per demonstration, the raw
        sample streams (:class:`RawStream`, time stamps on the clock of ``times``) that the
        interpolated columns were made from.  ``None`` when the demonstrations are the recorded
        samples themselves.  An evaluation builds a causal prefix from them
        (:func:`interprim.model_selection.prefixes.causal_prefix`): interpolating over the whole
        recording lets a frame near the end of a prefix depend on a raw sample after it.
    notes : list of str
        What the reader decided for the user to know (e.g. the unit it took for a time column).
    """

    demos: list
    times: list
    columns: list
    dt: float | None = None
    observed_dofs: list | None = None
    name: str = ""
    source: str = ""
    labels: list = field(default_factory=list)
    units: list | None = None
    raw: list | None = None
    notes: list = field(default_factory=list)

    def __post_init__(self):
        if not self.labels:
            self.labels = [f"{i:03d}" for i in range(len(self.demos))]
        if self.units is not None and len(self.units) != len(self.columns):
            raise ValueError(f"units has {len(self.units)} entries for {len(self.columns)} columns")
        if self.raw is not None and len(self.raw) != len(self.demos):
            raise ValueError(f"raw has {len(self.raw)} entries for {len(self.demos)} demonstrations")

    # -- sequence protocol -------------------------------------------------
    def __len__(self) -> int:
        return len(self.demos)

    def __getitem__(self, i):
        return self.demos[i]

    def __iter__(self):
        return iter(self.demos)

    def __repr__(self) -> str:
        lengths = [d.shape[0] for d in self.demos]
        rng = f"{min(lengths)}-{max(lengths)} frames" if lengths else "empty"
        return (
            f"Demonstrations(name={self.name!r}, n={len(self.demos)}, D={self.n_dofs}, {rng}, "
            f"dt={self.dt!r}, observed_dofs={self.observed_dofs!r})"
        )

    # -- conveniences ------------------------------------------------------
    @property
    def n_dofs(self) -> int:
        """Number of columns ``D``."""
        return len(self.columns)

    @property
    def controlled_dofs(self) -> list | None:
        """Indices of the columns not in ``observed_dofs`` (``None`` when that is unknown)."""
        if self.observed_dofs is None:
            return None
        obs = set(self.observed_dofs)
        return [i for i in range(self.n_dofs) if i not in obs]

    def column_indices(self, names) -> list:
        """Indices of ``names`` (column names or integer indices) in ``columns``.

        Raises
        ------
        DataFileError
            If a name is not a column or an index is out of range.
        """
        return select_columns(self.columns, names, where=self.source or self.name or "demonstrations")

    def take(self, indices) -> Demonstrations:
        """A new set holding only the demonstrations ``indices`` (in that order), with their time stamps,
        labels and raw samples (a hold-out split keeps causal prefixes).

        Raises
        ------
        IndexError
            If an index is out of range.
        """
        idx = [int(i) for i in indices]
        n = len(self.demos)
        bad = [i for i in idx if not -n <= i < n]
        if bad:
            raise IndexError(f"demonstration index {bad[0]} out of range for {n} demonstrations")
        return Demonstrations(
            demos=[self.demos[i] for i in idx],
            times=[self.times[i] for i in idx],
            columns=list(self.columns),
            dt=self.dt,
            observed_dofs=None if self.observed_dofs is None else list(self.observed_dofs),
            name=self.name,
            source=self.source,
            labels=[self.labels[i] for i in idx],
            units=None if self.units is None else list(self.units),
            raw=None if self.raw is None else [self.raw[i] for i in idx],
        )

    def select(self, names) -> Demonstrations:
        """A new set holding only the columns ``names`` (in that order)."""
        idx = self.column_indices(names)
        obs = None
        if self.observed_dofs is not None:
            pos = {c: k for k, c in enumerate(idx)}
            obs = [pos[i] for i in self.observed_dofs if i in pos]
        return Demonstrations(
            demos=[np.ascontiguousarray(d[:, idx]) for d in self.demos],
            times=[t.copy() for t in self.times],
            columns=[self.columns[i] for i in idx],
            dt=self.dt,
            observed_dofs=obs,
            name=self.name,
            source=self.source,
            labels=list(self.labels),
            units=None if self.units is None else [self.units[i] for i in idx],
            raw=None if self.raw is None else [[r.select(idx) for r in streams] for streams in self.raw],
            notes=list(self.notes),
        )


def shown_names(names, n: int = 12) -> str:
    """The first ``n`` of ``names`` for a message, with how many there are in all when there are more."""
    names = [str(x) for x in names]
    if len(names) <= n:
        return ", ".join(names)
    return ", ".join(names[:n]) + f", ... ({len(names)} in all)"


def select_columns(columns, names, where: str) -> list:
    """Map column names or integer indices (or a comma-separated string) to indices into ``columns``."""
    if isinstance(names, str):
        names = [n.strip() for n in names.split(",") if n.strip()]
    out = []
    pos: dict | None = None  # name -> index, built once (linear in the number of columns)
    for n in names:
        if isinstance(n, (int, np.integer)) and not isinstance(n, bool):
            i = int(n)
            if not -len(columns) <= i < len(columns):
                raise DataFileError(f"{where}: column index {i} is out of range (there are {len(columns)} columns)")
            out.append(i % len(columns))
            continue
        s = str(n).strip()
        if pos is None:
            pos = {}
            for k, c in enumerate(columns):
                pos.setdefault(str(c), k)
        if s in pos:
            out.append(pos[s])
        elif s.lstrip("-").isdigit():
            out.extend(select_columns(columns, [int(s)], where))
        else:
            raise DataFileError(f"{where}: unknown column {s!r}; the columns are: {shown_names(columns)}")
    if len(set(out)) != len(out):
        raise DataFileError(f"{where}: a column is selected twice in {list(names)!r}")
    return out


def _candidates() -> list:
    cands = []
    env = os.environ.get(DATA_ENV)
    if env:
        return [Path(env).expanduser()]
    here = Path(__file__).resolve()
    for parent in here.parents:
        if (parent / "pyproject.toml").is_file():
            cands.append(parent.parent / "shared" / "data")
            break
    cands.append(Path.cwd().parent / "shared" / "data")
    cands.append(Path.cwd() / ".." / "shared" / "data")
    return cands


def data_dir() -> Path:
    """The folder holding the shared data sets.

    Resolved as ``$INTERPRIM_DATA`` when that environment variable is set,
    otherwise ``../shared/data`` beside the project checkout (the repository
    root is the folder with ``pyproject.toml`` above this module), otherwise
    ``../shared/data`` relative to the working directory.

    Raises
    ------
    DataNotFoundError
        If none of these folders exists.
    """
    cands = _candidates()
    for c in cands:
        if c.is_dir():
            return c.resolve()
    tried = ", ".join(str(c) for c in cands)
    raise DataNotFoundError(
        f"the data folder was not found (tried {tried}); set the environment variable {DATA_ENV} "
        "to the folder holding nuisi_v1/ and character_trajectories/, or pass the file path explicitly"
    )


def resolve_data_path(path, default_relative: str, what: str) -> Path:
    """Return ``path`` (or the default file under :func:`data_dir`) after checking that it exists."""
    if path is None:
        p = data_dir() / default_relative
    else:
        p = Path(path).expanduser()
        if p.is_dir() and (p / Path(default_relative).name).is_file():
            p = p / Path(default_relative).name
        elif p.is_dir() and (p / default_relative).is_file():
            p = p / default_relative
    if not p.exists():
        raise DataNotFoundError(f"{what} file not found: {p}")
    if p.is_dir():
        raise DataFileError(f"{what}: expected a file, got the folder {p}")
    return p


#: Time stamps count as uniformly sampled when each lies within this fraction of the interval of one
#: uniform grid, plus the rounding of the decimals they are written with (see :func:`sampling`).
UNIFORM_TOLERANCE = 0.01
#: The rounding of the written decimals is accepted only up to this fraction of the interval (coarser
#: rounding, e.g. 10 Hz stamps written with one decimal, must not hide a dropped frame).
ROUNDING_CAP = 0.25


@dataclass
class Sampling:
    """How far a set of time stamps is from uniform sampling (the result of :func:`sampling`).

    Attributes
    ----------
    dt : float or None
        The common sampling interval (s) when the stamps are uniform by the rule of
        :func:`sampling`, else ``None``.
    interval : float
        The interval of the uniform grid the stamps were compared with (the given one, or the
        least-squares fit of all demonstrations together); ``nan`` when it cannot be told.
    deviation : float
        The largest distance (s) of a stamp from that grid (for stamps that are not uniform: from
        the grid through most of them, at ``demo``, ``frame``).
    tolerance : float
        The largest distance accepted: ``UNIFORM_TOLERANCE * interval`` plus ``rounding``.
    rounding : float
        Half a unit of the last decimal the stamps are written with (``0.0005`` for
        ``0.033, 0.067, ...``); 0 when they are not written with 9 decimals or fewer, or when
        that is more than :data:`ROUNDING_CAP` (a quarter) of the interval.
    demo, frame : int
        Where the largest deviation is (demonstration index, frame index).
    intervals : list of float
        Each demonstration's own interval (least squares), to tell different rates apart.
    """

    dt: float | None
    interval: float
    deviation: float
    tolerance: float
    rounding: float
    demo: int = 0
    frame: int = 0
    intervals: list = field(default_factory=list)

    @property
    def uniform(self) -> bool:
        """Whether the stamps are uniform within the tolerance."""
        return self.dt is not None

    def describe(self, labels=None) -> str:
        """One sentence saying how the stamps deviate from uniform sampling (empty when they do not)."""
        if self.uniform:
            return ""
        if not np.isfinite(self.interval):
            return "a demonstration has fewer than 2 time stamps, so its sampling interval cannot be told"
        name = (lambda i: repr(labels[i])) if labels is not None and len(labels) == len(self.intervals) else str
        iv = self.intervals
        if len(iv) > 1 and min(iv) > 0 and (max(iv) - min(iv)) > UNIFORM_TOLERANCE * min(iv):
            lo, hi = int(np.argmin(iv)), int(np.argmax(iv))
            return (
                f"the demonstrations have different sampling intervals (demonstration {name(lo)}: "
                f"{iv[lo]:.6g} s, demonstration {name(hi)}: {iv[hi]:.6g} s)"
            )
        return (
            f"the time stamps are not uniform: demonstration {name(self.demo)}, frame {self.frame} is "
            f"{self.deviation * 1e3:.3g} ms ({100 * self.deviation / self.interval:.3g} % of the interval) off a "
            f"uniform grid of {self.interval:.6g} s; accepted are {100 * UNIFORM_TOLERANCE:g} % of the interval"
            + (f" plus the rounding of the written decimals ({self.rounding * 1e3:.3g} ms)" if self.rounding else "")
        )


def _rounding(times) -> float:
    """Half a unit of the last decimal (up to 9) that every stamp is written with, or 0."""
    for k in range(10):
        scale = 10.0**k
        if all(np.all(np.abs(t * scale - np.round(t * scale)) <= 1e-6 * np.maximum(1.0, np.abs(t * scale) * 1e-9))
               for t in times):
            return 0.5 / scale
    return 0.0


def sampling(times, dt=None, tol: float = UNIFORM_TOLERANCE) -> Sampling:
    """Whether time stamps are uniformly sampled at one interval: the rule every reader and command uses.

    The stamps of every demonstration are compared with a uniform grid ``t0_i + k * dt`` (``dt``
    given, or fitted by least squares to all demonstrations together; ``t0_i`` chosen per
    demonstration to centre its deviations).  They count as uniform when no stamp is further from
    its grid than ``tol * dt`` plus the rounding of the decimals they are written with (half a unit
    of the last decimal, counted when at most a quarter of ``dt``: stamps of a 30 Hz recording written
    as ``0.033, 0.067, 0.1, ...`` are uniform at ``dt = 1/30``).

    Parameters
    ----------
    times : list of ndarray, shape (T_i,)
        Time stamps (s) of each demonstration, strictly increasing.
    dt : float, optional
        The interval to compare with (e.g. a model's); default the least-squares interval.
    tol : float
        Accepted jitter as a fraction of the interval (default :data:`UNIFORM_TOLERANCE`, 1 %).

    Returns
    -------
    Sampling
        ``dt`` is the interval when uniform (the given one, or the fitted one), else ``None``;
        :meth:`Sampling.describe` says by how much the stamps deviate.
    """
    ts = [np.asarray(t, dtype=np.float64) for t in times]
    nan = float("nan")
    if not ts or any(len(t) < 2 for t in ts):
        return Sampling(None, nan, nan, nan, 0.0, intervals=[])
    intervals, num, den = [], 0.0, 0.0
    for t in ts:
        k = np.arange(len(t)) - (len(t) - 1) / 2.0
        a, b = float(k @ (t - t.mean())), float(k @ k)
        intervals.append(a / b)
        num, den = num + a, den + b
    step = float(dt) if dt is not None else num / den
    rounding = _rounding(ts)
    if rounding > ROUNDING_CAP * abs(step):  # so coarse that it could hide a dropped frame: not counted
        rounding = 0.0
    allowed = tol * abs(step) + rounding
    worst, shown, where = -1.0, 0.0, (0, 0)
    for i, t in enumerate(ts):
        r = t - np.arange(len(t)) * step
        half_range = float(r.max() - r.min()) / 2.0  # the distance to the best grid (offset at mid-range)
        if half_range > worst:
            off = r - np.median(r)  # where it deviates: the stamp furthest from the grid through most stamps
            j = int(np.argmax(np.abs(off)))
            worst, shown, where = half_range, float(abs(off[j])), (i, j)
    ok = step > 0 and worst <= allowed * (1 + 1e-9) + 1e-12
    return Sampling(step if ok else None, step, worst if ok else shown, allowed, rounding, where[0], where[1],
                    intervals)


def uniform_dt(times, rtol: float = UNIFORM_TOLERANCE):
    """The common sampling interval of a list of time-stamp arrays, or ``None`` if not uniform (:func:`sampling`)."""
    return sampling(times, tol=rtol).dt

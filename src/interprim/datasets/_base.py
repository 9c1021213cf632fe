"""Shared pieces of the data loaders: the :class:`Demonstrations` container and data paths."""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import DataFileError

__all__ = ["Demonstrations", "RawStream", "DataNotFoundError", "data_dir", "resolve_data_path"]

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

    def select(self, idx) -> "RawStream":
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
        uniformly sampled with the same interval, else ``None`` (then use
        ``times``).
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
        (:func:`interprim.evaluation.protocol.causal_prefix`): interpolating over the whole
        recording lets a frame near the end of a prefix depend on a raw sample after it.
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

    def select(self, names) -> "Demonstrations":
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
        )


def select_columns(columns, names, where: str) -> list:
    """Map column names or integer indices (or a comma-separated string) to indices into ``columns``."""
    if isinstance(names, str):
        names = [n.strip() for n in names.split(",") if n.strip()]
    out = []
    for n in names:
        if isinstance(n, (int, np.integer)) and not isinstance(n, bool):
            i = int(n)
            if not -len(columns) <= i < len(columns):
                raise DataFileError(f"{where}: column index {i} is out of range (there are {len(columns)} columns)")
            out.append(i % len(columns))
            continue
        s = str(n).strip()
        if s in columns:
            out.append(list(columns).index(s))
        elif s.lstrip("-").isdigit() and s not in columns:
            out.extend(select_columns(columns, [int(s)], where))
        else:
            raise DataFileError(
                f"{where}: unknown column {s!r}; the columns are: {', '.join(map(str, columns))}"
            )
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


def uniform_dt(times, rtol: float = 1e-6):
    """The common sampling interval of a list of time-stamp arrays, or ``None`` if not uniform."""
    dts = []
    for t in times:
        if len(t) < 2:
            return None
        d = np.diff(t)
        med = float(np.median(d))
        if med <= 0 or np.max(np.abs(d - med)) > rtol * med + 1e-12:
            return None
        dts.append(med)
    if not dts:
        return None
    ref = dts[0]
    if any(abs(x - ref) > 1e-6 * ref for x in dts):
        return None
    return float(np.mean(dts))

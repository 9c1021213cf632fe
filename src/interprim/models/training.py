"""The one validated training set every model family learns from, and the adapter that builds it.

A family never reads demonstrations itself: :meth:`interprim.models.base.Predictor.fit` turns what the user gave (a
list of ``(T, D)`` arrays with ``dt`` or ``times``, or a :class:`~interprim.datasets.Demonstrations`) into a
:class:`TrainingSet` once, with :func:`training_set`, and hands it to the family's ``_fit``.  A set of recordings
with irregular time stamps is resampled there, once, at the median interval, so every family sees the recorded
durations.  A cross-validation takes folds of a set with :meth:`TrainingSet.take`, which does not validate again.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..core.preprocessing import resample_uniform
from ..core.validation import as_demonstrations, check_positive, check_times

__all__ = ["TrainingSet", "training_set", "uniform_demonstrations", "pace_trend", "DEFAULT_DT", "PACE_P",
           "PACE_CHANGE"]

#: Sampling interval (s) assumed for plain arrays given without ``dt``.
DEFAULT_DT = 0.01
#: :func:`pace_trend` calls a trend significant below this p-value of the rank correlation ...
PACE_P = 0.05
#: ... when the last third's mean duration differs from the first third's by at least this fraction (together: on
#: 10-30 durations drawn independently with a spread of 5-10 %, 0-6 % of the sets are called significant).
PACE_CHANGE = 0.08


@dataclass(frozen=True, eq=False)
class TrainingSet(Sequence):
    """Validated demonstrations on a uniform grid: what every family's ``_fit`` receives.

    It behaves like a read-only list of the ``(T_i, D)`` arrays (``len``, indexing, iteration), so code written
    for a list of demonstrations takes it as it is.  Build one with :func:`training_set`; every array is a
    read-only, C-contiguous float64 ``(T_i, D)`` array with finite values and the same ``D``.

    Attributes
    ----------
    arrays : tuple of ndarray, shape (T_i, D)
        The demonstrations, time on axis 0, sampled every ``dt`` seconds.
    dt : float
        Sampling interval in seconds.
    columns : tuple of str or None
        The ``D`` column names, when known.
    observed_dofs : tuple of int or None
        The observed agent's columns, when the source says so (a family uses its own ``observed_dofs``).
    times : tuple of ndarray or None
        Time stamps of the frames when the source had them on this grid (a :class:`~interprim.datasets.Demonstrations`
        with a common interval; with ``raw``, they place the causal prefixes).
    raw : tuple or None
        Per demonstration, the raw sample streams the grid was interpolated from
        (:class:`~interprim.datasets.RawStream`); :class:`~interprim.model_selection.prefixes.Prefixes` builds causal
        prefixes from them.  ``None`` when the arrays are the recorded samples themselves.
    resampled : bool
        Whether the adapter resampled irregular time stamps onto the grid.
    """

    arrays: tuple[np.ndarray, ...]
    dt: float
    columns: tuple[str, ...] | None = None
    observed_dofs: tuple[int, ...] | None = None
    times: tuple[np.ndarray, ...] | None = None
    raw: tuple[Any, ...] | None = None
    resampled: bool = False

    def __len__(self) -> int:
        return len(self.arrays)

    def __getitem__(self, j):
        if isinstance(j, slice):
            return list(self.arrays[j])
        return self.arrays[j]

    @property
    def demos(self) -> list[np.ndarray]:
        """The arrays as a list (the attribute name of :class:`~interprim.datasets.Demonstrations`)."""
        return list(self.arrays)

    @property
    def n_dofs(self) -> int:
        """Columns ``D`` of every demonstration."""
        return int(self.arrays[0].shape[1])

    @property
    def lengths(self) -> np.ndarray:
        """Frames ``T_i`` of each demonstration."""
        return np.array([a.shape[0] for a in self.arrays], dtype=np.intp)

    @property
    def durations(self) -> np.ndarray:
        """Duration ``(T_i - 1) dt`` of each demonstration in seconds."""
        return np.array([(a.shape[0] - 1) * self.dt for a in self.arrays], dtype=np.float64)

    def frames(self, columns) -> np.ndarray:
        """All frames of ``columns``, the demonstrations one after the other, shape ``(sum T_i, len(columns))``."""
        cols = [int(i) for i in columns]
        return np.concatenate([a[:, cols] for a in self.arrays])

    def take(self, indices) -> TrainingSet:
        """The demonstrations ``indices`` only (renumbered from 0), without validating them again (a fold)."""
        idx = [int(i) for i in np.asarray(indices, dtype=np.intp).ravel()]
        bad = [i for i in idx if not 0 <= i < len(self.arrays)]
        if bad:
            raise IndexError(f"take: demonstrations {bad} out of range for a set of {len(self.arrays)}")
        return TrainingSet(tuple(self.arrays[i] for i in idx), self.dt, self.columns, self.observed_dofs,
                           None if self.times is None else tuple(self.times[i] for i in idx),
                           None if self.raw is None else tuple(self.raw[i] for i in idx), self.resampled)


def _frozen(a: np.ndarray) -> np.ndarray:
    a = np.ascontiguousarray(a, dtype=np.float64)
    if a.flags.writeable:
        a = a.view()
        a.setflags(write=False)
    return a


def training_set(demos, dt: float | None = None, times=None, columns=None) -> TrainingSet:
    """The adapter: the one place demonstrations and their time stamps are read and validated.

    Parameters
    ----------
    demos : TrainingSet, Demonstrations, list of array_like or ndarray (n, T, D)
        A :class:`TrainingSet` is returned as it is (``dt``, ``times`` and ``columns`` must then be ``None`` or
        agree with it).  A :class:`~interprim.datasets.Demonstrations` gives its ``dt`` (or, with irregular stamps,
        ``times``), column names, ``observed_dofs`` and raw samples unless given here.
    dt : float, optional
        Sampling interval in seconds of uniformly sampled arrays (default :data:`DEFAULT_DT`).
    times : list of array_like, shape (T_i,), optional
        Time stamps in seconds per demonstration (irregular sampling): the arrays are resampled linearly onto a
        grid at the median interval of all stamps, so the durations are the recorded ones.  Not with ``dt``.
    columns : list of str, optional
        Names of the ``D`` columns.

    Returns
    -------
    TrainingSet

    Raises
    ------
    TypeError, ValueError
        Naming the demonstration, frame and column at fault (a non-finite value, a width unlike ``demos[0]``'s,
        stamps that do not increase, ...).
    """
    if isinstance(demos, TrainingSet):
        if dt is not None and float(dt) != demos.dt:
            raise ValueError(f"dt={dt} differs from the training set's dt={demos.dt}")
        if times is not None:
            raise ValueError("times: a TrainingSet is already on its uniform grid; pass None")
        if columns is not None and [str(c) for c in columns] != list(demos.columns or []):
            raise ValueError("columns differ from the training set's column names")
        return demos
    observed = None
    raw = None
    stamps = None
    if hasattr(demos, "demos") and hasattr(demos, "times"):  # interprim.datasets.Demonstrations
        if columns is None:
            columns = getattr(demos, "columns", None)
        observed = getattr(demos, "observed_dofs", None)
        if times is None and (dt is None or dt == getattr(demos, "dt", None)):
            if getattr(demos, "dt", None) is not None:
                dt = demos.dt
                stamps = demos.times
                raw = getattr(demos, "raw", None)
            else:
                times = list(demos.times)
        demos = list(demos.demos)
    if isinstance(demos, np.ndarray) and demos.ndim == 3:
        demos = list(demos)
    if not isinstance(demos, (list, tuple)):
        raise TypeError(f"demos must be a list of (T, D) arrays, got {type(demos).__name__}")
    arrays = as_demonstrations(demos, fit=True)
    D = arrays[0].shape[1]
    if columns is not None:
        columns = tuple(str(c) for c in columns)
        if len(columns) != D:
            raise ValueError(f"columns has {len(columns)} names but the demonstrations have {D} columns")
    resampled = False
    if times is not None:
        if dt is not None:
            raise ValueError("give either dt or times, not both")
        if len(times) != len(arrays):
            raise ValueError(f"times has {len(times)} entries but there are {len(arrays)} demos")
        ts = [check_times(t, a.shape[0], f"times[{j}]") for j, (t, a) in enumerate(zip(times, arrays))]
        dt = float(np.median(np.concatenate([np.diff(t) for t in ts])))
        arrays = [resample_uniform(a, t, dt=dt)[0] for a, t in zip(arrays, ts)]
        resampled = True
    dt = DEFAULT_DT if dt is None else check_positive(dt, "dt")
    return TrainingSet(tuple(_frozen(a) for a in arrays), float(dt), columns,
                       None if observed is None else tuple(int(i) for i in observed),
                       None if stamps is None else tuple(np.asarray(t, dtype=np.float64) for t in stamps),
                       None if raw is None else tuple(raw), resampled)


def uniform_demonstrations(demos, dt: float | None = None):
    """``(arrays, dt, columns)`` of :func:`training_set` (a list of the arrays and a list of the names, or
    ``None``), for code that wants plain lists."""
    data = training_set(demos, dt)
    return list(data.arrays), data.dt, None if data.columns is None else list(data.columns)


def pace_trend(durations: Sequence[float]) -> dict[str, Any] | None:
    """How the demonstrations' durations change with their order: people repeating an interaction speed up or slow
    down over a session (on NuiSI's fist bump the last third of the development recordings is 13 % shorter than
    the first).

    Parameters
    ----------
    durations : sequence of float
        Each demonstration's duration (s), in the order given.

    Returns
    -------
    dict or None
        ``n`` (the demonstrations), ``rho`` and ``p`` (Spearman's rank correlation of duration with position and
        its two-sided p-value), ``first``, ``last`` (the mean duration of the first and the last third, s),
        ``change`` (``last / first - 1``) and ``significant`` (``p < PACE_P`` and ``|change| >= PACE_CHANGE``);
        None for fewer than 6 demonstrations or equal durations (no trend to measure).
    """
    from scipy.stats import spearmanr

    d = np.asarray(durations, dtype=np.float64).ravel()
    if d.size < 6 or not np.all(np.isfinite(d)) or np.ptp(d) <= 0.0:
        return None
    rho, p = spearmanr(np.arange(d.size), d)
    third = max(1, d.size // 3)
    first, last = float(np.mean(d[:third])), float(np.mean(d[-third:]))
    change = last / first - 1.0 if first > 0 else float("nan")
    return {"n": int(d.size), "rho": float(rho), "p": float(p), "first": first, "last": last, "change": float(change),
            "significant": bool(p < PACE_P and abs(change) >= PACE_CHANGE)}


"""Is an observation like the training demonstrations?  The out-of-range check of predict, Stream and server.

A partial observation in millimetres given to a model trained in metres, a wrong column order or another frame
of reference is still "a partial observation": conditioning (Eq. 16-18) would extrapolate without a word and the
robot would be sent to (343.9, 277.9) rad.  The check is the largest standardised distance
``max_{t,i} |x_ti - mean_i| / std_i`` of the observed frames from the training frames' per-column mean and std,
against a limit of 3x the largest such distance within the training frames themselves (at least 8): held-out
demonstrations of every built-in data set stay below 2x, a change of units (x10 and more) is far above.

Two columns of similar range given in the wrong order can stay below the limit (the tutorial's data: 7.1 against
8).  A distance with the training columns' correlations (Mahalanobis) would flag that swap at 4.3x the training
frames' largest, but held-out NuiSI recordings reach 4.2x (fistbump2, 24 observed columns): no limit separates
them, so the check does not claim to catch a column order.
"""

from __future__ import annotations

import threading
import warnings
from typing import Any, Protocol, TypeVar

import numpy as np
from numpy.typing import ArrayLike

from .errors import OutOfRangeWarning

__all__ = ["fit_input_range", "input_distance", "mark", "mark_duration", "duration_range", "DURATION_FACTOR",
           "CHECKED_BY_CALLER", "checked_by_caller"]

#: A predicted duration longer than this many times the longest demonstration, or shorter than the shortest
#: divided by it, is out of range (``Prediction.duration_out_of_range``): demonstrations of one interaction at
#: natural speeds differ by less (NuiSI: 1.7-2.7 s, 1.6x), a prediction 2.4x the longest does not follow them.
DURATION_FACTOR = 1.5


class _Checks(threading.local):
    """Per thread: how many callers around the current call check the input themselves."""

    depth = 0


_CHECKS = _Checks()


class _CheckedByCaller:
    """The context of :data:`CHECKED_BY_CALLER`."""

    __slots__ = ()

    def __enter__(self) -> None:
        _CHECKS.depth += 1

    def __exit__(self, *exc: object) -> None:
        _CHECKS.depth -= 1


#: ``with CHECKED_BY_CALLER:`` the models called inside skip their own input checks: :func:`input_distance` is NaN,
#: :func:`mark` and :func:`mark_duration` leave the prediction as it is and never warn, and the streams' running
#: checks (:class:`interprim.models.base.InputMarks`) do nothing.  For a wrapper that marks the prediction it
#: returns itself, after the call (:class:`interprim.models.auto.AutoInteraction`, a checked stream): the one
#: warning is its own, and the inner models' checks, whose results it overwrites, are not computed.  Per thread (a
#: prediction in another thread checks as usual), unlike suppressing the warnings with
#: :func:`warnings.catch_warnings`, which changes the process's filters.
CHECKED_BY_CALLER = _CheckedByCaller()


def checked_by_caller() -> bool:
    """Whether a caller around this call checks the input itself (inside :data:`CHECKED_BY_CALLER`)."""
    return _CHECKS.depth > 0



class _DurationMarked(Protocol):
    """What :func:`mark_duration` sets on a prediction of any family."""

    duration_out_of_range: bool


class _Marked(_DurationMarked, Protocol):
    """What :func:`mark` sets on a prediction of any family (and :func:`mark_duration`, which it calls)."""

    input_distance: float
    out_of_range: bool


_D = TypeVar("_D", bound=_DurationMarked)
_P = TypeVar("_P", bound=_Marked)


def fit_input_range(frames: ArrayLike) -> tuple[np.ndarray, np.ndarray, float]:
    """``(mean, std, limit)`` of the observed agent's training frames ``(n, D_o)`` (data columns)."""
    f = np.asarray(frames, dtype=np.float64)
    mean = f.mean(axis=0)
    sd = f.std(axis=0)
    std = np.where(sd > 0, sd, max(float(sd.max()), 1e-12))
    train = float(np.max(np.abs(f - mean) / std))
    return mean, std, max(3.0 * train, 8.0)


def input_distance(model: Any, frames: ArrayLike) -> float:
    """Largest standardised distance of frames ``(t, D_o)`` from ``model``'s training frames; NaN for a model
    (file) without the statistics, or inside :data:`CHECKED_BY_CALLER`."""
    if _CHECKS.depth:
        return float("nan")
    mean = getattr(model, "input_mean_", None)
    if mean is None:
        return float("nan")
    f = np.asarray(frames, dtype=np.float64)
    return float(np.max(np.abs(f - mean) / model.input_std_)) if f.size else 0.0


def duration_range(model: Any) -> tuple[float, float] | None:
    """``(shortest, longest)`` demonstrated duration (s) of ``model`` (its own ``durations_``, those of the model
    it wraps or of its members), ``(mean, mean)`` when only the mean is known, ``None`` when nothing is."""
    seen: set[int] = set()
    todo: list[Any] = [model]
    while todo:
        obj = todo.pop(0)
        if obj is None or id(obj) in seen:
            continue
        seen.add(id(obj))
        d = getattr(obj, "durations_", None)
        if d is not None and np.size(d):
            d = np.asarray(d, dtype=np.float64)
            return float(d.min()), float(d.max())
        todo.append(getattr(obj, "model_", None))
        members = getattr(obj, "members_", None)
        if isinstance(members, dict):
            todo.extend(members.values())
    mean = getattr(model, "mean_duration_", None)
    if mean is not None and np.isfinite(mean) and mean > 0:
        return float(mean), float(mean)
    return None


#: ``span`` not given: :func:`mark_duration` reads it (:func:`duration_range`)
_READ: Any = object()


def mark_duration(model: Any, prediction: _D, span: Any = _READ) -> _D:
    """Set ``prediction.duration_out_of_range``: its duration is more than :data:`DURATION_FACTOR` times the
    longest demonstration, or less than the shortest divided by it (flagged as the input range is); nothing inside
    :data:`CHECKED_BY_CALLER`.  ``span``: ``duration_range(model)`` when the caller has it already (a stream reads it
    once)."""
    if _CHECKS.depth:
        return prediction
    if span is _READ:
        span = duration_range(model)
    duration = float(getattr(prediction, "duration", float("nan")))
    prediction.duration_out_of_range = bool(span is not None and np.isfinite(duration) and (
        duration > DURATION_FACTOR * span[1] or duration < span[0] / DURATION_FACTOR))
    return prediction


def mark(model: Any, prediction: _P, dist: float, warn: bool = True, span: Any = _READ) -> _P:
    """Set ``prediction.input_distance`` / ``out_of_range`` and warn (:class:`~interprim.core.errors.OutOfRangeWarning`)
    at the caller's line: the first frame outside interprim, however many of the library's calls lie between.
    Nothing inside :data:`CHECKED_BY_CALLER` (the caller marks the prediction itself).  ``span``: as
    :func:`mark_duration` takes it."""
    if _CHECKS.depth:
        return prediction
    prediction.input_distance = dist
    limit = getattr(model, "input_limit_", None)
    prediction.out_of_range = bool(limit is not None and dist > limit)
    mark_duration(model, prediction, span)
    if prediction.out_of_range and warn:
        import inspect

        level, f = 1, inspect.currentframe()  # stacklevel 1 is this function
        while f is not None and str(f.f_globals.get("__name__", "")).split(".")[0] == "interprim":
            f, level = f.f_back, level + 1
        warnings.warn(OutOfRangeWarning(
            f"the observed frames are {dist:.3g} standard deviations from the training demonstrations' mean "
            f"(limit {limit:.3g}): wrong units, column order or frame of reference? The prediction "
            "extrapolates (Prediction.out_of_range is True)"), stacklevel=level)
    return prediction

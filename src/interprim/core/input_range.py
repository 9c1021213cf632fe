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

import warnings
from typing import Any, Protocol, TypeVar

import numpy as np
from numpy.typing import ArrayLike

from .errors import OutOfRangeWarning

__all__ = ["fit_input_range", "input_distance", "mark"]



class _Marked(Protocol):
    """What :func:`mark` sets on a prediction of any family."""

    input_distance: float
    out_of_range: bool


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
    (file) without the statistics."""
    mean = getattr(model, "input_mean_", None)
    if mean is None:
        return float("nan")
    f = np.asarray(frames, dtype=np.float64)
    return float(np.max(np.abs(f - mean) / model.input_std_)) if f.size else 0.0


def mark(model: Any, prediction: _P, dist: float, warn: bool = True) -> _P:
    """Set ``prediction.input_distance`` / ``out_of_range`` and warn (:class:`~interprim.core.errors.OutOfRangeWarning`)
    at the caller's line: the first frame outside interprim, however many of the library's calls lie between."""
    prediction.input_distance = dist
    limit = getattr(model, "input_limit_", None)
    prediction.out_of_range = bool(limit is not None and dist > limit)
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

"""Input validation shared by the public API (clear messages, never silent)."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike


def as_2d_finite(a: ArrayLike, name: str, n_cols: int | None = None, min_rows: int = 1) -> np.ndarray:
    """Return ``a`` as a C-contiguous float64 ``(T, D)`` array or raise a clear error.

    Parameters
    ----------
    a : array_like
        The array to check.
    name : str
        How the argument is called in messages (e.g. ``"demos[3]"``).
    n_cols : int, optional
        Required number of columns.
    min_rows : int
        Minimum number of rows (time steps).
    """
    if a is None:
        raise TypeError(f"{name} must be an array of shape (T, D), got None")
    try:
        arr = np.asarray(a, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"{name} must be a numeric array of shape (T, D): {exc}") from None
    if arr.ndim == 1 and n_cols is not None and n_cols == 1:
        arr = arr[:, None]
    if arr.ndim != 2:
        raise ValueError(f"{name} must be 2-D with shape (T, D) (time on axis 0), got shape {arr.shape}")
    if n_cols is not None and arr.shape[1] != n_cols:
        raise ValueError(f"{name} has {arr.shape[1]} columns, expected {n_cols}")
    if arr.shape[0] < min_rows:
        raise ValueError(f"{name} has {arr.shape[0]} frames, at least {min_rows} are needed")
    bad = ~np.isfinite(arr)
    if bad.any():
        row, col = np.argwhere(bad)[0]
        raise ValueError(
            f"{name} contains {int(bad.sum())} non-finite value(s) (NaN or inf); first at frame {row}, column {col}"
        )
    return np.ascontiguousarray(arr)


def as_demonstrations(demos: Any, min_rows: int = 1, name: str = "demos", fit: bool = False) -> list[np.ndarray]:
    """Return ``demos`` (a sequence of ``(T_j, D)`` arrays) as validated float64 arrays of one width, or raise a
    clear error: each checked by :func:`as_2d_finite` (``demos[j]`` in messages, at least ``min_rows`` frames), at
    least one, all with the first one's number of columns; ``fit``: no value beyond :data:`MAX_ABS_VALUE`."""
    arrays = [as_2d_finite(d, f"{name}[{j}]", min_rows=min_rows) for j, d in enumerate(demos)]
    if not arrays:
        raise ValueError(f"{name} is empty: at least one demonstration is needed")
    D = arrays[0].shape[1]
    for j, a in enumerate(arrays):
        if a.shape[1] != D:
            raise ValueError(f"{name}[{j}] has {a.shape[1]} columns but {name}[0] has {D}")
        big = np.abs(a) > MAX_ABS_VALUE if fit else None
        if big is not None and big.any():  # the sums of its squares would overflow: every spread becomes inf/NaN
            row, col = np.argwhere(big)[0]
            raise ValueError(f"{name}[{j}] holds {a[row, col]:.3g} at frame {row}, column {col}: beyond the "
                             f"{MAX_ABS_VALUE:.0e} the fit's sums of squares can hold (wrong units?)")
    return arrays


#: the largest magnitude a demonstration's value may have: the sums of squares of 10^8 such values stay finite
MAX_ABS_VALUE = 1e100


def check_min_frames(arrays: Any, min_frames: int, name: str = "demos") -> None:
    """Raise ``ValueError("demos[j] has T frames; at least min_frames are needed")`` for the first of the
    (validated) ``arrays`` with fewer than ``min_frames`` frames (rows)."""
    for j, a in enumerate(arrays):
        if a.shape[0] < min_frames:
            raise ValueError(f"{name}[{j}] has {a.shape[0]} frames; at least {min_frames} are needed")


def as_frame(frame: ArrayLike, name: str, n_cols: int) -> np.ndarray:
    """Check a single frame of ``n_cols`` finite values."""
    try:
        arr = np.asarray(frame, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"{name} must be a numeric array of shape ({n_cols},): {exc}") from None
    if arr.ndim == 2 and arr.shape[0] == 1:
        arr = arr[0]
    if arr.shape != (n_cols,):
        raise ValueError(f"{name} must have shape ({n_cols},) (one value per observed DoF), got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains NaN or inf: {arr.tolist()}")
    return arr


def check_times(times: ArrayLike, n_rows: int, name: str) -> np.ndarray:
    """Check time stamps: 1-D, one per frame, finite and strictly increasing."""
    t = np.asarray(times, dtype=np.float64)
    if t.ndim != 1 or t.shape[0] != n_rows:
        raise ValueError(f"{name} must have shape ({n_rows},) (one time stamp per frame), got shape {t.shape}")
    if not np.all(np.isfinite(t)):
        raise ValueError(f"{name} contains NaN or inf")
    d = np.diff(t)
    if np.any(d <= 0):
        i = int(np.argmax(d <= 0))
        raise ValueError(
            f"{name} must be strictly increasing; t[{i + 1}]={t[i + 1]!r} does not follow t[{i}]={t[i]!r}"
        )
    return t


def check_positive(value: Any, name: str) -> float:  # any user input
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be a positive number, got {value!r}") from None
    if not np.isfinite(v) or v <= 0:
        raise ValueError(f"{name} must be a positive finite number, got {value!r}")
    return v

"""Checks shared by every reader of demonstration files (CSV/NPZ in :mod:`.files`, C3D, BVH, ROS bags): gaps of
missing values, time stamps, lengths."""

from __future__ import annotations

import numpy as np

from ..core.errors import DataFileError


def fill_nans(y, max_nan_gap, where, row_of):
    """Interpolate interior NaN runs of at most ``max_nan_gap`` frames; reject any other NaN."""
    bad = np.isnan(y)
    if not bad.any():
        return y
    y = y.copy()
    for d in range(y.shape[1]):
        col = bad[:, d]
        if not col.any():
            continue
        i = 0
        T = col.shape[0]
        while i < T:
            if not col[i]:
                i += 1
                continue
            j = i
            while j < T and col[j]:
                j += 1
            run = j - i
            if run == T:  # empty everywhere: not a gap at the start or end
                raise DataFileError(f"{where(d)}: no value in any of its {T} frames; leave it out (columns=, "
                                    "markers=, joints=)")
            if run > max_nan_gap or i == 0 or j == T:
                why = (
                    "missing value(s)"
                    if max_nan_gap == 0
                    else ("a run of missing values at the start or end" if (i == 0 or j == T)
                          else f"a run of {run} missing values (max_nan_gap={max_nan_gap})")
                )
                edge = i == 0 or j == T  # interpolation cannot fill a run at the start or end
                raise DataFileError(
                    f"{where(d)}: {why} starting at {row_of(i)} ({run} frame(s)); fill or cut them"
                    + ("" if edge else f", or interpolate interior gaps of up to {run} frames with max_nan_gap={run}")
                )
            y[i:j, d] = np.interp(np.arange(i, j), [i - 1, j], [y[i - 1, d], y[j, d]])
            i = j
    return y


def check_stamps(t, where, row_of):
    if not np.all(np.isfinite(t)):
        i = int(np.argmax(~np.isfinite(t)))
        raise DataFileError(f"{where}: missing or non-finite time at {row_of(i)}")
    d = np.diff(t)
    if np.any(d <= 0):
        i = int(np.argmax(d <= 0)) + 1
        raise DataFileError(
            f"{where}: time must be strictly increasing, but {row_of(i)} has time {float(t[i])!r} "
            f"after {float(t[i - 1])!r}"
        )


def warn(message, category):
    """``warnings.warn`` attributed to the first caller outside interprim (the user's line, not a reader's)."""
    import sys
    import warnings

    level, f = 2, sys._getframe(1)  # stacklevel 1 is this function, 2 its caller
    while f is not None and str(f.f_globals.get("__name__", "")).split(".")[0] == "interprim":
        f, level = f.f_back, level + 1
    warnings.warn(message, category, stacklevel=level)


def check_frames(n, min_frames, where):
    if n < min_frames:
        raise DataFileError(f"{where}: only {n} frame(s), at least {min_frames} are needed")


# --------------------------------------------------------------------------- CSV

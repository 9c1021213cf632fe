"""Checks shared by every reader of demonstration files (CSV/NPZ in :mod:`.files`, C3D, BVH, ROS bags): gaps of
missing values, time stamps, lengths."""

from __future__ import annotations

import math

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


def check_column_names(names, where):
    """Refuse column names that no file written from them can hold: none at all, an empty name, or one with a
    comma or a line break (the CSV files written from the demonstrations, e.g. a prediction, would be corrupt)."""
    if not len(names):
        raise DataFileError(f"{where}: no data columns (0 columns)")
    for j, name in enumerate(names):
        text = str(name)
        if not text.strip():
            raise DataFileError(f"{where}: column {j} has an empty name")
        bad = next((c for c in (",", "\n", "\r") if c in text), None)
        if bad is not None:
            what = "a comma" if bad == "," else "a line break"
            raise DataFileError(f"{where}: column {j} name {text[:80]!r} holds {what}; column names must not "
                                "(they are written to CSV headers)")


def number(text: str) -> float:
    """``float(text)``, but ``ValueError`` for the underscores Python's ``float`` accepts (``1_0`` is 10): a cell of a
    data file with one is not a number."""
    if "_" in text:
        raise ValueError(f"could not convert string to float: {text!r}")
    return float(text)


def whole_number(text: str):
    """``text`` as an ``int`` when it is a finite whole number (``"12"``, ``"12.0"``), else ``None``."""
    try:
        v = number(text.strip())
    except ValueError:
        return None
    if not math.isfinite(v) or v != int(v):
        return None
    return int(v)


def first_bad_utf8(path):
    """``(line, byte offset)`` (1-based line) of the first byte of ``path`` that is not UTF-8, or ``None``; read in
    blocks (only called after a ``UnicodeDecodeError``, to name where)."""
    import codecs

    dec = codecs.getincrementaldecoder("utf-8")()
    line, offset = 1, 0
    with open(path, "rb") as fh:
        while True:
            block = fh.read(1 << 20)
            if not block:
                return None
            try:
                dec.decode(block)
            except UnicodeDecodeError as exc:  # exc.start counts from the start of the bytes the decoder held
                held = len(exc.object) - len(block)
                pos = exc.start - held
                return line + block[:max(pos, 0)].count(b"\n"), offset + pos
            line += block.count(b"\n")
            offset += len(block)


def not_utf8(path, what):
    """The :class:`DataFileError` of a text file with a byte that is not UTF-8, naming its line and offset."""
    where = first_bad_utf8(path)
    at = f" (line {where[0]}, byte {where[1]})" if where else ""
    return DataFileError(f"{path}: not a {what} text file: a byte that is not UTF-8{at}; export it as UTF-8 text")


def check_frames(n, min_frames, where):
    if n < min_frames:
        raise DataFileError(f"{where}: only {n} frame(s), at least {min_frames} are needed")


# --------------------------------------------------------------------------- CSV


#: Most frames one demonstration may have after ``resample_dt`` (checked before the grid is allocated).
MAX_RESAMPLED_FRAMES = 10_000_000
#: Most values (frames times columns) one demonstration may have after ``resample_dt`` (2 GiB of float64).
MAX_RESAMPLED_VALUES = 1 << 28


def check_grid(n: int, n_cols: int, duration: float, dt: float, min_frames: int | None, where: str) -> None:
    """Refuse a resampling grid of ``n`` frames (``resample_dt=dt`` over ``duration`` s) before it is allocated: more
    than :data:`MAX_RESAMPLED_FRAMES` frames (or :data:`MAX_RESAMPLED_VALUES` values), or fewer than ``min_frames``."""
    if n > MAX_RESAMPLED_FRAMES or n * max(n_cols, 1) > MAX_RESAMPLED_VALUES:
        raise DataFileError(
            f"{where}: resample_dt={dt!r} s over its {duration:.6g} s gives {duration / dt + 1:.3g} frames of "
            f"{n_cols} columns, over the limit of {MAX_RESAMPLED_FRAMES:g} frames ({MAX_RESAMPLED_VALUES:g} values) "
            "for one demonstration; choose a larger resample interval (seconds)")
    if min_frames is not None and n < min_frames:
        raise DataFileError(
            f"{where}: resample_dt={dt!r} s over its {duration:.6g} s leaves only {n} frame(s), at least {min_frames} "
            "are needed; choose a smaller resample interval (seconds)")

"""Cutting one long recording into demonstrations: the one splitting rule of every reader.

:func:`spans` turns start markers, explicit ranges and pauses into intervals; the ROS-bag reader
(:mod:`.ros_bags`) calls it on time stamps in nanoseconds, the motion-capture readers (:mod:`.mocap_c3d`,
:mod:`.mocap_bvh`) through :func:`split_take` on frame indices.
"""

from __future__ import annotations

import numpy as np

from ..core.errors import DataFileError

__all__ = ["spans", "split_take", "parse_ranges", "PAUSE_SPEED"]

#: In a motion-capture take, a frame is *still* when every column moves slower than this fraction of the
#: take's 95th-percentile speed (speeds measured over :data:`SPEED_WINDOW` seconds).
PAUSE_SPEED = 0.05
#: Seconds over which the speed of a motion-capture take is measured for pauses (smooths marker noise).
SPEED_WINDOW = 0.1


def spans(lo, hi, starts=(), cuts=(), ranges=None) -> list:
    """Intervals ``[a, b]`` (inclusive) of the demonstrations in ``[lo, hi]``.

    Parameters
    ----------
    lo, hi : int
        The first and last position of the recording (a frame index, or a time in ns).
    starts : sequence of int
        Start markers: each starts a demonstration that lasts until the next one (the last until
        ``hi``); the recording before the first marker is not used.
    cuts : sequence of (int, int)
        Pauses ``(c0, c1)``: a demonstration ends at ``c0`` and the next starts at ``c1``.
    ranges : sequence of (int, int), optional
        Explicit intervals (instead of ``lo..hi`` or ``starts``); pauses still cut them.

    Returns
    -------
    list of (int, int)
    """
    if ranges is not None:
        segs = [(max(int(a), lo), min(int(b), hi)) for a, b in ranges]
        segs = [(a, b) for a, b in segs if b >= a]
    elif len(starts):
        bounds = sorted(int(s) for s in starts)
        bounds.append(max(hi, bounds[-1]) + 1)
        segs = [(a, b - 1) for a, b in zip(bounds[:-1], bounds[1:]) if b > a]
    else:
        segs = [(lo, hi)]
    if len(cuts):
        cuts = sorted((int(a), int(b)) for a, b in cuts)
        out = []
        for a, b in segs:
            cur = a
            for c0, c1 in cuts:
                if c1 <= cur or c0 >= b:
                    continue
                if c0 >= cur:
                    out.append((cur, c0))
                cur = max(cur, c1)
            if cur <= b:
                out.append((cur, b))
        segs = out
    return segs


def parse_ranges(text, where: str, first: int, last: int) -> list:
    """``"A-B,C-D"`` (inclusive frame numbers) as ``[(A, B), (C, D)]``, checked against ``first..last``."""
    if isinstance(text, str):
        items = [x.strip() for x in text.split(",") if x.strip()]
    else:
        items = list(text)
    out = []
    for item in items:
        if isinstance(item, str):
            a, sep, b = item.partition("-")
            try:
                a, b = int(a), int(b)
            except ValueError:
                raise DataFileError(f"{where}: split_frames {item!r} is not a frame range FIRST-LAST") from None
            if not sep:
                raise DataFileError(f"{where}: split_frames {item!r} is not a frame range FIRST-LAST")
        else:
            a, b = (int(v) for v in item)
        if not first <= a <= b <= last:
            raise DataFileError(
                f"{where}: split_frames {a}-{b} is not inside the recording's frames {first}-{last}"
            )
        out.append((a, b))
    if not out:
        raise DataFileError(f"{where}: split_frames names no frame range")
    return out


def _pauses(y, rate, gap):
    """Runs of frames (``(first, last)`` indices) longer than ``gap`` s in which the take is still or missing."""
    T = y.shape[0]
    w = max(1, int(round(SPEED_WINDOW * rate)))
    missing = np.isnan(y).any(axis=1)
    speed = np.full(T, np.nan)
    if T > w:
        d = np.abs(y[w:] - y[:-w]).max(axis=1) * rate / w  # NaN where a frame of the pair is missing
        h = w // 2  # centred on the window
        speed[h:h + T - w] = d
        speed[:h], speed[h + T - w:] = d[0], d[-1]
    ok = np.isfinite(speed)
    ref = np.percentile(speed[ok], 95) if ok.any() else 0.0
    quiet = missing | (ok & (speed <= PAUSE_SPEED * ref))
    n_min = gap * rate
    runs, i = [], 0
    while i < T:
        if not quiet[i]:
            i += 1
            continue
        j = i
        while j < T and quiet[j]:
            j += 1
        if j - i > n_min:
            runs.append((i, j - 1))
        i = j
    return runs


def split_take(y, rate, numbers, *, where: str, trim=False, events=None, ranges=None, gap=None) -> list:
    """Row intervals ``(i0, i1)`` (inclusive) of the demonstrations in one motion-capture take.

    Parameters
    ----------
    y : ndarray, shape (T, D)
        The take, ``nan`` where a marker or channel is missing.
    rate : float
        Frames per second.
    numbers : ndarray of int, shape (T,)
        Each row's frame number as the file numbers it (shown in messages, used by ``ranges``).
    where : str
        The file (for messages).
    trim : bool
        Drop the leading and trailing frames of each demonstration in which a column is missing
        (a marker written as 0,0,0 or with a negative residual, a ``nan`` channel).
    events : sequence of int, optional
        Row indices at which a demonstration starts (the C3D file's events).
    ranges : str or sequence, optional
        Frame ranges ``"A-B,C-D"`` (inclusive, in the file's frame numbers).
    gap : float, optional
        Seconds: a pause longer than this starts a new demonstration.  A pause is a run of frames in which
        every column moves slower than :data:`PAUSE_SPEED` times the take's 95th-percentile speed, or
        in which a column is missing.

    Returns
    -------
    list of (int, int)
    """
    T = y.shape[0]
    rows = None
    if ranges is not None:
        rng = parse_ranges(ranges, where, int(numbers[0]), int(numbers[-1]))
        rows = [(a - int(numbers[0]), b - int(numbers[0])) for a, b in rng]
    cuts = []
    if gap is not None:
        if not (np.isfinite(gap) and gap > 0):
            raise ValueError(f"split_gap must be a positive number of seconds, got {gap!r}")
        cuts = [(a - 1, b + 1) for a, b in _pauses(y, rate, gap)]
    if events is not None and not len(events):
        raise DataFileError(f"{where}: no event inside the recording to split at (split_events)")
    segs = spans(0, T - 1, starts=events or (), cuts=cuts, ranges=rows)
    if not segs:
        raise DataFileError(f"{where}: nothing is left between the pauses (split_gap={gap})")
    if trim:
        bad = np.isnan(y).any(axis=1)
        out = []
        for a, b in segs:
            while a <= b and bad[a]:
                a += 1
            while b >= a and bad[b]:
                b -= 1
            if a > b:
                continue
            out.append((a, b))
        if not out:
            raise DataFileError(f"{where}: every frame has a missing value; trimming leaves nothing")
        segs = out
    return segs


def cut_take(path, y, t, numbers, split, *, max_nan_gap, min_frames, where_col, row_of):
    """One motion-capture take as demonstrations: split (:func:`split_take`), gaps filled, lengths checked.

    ``split`` holds ``trim``, ``events`` (row indices or None), ``ranges`` and ``gap``; ``where_col(d)``
    names column ``d`` and ``row_of(i)`` row ``i`` of the take in messages.  Returns ``(demos, times,
    labels)``: one demonstration per interval, time stamps from 0, labels ``<file>@<start>s`` when the
    take is split (the file's name otherwise).
    """
    from ._checks import _check_frames, _fill_nans

    rate = 1.0 / float(t[1] - t[0]) if len(t) > 1 else 1.0
    splitting = split.get("events") is not None or split.get("ranges") is not None or split.get("gap") is not None
    if splitting or split.get("trim"):
        segs = split_take(y, rate, numbers, where=str(path), trim=bool(split.get("trim")), events=split.get("events"),
                          ranges=split.get("ranges"), gap=split.get("gap"))
    else:
        segs = [(0, y.shape[0] - 1)]
    demos, times, labels = [], [], []
    for a, b in segs:
        where = str(path) if not splitting else f"{path}, frames {numbers[a]}-{numbers[b]}"
        hint = " (a larger split_gap, fewer events or longer split_frames?)" if splitting and len(segs) > 1 else ""
        _check_frames(b - a + 1, min_frames, where + hint)
        piece = _fill_nans(y[a:b + 1], max_nan_gap, where_col, lambda i, _a=a: row_of(_a + i))
        demos.append(piece)
        times.append(t[a:b + 1] - t[a])
        labels.append(f"{path.stem}@{t[a]:.3f}s" if splitting else path.stem)
    return demos, times, labels

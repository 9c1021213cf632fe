"""Cutting one long recording into demonstrations: the one splitting rule of every reader.

:func:`spans` turns start markers, explicit ranges and pauses into intervals; the ROS-bag reader
(:mod:`.ros_bags`) calls it on time stamps in nanoseconds, the motion-capture readers (:mod:`.mocap_c3d`,
:mod:`.mocap_bvh`) through :func:`split_take` on frame indices.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..core.errors import DataFileError

__all__ = ["spans", "split_take", "parse_ranges", "find_repetitions", "PAUSE_SPEED"]

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
            first_text, sep, last_text = item.partition("-")
            try:
                a, b = int(first_text), int(last_text)
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


#: A repetition is found when the take's autocorrelation at the period is at least this (1: exactly periodic).
MIN_PERIODICITY = 0.3


def _filled(y):
    """``y`` with missing values interpolated per column (for measuring the take, not for the demonstrations),
    centred and divided by one overall scale; columns that are all missing are left out."""
    z = np.array(y, dtype=np.float64)
    keep = ~np.all(np.isnan(z), axis=0)
    z = z[:, keep]
    idx = np.arange(z.shape[0])
    for d in range(z.shape[1]):
        bad = np.isnan(z[:, d])
        if bad.any():
            z[bad, d] = np.interp(idx[bad], idx[~bad], z[~bad, d])
    z -= z.mean(axis=0)
    # one scale for all columns (not one per column): a marker that barely moves must not weigh its noise as
    # much as the movement of the others
    rms = float(np.sqrt(np.mean(z**2))) if z.size else 0.0
    return z / rms if rms > 0 else z[:, :0]


#: Fewest frames of one repetition (a found or given period).
MIN_PERIOD_FRAMES = 4
#: The period is the first autocorrelation peak at least this share of the highest one: the highest peak of a
#: periodic take may be at any multiple of its period (each multiple is as periodic), the first is the period.
PEAK_SHARE = 0.9


def _period(z, rate, where):
    """The period (frames) of a repeating movement: after the autocorrelation's first dip below 0, the first peak
    within :data:`PEAK_SHARE` of the highest (the fundamental, not a multiple of it)."""
    T = z.shape[0]
    n = 1 << int(np.ceil(np.log2(2 * T)))
    f = np.fft.rfft(z, n, axis=0)
    ac = np.fft.irfft((f * np.conj(f)).real.sum(axis=1), n)[:T]
    ac = ac / (T - np.arange(T))  # each lag's mean product
    ac = ac / ac[0]
    below = np.flatnonzero(ac[: T // 2 + 1] < 0)
    if not below.size:
        raise DataFileError(f"{where}: split_repetitions found no repeating movement (the take never moves away "
                            "from its first poses for long); give the period in seconds, or use split_frames")
    lo = int(below[0])
    seg = ac[lo:T // 2 + 1]
    best = float(seg.max())
    level = PEAK_SHARE * best if best > 0 else best  # (a take without a positive peak is refused below)
    first = int(np.flatnonzero(seg >= level)[0])  # the first lag near the highest peak's height
    end = first
    while end + 1 < len(seg) and seg[end + 1] >= level:  # the first such lobe ...
        end += 1
    P = lo + first + int(np.argmax(seg[first:end + 1]))  # ... and its top
    if ac[P] < MIN_PERIODICITY or P < MIN_PERIOD_FRAMES:
        raise DataFileError(
            f"{where}: split_repetitions found no repeating movement (best period {P / rate:.3g} s, autocorrelation "
            f"{ac[P]:.2f} < {MIN_PERIODICITY}; at least two repetitions are needed); give the period in seconds, or "
            "use split_frames or split_gap"
        )
    return P, float(ac[P])


def _slow_moment(speed, P):
    """The middle of the slowest moment of the first period of ``speed``: of the runs of frames slower than
    10 % of the range above the minimum, the one with the lowest speed among those that start in the first
    ``P`` frames and are not cut by either end of ``speed`` (a run cut by an end has an unknown middle)."""
    low = speed <= speed.min() + 0.1 * (speed.max() - speed.min())
    runs, i, n = [], 0, len(speed)
    while i < n:
        if not low[i]:
            i += 1
            continue
        j = i
        while j + 1 < n and low[j + 1]:
            j += 1
        runs.append((i, j))
        i = j + 1
    inside = [(a, b) for a, b in runs if a > 0 and b < n - 1 and a < P] or [(a, b) for a, b in runs if a < P] or runs
    a, b = min(inside, key=lambda r: speed[r[0]:r[1] + 1].min())
    return (a + b) // 2


def find_repetitions(y, rate, *, where: str, period=None):
    """Row intervals ``(i0, i1)`` of the repetitions of one movement in a continuous take, and a note.

    The period is the highest peak of the take's autocorrelation (all columns, centred) after it first
    drops below zero, or ``period`` seconds when given.  The first cut is the slowest frame of the first period
    (a landing, the pause between two serves); each next cut is the frame, between 0.6 and 1.4 periods after
    the previous one, whose surroundings (a window of a quarter period) best match those of the first cut
    (least squares).  The partial movements before the first cut and after the last are left out.
    """
    from numpy.lib.stride_tricks import sliding_window_view

    z = _filled(y)
    T = z.shape[0]
    if z.shape[1] == 0 or T < 8:
        raise DataFileError(f"{where}: split_repetitions needs a take that moves ({T} frames)")
    if period is None:
        P, corr = _period(z, rate, where)
        how = f"autocorrelation {corr:.2f}"
    else:
        if not (np.isfinite(period) and period > 0):
            raise DataFileError(f"split_repetitions must be True or a positive period in seconds (finite), got "
                                f"{period!r}")
        if period * rate < MIN_PERIOD_FRAMES - 0.5:  # not clamped: a period this short is a wrong number or unit
            raise DataFileError(
                f"{where}: split_repetitions period {period:g} s is {period * rate:.3g} frames at {rate:.4g} Hz; a "
                f"repetition needs at least {MIN_PERIOD_FRAMES} frames ({MIN_PERIOD_FRAMES / rate:.3g} s): give the "
                "period in seconds")
        P, how = int(round(period * rate)), "given"
        if 2 * P > T:
            raise DataFileError(f"{where}: split_repetitions period {period} s ({P} frames) leaves less than two "
                                f"repetitions in {T} frames")
    speed = np.linalg.norm(np.gradient(z, axis=0), axis=1)  # centred differences: no half-frame shift
    k = max(1, P // 10)
    speed = np.convolve(speed, np.ones(k) / k, mode="same")
    w = max(2, P // 8)
    c0 = w + _slow_moment(speed[w:min(T - w, w + 2 * P)], P)
    win = sliding_window_view(z, 2 * w + 1, axis=0)  # (T - 2w, D, 2w + 1): window centred on frame i + w
    template = win[c0 - w]
    cuts = [c0]
    while True:
        a, b = cuts[-1] + int(0.6 * P), min(cuts[-1] + int(np.ceil(1.4 * P)), T - 1 - w)
        if a > b:
            break
        cost = ((win[a - w:b - w + 1] - template) ** 2).sum(axis=(1, 2))
        best = a + int(np.argmin(cost))
        if best == b and b < cuts[-1] + int(np.ceil(1.4 * P)):
            break  # the best match is where the take ends: the true cut may lie beyond it
        cuts.append(best)
    segs = [(c, d - 1) for c, d in zip(cuts[:-1], cuts[1:])]
    if not segs:
        raise DataFileError(f"{where}: split_repetitions found less than one whole repetition (period "
                            f"{P / rate:.3g} s)")
    note = (f"{where}: split_repetitions: period {P / rate:.3g} s ({how}), {len(segs)} repetitions cut at the frames "
            f"most like the slowest frame of the first; left out: the partial movement before row {segs[0][0]} and "
            f"after row {segs[-1][1]}")
    return segs, note


def split_take(y, rate, numbers, *, where: str, trim=False, events=None, ranges=None, gap=None,
               repetitions=None, notes=None, keep_partial=False, names=None) -> list:
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
    repetitions : True or float, optional
        Cut a continuous take into the repetitions of one movement (:func:`find_repetitions`); a float is
        the period in seconds.  Applied to each piece left by the other options.
    notes : list, optional
        Receives what the repetition finder decided (period, cuts) and what was left out, for the user.
    keep_partial : bool
        With ``events``: also keep the piece after the last event (by default left out, and said in
        ``notes``: it is not a whole cycle).
    names : sequence of str, optional
        The columns' names (for messages).

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
            raise DataFileError(f"split_gap must be a positive number of seconds, got {gap!r}")
        cuts = [(a - 1, b + 1) for a, b in _pauses(y, rate, gap)]
    if events is not None and not len(events):
        raise DataFileError(f"{where}: no event inside the recording to split at (split_events)")
    segs = spans(0, T - 1, starts=events or (), cuts=cuts, ranges=rows)
    if events is not None and len(segs) > 1 and not keep_partial:
        # the piece after the last event runs to the end of the recording, not to a next event: not a whole cycle
        last = max(int(e) for e in events)
        tail = [(a, b) for a, b in segs if a >= last]
        if tail:
            a, b = tail[0]
            segs = [s_ for s_ in segs if s_[0] < last]
            if notes is not None:
                notes.append(f"{where}: split_events: the piece after the last event (frames "
                             f"{numbers[a]}-{numbers[b]}, {(b - a + 1) / rate:.3g} s) runs to the end of the "
                             "recording, not to a next event, so it is not a whole cycle: left out (keep it with "
                             "keep_partial=True)")
    if not segs:
        raise DataFileError(f"{where}: nothing is left between the pauses (split_gap={gap})")
    if repetitions is not None:
        if isinstance(repetitions, str) or isinstance(repetitions, (bool, np.bool_)) and not repetitions:
            raise DataFileError(f"split_repetitions must be True (the period found from the take) or a positive period "
                             f"in seconds, got {repetitions!r}")
        period = None if repetitions is True else float(repetitions)
        out = []
        for a, b in segs:
            reps, note = find_repetitions(y[a:b + 1], rate, where=where if len(segs) == 1 else
                                          f"{where}, frames {numbers[a]}-{numbers[b]}", period=period)
            out += [(a + i, a + j) for i, j in reps]
            if notes is not None:
                notes.append(note.replace(f"row {reps[0][0]}", f"frame {numbers[a + reps[0][0]]}")
                             .replace(f"row {reps[-1][1]}", f"frame {numbers[a + reps[-1][1]]}"))
        segs = out
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
            gone = np.flatnonzero(np.isnan(y).all(axis=0))
            named = ([str(names[j]) for j in gone] if names is not None else [f"column {j}" for j in gone])[:20]
            why = (f"{', '.join(named)} {'is' if len(gone) == 1 else 'are'} missing in every frame" if len(gone)
                   else "in every frame some column is missing")
            raise DataFileError(f"{where}: trimming leaves nothing: {why}; leave them out (markers=, columns= or "
                                "min_marker_coverage=) or fill the gaps (max_nan_gap=)")
        segs = out
    return segs


def cut_take(path, y, t, numbers, split, *, max_nan_gap, min_frames, where_col, row_of, markers=None,
             names=None, named=False):
    """One take as demonstrations: split (:func:`split_take`), gaps filled, lengths checked.

    ``split`` holds ``trim``, ``events`` (row indices or None), ``ranges``, ``gap``, ``repetitions`` and
    ``keep_partial``; ``where_col(d)`` names column ``d`` and ``row_of(i)`` row ``i`` of the take in messages.
    ``markers`` (:class:`~interprim.datasets._gaps.MarkerSet`): a marker take, whose gaps follow
    :mod:`interprim.datasets._gaps` (gaps of up to ``max_nan_gap`` frames filled, or the default; what is left
    refused with one table); otherwise each missing value left after filling ``max_nan_gap`` frames is an error.
    Returns ``(demos, times, labels)``: one demonstration per interval, time stamps from 0, labels
    ``<file>@<start>s`` when the take is split (the file's name otherwise).
    """
    from ..core.errors import DataFileWarning
    from ._checks import check_frames, fill_nans, warn
    from ._gaps import GapReport, default_max_gap, fill_runs

    path = Path(path)
    rate = 1.0 / float(np.median(np.diff(t))) if len(t) > 1 else 1.0
    automatic = any(split.get(k) is not None for k in ("events", "gap", "repetitions"))
    splitting = automatic or split.get("ranges") is not None
    notes = split.setdefault("notes", [])
    if splitting or split.get("trim"):
        segs = split_take(y, rate, numbers, where=str(path), trim=bool(split.get("trim")), events=split.get("events"),
                          ranges=split.get("ranges"), gap=split.get("gap"), repetitions=split.get("repetitions"),
                          notes=notes, keep_partial=bool(split.get("keep_partial")), names=names)
    else:
        segs = [(0, y.shape[0] - 1)]
    if automatic and len(segs) > 1:  # pieces too short to learn from, left by pauses, events or repetitions: dropped
        short = [(a, b) for a, b in segs if b - a + 1 < min_frames]
        if short and len(short) < len(segs):
            shown = ", ".join(f"{numbers[a]}-{numbers[b]}" for a, b in short[:10]) + (" ..." if len(short) > 10 else "")
            warn(f"{path}: {len(short)} piece(s) shorter than {min_frames} frames left out (frames {shown}); "
                 f"{len(segs) - len(short)} demonstrations kept", DataFileWarning)
            segs = [(a, b) for a, b in segs if b - a + 1 >= min_frames]
    gap = max_nan_gap
    if markers is not None and gap is None:
        gap = default_max_gap(rate)
    gap = int(gap or 0)
    report = GapReport(path, markers, y.shape[0], rate, gap, named=named) if markers is not None else None
    demos, times, labels = [], [], []
    for a, b in segs:
        where = str(path) if not splitting else f"{path}, frames {numbers[a]}-{numbers[b]}"
        hint = " (a larger split_gap, fewer events or longer split_frames?)" if splitting and len(segs) > 1 else ""
        check_frames(b - a + 1, min_frames, where + hint)
        if report is not None:
            piece = fill_runs(y[a:b + 1], gap)
            report.add(markers.missing(piece), numbers[a:b + 1])
        else:
            piece = fill_nans(y[a:b + 1], gap, where_col, lambda i, _a=a: row_of(_a + i))
        demos.append(piece)
        times.append(t[a:b + 1] - t[a])
        labels.append(f"{path.stem}@{t[a]:.3f}s" if splitting else path.stem)
    if report is not None and report.bad:
        if gap:
            how = (f"filling gaps of up to {gap} frames ({gap / rate:.3g} s at {rate:.4g} Hz"
                   + ("; the default" if max_nan_gap is None else f"; max_nan_gap={gap}")
                   + ") by linear interpolation")
        else:
            how = "filling no gap (max_nan_gap=0)"
        raise report.error(how)
    return demos, times, labels

"""Marker trajectories from C3D motion-capture files (Vicon, OptiTrack, Qualisys, ... exports).

Needs the optional extra ``pip install 'interprim[mocap]'``, which installs the pure-Python
`c3d <https://pypi.org/project/c3d/>`_ package.  ``ezc3d`` (a C++ reader, 1.7.2) was considered and
not used: on randomly damaged copies of a small file it crashed the Python process (segmentation
fault) or did not return within two minutes, instead of raising an error; a loader must report a
damaged recording, not take the program down.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from ..core.errors import DataFileError, DataFileWarning, MissingExtraError

__all__ = ["read_c3d", "LENGTH_UNITS"]

#: Metres per unit, for C3D ``POINT:UNITS`` and BVH ``length_unit`` values (lower case, stripped).
LENGTH_UNITS = {
    "mm": 1e-3,
    "millimeter": 1e-3,
    "millimeters": 1e-3,
    "millimetre": 1e-3,
    "millimetres": 1e-3,
    "cm": 1e-2,
    "dm": 1e-1,
    "m": 1.0,
    "meter": 1.0,
    "meters": 1.0,
    "metre": 1.0,
    "metres": 1.0,
    "in": 0.0254,
    "inch": 0.0254,
    "inches": 0.0254,
    "ft": 0.3048,
}

# POINT parameters that list points which are model outputs (angles in degrees, forces, ...), not markers.
_NON_MARKER_GROUPS = ("ANGLES", "FORCES", "MOMENTS", "POWERS", "SCALARS", "REACTIONS")
_AXES = ("x", "y", "z")
_HINT = "reading .c3d files needs the optional extra: pip install 'interprim[mocap]' (the c3d package)"


def _import_c3d():
    try:
        import c3d
    except ImportError as exc:
        raise MissingExtraError(f"{_HINT} ({exc})") from None
    return c3d


def metres_per_unit(unit: str, where: str, what: str) -> float:
    """Metres per ``unit`` (see :data:`LENGTH_UNITS`), or a :class:`DataFileError` naming ``what``."""
    key = str(unit).strip().lower()
    if key not in LENGTH_UNITS:
        raise DataFileError(
            f"{where}: unknown length unit {unit!r} ({what}); expected one of mm, cm, m, in, ft"
            " - pass length_unit= to say which unit the file uses"
        )
    return LENGTH_UNITS[key]


def _strings(reader, key):
    p = reader.get(key)
    if p is None:
        return []
    try:
        arr = p.string_array
    except Exception:  # noqa: BLE001 - a scalar string parameter
        arr = [p.string_value]
    return [str(s).strip() for s in np.atleast_1d(arr)]


def _labels(reader, n_points):
    labels = []
    for key in ("POINT:LABELS", "POINT:LABELS2", "POINT:LABELS3", "POINT:LABELS4"):
        labels.extend(_strings(reader, key))
    labels = labels[:n_points]
    labels += [f"point{i + 1}" for i in range(len(labels), n_points)]
    return [lab or f"point{i + 1}" for i, lab in enumerate(labels)]


def read_c3d(path, *, markers=None, length_unit=None, max_nan_gap=0, min_frames=5, split=None):
    """Read one C3D file; returns ``(demos, times, columns, labels, meta)`` as the other readers do.

    See :func:`load_c3d` for the parameters and what is read; ``split`` holds ``trim``, ``events``
    (True or event labels), ``ranges`` and ``gap`` (:func:`._split.cut_take`).
    """
    from ._split import cut_take  # the rules of every reader for splitting, gaps and lengths

    c3d = _import_c3d()
    path = Path(path)
    size = path.stat().st_size
    if size == 0:
        raise DataFileError(f"{path}: empty file, expected a C3D file")
    with open(path, "rb") as fh, warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            reader = c3d.Reader(fh)
            n_points = int(reader.point_used)
            rate = float(reader.point_rate)
            first = int(reader.first_frame)
            n_frames = int(reader.frame_count)
            unit_param = reader.get("POINT:UNITS")
            file_unit = unit_param.string_value.strip() if unit_param is not None else None
            labels = _labels(reader, n_points)
            skip = set()
            for grp in _NON_MARKER_GROUPS:
                skip.update(s for s in _strings(reader, f"POINT:{grp}") if s)
            data_start = (int(reader.header.data_block) - 1) * 512
            events = _events(reader)
        except Exception as exc:  # noqa: BLE001 - the c3d package raises many kinds on damaged headers
            raise DataFileError(
                f"{path}: not a readable C3D file (header or parameter section, byte {fh.tell()} of {size}: {exc})"
            ) from None
        if n_points == 0:
            raise DataFileError(f"{path}: the file holds no 3-D points (POINT:USED is 0)")
        if not (np.isfinite(rate) and rate > 0):
            raise DataFileError(f"{path}: the point rate (POINT:RATE) is {rate!r}; expected a positive number")
        if not 0 < n_frames <= size:  # a frame takes at least one byte
            raise DataFileError(f"{path}: the header announces {n_frames} frames in a file of {size} bytes")
        if not 0 <= data_start < size:
            raise DataFileError(f"{path}: the data section starts at byte {data_start}, past the end ({size} bytes)")
        frames, lost = [], []  # grown frame by frame: a damaged header cannot make us allocate more than the file
        k = 0
        try:
            for _, pts, _analog in reader.read_frames(copy=True):
                if k >= n_frames:
                    break
                frames.append(pts[:, :3].astype(np.float64))
                lost.append((pts[:, 3] < 0) | np.all(pts[:, :3] == 0, axis=1))
                k += 1
        except Exception as exc:  # noqa: BLE001
            raise DataFileError(
                f"{path}, frame {first + k}: unreadable point data at byte {fh.tell()} of {size} ({exc})"
            ) from None
        truncated = None
        if k < n_frames:
            what = (f"{path}: truncated file: the header announces frames {first}-{first + n_frames - 1} ({n_frames}) "
                    f"but the data ends at byte {fh.tell()} of {size}, in frame {first + k} ({k} complete frames)")
            if k == 0:
                raise DataFileError(what)
            truncated = f"{what}; keeping frames {first}-{first + k - 1}, {n_frames - k} announced frames are missing"
            n_frames = k
    del caught  # the package's warnings (no analog data, ...) are replaced by the checks above
    if truncated:
        from ._checks import _warn

        _warn(truncated, DataFileWarning)
    xyz, missing = np.stack(frames), np.stack(lost)
    unit = length_unit if length_unit is not None else (file_unit or "mm")
    scale = metres_per_unit(unit, str(path), "length_unit" if length_unit is not None else "POINT:UNITS")
    dup = sorted({lab for lab in labels if labels.count(lab) > 1})
    if dup:
        raise DataFileError(f"{path}: duplicate marker label(s) {dup} in POINT:LABELS")
    available = [i for i, lab in enumerate(labels) if lab not in skip]
    if markers is None:
        keep = available
        if not keep:
            raise DataFileError(f"{path}: every point is a model output ({', '.join(sorted(skip))}); no markers")
    else:
        if isinstance(markers, str):
            markers = [m.strip() for m in markers.split(",") if m.strip()]
        keep = []
        for m in markers:
            if str(m) not in labels:
                shown = ", ".join(labels[i] for i in available[:40]) + (" ..." if len(available) > 40 else "")
                raise DataFileError(
                    f"{path}: unknown marker {m!r} (markers={','.join(map(str, markers))}); "
                    f"the file's markers are: {shown}"
                )
            keep.append(labels.index(str(m)))
        if len(set(keep)) != len(keep):
            raise DataFileError(f"{path}: a marker is selected twice in markers={list(markers)!r}")
    y = xyz[:, keep, :] * scale
    y[missing[:, keep]] = np.nan
    y = y.reshape(n_frames, 3 * len(keep))
    columns = [f"{labels[i]}_{a}" for i in keep for a in _AXES]

    def where_col(d):
        return f"{path}, marker {labels[keep[d // 3]]!r} (column {columns[d]!r})"

    split = dict(split or {})
    if split.get("events") is not None:
        split["events"] = _event_rows(path, events, split["events"], rate, first, n_frames)
    t = np.arange(n_frames) / rate
    demos, times, names = cut_take(path, y, t, first + np.arange(n_frames), split, max_nan_gap=max_nan_gap,
                                   min_frames=min_frames, where_col=where_col, row_of=lambda i: f"frame {first + i}")
    meta = {"units": ["m"] * len(columns)}
    return demos, times, columns, names, meta


def _events(reader):
    """The file's events as ``(context, label, time in s)`` from ``EVENT:CONTEXTS/LABELS/TIMES``."""
    p = reader.get("EVENT:TIMES")
    if p is None:
        return []
    try:
        times = np.asarray(p.float_array, dtype=np.float64).reshape(-1, 2)  # (minutes, seconds) per event
    except Exception:  # noqa: BLE001 - a malformed parameter is reported as 'no events'
        return []
    labels = _strings(reader, "EVENT:LABELS")
    contexts = _strings(reader, "EVENT:CONTEXTS")
    used = reader.get("EVENT:USED")
    n = len(times) if used is None else min(len(times), max(int(used.int16_value), 0))
    return [(contexts[i] if i < len(contexts) else "", labels[i] if i < len(labels) else "",
             60.0 * times[i, 0] + times[i, 1]) for i in range(n)]


def _event_rows(path, events, which, rate, first, n_frames):
    """Row indices of the events named by ``which`` (True/'*' = all; labels, or 'Context:Label').

    An event at time ``s`` is at frame ``round(s * rate) + 1`` in the capture's numbering (frame 1 at
    time 0, as the C3D specification defines EVENT:TIMES); events outside the file's frames are left out.
    """
    if which is True or which in ("*", "all"):
        names = None
    else:
        names = [w.strip() for w in (which.split(",") if isinstance(which, str) else which) if str(w).strip()]
    chosen = []
    for ctx, lab, s in events:
        if names is not None and lab not in names and f"{ctx}:{lab}" not in names:
            continue
        row = int(round(s * rate)) + 1 - first
        if 0 <= row < n_frames:
            chosen.append(row)
    if not chosen:
        shown = ", ".join(f"{c + ':' if c else ''}{lab} at {s:.3f} s" for c, lab, s in events[:20]) or "none"
        raise DataFileError(
            f"{path}: no event {'' if names is None else ','.join(names) + ' '}inside frames "
            f"{first}-{first + n_frames - 1} to split at (split_events); the file's events: {shown}"
        )
    return sorted(set(chosen))

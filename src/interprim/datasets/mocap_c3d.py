"""Marker trajectories from C3D motion-capture files (Vicon, OptiTrack, Qualisys, Optotrak, ... exports).

Needs the optional extra ``pip install 'interprim[mocap]'``, which installs
`ezc3d <https://pypi.org/project/ezc3d/>`_, the C++ reader used in biomechanics (kinetics-toolkit, pyomeca).
It reads files that the pure-Python ``c3d`` package refuses (an ``ANALOG:SCALE`` or ``ANALOG:OFFSET``
stored without dimensions; ``POINT:UNITS`` with one string per point).

On randomly damaged files ezc3d can run for a long time or exhaust memory instead of raising an error,
so the file is read in a child process (:data:`READ_TIMEOUT`, memory capped): a damaged recording
becomes a :class:`~interprim.core.errors.DataFileError`, never a hung or killed program.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from ..core.errors import DataFileError, DataFileWarning, MissingExtraError

__all__ = ["read_c3d", "marker_take", "LENGTH_UNITS"]

#: Seconds the child process may take to read a C3D file, plus 2 s per MB of file.
READ_TIMEOUT = 20.0
#: The child reading a C3D file may use at most this much address space (bytes), or 50 times the file's size.
READ_MEMORY = 1024**3

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
_HINT = "reading .c3d files needs the optional extra: pip install 'interprim[mocap]' (the ezc3d package)"

# Run by the child process (python -I -c): read with ezc3d, write the arrays and the parameters we use.
_CHILD = r"""
import json, sys
try:
    import resource
    resource.setrlimit(resource.RLIMIT_AS, (int(sys.argv[3]), int(sys.argv[3])))
except Exception:
    pass
import numpy as np
import ezc3d
try:
    c = ezc3d.c3d(sys.argv[1])
except Exception as exc:
    sys.stderr.write(str(exc) or type(exc).__name__)
    sys.exit(3)
P = c["parameters"]
def get(g, k):
    try:
        v = P[g][k]["value"]
    except KeyError:
        return None
    v = np.asarray(v)
    return v.astype(str).tolist() if v.dtype.kind in "USO" else v.astype(float).tolist()
h = c["header"]
meta = {"params": {f"{g}:{k}": get(g, k) for g in P if g != "__METADATA__" for k in P[g] if k != "__METADATA__"},
        "points": {k: float(v) for k, v in h["points"].items()},
        "analogs": {k: float(v) for k, v in h["analogs"].items()}}
pts = np.asarray(c["data"]["points"], dtype=np.float64)
res = np.asarray(c["data"]["meta_points"]["residuals"], dtype=np.float64) if pts.size else np.zeros((1, 0, 0))
np.savez(sys.argv[2], points=pts[:3], residuals=res.reshape(res.shape[-2:]) if res.size else np.zeros(pts.shape[1:]),
         meta=np.array(json.dumps(meta)))
"""


def _import_ezc3d():
    try:
        import ezc3d  # noqa: F401 - only to say which extra is missing; the child process reads the file
    except ImportError as exc:
        raise MissingExtraError(f"{_HINT} ({exc})") from None


def _run_reader(path: Path, size: int):
    """The file as read by ezc3d in a child process: ``(points (3, M, T), residuals (M, T), meta)``."""
    timeout = READ_TIMEOUT + 2.0 * size / 1e6
    memory = max(READ_MEMORY, 50 * size)
    with tempfile.TemporaryDirectory(prefix="interprim-c3d-") as tmp:
        out = os.path.join(tmp, "c3d.npz")
        try:
            # one BLAS thread: OpenBLAS reserves address space per thread, which the memory cap counts
            env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1")
            r = subprocess.run([sys.executable, "-I", "-c", _CHILD, str(path), out, str(memory)],
                               capture_output=True, timeout=timeout, stdin=subprocess.DEVNULL, env=env)
        except subprocess.TimeoutExpired:
            raise DataFileError(
                f"{path}: not a readable C3D file (the reader did not finish within {timeout:.0f} s; a damaged "
                "header or parameter section?)"
            ) from None
        if r.returncode != 0 or not os.path.exists(out):
            said = r.stderr.decode("utf-8", "replace").strip().splitlines()
            why = said[-1][:300] if said else (f"the reader stopped with signal {-r.returncode}" if r.returncode < 0
                                             else f"the reader stopped with exit status {r.returncode}")
            if "MemoryError" in why or "bad_alloc" in why:
                why = f"the reader needed more than {memory / 1024**3:.1f} GB of memory"
            raise DataFileError(f"{path}: not a readable C3D file (header or parameter section: {why})")
        with np.load(out, allow_pickle=False) as z:
            return z["points"], z["residuals"], json.loads(str(z["meta"]))


def metres_per_unit(unit: str, where: str, what: str) -> float:
    """Metres per ``unit`` (see :data:`LENGTH_UNITS`), or a :class:`DataFileError` naming ``what``."""
    key = str(unit).strip().lower()
    if key not in LENGTH_UNITS:
        raise DataFileError(
            f"{where}: unknown length unit {unit!r} ({what}); expected one of mm, cm, m, in, ft"
            " - pass length_unit= to say which unit the file uses"
        )
    return LENGTH_UNITS[key]


def _strings(params, key):
    v = params.get(key)
    if v is None:
        return []
    return [str(s).strip() for s in np.ravel(np.asarray(v, dtype=object))]


def _number(params, key, default=None):
    v = params.get(key)
    if v is None:
        return default
    try:
        a = np.ravel(np.asarray(v, dtype=np.float64))
    except (TypeError, ValueError):
        return default
    return float(a[0]) if a.size else default


def _labels(params, n_points):
    labels = []
    for key in ("POINT:LABELS", "POINT:LABELS2", "POINT:LABELS3", "POINT:LABELS4"):
        labels.extend(_strings(params, key))
    labels = labels[:n_points]
    labels += [f"point{i + 1}" for i in range(len(labels), n_points)]
    return [lab or f"point{i + 1}" for i, lab in enumerate(labels)]


def _unit_scales(path, params, n_points, length_unit):
    """Metres per unit of each point: ``length_unit``, else ``POINT:UNITS`` (one string, or one per point)."""
    if length_unit is not None:
        return np.full(n_points, metres_per_unit(length_unit, str(path), "length_unit"))
    units = [u for u in _strings(params, "POINT:UNITS")]
    if not units or not any(units):
        return np.full(n_points, 1e-3)  # the C3D default
    if len(units) == 1 or len(set(units)) == 1:
        return np.full(n_points, metres_per_unit(units[0], str(path), "POINT:UNITS"))
    units = (units + [units[-1]] * n_points)[:n_points]  # one string per point (Optotrak exports)
    return np.array([metres_per_unit(u or "mm", str(path), f"POINT:UNITS of point {i + 1}")
                     for i, u in enumerate(units)])


def read_c3d(path, *, markers=None, length_unit=None, max_nan_gap=None, min_frames=5, split=None,
             min_marker_coverage=None):
    """Read one C3D file; returns ``(demos, times, columns, labels, meta)`` as the other readers do.

    See :func:`load_c3d` for the parameters and what is read; ``split`` holds ``trim``, ``events``
    (True or event labels), ``ranges``, ``gap``, ``repetitions`` and ``keep_partial`` (:func:`._split.cut_take`).
    Missing markers follow :mod:`interprim.datasets._gaps` (sparse markers left out, short gaps filled, the rest
    refused with a table).
    """
    from ._checks import warn

    _import_ezc3d()
    path = Path(path)
    size = path.stat().st_size
    if size == 0:
        raise DataFileError(f"{path}: empty file, expected a C3D file")
    with open(path, "rb") as fh:
        head = fh.read(512)
    if len(head) < 512 or head[1:2] != b"\x50":
        raise DataFileError(f"{path}: not a readable C3D file (header or parameter section, byte 0 of {size}: "
                            "no C3D header, whose second byte is 0x50)")
    # the header (words 2-9): points, analog samples per frame, first/last frame, scale (< 0: floats), data block
    h_points, h_analog, h_first, h_last = np.frombuffer(head[2:10], "<u2").astype(int)
    h_scale = float(np.frombuffer(head[12:16], "<f4")[0])
    data_start = (int(np.frombuffer(head[16:18], "<u2")[0]) - 1) * 512
    frame_bytes = (4 if not h_scale >= 0 else 2) * (4 * h_points + h_analog)
    if h_points and h_last >= h_first and 0 <= data_start < size and size - data_start < frame_bytes:
        raise DataFileError(
            f"{path}: truncated file: the header announces frames {h_first}-{h_last} ({h_last - h_first + 1}) but "
            f"the data ends at byte {size} of {size}, in frame {h_first} (0 complete frames)"
        )
    pts, res, meta = _run_reader(path, size)
    params = meta["params"]
    n_points = int(meta["points"].get("size", 0))
    rate = float(meta["points"].get("frame_rate", 0.0))
    first = int(meta["points"].get("first_frame", 0)) + 1  # ezc3d counts from 0, the file and capture from 1
    n_frames = int(meta["points"].get("last_frame", -1)) - first + 2
    if h_last >= h_first:  # ezc3d shortens the header's count to the frames it read: the file's own count
        n_frames = max(n_frames, int(h_last - h_first + 1))
    if n_points == 0:
        raise DataFileError(f"{path}: the file holds no 3-D points (POINT:USED is 0)")
    if not (np.isfinite(rate) and rate > 0):
        raise DataFileError(f"{path}: the point rate (POINT:RATE) is {rate!r}; expected a positive number")
    if not 0 < n_frames <= size:  # a frame takes at least one byte
        raise DataFileError(f"{path}: the header announces {n_frames} frames in a file of {size} bytes")
    if not 0 <= data_start < size:
        raise DataFileError(f"{path}: the data section starts at byte {data_start}, past the end ({size} bytes)")
    # the frames the file holds complete: ezc3d pads a last partial frame, which must not be read as data
    k = min(int(pts.shape[2]) if pts.ndim == 3 else 0, n_frames, (size - data_start) // max(frame_bytes, 1))
    if k < n_frames:
        what = (f"{path}: truncated file: the header announces frames {first}-{first + n_frames - 1} ({n_frames}) "
                f"but the data ends at byte {size} of {size}, in frame {first + k} ({k} complete frames)")
        if k == 0:
            raise DataFileError(what)
        warn(f"{what}; keeping frames {first}-{first + k - 1}, {n_frames - k} announced frames are missing",
              DataFileWarning)
        n_frames = k
    xyz = np.transpose(pts[:, :n_points, :n_frames], (2, 1, 0))  # (T, M, 3)
    r = res[:n_points, :n_frames].T if res.shape[0] >= n_points else np.zeros((n_frames, n_points))
    missing = ~np.isfinite(xyz).all(axis=2) | (r < 0) | np.all(xyz == 0, axis=2)
    labels = _labels(params, n_points)
    skip = set()
    for grp in _NON_MARKER_GROUPS:
        skip.update(s for s in _strings(params, f"POINT:{grp}") if s)
    scales = _unit_scales(path, params, n_points, length_unit)
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
    y = xyz[:, keep, :] * scales[keep][None, :, None]
    y[missing[:, keep]] = np.nan
    y = y.reshape(n_frames, 3 * len(keep))
    columns = [f"{labels[i]}_{a}" for i in keep for a in _AXES]
    return marker_take(path, y, columns, rate, first, params=params, named=markers is not None,
                       max_nan_gap=max_nan_gap, min_frames=min_frames, split=split,
                       min_marker_coverage=min_marker_coverage)


def marker_take(path, y, columns, rate, first, *, named, max_nan_gap, min_frames, split, min_marker_coverage,
                params=None, events=None):
    """A marker take ``(T, 3M)`` (``nan`` where a marker is missing, columns ``<marker>_x/_y/_z`` in metres) as
    demonstrations: sparse markers left out, split, gaps filled (:mod:`interprim.datasets._gaps`); returns
    ``(demos, times, columns, labels, meta)``.  ``first``: the number of the first frame; ``events``: the
    file's events as ``(context, label, seconds)`` (C3D: from ``params``)."""
    from ._gaps import DEFAULT_MIN_COVERAGE, MarkerSet, drop_sparse
    from ._split import cut_take

    path = Path(path)
    n_frames = y.shape[0]
    cov = DEFAULT_MIN_COVERAGE if min_marker_coverage is None else float(min_marker_coverage)
    if not 0.0 <= cov <= 1.0:
        raise ValueError(f"min_marker_coverage must be a share of frames in [0, 1], got {min_marker_coverage!r}")
    y, columns = drop_sparse(path, y, columns, MarkerSet.of_columns(columns), cov, named)
    marker_set = MarkerSet.of_columns(columns)

    def where_col(d):
        return f"{path}, marker {marker_set.names[[d in g for g in marker_set.groups].index(True)]!r} " \
               f"(column {columns[d]!r})"

    split = dict(split or {})
    if split.get("events") is not None:
        evs = _events(params) if params is not None else list(events or [])
        split["events"] = _event_rows(path, evs, split["events"], rate, first, n_frames)
    t = np.arange(n_frames) / rate
    demos, times, names = cut_take(path, y, t, first + np.arange(n_frames), split, max_nan_gap=max_nan_gap,
                                   min_frames=min_frames, where_col=where_col, row_of=lambda i: f"frame {first + i}",
                                   markers=marker_set, names=columns, named=named)
    meta = {"units": ["m"] * len(columns), "notes": split.get("notes", [])}
    return demos, times, columns, names, meta


def _events(params):
    """The file's events as ``(context, label, time in s)`` from ``EVENT:CONTEXTS/LABELS/TIMES``."""
    v = params.get("EVENT:TIMES")
    if v is None:
        return []
    try:
        a = np.asarray(v, dtype=np.float64)
        times = a.T if a.ndim == 2 and a.shape[0] == 2 else a.reshape(-1, 2)  # (minutes, seconds) per event
    except (TypeError, ValueError):  # a malformed parameter is reported as 'no events'
        return []
    labels = _strings(params, "EVENT:LABELS")
    contexts = _strings(params, "EVENT:CONTEXTS")
    used = _number(params, "EVENT:USED")
    n = len(times) if used is None else min(len(times), max(int(used), 0))
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
        if not np.isfinite(s * rate):
            shown = f"{ctx}:{lab}" if ctx else lab
            raise DataFileError(f"{path}: event {shown!r} has time {float(s)!r} s, not a finite number; it cannot mark "
                                "a frame to split at (split_events): fix or remove it, or name the other events")
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

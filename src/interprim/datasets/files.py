"""Reading and writing users' own demonstrations (CSV and NPZ; see ``docs/data-formats.md``).

:func:`load_demonstrations` also reads motion-capture recordings (C3D, BVH: :mod:`.mocap_c3d`,
:mod:`.mocap_bvh`) and ROS bags (:mod:`.ros_bags`), choosing the reader by extension.

Formats
-------
CSV (one file)
    A header row of column names, then one row per frame.  A ``time`` column (seconds,
    strictly increasing within a demonstration) is required unless ``dt`` is given.  An
    optional ``demo`` column labels the demonstration each row belongs to; rows of one
    demonstration must be contiguous.  Every other column is a degree of freedom (numbers;
    an empty cell, ``nan`` or ``NA`` is a missing value).  Lines starting with ``#`` are
    comments; ``# observed: a, b`` names the observed agent's columns.
Folder
    Every ``*.csv`` and ``*.npz`` file in it (not recursive), in natural order; all must
    have the same columns.
NPZ
    Arrays ``demo_000``, ``demo_001``, ... of shape ``(T, D)``, ``time_000``, ... of shape
    ``(T,)`` (or a scalar ``dt``), optional ``columns`` (``(D,)`` strings) and ``observed``
    (strings).  Read with ``allow_pickle=False``.
"""

from __future__ import annotations

import csv
import math
import os
import re
from pathlib import Path

import numpy as np

from ..core.errors import DataFileError
from ..core.preprocessing import resample_step
from ._base import DataNotFoundError, Demonstrations, RawStream, sampling, select_columns, uniform_dt
from ._checks import check_frames, check_stamps, fill_nans

__all__ = ["load_demonstrations", "save_demonstrations"]

TIME = "time"
DEMO = "demo"
_MISSING = {"", "nan", "NaN", "NAN", "NA", "N/A", "na", "null", "None"}
_DEMO_KEY = re.compile(r"^demo_(\d+)$")
_TIME_KEY = re.compile(r"^time_(\d+)$")
_NPZ_META = {"columns", "dt", "observed"}


def _natural_key(p: Path):
    return [int(s) if s.isdigit() else s for s in re.split(r"(\d+)", p.name)]


# --------------------------------------------------------------------------- CSV limits
#: Limits of the CSV reader, checked while reading (the file is streamed, never held whole). Raise one with
#: its environment variable (e.g. ``INTERPRIM_CSV_MAX_COLUMNS=500000``) or by assigning to this dict.
CSV_LIMITS = {"max_line_chars": 64 * 2**20, "max_columns": 1_000_000, "max_bytes": 8 * 2**30}
_LIMIT_ENV = {"max_line_chars": "INTERPRIM_CSV_MAX_LINE_CHARS", "max_columns": "INTERPRIM_CSV_MAX_COLUMNS",
              "max_bytes": "INTERPRIM_CSV_MAX_BYTES"}


def _csv_limit(name: str) -> int:
    env = os.environ.get(_LIMIT_ENV[name])
    if env:
        try:
            value = int(env)
        except ValueError:
            raise ValueError(f"{_LIMIT_ENV[name]}={env!r} is not a whole number") from None
        if value > 0:
            return value
    return int(CSV_LIMITS[name])


def _over(path, what, value, name):
    return DataFileError(
        f"{path}: {what} ({value}) exceeds the CSV reader's limit {name}={_csv_limit(name)}; if the file is "
        f"right, raise it with the environment variable {_LIMIT_ENV[name]}=N"
    )


def _lines(fh, path, max_chars):
    """The file's lines, each read with a bounded ``readline``: a too-long line is refused without reading it."""
    n = 0
    while True:
        line = fh.readline(max_chars + 1)
        if not line:
            return
        n += 1
        if len(line) > max_chars and not line.endswith("\n"):
            raise _over(f"{path}, line {n}", "a line longer than the limit", f"more than {max_chars} characters",
                        "max_line_chars")
        yield line


#: Time columns recognised when a CSV file has no ``time`` column, in this order: ``rostopic echo -p``
#: (``%time``, ns), PlotJuggler and ``ros2 bag`` CSV exports (``__time``, ``timestamp``), bagpy (``Time``).
TIME_CANDIDATES = ("%time", "__time", "timestamp", "Time", "field.header.stamp", "header.stamp")
TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9}
# A ROS export's bookkeeping fields: not degrees of freedom unless named with columns=.
_ROS_BOOKKEEPING = re.compile(r"(^|[./])(header[./](seq|frame_id|stamp([./](secs|nsecs|sec|nanosec))?)|child_frame_id)$")


def _ros_shaped(header) -> bool:
    """A ``rostopic echo -p`` (``%time``, ``field.*``) or ``ros2 bag``/PlotJuggler (``__time``, ``/topic/...``)
    export."""
    return "%time" in header or "__time" in header or any(h.startswith(("field.", "/")) for h in header[:50])


def _time_scale(t_all, name, unit, explicit):
    """Seconds per unit of the time column, and a note saying which unit was taken and why."""
    if unit is not None:
        return TIME_UNITS[unit], None
    if name == TIME and not explicit:
        return 1.0, None  # the documented format: seconds
    steps = np.diff(t_all)
    steps = steps[steps > 0]
    whole = bool(np.all(np.mod(t_all, 1.0) == 0))
    if whole and steps.size and float(np.median(steps)) > 1e3:
        return 1e-9, (f"time column {name!r}: whole numbers {float(np.median(steps)):.3g} apart, taken as "
                      "nanoseconds (as ROS stamps are); pass time_unit= (--time-unit) to say otherwise")
    return 1.0, (f"time column {name!r}: taken as seconds (median step {float(np.median(steps)) if steps.size else 0:.3g}); "
                 "pass time_unit= (--time-unit) to say otherwise")


def _read_csv(path: Path, dt, max_nan_gap, min_frames, time_column=None, time_unit=None, columns=None):
    """Parse one CSV file into (demos, times, columns, labels, meta), streaming it line by line.

    ``columns`` (names or indices of the data columns) restricts what is parsed: the other columns may
    hold text.  Checks as it reads: :data:`CSV_LIMITS`.
    """
    from collections import Counter

    from ._base import select_columns, shown_names

    size = path.stat().st_size
    if size > _csv_limit("max_bytes"):
        raise _over(path, "the file's size", f"{size} bytes", "max_bytes")
    max_chars = _csv_limit("max_line_chars")
    max_cols = _csv_limit("max_columns")
    if csv.field_size_limit() < max_chars:  # one cell may be as long as a line (the module's default is 128 KiB)
        csv.field_size_limit(max_chars)
    meta = {}
    header = None
    header_line = 0
    with open(path, newline="", encoding="utf-8-sig") as fh:
        reader = csv.reader(_lines(fh, path, max_chars))
        try:
            for cells in reader:  # the comments and the header
                if not cells or all(not c.strip() for c in cells):
                    continue
                if cells[0].lstrip().startswith("#"):
                    text = ",".join(cells).lstrip()[1:]
                    if ":" in text:
                        k, v = text.split(":", 1)
                        meta[k.strip().lower()] = v.strip()
                    continue
                header = [c.strip() for c in cells]
                header_line = reader.line_num
                break
        except (csv.Error, UnicodeDecodeError) as exc:
            raise DataFileError(f"{path}: not a readable CSV text file ({exc})") from None
        if header is None:
            raise DataFileError(f"{path}: empty file, expected a header row of column names")
        n_cols = len(header)
        if n_cols > max_cols:
            raise _over(f"{path}, line {header_line}", "the number of columns", n_cols, "max_columns")
        if any(not h for h in header):
            k = next(i for i, h in enumerate(header) if not h)
            raise DataFileError(f"{path}, line {header_line}: empty column name in the header (column {k + 1} of "
                                f"{n_cols}: {shown_names(header)})")
        dup = sorted(h for h, c in Counter(header).items() if c > 1)
        if dup:
            raise DataFileError(f"{path}, line {header_line}: duplicate column name(s) {dup[:10]}")
        index = {h: i for i, h in enumerate(header)}
        ros = _ros_shaped(header)
        if time_column is not None:
            if time_column not in index:
                raise DataFileError(f"{path}: no column {time_column!r} (time_column); the header has {n_cols} "
                                    f"columns: {shown_names(header)}")
            tname = time_column
        elif TIME in index:
            tname = TIME
        elif dt is None or ros:  # a ROS export's own stamps win over a fallback dt (predict passes the model's)
            tname = next((c for c in TIME_CANDIDATES if c in index), None)
            if tname is None and dt is None:
                raise DataFileError(
                    f"{path}: missing column 'time' (seconds); the header has {n_cols} columns: {shown_names(header)}. "
                    "Name the time column with time_column= (--time-column), add a time column, or pass dt for "
                    "uniformly sampled data"
                )
        else:
            tname = None
        skip = {TIME, DEMO, tname}
        if ros:
            skip.update(h for h in header if h in TIME_CANDIDATES or _ROS_BOOKKEEPING.search(h))
        data_cols = [h for h in header if h not in skip]
        if columns is not None:
            pool = data_cols if not ros else [h for h in header if h not in (TIME, DEMO, tname)]
            data_cols = [pool[i] for i in select_columns(pool, columns, where=str(path))]
        if not data_cols:
            raise DataFileError(f"{path}: no data columns besides the time and demo columns in the header "
                                f"({shown_names(header)})")
        i_time = index[tname] if tname is not None else None
        i_demo = index.get(DEMO)
        i_data = [index[c] for c in data_cols]
        order, groups = [], {}  # label -> (lines, rows of floats, times)
        last = None

        def num(cell, line, col, allow_missing):
            s = cell.strip()
            if s in _MISSING:
                if not allow_missing:
                    raise DataFileError(f"{path}, line {line}: missing value in column {col!r}")
                return math.nan
            try:
                v = float(s)
            except ValueError:
                hint = ("" if columns is not None or not allow_missing  # the time column has no such hint
                        else "; choose the numeric columns with columns= (--columns)")
                raise DataFileError(
                    f"{path}, line {line}: non-numeric value {cell[:80]!r} in column {col!r}{hint}") from None
            if math.isinf(v):
                raise DataFileError(f"{path}, line {line}: infinite value {cell[:80]!r} in column {col!r}")
            return v

        try:
            for cells in reader:
                line = reader.line_num
                if not cells or all(not c.strip() for c in cells):
                    continue
                if cells[0].lstrip().startswith("#"):
                    continue
                if len(cells) != n_cols:
                    raise DataFileError(f"{path}, line {line}: {len(cells)} cells but the header has {n_cols} columns")
                label = cells[i_demo].strip() if i_demo is not None else "0"
                if label != last:
                    if label in groups:
                        raise DataFileError(f"{path}, line {line}: rows of demo {label!r} are not contiguous "
                                            f"(it appeared before line {line})")
                    groups[label] = ([], [], [])
                    order.append(label)
                    last = label
                lines, rows, ts = groups[label]
                lines.append(line)
                rows.append([num(cells[i], line, header[i], True) for i in i_data])
                if i_time is not None:
                    ts.append(num(cells[i_time], line, tname, False))
        except (csv.Error, UnicodeDecodeError) as exc:
            raise DataFileError(f"{path}, line {reader.line_num}: not a readable CSV text file ({exc})") from None
    if not order:
        raise DataFileError(f"{path}: no data rows after the header (line {header_line})")
    scale = 1.0
    if i_time is not None:
        t_all = np.concatenate([np.asarray(groups[g][2], dtype=np.float64) for g in order])
        scale, note = _time_scale(t_all, tname, time_unit, explicit=time_column is not None)
        if note:
            meta["notes"] = [note]
    demos, times, labels = [], [], []
    for label in order:
        lines, rows, ts = groups[label]
        where_demo = f"{path}" + (f", demo {label!r}" if i_demo is not None else "")
        y = np.array(rows, dtype=np.float64).reshape(len(rows), len(i_data))
        if i_time is not None:
            t = np.asarray(ts, dtype=np.float64)
            if scale != 1.0:
                t = t * scale
        else:
            t = np.arange(len(rows)) * float(dt)

        def row_of(i, _lines=lines):
            return f"line {_lines[i]}"

        check_frames(len(rows), min_frames, where_demo)
        check_stamps(t, where_demo, row_of)
        y = fill_nans(y, max_nan_gap, lambda d, _w=where_demo: f"{_w}, column {data_cols[d]!r}", row_of)
        demos.append(y)
        times.append(t)
        labels.append(label if i_demo is not None else path.stem)
    if columns is not None:
        meta["selected"] = True
    return demos, times, data_cols, labels, meta


# --------------------------------------------------------------------------- NPZ
MAX_NPZ_ARRAY_BYTES = 4 << 30  # one array of a data .npz once read (4 GiB)


def _check_npz_member(npz, key: str, path: Path) -> None:
    """Refuse an array of a data ``.npz`` from its ``.npy`` header (shape and dtype; no data read) when it declares
    more than :data:`MAX_NPZ_ARRAY_BYTES`, or more than the member holds."""
    zf = getattr(npz, "zip", None)
    if zf is None:
        return
    try:
        info = zf.getinfo(key + ".npy")
        with zf.open(info) as fh:
            version = np.lib.format.read_magic(fh)
            if version == (1, 0):
                shape, _, dtype = np.lib.format.read_array_header_1_0(fh)
            elif version == (2, 0):
                shape, _, dtype = np.lib.format.read_array_header_2_0(fh)
            else:
                return  # np.load reports it
            offset = fh.tell()
    except (KeyError, ValueError, OSError, EOFError):
        return  # np.load reports it
    count = 1
    for d in shape:
        count *= int(d)
    nbytes = count * dtype.itemsize
    if nbytes > MAX_NPZ_ARRAY_BYTES:
        raise DataFileError(f"{path}: key {key!r} declares shape {shape} of {dtype} ({count:.3g} values, "
                            f"{nbytes / 2**30:.3g} GiB), over the limit of {MAX_NPZ_ARRAY_BYTES / 2**30:g} GiB "
                            "for one array: a damaged file?")
    if not dtype.hasobject and offset + nbytes > int(info.file_size):
        raise DataFileError(f"{path}: key {key!r} declares shape {shape} of {dtype} ({nbytes} bytes) but holds "
                            f"only {int(info.file_size) - offset} bytes: the file is truncated or damaged")


def _read_npz(path: Path, dt, max_nan_gap, min_frames):
    try:
        npz = np.load(path, allow_pickle=False)
    except Exception as exc:  # noqa: BLE001
        raise DataFileError(f"{path}: not a readable .npz file ({exc})") from None
    if not hasattr(npz, "files"):
        raise DataFileError(f"{path}: a single .npy array, expected an .npz archive with demo_000, ...")
    meta = {}
    with npz:
        keys = list(npz.files)
        demo_keys = {}
        time_keys = {}
        for k in keys:
            m = _DEMO_KEY.match(k)
            if m:
                demo_keys[int(m.group(1))] = k
                continue
            m = _TIME_KEY.match(k)
            if m:
                time_keys[int(m.group(1))] = k
                continue
            if k not in _NPZ_META:
                raise DataFileError(
                    f"{path}: unknown key {k!r}; expected demo_000, demo_001, ..., time_000, ..., "
                    "and optionally columns, dt, observed"
                )
        if not demo_keys:
            raise DataFileError(f"{path}: no demonstrations (keys demo_000, demo_001, ...); it has {keys}")
        extra = sorted(set(time_keys) - set(demo_keys))
        if extra:
            raise DataFileError(f"{path}: {time_keys[extra[0]]!r} has no matching demo_ key")

        def load(k):
            _check_npz_member(npz, k, path)  # from its header, before any data is read
            try:
                return npz[k]
            except ValueError as exc:  # object arrays would need pickle
                raise DataFileError(f"{path}: key {k!r} cannot be read without pickle ({exc})") from None
            except MemoryError:
                raise DataFileError(f"{path}: key {k!r} does not fit in memory") from None

        file_dt = None
        if "dt" in npz.files:
            a = load("dt")
            try:
                file_dt = float(np.asarray(a, dtype=np.float64).reshape(()))
            except (TypeError, ValueError):
                raise DataFileError(f"{path}: 'dt' must be one positive number, got shape {a.shape}") from None
            if not (np.isfinite(file_dt) and file_dt > 0):
                raise DataFileError(f"{path}: 'dt' must be a positive number, got {file_dt!r}")
        columns = None
        if "columns" in npz.files:
            a = load("columns")
            if a.dtype.kind not in "US" or a.ndim != 1:
                raise DataFileError(f"{path}: 'columns' must be a 1-D string array, got dtype {a.dtype} shape {a.shape}")
            columns = [str(c) for c in a.astype(str)]
            dup = sorted({c for c in columns if columns.count(c) > 1})
            if dup:
                raise DataFileError(f"{path}: duplicate column name(s) {dup} in 'columns'")
        if "observed" in npz.files:
            a = load("observed")
            meta["observed"] = ",".join(str(c) for c in np.atleast_1d(a).astype(str))
        if time_keys and len(time_keys) != len(demo_keys):
            missing = [demo_keys[i] for i in sorted(demo_keys) if i not in time_keys]
            raise DataFileError(f"{path}: time stamps missing for {missing[:3]} (every demo_ needs a time_ or none)")
        step = file_dt if file_dt is not None else dt
        if not time_keys and step is None:
            raise DataFileError(f"{path}: no time stamps (time_000, ...) and no 'dt'; add either, or pass dt")
        demos, times, labels = [], [], []
        n_cols = None
        for i in sorted(demo_keys):
            k = demo_keys[i]
            y = load(k)
            if y.dtype.kind not in "fiub":
                raise DataFileError(f"{path}: {k!r} is not numeric (dtype {y.dtype})")
            if y.ndim == 1:
                y = y[:, None]
            if y.ndim != 2:
                raise DataFileError(f"{path}: {k!r} must have shape (T, D), got {y.shape}")
            y = y.astype(np.float64)
            if n_cols is None:
                n_cols = y.shape[1]
                if columns is not None and len(columns) != n_cols:
                    raise DataFileError(f"{path}: 'columns' names {len(columns)} columns but {k!r} has {n_cols}")
            elif y.shape[1] != n_cols:
                raise DataFileError(f"{path}: {k!r} has {y.shape[1]} columns, the first demonstration has {n_cols}")
            where = f"{path}, {k}"
            check_frames(y.shape[0], min_frames, where)
            if np.isinf(y).any():
                r, c = np.argwhere(np.isinf(y))[0]
                raise DataFileError(f"{where}: infinite value at row {r}, column {c}")
            if i in time_keys:
                t = load(time_keys[i])
                if t.dtype.kind not in "fiu" or t.ndim != 1 or t.shape[0] != y.shape[0]:
                    raise DataFileError(
                        f"{path}: {time_keys[i]!r} must be numeric with shape ({y.shape[0]},), got {t.dtype} {t.shape}"
                    )
                t = t.astype(np.float64)
            else:
                t = np.arange(y.shape[0]) * float(step)

            def row_of(r):
                return f"row {r}"

            check_stamps(t, f"{path}, {time_keys.get(i, k)}", row_of)
            cols_now = columns or [f"dof_{j}" for j in range(n_cols)]
            y = fill_nans(y, max_nan_gap, lambda d, _w=where, _c=cols_now: f"{_w}, column {_c[d]!r}", row_of)
            demos.append(y)
            times.append(t)
            labels.append(k)
    if columns is None:
        columns = [f"dof_{j}" for j in range(n_cols)]
    return demos, times, columns, labels, meta


# --------------------------------------------------------------------------- public
RECORDING_SUFFIXES = (".c3d", ".bvh", ".bag", ".db3", ".mcap")
_FOLDER_SUFFIXES = (".csv", ".npz") + RECORDING_SUFFIXES
# Which format reads which option (the options not listed for a format must be left at None).
_OPTIONS = {
    ".csv": ("time_column", "time_unit", "columns"),
    ".c3d": ("markers", "length_unit", "trim", "split_events", "split_frames", "split_gap", "split_repetitions"),
    ".bvh": ("bvh_mode", "joints", "length_unit", "end_sites", "trim", "split_frames", "split_gap",
             "split_repetitions"),
    "ros": ("topics", "joints", "orientation", "split_topic", "split_gap"),
}


def _take_split(opts) -> dict:
    """The splitting options of a motion-capture take (:func:`._split.cut_take`)."""
    return dict(trim=bool(opts["trim"]), events=opts["split_events"], ranges=opts["split_frames"],
                gap=opts["split_gap"], repetitions=opts["split_repetitions"])


def _check_readable(p: Path) -> None:
    """A regular file or a folder, checked before it is opened: a FIFO or a device would block the reader."""
    import errno
    import stat

    try:
        st = os.stat(p)
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise DataFileError(f"{p}: symlink loop (a symbolic link that points, through others, to itself)") from None
        if exc.errno in (errno.ENOENT, errno.ENOTDIR):
            raise DataNotFoundError(f"demonstrations not found: {p}") from None
        raise DataFileError(f"{p}: cannot be read ({exc.strerror})") from None
    if not (stat.S_ISREG(st.st_mode) or stat.S_ISDIR(st.st_mode)):
        kind = ("a named pipe (FIFO)" if stat.S_ISFIFO(st.st_mode) else "a character device" if stat.S_ISCHR(st.st_mode)
                else "a block device" if stat.S_ISBLK(st.st_mode) else "a socket" if stat.S_ISSOCK(st.st_mode)
                else "a special file")
        raise DataFileError(f"{p}: is {kind}, not a regular file; demonstrations are read from files or folders")


def _read_file(p: Path, dt, max_nan_gap, min_frames, opts, resample_dt=None):
    from .ros_bags import is_rosbag2_folder

    suffix = p.suffix.lower()
    kind = "ros" if (suffix in (".bag", ".db3", ".mcap") or is_rosbag2_folder(p)) else suffix
    allowed = _OPTIONS.get(kind, ())
    for name, value in opts.items():
        if value is not None and value is not False and name not in allowed:
            fmts = [k if k != "ros" else "ROS bag" for k, v in _OPTIONS.items() if name in v]
            this = "ROS bag" if kind == "ros" else (kind or "extension-less") + " file"
            raise DataFileError(f"{p}: the option {name}= applies to {', '.join(fmts)} files, not to this {this}")
    if kind == ".csv":
        return _read_csv(p, dt, max_nan_gap, min_frames, time_column=opts["time_column"], time_unit=opts["time_unit"],
                         columns=opts["columns"])
    if kind == ".npz":
        return _read_npz(p, dt, max_nan_gap, min_frames)
    if kind == ".c3d":
        from .mocap_c3d import read_c3d

        return read_c3d(p, markers=opts["markers"], length_unit=opts["length_unit"], max_nan_gap=max_nan_gap,
                        min_frames=min_frames, split=_take_split(opts))
    if kind == ".bvh":
        from .mocap_bvh import read_bvh

        return read_bvh(p, mode=opts["bvh_mode"] or "positions", joints=opts["joints"],
                        length_unit=opts["length_unit"], end_sites=bool(opts["end_sites"]),
                        max_nan_gap=max_nan_gap, min_frames=min_frames, split=_take_split(opts))
    if kind == "ros":
        from .ros_bags import read_rosbag

        return read_rosbag(p, topics=opts["topics"], joints=opts["joints"], orientation=bool(opts["orientation"]),
                           split_topic=opts["split_topic"], split_gap=opts["split_gap"], grid_dt=resample_dt,
                           max_nan_gap=max_nan_gap, min_frames=min_frames)
    raise DataFileError(
        f"{p}: unsupported file type {p.suffix!r}; expected .csv, .npz, .c3d, .bvh, a ROS bag (.bag, .db3, .mcap, "
        "a rosbag2 folder) or a folder of such files"
    )


def load_demonstrations(
    path,
    *,
    columns=None,
    dt: float | None = None,
    resample_dt: float | None = None,
    max_nan_gap: int = 0,
    min_frames: int = 5,
    markers=None,
    joints=None,
    length_unit: str | None = None,
    bvh_mode: str | None = None,
    end_sites: bool = False,
    topics=None,
    orientation: bool = False,
    split_topic: str | None = None,
    split_gap: float | None = None,
    trim: bool = False,
    split_events=None,
    split_frames=None,
    time_column: str | None = None,
    time_unit: str | None = None,
    split_repetitions=None,
) -> Demonstrations:
    """Load demonstrations from CSV/NPZ files, motion-capture recordings or ROS bags.

    The format follows the extension (see ``docs/data-formats.md``): ``.csv``, ``.npz``,
    ``.c3d`` (:func:`~interprim.datasets.recordings.load_c3d`), ``.bvh``
    (:func:`~interprim.datasets.recordings.load_bvh`), ``.bag``/``.db3``/``.mcap`` or a rosbag2
    folder with ``metadata.yaml`` (:func:`~interprim.datasets.recordings.load_rosbag`); any other
    folder is read file by file (every ``.csv``, ``.npz``, ``.c3d``, ``.bvh``, ``.bag``, ``.db3``
    and ``.mcap`` in it, natural order).  Every problem is reported as a
    :class:`~interprim.core.errors.DataFileError` naming the file and the position: the line (CSV,
    1-based, counting the header and comments; BVH), the row (NPZ, 0-based frame index), the
    frame (C3D, as the capture software numbers it) or the topic, message and time (ROS bags).

    Parameters
    ----------
    path : str or Path
        A file, a rosbag2 folder or a folder of files.
    columns : sequence of str or int, or str, optional
        Columns to keep, in this order (names, indices or a comma-separated string);
        default all data columns.  Unknown names raise ``DataFileError``.  In CSV files only
        these columns are parsed, so the others may hold text.
    dt : float, optional
        Sampling interval in seconds for files without time stamps (a CSV without a
        ``time`` column, an NPZ without ``time_`` keys or ``dt``).  Ignored when the file
        has time stamps.
    resample_dt : float, optional
        If given, every demonstration is linearly interpolated onto a uniform grid with this
        interval (:func:`interprim.core.preprocessing.resample_uniform`).  For a ROS bag both
        agents' streams are interpolated onto that grid directly (instead of onto the
        observed agent's stamps).
    max_nan_gap : int
        Longest interior run of missing values (per column) that is filled by linear
        interpolation (default 0: any missing value is an error).  Missing values at the
        start or end of a demonstration are always an error.  Missing motion-capture markers
        and joints absent from a JointState message are missing values.
    min_frames : int
        Fewest frames a demonstration may have (default 5).
    markers : sequence of str or str, optional
        C3D: the markers to keep (default all).
    joints : sequence of str or str, optional
        BVH: the joints to keep; ROS JointState: the joints to read (default all).
    length_unit : str, optional
        C3D: overrides the file's ``POINT:UNITS``; BVH: the file's length unit (positions are
        then converted to metres).
    bvh_mode : {"positions", "angles"}, optional
        BVH: joint world positions by forward kinematics (default) or joint angles (radians).
    end_sites : bool
        BVH positions: also the End Site points.
    topics : sequence of str or str, optional
        ROS bags (required): ``(observed, controlled)`` topics or ``tf:FRAME`` streams.
    orientation : bool
        ROS bags: also read orientation quaternions of poses and tf frames.
    split_topic : str, optional
        ROS bags: a topic whose messages mark the start of each demonstration.
    split_gap : float, optional
        A pause longer than this many seconds starts a new demonstration: in a ROS bag, no
        message in either stream; in a C3D or BVH take, a run of frames in which every column
        moves slower than 5 % of the take's 95th-percentile speed, or in which a value is missing
        (:func:`interprim.datasets._split.split_take`).
    trim : bool
        C3D, BVH: drop the leading and trailing frames (of each demonstration) in which a
        marker or channel is missing (written as 0,0,0, with a negative residual, or ``nan``).
    split_events : True or str or sequence of str, optional
        C3D: each of the file's events (``True``: every event; else the event labels, or
        ``Context:Label``) starts a demonstration lasting until the next one.
    time_column : str, optional
        CSV: the column holding the time stamps (default ``time``; without it, the first of
        :data:`TIME_CANDIDATES` present: ``%time`` of ``rostopic echo -p``, ``__time``,
        ``timestamp``, ``Time``, ``field.header.stamp``, ``header.stamp``).
    time_unit : {"s", "ms", "us", "ns"}, optional
        CSV: the unit of the time column.  Default: seconds for a ``time`` column; for another
        column, nanoseconds when its values are whole numbers more than 1000 apart (ROS stamps),
        else seconds; the choice is stated in ``Demonstrations.notes``.
    split_repetitions : True or float, optional
        C3D, BVH: cut a continuous take (walking, hopping, serves one after the other) into the
        repetitions of its movement: ``True`` finds the period from the take's autocorrelation, a
        number gives it in seconds (:func:`interprim.datasets._split.find_repetitions`); what was
        found is stated in ``Demonstrations.notes``.  Pieces left by ``split_gap``, ``split_events``
        or ``split_repetitions`` that are shorter than ``min_frames`` are left out with one warning.
    split_frames : str or sequence of (int, int), optional
        C3D, BVH: the demonstrations as frame ranges ``"FIRST-LAST,FIRST-LAST"`` (inclusive; C3D
        frames numbered as the capture software numbers them, BVH frames from 0).

    Returns
    -------
    Demonstrations
        The demonstrations, time stamps (seconds), column names, ``dt`` (when uniformly
        sampled), ``observed_dofs`` (from an ``observed`` entry in the file or the first of
        two ROS topics), labels (``demo`` values, file names, NPZ keys, bag start times) and
        ``units`` (when the format says them).

    Raises
    ------
    DataNotFoundError
        If ``path`` does not exist (also a ``FileNotFoundError``).
    DataFileError
        For a malformed file: missing ``time`` column, unknown columns, non-numeric cells,
        missing values, non-increasing time, too few frames, inconsistent columns, a damaged
        or truncated recording, a missing topic, marker or joint.
    MissingExtraError
        If the format needs an optional extra that is not installed (``interprim[mocap]``
        for C3D, ``interprim[ros]`` for ROS bags); also an ``ImportError``.
    """
    from .ros_bags import is_rosbag2_folder

    p = Path(path).expanduser()
    _check_readable(p)
    if time_unit is not None and time_unit not in TIME_UNITS:
        raise ValueError(f"time_unit must be one of {', '.join(TIME_UNITS)}, got {time_unit!r}")
    if dt is not None and not (np.isfinite(dt) and dt > 0):
        raise ValueError(f"dt must be a positive number of seconds, got {dt!r}")
    if resample_dt is not None and not (np.isfinite(resample_dt) and resample_dt > 0):
        raise ValueError(f"resample_dt must be a positive number of seconds, got {resample_dt!r}")
    if bvh_mode is not None and bvh_mode not in ("positions", "angles"):
        raise ValueError(f"bvh_mode must be 'positions' or 'angles', got {bvh_mode!r}")
    if split_gap is not None and not (np.isfinite(split_gap) and split_gap > 0):
        raise ValueError(f"split_gap must be a positive number of seconds, got {split_gap!r}")
    opts = dict(markers=markers, joints=joints, length_unit=length_unit, bvh_mode=bvh_mode, end_sites=end_sites,
                topics=topics, orientation=orientation, split_topic=split_topic, split_gap=split_gap, trim=trim,
                split_events=split_events or None, split_frames=split_frames, time_column=time_column,
                time_unit=time_unit, columns=None, split_repetitions=split_repetitions)
    if p.is_dir() and not is_rosbag2_folder(p):
        files = sorted(
            (f for f in p.iterdir() if (f.is_file() and f.suffix.lower() in _FOLDER_SUFFIXES) or is_rosbag2_folder(f)),
            key=_natural_key,
        )
        if not files:
            raise DataFileError(
                f"{p}: the folder holds no .csv or .npz files (nor recordings: .c3d, .bvh, .bag, .db3, .mcap files "
                "or rosbag2 folders)"
            )
    else:
        files = [p]
    if columns is not None and all(f.suffix.lower() == ".csv" and f.is_file() for f in files):
        opts["columns"] = columns  # parsed by the CSV reader: the columns not named may hold text
    demos, times, labels = [], [], []
    cols = None
    meta = {}
    notes = []
    all_bags = True  # bags are interpolated onto the resample_dt grid by their reader
    for f in files:
        is_bag = f.suffix.lower() in (".bag", ".db3", ".mcap") or is_rosbag2_folder(f)
        all_bags = all_bags and is_bag
        d, t, c, lab, m = _read_file(f, dt, int(max_nan_gap), int(min_frames), opts,
                                     resample_dt=resample_dt if is_bag else None)
        notes += [n for n in m.get("notes", []) if n not in notes]  # once per cause, not once per file
        if cols is None:
            cols, first = c, f
            meta = m
        elif c != cols:
            if sorted(c) == sorted(cols):
                order = [c.index(name) for name in cols]
                d = [x[:, order] for x in d]
            else:
                missing = [x for x in cols if x not in c]
                extra = [x for x in c if x not in cols]
                raise DataFileError(
                    f"{f}: columns differ from {first.name}: missing {missing}, unexpected {extra}"
                )
        demos.extend(d)
        times.extend(t)
        labels.extend(lab if len(files) == 1 else [f"{f.stem}:{x}" if len(d) > 1 else f.stem for x in lab])
    observed = None
    if meta.get("observed"):
        names = meta["observed"]
        if opts["columns"] is not None:  # the columns not selected are not read: the observed ones among those kept
            kept = set(cols)
            names = [n for n in (x.strip() for x in names.split(",")) if n in kept]
        if names:
            observed = select_columns(cols, names, where=f"{files[0]} ('observed')")
    ds = Demonstrations(
        demos=demos, times=times, columns=list(cols), dt=uniform_dt(times), observed_dofs=observed,
        name=p.stem, source=str(p), labels=labels, units=meta.get("units"), notes=notes,
    )  # fmt: skip
    if columns is not None and opts["columns"] is None:
        ds = ds.select(columns)
    if resample_dt is not None and not all_bags and sampling(ds.times, dt=resample_dt).uniform:
        ds.dt = float(resample_dt)  # already on that grid up to rounding (the rule of every command): kept as read
    elif resample_dt is not None and not all_bags:
        new_d, new_t = [], []
        # the recorded samples, so that an evaluation can build causal prefixes (evaluation.protocol)
        ds.raw = [[RawStream(np.asarray(t, dtype=np.float64), tuple(range(y.shape[1])), np.asarray(y, dtype=np.float64))]
                  for y, t in zip(ds.demos, ds.times)]
        for y, t in zip(ds.demos, ds.times):
            yy, t_new = resample_step(y, t, resample_dt)
            new_d.append(yy)
            new_t.append(t_new)
        ds.demos, ds.times, ds.dt = new_d, new_t, float(resample_dt)
    elif resample_dt is not None:
        ds.dt = float(resample_dt)
    return ds


def _fmt(v: float) -> str:
    return repr(float(v))


def save_demonstrations(path, demos, times=None, *, dt=None, columns=None, observed=None) -> Path:
    """Write demonstrations in one of the formats :func:`load_demonstrations` reads.

    The format follows ``path``: ``*.csv`` writes one CSV file (with a ``demo`` column when
    there is more than one demonstration), ``*.npz`` one NPZ archive, anything else a folder
    with one CSV file per demonstration (``demo_000.csv``, ...).  Numbers are written with
    full precision, so a round trip is exact.

    Parameters
    ----------
    path : str or Path
        Output file or folder (parent folders are created).
    demos : Demonstrations or list of ndarray, shape (T_i, D)
        The demonstrations.  A :class:`Demonstrations` also supplies ``times``,
        ``columns`` and ``observed`` unless they are given.
    times : list of ndarray, shape (T_i,), optional
        Time stamps in seconds; default ``arange(T_i) * dt``.
    dt : float, optional
        Sampling interval used when ``times`` is not given.
    columns : sequence of str, optional
        Column names (default ``dof_0``, ``dof_1``, ...).  ``time`` and ``demo`` are
        reserved.
    observed : sequence of str or int, optional
        The observed agent's columns, stored in the file (``# observed:`` comment in CSV,
        ``observed`` array in NPZ).

    Returns
    -------
    Path
        The written file or folder.
    """
    from ..core.validation import as_2d_finite, check_times

    if isinstance(demos, Demonstrations):
        times = demos.times if times is None else times
        columns = demos.columns if columns is None else columns
        if observed is None and demos.observed_dofs is not None:
            observed = [demos.columns[i] for i in demos.observed_dofs]
        dt = demos.dt if dt is None else dt
        demos = demos.demos
    if isinstance(demos, np.ndarray) and demos.ndim == 2:
        demos = [demos]
    arrs = [as_2d_finite(d, f"demos[{i}]") for i, d in enumerate(demos)]
    if not arrs:
        raise ValueError("demos is empty; nothing to save")
    D = arrs[0].shape[1]
    for i, a in enumerate(arrs):
        if a.shape[1] != D:
            raise ValueError(f"demos[{i}] has {a.shape[1]} columns, demos[0] has {D}")
    if columns is None:
        columns = [f"dof_{j}" for j in range(D)]
    columns = [str(c) for c in columns]
    if len(columns) != D:
        raise ValueError(f"columns has {len(columns)} names for {D} columns")
    bad = [c for c in columns if c in (TIME, DEMO) or not c or "," in c or c.startswith("#")]
    if bad or len(set(columns)) != D:
        raise ValueError(f"columns must be unique, non-empty, without commas and not 'time'/'demo': {columns}")
    if times is None:
        if dt is None:
            raise ValueError("give times or dt")
        times = [np.arange(a.shape[0]) * float(dt) for a in arrs]
    times = [check_times(t, a.shape[0], f"times[{i}]") for i, (t, a) in enumerate(zip(times, arrs))]
    obs_names = None
    if observed is not None:
        obs_names = [columns[i] for i in select_columns(columns, observed, where="observed")]
    p = Path(path).expanduser()
    suffix = p.suffix.lower()
    if suffix == ".npz":
        p.parent.mkdir(parents=True, exist_ok=True)
        out = {"columns": np.array(columns, dtype=str)}
        for i, (a, t) in enumerate(zip(arrs, times)):
            out[f"demo_{i:03d}"] = a
            out[f"time_{i:03d}"] = t
        if obs_names:
            out["observed"] = np.array(obs_names, dtype=str)
        np.savez(p, **out)
        return p

    def write_csv(fp: Path, items):
        with open(fp, "w", newline="", encoding="utf-8") as fh:
            fh.write("# interprim demonstrations (see docs/data-formats.md)\n")
            if obs_names:
                fh.write("# observed: " + ", ".join(obs_names) + "\n")
            multi = len(items) > 1
            fh.write(",".join(([DEMO] if multi else []) + [TIME] + columns) + "\n")
            for k, (a, t) in items:
                lead = f"{k}," if multi else ""
                for r in range(a.shape[0]):
                    fh.write(lead + _fmt(t[r]) + "," + ",".join(_fmt(v) for v in a[r]) + "\n")

    if suffix == ".csv":
        p.parent.mkdir(parents=True, exist_ok=True)
        write_csv(p, list(enumerate(zip(arrs, times))))
        return p
    if p.exists() and not p.is_dir():
        raise ValueError(f"{p} exists and is not a folder; use a .csv or .npz name to write a file")
    p.mkdir(parents=True, exist_ok=True)
    for i, (a, t) in enumerate(zip(arrs, times)):
        write_csv(p / f"demo_{i:03d}.csv", [(i, (a, t))])
    return p

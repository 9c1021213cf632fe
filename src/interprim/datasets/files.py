"""Reading and writing users' own demonstrations (see ``docs/data-formats.md``).

:func:`load_demonstrations` chooses the reader of a file by its suffix (and, for a ``.csv`` file, its first
bytes: an OptiTrack Motive export) among the readers of :mod:`interprim.datasets.formats`, one module per
format behind one interface with typed options: CSV and NPZ files, motion capture (C3D, Qualisys TSV, Motive
CSV, BVH) and ROS bags.  A folder is read file by file; all files must have the same columns.
:func:`save_demonstrations` writes CSV or NPZ.
"""

from __future__ import annotations

import os
import re
from dataclasses import fields
from pathlib import Path

import numpy as np

from ..core.errors import DataFileError
from ..core.preprocessing import resample_step
from ._base import DataNotFoundError, Demonstrations, RawStream, sampling, select_columns, uniform_dt
from ._checks import MAX_RESAMPLED_FRAMES, MAX_RESAMPLED_VALUES, check_grid  # noqa: F401 - documented names
from .formats import OPTION_TYPES, READERS, Common, Reader, Table, reader_for
from .formats.csvfile import CSV_LIMITS, TIME_CANDIDATES, TIME_UNITS  # noqa: F401 - documented names
from .formats.npzfile import MAX_NPZ_ARRAY_BYTES  # noqa: F401 - documented name

__all__ = ["load_demonstrations", "save_demonstrations", "resampled", "median_interval"]

TIME = "time"
DEMO = "demo"
#: suffixes of the files a folder is read for
RECORDING_SUFFIXES = (".c3d", ".bvh", ".bag", ".db3", ".mcap", ".tsv")
_FOLDER_SUFFIXES = (".csv", ".npz") + RECORDING_SUFFIXES


def _natural_key(p: Path):
    return [int(s) if s.isdigit() else s for s in re.split(r"(\d+)", p.name)]


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


def _options(kwargs: dict) -> dict:
    """The typed options (:data:`~.formats.OPTION_TYPES`) of ``load_demonstrations``'s keyword arguments."""
    return {T: T(**{f.name: kwargs[f.name] for f in fields(T) if f.name in kwargs}) for T in OPTION_TYPES}


def _given(kwargs: dict) -> list:
    """The names of the format options that were given (not left at their defaults)."""
    return [k for k, v in kwargs.items() if v is not None and v is not False]


def _module_order(reader) -> int:
    """A reader's place in :data:`~.formats.MODULES` (messages list the formats in one order)."""
    from .formats import MODULES

    name = reader.__module__.rsplit(".", 1)[-1]
    return MODULES.index(name) if name in MODULES else len(MODULES)


def _read_file(p: Path, common: Common, kwargs: dict) -> Table:
    """``p`` read by its format's reader, after refusing the options that reader does not take."""
    cls = reader_for(p)
    if cls is None:
        known = list(dict.fromkeys(s for r in sorted(READERS, key=_module_order) for s in r.suffixes))
        raise DataFileError(
            f"{p}: unsupported file type {p.suffix!r}; expected {', '.join(known)}, a rosbag2 folder or a folder of "
            "such files (other formats: convert them to CSV, see docs/data-formats.md)"
        )
    accepted = cls.accepts()
    for name in _given(kwargs):
        if name not in accepted:
            fmts = [r.name for r in sorted(READERS, key=_module_order) if name in r.accepts()]
            raise DataFileError(f"{p}: the option {name}= applies to {', '.join(dict.fromkeys(fmts))} files, not to "
                                f"this {cls.name} file")
    from ._checks import check_column_names

    opts = _options(kwargs)
    table = cls().read(p, common, {T: opts[T] for T in cls.takes})
    check_column_names(table.columns, str(p))  # names from the file end up in CSV headers (predictions)
    return table


def _seconds(name: str, value) -> None:
    """Refuse an interval option that is not a positive, finite number of seconds (one line on the command line)."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise DataFileError(f"{name} must be a positive number of seconds, got {value!r}") from None
    if not (np.isfinite(v) and v > 0):
        why = "" if np.isfinite(v) else " (not a finite number)"
        raise DataFileError(f"{name} must be a positive number of seconds, got {value!r}{why}")


def load_demonstrations(
    path,
    *,
    columns=None,
    dt: float | None = None,
    resample_dt: float | None = None,
    max_nan_gap: int | None = None,
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
    min_marker_coverage: float | None = None,
    keep_partial: bool = False,
    options=(),
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
    max_nan_gap : int, optional
        Longest interior run of missing values (per column) that is filled by linear
        interpolation.  Default: 0 for CSV, NPZ, BVH and ROS bags (any missing value is an
        error); for marker files (C3D, Qualisys TSV, Motive CSV) gaps of up to 0.1 s
        (:data:`interprim.datasets._gaps.DEFAULT_GAP_SECONDS`: 10 frames at 100 Hz), and what is
        left is refused with one table of the markers, their missing share and longest gap
        (:mod:`interprim.datasets._gaps`).  Missing values at the start or end of a
        demonstration are never filled (see ``trim``).
    min_frames : int
        Fewest frames a demonstration may have (default 5).
    markers : sequence of str or str, optional
        C3D, Qualisys TSV, Motive CSV: the markers to keep (default all seen in at least
        ``min_marker_coverage`` of the frames).
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
        message in either stream; in a take (CSV, NPZ, C3D, BVH, TSV, Motive CSV), a run of frames in which every column
        moves slower than 5 % of the take's 95th-percentile speed, or in which a value is missing
        (:func:`interprim.datasets._split.split_take`).
    trim : bool
        Every take format: drop the leading and trailing frames (of each demonstration) in which a
        marker or channel is missing (written as 0,0,0, with a negative residual, or ``nan``).
    split_events : True or str or sequence of str, optional
        C3D, Qualisys TSV: each of the file's events (``True``: every event; else the event labels, or
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
        CSV, NPZ, C3D, BVH, Qualisys TSV, Motive CSV: cut a continuous take (walking, hopping,
        serves one after the other) into the
        repetitions of its movement: ``True`` finds the period from the take's autocorrelation, a
        number gives it in seconds (:func:`interprim.datasets._split.find_repetitions`); what was
        found is stated in ``Demonstrations.notes``.  Pieces left by ``split_gap``, ``split_events``
        or ``split_repetitions`` that are shorter than ``min_frames`` are left out with one warning.
    min_marker_coverage : float, optional
        Marker files: a marker seen in fewer than this share of the take's frames is left out,
        with one warning listing them (default 0.5; 0 keeps every marker; markers named with
        ``markers`` are always kept).
    keep_partial : bool
        With ``split_events``: also keep the piece after the last event, which runs to the end
        of the recording and is not a whole cycle (left out by default, said in ``notes``).
    options : option instance or sequence of them, optional
        The format options as the readers take them (:mod:`interprim.datasets.formats`):
        ``TakeOptions(split_gap=1.0)``, ``MarkerOptions(markers=["A:RHand"])``, ``CsvOptions``,
        ``BvhOptions``, ``RosOptions``; the same as the keyword arguments of their fields.
    split_frames : str or sequence of (int, int), optional
        Every take format: the demonstrations as frame ranges ``"FIRST-LAST,FIRST-LAST"`` (inclusive;
        C3D, TSV and Motive frames numbered as the capture software numbers them, BVH frames and the
        rows of each CSV/NPZ demonstration from 0).

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
    # the options' errors are DataFileErrors (also ValueErrors): the command line reports them in one line
    if time_unit is not None and time_unit not in TIME_UNITS:
        raise DataFileError(f"time_unit must be one of {', '.join(TIME_UNITS)}, got {time_unit!r}")
    for name, value in (("dt", dt), ("resample_dt", resample_dt), ("split_gap", split_gap)):
        if value is not None:
            _seconds(name, value)
    if split_repetitions is not None and not isinstance(split_repetitions, (bool, np.bool_, str)):
        _seconds("split_repetitions (the period)", split_repetitions)
    if bvh_mode is not None and bvh_mode not in ("positions", "angles"):
        raise DataFileError(f"bvh_mode must be 'positions' or 'angles', got {bvh_mode!r}")
    if min_marker_coverage is not None and not (0.0 <= float(min_marker_coverage) <= 1.0):
        raise DataFileError(f"min_marker_coverage must be a share of frames in [0, 1], got {min_marker_coverage!r}")
    kwargs = dict(markers=markers, joints=joints, length_unit=length_unit, bvh_mode=bvh_mode, end_sites=end_sites,
                  topics=topics, orientation=orientation, split_topic=split_topic, split_gap=split_gap, trim=trim,
                  split_events=split_events or None, split_frames=split_frames, time_column=time_column,
                  time_unit=time_unit, split_repetitions=split_repetitions, min_marker_coverage=min_marker_coverage,
                  keep_partial=keep_partial)
    for o in (options,) if not isinstance(options, (list, tuple)) else options:  # typed options, as the readers take
        if type(o) not in OPTION_TYPES:
            raise TypeError(f"options: expected instances of {', '.join(t.__name__ for t in OPTION_TYPES)}, got {o!r}")
        for fld in fields(o):
            value = getattr(o, fld.name)
            if value == fld.default:
                continue
            if fld.name == "columns":
                columns = value if columns is None else columns
                continue
            if kwargs.get(fld.name) not in (None, False, value):
                raise ValueError(f"{fld.name} is given twice: {kwargs[fld.name]!r} and {value!r} ({type(o).__name__})")
            kwargs[fld.name] = value
    if p.is_dir() and not is_rosbag2_folder(p):
        files = sorted(
            (f for f in p.iterdir() if (f.is_file() and f.suffix.lower() in _FOLDER_SUFFIXES) or is_rosbag2_folder(f)),
            key=_natural_key,
        )
        if not files:
            raise DataFileError(
                f"{p}: the folder holds no .csv or .npz files (nor recordings: .c3d, .bvh, .tsv, .bag, .db3, .mcap "
                "files or rosbag2 folders)"
            )
    else:
        files = [p]
    # parsed by the CSV reader when every file is a plain CSV file: the columns not named may hold text
    parse_columns = columns is not None and all(f.is_file() and "columns" in (reader_for(f) or Reader).accepts()
                                                for f in files)
    if parse_columns:
        kwargs["columns"] = columns
    demos: list[np.ndarray] = []
    times: list[np.ndarray] = []
    labels: list[str] = []
    cols: list[str] | None = None
    meta: dict = {}
    notes: list[str] = []
    all_bags = True  # bags are interpolated onto the resample_dt grid by their reader
    raw: list | None = []  # every file's recorded samples, or None once a file has none
    for f in files:
        is_bag = f.suffix.lower() in (".bag", ".db3", ".mcap") or is_rosbag2_folder(f)
        all_bags = all_bags and is_bag
        common = Common(dt=dt, max_nan_gap=None if max_nan_gap is None else int(max_nan_gap),
                        min_frames=int(min_frames), resample_dt=resample_dt if is_bag else None)
        d, t, c, lab, m = _read_file(f, common, kwargs)
        notes += [n for n in m.get("notes", []) if n not in notes]  # once per cause, not once per file
        r = m.get("raw")  # the samples as recorded, when the reader interpolated them (a bag on a grid)
        if cols is None:
            cols, first = c, f
            meta = m
        elif c != cols:
            if sorted(c) == sorted(cols):
                order = [c.index(name) for name in cols]
                d = [x[:, order] for x in d]
                r = None if r is None else [[s.select(order) for s in streams] for streams in r]
            else:
                missing = [x for x in cols if x not in c]
                extra = [x for x in c if x not in cols]
                raise DataFileError(
                    f"{f}: columns differ from {first.name}: missing {missing}, unexpected {extra}"
                )
        demos.extend(d)
        times.extend(t)
        raw = None if raw is None or r is None else raw + list(r)
        labels.extend(lab if len(files) == 1 else [f"{f.stem}:{x}" if len(d) > 1 else f.stem for x in lab])
    assert cols is not None  # set by the first file (there is at least one)
    observed = None
    if meta.get("observed"):
        names = meta["observed"]
        if parse_columns:  # the columns not selected are not read: the observed ones among those kept
            kept = set(cols)
            names = [n for n in (x.strip() for x in names.split(",")) if n in kept]
        if names:
            observed = select_columns(cols, names, where=f"{files[0]} ('observed')")
    ds = Demonstrations(
        demos=demos, times=times, columns=list(cols), dt=uniform_dt(times), observed_dofs=observed,
        name=p.stem, source=str(p), labels=labels, units=meta.get("units"), notes=notes, raw=raw or None,
    )  # fmt: skip
    if columns is not None and not parse_columns:
        ds = ds.select(columns)
    if resample_dt is not None and not all_bags:
        ds = resampled(ds, resample_dt, min_frames=int(min_frames))
    elif resample_dt is not None:
        ds.dt = float(resample_dt)
    return ds


def median_interval(times) -> float:
    """The median interval (s) of all the stamps of ``times`` (a list of arrays): the grid irregular stamps are
    resampled onto when no interval is given (the rule of :func:`interprim.models.base.uniform_demonstrations`)."""
    return float(np.median(np.concatenate([np.diff(np.asarray(t, dtype=np.float64)) for t in times])))


def resampled(ds: Demonstrations, dt: float, min_frames: int | None = None) -> Demonstrations:
    """``ds`` linearly interpolated onto a uniform grid of interval ``dt`` (s), its recorded samples kept in ``raw``
    (so that an evaluation builds causal prefixes); stamps already on that grid up to rounding are kept as read.
    A grid of more than :data:`MAX_RESAMPLED_FRAMES` frames, or of fewer than ``min_frames``, is refused before it
    is allocated."""
    from ..core.preprocessing import step_count

    if sampling(ds.times, dt=dt).uniform:
        ds.dt = float(dt)
        return ds
    for i, (y, t) in enumerate(zip(ds.demos, ds.times)):
        duration = float(t[-1] - t[0])
        count = duration / float(dt)
        n = int(min(count, 1e18)) + 1 if np.isfinite(count) else 2**62  # bounded before step_count's int()
        if n <= MAX_RESAMPLED_FRAMES:
            n = step_count(duration, dt)
        label = ds.labels[i] if ds.labels and i < len(ds.labels) else str(i)
        check_grid(n, np.shape(y)[1], duration, dt, min_frames, f"{ds.source}, demonstration {label!r}")
    new_d, new_t = [], []
    # the recorded samples, so that an evaluation can build causal prefixes (model_selection.prefixes)
    ds.raw = [[RawStream(np.asarray(t, dtype=np.float64), tuple(range(y.shape[1])), np.asarray(y, dtype=np.float64))]
              for y, t in zip(ds.demos, ds.times)]
    for y, t in zip(ds.demos, ds.times):
        yy, t_new = resample_step(y, t, dt)
        new_d.append(yy)
        new_t.append(t_new)
    ds.demos, ds.times, ds.dt = new_d, new_t, float(dt)
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
    from ..core.validation import as_demonstrations, check_times

    if isinstance(demos, Demonstrations):
        times = demos.times if times is None else times
        columns = demos.columns if columns is None else columns
        if observed is None and demos.observed_dofs is not None:
            observed = [demos.columns[i] for i in demos.observed_dofs]
        dt = demos.dt if dt is None else dt
        demos = demos.demos
    if isinstance(demos, np.ndarray) and demos.ndim == 2:
        demos = [demos]
    arrs = as_demonstrations(demos)
    D = arrs[0].shape[1]
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
        np.savez(p, allow_pickle=False, **out)  # float and text arrays only: the same file, and no pickle
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

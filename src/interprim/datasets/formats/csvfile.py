"""CSV files: a header row of column names, then one row per frame (``docs/data-formats.md``).

A ``time`` column (seconds, strictly increasing within a demonstration) is required unless ``dt`` is given
(or another time column is found: :data:`TIME_CANDIDATES`).  An optional ``demo`` column labels the
demonstration each row belongs to; rows of one demonstration must be contiguous.  Every other column is a
degree of freedom (numbers; an empty cell, ``nan`` or ``NA`` is a missing value).  Lines starting with ``#``
are comments; ``# observed: a, b`` names the observed agent's columns, ``# units: m`` (one unit, or one per
column) the columns' units.  The file is streamed line by line, within :data:`CSV_LIMITS`.
"""

from __future__ import annotations

import csv
import math
import os
import re
from pathlib import Path
from typing import Any

import numpy as np

from ...core.errors import DataFileError
from .._checks import check_frames, check_stamps, fill_nans, number
from .base import Common, CsvOptions, Reader, Table, TakeOptions, register
from .takes import split_table

__all__ = ["CsvReader", "CSV_LIMITS", "TIME_CANDIDATES", "TIME_UNITS", "read_csv"]

TIME = "time"
DEMO = "demo"
_MISSING = {"", "nan", "NaN", "NAN", "NA", "N/A", "na", "null", "None"}


# --------------------------------------------------------------------------- CSV limits
#: Limits of the CSV reader, checked while reading (the file is streamed, never held whole). Raise one with
#: its environment variable (e.g. ``INTERPRIM_CSV_MAX_COLUMNS=500000``) or by assigning to this dict.
CSV_LIMITS = {"max_line_chars": 64 * 2**20, "max_columns": 1_000_000, "max_bytes": 8 * 2**30}
_LIMIT_ENV = {"max_line_chars": "INTERPRIM_CSV_MAX_LINE_CHARS", "max_columns": "INTERPRIM_CSV_MAX_COLUMNS",
              "max_bytes": "INTERPRIM_CSV_MAX_BYTES"}


def csv_limit(name: str) -> int:
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
        f"{path}: {what} ({value}) exceeds the CSV reader's limit {name}={csv_limit(name)}; if the file is "
        f"right, raise it with the environment variable {_LIMIT_ENV[name]}=N"
    )


def _looks_like_data(header) -> bool:
    """Whether a header line is a line of data: every cell a number, and not all of them plain whole numbers (0, 1,
    2, ... are column names as a data frame without names writes them)."""
    try:
        [number(h) for h in header]  # a number as the data's cells are read
    except ValueError:
        return False
    return not all(re.fullmatch(r"\d+", h) for h in header)


def bounded_lines(fh, path, max_chars):
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
_ROS_BOOKKEEPING = re.compile(
    r"(^|[./])(header[./](seq|frame_id|stamp([./](secs|nsecs|sec|nanosec))?)|child_frame_id)$")


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
                      "nanoseconds (as ROS stamps are); pass time_unit= to say otherwise")
    median = float(np.median(steps)) if steps.size else 0.0
    return 1.0, (f"time column {name!r}: taken as seconds (median step {median:.3g}); "
                 "pass time_unit= to say otherwise")


def read_csv(path: Path, dt, max_nan_gap, min_frames, time_column=None, time_unit=None, columns=None, fill=True):
    """Parse one CSV file into (demos, times, columns, labels, meta), streaming it line by line.

    ``columns`` (names or indices of the data columns) restricts what is parsed: the other columns may
    hold text.  Checks as it reads: :data:`CSV_LIMITS`.
    """
    from collections import Counter

    from .._base import select_columns, shown_names

    size = path.stat().st_size
    if size > csv_limit("max_bytes"):
        raise _over(path, "the file's size", f"{size} bytes", "max_bytes")
    max_chars = csv_limit("max_line_chars")
    max_cols = csv_limit("max_columns")
    if csv.field_size_limit() < max_chars:  # one cell may be as long as a line (the module's default is 128 KiB)
        csv.field_size_limit(max_chars)
    meta: dict[str, Any] = {}
    header = None
    header_line = 0
    with open(path, newline="", encoding="utf-8-sig") as fh:
        reader = csv.reader(bounded_lines(fh, path, max_chars))
        try:
            for cells in reader:  # the comments and the header
                if not cells or all(not c.strip() for c in cells):
                    continue
                if cells[0].lstrip().startswith("#"):
                    text = ",".join(cells).lstrip()[1:]
                    if ":" in text:
                        k, v = text.split(":", 1)
                        meta[k.strip().lower()] = v.strip()
                        meta.setdefault("comment_lines", {})[k.strip().lower()] = reader.line_num
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
            empty = next(i for i, h in enumerate(header) if not h)
            raise DataFileError(f"{path}, line {header_line}: empty column name in the header (column {empty + 1} of "
                                f"{n_cols}: {shown_names(header)})")
        if _looks_like_data(header):  # no header line: the first frame would be taken as names and lost
            raise DataFileError(f"{path}, line {header_line}: the first line is numbers ({shown_names(header)}), not "
                                "column names: a CSV file starts with a header line naming its columns (e.g. "
                                "time,x,y)")
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
                    "Name the time column with time_column=, add a time column, or pass dt for "
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
        order: list[str] = []
        groups: dict[str, tuple[list[int], list[list[float]], list[float]]] = {}  # label -> (lines, rows, times)
        last = None

        def num(cell, line, col, allow_missing):
            s = cell.strip()
            if s in _MISSING:
                if not allow_missing:
                    raise DataFileError(f"{path}, line {line}: missing value in column {col!r}")
                return math.nan
            try:
                v = number(s)  # not float: it reads 1_0 as 10
            except ValueError:
                hint = ("" if columns is not None or not allow_missing  # the time column has no such hint
                        else "; choose the numeric columns with columns=")
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
        t: np.ndarray
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
        if fill:
            y = fill_nans(y, max_nan_gap, lambda d, _w=where_demo: f"{_w}, column {data_cols[d]!r}", row_of)
        demos.append(y)
        meta.setdefault("lines", []).append(lines)
        times.append(t)
        labels.append(label if i_demo is not None else path.stem)
    if columns is not None:
        meta["selected"] = True
    units_line = meta.pop("comment_lines", {}).get("units")
    meta["units"] = _units(path, units_line, meta.get("units"), [h for h in header if h not in skip], data_cols)
    return demos, times, data_cols, labels, meta


def _units(path, line, text, file_columns, columns):
    """``# units:`` of a CSV file (line ``line``): one unit for every column, or one per data column of the file
    (comma-separated, in the order of the header), of which those of ``columns`` are kept; another number of
    units is refused (ignoring it would leave the columns without units, or with the wrong ones)."""
    if not text:
        return None
    parts = [u.strip() for u in str(text).split(",")]
    if len(parts) == 1:
        return [parts[0]] * len(columns)
    if len(parts) != len(file_columns):
        raise DataFileError(f"{path}, line {line}: '# units: {str(text)[:80]}' names {len(parts)} units for the "
                            f"{len(file_columns)} data columns; give one unit for all of them or one per data column, "
                            "in the order of the header")
    unit = dict(zip(file_columns, parts))
    return [unit.get(c) for c in columns]


@register
class CsvReader(Reader):
    """CSV files (also ``rostopic echo -p`` and ``ros2 bag``/PlotJuggler exports); a take in it may be split."""

    name = "CSV"
    suffixes = (".csv",)
    takes = (CsvOptions, TakeOptions)

    def read(self, path: Path, common: Common, options: dict) -> Table:
        """Read ``path`` (see :meth:`Reader.read`)."""
        o, take = options[CsvOptions], options[TakeOptions]
        splitting = take != TakeOptions()
        demos, times, cols, labels, meta = read_csv(path, common.dt, int(common.max_nan_gap or 0), common.min_frames,
                                                    time_column=o.time_column, time_unit=o.time_unit,
                                                    columns=o.columns, fill=not splitting)
        lines = meta.pop("lines", None)
        meta.setdefault("units", None)
        table = Table(demos, times, cols, labels, meta)
        if splitting:
            table = split_table(path, table, take, common, row_name="line", numbers=lines)
        return table

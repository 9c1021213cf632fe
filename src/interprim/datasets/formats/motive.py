"""OptiTrack Motive CSV exports.

The export (OptiTrack's documentation, "Data Export: CSV") starts with a line of ``key,value`` pairs
(``Format Version``, ``Take Name``, ``Capture Frame Rate``, ``Export Frame Rate``, ``Total Exported Frames``,
``Rotation Type``, ``Length Units``, ...), then rows describing each column: ``Type`` (Rigid Body, Rigid Body
Marker, Marker, Bone, Bone Marker), ``Name``, ``ID``, a row naming the quantity (Rotation, Position, Mean Marker
Error, Marker Quality) and the row ``Frame,Time (Seconds),X,Y,Z,...``; then one row per frame.  A marker hidden
in a frame is a blank cell.  Read: every ``Position`` (``<name>_x/_y/_z``, metres), the rotations and quality
columns left out, with the gap rule of every marker file (:mod:`interprim.datasets._gaps`).
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from ...core.errors import DataFileError, DataFileWarning
from .._checks import not_utf8, number, whole_number
from .base import Common, MarkerOptions, Reader, Table, TakeOptions, register
from .csvfile import bounded_lines, csv_limit
from .takes import read_marker_take

__all__ = ["MotiveCsvReader", "read_motive_csv"]

_UNITS = {"meters": "m", "millimeters": "mm", "centimeters": "cm", "m": "m", "mm": "mm", "cm": "cm"}
MAX_BYTES = 8 * 2**30


def _parse(path):
    """The first line's ``key,value`` pairs, the description rows, the ``Frame,...`` row and the frame rows."""
    max_chars = csv_limit("max_line_chars")
    if csv.field_size_limit() < max_chars:  # one cell may be as long as a line (the module's default is 128 KiB)
        csv.field_size_limit(max_chars)
    with open(path, encoding="utf-8-sig", newline="") as fh:
        reader = csv.reader(bounded_lines(fh, path, max_chars))
        try:
            first = next(reader)
        except StopIteration:
            raise DataFileError(f"{path}: empty file") from None
        info = {first[i].strip(): first[i + 1].strip() for i in range(0, len(first) - 1, 2)}
        desc, header, rows = {}, None, []
        for cells in reader:
            line = reader.line_num
            if header is None:
                if not cells or not any(c.strip() for c in cells):
                    continue
                if cells[0].strip() == "Frame":
                    header = (line, [c.strip() for c in cells])
                    continue
                label = cells[1].strip() if len(cells) > 1 and not cells[0].strip() else ""
                desc[label or "quantity"] = [c.strip() for c in cells]
                continue
            if not cells or not any(c.strip() for c in cells):
                continue
            rows.append((line, cells))
    return info, desc, header, rows


def read_motive_csv(path: Path, *, markers=None, length_unit=None, max_nan_gap=None, min_frames=5, split=None,
                    min_marker_coverage=None):
    """Read one Motive CSV export; ``(demos, times, columns, labels, meta)`` as the other readers return."""
    from ..mocap_c3d import marker_take, metres_per_unit

    path = Path(path)
    if path.stat().st_size > MAX_BYTES:
        raise DataFileError(f"{path}: over the reader's limit of {MAX_BYTES} bytes")
    try:
        info, desc, header, rows = _parse(path)
    except UnicodeDecodeError:
        raise not_utf8(path, "Motive CSV") from None
    except csv.Error as exc:
        raise DataFileError(f"{path}: not a readable Motive CSV text file ({exc})") from None
    if header is None:
        raise DataFileError(f"{path}: no 'Frame,Time (Seconds),...' row; expected an OptiTrack Motive CSV export "
                            "with its header")
    n_cols = len(header[1])
    kinds, names, quantity = desc.get("Type"), desc.get("Name"), desc.get("quantity")
    if kinds is None or names is None or quantity is None:
        raise DataFileError(f"{path}: the header lacks the Type, Name or Position rows of a Motive CSV export")
    rate_text = info.get("Export Frame Rate") or info.get("Capture Frame Rate")
    try:
        rate = float(rate_text if rate_text is not None else "")  # no entry is refused as an empty one is
    except ValueError:
        raise DataFileError(f"{path}: line 1 has no Export Frame Rate (got {rate_text!r})") from None
    if not (np.isfinite(rate) and rate > 0):
        raise DataFileError(f"{path}: the export frame rate must be positive, got {rate!r}")
    unit = length_unit or _UNITS.get(info.get("Length Units", "Meters").strip().lower())
    if unit is None:
        raise DataFileError(f"{path}: unknown Length Units {info.get('Length Units')!r}; pass length_unit=")
    scale = metres_per_unit(unit, str(path), "Length Units")
    picked, columns, seen = [], [], set()
    count: dict[tuple, int] = {}
    renamed: dict[str, list] = {}
    for j in range(2, n_cols):
        q = quantity[j] if j < len(quantity) else ""
        axis = header[1][j].strip().lower()
        if q != "Position" or axis not in ("x", "y", "z"):
            continue
        name = names[j] if j < len(names) else ""
        kind = (kinds[j] if j < len(kinds) else "").replace(" ", "")
        nth = count[(name, axis)] = count.get((name, axis), 0) + 1
        given = name
        if (name, axis) in seen:  # a Rigid Body Marker and a Marker of one name: the type tells them apart
            name = f"{kind}:{given}"
        if (name, axis) in seen:  # two of one type and name: numbered in the order of the columns
            name = f"{kind}:{given}#{nth}"
            while (name, axis) in seen:
                nth += 1
                name = f"{kind}:{given}#{nth}"
            renamed.setdefault(given, []).append(name)
        seen.add((name, axis))
        picked.append(j)
        columns.append(f"{name}_{axis}")
    if renamed:
        from .._checks import warn

        shown = "; ".join(f"{given!r} as {', '.join(dict.fromkeys(new))}" for given, new in renamed.items())
        warn(f"{path}: several bodies or markers of one type share a name; their columns are numbered in the "
             f"order of the file: {shown}", DataFileWarning)
    if not picked:
        raise DataFileError(f"{path}: no Position columns (Rigid Body, Marker, Bone) in the export")
    if not rows:
        raise DataFileError(f"{path}: no frames after the header (line {header[0]})")
    data = np.full((len(rows), len(picked)), np.nan)
    frames = []
    for r, (line, cells) in enumerate(rows):
        if len(cells) < n_cols:
            cells = cells + [""] * (n_cols - len(cells))
        frame = whole_number(cells[0])
        if frame is None:
            raise DataFileError(f"{path}, line {line}: frame number {cells[0][:40]!r} is not a whole number")
        frames.append(frame)
        for k, j in enumerate(picked):
            c = cells[j].strip()
            if c:
                try:
                    data[r, k] = number(c)
                except ValueError:
                    raise DataFileError(f"{path}, line {line}: non-numeric value {c[:40]!r} in column "
                                        f"{columns[k]!r}") from None
    if np.isinf(data).any():
        raise DataFileError(f"{path}: infinite coordinate")
    y = data * scale
    if markers is not None:
        wanted = [m.strip() for m in markers.split(",")] if isinstance(markers, str) else [str(m) for m in markers]
        have = list(dict.fromkeys(c[:-2] for c in columns))
        unknown = [m for m in wanted if m not in have]
        if unknown:
            raise DataFileError(f"{path}: unknown marker(s) {unknown} (markers=); the file's bodies and markers are: "
                                f"{', '.join(have[:40])}")
        idx = [columns.index(f"{m}_{a}") for m in wanted for a in ("x", "y", "z") if f"{m}_{a}" in columns]
        y, columns = y[:, idx], [columns[i] for i in idx]
    if np.any(np.diff(frames) != 1):
        k = int(np.argmax(np.diff(frames) != 1)) + 1
        raise DataFileError(f"{path}, line {rows[k][0]}: frame {frames[k]} after frame {frames[k - 1]}; the frames "
                            "must follow one another")
    return marker_take(path, y, columns, rate, frames[0], named=markers is not None, max_nan_gap=max_nan_gap,
                       min_frames=min_frames, split=split, min_marker_coverage=min_marker_coverage)


@register
class MotiveCsvReader(Reader):
    """OptiTrack Motive CSV exports: a ``.csv`` whose first cell is ``Format Version``."""

    name = "Motive CSV"
    suffixes = (".csv",)
    takes = (MarkerOptions, TakeOptions)
    priority = 10

    @classmethod
    def sniff(cls, path: Path, head: bytes) -> bool:
        """Whether ``path`` is of this format (see :meth:`Reader.sniff`)."""
        return head.lstrip(b"\xef\xbb\xbf").startswith(b"Format Version,")

    def read(self, path: Path, common: Common, options: dict) -> Table:
        """Read ``path`` (see :meth:`Reader.read`)."""
        return read_marker_take(read_motive_csv, path, common, options)

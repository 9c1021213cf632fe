"""Qualisys Track Manager (QTM) 3D motion data exported as TSV.

The export (QTM's documentation, "Motion data (.tsv)") is tab-separated text: a header of one variable a line
(``NO_OF_FRAMES``, ``NO_OF_CAMERAS``, ``NO_OF_MARKERS``, ``FREQUENCY``, ``DATA_INCLUDED 3D``, ``EVENT <name>
<frame> <time>`` lines, ``MARKER_NAMES`` followed by the names, ``TRAJECTORY_TYPES``, ...), then, in files of
version 2 and later, a row of column names (``Frame``, ``Time``, ``<marker> X``, ``<marker> Y``, ``<marker> Z``),
then one row per frame.  Positions are in millimetres; a marker not seen in a frame is written as ``0`` in its
three coordinates (or left empty).  Read as markers ``<marker>_x/_y/_z`` in metres, with the gap rule of every
marker file (:mod:`interprim.datasets._gaps`) and the file's events for ``split_events``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...core.errors import DataFileError, DataFileWarning
from .._checks import not_utf8, number, whole_number
from .base import Common, MarkerOptions, Reader, Table, TakeOptions, register
from .csvfile import bounded_lines, csv_limit
from .takes import read_marker_take

__all__ = ["QualisysTsvReader", "read_qualisys_tsv"]

_KEYS = ("NO_OF_FRAMES", "NO_OF_CAMERAS", "NO_OF_MARKERS", "FREQUENCY", "MARKER_NAMES", "FILE_VERSION")
#: bytes of a TSV file read at most (as the CSV reader's default)
MAX_BYTES = 8 * 2**30


def _number(path, line_no, key, text):
    try:
        return number(text.strip())
    except ValueError:
        raise DataFileError(f"{path}, line {line_no}: {key} must be a number, got {text!r}") from None


def _parse(path):
    """The header variables, events, marker names, row of column names and data rows ``(line, cells)`` of a TSV."""
    header, events, names, col_names = {}, [], None, None
    rows, first_data = [], None
    with open(path, encoding="utf-8-sig", errors="strict", newline="") as fh:
        for n, raw in enumerate(bounded_lines(fh, path, csv_limit("max_line_chars")), start=1):
            line = raw.rstrip("\r\n")
            if not line.strip():
                continue
            cells = line.split("\t")
            key = cells[0].strip()
            if first_data is None and key.upper() == key and key[:1].isalpha() and key not in ("Frame",):
                if key == "MARKER_NAMES":
                    names = [c.strip() for c in cells[1:] if c.strip()]
                elif key == "EVENT":
                    if len(cells) >= 4:
                        events.append(("", cells[1].strip(), _number(path, n, "EVENT time", cells[3])))
                else:
                    header[key] = (n, cells[1].strip() if len(cells) > 1 else "")
                continue
            if first_data is None and key == "Frame":
                col_names = [c.strip() for c in cells]
                continue
            if first_data is None:
                first_data = n
            rows.append((n, cells))
    return header, events, names, col_names, rows


def read_qualisys_tsv(path: Path, *, markers=None, length_unit=None, max_nan_gap=None, min_frames=5, split=None,
                      min_marker_coverage=None):
    """Read one QTM 3D TSV export; ``(demos, times, columns, labels, meta)`` as the other readers return."""
    from .._checks import warn
    from ..mocap_c3d import marker_take, metres_per_unit

    path = Path(path)
    size = path.stat().st_size
    if size > MAX_BYTES:
        raise DataFileError(f"{path}: {size} bytes, over the TSV reader's limit of {MAX_BYTES} bytes")
    try:
        parsed = _parse(path)
    except UnicodeDecodeError:
        raise not_utf8(path, "Qualisys TSV") from None
    header, events, names, col_names, rows = parsed
    frames = []
    if names is None:
        raise DataFileError(f"{path}: no MARKER_NAMES line; expected a Qualisys 3D TSV export with its header "
                            "(QTM: Project options > TSV export > Include TSV header)")
    if "FREQUENCY" not in header:
        raise DataFileError(f"{path}: no FREQUENCY line in the header")
    rate = _number(path, header["FREQUENCY"][0], "FREQUENCY", header["FREQUENCY"][1])
    if not (np.isfinite(rate) and rate > 0):
        raise DataFileError(f"{path}, line {header['FREQUENCY'][0]}: FREQUENCY must be positive, got {rate!r}")
    dup = sorted({m for m in names if names.count(m) > 1})
    if dup:
        raise DataFileError(f"{path}: duplicate marker name(s) {dup} in MARKER_NAMES")
    M = len(names)
    lead = 0
    if col_names is not None:
        lead = sum(1 for c in col_names[:2] if c in ("Frame", "Time"))
    if not rows:
        raise DataFileError(f"{path}: no frames after the header")
    data = np.full((len(rows), 3 * M), np.nan)
    for r, (n, cells) in enumerate(rows):
        cells = [c.strip() for c in cells]
        while cells and cells[-1] == "" and len(cells) > lead + 3 * M:
            cells.pop()
        if r == 0 and col_names is None and len(cells) == 3 * M + 2:
            lead = 2  # Frame and Time without a row of column names
        if len(cells) != lead + 3 * M:
            raise DataFileError(f"{path}, line {n}: {len(cells)} cells, expected {lead + 3 * M} ({lead} frame/time "
                                f"and 3 for each of the {M} markers of MARKER_NAMES)")
        frame = whole_number(cells[0]) if lead else r + 1
        if frame is None:
            raise DataFileError(f"{path}, line {n}: frame number {cells[0][:40]!r} is not a whole number")
        frames.append(frame)
        for j, c in enumerate(cells[lead:]):
            if c in ("", "NaN", "nan", "-"):
                continue
            try:
                data[r, j] = number(c)
            except ValueError:
                raise DataFileError(f"{path}, line {n}: non-numeric value {c[:40]!r} for marker "
                                    f"{names[j // 3]!r}") from None
    declared = header.get("NO_OF_FRAMES")
    if declared is not None:
        want = whole_number(declared[1])
        if want is None or want < 0:
            raise DataFileError(f"{path}, line {declared[0]}: NO_OF_FRAMES must be a whole number of frames, got "
                                f"{declared[1][:40]!r}")
        if len(rows) < want:
            warn(f"{path}: NO_OF_FRAMES announces {want} frames but the file holds {len(rows)}; keeping those",
                 DataFileWarning)
    xyz = data.reshape(len(rows), M, 3)
    xyz[np.all(xyz == 0, axis=2)] = np.nan  # QTM writes a marker not seen as 0, 0, 0
    if np.isinf(xyz).any():
        raise DataFileError(f"{path}: infinite coordinate")
    scale = metres_per_unit(length_unit, str(path), "length_unit") if length_unit is not None else 1e-3
    columns = [f"{m}_{a}" for m in names for a in ("x", "y", "z")]
    y = xyz.reshape(len(rows), 3 * M) * scale
    if markers is not None:
        wanted = [m.strip() for m in markers.split(",")] if isinstance(markers, str) else [str(m) for m in markers]
        unknown = [m for m in wanted if m not in names]
        if unknown:
            raise DataFileError(f"{path}: unknown marker(s) {unknown} (markers=); the file's markers are: "
                                f"{', '.join(names[:40])}")
        idx = [3 * names.index(m) + k for m in wanted for k in range(3)]
        y, columns = y[:, idx], [columns[i] for i in idx]
    first = frames[0]
    if np.any(np.diff(frames) != 1):
        k = int(np.argmax(np.diff(frames) != 1)) + 1
        raise DataFileError(f"{path}, line {rows[k][0]}: frame {frames[k]} after frame {frames[k - 1]}; the frames "
                            "must follow one another")
    # QTM numbers EVENT times from the first frame of the measurement (frame 1 at time 0), as C3D events
    return marker_take(path, y, columns, rate, first, named=markers is not None, max_nan_gap=max_nan_gap,
                       min_frames=min_frames, split=split, min_marker_coverage=min_marker_coverage, events=events)


@register
class QualisysTsvReader(Reader):
    """Qualisys QTM 3D TSV exports (``.tsv``)."""

    name = "Qualisys TSV"
    suffixes = (".tsv",)
    takes = (MarkerOptions, TakeOptions)

    def read(self, path: Path, common: Common, options: dict) -> Table:
        """Read ``path`` (see :meth:`Reader.read`)."""
        return read_marker_take(read_qualisys_tsv, path, common, options)

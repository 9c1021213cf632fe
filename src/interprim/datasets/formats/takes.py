"""Splitting the takes of a table format (CSV, NPZ): each demonstration read is a take that the splitting
options cut (:func:`interprim.datasets._split.cut_take`, the rule of the motion-capture readers too)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...core.errors import DataFileError
from .base import Common, MarkerOptions, Table, TakeOptions

__all__ = ["split_table", "split_dict", "read_marker_take"]


def read_marker_take(load, path: Path, common: Common, options: dict) -> Table:
    """The :class:`Table` of a marker file (C3D, Qualisys TSV, OptiTrack Motive CSV) read by its loader ``load``
    (``read_c3d``, ...) with the marker options, the common gap and length limits and the take's splitting."""
    o = options[MarkerOptions]
    return Table(*load(path, markers=o.markers, length_unit=o.length_unit, max_nan_gap=common.max_nan_gap,
                       min_frames=common.min_frames, split=split_dict(options[TakeOptions]),
                       min_marker_coverage=o.min_marker_coverage))


def split_dict(take: TakeOptions) -> dict:
    """The ``split`` argument of :func:`~interprim.datasets._split.cut_take` for ``take``."""
    return dict(trim=bool(take.trim), events=take.split_events or None, ranges=take.split_frames,
                gap=take.split_gap, repetitions=take.split_repetitions, keep_partial=bool(take.keep_partial))


def split_table(path: Path, table: Table, take: TakeOptions, common: Common, *, row_name: str = "row",
                numbers=None) -> Table:
    """Cut every demonstration of ``table`` (a take each) by ``take``; gaps filled after cutting.

    Frames are numbered from 0 within each demonstration of the file (``split_frames``); messages name a row by
    ``row_name`` and ``numbers[i][k]`` (CSV: the file's line) when given.
    """
    from .._split import cut_take

    if take.split_events:
        raise DataFileError(f"{path}: split_events applies to files that carry events (C3D, Qualisys TSV); cut this "
                            "take with split_gap=, split_repetitions= or split_frames=")
    demos: list[np.ndarray] = []
    times: list[np.ndarray] = []
    labels: list[str] = []
    notes = list(table.meta.get("notes", []))
    multi = len(table.demos) > 1
    for i, (y, t) in enumerate(zip(table.demos, table.times)):
        where = f"{path}" + (f", demo {table.labels[i]!r}" if multi else "")
        rows = numbers[i] if numbers is not None else None

        def where_col(d, _w=where):
            return f"{_w}, column {table.columns[d]!r}"

        def row_of(k, _rows=rows):
            return f"{row_name} {_rows[k]}" if _rows is not None else f"{row_name} {k}"

        split = split_dict(take)
        d, tt, lab = cut_take(Path(where) if not multi else Path(path), y, np.asarray(t, dtype=np.float64),
                              np.arange(len(t)), split, max_nan_gap=int(common.max_nan_gap or 0),
                              min_frames=common.min_frames, where_col=where_col, row_of=row_of,
                              names=table.columns)
        notes += [n for n in split.get("notes", []) if n not in notes]
        demos += d
        times += tt
        base = table.labels[i]
        labels += [f"{base}@{x.split('@', 1)[1]}" if "@" in x else base for x in lab] if multi else lab
    meta = dict(table.meta)
    meta["notes"] = notes
    return Table(demos, times, table.columns, labels, meta)

"""Missing markers in motion-capture takes (C3D, Qualisys TSV, OptiTrack Motive CSV): the one rule of every
marker reader.

Real recordings are never complete: a marker hidden for a few frames, a probe marker never seen, a marker
lost at the end of the capture.  Three steps, in this order:

1. **Sparse markers are left out.**  A marker seen (all three coordinates) in fewer than
   :data:`DEFAULT_MIN_COVERAGE` of the take's frames (``min_marker_coverage``) is left out, with one
   warning listing every such marker and its share.  Markers named with ``markers=`` are never left out.
2. **Short gaps are filled** by linear interpolation between the frames on either side (``numpy.interp``,
   per coordinate): by default gaps of up to :data:`DEFAULT_GAP_SECONDS` (rounded to frames at the file's
   rate, at least one frame: 10 frames at 100 Hz, 12 at 120 Hz), or ``max_nan_gap`` frames when given.
   A run at the start or end of a demonstration has no frame on one side and is never filled.
3. **What is left is refused** with one error holding a table (marker, missing share, longest gap and where)
   and the options that fix it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.errors import DataFileError, DataFileWarning

__all__ = ["DEFAULT_GAP_SECONDS", "DEFAULT_MIN_COVERAGE", "MarkerSet", "default_max_gap", "drop_sparse",
           "fill_runs", "GapReport"]

#: Gaps of up to this many seconds are filled by default in marker files (0.1 s: 10 frames at 100 Hz).
DEFAULT_GAP_SECONDS = 0.1
#: By default a marker seen in fewer than this share of a take's frames is left out (with a warning).
DEFAULT_MIN_COVERAGE = 0.5


def default_max_gap(rate: float) -> int:
    """Frames filled by default at ``rate`` frames per second: :data:`DEFAULT_GAP_SECONDS`, at least 1."""
    return max(1, int(round(DEFAULT_GAP_SECONDS * float(rate))))


@dataclass(frozen=True)
class MarkerSet:
    """The markers of a take: one name and the column indices (x, y, z) of each."""

    names: tuple
    groups: tuple

    @classmethod
    def of_columns(cls, columns, axes=("_x", "_y", "_z")) -> MarkerSet:
        """Markers from column names ``<marker>_x/_y/_z`` (a column of another name is a marker alone)."""
        names, groups, index = [], [], {}
        for j, c in enumerate(columns):
            base = next((c[: -len(a)] for a in axes if c.endswith(a)), c)
            if base not in index:
                index[base] = len(names)
                names.append(base)
                groups.append([])
            groups[index[base]].append(j)
        return cls(tuple(names), tuple(tuple(g) for g in groups))

    def missing(self, y) -> np.ndarray:
        """``(T, M)``: whether marker ``m`` misses a coordinate at frame ``t``."""
        bad = np.isnan(y)
        return np.stack([bad[:, list(g)].any(axis=1) for g in self.groups], axis=1) if self.groups else bad[:, :0]


def _pct(x: float) -> str:
    return f"{100 * x:.3g} %"


def drop_sparse(path, y, columns, markers: MarkerSet, min_coverage, named: bool, frames: str = "frames"):
    """Leave out the markers seen in fewer than ``min_coverage`` of the frames (one warning); ``(y, columns)``.

    ``named``: the user chose the markers, none is left out.  Every marker sparse: a :class:`DataFileError`
    with the table of :class:`GapReport`.
    """
    from ._checks import warn

    if named or not markers.names or not min_coverage or y.shape[0] == 0:
        return y, columns
    seen = 1.0 - markers.missing(y).mean(axis=0)
    low = [m for m in range(len(markers.names)) if seen[m] < min_coverage]
    if not low:
        return y, columns
    T = y.shape[0]
    if len(low) == len(markers.names):
        rep = GapReport(path, markers, T)
        rep.add(markers.missing(y), np.arange(T), edges=True)
        exc = DataFileError(
            f"{path}: every marker is seen in fewer than {_pct(min_coverage)} of the {T} {frames} "
            f"(min_marker_coverage={min_coverage:g}):\n{rep.table()}\n" + rep.fixes())
        exc.multiline = True
        raise exc
    shown = ", ".join(f"{markers.names[m]} ({'never seen' if seen[m] == 0 else 'seen in ' + _pct(seen[m])})"
                      for m in low[:30]) + (f", ... ({len(low)} in all)" if len(low) > 30 else "")
    warn(f"{path}: {len(low)} of {len(markers.names)} markers left out, seen in fewer than {_pct(min_coverage)} "
         f"of the {T} {frames}: {shown}; keep them with markers= (naming them) or min_marker_coverage=0",
         DataFileWarning)
    keep = sorted(j for m in range(len(markers.names)) if m not in set(low) for j in markers.groups[m])
    return y[:, keep], [columns[j] for j in keep]


def fill_runs(y, max_gap: int):
    """``y`` with every interior run of at most ``max_gap`` missing frames (per column) filled by linear
    interpolation (``numpy.interp`` between the frames on either side); the other missing values stay NaN."""
    bad = np.isnan(y)
    if not bad.any() or max_gap <= 0:
        return y
    y = y.copy()
    T = y.shape[0]
    for d in np.flatnonzero(bad.any(axis=0)):
        for i, j in _runs(bad[:, d]):
            if i > 0 and j < T and j - i <= max_gap:
                y[i:j, d] = np.interp(np.arange(i, j), [i - 1, j], [y[i - 1, d], y[j, d]])
    return y


def _runs(col):
    """``[(start, stop)]`` (stop excluded) of the True runs of a boolean vector."""
    edges = np.flatnonzero(np.diff(np.concatenate(([0], col.astype(np.int8), [0]))))
    return [(int(a), int(b)) for a, b in edges.reshape(-1, 2)]  # each run: where it starts, where it stops


class GapReport:
    """Per marker, the frames still missing after filling, over every demonstration of a take."""

    def __init__(self, path, markers: MarkerSet, n_frames: int, rate: float | None = None, max_gap: int = 0,
                 numbers=None, named: bool = False):
        self.path, self.markers, self.T = path, markers, int(n_frames)
        self.named = bool(named)  # the user named the markers: none is left out by coverage
        self.rate, self.max_gap = rate, int(max_gap)
        self.numbers = numbers
        M = len(markers.names)
        self.count = np.zeros(M, dtype=np.int64)
        self.longest = [(0, 0, 0, False)] * M  # (length, first number, last number, at an edge)

    def add(self, missing, numbers, edges: bool = True):
        """Count the ``(T_piece, M)`` missing frames of one demonstration whose rows are numbered ``numbers``."""
        n = missing.shape[0]
        for m in range(missing.shape[1]):
            col = missing[:, m]
            if not col.any():
                continue
            self.count[m] += int(col.sum())
            for i, j in _runs(col):
                if j - i > self.longest[m][0]:
                    self.longest[m] = (j - i, int(numbers[i]), int(numbers[j - 1]), i == 0 or j == n)

    @property
    def bad(self) -> list:
        return [m for m in range(len(self.markers.names)) if self.count[m]]

    def _secs(self, n: int) -> str:
        return f" ({n / self.rate:.3g} s)" if self.rate else ""

    def table(self, limit: int = 25) -> str:
        """The markers with missing frames: name, share missing, longest gap and where (a fixed-width table)."""
        rows = [("marker", "missing", "longest gap")]
        order = sorted(self.bad, key=lambda m: (-self.count[m], m))
        for m in order[:limit]:
            n, a, b, edge = self.longest[m]
            if self.count[m] >= self.T and n >= self.T:
                where = f"all {self.T} frames (never seen)"
            else:
                where = (f"{n} frames{self._secs(n)}, frames {a}-{b}" if n > 1 else f"1 frame, frame {a}")
                where += " (at the start or end: not filled)" if edge else ""
            rows.append((self.markers.names[m], _pct(self.count[m] / max(self.T, 1)), where))
        w0 = max(len(r[0]) for r in rows)
        w1 = max(len(r[1]) for r in rows)
        lines = [f"  {a:<{w0}}  {b:>{w1}}  {c}" for a, b, c in rows]
        if len(order) > limit:
            lines.append(f"  ... and {len(order) - limit} more markers")
        return "\n".join(lines)

    def fixes(self) -> str:
        """The options that fix the gaps of the table, one per line (only those that would)."""
        bad = self.bad
        never = [m for m in bad if self.count[m] >= self.T]
        some = [m for m in bad if m not in set(never)]
        interior = [self.longest[m][0] for m in some if not self.longest[m][3]]
        complete = [n for m, n in enumerate(self.markers.names) if m not in set(bad)]
        shown = ",".join(complete[:12]) + ("..." if len(complete) > 12 else "")
        lines = ["what fixes it:"]
        if never:
            lines.append(f"  markers=...: leave out {', '.join(self.markers.names[m] for m in never[:12])} (never seen)"
                         + (f"; complete markers: {shown}" if complete else ""))
        if interior:
            need = max(interior)
            lines.append(f"  max_nan_gap={need}: fill gaps of up to {need} frames{self._secs(need)} by linear "
                         "interpolation")
        if any(self.longest[m][3] for m in some):
            lines.append("  trim=True: cut the frames at the start and end of each demonstration in which a marker "
                         "is missing")
        if some and not never:
            lines.append("  markers=...: keep only the markers you need" + (f" (complete ones: {shown})" if complete
                                                                              else ""))
        if some and not self.named:
            share = max(self.count[m] for m in some) / max(self.T, 1)
            lines.append(f"  min_marker_coverage=...: leave out the markers missing in more than that share of the "
                         f"frames (e.g. min_marker_coverage={min(0.99, max(0.5, 1 - share / 2)):.2g})")
        return "\n".join(lines)

    def error(self, where_fill: str) -> DataFileError:
        bad = self.bad
        exc = DataFileError(
            f"{self.path}: {len(bad)} of {len(self.markers.names)} markers still miss frames after {where_fill}:\n"
            f"{self.table()}\n{self.fixes()}")
        exc.multiline = True  # the command line prints it as it is, not joined into one line
        return exc

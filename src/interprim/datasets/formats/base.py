"""The interface every file format's reader implements, its typed options and the registry of readers.

A reader is one class in one module of this package: it names the file suffixes it reads (and, when a suffix
is shared, how to recognise its files from their first bytes), the option types it takes, and a ``read``
method returning a :class:`Table`.  :func:`~interprim.datasets.load_demonstrations` chooses the reader,
refuses options the reader does not take (from the fields of the option types it names) and joins the
tables of a folder.  A new format is one module that defines a :class:`Reader` and registers it with
:func:`register`.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any, ClassVar

__all__ = ["Common", "TakeOptions", "CsvOptions", "MarkerOptions", "BvhOptions", "RosOptions", "Table", "Reader",
           "register", "READERS", "reader_for", "OPTION_TYPES"]


@dataclass(frozen=True)
class Common:
    """Options every reader takes.

    Attributes
    ----------
    dt : float or None
        Sampling interval (s) of files without time stamps.
    max_nan_gap : int or None
        Longest run of missing frames (per column) filled by linear interpolation; ``None``: the format's
        default (0 for CSV, NPZ, BVH and ROS bags; :data:`~interprim.datasets._gaps.DEFAULT_GAP_SECONDS` of
        frames for motion-capture marker files).
    min_frames : int
        Fewest frames a demonstration may have.
    resample_dt : float or None
        ROS bags: the uniform grid both streams are interpolated onto.
    """

    dt: float | None = None
    max_nan_gap: int | None = None
    min_frames: int = 5
    resample_dt: float | None = None


@dataclass(frozen=True)
class TakeOptions:
    """How one continuous take is cut into demonstrations (:func:`interprim.datasets._split.split_take`).

    Taken by every reader of a take (CSV, NPZ, C3D, BVH, Qualisys TSV, OptiTrack Motive CSV); ``split_gap`` is
    also read by the ROS bag reader (a pause without messages).
    """

    trim: bool = False
    split_gap: float | None = None
    split_frames: Any = None
    split_repetitions: Any = None
    split_events: Any = None
    keep_partial: bool = False


@dataclass(frozen=True)
class CsvOptions:
    """CSV files: the time column, its unit, the columns parsed."""

    time_column: str | None = None
    time_unit: str | None = None
    columns: Any = None


@dataclass(frozen=True)
class MarkerOptions:
    """Marker files (C3D, Qualisys TSV, OptiTrack Motive CSV): which markers, their unit, which are left out."""

    markers: Any = None
    length_unit: str | None = None
    min_marker_coverage: float | None = None


@dataclass(frozen=True)
class BvhOptions:
    """BVH files."""

    bvh_mode: str | None = None
    joints: Any = None
    length_unit: str | None = None
    end_sites: bool = False


@dataclass(frozen=True)
class RosOptions:
    """ROS bags."""

    topics: Any = None
    joints: Any = None
    orientation: bool = False
    split_topic: str | None = None
    split_gap: float | None = None


#: every option type, in the order their fields are shown
OPTION_TYPES = (TakeOptions, CsvOptions, MarkerOptions, BvhOptions, RosOptions)


@dataclass
class Table:
    """What a reader returns: demonstrations ``(T_i, D)``, their time stamps (s), the column names, one label per
    demonstration and what the format says besides (``units``, ``observed`` names, ``notes`` for the user,
    ``selected`` when ``columns`` were parsed by the reader itself)."""

    demos: list
    times: list
    columns: list
    labels: list
    meta: dict = field(default_factory=dict)

    def __iter__(self):  # (demos, times, columns, labels, meta), as the readers returned before
        return iter((self.demos, self.times, self.columns, self.labels, self.meta))


class Reader:
    """One file format.  Subclasses set the class attributes and implement :meth:`read`.

    Attributes
    ----------
    name : str
        How messages call the format ("CSV", "C3D", "ROS bag").
    suffixes : tuple of str
        Lower-case file suffixes the format uses.
    takes : tuple of type
        The option types (:data:`OPTION_TYPES`) the reader takes; options of other types left at their
        defaults are ignored, given ones are refused.
    priority : int
        Among readers of one suffix, the one with the highest priority whose :meth:`sniff` accepts the file
        reads it (a specific export before the generic format).
    """

    name: ClassVar[str] = ""
    suffixes: ClassVar[tuple] = ()
    takes: ClassVar[tuple] = ()
    priority: ClassVar[int] = 0
    folder: ClassVar[bool] = False  # whether it reads a folder (a rosbag2 folder)

    @classmethod
    def sniff(cls, path: Path, head: bytes) -> bool:
        """Whether the file (first 4 KiB ``head``) is of this format; the default accepts every file of a suffix."""
        return True

    @classmethod
    def accepts(cls) -> set:
        """The option names the reader takes."""
        return {f.name for t in cls.takes for f in fields(t)}

    def read(self, path: Path, common: Common, options: dict) -> Table:  # pragma: no cover - interface
        """Read ``path``; ``options`` maps each type of :attr:`takes` to its instance."""
        raise NotImplementedError


#: registered readers, in registration order
READERS: list = []


def register(cls):
    """Class decorator: add a :class:`Reader` to :data:`READERS`."""
    READERS.append(cls)
    return cls


def _head(path: Path) -> bytes:
    try:
        with open(path, "rb") as fh:
            return fh.read(4096)
    except OSError:
        return b""


def reader_for(path: Path):
    """The reader class of ``path`` (by suffix, then by content among readers of one suffix), or ``None``."""
    from . import load_all

    load_all()
    p = Path(path)
    if p.is_dir():
        for cls in READERS:
            if cls.folder and cls.sniff(p, b""):
                return cls
        return None
    suffix = p.suffix.lower()
    cands = sorted((c for c in READERS if suffix in c.suffixes), key=lambda c: -c.priority)
    if not cands:
        return None
    head = _head(p) if len(cands) > 1 else b""
    for cls in cands:
        if len(cands) == 1 or cls.sniff(p, head):
            return cls
    return cands[-1]



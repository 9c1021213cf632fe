"""C3D motion-capture files (:mod:`interprim.datasets.mocap_c3d`; needs ``interprim[mocap]``)."""

from __future__ import annotations

from pathlib import Path

from .base import Common, MarkerOptions, Reader, Table, TakeOptions, register
from .takes import split_dict

__all__ = ["C3dReader"]


@register
class C3dReader(Reader):
    """C3D files: markers ``<marker>_x/_y/_z`` in metres; events may split the take."""

    name = "C3D"
    suffixes = (".c3d",)
    takes = (MarkerOptions, TakeOptions)

    def read(self, path: Path, common: Common, options: dict) -> Table:
        """Read ``path`` (see :meth:`Reader.read`)."""
        from ..mocap_c3d import read_c3d

        o = options[MarkerOptions]
        return Table(*read_c3d(path, markers=o.markers, length_unit=o.length_unit, max_nan_gap=common.max_nan_gap,
                               min_frames=common.min_frames, split=split_dict(options[TakeOptions]),
                               min_marker_coverage=o.min_marker_coverage))

"""C3D motion-capture files (:mod:`interprim.datasets.mocap_c3d`; needs ``interprim[mocap]``)."""

from __future__ import annotations

from pathlib import Path

from .base import Common, MarkerOptions, Reader, Table, TakeOptions, register
from .takes import read_marker_take

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

        return read_marker_take(read_c3d, path, common, options)

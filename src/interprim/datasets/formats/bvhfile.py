"""BVH motion-capture files (:mod:`interprim.datasets.mocap_bvh`)."""

from __future__ import annotations

from pathlib import Path

from ...core.errors import DataFileError
from .base import BvhOptions, Common, Reader, Table, TakeOptions, register
from .takes import split_dict

__all__ = ["BvhReader"]


@register
class BvhReader(Reader):
    """BVH files: joint world positions (forward kinematics) or joint angles."""

    name = "BVH"
    suffixes = (".bvh",)
    takes = (BvhOptions, TakeOptions)

    def read(self, path: Path, common: Common, options: dict) -> Table:
        """Read ``path`` (see :meth:`Reader.read`)."""
        from ..mocap_bvh import read_bvh

        o, take = options[BvhOptions], options[TakeOptions]
        if take.split_events:
            raise DataFileError(f"{path}: split_events applies to files that carry events (C3D, Qualisys TSV), not "
                                "to this BVH file")
        return Table(*read_bvh(path, mode=o.bvh_mode or "positions", joints=o.joints, length_unit=o.length_unit,
                               end_sites=bool(o.end_sites), max_nan_gap=int(common.max_nan_gap or 0),
                               min_frames=common.min_frames, split=split_dict(take)))

"""ROS 1 and ROS 2 bags (:mod:`interprim.datasets.ros_bags`; needs ``interprim[ros]``)."""

from __future__ import annotations

from pathlib import Path

from .base import Common, Reader, RosOptions, Table, register

__all__ = ["RosbagReader"]


@register
class RosbagReader(Reader):
    """``.bag`` (ROS 1), ``.db3``/``.mcap`` (ROS 2) or a rosbag2 folder holding ``metadata.yaml``."""

    name = "ROS bag"
    suffixes = (".bag", ".db3", ".mcap")
    takes = (RosOptions,)
    folder = True

    @classmethod
    def sniff(cls, path: Path, head: bytes) -> bool:
        """Whether ``path`` is of this format (see :meth:`Reader.sniff`)."""
        from ..ros_bags import is_rosbag2_folder

        return path.suffix.lower() in cls.suffixes or is_rosbag2_folder(path)

    def read(self, path: Path, common: Common, options: dict) -> Table:
        """Read ``path`` (see :meth:`Reader.read`)."""
        from ..ros_bags import read_rosbag

        o = options[RosOptions]
        return Table(*read_rosbag(path, topics=o.topics, joints=o.joints, orientation=bool(o.orientation),
                                  split_topic=o.split_topic, split_gap=o.split_gap, grid_dt=common.resample_dt,
                                  max_nan_gap=int(common.max_nan_gap or 0), min_frames=common.min_frames))

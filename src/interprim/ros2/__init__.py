"""Live on ROS 2: the partner's topics in, the model's predicted response out (``interprim ros2``).

Needs ``pip install 'interprim[ros2]'`` (``cyclonedds``, which speaks ROS 2's DDS wire protocol, and ``rosbags``,
whose ROS 2 message definitions give the types); no ROS 2 installation.  See docs/ros2.md.
"""

from .bridge import BridgeConfigError, QosSpec, Ros2Bridge, loopback_config
from .grid import GridStep, StampGrid
from .observe import ObservationError, Source, parse_observe

__all__ = ["Ros2Bridge", "BridgeConfigError", "QosSpec", "loopback_config", "StampGrid", "GridStep", "Source",
           "parse_observe",
           "ObservationError"]

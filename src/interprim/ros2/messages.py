"""ROS 2 message types on the DDS wire, made from ``rosbags``' message definitions.

ROS 2 (with the Cyclone DDS middleware, ``rmw_cyclonedds_cpp``) puts a message of type ``pkg/msg/Type`` on the
DDS topic ``rt/<topic name>`` with the DDS type name ``pkg::msg::dds_::Type_``, serialised as classic (XCDR1)
CDR.  This module builds, for any ROS 2 message type that ``rosbags`` defines (its ROS 2 Humble store; the
field layout of these common types is the same in Jazzy), a ``cyclonedds`` IDL struct with that name and those
fields, so that ``cyclonedds`` writes and reads the bytes a ROS 2 node writes and reads.  The field definitions
come from ``rosbags``; the serialisation is ``cyclonedds``' own; nothing here encodes CDR by hand.

Needs the optional extra ``pip install 'interprim[ros2]'`` (``cyclonedds`` and ``rosbags``).
"""

from __future__ import annotations

import keyword
import math
from functools import cache, lru_cache

from ..core.errors import MissingExtraError

__all__ = ["dds_topic", "dds_type_name", "message_class", "new_message", "known_type", "stamp_seconds",
           "stamp_of", "SHORT_TYPES"]

_HINT = "ROS 2 topics need the optional extra: pip install 'interprim[ros2]' (cyclonedds and rosbags)"

#: short names accepted for the common message types
SHORT_TYPES = {
    "PointStamped": "geometry_msgs/msg/PointStamped",
    "PoseStamped": "geometry_msgs/msg/PoseStamped",
    "TransformStamped": "geometry_msgs/msg/TransformStamped",
    "TFMessage": "tf2_msgs/msg/TFMessage",
    "JointState": "sensor_msgs/msg/JointState",
    "Odometry": "nav_msgs/msg/Odometry",
    "JointTrajectory": "trajectory_msgs/msg/JointTrajectory",
    "Path": "nav_msgs/msg/Path",
    "PoseArray": "geometry_msgs/msg/PoseArray",
    "DiagnosticArray": "diagnostic_msgs/msg/DiagnosticArray",
}


def _imports():
    try:
        import cyclonedds.idl  # noqa: F401
        import cyclonedds.idl.types  # noqa: F401
        from rosbags.typesys import Stores, get_typestore  # noqa: F401
    except ImportError as exc:
        raise MissingExtraError(f"{_HINT} ({exc})") from None


@lru_cache(maxsize=1)
def ros2_typestore():
    _imports()
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_HUMBLE)


def known_type(name: str) -> str:
    """The full ROS 2 name (``pkg/msg/Type``) of ``name`` (also a short name such as ``PointStamped``, or
    ``pkg/Type``); ``ValueError`` naming the problem for a type ``rosbags`` does not define."""
    full = SHORT_TYPES.get(name, name)
    parts = full.split("/")
    if len(parts) == 2:
        full = f"{parts[0]}/msg/{parts[1]}"
    if full not in ros2_typestore().fielddefs:
        raise ValueError(f"unknown ROS 2 message type {name!r} (give pkg/msg/Type, e.g. geometry_msgs/msg/PointStamped,"
                         f" or one of {', '.join(SHORT_TYPES)})")
    return full


def dds_type_name(msgtype: str) -> str:
    """``geometry_msgs/msg/PointStamped`` -> ``geometry_msgs::msg::dds_::PointStamped_`` (ROS 2's DDS type name)."""
    pkg, sub, name = known_type(msgtype).split("/")
    return f"{pkg}::{sub}::dds_::{name}_"


def dds_topic(topic: str) -> str:
    """``/human/hand`` -> ``rt/human/hand`` (ROS 2's DDS topic name of a topic); a bad name is a ``ValueError``."""
    t = str(topic).strip()
    if not t.startswith("/"):
        t = "/" + t
    if len(t) < 2 or any(not (c.isalnum() or c in "_/~") for c in t) or "//" in t or t.endswith("/"):
        raise ValueError(f"{topic!r} is not a ROS 2 topic name (letters, digits, '_' and '/', e.g. /human/hand)")
    return "rt" + t


def _base(types, name: str, maxlen: int):
    if name == "string":
        return types.bounded_str[maxlen] if maxlen else str
    if name == "bool":
        return bool
    # ROS 2 maps char to uint8 and byte to octet (REP 2011 / rosidl's IDL mapping)
    table = {"byte": types.byte, "char": types.uint8, "int8": types.int8, "uint8": types.uint8,
             "int16": types.int16, "uint16": types.uint16, "int32": types.int32, "uint32": types.uint32,
             "int64": types.int64, "uint64": types.uint64, "float32": types.float32, "float64": types.float64}
    if name not in table:
        raise ValueError(f"the ROS field type {name!r} has no DDS mapping here")
    return table[name]


def _field_type(types, desc):
    kind = getattr(desc[0], "name", str(desc[0]))
    if kind == "BASE":
        name, maxlen = desc[1]
        return _base(types, name, maxlen)
    if kind == "NAME":
        return message_class(desc[1])
    if kind == "ARRAY":
        sub, count = desc[1]
        return types.array[_field_type(types, sub), count]
    if kind == "SEQUENCE":
        sub, maxcount = desc[1]
        inner = _field_type(types, sub)
        return types.sequence[inner, maxcount] if maxcount else types.sequence[inner]
    raise ValueError(f"unsupported ROS field description {desc!r}")


def message_class(msgtype: str):
    """The ``cyclonedds`` IDL struct of the ROS 2 message type ``msgtype`` (named as ROS 2 names it on DDS)."""
    return _message_class(known_type(msgtype))


@cache
def _message_class(full: str):
    _imports()
    from cyclonedds.idl import make_idl_struct, types

    fields = {}
    for name, desc in ros2_typestore().fielddefs[full][1]:
        fields[name + "_" if keyword.iskeyword(name) else name] = _field_type(types, desc)
    if not fields:  # an empty ROS message carries one uint8 on the wire (rosidl's structure_needs_at_least_one_member)
        fields["structure_needs_at_least_one_member"] = types.uint8
    cls = make_idl_struct(full.split("/")[-1] + "_", dds_type_name(full), fields)
    cls.__ros_type__ = full  # type: ignore[attr-defined]  # the ROS name, read back by the bridge
    return cls


def _default(types, desc):
    kind = getattr(desc[0], "name", str(desc[0]))
    if kind == "BASE":
        name = desc[1][0]
        return "" if name == "string" else False if name == "bool" else 0.0 if name.startswith("float") else 0
    if kind == "NAME":
        return new_message(desc[1])
    if kind == "ARRAY":
        sub, count = desc[1]
        return [_default(types, sub) for _ in range(count)]
    return []


def new_message(msgtype: str, **fields):
    """A message of type ``msgtype`` with ``fields`` set and every other field zero / empty."""
    from cyclonedds.idl import types

    full = known_type(msgtype)
    cls = message_class(full)
    values = {}
    for name, desc in ros2_typestore().fielddefs[full][1]:
        key = name + "_" if keyword.iskeyword(name) else name
        values[key] = fields.pop(key) if key in fields else _default(types, desc)
    if not ros2_typestore().fielddefs[full][1]:
        values["structure_needs_at_least_one_member"] = 0
    if fields:
        raise TypeError(f"{full} has no field(s) {sorted(fields)}")
    return cls(**values)


def stamp_of(seconds: float, base_sec: int = 0):
    """A ``builtin_interfaces/msg/Time`` for ``base_sec + seconds`` since the epoch (``base_sec`` whole seconds,
    kept exact; ``seconds`` a float, rounded to the nanosecond)."""
    ns = int(base_sec) * 1_000_000_000 + int(round(float(seconds) * 1e9))
    return new_message("builtin_interfaces/msg/Time", sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def stamp_seconds(stamp, base_sec: int = 0) -> float:
    """Seconds of a ``builtin_interfaces/msg/Time`` after ``base_sec`` (NaN for a malformed one); the whole seconds
    are subtracted before the conversion to float, so nanoseconds survive."""
    try:
        s = float(int(stamp.sec) - int(base_sec)) + float(stamp.nanosec) * 1e-9
    except (AttributeError, TypeError, ValueError):
        return math.nan
    return s

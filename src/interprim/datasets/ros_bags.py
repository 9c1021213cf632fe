"""Demonstrations from ROS 1 and ROS 2 bags (``.bag``, ``.db3``, ``.mcap``, rosbag2 folders).

Needs the optional extra ``pip install 'interprim[ros]'``, which installs the pure-Python
`rosbags <https://pypi.org/project/rosbags/>`_ package (no ROS installation is needed).

What is read
------------
Each *agent* is one stream, named by a topic or a tf frame:

``sensor_msgs/msg/JointState``
    The ``position`` of every joint (or of ``joints``), one column per joint name.  A joint
    absent from a message is a missing value there.
``geometry_msgs/msg/PoseStamped`` (also ``PointStamped``, ``TransformStamped``)
    The position ``<prefix>_x``, ``_y``, ``_z`` in metres, plus the orientation quaternion
    ``<prefix>_qx``, ``_qy``, ``_qz``, ``_qw`` with ``orientation=True``.  ``<prefix>`` is the
    topic without its leading ``/`` (``/human/wrist`` -> ``human/wrist_x``).
``tf2_msgs/msg/TFMessage``
    Named ``tf:FRAME`` (on ``/tf``) or ``TOPIC:FRAME``: the translation (and with
    ``orientation=True`` the rotation) of the child frame ``FRAME`` relative to its parent,
    columns ``FRAME_x``, ... .  The parent must be the same in every message.

``tf/msg/tfMessage`` (ROS 1's old name of the same message) is read like ``TFMessage``.
``nav_msgs/msg/Odometry``, ``geometry_msgs/msg/PoseWithCovarianceStamped``
    The pose (``pose.pose``), columns as for ``PoseStamped``.
Any other message, by field paths: ``TOPIC:FIELD,FIELD,...``
    Numeric fields read by path from any message the bag's own type definitions describe
    (``/turtle1/pose:x,y``; ``pose.position.x``; ``data[2]``), columns ``<prefix>_<field>``,
    units unknown.  With a comma-separated ``topics`` string, a name without ``/`` or ``:`` after
    a field list is one more field (write further topics with their leading ``/``).

Message types come from the bag's own definitions (a ROS 1 bag always has them, rosbag2 has them
since Iron), else from ``rosbags``' latest ROS 2 types.  A topic whose definition cannot be parsed
is skipped unless it is needed; then the error names the topic, its type and what failed.

Time stamps are the messages' ``header.stamp`` (the bag's receive time for a stream whose
header stamps are all zero).  A stream is sorted by stamp; a message with the same stamp as
the one before it is skipped.

Pairing two agents
------------------
With two agents (observed, controlled), the controlled stream is linearly interpolated onto
the observed stream's stamps, or - with ``grid_dt`` - both streams onto a uniform grid of
that interval; only the time span covered by both streams is kept (no extrapolation), and
streams that do not overlap are an error.  Quaternions are sign-aligned before and
renormalised after interpolation.

Splitting
---------
``split_topic``: every message on that topic (any type, e.g. ``std_msgs/msg/Empty`` or
``String``) starts a demonstration, which lasts until the next one; data before the first
marker is not used.  ``split_gap``: a pause longer than that many seconds in either stream
ends a demonstration.  Both may be combined.  Each demonstration's time stamps start at 0.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from ..core.errors import DataFileError, DataFileWarning, MissingExtraError
from ..core.preprocessing import interp_columns, step_count
from ._base import RawStream

__all__ = ["read_rosbag", "is_rosbag2_folder", "ROS_SUFFIXES"]

ROS_SUFFIXES = (".bag", ".db3", ".mcap")
JOINT_STATE = "sensor_msgs/msg/JointState"
POSE = "geometry_msgs/msg/PoseStamped"
POINT = "geometry_msgs/msg/PointStamped"
TRANSFORM = "geometry_msgs/msg/TransformStamped"
TF = "tf2_msgs/msg/TFMessage"
TF_TYPES = (TF, "tf/msg/tfMessage")  # ROS 1's old tf name, the same layout
ODOMETRY = "nav_msgs/msg/Odometry"
POSE_COV = "geometry_msgs/msg/PoseWithCovarianceStamped"
SUPPORTED = (JOINT_STATE, POSE, POINT, TRANSFORM, ODOMETRY, POSE_COV) + TF_TYPES
_HINT = "reading ROS bags needs the optional extra: pip install 'interprim[ros]' (the rosbags package)"


def is_rosbag2_folder(p: Path) -> bool:
    """Whether ``p`` is a rosbag2 folder (it holds ``metadata.yaml``)."""
    return p.is_dir() and (p / "metadata.yaml").is_file()


def _import_rosbags():
    try:
        import rosbags.rosbag1  # noqa: F401
        import rosbags.rosbag2  # noqa: F401
        import rosbags.typesys  # noqa: F401
    except ImportError as exc:
        raise MissingExtraError(f"{_HINT} ({exc})") from None


def _closure(fielddefs, typ, out):
    """``typ`` and every type its fields use, from ``fielddefs`` (a typestore's), as a dict to register."""
    if typ in out or typ not in fielddefs:
        return out
    out[typ] = fielddefs[typ]

    def walk(node):
        if isinstance(node, str):
            if "/" in node:
                _closure(fielddefs, node, out)
        elif isinstance(node, (tuple, list)):
            for x in node:
                walk(x)

    walk(fielddefs[typ][1])
    return out


class _Bag:
    """A ROS 1 bag or rosbag2 recording opened with the types of its own definitions.

    Unlike ``rosbags.highlevel.AnyReader``, a connection whose definition cannot be parsed (e.g. a service
    event type) does not make the whole bag unreadable: its type is listed in ``unparsed`` with the
    reason, and only a topic that is read needs it.
    """

    def __init__(self, path):
        from rosbags.interfaces import MessageDefinitionFormat
        from rosbags.rosbag1 import Reader as Reader1
        from rosbags.rosbag2 import Reader as Reader2
        from rosbags.typesys import Stores, get_types_from_idl, get_types_from_msg, get_typestore

        self.path = Path(path)
        self.is2 = self.path.suffix.lower() != ".bag"
        self.reader = (Reader2 if self.is2 else Reader1)(self.path)
        self.reader.open()
        self.connections = list(self.reader.connections)
        self.unparsed = {}
        self.typestore = get_typestore(Stores.EMPTY)
        none = MessageDefinitionFormat.NONE
        defined = [c for c in self.connections if c.msgdef.format != none]
        latest = get_typestore(Stores.LATEST)
        if not defined:  # an older rosbag2 without definitions: the latest ROS 2 types
            self.typestore.register(latest.fielddefs)
        for c in defined:
            if c.msgtype in self.typestore.fielddefs or c.msgtype in self.unparsed:
                continue
            try:
                if c.msgdef.format == MessageDefinitionFormat.MSG:
                    types = get_types_from_msg(c.msgdef.data, c.msgtype)
                else:
                    sep = "=" * 80 + "\n"
                    types = {}
                    if c.msgdef.data.startswith(f"{sep}IDL: "):
                        for part in c.msgdef.data.split(sep)[1:]:
                            types.update(get_types_from_idl(part.split("\n", 1)[1]))
                    else:
                        types.update(get_types_from_idl(c.msgdef.data))
                if c.msgtype not in types:
                    raise KeyError(f"it defines {', '.join(sorted(types)) or 'nothing'}, not {c.msgtype}")
                self.typestore.register(types)
            except Exception as exc:  # noqa: BLE001 - the parsers raise several kinds
                text = exc.args[0] if isinstance(exc, KeyError) and exc.args else str(exc)
                self.unparsed[c.msgtype] = f"{type(exc).__name__}: {' '.join(str(text).split())[:200]}"

        for c in self.connections:  # a connection without a definition in a bag that has others: the latest types
            if c.msgdef.format == none and c.msgtype not in self.typestore.fielddefs:
                try:
                    self.typestore.register(_closure(latest.fielddefs, c.msgtype, {}))
                except Exception as exc:  # noqa: BLE001 - conflicts with the bag's own definitions
                    self.unparsed[c.msgtype] = f"no definition in the bag, and the known one conflicts ({exc})"

    @property
    def start_time(self):
        return int(self.reader.start_time)

    @property
    def topics(self):
        out = {}
        for c in self.connections:
            out.setdefault(c.topic, c.msgtype)
        return out

    def messages(self, connections):
        return self.reader.messages(connections=connections)

    def deserialize(self, raw, msgtype):
        if self.is2:
            return self.typestore.deserialize_cdr(raw, msgtype)
        return self.typestore.deserialize_ros1(raw, msgtype)

    def close(self):
        self.reader.close()


class _Stream:
    """One agent: where it comes from and the samples read for it."""

    def __init__(self, spec: str, role: str):
        self.spec, self.role = spec, role
        s = spec.strip()
        if s.startswith("tf:"):
            s = "/tf:" + s[3:]
        topic, _, frame = s.partition(":")
        self.topic = topic if topic.startswith("/") else "/" + topic
        self.frame = frame.strip().lstrip("/") or None  # a tf frame, or the field paths of another message
        self.fields = None
        self.msgtype = None
        self.stamps: list = []
        self.bag_times: list = []
        self.rows: list = []
        self.names: list = []  # JointState: joint names in order of appearance
        self.parent = None

    @property
    def label(self):
        return f"{self.topic}:{self.frame}" if self.frame else self.topic


def _parse_topics(topics):
    """The stream specs in ``topics`` (a list, or a comma-separated string in which a name without ``/`` or
    ``:`` that follows a ``TOPIC:FIELD`` spec is one more field: ``/a/pose:x,y,/b/pose:x,y``)."""
    if not isinstance(topics, str):
        return [str(x).strip() for x in topics if str(x).strip()]
    out = []
    for tok in (x.strip() for x in topics.split(",")):
        if not tok:
            continue
        if out and ":" in out[-1] and not out[-1].startswith("tf:") and "/" not in tok and ":" not in tok:
            out[-1] += "," + tok
        else:
            out.append(tok)
    return out


_FIELD = re.compile(r"^([A-Za-z_]\w*)((?:\[\d+\])*)$")  # one step of a field path: name, name[2], name[0][1]
_INDEX = re.compile(r"\[(\d+)\]")


def field_value(msg, path):
    """The value at ``path`` (``a.b``, ``c[2]``) of a decoded message."""
    v = msg
    for part in path.split("."):
        m = _FIELD.match(part)
        if not m:
            raise KeyError(f"{path!r} is not a field path (name.name[index])")
        v = getattr(v, m.group(1))
        for idx in _INDEX.findall(m.group(2)):
            v = v[int(idx)]
    return v


def _numeric_fields(typestore, msgtype, prefix="", depth=0):
    """Field paths of the numeric scalar fields of ``msgtype`` (for messages)."""
    out = []
    try:
        fields = typestore.fielddefs[msgtype][1]
    except Exception:  # noqa: BLE001
        return out
    for name, desc in fields:
        kind = getattr(desc, "name", None) or desc[0]
        kname = getattr(kind, "name", str(kind))
        if kname == "BASE":
            base = desc[1][0] if isinstance(desc[1], tuple) else desc[1]
            if base not in ("string", "bool"):
                out.append(prefix + name)
        elif kname == "NAME" and depth < 3:
            out += _numeric_fields(typestore, desc[1], prefix + name + ".", depth + 1)
    return out


def _stamp_ns(msg):
    h = getattr(msg, "header", None)
    if h is None:
        return None
    return int(h.stamp.sec) * 1_000_000_000 + int(h.stamp.nanosec)


def _xyz(v):
    return [float(v.x), float(v.y), float(v.z)]


def _quat(q):
    return [float(q.x), float(q.y), float(q.z), float(q.w)]


def _take(stream, msg, orientation, where):
    """The values of one message for ``stream`` (a dict for JointState, a list otherwise), or None."""
    t = stream.msgtype
    if stream.fields is not None:
        vals = []
        for f in stream.fields:
            v = field_value(msg, f)
            arr = np.asarray(v, dtype=np.float64).ravel()
            if arr.size != 1:
                raise DataFileError(f"{where}: field {f!r} holds {arr.size} values; name one, e.g. {f}[0]")
            vals.append(float(arr[0]))
        return vals, _stamp_ns(msg)
    if t == JOINT_STATE:
        names, pos = list(msg.name), np.asarray(msg.position, dtype=np.float64)
        if len(pos) != len(names):
            raise DataFileError(f"{where}: {len(names)} joint names but {len(pos)} positions")
        for n in names:
            if n not in stream.names:
                stream.names.append(n)
        return dict(zip(names, pos.tolist())), _stamp_ns(msg)
    if t == POSE:
        p = msg.pose
        return _xyz(p.position) + (_quat(p.orientation) if orientation else []), _stamp_ns(msg)
    if t == POINT:
        return _xyz(msg.point), _stamp_ns(msg)
    if t == TRANSFORM:
        tr = msg.transform
        return _xyz(tr.translation) + (_quat(tr.rotation) if orientation else []), _stamp_ns(msg)
    if t in (ODOMETRY, POSE_COV):
        p = msg.pose.pose
        return _xyz(p.position) + (_quat(p.orientation) if orientation else []), _stamp_ns(msg)
    # TFMessage: the transform whose child is stream.frame, if this message has it
    for tr in msg.transforms:
        if str(tr.child_frame_id).lstrip("/") != stream.frame:
            continue
        parent = str(tr.header.frame_id).lstrip("/")
        if stream.parent is None:
            stream.parent = parent
        elif parent != stream.parent:
            raise DataFileError(
                f"{where}: frame {stream.frame!r} has parent {parent!r} here but {stream.parent!r} before"
            )
        tf = tr.transform
        return _xyz(tf.translation) + (_quat(tf.rotation) if orientation else []), _stamp_ns(tr)
    return None, None


def _read_streams(path, streams, split_topic, orientation):
    """Read every needed message in one pass; returns (bag start ns, marker times ns)."""
    _import_rosbags()
    markers = []
    try:
        reader = _Bag(path)
    except DataFileError:
        raise
    except Exception as exc:  # noqa: BLE001 - rosbags raises many kinds on damaged files
        raise DataFileError(f"{path}: not a readable ROS bag ({type(exc).__name__}: {exc})") from None
    try:
        topics = reader.topics
        shown = ", ".join(f"{k} ({v})" for k, v in sorted(topics.items())) or "none"

        def understood(topic, what):
            why = reader.unparsed.get(topics[topic])
            if why is not None:
                raise DataFileError(
                    f"{path}: topic {topic!r} ({what}) has messages of type {topics[topic]}, whose definition in the "
                    f"bag could not be parsed ({why}); the bag itself is readable, and topics not needed are skipped"
                )

        for s in streams:
            if s.topic not in topics:
                raise DataFileError(
                    f"{path}: no topic {s.topic!r} ({s.role} agent, topics={','.join(x.spec for x in streams)}); "
                    f"the bag has: {shown}"
                )
            s.msgtype = topics[s.topic]
            understood(s.topic, f"{s.role} agent")
            if s.msgtype in TF_TYPES:
                if s.frame is None:
                    raise DataFileError(
                        f"{path}: {s.spec!r} ({s.role} agent): topic {s.topic!r} holds tf transforms; name the child "
                        f"frame as {s.topic}:FRAME or tf:FRAME"
                    )
            elif s.frame is not None:  # field paths of any message type
                s.fields = [f.strip() for f in s.frame.split(",") if f.strip()]
                s.frame = None
                for f in s.fields:
                    try:
                        check_field_path(reader.typestore, s.msgtype, f)
                    except KeyError as exc:
                        fields = _numeric_fields(reader.typestore, s.msgtype)
                        raise DataFileError(
                            f"{path}: {s.spec!r} ({s.role} agent): {exc.args[0]}; the numeric fields of "
                            f"{s.msgtype} are: {', '.join(fields) or 'none'}"
                        ) from None
            elif s.msgtype not in SUPPORTED:
                fields = _numeric_fields(reader.typestore, s.msgtype)
                raise DataFileError(
                    f"{path}: topic {s.topic!r} ({s.role} agent) has messages of type {s.msgtype}; "
                    f"expected one of {', '.join(SUPPORTED)}, or name numeric fields to read as "
                    f"{s.topic}:FIELD,FIELD" + (f" (its numeric fields: {', '.join(fields[:12])})" if fields else "")
                )
        if split_topic is not None:
            split_topic = split_topic if split_topic.startswith("/") else "/" + split_topic
            if split_topic not in topics:
                raise DataFileError(
                    f"{path}: no topic {split_topic!r} (split_topic={split_topic}); the bag has: {shown}"
                )
            understood(split_topic, "split_topic")
        wanted = {s.topic for s in streams} | ({split_topic} if split_topic else set())
        conns = [c for c in reader.connections if c.topic in wanted]
        start = int(reader.start_time)
        counts = dict.fromkeys(wanted, 0)
        for con, bag_t, raw in reader.messages(connections=conns):
            k = counts[con.topic]
            counts[con.topic] = k + 1
            where = f"{path}, topic {con.topic}, message {k} (bag time {(bag_t - start) * 1e-9:.3f} s)"
            try:
                msg = reader.deserialize(raw, topics[con.topic])
            except Exception as exc:  # noqa: BLE001
                raise DataFileError(f"{where}: cannot decode the message ({exc})") from None
            if con.topic == split_topic:
                st = _stamp_ns(msg)
                markers.append(st if st else bag_t)
            for s in streams:
                if s.topic != con.topic:
                    continue
                try:
                    vals, st = _take(s, msg, orientation, where)
                except DataFileError:
                    raise
                except Exception as exc:  # noqa: BLE001 - a message that decodes but lacks a field
                    raise DataFileError(f"{where}: unexpected message content ({exc})") from None
                if vals is not None:
                    s.rows.append(vals)
                    s.stamps.append(st)
                    s.bag_times.append(bag_t)
    except DataFileError:
        raise
    except Exception as exc:  # noqa: BLE001
        raise DataFileError(f"{path}: cannot read the bag ({type(exc).__name__}: {exc})") from None
    finally:
        try:
            reader.close()
        except Exception:  # noqa: BLE001
            pass
    return start, sorted(markers)


def check_field_path(typestore, msgtype, path):
    """Raise ``KeyError`` (with a message) unless ``path`` (``a.b``, ``c[2]``) names a field of ``msgtype`` in
    ``typestore`` (rosbags' message definitions); used by the bag loader and the ROS 2 bridge."""
    typ = msgtype
    for part in path.split("."):
        m = _FIELD.match(part)
        if not m:
            raise KeyError(f"{path!r} is not a field path (name.name[index])")
        if typ not in typestore.fielddefs:
            raise KeyError(f"the type {typ} is neither defined in the bag nor a known ROS 2 type")
        fields = dict(typestore.fielddefs[typ][1])
        if m.group(1) not in fields:
            raise KeyError(f"{typ} has no field {m.group(1)!r} (in {path!r})")
        desc = fields[m.group(1)]
        while getattr(desc[0], "name", "") in ("ARRAY", "SEQUENCE"):
            desc = desc[1][0]
        typ = desc[1] if getattr(desc[0], "name", "") == "NAME" else None


def _finish_stream(path, s, joints):
    """Turn the samples of ``s`` into (times ns, values (n, d), column names, units)."""
    if not s.rows:
        if s.msgtype in TF_TYPES:
            raise DataFileError(f"{path}: topic {s.topic!r} has no transform with child frame {s.frame!r}")
        raise DataFileError(f"{path}: topic {s.topic!r} ({s.role} agent) holds no messages")
    stamps = np.array(s.stamps, dtype=object)
    if all(st is None or st == 0 for st in s.stamps):
        t = np.array(s.bag_times, dtype=np.int64)
    else:
        zero = [i for i, st in enumerate(s.stamps) if not st]
        if zero:
            raise DataFileError(
                f"{path}, topic {s.topic}, message {zero[0]}: header stamp is zero while other messages have stamps"
            )
        t = stamps.astype(np.int64)
    if s.msgtype == JOINT_STATE:
        names = list(s.names)
        if not names:
            raise DataFileError(f"{path}: topic {s.topic!r} ({s.role} agent): the JointState messages name no joints")
        if joints is not None:
            unknown = [j for j in joints if j not in names]
            if unknown:
                raise DataFileError(
                    f"{path}: topic {s.topic!r} has no joint {unknown[0]!r} (joints={','.join(joints)}); "
                    f"its joints are: {', '.join(names)}"
                )
            names = [j for j in joints if j in names]
            if not names:
                raise DataFileError(f"{path}: topic {s.topic!r}: none of the joints {list(joints)} is on it")
        y = np.array([[r.get(n, np.nan) for n in names] for r in s.rows], dtype=np.float64).reshape(len(s.rows), -1)
        cols, units = names, [None] * len(names)
    elif s.fields is not None:
        y = np.array(s.rows, dtype=np.float64).reshape(len(s.rows), len(s.fields))
        cols = [f"{s.topic.lstrip('/')}_{f}" for f in s.fields]
        units = [None] * len(cols)
    else:
        y = np.array(s.rows, dtype=np.float64)
        prefix = s.frame if s.frame else s.topic.lstrip("/")
        axes = ["x", "y", "z"] + (["qx", "qy", "qz", "qw"] if y.shape[1] == 7 else [])
        cols = [f"{prefix}_{a}" for a in axes]
        units = ["m"] * 3 + [""] * (len(axes) - 3)
    if np.isinf(y).any():  # NaN is a missing value (filled or refused later); an infinite value is refused
        r, c = (int(v) for v in np.argwhere(np.isinf(y))[0])
        raise DataFileError(f"{path}, topic {s.topic}, message {r}: infinite value {y[r, c]} in field {cols[c]!r}")
    order = np.argsort(t, kind="stable")
    t, y = t[order], y[order]
    keep = np.concatenate([[True], np.diff(t) > 0])  # same stamp as the message before: skipped
    dropped = int((~keep).sum())
    if dropped:
        from ._checks import warn

        warn(f"{path}: topic {s.topic}: {dropped} of {len(t)} messages have the same time stamp as a message before "
             "them and are left out (the first message of each stamp is kept); check the publisher's header stamps",
             DataFileWarning)
    t, y = t[keep], y[keep]
    if s.msgtype != JOINT_STATE and s.fields is None and y.shape[1] == 7:
        q = y[:, 3:7]
        for i in range(1, len(q)):  # one hemisphere, so interpolation takes the short way
            if np.dot(q[i], q[i - 1]) < 0:
                q[i] = -q[i]
        y[:, 3:7] = q
    return t, y, cols, units


def _segments(streams_t, markers, split_gap):
    """Time intervals [a, b] (ns) of the demonstrations: :func:`._split.spans` with the streams' pauses."""
    from ._split import spans

    lo = min(int(t[0]) for t in streams_t)
    hi = max(int(t[-1]) for t in streams_t)
    cuts = []
    if split_gap is not None:
        gap_ns = split_gap * 1e9
        for t in streams_t:
            d = np.diff(t)
            cuts.extend((int(t[i]), int(t[i + 1])) for i in np.nonzero(d > gap_ns)[0])
    return spans(lo, hi, starts=markers, cuts=cuts)


#: A target time inside a pause of a source stream longer than this many of its median intervals
#: (or longer than ``split_gap``) is not interpolated but a missing value.
PAUSE_FACTOR = 5.0


def _max_step(t, split_gap):
    """Longest interval of stream stamps ``t`` (ns) that interpolation may bridge."""
    step = PAUSE_FACTOR * float(np.median(np.diff(t))) if len(t) > 1 else 0.0
    return min(step, split_gap * 1e9) if split_gap is not None else step


def _interp(t_new, t, y, max_step):
    """Linear interpolation of ``y`` (stamps ``t``) at ``t_new``; NaN inside pauses longer than ``max_step``."""
    t_new, t = np.asarray(t_new, dtype=np.float64), np.asarray(t, dtype=np.float64)
    out = interp_columns(t_new, t, y)
    i = np.clip(np.searchsorted(t, t_new, "right"), 1, max(len(t) - 1, 1))
    if len(t) > 1:
        out[(t[i] - t[i - 1] > max_step) & (t_new > t[i - 1]) & (t_new < t[i])] = np.nan
    return out


def read_rosbag(path, *, topics, joints=None, orientation=False, split_topic=None, split_gap=None, grid_dt=None,
                max_nan_gap=0, min_frames=5):
    """Read one ROS bag; returns ``(demos, times, columns, labels, meta)`` as the other readers do.

    See the module docstring and :func:`load_rosbag` for the parameters.
    """
    from ._checks import check_frames, fill_nans

    path = Path(path)
    if topics is None:
        raise DataFileError(f"{path}: a ROS bag needs topics=OBSERVED,CONTROLLED: the two agents' topics (or tf:FRAME)")
    topics = _parse_topics(topics)
    if not 1 <= len(topics) <= 2:
        raise DataFileError(f"{path}: topics must name one or two streams (observed, controlled), got {topics!r}")
    if isinstance(joints, str):
        joints = [j.strip() for j in joints.split(",") if j.strip()]
    if split_gap is not None and not (np.isfinite(split_gap) and split_gap > 0):
        raise DataFileError(f"split_gap must be a positive number of seconds, got {split_gap!r}")
    if grid_dt is not None and not (np.isfinite(grid_dt) and grid_dt > 0):
        raise DataFileError(f"resample_dt (grid_dt) must be a positive number of seconds, got {grid_dt!r}")
    streams = [_Stream(spec, role) for spec, role in zip(topics, ("observed", "controlled"))]
    if len(streams) == 2 and streams[0].label == streams[1].label:
        raise DataFileError(f"{path}: the observed and controlled agents are the same stream {streams[0].label!r}")
    start, markers = _read_streams(path, streams, split_topic, orientation)
    if split_topic is not None and not markers:
        raise DataFileError(f"{path}: the split_topic {split_topic!r} holds no messages")
    done = [_finish_stream(path, s, joints) for s in streams]
    cols = [c for _, _, c, _ in done]
    if len(done) == 2 and set(cols[0]) & set(cols[1]):  # e.g. two JointState topics with the same joint names
        cols = [[f"{s.topic.lstrip('/')}/{c}" for c in cc] if s.msgtype == JOINT_STATE else cc
                for s, cc in zip(streams, cols)]
        if set(cols[0]) & set(cols[1]):
            same = sorted(set(cols[0]) & set(cols[1]))
            raise DataFileError(f"{path}: the two agents give the same column names {same}")
    columns = cols[0] + (cols[1] if len(cols) > 1 else [])
    units = [u for _, _, _, uu in done for u in uu]
    segs = _segments([d[0] for d in done], markers, split_gap)
    max_steps = [_max_step(t, split_gap) for t, _, _, _ in done]
    demos, times, labels, raw = [], [], [], []
    offsets = np.cumsum([0] + [len(c) for c in cols])  # each stream's first column
    for k, (a, b) in enumerate(segs):
        where = f"{path}, demonstration {k} ({(a - start) * 1e-9:.3f}-{(b - start) * 1e-9:.3f} s after the bag start)"
        parts = []
        for s, (t, y, _, _), step in zip(streams, done, max_steps):
            i0, i1 = np.searchsorted(t, a, "left"), np.searchsorted(t, b, "right")
            if i1 <= i0:
                raise DataFileError(f"{where}: topic {s.label} ({s.role} agent) has no messages in it")
            # one neighbour on each side (when not across a pause) lets interpolation reach the ends
            i0 -= int(i0 > 0 and t[i0] - t[i0 - 1] <= step)
            i1 += int(i1 < len(t) and t[i1] - t[i1 - 1] <= step)
            parts.append((t[i0:i1], y[i0:i1]))
        lo = max(a, *(p[0][0] for p in parts))
        hi = min(b, *(p[0][-1] for p in parts))
        if hi < lo:
            spans = "; ".join(f"{s.label} {(p[0][0] - start) * 1e-9:.3f}-{(p[0][-1] - start) * 1e-9:.3f} s"
                              for s, p in zip(streams, parts))
            raise DataFileError(f"{where}: the streams do not overlap in time ({spans})")
        if grid_dt is not None:
            from ._checks import MAX_RESAMPLED_FRAMES, check_grid

            count = (hi - lo) / (grid_dt * 1e9)
            n = int(min(count, 1e18)) + 1 if np.isfinite(count) else 2**62  # bounded before it is allocated
            if n <= MAX_RESAMPLED_FRAMES:
                n = step_count(hi - lo, grid_dt * 1e9)
            check_grid(n, len(columns), (hi - lo) * 1e-9, grid_dt, min_frames, where)
            t_ns = lo + np.round(np.arange(n) * grid_dt * 1e9).astype(np.int64)
        else:
            t_obs = parts[0][0]
            t_ns = t_obs[(t_obs >= lo) & (t_obs <= hi)]
        blocks = []
        for i, ((t, y), step) in enumerate(zip(parts, max_steps)):
            if grid_dt is None and i == 0:  # the observed stream's own samples
                blocks.append(y[(t >= lo) & (t <= hi)])
            else:
                blocks.append(_interp(t_ns - start, t - start, y, step))
        y = np.hstack(blocks)
        for j, u in enumerate(units):  # renormalise interpolated quaternions
            if columns[j].endswith("_qx") and u == "":
                q = y[:, j:j + 4]
                y[:, j:j + 4] = q / np.linalg.norm(q, axis=1, keepdims=True)
        hint = " (a larger split_gap or fewer split_topic markers?)" if len(segs) > 1 else ""
        check_frames(len(t_ns), min_frames, where + hint)
        t_rel = (t_ns - t_ns[0]) * 1e-9

        def row_of(i, _t=t_ns):
            return f"{(_t[i] - start) * 1e-9:.3f} s after the bag start"

        y = fill_nans(y, max_nan_gap, lambda d, _w=where: f"{_w}, column {columns[d]!r}", row_of)
        demos.append(y)
        times.append(t_rel)
        labels.append(f"{path.stem}@{(t_ns[0] - start) * 1e-9:.3f}s")
        if grid_dt is not None:  # the samples as recorded, on the demonstration's clock (causal prefixes)
            raw.append([RawStream((t - t_ns[0]) * 1e-9, tuple(range(offsets[i], offsets[i + 1])),
                                  np.asarray(yy, dtype=np.float64)) for i, (t, yy) in enumerate(parts)])
    meta = {"units": units}
    if grid_dt is not None:
        meta["raw"] = raw
    if len(streams) == 2:
        meta["observed"] = cols[0]
    return demos, times, columns, labels, meta

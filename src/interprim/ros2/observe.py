"""What the bridge reads: ``--observe TOPIC[:SELECTOR][@TYPE]`` specs and the values they take from a message.

Column names follow the bag loader (:mod:`interprim.datasets.ros_bags`), so a model fitted from a bag of the same
topics needs no selector:

========================================  ==========================================================================
type                                      columns (``<prefix>`` = the topic without its leading ``/``)
========================================  ==========================================================================
``geometry_msgs/msg/PointStamped``        ``<prefix>_x``, ``_y``, ``_z`` (``point``)
``geometry_msgs/msg/PoseStamped``         the position as above and the orientation ``_qx``, ``_qy``, ``_qz``, ``_qw``
``TransformStamped``, ``Odometry``        the same from ``transform`` / ``pose.pose``
``tf2_msgs/msg/TFMessage``                ``TOPIC:FRAME``: the child frame ``FRAME``'s translation ``FRAME_x``, ...
                                          (and rotation ``FRAME_qx``, ...)
``sensor_msgs/msg/JointState``            one column per joint name (``position``)
any other type                            ``TOPIC:FIELD,FIELD``: numeric fields by path (``pose.position.x``,
                                          ``data[2]``), columns ``<prefix>_<field>``
========================================  ==========================================================================

Without a selector, a spec offers every column of its type and the model's observed columns pick those they name;
with one (``/human/hand:x,y``; ``/joint_states:elbow,wrist``; ``/tf:hand:x,y``), exactly those.  ``ITEM=COLUMN``
renames a value onto a model column of another name (``/human/hand:x=hx,y=hy``).  ``@TYPE`` gives the message type
(``@PointStamped``, ``@sensor_msgs/msg/JointState``); the default is ``PoseStamped``, and ``TFMessage`` for
``/tf`` and ``/tf_static``.

Units and frames: the values are taken as they are on the wire (ROS: metres, radians, REP 103).  A model file
records its columns' names, not their units or frames, so the bridge checks names only; the header's
``frame_id`` (or a TF parent frame) is checked to stay the same during a run.
"""

from __future__ import annotations

import numpy as np

from ..datasets.ros_bags import field_value
from .messages import dds_topic, known_type

__all__ = ["Source", "parse_observe", "match_columns", "ObservationError"]

_XYZ = ("x", "y", "z")
_Q = ("qx", "qy", "qz", "qw")
_POSE_LIKE = {  # type -> (position path, orientation path or None)
    "geometry_msgs/msg/PointStamped": ("point", None),
    "geometry_msgs/msg/PoseStamped": ("pose.position", "pose.orientation"),
    "geometry_msgs/msg/TransformStamped": ("transform.translation", "transform.rotation"),
    "nav_msgs/msg/Odometry": ("pose.pose.position", "pose.pose.orientation"),
    "geometry_msgs/msg/PoseWithCovarianceStamped": ("pose.pose.position", "pose.pose.orientation"),
}
TF = "tf2_msgs/msg/TFMessage"
JOINT_STATE = "sensor_msgs/msg/JointState"
MAX_SPEC = 1000  # characters of one spec (read from outside: bounded)


class ObservationError(ValueError):
    """A message that does not give the selected values (a missing TF frame or joint, a changed frame_id)."""


def _items(text: str):
    """``a,b=c`` -> [("a", None), ("b", "c")]."""
    out = []
    for tok in (x.strip() for x in text.split(",")):
        if not tok:
            continue
        src, _, col = tok.partition("=")
        out.append((src.strip(), col.strip() or None))
    return out


class Source:
    """One observed topic: its message type and the (value, column) pairs it gives.

    ``values(msg)`` returns ``(stamp, values)`` (the ``builtin_interfaces/msg/Time``, or ``None`` for a message
    without a header) for the selected ``columns`` (after :func:`match_columns`,
    the model's), or raises :class:`ObservationError` naming what the message lacks.
    """

    def __init__(self, spec: str):
        spec = str(spec).strip()
        if not spec or len(spec) > MAX_SPEC:
            raise ValueError(f"--observe {spec[:60]!r}: give TOPIC[:SELECTOR][@TYPE] (at most {MAX_SPEC} characters)")
        self.spec = spec
        body, _, typ = spec.partition("@")
        topic, _, selector = body.partition(":")
        if topic == "tf":  # the bag loader's tf:FRAME
            topic = "/tf"
        self.topic = topic if topic.startswith("/") else "/" + topic
        dds_topic(self.topic)  # a ValueError naming a bad topic name
        if typ.strip():
            self.msgtype = known_type(typ.strip())
        else:
            self.msgtype = TF if self.topic in ("/tf", "/tf_static") else "geometry_msgs/msg/PoseStamped"
        self.prefix = self.topic.lstrip("/")
        self.frame = None  # TF child frame
        self.explicit = bool(selector.strip())
        self.offers = []  # [(path or key, default column name)]
        self.renames = {}
        self._frame_id = None
        t = self.msgtype
        if t == TF:
            frame, _, rest = selector.partition(":")
            if not frame.strip():
                raise ValueError(f"--observe {spec!r}: a TFMessage topic needs the child frame: {self.topic}:FRAME")
            self.frame = frame.strip()
            self.explicit = bool(rest.strip())
            self._pose_offers(self.frame, "transform.translation", "transform.rotation", rest)
        elif t in _POSE_LIKE:
            pos, rot = _POSE_LIKE[t]
            self._pose_offers(self.prefix, pos, rot, selector)
        elif t == JOINT_STATE:
            for name, col in _items(selector):
                self.offers.append((name, name))
                if col:
                    self.renames[name] = col
        else:
            if not self.explicit:
                raise ValueError(f"--observe {spec!r}: a {t} topic needs field paths: {self.topic}:FIELD,FIELD")
            from .messages import ros2_typestore

            for path, col in _items(selector):
                self._check_path(ros2_typestore(), t, path)
                self.offers.append((path, f"{self.prefix}_{path}"))
                if col:
                    self.renames[path] = col
        self.columns: list = []  # set by match_columns
        self._take: list = []

    def _pose_offers(self, prefix, pos, rot, selector):
        keys = {k: f"{pos}.{k}" for k in _XYZ}
        if rot:
            keys.update({q: f"{rot}.{q[1]}" for q in _Q})
        if selector.strip():
            for key, col in _items(selector):
                if key not in keys:
                    raise ValueError(f"--observe {self.spec!r}: {key!r} is not one of {', '.join(keys)} "
                                     f"for {self.msgtype}")
                self.offers.append((keys[key], f"{prefix}_{key}"))
                if col:
                    self.renames[keys[key]] = col
        else:
            self.offers = [(p, f"{prefix}_{k}") for k, p in keys.items()]

    @staticmethod
    def _check_path(typestore, msgtype, path):
        from ..datasets.ros_bags import check_field_path

        try:
            check_field_path(typestore, msgtype, path)
        except KeyError as exc:
            raise ValueError(exc.args[0]) from None

    def offered(self):
        """``[(key, column)]``: every value the spec can give, under the column name it gives it."""
        return [(k, self.renames.get(k, c)) for k, c in self.offers]

    def select(self, pairs):
        """Keep ``pairs`` (``[(key, column)]``, in the model's order)."""
        self._take = [k for k, _ in pairs]
        self.columns = [c for _, c in pairs]

    def values(self, msg):
        """``(stamp, values)`` of the selected keys in ``msg``."""
        t = self.msgtype
        if t == TF:
            tr = None
            for x in msg.transforms:
                if x.child_frame_id == self.frame:
                    tr = x
            if tr is None:
                got = sorted({x.child_frame_id for x in msg.transforms})[:10]
                raise ObservationError(f"{self.topic}: no transform of child frame {self.frame!r} in this message "
                                       f"(it has {', '.join(got) or 'none'})")
            self._check_frame(tr.header.frame_id, "parent frame")
            return tr.header.stamp, np.array([float(field_value(tr, k)) for k in self._take])
        if t == JOINT_STATE:
            names = list(msg.name)
            pos = msg.position
            idx = {n: i for i, n in enumerate(names)}
            out = []
            for k in self._take:
                i = idx.get(k)
                if i is None or i >= len(pos):
                    raise ObservationError(f"{self.topic}: joint {k!r} has no position in this message "
                                           f"({len(names)} names, {len(pos)} positions)")
                out.append(float(pos[i]))
            return msg.header.stamp, np.array(out)
        if t in _POSE_LIKE:
            self._check_frame(msg.header.frame_id, "frame_id")
        try:
            vals = np.array([float(field_value(msg, k)) for k in self._take])
        except (AttributeError, IndexError, TypeError, ValueError) as exc:
            raise ObservationError(f"{self.topic}: cannot read {self._take} from this message ({exc})") from None
        return (msg.header.stamp if hasattr(msg, "header") else None), vals

    def _check_frame(self, frame_id, what):
        frame_id = str(frame_id)
        if self._frame_id is None:
            self._frame_id = frame_id
        elif frame_id != self._frame_id:
            raise ObservationError(f"{self.topic}: {what} changed from {self._frame_id!r} to {frame_id!r}; "
                                   f"the model's values are in one frame")


def parse_observe(specs) -> list:
    """The :class:`Source` of each ``--observe`` spec (``ValueError`` naming a bad one)."""
    if isinstance(specs, str):
        specs = [specs]
    sources = [Source(s) for s in specs]
    if not sources:
        raise ValueError("give at least one --observe TOPIC[:SELECTOR][@TYPE]")
    seen = set()
    for s in sources:
        key = (s.topic, s.frame)
        if key in seen:
            raise ValueError(f"--observe: {s.topic}{':' + s.frame if s.frame else ''} is given twice")
        seen.add(key)
    return sources


def match_columns(sources, observed_columns) -> None:
    """Map the sources' values onto the model's ``observed_columns`` (names, in the model's order).

    Each observed column must be given by exactly one source; an explicit selector's values must all be observed
    columns.  ``ValueError`` names what does not match.  Afterwards each source's ``columns`` are its part of the
    frame and the sources, concatenated in the given order, are permuted onto the model's order by the caller
    (:func:`frame_order`).
    """
    observed = [str(c) for c in observed_columns]
    want = set(observed)
    by_col: dict = {}
    for s in sources:
        if s.msgtype == JOINT_STATE and not s.explicit:  # joint names are the model's column names
            s.offers = [(c, c) for c in observed if c not in by_col]
        pairs = []
        for key, col in s.offered():
            if col in want:
                if col in by_col:
                    raise ValueError(f"the model column {col!r} is given by both {by_col[col].spec!r} and {s.spec!r}")
                by_col[col] = s
                pairs.append((key, col))
            elif s.explicit:
                raise ValueError(f"--observe {s.spec!r}: {col!r} is not an observed column of the model "
                                 f"(it observes {', '.join(observed)}); rename with ITEM=COLUMN")
        if not pairs:
            offered = ", ".join(c for _, c in s.offered()) or "nothing"
            raise ValueError(f"--observe {s.spec!r} gives none of the model's observed columns "
                             f"({', '.join(observed)}); it offers {offered}; select and rename with "
                             f"{s.topic}:ITEM=COLUMN,...")
        s.select(pairs)
    missing = [c for c in observed if c not in by_col]
    if missing:
        raise ValueError(f"no --observe gives the model's observed column(s) {', '.join(missing)}")


def frame_order(sources, observed_columns) -> np.ndarray:
    """Indices that put the sources' concatenated values into the model's observed column order."""
    cols = [c for s in sources for c in s.columns]
    return np.array([cols.index(str(c)) for c in observed_columns], dtype=np.intp)

"""The ROS 2 bridge: the partner's topics in, the model's predicted response out, over DDS.

:class:`Ros2Bridge` subscribes to the ``--observe`` topics (:mod:`interprim.ros2.observe`), puts each message's
values on the model's frame grid by their ``header.stamp`` (:mod:`interprim.ros2.grid`), streams the grid frames
into ``model.stream()`` and publishes, for each message that gave at least one frame:

* the response (``pred.response(points)``) as ``trajectory_msgs/msg/JointTrajectory`` (joint names: the model's
  controlled columns; ``time_from_start``: the prediction's seconds ahead; ``header.stamp``: the time of the grid
  frame it answers; each point's velocities and accelerations from the spline through the points:
  :func:`response_derivatives`), or as ``nav_msgs/msg/Path`` / ``geometry_msgs/msg/PoseArray`` for a task-space model
  whose controlled columns are ``<name>_x``, ``_y`` (and ``_z``);
* on ``<publish>/status`` a ``diagnostic_msgs/msg/DiagnosticArray`` with one status: level OK (WARN when the
  partner is out of the training range), and the values ``phase``, ``normalised_time``, ``speed``,
  ``duration``, ``out_of_range``, ``duration_out_of_range``, ``input_distance``, ``n_observed``, ``frame_time``
  and, per controlled column,
  ``std.<column>``: the prediction's standard deviation at the response's points (a JSON list; the band is
  ``mean +- z * std``).

Nothing is published without a new frame: a stalled partner topic leaves the last response as it was, stamped
with the time of the last frame, never re-sent as if fresh.  Dropped messages (duplicate or late stamps, a
missing TF frame or joint, a changed frame) are counted in :attr:`Ros2Bridge.counts` and logged once per cause,
then at most once per ``log_interval`` seconds with the count since.
"""

from __future__ import annotations

import json
import logging
import math
import threading
import time

import numpy as np

from ..core.errors import InterprimError
from .grid import StampGrid
from .messages import dds_topic, dds_type_name, known_type, message_class, new_message, stamp_of, stamp_seconds
from .observe import ObservationError, frame_order, match_columns, parse_observe

__all__ = ["Ros2Bridge", "QosSpec", "loopback_config", "RESPONSE_TYPES", "BridgeConfigError"]

log = logging.getLogger("interprim.ros2")

RESPONSE_TYPES = ("JointTrajectory", "Path", "PoseArray")


class BridgeConfigError(InterprimError, ValueError):
    """A bridge set-up that cannot work (a bad --observe spec, columns that do not match the model, a bad QoS)."""


class QosSpec:
    """A topic's QoS: ``reliable`` (else best effort) and the history ``depth`` (keep last).

    ``QosSpec.parse("best_effort,1")`` / ``"reliable,10"`` (the command line's form).
    """

    def __init__(self, reliable: bool, depth: int):
        depth = int(depth)
        if not 1 <= depth <= 10000:
            raise ValueError(f"QoS depth must be 1..10000, got {depth}")
        self.reliable, self.depth = bool(reliable), depth

    @classmethod
    def parse(cls, text: str) -> QosSpec:
        """``KIND[,DEPTH]``: ``reliable`` (default depth 10) or ``best_effort`` (default depth 1)."""
        kind, _, depth = str(text).strip().partition(",")
        kind = kind.strip().lower().replace("-", "_")
        if kind not in ("reliable", "best_effort"):
            raise ValueError(f"QoS {text!r}: give reliable[,DEPTH] or best_effort[,DEPTH]")
        try:
            d = int(depth) if depth.strip() else (1 if kind == "best_effort" else 10)
        except ValueError:
            raise ValueError(f"QoS {text!r}: DEPTH must be a whole number") from None
        return cls(kind == "reliable", d)

    def __repr__(self):
        return f"QosSpec({'reliable' if self.reliable else 'best_effort'},{self.depth})"

    def dds(self):
        """The ``cyclonedds`` QoS: this reliability and depth, volatile, classic CDR (as ``rmw_cyclonedds_cpp``)."""
        from cyclonedds.qos import Policy, Qos
        from cyclonedds.util import duration

        best_effort = Policy.Reliability.BestEffort
        rel = Policy.Reliability.Reliable(duration(milliseconds=100)) if self.reliable else best_effort
        # volatile durability and XCDR1 (classic CDR): what rmw_cyclonedds_cpp uses for ROS 2 topics
        return Qos(rel, Policy.History.KeepLast(self.depth), Policy.Durability.Volatile,
                   Policy.DataRepresentation(use_cdrv0_representation=True))


def loopback_config() -> str:
    """A Cyclone DDS configuration that keeps a domain's traffic on this machine: the loopback interface, no
    multicast, discovery by unicast to 127.0.0.1."""
    return ("<CycloneDDS><Domain id=\"any\"><General><Interfaces><NetworkInterface name=\"lo\"/></Interfaces>"
            "<AllowMulticast>false</AllowMulticast></General><Discovery><ParticipantIndex>auto</ParticipantIndex>"
            "<MaxAutoParticipantIndex>40</MaxAutoParticipantIndex><Peers><Peer address=\"127.0.0.1\"/></Peers>"
            "</Discovery></Domain></CycloneDDS>")


class _Say:
    """Log a cause the first time, then at most once per ``interval`` seconds with the count since."""

    def __init__(self, interval: float):
        self.interval = float(interval)
        self.last: dict = {}
        self.pending: dict = {}

    def __call__(self, cause: str, message: str, level=logging.WARNING) -> None:
        now = time.monotonic()
        if cause not in self.last:
            self.last[cause] = now
            log.log(level, "%s (logged once per %.0f s from now on)", message, self.interval)
            return
        self.pending[cause] = self.pending.get(cause, 0) + 1
        if now - self.last[cause] >= self.interval:
            log.log(level, "%s (%d times in the last %.0f s)", message, self.pending[cause], now - self.last[cause])
            self.last[cause], self.pending[cause] = now, 0


#: A partner frame further than this many standard deviations from the training frames, or (for a model that does
#: not know its training range) a value larger than ``MAX_ABS_VALUE``, is absurd: refused before the model with
#: the non-finite ones (the rule of the server's ``bad_frame``: ``interprim.server.compute``).
MAX_INPUT_DISTANCE = 1e6
MAX_ABS_VALUE = 1e12


def _bad_values(vals):
    """Why the partner's values cannot go to the model (non-finite or absurd), or ``None``."""
    v = np.asarray(vals, dtype=np.float64)
    if not np.all(np.isfinite(v)):
        return "a non-finite value (nan or inf)"
    big = np.abs(v) > MAX_ABS_VALUE
    if big.any():
        return f"an absurd value {float(v[big][0]):.3g} (beyond +-{MAX_ABS_VALUE:g})"
    return None


def _stamp_text(base_sec: int, t: float) -> str:
    """``base_sec + t`` seconds as ``SEC.NANOSEC`` (a float of seconds since 1970 would print rounding noise)."""
    if not math.isfinite(t):
        return "nan"
    ns = int(base_sec) * 1_000_000_000 + int(round(t * 1e9))
    return f"{ns // 1_000_000_000}.{ns % 1_000_000_000:09d}"


def _controlled_names(model, names):
    return [names[i] for i in model.controlled_dofs_]


def _xyz_group(cols):
    """``(x, y, z or None)`` column indices of a task-space model's controlled columns, or ``None``."""
    for i, c in enumerate(cols):
        if c.endswith("_x"):
            base = c[:-2]
            y = cols.index(base + "_y") if base + "_y" in cols else None
            z = cols.index(base + "_z") if base + "_z" in cols else None
            if y is not None:
                return i, y, z
    return None


def response_derivatives(t, y):
    """Velocities and accelerations of the response ``y`` (points, columns) at its times ``t`` (seconds ahead): the
    first and second derivatives of the cubic spline through the points (not-a-knot ends).

    A ``JointTrajectory`` with positions only is followed by linear interpolation (ros2_controllers'
    joint_trajectory_controller: linear with positions, cubic with velocities, quintic with accelerations too), whose
    velocity jumps at every point and whose acceleration is zero between them; the robot then tracks a polyline.  With
    both, it follows the smooth predicted movement.  Fewer than two distinct times (the movement's end): zeros."""
    t = np.asarray(t, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    zeros = np.zeros_like(y)
    if t.size < 2 or not np.all(np.diff(t) > 0) or not np.all(np.isfinite(y)):
        return zeros, zeros.copy()
    from scipy.interpolate import make_interp_spline  # (the same spline as CubicSpline's, at a sixth of its cost)

    spline = make_interp_spline(t, y, k=min(3, t.size - 1), axis=0)
    return spline(t, 1), spline(t, 2) if t.size > 2 else zeros.copy()


class Ros2Bridge:
    """Stream a model's predictions between ROS 2 topics (see the module docstring).

    Parameters
    ----------
    model : fitted model
        Any interprim model (``interprim.load_any(path)``).
    observe : list of str
        ``TOPIC[:SELECTOR][@TYPE]`` specs of the partner's movement (:mod:`interprim.ros2.observe`); the first
        one's messages clock the frames, the others' latest values are held.
    publish : str
        Topic of the response; the companion status goes to ``publish + "/status"`` (or ``status``).
    response_type : {"JointTrajectory", "Path", "PoseArray"}
    points : int
        Points of the published response (current phase to the end).
    max_gap : float
        Seconds between two partner samples beyond which the interaction restarts (:class:`StampGrid`).
    partner_qos, response_qos : QosSpec or str
        Default ``best_effort,1`` and ``reliable,10``.
    domain_id : int, optional
        DDS domain (ROS_DOMAIN_ID; default: the ``ROS_DOMAIN_ID`` environment variable, else 0).
    config : str, optional
        Cyclone DDS XML configuration of the domain (e.g. :func:`loopback_config`); default: Cyclone's own
        (``CYCLONEDDS_URI``).
    frame_id : str
        ``header.frame_id`` of the published messages (default: the partner's, from its messages' headers).
    """

    def __init__(self, model, observe, publish="/interprim/response", **options):
        try:
            self._setup(model, observe, publish, **options)
        except (ValueError, TypeError) as exc:
            raise BridgeConfigError(str(exc)) from None

    @property
    def domain_id(self):
        """The DDS domain of the open bridge (``None`` before :meth:`open`)."""
        return None if self._dds is None else self._dds["domain_id"]

    def _setup(self, model, observe, publish, *, status=None, response_type="JointTrajectory", points: int = 20,
               max_gap: float = 0.5, partner_qos="best_effort,1", response_qos="reliable,10", domain_id=None,
               config=None, frame_id: str = "", log_interval: float = 5.0):
        self.model = model
        names = getattr(model, "columns_", None) or [f"dof_{i}" for i in range(int(model.n_dofs_))]
        self.columns = [str(c) for c in names]
        self.observed = [self.columns[i] for i in model.observed_dofs_]
        self.controlled = _controlled_names(model, self.columns)
        self.sources = parse_observe(observe)
        match_columns(self.sources, self.observed)
        self._order = frame_order(self.sources, self.observed)
        self.points = int(points)
        if not 2 <= self.points <= 10000:
            raise ValueError(f"points must be 2..10000, got {points}")
        self.response_type = known_type(response_type).split("/")[-1]
        if self.response_type not in RESPONSE_TYPES:
            raise ValueError(f"response_type must be one of {', '.join(RESPONSE_TYPES)}, got {response_type!r}")
        self._xyz: tuple | None = None
        if self.response_type != "JointTrajectory":
            self._xyz = _xyz_group(self.controlled)
            if self._xyz is None:
                raise ValueError(f"a {self.response_type} response needs controlled columns NAME_x, NAME_y[, NAME_z]; "
                                 f"this model controls {', '.join(self.controlled)} (use JointTrajectory)")
        self.publish_topic = publish
        self.status_topic = status or publish.rstrip("/") + "/status"
        dds_topic(self.publish_topic), dds_topic(self.status_topic)  # check the names now
        self.partner_qos = partner_qos if isinstance(partner_qos, QosSpec) else QosSpec.parse(partner_qos)
        self.response_qos = response_qos if isinstance(response_qos, QosSpec) else QosSpec.parse(response_qos)
        self.frame_id = str(frame_id)
        self.partner_frame = ""  # header.frame_id of the partner's last message (the default of the response's)
        self.grid = StampGrid(float(model.dt_), max_gap)
        self.stream = model.stream()
        self._latest: list[np.ndarray | None] = [None] * len(self.sources)
        self.counts = {"received": 0, "frames": 0, "published": 0, "duplicate": 0, "late": 0, "gap": 0, "back": 0,
                       "invalid": 0, "unusable": 0, "waiting": 0, "between": 0}
        self._say = _Say(log_interval)
        self._std_grid = 101
        self._domain_id = domain_id
        self._config = config
        self._dds: dict | None = None
        self._sink = None  # callable(response, status) instead of DDS writers (tests of the logic)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._wrong_types: set = set()
        self.last_prediction = None
        self.last_frame_time: float | None = None  # seconds since 1970 of the last grid frame
        self.base_sec: int | None = None  # whole seconds of the first stamp: the origin of the grid's times

    # ---- the logic, independent of the transport ----
    def handle(self, index: int, msg) -> bool:
        """One message of ``sources[index]``; returns whether a response was published."""
        self.counts["received"] += 1
        src = self.sources[index]
        try:
            stamp, vals = src.values(msg)
        except ObservationError as exc:
            self.counts["unusable"] += 1
            self._say(f"unusable:{src.spec}", f"dropped a message: {exc}")
            return False
        bad = _bad_values(vals)
        if bad is not None:  # refused before the model, counted with the other invalid messages
            self.counts["invalid"] += 1
            self._say("invalid", f"{src.topic}: dropped an invalid message: {bad}")
            return False
        if index == 0:
            frame = getattr(getattr(msg, "header", None), "frame_id", "")
            if isinstance(frame, str) and frame:
                self.partner_frame = frame
        self._latest[index] = vals
        if index != 0:
            return False
        if any(v is None for v in self._latest):
            self.counts["waiting"] += 1
            missing = [s.topic for s, v in zip(self.sources, self._latest) if v is None]
            self._say("waiting", f"waiting for a first message on {', '.join(missing)}", logging.INFO)
            return False
        y = np.concatenate([v for v in self._latest if v is not None])[self._order]  # none is None here
        dist = self.model.input_distance(y) if hasattr(self.model, "input_distance") else float("nan")
        if math.isfinite(dist) and dist > MAX_INPUT_DISTANCE:
            self.counts["invalid"] += 1
            self._say("invalid", f"{src.topic}: dropped an invalid message: a frame {dist:.3g} standard deviations "
                                 f"from the training demonstrations (beyond {MAX_INPUT_DISTANCE:g})")
            return False
        if self.base_sec is None and stamp is not None:
            self.base_sec = int(stamp.sec)  # stamps in seconds after this (float seconds since 1970 lose ~0.2 us)
        t = math.nan if stamp is None else stamp_seconds(stamp, self.base_sec or 0)
        step = self.grid.add(t, y)
        if step.status in ("duplicate", "late", "invalid"):
            self.counts[step.status] += 1
            last = self.grid.last_t
            b = self.base_sec or 0
            what = {"duplicate": f"the same stamp as the last ({_stamp_text(b, t)} s)",
                    "late": f"stamp {_stamp_text(b, t)} s older than the last ({_stamp_text(b, last)} s)",
                    "invalid": "a non-finite stamp or value"}[step.status]
            self._say(step.status, f"{src.topic}: dropped a {step.status} message: {what}")
            return False
        if step.status == "gap":
            self.counts["gap"] += 1
            self._say("gap", f"{src.topic}: no message for more than {self.grid.max_gap} s: a new interaction starts "
                             f"at {_stamp_text(self.base_sec or 0, t)} s (stream reset)", logging.INFO)
        elif step.status == "back":
            self.counts["back"] += 1
            self._say("back", f"{src.topic}: the stamps jumped back by more than {self.grid.max_gap} s (a restarted "
                              f"clock?): a new interaction starts at {_stamp_text(self.base_sec or 0, t)} s "
                              "(stream reset)")
        if step.restarted:
            self.stream.reset()
        if len(step.times) == 0:
            self.counts["between"] += 1
            return False
        frames = step.frames
        pred = self.stream.update(frames[0]) if len(frames) == 1 else self.stream.extend(frames)
        self.counts["frames"] += len(frames)
        self.last_prediction = pred
        base = self.base_sec or 0  # a frame on the grid has a stamp, so base_sec is set
        self.last_frame_time = base + float(step.times[-1])
        response, status = self.messages(pred, float(step.times[-1]), base)
        self._emit(response, status)
        self.counts["published"] += 1
        return True

    @property
    def out_frame(self) -> str:
        """``header.frame_id`` of the published messages: ``frame_id`` when given, else the partner's frame."""
        return self.frame_id or self.partner_frame

    def messages(self, pred, frame_time: float, base_sec: int = 0):
        """The response and the status message of ``pred`` for the grid frame at ``base_sec + frame_time`` s."""
        t, y = pred.response(self.points)
        t = np.asarray(t, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        header = new_message("std_msgs/msg/Header", stamp=stamp_of(frame_time, base_sec), frame_id=self.out_frame)
        if self.response_type == "JointTrajectory":
            vel, acc = response_derivatives(t, y)
            pts = [new_message("trajectory_msgs/msg/JointTrajectoryPoint", positions=[float(v) for v in row],
                               velocities=[float(v) for v in vr], accelerations=[float(v) for v in ar],
                               time_from_start=self._duration(dt)) for dt, row, vr, ar in zip(t, y, vel, acc)]
            response = new_message("trajectory_msgs/msg/JointTrajectory", header=header,
                                   joint_names=list(self.controlled), points=pts)
        else:
            assert self._xyz is not None  # checked by __init__ for these response types
            ix, iy, iz = self._xyz
            poses = []
            for row in y:
                pos = new_message("geometry_msgs/msg/Point", x=float(row[ix]), y=float(row[iy]),
                                  z=float(row[iz]) if iz is not None else 0.0)
                pose = new_message("geometry_msgs/msg/Pose", position=pos,
                                   orientation=new_message("geometry_msgs/msg/Quaternion", w=1.0))
                poses.append(pose)
            if self.response_type == "PoseArray":
                response = new_message("geometry_msgs/msg/PoseArray", header=header, poses=poses)
            else:
                stamped = [new_message("geometry_msgs/msg/PoseStamped", pose=p, header=new_message(
                    "std_msgs/msg/Header", stamp=stamp_of(frame_time + float(dt), base_sec), frame_id=self.out_frame))
                    for dt, p in zip(t, poses)]
                response = new_message("nav_msgs/msg/Path", header=header, poses=stamped)
        return response, self._status(pred, base_sec + frame_time, t, header)

    @staticmethod
    def _duration(seconds: float):
        ns = max(int(round(float(seconds) * 1e9)), 0)
        return new_message("builtin_interfaces/msg/Duration", sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)

    def band(self, pred, t) -> dict:
        """Per controlled column, the prediction's std at the response's points ``t`` (seconds ahead): the std on
        normalised time interpolated at ``normalised_time + t / duration`` (``{}``: the model gives no std)."""
        sd = pred.std(self._std_grid)
        if sd is None:
            return {}
        sd = np.asarray(sd)[:, list(self.model.controlled_dofs_)]
        s0, dur = float(pred.normalised_time), float(pred.duration)
        if math.isfinite(s0) and math.isfinite(dur) and dur > 0:
            s = np.clip(s0 + np.asarray(t) / dur, 0.0, 1.0)
        else:
            s = np.linspace(s0 if math.isfinite(s0) else 0.0, 1.0, len(t))
        u = np.linspace(0.0, 1.0, self._std_grid)
        return {c: np.interp(s, u, sd[:, j]) for j, c in enumerate(self.controlled)}

    def _status(self, pred, frame_time, t, header):
        def kv(k, v):
            return new_message("diagnostic_msgs/msg/KeyValue", key=k, value=v)

        oor = bool(pred.out_of_range)
        values = [kv("phase", repr(float(pred.phase))), kv("normalised_time", repr(float(pred.normalised_time))),
                  kv("speed", repr(float(pred.speed))), kv("duration", repr(float(pred.duration))),
                  kv("out_of_range", "true" if oor else "false"),
                  kv("duration_out_of_range", "true" if getattr(pred, "duration_out_of_range", False) else "false"),
                  kv("input_distance", repr(float(pred.input_distance))), kv("n_observed", str(int(pred.n_observed))),
                  kv("frame_time", repr(float(frame_time)))]
        for c, sd in self.band(pred, t).items():
            values.append(kv(f"std.{c}", json.dumps([round(float(v), 9) for v in sd])))
        st = new_message("diagnostic_msgs/msg/DiagnosticStatus", level=1 if oor else 0, name="interprim",
                         message="partner out of the training range" if oor else "ok",
                         hardware_id=type(self.model).__name__, values=values)
        return new_message("diagnostic_msgs/msg/DiagnosticArray", header=header, status=[st])

    def _emit(self, response, status):
        if self._sink is not None:
            self._sink(response, status)
            return
        d = self._dds
        d["response"].write(response)
        d["status"].write(status)

    # ---- the DDS transport ----
    def open(self):
        """Create the DDS participant, readers and writers (``cyclonedds``)."""
        import os

        from cyclonedds.builtin import BuiltinDataReader, BuiltinTopicDcpsPublication
        from cyclonedds.core import InstanceState, ReadCondition, SampleState, ViewState, WaitSet
        from cyclonedds.domain import Domain, DomainParticipant
        from cyclonedds.pub import DataWriter
        from cyclonedds.sub import DataReader
        from cyclonedds.topic import Topic

        did = self._domain_id
        if did is None:
            did = int(os.environ.get("ROS_DOMAIN_ID", "0") or 0)
        if not 0 <= int(did) <= 232:
            raise BridgeConfigError(f"the DDS domain id must be 0..232 (ROS_DOMAIN_ID), got {did}")
        d = {"domain_id": int(did)}
        if self._config is not None:
            d["domain"] = Domain(int(did), self._config)
        dp = DomainParticipant(int(did))
        d["participant"] = dp
        mask = SampleState.Any | ViewState.Any | InstanceState.Any
        ws = WaitSet(dp)
        readers = []
        for s in self.sources:
            tp = Topic(dp, dds_topic(s.topic), message_class(s.msgtype))
            r = DataReader(dp, tp, qos=self.partner_qos.dds())
            rc = ReadCondition(r, mask)
            ws.attach(rc)
            readers.append((r, rc))
        d["readers"], d["waitset"] = readers, ws
        rt = Topic(dp, dds_topic(self.publish_topic), message_class(self.response_type))
        stt = Topic(dp, dds_topic(self.status_topic), message_class("DiagnosticArray"))
        d["response"] = DataWriter(dp, rt, qos=self.response_qos.dds())
        d["status"] = DataWriter(dp, stt, qos=self.response_qos.dds())
        d["pubs"] = BuiltinDataReader(dp, BuiltinTopicDcpsPublication)
        self._dds = d
        return self

    def _check_types(self):
        """Log once per (topic, type) a publisher of an observed topic with another message type (DDS does not
        match it, so its messages never arrive)."""
        want = {dds_topic(s.topic): dds_type_name(s.msgtype) for s in self.sources}
        for p in self._dds["pubs"].take(N=64):
            name, typ = getattr(p, "topic_name", None), getattr(p, "type_name", None)
            if name in want and typ != want[name] and (name, typ) not in self._wrong_types:
                self._wrong_types.add((name, typ))
                self.counts["wrong_type"] = self.counts.get("wrong_type", 0) + 1
                log.warning("topic %s is published as %s, but the bridge reads it as %s: those messages are not "
                            "received (give the type with --observe TOPIC@TYPE)", name[2:], typ, want[name])

    def spin_once(self, timeout: float = 0.1) -> int:
        """Wait up to ``timeout`` seconds for messages and handle them; returns the number published."""
        from cyclonedds.util import duration

        if self._dds is None:
            self.open()
        assert self._dds is not None  # set by open
        self._dds["waitset"].wait(duration(seconds=float(timeout)))
        n = 0
        for i, (r, _) in enumerate(self._dds["readers"]):
            for msg in r.take(N=256):
                if getattr(getattr(msg, "sample_info", None), "valid_data", True) is False:
                    continue
                try:
                    n += bool(self.handle(i, msg))
                except Exception as exc:  # noqa: BLE001 - one bad message must not stop the bridge
                    self.counts["unusable"] += 1
                    self._say(f"error:{type(exc).__name__}", f"{self.sources[i].topic}: a message could not be "
                                                             f"used: {type(exc).__name__}: {exc}")
        self._check_types()
        return n

    def spin(self, seconds=None) -> None:
        """Handle messages until :meth:`stop` (or for ``seconds``)."""
        end = None if seconds is None else time.monotonic() + float(seconds)
        while not self._stop.is_set() and (end is None or time.monotonic() < end):
            self.spin_once(0.05)

    def start(self) -> Ros2Bridge:
        """Open and spin in a background thread (until :meth:`close`)."""
        if self._dds is None:
            self.open()
        self._thread = threading.Thread(target=self.spin, name="interprim-ros2", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        """Ask :meth:`spin` to return (the DDS entities stay open until :meth:`close`)."""
        self._stop.set()

    def close(self) -> None:
        """Stop spinning and delete the DDS entities."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(5.0)
            self._thread = None
        self._dds = None  # cyclonedds deletes the entities when they are garbage collected

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc):
        self.close()

"""``interprim ros2``: run a model live between ROS 2 topics (the partner's movement in, the response out)."""

from __future__ import annotations

DESCRIPTION = """\
Subscribe to the partner's movement on ROS 2 topics, stream it into MODEL's online predictor at the
message's header.stamp, and publish the predicted response (trajectory_msgs/JointTrajectory, or
nav_msgs/Path / geometry_msgs/PoseArray) plus phase, speed, out_of_range and the band on
PUBLISH/status (diagnostic_msgs/DiagnosticArray). Speaks DDS with cyclonedds (no ROS 2 install);
interoperates with ROS 2 nodes using RMW_IMPLEMENTATION=rmw_cyclonedds_cpp on the same ROS_DOMAIN_ID.
"""

EPILOG = """\
--observe TOPIC[:SELECTOR][@TYPE] (repeatable; the first one clocks the frames):
  /human/hand@PointStamped          columns human/hand_x, _y, _z (the bag loader's names)
  /human/hand:x=hx,y=hy@PointStamped  x and y onto the model's columns hx, hy
  /tf:right_hand                    a tf2_msgs/TFMessage child frame: right_hand_x, ...
  /joint_states@JointState          joint positions named like the model's columns
  /pose:pose.position.x@PoseStamped any numeric field by path
TYPE: a short name (PointStamped, PoseStamped, TransformStamped, TFMessage, JointState, Odometry)
or pkg/msg/Type; default PoseStamped (TFMessage for /tf).

example:
  interprim ros2 model.npz --observe /human/hand@PointStamped --publish /robot/response
  ros2 topic echo /robot/response/status     # on a ROS 2 machine, rmw_cyclonedds_cpp
"""


def add_parser(subparsers) -> None:
    import argparse

    p = subparsers.add_parser("ros2", help="run a model live on ROS 2 topics (DDS, no ROS 2 install needed)",
                              description=DESCRIPTION, epilog=EPILOG,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("model", metavar="MODEL", help="a saved model file (.npz), any model 'interprim fit' writes")
    p.add_argument("--observe", action="append", required=True, metavar="TOPIC[:SELECTOR][@TYPE]",
                   help="the partner's movement (repeatable; see below)")
    p.add_argument("--publish", default="/interprim/response", metavar="TOPIC",
                   help="topic of the response (default /interprim/response)")
    p.add_argument("--status", default=None, metavar="TOPIC",
                   help="topic of the DiagnosticArray status (default: PUBLISH/status)")
    p.add_argument("--response-type", default="JointTrajectory", choices=["JointTrajectory", "Path", "PoseArray"],
                   help="message type of the response (Path/PoseArray: controlled columns NAME_x, NAME_y[, NAME_z])")
    p.add_argument("--points", type=int, default=20, help="points of the published response (default 20)")
    p.add_argument("--max-gap", type=float, default=0.5,
                   help="seconds without a partner message after which a new interaction starts (default 0.5)")
    p.add_argument("--partner-qos", default="best_effort,1", metavar="KIND[,DEPTH]",
                   help="QoS of the partner's topics: best_effort or reliable, history depth (default best_effort,1)")
    p.add_argument("--response-qos", default="reliable,10", metavar="KIND[,DEPTH]",
                   help="QoS of the published topics (default reliable,10)")
    p.add_argument("--domain-id", type=int, default=None,
                   help="DDS domain (default: $ROS_DOMAIN_ID, else 0)")
    p.add_argument("--localhost", action="store_true",
                   help="keep DDS traffic on this machine (loopback interface, unicast discovery)")
    p.add_argument("--frame-id", default="",
                   help="header.frame_id of the published messages (default: the partner's messages' frame)")
    p.add_argument("--duration", type=float, default=None, metavar="SECONDS",
                   help="stop after this many seconds (default: run until Ctrl-C)")
    p.set_defaults(func=run)


def run(args) -> int:
    import logging
    import signal
    import sys
    import threading
    import time

    from ..models.files import load_any
    from ..ros2 import Ros2Bridge, loopback_config
    from ..ros2.bridge import BridgeConfigError

    if args.duration is not None and not args.duration > 0:
        raise BridgeConfigError(f"--duration must be a positive number of seconds, got {args.duration}")
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter("interprim ros2: %(message)s"))
    lg = logging.getLogger("interprim.ros2")
    lg.addHandler(handler)
    lg.setLevel(logging.INFO)
    lg.propagate = False
    model = load_any(args.model)
    bridge = Ros2Bridge(model, args.observe, args.publish, status=args.status, response_type=args.response_type,
                        points=args.points, max_gap=args.max_gap, partner_qos=args.partner_qos,
                        response_qos=args.response_qos, domain_id=args.domain_id,
                        config=loopback_config() if args.localhost else None, frame_id=args.frame_id)
    bridge.open()
    for s in bridge.sources:
        print(f"observing {s.topic} ({s.msgtype}{', frame ' + s.frame if s.frame else ''}): {', '.join(s.columns)}")
    print(f"publishing {bridge.publish_topic} ({bridge.response_type}: {', '.join(bridge.controlled)}) and "
          f"{bridge.status_topic} (DiagnosticArray); model {type(model).__name__}, dt {model.dt_:g} s; "
          f"DDS domain {bridge.domain_id}{' (localhost only)' if args.localhost else ''}", flush=True)
    start = time.monotonic()
    status = 0
    stop: list[int] = []

    def on_signal(sig, _frame):
        # A signal only sets a flag, read between two spins: an exception raised wherever the signal lands (inside
        # a compiled phase search, a DDS callback) would be turned into another error there and lost, and the
        # bridge would go on. A second Ctrl-C raises KeyboardInterrupt at once.
        stop.append(sig)
        signal.signal(signal.SIGINT, signal.default_int_handler)

    main = threading.current_thread() is threading.main_thread()
    before = (signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)) if main else None
    if main:  # a service manager's SIGTERM: stop, exit 0
        signal.signal(signal.SIGTERM, on_signal)
        # Ctrl-C (SIGINT) stops it even when started from a script's background job, which starts with SIGINT
        # ignored (Python then leaves it ignored, and `kill -INT` did nothing)
        signal.signal(signal.SIGINT, on_signal)
    try:
        while not stop and (args.duration is None or time.monotonic() - start < args.duration):
            bridge.spin_once(0.05)
    except KeyboardInterrupt:
        stop.append(signal.SIGINT)
    finally:
        bridge.close()
        if before is not None:  # a caller's own handlers again (main() may run inside a program)
            signal.signal(signal.SIGINT, before[0])
            signal.signal(signal.SIGTERM, before[1])
    if signal.SIGINT in stop:
        status = 130  # 128 + SIGINT, as the shell reports Ctrl-C (and as interprim serve exits)
    c = bridge.counts
    print("received {received} messages, {frames} frames, published {published} responses; dropped: "
          "{duplicate} duplicate, {late} late, {unusable} unusable, {invalid} invalid; {gap} restarts after a gap, "
          "{back} after the clock jumped back"
          .format(**c), flush=True)
    return status

"""ROS bags with the message types of real recordings: ROS 1's ``tf/tfMessage``, ``nav_msgs/Odometry``,
``PoseWithCovarianceStamped``, custom messages read by field path (``turtlesim/Pose``, as in rosbag.js'
``fixtures/example.bag`` where turtle2 follows turtle1), and a bag with a type its reader cannot parse
(as rosbag2's ``topics_and_services.mcap`` with ``AddTwoInts_Event``).  Every bag is written here with ``rosbags``.
"""

import numpy as np
import pytest
from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Writer2
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from interprim.core.errors import DataFileError
from interprim.datasets import load_rosbag

TURTLE_POSE = "float32 x\nfloat32 y\nfloat32 theta\nfloat32 linear_velocity\nfloat32 angular_velocity\n"


def _store(kind):
    ts = get_typestore(Stores.ROS1_NOETIC if kind == "ros1" else Stores.ROS2_HUMBLE)
    ts.register(get_types_from_msg(TURTLE_POSE, "turtlesim/msg/Pose"))
    if kind == "ros1":
        ts.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", "tf/msg/tfMessage"))
    return ts


def _write(path, kind, items, extra=()):
    """items: (t, topic, msgtype, msg); extra: (topic, msgtype, msgdef, raw bytes) written as they are."""
    ts = _store(kind)
    if kind == "ros1":
        w, ser = Writer1(path), ts.serialize_ros1
    else:
        w = Writer2(path, version=9, storage_plugin=StoragePlugin.MCAP)
        ser = ts.serialize_cdr
    with w:
        conns = {}
        for _, topic, typ, _ in items:
            if topic not in conns:
                conns[topic] = w.add_connection(topic, typ, typestore=ts)
        for topic, typ, msgdef, _ in extra:
            conns[topic] = w.add_connection(topic, typ, msgdef=msgdef, rihs01="RIHS01_" + "0" * 64)
        for t, topic, typ, msg in sorted(items, key=lambda x: x[0]):
            w.write(conns[topic], int(round(t * 1e9)), ser(msg, typ))
        for topic, _, _, raw in extra:
            w.write(conns[topic], int(1e9), raw)
    return path


def _stamp(ts, t, kind, frame="world"):
    T = ts.types
    kw = dict(stamp=T["builtin_interfaces/msg/Time"](sec=int(t // 1), nanosec=int(round((t % 1) * 1e9))),
              frame_id=frame)
    if kind == "ros1":
        kw["seq"] = 0
    return T["std_msgs/msg/Header"](**kw)


def turtles(t):
    """turtle1 drives a circle; turtle2 follows 0.3 s behind."""
    return np.array([5 + 2 * np.cos(t), 5 + 2 * np.sin(t)]), np.array([5 + 2 * np.cos(t - 0.3),
                                                                       5 + 2 * np.sin(t - 0.3)])


def turtlesim_bag(path, kind="ros1", n=60, dt=1 / 62.5):
    ts = _store(kind)
    T = ts.types
    items = []
    for k in range(n):
        t = 100.0 + k * dt
        p1, p2 = turtles(t)
        for name, p in (("turtle1", p1), ("turtle2", p2)):
            items.append((t, f"/{name}/pose", "turtlesim/msg/Pose",
                          T["turtlesim/msg/Pose"](x=float(p[0]), y=float(p[1]), theta=0.5, linear_velocity=2.0,
                                                  angular_velocity=1.0)))
        tr = T["geometry_msgs/msg/Transform"](translation=T["geometry_msgs/msg/Vector3"](float(p2[0]), float(p2[1]),
                                                                                         0.0),
                                              rotation=T["geometry_msgs/msg/Quaternion"](0.0, 0.0, 0.0, 1.0))
        stamped = T["geometry_msgs/msg/TransformStamped"](header=_stamp(ts, t, kind), child_frame_id="turtle2",
                                                          transform=tr)
        tf_type = "tf/msg/tfMessage" if kind == "ros1" else "tf2_msgs/msg/TFMessage"
        items.append((t, "/tf", tf_type, T[tf_type](transforms=[stamped])))
    return _write(path, kind, items)


def test_turtlesim_custom_messages_by_field_path(tmp_path):
    path = turtlesim_bag(tmp_path / "example.bag")
    ds = load_rosbag(path, "/turtle1/pose:x,y,/turtle2/pose:x,y")  # one comma-separated string, as --topics
    assert ds.columns == ["turtle1/pose_x", "turtle1/pose_y", "turtle2/pose_x", "turtle2/pose_y"]
    assert ds.observed_dofs == [0, 1] and ds.units == [None] * 4
    t = 100.0 + ds.times[0]  # no header: the bag's receive times
    p1, p2 = turtles(t)
    np.testing.assert_allclose(ds.demos[0][:, :2], p1.T, atol=1e-5)  # float32 fields
    np.testing.assert_allclose(ds.demos[0][:, 2:], p2.T, atol=1e-5)
    same = load_rosbag(path, ["/turtle1/pose:x,y", "/turtle2/pose:x,y"])
    np.testing.assert_array_equal(same.demos[0], ds.demos[0])
    with pytest.raises(DataFileError, match=r"turtlesim/msg/Pose has no field 'z' \(in 'z'\); the numeric fields of "
                                            r"turtlesim/msg/Pose are: x, y, theta, linear_velocity, angular_velocity"):
        load_rosbag(path, "/turtle1/pose:x,z")
    with pytest.raises(DataFileError, match=r"has messages of type turtlesim/msg/Pose; expected one of .*or name "
                                            r"numeric fields to read as /turtle1/pose:FIELD,FIELD \(its numeric "
                                            r"fields: x, y, theta"):
        load_rosbag(path, "/turtle1/pose")


@pytest.mark.parametrize("kind", ["ros1", "mcap"])
def test_ros1_tf_tfmessage_and_tf2(tmp_path, kind):
    path = turtlesim_bag(tmp_path / ("example.bag" if kind == "ros1" else "example"), kind)
    ds = load_rosbag(path, ["/turtle1/pose:x,y", "tf:turtle2"])
    assert ds.columns == ["turtle1/pose_x", "turtle1/pose_y", "turtle2_x", "turtle2_y", "turtle2_z"]
    t = 100.0 + ds.times[0]
    np.testing.assert_allclose(ds.demos[0][:, 2:4], turtles(t)[1].T, atol=1e-6)


@pytest.mark.parametrize("kind", ["ros1", "mcap"])
def test_odometry_and_pose_with_covariance(tmp_path, kind):
    ts = _store(kind)
    T = ts.types
    items = []
    for k in range(30):
        t = 10.0 + 0.02 * k
        pose = T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](t, 2 * t, 0.5),
                                           orientation=T["geometry_msgs/msg/Quaternion"](0.0, 0.0, 0.0, 1.0))
        cov = T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.zeros(36))
        twist = T["geometry_msgs/msg/TwistWithCovariance"](
            twist=T["geometry_msgs/msg/Twist"](linear=T["geometry_msgs/msg/Vector3"](1.0, 0.0, 0.0),
                                               angular=T["geometry_msgs/msg/Vector3"](0.0, 0.0, 0.0)),
            covariance=np.zeros(36))
        items.append((t, "/odom", "nav_msgs/msg/Odometry",
                      T["nav_msgs/msg/Odometry"](header=_stamp(ts, t, kind, "odom"), child_frame_id="base", pose=cov,
                                                 twist=twist)))
        items.append((t + 0.005, "/amcl_pose", "geometry_msgs/msg/PoseWithCovarianceStamped",
                      T["geometry_msgs/msg/PoseWithCovarianceStamped"](header=_stamp(ts, t + 0.005, kind), pose=cov)))
    path = _write(tmp_path / ("o.bag" if kind == "ros1" else "o"), kind, items)
    ds = load_rosbag(path, ["/odom", "/amcl_pose"], orientation=True)
    assert ds.columns[:3] == ["odom_x", "odom_y", "odom_z"] and ds.columns[7:10] == ["amcl_pose_x", "amcl_pose_y",
                                                                                   "amcl_pose_z"]
    t = 10.0 + float(ds.labels[0].split("@")[1][:-1]) + ds.times[0]  # the overlap starts at the 2nd odometry
    np.testing.assert_allclose(ds.demos[0][:, 0], t, atol=1e-9)
    np.testing.assert_allclose(ds.demos[0][:, 8], 2 * (t - 0.005), atol=1e-9)  # stamped 5 ms later, interpolated
    field = load_rosbag(path, ["/odom:twist.twist.linear.x,pose.covariance[0]"])
    assert field.columns == ["odom_twist.twist.linear.x", "odom_pose.covariance[0]"]
    np.testing.assert_allclose(field.demos[0], [[1.0, 0.0]] * 30)


@pytest.mark.parametrize("msgdef", ["int64 a\nint64 b\n---\nint64 sum\n",  # a service: 'Could not parse'
                                    "service_msgs/ServiceEventInfo info\n"])  # parses, but as another type name
def test_a_type_the_reader_cannot_parse_is_skipped_unless_needed(tmp_path, msgdef):
    """rosbag2's topics_and_services.mcap records service events (AddTwoInts_Event) whose definition rosbags
    cannot parse: the bag is still read, and the error names the topic and type only when it is asked for."""
    ts = _store("mcap")
    T = ts.types
    items = []
    for k in range(20):
        t = 1.0 + 0.05 * k
        items.append((t, "/turtle1/pose", "turtlesim/msg/Pose", T["turtlesim/msg/Pose"](x=t, y=0.0, theta=0.0,
                                                                                        linear_velocity=0.0,
                                                                                        angular_velocity=0.0)))
    bad = ("/add_two_ints/_service_event", "example_interfaces/srv/AddTwoInts_Event",
           msgdef, b"\x00\x01\x00\x00garbage")
    path = _write(tmp_path / "topics_and_services", "mcap", items, extra=[bad])
    ds = load_rosbag(path, "/turtle1/pose:x")
    np.testing.assert_allclose(ds.demos[0][:, 0], 1.0 + ds.times[0], atol=1e-5)
    with pytest.raises(DataFileError, match=r"topic '/add_two_ints/_service_event' \(observed agent\) has messages of "
                                            r"type example_interfaces/srv/AddTwoInts_Event, whose definition in the "
                                            r"bag could not be parsed \(.+\); the bag itself is readable"):
        load_rosbag(path, "/add_two_ints/_service_event:x")

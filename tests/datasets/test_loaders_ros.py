"""ROS 1 / ROS 2 bag loader: bags written here with ``rosbags`` (the [ros] extra, part of the test extra).

The streams carry functions of their own time stamps (linear, so that linear interpolation onto the other
stream's stamps is exact up to rounding), which makes every value read back checkable.
"""

import random

import numpy as np
import pytest
from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Writer2
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from interprim.core.errors import DataFileError, MissingExtraError
from interprim.datasets import load_demonstrations, load_rosbag

KINDS = ("ros1", "db3", "mcap")


def ros2_typestore(kind):
    ts = get_typestore(Stores.ROS1_NOETIC if kind == "ros1" else Stores.ROS2_HUMBLE)
    if "tf2_msgs/msg/TFMessage" not in ts.types:  # not in rosbags' ROS 1 store: defined as in tf2_msgs
        ts.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage"))
    return ts


class Bag:
    """Collects (time, topic, type, message) and writes them as a ROS 1 .bag or a rosbag2 folder (.db3/.mcap)."""

    def __init__(self, kind):
        self.kind, self.ts, self.items = kind, ros2_typestore(kind), []
        self.T = self.ts.types

    def header(self, t, frame="world"):
        kw = dict(stamp=self.T["builtin_interfaces/msg/Time"](sec=int(t // 1), nanosec=int(round((t % 1) * 1e9))),
                  frame_id=frame)
        if self.kind == "ros1":
            kw["seq"] = 0
        return self.T["std_msgs/msg/Header"](**kw)

    def pose(self, topic, t, xyz, q=(0.0, 0.0, 0.0, 1.0), stamp=None):
        T = self.T
        p = T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](*map(float, xyz)),
                                        orientation=T["geometry_msgs/msg/Quaternion"](*map(float, q)))
        h = self.header(t if stamp is None else stamp)
        self.items.append((t, topic, "geometry_msgs/msg/PoseStamped", T["geometry_msgs/msg/PoseStamped"](h, p)))

    def joints(self, topic, t, names, pos, stamp=None):
        m = self.T["sensor_msgs/msg/JointState"](header=self.header(t if stamp is None else stamp), name=list(names),
                                                 position=np.asarray(pos, float), velocity=np.zeros(0),
                                                 effort=np.zeros(0))
        self.items.append((t, topic, "sensor_msgs/msg/JointState", m))

    def tf(self, t, child, xyz, parent="world", q=(0.0, 0.0, 0.0, 1.0)):
        T = self.T
        tr = T["geometry_msgs/msg/Transform"](translation=T["geometry_msgs/msg/Vector3"](*map(float, xyz)),
                                              rotation=T["geometry_msgs/msg/Quaternion"](*map(float, q)))
        ts = T["geometry_msgs/msg/TransformStamped"](header=self.header(t, parent), child_frame_id=child,
                                                     transform=tr)
        self.items.append((t, "/tf", "tf2_msgs/msg/TFMessage", T["tf2_msgs/msg/TFMessage"](transforms=[ts])))

    def mark(self, topic, t, text=None):
        if text is None:
            self.items.append((t, topic, "std_msgs/msg/Empty", self.T["std_msgs/msg/Empty"]()))
        else:
            self.items.append((t, topic, "std_msgs/msg/String", self.T["std_msgs/msg/String"](data=text)))

    def write(self, path):
        if self.kind == "ros1":
            w, ser = Writer1(path), self.ts.serialize_ros1
        else:
            plugin = StoragePlugin.SQLITE3 if self.kind == "db3" else StoragePlugin.MCAP
            w, ser = Writer2(path, version=9, storage_plugin=plugin), self.ts.serialize_cdr
        with w:
            conns = {}
            for _, topic, typ, _ in self.items:
                if topic not in conns:
                    conns[topic] = w.add_connection(topic, typ, typestore=self.ts)
            for t, topic, typ, msg in sorted(self.items, key=lambda x: x[0]):
                w.write(conns[topic], int(round(t * 1e9)), ser(msg, typ))
        return path


def bag_path(tmp_path, kind, name="rec"):
    return tmp_path / (name + ".bag" if kind == "ros1" else name)


def human(t):
    return np.array([0.5 * t, 1.0 - 0.25 * t, 2.0])


def robot(t):
    return np.array([2.0 * t, -t])


def two_agent_bag(kind, starts=(10.0,), n=40, period=0.02, lag=0.007, marker=None, tf=False):
    """Human wrist poses at ``start + k period``; robot joints ``lag`` s later; optional start markers."""
    b = Bag(kind)
    for t0 in starts:
        if marker:
            b.mark(marker, t0 - 0.3)
        for k in range(n):
            t = t0 + k * period
            b.pose("/human/wrist", t, human(t))
            b.joints("/robot/joint_states", t + lag, ["j1", "j2"], robot(t + lag))
            if tf:
                b.tf(t + lag, "robot_hand", [3 * (t + lag), 0.0, 1.0])
    return b


# ----------------------------------------------------------------------------- reading and pairing
@pytest.mark.parametrize("kind", KINDS)
def test_two_agents_paired_on_the_observed_stamps(tmp_path, kind):
    path = two_agent_bag(kind).write(bag_path(tmp_path, kind))
    ds = load_rosbag(path, ["/human/wrist", "/robot/joint_states"])
    assert ds.columns == ["human/wrist_x", "human/wrist_y", "human/wrist_z", "j1", "j2"]
    assert ds.observed_dofs == [0, 1, 2] and ds.units == ["m", "m", "m", None, None]
    assert len(ds) == 1
    # the first human pose precedes the first robot message: it cannot be paired and is left out
    t_abs = 10.0 + 0.02 * np.arange(1, 40)
    np.testing.assert_allclose(ds.times[0], t_abs - t_abs[0], rtol=0, atol=2e-9)
    y = ds.demos[0]
    np.testing.assert_allclose(y[:, :3], np.array([human(t) for t in t_abs]), rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(y[:, 3:], np.array([robot(t) for t in t_abs]), rtol=1e-9, atol=1e-7)


@pytest.mark.parametrize("kind", ["db3", "mcap"])
def test_rosbag2_storage_file_and_folder_are_the_same(tmp_path, kind):
    folder = two_agent_bag(kind).write(bag_path(tmp_path, kind))
    file = next(folder.glob(f"*.{kind}"))
    a = load_demonstrations(folder, topics="/human/wrist,/robot/joint_states")
    b = load_demonstrations(file, topics=["human/wrist", "robot/joint_states"])  # leading '/' optional
    np.testing.assert_array_equal(a.demos[0], b.demos[0])


def test_uniform_grid_with_resample_dt(tmp_path):
    path = two_agent_bag("mcap").write(bag_path(tmp_path, "mcap"))
    ds = load_rosbag(path, ["/human/wrist", "/robot/joint_states"], resample_dt=0.01)
    assert ds.dt == 0.01
    t_abs = 10.007 + 0.01 * np.arange(ds.demos[0].shape[0])  # the span both streams cover
    assert t_abs[-1] <= 10.78 + 1e-9 and t_abs[-1] > 10.77
    np.testing.assert_allclose(ds.demos[0][:, :3], np.array([human(t) for t in t_abs]), rtol=1e-9, atol=1e-7)
    np.testing.assert_allclose(ds.demos[0][:, 3:], np.array([robot(t) for t in t_abs]), rtol=1e-9, atol=1e-7)


def test_a_bag_on_a_grid_keeps_its_samples_as_recorded_for_causal_prefixes(tmp_path):
    """With resample_dt the grid is interpolated from both streams; the samples as recorded are kept (``raw``), so
    a prefix sees only the partner's samples recorded by its last frame, and split demonstrations and a folder of
    bags whose columns come in another order keep them too."""
    from interprim.model_selection.prefixes import Prefixes

    b = two_agent_bag("mcap", starts=(10.0, 13.0), period=0.05, marker="/start")  # the partner at 20 Hz
    path = b.write(bag_path(tmp_path, "mcap"))
    ds = load_rosbag(path, ["/human/wrist", "/robot/joint_states"], resample_dt=0.01, split_topic="/start")
    assert len(ds) == 2 and ds.raw is not None and len(ds.raw) == 2
    P = Prefixes(ds, ds.observed_dofs)
    assert P.causal
    for j, (y, t, streams) in enumerate(zip(ds.demos, ds.times, ds.raw)):
        obs, ctrl = streams
        assert obs.columns == (0, 1, 2) and ctrl.columns == (3, 4)
        # the recorded values at their stamps, on the demonstration's clock
        np.testing.assert_allclose(obs.values, np.array([human(t0) for t0 in obs.times + t[0] + ds_start(j)]),
                                   rtol=1e-9, atol=1e-7)
        for k in (1, 7, 23, len(t)):
            got = P(j, k)
            recorded = obs.times <= t[k - 1] + 1e-9
            last = obs.times[recorded][-1]
            inside = t[:k] <= last + 1e-9
            np.testing.assert_allclose(got[inside], y[:k][inside][:, :3], rtol=0, atol=1e-9)
            np.testing.assert_allclose(got[~inside], np.repeat(obs.values[recorded][-1:], (~inside).sum(), 0),
                                       rtol=0, atol=0)  # after the last sample recorded: held, not the next one
        assert any((t[:k] > obs.times[obs.times <= t[k - 1] + 1e-9][-1] + 1e-9).any() for k in range(1, len(t)))
    # without a grid, nothing is interpolated onto the partner's stamps: no raw samples are needed
    assert load_rosbag(path, ["/human/wrist", "/robot/joint_states"], split_topic="/start").raw is None


def ds_start(j):
    """Seconds from a demonstration's first grid frame back to the bag's clock origin of ``human``: the grid starts
    at the robot's first message after the marker (0.007 s after the partner's first sample)."""
    return (10.0, 13.0)[j] + 0.007


def test_a_folder_of_bags_keeps_their_samples_in_its_column_order(tmp_path):
    folder = tmp_path / "bags"
    folder.mkdir()
    two_agent_bag("ros1").write(folder / "a.bag")
    b = Bag("ros1")  # the robot's joints named in the other order: its columns are reordered to a.bag's
    for k in range(40):
        t = 20.0 + 0.02 * k
        b.pose("/human/wrist", t, human(t))
        b.joints("/robot/joint_states", t + 0.007, ["j2", "j1"], robot(t + 0.007)[::-1].copy())
    b.write(folder / "b.bag")
    ds = load_demonstrations(folder, topics="/human/wrist,/robot/joint_states", resample_dt=0.01)
    assert ds.columns[3:] == ["j1", "j2"] and ds.raw is not None and len(ds.raw) == 2
    for y, t, streams in zip(ds.demos, ds.times, ds.raw):
        joints = next(s for s in streams if 3 in s.columns)
        assert sorted(joints.columns) == [3, 4]
        for c in (3, 4):  # each raw column holds the joint its grid column holds
            v = joints.values[:, joints.columns.index(c)]
            np.testing.assert_allclose(np.interp(t, joints.times, v), y[:, c], rtol=0, atol=1e-9)
    sel = ds.select(["j2", "human/wrist_x", "human/wrist_y", "human/wrist_z", "j1"])
    for streams in sel.raw:
        assert sorted(c for s in streams for c in s.columns) == [0, 1, 2, 3, 4]
        wrist = next(s for s in streams if 1 in s.columns)
        assert wrist.columns == (1, 2, 3)


def test_tf_frame_with_orientation(tmp_path):
    b = Bag("ros1")
    angle = np.linspace(0, 3.0, 30)  # about z, through more than pi: the quaternion sign flips in the file
    for k in range(30):
        t = 5.0 + 0.05 * k
        b.pose("/human/wrist", t, human(t))
        q = [0.0, 0.0, np.sin(angle[k] / 2), np.cos(angle[k] / 2)]
        if k % 2:
            q = [-v for v in q]  # the same rotation
        b.tf(t + 0.01, "robot/hand", [t, 0.0, 0.0], parent="base", q=q)
    path = b.write(tmp_path / "tf.bag")
    ds = load_rosbag(path, ["/human/wrist", "tf:robot/hand"], orientation=True)
    axes = ["x", "y", "z", "qx", "qy", "qz", "qw"]
    assert ds.columns == [f"human/wrist_{a}" for a in axes] + [f"robot/hand_{a}" for a in axes]
    assert ds.units == ["m", "m", "m", "", "", "", ""] * 2
    y = ds.demos[0]
    q = y[:, -4:]
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, rtol=1e-12)
    assert np.all(np.sum(q[1:] * q[:-1], axis=1) > 0)  # continuous: one hemisphere
    t_abs = 5.0 + 0.05 * np.arange(1, 30)
    half = np.interp(t_abs, 5.01 + 0.05 * np.arange(30), angle) / 2
    np.testing.assert_allclose(np.abs(q[:, 2]), np.abs(np.sin(half)), atol=0.02)  # slerp vs lerp: small angle steps
    np.testing.assert_allclose(y[:, -7], t_abs - 0.01, rtol=1e-9)  # x = its own stamp, 0.01 s after the pose


def test_tf_frame_errors(tmp_path):
    b = Bag("mcap")
    for k in range(10):
        t = 1.0 + 0.1 * k
        b.pose("/human/wrist", t, human(t))
        b.tf(t, "hand", [t, 0, 0], parent="base" if k < 6 else "world")
    path = b.write(tmp_path / "tfbag")
    with pytest.raises(DataFileError, match=r"tfbag, topic /tf, message 6 \(bag time 0\.600 s\): frame 'hand' has "
                                            r"parent 'world' here but 'base' before"):
        load_rosbag(path, ["/human/wrist", "tf:hand"])
    with pytest.raises(DataFileError, match=r"topic '/tf' has no transform with child frame 'elbow'"):
        load_rosbag(path, ["/human/wrist", "tf:elbow"])
    with pytest.raises(DataFileError, match=r"topic '/tf' holds tf transforms; name the child frame"):
        load_rosbag(path, ["/human/wrist", "/tf"])


# ----------------------------------------------------------------------------- splitting
@pytest.mark.parametrize("kind", KINDS)
def test_split_by_marker_topic(tmp_path, kind):
    b = two_agent_bag(kind, starts=(10.0, 12.0, 14.5), marker="/demo_start")
    b.mark("/chatter", 11.0, "not a marker")
    path = b.write(bag_path(tmp_path, kind))
    ds = load_rosbag(path, ["/human/wrist", "/robot/joint_states"], split_topic="/demo_start")
    assert len(ds) == 3
    assert [round(float(d[0, 0]) / 0.5, 6) for d in ds.demos] == [10.02, 12.02, 14.52]
    assert ds.labels == ["rec@0.320s", "rec@2.320s", "rec@4.820s"]
    for y, t in zip(ds.demos, ds.times):
        assert y.shape == (39, 5) and t[0] == 0.0
        np.testing.assert_allclose(y[:, 3], 4 * y[:, 0], rtol=1e-9)  # j1 = 2 t, human x = t / 2


def test_split_by_string_marker_and_by_gaps(tmp_path):
    b = two_agent_bag("db3", starts=(1.0, 3.0, 7.0))
    b.mark("/events", 0.9, "start")
    b.mark("/events", 6.9, "start")
    path = b.write(bag_path(tmp_path, "db3"))
    gaps = load_rosbag(path, ["/human/wrist", "/robot/joint_states"], split_gap=0.5)
    assert [round(float(d[0, 0]) * 2, 6) for d in gaps.demos] == [1.02, 3.02, 7.02]
    assert all(d.shape[0] == 39 for d in gaps.demos)
    # the first marked span holds two movements with a pause between them: the controlled stream cannot be
    # interpolated across the pause, so the observed stamp right after it has no partner (missing value)
    with pytest.raises(DataFileError, match=r"rec, demonstration 0 \(0\.000-6\.000 s after the bag start\), column "
                                            r"'j1': missing value\(s\) starting at 2\.100 s after the bag start"):
        load_rosbag(path, ["/human/wrist", "/robot/joint_states"], split_topic="/events")
    both = load_rosbag(path, ["/human/wrist", "/robot/joint_states"], split_topic="/events", split_gap=0.5)
    assert len(both) == 3


def test_a_pause_inside_a_demonstration_is_missing_data(tmp_path):
    b = Bag("ros1")
    for k in range(60):
        t = 2.0 + 0.02 * k
        b.pose("/human/wrist", t, human(t))
        if not 20 <= k < 30:  # the robot stream pauses for 0.2 s
            b.joints("/robot/joint_states", t + 0.005, ["j1", "j2"], robot(t + 0.005))
    path = b.write(tmp_path / "pause.bag")
    # human stamps 2.40 ... 2.60 fall inside the robot's pause (2.385 to 2.605): 11 frames
    with pytest.raises(DataFileError, match=r"pause\.bag, demonstration 0 .*column 'j1': missing value\(s\) "
                                            r"starting at 0\.400 s after the bag start \(11 frame\(s\)\)"):
        load_rosbag(path, ["/human/wrist", "/robot/joint_states"])
    ds = load_rosbag(path, ["/human/wrist", "/robot/joint_states"], max_nan_gap=11)
    np.testing.assert_allclose(ds.demos[0][:, 3], 4 * ds.demos[0][:, 0], rtol=1e-9)  # linear: filled exactly


def test_joint_state_subsets_and_selection(tmp_path):
    b = Bag("mcap")
    for k in range(30):
        t = 1.0 + 0.05 * k
        b.pose("/human/wrist", t, human(t))
        names, pos = ["j1", "j2", "gripper"], [2 * t, -t, 0.5]
        if k == 12:
            names, pos = ["j2", "gripper"], [-t, 0.5]  # j1 left out of one message
        b.joints("/robot/joint_states", t, names, pos)
    path = b.write(tmp_path / "js")
    with pytest.raises(DataFileError, match=r"js, demonstration 0 .*column 'j1': .* starting at 0\.600 s after the "
                                            r"bag start"):
        load_rosbag(path, ["/human/wrist", "/robot/joint_states"])
    ds = load_rosbag(path, ["/human/wrist", "/robot/joint_states"], joints=["j2", "j1"], max_nan_gap=1)
    assert ds.columns[3:] == ["j2", "j1"]
    np.testing.assert_allclose(ds.demos[0][:, 4], 4 * ds.demos[0][:, 0], rtol=1e-12)
    with pytest.raises(DataFileError, match=r"topic '/robot/joint_states' has no joint 'elbow' \(joints=elbow\); "
                                            r"its joints are: j1, j2, gripper"):
        load_rosbag(path, ["/human/wrist", "/robot/joint_states"], joints="elbow")


def test_two_joint_state_agents_get_topic_prefixes(tmp_path):
    b = Bag("ros1")
    for k in range(10):
        t = 1.0 + 0.1 * k
        b.joints("/left/joint_states", t, ["j1"], [t])
        b.joints("/right/joint_states", t, ["j1"], [2 * t])
    ds = load_rosbag(b.write(tmp_path / "lr.bag"), ["/left/joint_states", "/right/joint_states"])
    assert ds.columns == ["left/joint_states/j1", "right/joint_states/j1"]
    np.testing.assert_allclose(ds.demos[0][:, 1], 2 * ds.demos[0][:, 0], rtol=1e-12)


# ----------------------------------------------------------------------------- errors
def test_streams_that_do_not_overlap(tmp_path):
    b = Bag("ros1")
    for k in range(10):
        b.pose("/human/wrist", 1.0 + 0.1 * k, human(1.0))
        b.joints("/robot/joint_states", 5.0 + 0.1 * k, ["j1"], [0.0])
    path = b.write(tmp_path / "apart.bag")
    with pytest.raises(DataFileError, match=r"apart\.bag, demonstration 0 .*the streams do not overlap in time "
                                            r"\(/human/wrist 0\.000-0\.900 s; /robot/joint_states 4\.000-4\.900 s\)"):
        load_rosbag(path, ["/human/wrist", "/robot/joint_states"])


def test_missing_topic_wrong_type_and_bad_options(tmp_path):
    b = two_agent_bag("mcap", marker="/go")
    b.mark("/chatter", 10.5, "hello")
    path = b.write(bag_path(tmp_path, "mcap"))
    with pytest.raises(DataFileError, match=r"rec: no topic '/robot/pose' \(controlled agent, topics=/human/wrist,"
                                            r"/robot/pose\); the bag has: /chatter \(std_msgs/msg/String\), /go "):
        load_rosbag(path, ["/human/wrist", "/robot/pose"])
    with pytest.raises(DataFileError, match=r"topic '/chatter' \(controlled agent\) has messages of type "
                                            r"std_msgs/msg/String; expected one of sensor_msgs/msg/JointState"):
        load_rosbag(path, ["/human/wrist", "/chatter"])
    with pytest.raises(DataFileError, match=r"no topic '/stop' \(split_topic=/stop\)"):
        load_rosbag(path, ["/human/wrist", "/robot/joint_states"], split_topic="/stop")
    with pytest.raises(DataFileError, match=r"a ROS bag needs topics=OBSERVED,CONTROLLED"):
        load_demonstrations(path)
    with pytest.raises(DataFileError, match=r"the observed and controlled agents are the same stream"):
        load_rosbag(path, ["/human/wrist", "human/wrist"])
    with pytest.raises(DataFileError, match=r"the option markers= applies to C3D, Qualisys TSV, Motive CSV files, "
                                            r"not to this ROS bag file"):
        load_demonstrations(path, topics="/human/wrist", markers="x")
    single = load_rosbag(path, "/human/wrist")  # one agent
    assert single.columns == ["human/wrist_x", "human/wrist_y", "human/wrist_z"] and single.observed_dofs is None


@pytest.mark.parametrize("kind", KINDS)
def test_damaged_bags_name_the_file(tmp_path, kind):
    path = two_agent_bag(kind).write(bag_path(tmp_path, kind))
    file = path if kind == "ros1" else next(path.glob(f"*.{kind}"))
    data = file.read_bytes()
    cut = tmp_path / f"cut{file.suffix}"
    cut.write_bytes(data[: len(data) // 2])
    with pytest.raises(DataFileError, match=rf"cut\{file.suffix}: "):
        load_rosbag(cut, ["/human/wrist", "/robot/joint_states"])
    junk = tmp_path / f"junk{file.suffix}"
    junk.write_bytes(bytes(np.random.default_rng(1).integers(0, 256, 4000, dtype=np.uint8)))
    with pytest.raises(DataFileError, match=rf"junk\{file.suffix}: not a readable ROS bag"):
        load_rosbag(junk, ["/human/wrist", "/robot/joint_states"])


@pytest.mark.parametrize("kind", KINDS)
def test_random_damage_never_escapes_as_another_error(tmp_path, kind):
    path = two_agent_bag(kind, n=15).write(bag_path(tmp_path, kind))
    file = path if kind == "ros1" else next(path.glob(f"*.{kind}"))
    good = file.read_bytes()
    rnd = random.Random(3)
    outcomes = set()
    for k in range(25):
        b = bytearray(good)
        if k % 3 == 0:
            b = b[: rnd.randrange(len(b))]
        else:
            for _ in range(rnd.randint(1, 6)):
                b[rnd.randrange(len(b))] = rnd.randrange(256)
        p = tmp_path / f"d{k}{file.suffix}"
        p.write_bytes(bytes(b))
        try:
            load_rosbag(p, ["/human/wrist", "/robot/joint_states"], max_nan_gap=20, min_frames=1)
            outcomes.add("read")
        except DataFileError as exc:
            assert f"d{k}{file.suffix}" in str(exc)
            outcomes.add("error")
    assert "error" in outcomes


def test_without_the_extra_names_it(monkeypatch, tmp_path):
    import builtins

    path = two_agent_bag("ros1").write(tmp_path / "x.bag")
    real = builtins.__import__

    def fake(name, *args, **kwargs):
        if name.startswith("rosbags"):
            raise ImportError("No module named 'rosbags'")
        return real(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", fake)
    with pytest.raises(MissingExtraError, match=r"pip install 'interprim\[ros\]'"):
        load_rosbag(path, ["/human/wrist", "/robot/joint_states"])


# ----------------------------------------------------------------------------- command line
@pytest.mark.slow  # fits through the CLI
def test_cli_fit_on_a_bag_split_by_markers(tmp_path, capsys):
    import interprim as ip
    from interprim.cli import main

    b = Bag("mcap")
    rng = np.random.default_rng(0)
    for d in range(5):
        t0, amp, n = 10.0 + 3 * d, rng.uniform(0.8, 1.2), 40 + 3 * d
        b.mark("/demo_start", t0 - 0.2)
        for k in range(n):
            s = k / (n - 1)
            t = t0 + 0.025 * k
            b.pose("/human/wrist", t, [amp * np.sin(np.pi * s / 2), 0.2 * s, 1.0])
            b.joints("/robot/joint_states", t + 0.004, ["j1", "j2"], [amp * s**2, -0.5 * amp * s])
    path = b.write(tmp_path / "rec")
    model = tmp_path / "m.npz"
    argv = ["fit", "--model", "ip", str(path), "--topics", "/human/wrist,/robot/joint_states", "--split-topic",
            "/demo_start",
            "--n-basis", "5", "-o", str(model)]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert out.startswith("fitted 5 demonstrations, 5 columns")
    m = ip.InteractionPrimitive.load(model)
    assert list(m.columns_) == ["human/wrist_x", "human/wrist_y", "human/wrist_z", "j1", "j2"]
    assert list(m.observed_dofs_) == [0, 1, 2]
    assert main(argv[:-1] + [str(tmp_path / "g.npz"), "--resample", "0.05"]) == 0
    assert ip.InteractionPrimitive.load(tmp_path / "g.npz").dt_ == pytest.approx(0.05)
    assert main(["evaluate", "--data", str(path), "--topics", "/human/wrist,/robot/joint_states", "--split-topic",
                 "/demo_start", "--resample", "0.05", "--n-basis", "5", "--out", str(tmp_path / "ev")]) == 0
    assert (tmp_path / "ev" / "report.md").is_file()
    capsys.readouterr()
    assert main(["fit", "--model", "ip", str(path), "-o", str(model)]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "a ROS bag needs --topics OBSERVED,CONTROLLED" in err
    assert main(["fit", "--model", "ip", str(path), "--topics", "/human/wrist,/robot/joint_states", "--split-topic",
                 "/nope",
                 "-o", str(model)]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no topic '/nope' (--split-topic /nope)" in err

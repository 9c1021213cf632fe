"""Learn a handover from a ROS 2 bag: a person's wrist pose (motion capture) and a robot's joint states.

Writes one small synthetic recording of twelve handovers, separated by pauses, as a ROS 2 bag (MCAP storage)
into a temporary folder: ``/human/wrist`` (geometry_msgs/PoseStamped, 50 Hz) and ``/robot/joint_states``
(sensor_msgs/JointState, 100 Hz, its own clock phase).  The bag is split at the pauses, both streams are
interpolated onto a common 20 ms grid, an Interaction Primitive is fitted on eight handovers (wrist observed,
joints controlled), and the robot's joints are predicted in the four others from the first half of the wrist's
movement.  Needs ``pip install 'interprim[ros]'`` (rosbags; no ROS installation).
"""

import tempfile
from pathlib import Path

import numpy as np
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

import interprim as ip
from interprim.core.preprocessing import time_normalise
from interprim.datasets import load_rosbag


def write_bag(path, rng):
    ts = get_typestore(Stores.ROS2_HUMBLE)
    T = ts.types

    def header(t):
        return T["std_msgs/msg/Header"](T["builtin_interfaces/msg/Time"](int(t), int(round(t % 1 * 1e9))), "world")

    msgs, t0 = [], 100.0
    for _ in range(12):
        dur, reach = rng.uniform(1.2, 1.8), rng.uniform(0.3, 0.6)  # the person's speed and reach vary
        for t in np.arange(t0, t0 + dur, 0.02):  # the wrist moves out to `reach` metres
            s = (t - t0) / dur
            s = 10 * s**3 - 15 * s**4 + 6 * s**5
            pose = T["geometry_msgs/msg/Pose"](T["geometry_msgs/msg/Point"](reach * s, 0.1 * s, 1.0 + 0.2 * s),
                                               T["geometry_msgs/msg/Quaternion"](0.0, 0.0, 0.0, 1.0))
            msgs.append((t, "/human/wrist", "geometry_msgs/msg/PoseStamped",
                         T["geometry_msgs/msg/PoseStamped"](header(t), pose)))
        for t in np.arange(t0 + 0.003, t0 + dur, 0.01):  # the robot turns and extends its arm to meet it
            s = np.clip((t - t0) / dur, 0, 1)
            s = 10 * s**3 - 15 * s**4 + 6 * s**5
            q = np.array([0.8 * reach * s, 0.5 + 1.5 * reach * s, -0.4 * s])
            msgs.append((t, "/robot/joint_states", "sensor_msgs/msg/JointState", T["sensor_msgs/msg/JointState"](
                header(t), ["shoulder", "elbow", "wrist"], q, np.zeros(0), np.zeros(0))))
        t0 += dur + 2.0  # a pause between handovers
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        conns = {}
        for t, topic, typ, msg in sorted(msgs, key=lambda m: m[0]):
            if topic not in conns:
                conns[topic] = w.add_connection(topic, typ, typestore=ts)
            w.write(conns[topic], int(round(t * 1e9)), ts.serialize_cdr(msg, typ))


def main():
    with tempfile.TemporaryDirectory() as tmp:
        write_bag(Path(tmp) / "handovers", np.random.default_rng(3))
        ds = load_rosbag(Path(tmp) / "handovers", ["/human/wrist", "/robot/joint_states"], split_gap=1.0,
                         resample_dt=0.02)
    obs = ds.observed_dofs  # the first topic's columns: human/wrist_x, _y, _z
    n = len(obs)
    model = ip.InteractionPrimitive(observed_dofs=obs, n_basis=8).fit(ds.demos[:8], dt=ds.dt)
    err, err0 = [], []
    for test in ds.demos[8:]:
        seen, truth = test[: len(test) // 2, :n], time_normalise(test, 100)[:, n:]
        err.append(np.mean((model.predict(seen).trajectory(100)[:, n:] - truth) ** 2))
        err0.append(np.mean((model.predict(seen[:1]).trajectory(100)[:, n:] - truth) ** 2))
    print(f"ROS 2 bag: {len(ds)} handovers split at pauses, columns {', '.join(ds.columns)}; robot joints from half "
          f"of the wrist's reach: RMSE {np.sqrt(np.mean(err)):.3f} rad (from its first frame only: "
          f"{np.sqrt(np.mean(err0)):.3f} rad)")


if __name__ == "__main__":
    main()

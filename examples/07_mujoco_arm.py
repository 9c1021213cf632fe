"""Step 7 - a physics-simulated robot answering a partner live: the high five in MuJoCo.

    python examples/07_mujoco_arm.py [FIGURE.png]          (default: a temporary folder)
    python examples/07_mujoco_arm.py --ros2 [FIGURE.png]   the same, through `interprim ros2` (tutorial step 12)

The robot is a torque-controlled 3-joint arm (masses, gravity, motor limits; MJCF shipped with interprim)
whose joint controller (PD + inverse dynamics) tracks the IP's predicted response; a held-out partner is
replayed and each of its frames goes to `model.stream()`.  Reports whether and when the hands meet and
draws the run (matplotlib, no display needed).  Needs the [mujoco] extra: pip install "interprim[mujoco]".

With --ros2 the model runs in another process, `interprim ros2` (DDS on this machine only, [ros2] extra): the
simulation publishes the partner's joints as sensor_msgs/JointState, stamped with the simulated time, and its
controller tracks the trajectory_msgs/JointTrajectory it gets back (with phase and duration from the
diagnostic_msgs/DiagnosticArray status), as a ROS 2 robot would.
"""
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from interprim.sim.mujoco_arm import draw_mujoco_highfive, fit_highfive_model, run_mujoco_highfive

args = [a for a in sys.argv[1:] if a != "--ros2"]
over_ros2 = "--ros2" in sys.argv[1:]
figure = Path(args[0]) if args else Path(tempfile.mkdtemp(prefix="interprim-mujoco-")) / "highfive.png"
figure.parent.mkdir(parents=True, exist_ok=True)


class OverRos2:
    """The model as the simulation sees it when it runs behind `interprim ros2`: `stream().update(frame)` publishes
    the partner's joints and waits for the response to that frame (matched by its stamp)."""

    def __init__(self, model, points=201):
        import os
        import random
        import subprocess

        from cyclonedds.domain import Domain, DomainParticipant
        from cyclonedds.pub import DataWriter
        from cyclonedds.sub import DataReader
        from cyclonedds.topic import Topic

        from interprim.ros2 import QosSpec, loopback_config
        from interprim.ros2.messages import dds_topic, message_class

        self.model = model
        self.dir = Path(tempfile.mkdtemp(prefix="interprim-ros2-"))
        model.save(self.dir / "highfive.npz")
        domain = random.randint(30, 220)
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "interprim", "ros2", str(self.dir / "highfive.npz"), "--localhost",
             "--domain-id", str(domain), "--observe", "/partner/joints:obs_shoulder=dof_0,obs_elbow=dof_1@JointState",
             "--publish", "/robot/response", "--points", str(points)],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=dict(os.environ))
        for _ in range(2):
            print("  bridge:", self.proc.stdout.readline().strip())
        self._domain = Domain(domain, loopback_config())
        dp = DomainParticipant(domain)
        self.writer = DataWriter(dp, Topic(dp, dds_topic("/partner/joints"), message_class("JointState")),
                                 qos=QosSpec.parse("best_effort,1").dds())
        reliable = QosSpec.parse("reliable,10").dds()
        self.response = DataReader(dp, Topic(dp, dds_topic("/robot/response"), message_class("JointTrajectory")),
                                   qos=reliable)
        self.status = DataReader(dp, Topic(dp, dds_topic("/robot/response/status"), message_class("DiagnosticArray")),
                                 qos=reliable)
        time.sleep(1.0)  # DDS discovery

    def __getattr__(self, name):  # dt_, prior_, observed_dofs_, ... of the model
        return getattr(self.model, name)

    def stream(self, robot_state=None):
        return _RemoteStream(self)

    def close(self):
        import signal

        self.proc.send_signal(signal.SIGINT)
        # the bridge answers the frames it has received before it prints its counts: on a busy machine that takes
        # a while, so the wait is generous (a hang still ends the example with an error)
        out, _ = self.proc.communicate(timeout=180)
        print("  bridge:", out.strip().splitlines()[-1])


class _RemoteStream:
    def __init__(self, remote):
        self.r, self.k, self.t0 = remote, 0, int(time.time())

    def update(self, frame):
        from interprim.ros2.messages import new_message, stamp_of

        r, k = self.r, self.k
        self.k += 1
        header = new_message("std_msgs/msg/Header", stamp=stamp_of(k * r.model.dt_, self.t0))
        r.writer.write(new_message("JointState", header=header, name=["obs_shoulder", "obs_elbow"],
                                   position=[float(v) for v in frame]))
        want = (header.stamp.sec, header.stamp.nanosec)
        traj = stat = None
        end = time.monotonic() + 5.0
        while (traj is None or stat is None) and time.monotonic() < end:
            for m in r.response.take(N=10):
                traj = m if (m.header.stamp.sec, m.header.stamp.nanosec) == want else traj
            for m in r.status.take(N=10):
                stat = m if (m.header.stamp.sec, m.header.stamp.nanosec) == want else stat
            time.sleep(0.0002)
        if traj is None or stat is None:
            raise RuntimeError(f"no response to frame {k} from interprim ros2 within 5 s")
        return _Response(traj, stat)


class _Response:
    """The prediction's parts that the simulation's controller uses, rebuilt from the two messages."""

    def __init__(self, traj, stat):
        v = {kv.key: kv.value for kv in stat.status[0].values}
        self.phase, self.normalised_time = float(v["phase"]), float(v["normalised_time"])
        self.duration, self.out_of_range = float(v["duration"]), v["out_of_range"] == "true"
        t = np.array([p.time_from_start.sec + p.time_from_start.nanosec * 1e-9 for p in traj.points])
        self.s = self.normalised_time + t / self.duration  # the points' normalised times
        self.y = np.array([p.positions for p in traj.points])
        self.v = np.array([p.velocities for p in traj.points])  # per second

    def mean_rollout(self, n, columns):
        def on_grid(p):
            """The response from now to the end on linspace(0, 1, n), through the cubic Hermite spline of its points and
            velocities (as a ROS 2 joint trajectory controller follows it); before now the spline is extended by a few
            grid steps, then held.  The controller takes the reference's velocity and acceleration from this grid by
            finite differences, so it must be smooth around now (a linear interpolation, held flat before now, gave
            it a kink there and an acceleration made of spikes: 0.029 rad of tracking error instead of 0.007)."""
            from scipy.interpolate import CubicHermiteSpline

            u = np.linspace(0.0, 1.0, n)
            spline = CubicHermiteSpline(p.s, p.y, p.v * p.duration, axis=0)  # dy/ds = dy/dt * duration
            return spline(np.clip(u, p.s[0] - 3.0 / (n - 1), p.s[-1]))

        return on_grid


tic = time.perf_counter()
model = fit_highfive_model(n_train=40, seed=0)  # the simulated high five, robot joints as controlled DoFs
print(f"fitted the model in {time.perf_counter() - tic:.1f} s")

remote = OverRos2(model) if over_ros2 else None
tic = time.perf_counter()
try:
    result = run_mujoco_highfive(remote or model, seed=0)  # a held-out partner (its goal is not in the training set)
finally:
    if remote is not None:
        remote.close()
print(f"simulated {result.t[-1]:.2f} s in {time.perf_counter() - tic:.1f} s")
print(result.summary())
if result.goal is not None:
    print(f"true high-five point {result.goal.round(3)} m; robot hand at the end {result.robot_hand[-1].round(3)} m")
print(f"figure: {draw_mujoco_highfive(result, figure)}")

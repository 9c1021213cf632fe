"""Latency of ``interprim ros2``: from a partner message published to the response received, at 100 Hz.

The bridge runs as the command (``python -m interprim ros2 MODEL --localhost``) in its own process; this process
publishes ``geometry_msgs/msg/PointStamped`` samples at 100 Hz (held-out synthetic interactions, one after the
other, a 1 s jump of the stamps between two so that each is a new interaction) and reads the
``trajectory_msgs/msg/JointTrajectory`` responses.  A response is matched to its partner message by
``header.stamp``; the latency is the receive time minus the publish time, both on this process's monotonic clock.
All DDS traffic stays on the loopback interface.

    python -m benchmarks.ros2_latency                    # IP and the default model (AutoInteraction)
    python -m benchmarks.ros2_latency --seconds 20 --models ip

Models (fitted here on ``interprim.synthetic.two_agent_demos``, dt 10 ms, 2 observed + 3 controlled columns):
``ip``: InteractionPrimitive (defaults, 20 demonstrations); ``auto``: AutoInteraction (defaults, 12 demonstrations of
~100 frames, which keeps its fit under a minute).  Responses of 20 points.
"""

from __future__ import annotations

import argparse
import os
import platform
import random
import signal
import subprocess
import sys
import tempfile
import time
import uuid
from pathlib import Path

import numpy as np

NAMES = ["human/hand_x", "human/hand_y", "j1", "j2", "j3"]


def _fit(kind, out: Path):
    import interprim as ip
    from interprim.synthetic import two_agent_demos

    t = time.perf_counter()
    if kind == "ip":
        demos = two_agent_demos(20, seed=0, frames=150)
        m = ip.InteractionPrimitive(observed_dofs=[0, 1]).fit(demos, dt=0.01, columns=NAMES)
        size = "20 demos x 150 frames"
    else:
        from interprim.datasets import Demonstrations

        demos = two_agent_demos(12, seed=0, frames=100)
        ds = Demonstrations(demos=demos, times=None, columns=NAMES, dt=0.01, observed_dofs=[0, 1], name="synthetic")
        m = ip.AutoInteraction(observed_dofs=[0, 1]).fit(ds)
        size = "12 demos x 100 frames"
    m.save(out)
    return m, size, time.perf_counter() - t


def run_one(kind: str, seconds: float, rate: float, workdir: Path):
    from cyclonedds.domain import Domain, DomainParticipant
    from cyclonedds.pub import DataWriter
    from cyclonedds.sub import DataReader
    from cyclonedds.topic import Topic

    from interprim.ros2 import loopback_config
    from interprim.ros2.bridge import QosSpec
    from interprim.ros2.messages import dds_topic, message_class, new_message, stamp_of
    from interprim.synthetic import two_agent_demos

    path = workdir / f"{kind}.npz"
    model, size, fit_s = _fit(kind, path)
    did = random.Random(time.time_ns()).randint(30, 220)
    hand, resp = f"/b{uuid.uuid4().hex[:6]}/hand", f"/b{uuid.uuid4().hex[:6]}/response"
    src = str(Path(__file__).resolve().parents[1] / "src")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([src, os.environ.get("PYTHONPATH", "")]))
    proc = subprocess.Popen([sys.executable, "-m", "interprim", "ros2", str(path), "--observe",
                             hand + ":x=human/hand_x,y=human/hand_y@PointStamped", "--publish", resp,
                             "--domain-id", str(did), "--localhost"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=env)
    try:
        proc.stdout.readline()
        proc.stdout.readline()  # the two start-up lines: the bridge is up
        dom = Domain(did, loopback_config())  # noqa: F841
        dp = DomainParticipant(did)
        w = DataWriter(dp, Topic(dp, dds_topic(hand), message_class("PointStamped")),
                       qos=QosSpec.parse("best_effort,1").dds())
        r = DataReader(dp, Topic(dp, dds_topic(resp), message_class("JointTrajectory")),
                       qos=QosSpec.parse("reliable,100").dds())
        held = two_agent_demos(10, seed=77, frames=150 if kind == "ip" else 100)
        frames = []  # (stamp, x, y)
        t_stamp = 1000.0
        for d in held:
            for row in d:
                frames.append((t_stamp, row[0], row[1]))
                t_stamp += 0.01
            t_stamp += 1.0
        # warm up: until the first response arrives (discovery), then the timed run
        sent, got = {}, {}
        k, end = 0, time.monotonic() + 15
        while not got and time.monotonic() < end:
            s, x, y = frames[k % len(frames)]
            w.write(new_message("PointStamped", header=new_message("std_msgs/msg/Header", stamp=stamp_of(s)),
                                point=new_message("geometry_msgs/msg/Point", x=x, y=y)))
            k += 1
            time.sleep(0.02)
            got = {m.header.stamp.sec: 1 for m in r.take(N=100)}
        if not got:
            raise RuntimeError("the bridge never answered (discovery on the loopback interface failed?)")
        time.sleep(0.5)
        r.take(N=1000)
        n = int(seconds * rate)
        period = 1.0 / rate
        base = frames[k % len(frames)][0] + 10.0  # a new interaction after the warm-up
        got = {}
        t_next = time.monotonic()
        for i in range(n):
            j = i % len(frames)
            s = base + frames[j][0] - frames[0][0] + (i // len(frames)) * (frames[-1][0] - frames[0][0] + 1.0)
            msg = new_message("PointStamped", header=new_message("std_msgs/msg/Header", stamp=stamp_of(s)),
                              point=new_message("geometry_msgs/msg/Point", x=frames[j][1], y=frames[j][2]))
            key = int(round(s * 1e6))
            sent[key] = time.monotonic()
            w.write(msg)
            t_next += period
            while True:
                now = time.monotonic()
                for m in r.take(N=100):
                    got[int(round((m.header.stamp.sec + m.header.stamp.nanosec * 1e-9) * 1e6))] = now
                    now = time.monotonic()
                if now >= t_next:
                    break
                time.sleep(min(0.0002, t_next - now))
        end = time.monotonic() + 1.0
        while time.monotonic() < end:
            for m in r.take(N=100):
                got[int(round((m.header.stamp.sec + m.header.stamp.nanosec * 1e-9) * 1e6))] = time.monotonic()
            time.sleep(0.001)
    finally:
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=30)
    lat = np.array([got[key] - t0 for key, t0 in sent.items() if key in got]) * 1e3
    return {"model": type(model).__name__, "size": size, "fit_s": fit_s, "sent": len(sent), "answered": len(lat),
            "median_ms": float(np.median(lat)), "p99_ms": float(np.percentile(lat, 99)),
            "max_ms": float(lat.max()), "bridge": out.strip().splitlines()[-1] if out.strip() else err[-300:]}


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--models", default="ip,auto", help="comma-separated: ip, auto (default both)")
    p.add_argument("--seconds", type=float, default=10.0, help="timed run per model (default 10 s at 100 Hz)")
    p.add_argument("--rate", type=float, default=100.0, help="partner messages per second (default 100)")
    args = p.parse_args(argv)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for kind in [m.strip() for m in args.models.split(",") if m.strip()]:
            rows.append(run_one(kind, args.seconds, args.rate, Path(tmp)))
    print(f"Machine: {platform.processor() or platform.machine()}, {os.cpu_count()} logical cores, Python "
          f"{platform.python_version()}; load average {os.getloadavg()}")
    print()
    print("| model | fitted on | rate | messages answered | latency median | latency p99 | max |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['model']} | {r['size']} (fit {r['fit_s']:.1f} s) | {args.rate:g} Hz | {r['answered']}/{r['sent']} "
              f"| {r['median_ms']:.2f} ms | {r['p99_ms']:.2f} ms | {r['max_ms']:.2f} ms |")
    for r in rows:
        print(f"\n{r['model']} bridge: {r['bridge']}")


if __name__ == "__main__":
    main()

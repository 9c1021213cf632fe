"""Step 6 - run the model behind `interprim serve` and stream a movement to it with the Python client.

    python examples/06_serve_and_client.py [OUT_DIR]

Starts `interprim serve MODEL --port 0` (a free loopback port) as a subprocess, reads the address it prints,
connects `interprim.server.Client`, streams a held-out movement frame by frame, then stops the server with
SIGTERM (what a service manager sends; Ctrl-C gives status 130) and checks it exited cleanly.  Needs the [serve] extra.
"""
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import interprim as ip
from interprim.server.client import Client
from interprim.sim import highfive_recordings

out = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(tempfile.mkdtemp(prefix="interprim-serve-"))
out.mkdir(parents=True, exist_ok=True)
model_path = out / "highfive.npz"
ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=10).fit(highfive_recordings(20, seed=0)).save(model_path)

server = subprocess.Popen([sys.executable, "-m", "interprim", "serve", str(model_path), "--port", "0",
                           "--log-level", "WARNING"], stdout=subprocess.PIPE, text=True)
try:
    line = server.stdout.readline()  # "interprim serve: open http://127.0.0.1:PORT/  (WebSocket ws://...; ...)"
    if "WebSocket" not in line:
        raise SystemExit(f"the server did not start: {line!r} (exit status {server.poll()})")
    url = line.split("WebSocket ")[1].split(";")[0]
    print(f"server at {url}")
    partner = highfive_recordings(1, seed=7, region="test")[0]
    rtt = []
    with Client(url) as client:
        opened = client.open("highfive", points=50, std=True)  # the model's name is its file stem
        print(f"opened {opened['model']}: columns {opened['columns']}")
        dt = next(m["dt"] for m in client.models if m["name"] == "highfive")  # from the server's welcome
        next_tick = time.perf_counter()
        for frame in partner[:, :2]:  # at the sensor's rate (the model's dt; the server limits bursts)
            tic = time.perf_counter()
            reply = client.frame(frame)  # one prediction per frame, in order
            rtt.append(time.perf_counter() - tic)
            next_tick += dt
            time.sleep(max(0.0, next_tick - time.perf_counter()))
            if reply["out_of_range"]:
                print("out of range: wrong units or frame?")
            if reply["conditioned"] and reply["phase"] >= 1.0:  # over (phase is null for the first frames)
                break
    final = np.array(reply["mean"])[-1]  # predicted final posture of the robot (the controlled columns)
    print(f"{len(rtt)} frames: phase {reply['phase']:.2f}, final posture {np.round(final, 2)} rad "
          f"(true {np.round(partner[-1, 2:], 2)}), server compute {reply['compute_ms']:.2f} ms, "
          f"round trip median {1e3 * np.median(rtt):.2f} ms, p99 {1e3 * np.percentile(rtt, 99):.2f} ms")
finally:
    server.send_signal(signal.SIGTERM)  # sessions answered and closed, workers joined: exit status 0
    rest, _ = server.communicate(timeout=30)
print(rest.strip())
print(f"server stopped cleanly (exit status {server.returncode})" if server.returncode == 0
      else f"server exit status {server.returncode}")
sys.exit(server.returncode)

"""Step 7 - a physics-simulated robot answering a partner live: the high five in MuJoCo.

    python examples/07_mujoco_arm.py [FIGURE.png]      (default: a temporary folder)

The robot is a torque-controlled 3-joint arm (masses, gravity, motor limits; MJCF shipped with interprim)
whose joint controller (PD + inverse dynamics) tracks the IP's predicted response; a held-out partner is
replayed and each of its frames goes to `model.stream()`.  Reports whether and when the hands meet and
draws the run (matplotlib, no display needed).  Needs the [mujoco] extra: pip install "interprim[mujoco]".
"""
import sys
import tempfile
import time
from pathlib import Path

from interprim.sim.mujoco_arm import draw_mujoco_highfive, fit_highfive_model, run_mujoco_highfive

figure = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(tempfile.mkdtemp(prefix="interprim-mujoco-")) / "highfive.png"
figure.parent.mkdir(parents=True, exist_ok=True)

tic = time.perf_counter()
model = fit_highfive_model(n_train=40, seed=0)  # the simulated high five, robot joints as controlled DoFs
print(f"fitted the model in {time.perf_counter() - tic:.1f} s")

tic = time.perf_counter()
result = run_mujoco_highfive(model, seed=0)  # a held-out partner (its goal is not in the training set)
print(f"simulated {result.t[-1]:.2f} s in {time.perf_counter() - tic:.1f} s")
print(result.summary())
if result.goal is not None:
    print(f"true high-five point {result.goal.round(3)} m; robot hand at the end {result.robot_hand[-1].round(3)} m")
print(f"figure: {draw_mujoco_highfive(result, figure)}")

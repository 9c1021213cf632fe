"""Step 1 - check recordings before fitting: lengths, time step, missing frames (NaN gaps), ranges, a plot.

    python examples/01_check_data.py [OUT_DIR]        (default: a new temporary folder)

It writes a practice set (the simulated high five as a lab records it: the partner's hand in metres with
tracker noise, the robot's joints in radians; one tracker dropout of 3 frames) to OUT_DIR/recordings.csv,
then checks it the way you should check yours (docs/tutorial.md, "Check the data").
"""
import sys
import tempfile
from pathlib import Path

import numpy as np

from interprim import DataFileError
from interprim.datasets import load_demonstrations, save_demonstrations
from interprim.sim import highfive_recordings

out = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(tempfile.mkdtemp(prefix="interprim-check-"))
out.mkdir(parents=True, exist_ok=True)
csv = out / "recordings.csv"
save_demonstrations(csv, highfive_recordings(20, seed=0))
lines = csv.read_text().splitlines()  # the tracker lost the partner's hand for 3 frames of demonstration 4:
rows = [i for i, line in enumerate(lines) if line.startswith("4,")]
for i in rows[60:63]:
    cells = lines[i].split(",")  # demo, time, human_x, human_y, robot_...
    cells[2] = cells[3] = ""  # empty cells (or nan, NA, null) are missing values
    lines[i] = ",".join(cells)
csv.write_text("\n".join(lines) + "\n")

# 1. missing values are an error by default, naming the file, column and line
try:
    load_demonstrations(csv)
except DataFileError as exc:
    print(f"as recorded: {exc}")
ds = load_demonstrations(csv, max_nan_gap=5)  # fill interior gaps of <= 5 frames linearly (`--max-nan-gap 5`)

# 2. lengths, time step, durations: the phase estimation needs similar movements, not identical lengths
lengths = np.array([len(d) for d in ds])
print(f"{len(ds)} demonstrations, {lengths.min()}-{lengths.max()} frames, dt = {ds.dt:.4g} s "
      f"({1 / ds.dt:.0f} Hz), durations {(lengths.min() - 1) * ds.dt:.2f}-{(lengths.max() - 1) * ds.dt:.2f} s")
if ds.dt is None:
    print("irregular time stamps: pass resample_dt= (or `interprim fit --resample DT`)")

# 3. ranges per column: units (metres? millimetres?) and frames of reference show up here
allf = np.vstack(ds.demos)
for j, name in enumerate(ds.columns):
    role = "observed " if j in ds.observed_dofs else "controlled"
    print(f"  {role} {name:15s} min {allf[:, j].min():8.3f}  max {allf[:, j].max():8.3f}  "
          f"start spread (std) {np.std([d[0, j] for d in ds]):.3f}")

# 4. a plot of every demonstration over normalised time: outliers and swapped columns stand out
import matplotlib  # noqa: E402  (the [plot] extra)

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

fig, axes = plt.subplots(1, ds.n_dofs, figsize=(3 * ds.n_dofs, 2.6))
for ax, j in zip(axes, range(ds.n_dofs)):
    for d in ds:
        ax.plot(np.linspace(0, 1, len(d)), d[:, j], lw=0.7)
    ax.set_title(ds.columns[j], fontsize=9)
    ax.set_xlabel("normalised time")
fig.tight_layout()
png = out / "check.png"
fig.savefig(png, dpi=80)
print(f"checked {len(ds)} demonstrations; plot: {png}; data: {csv}")

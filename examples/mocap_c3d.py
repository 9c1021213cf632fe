"""Learn a handover from C3D motion capture (Vicon/OptiTrack/Qualisys exports).

Writes twelve small synthetic two-person takes (person A reaches out, person B meets A's hand) as C3D files
in millimetres into a temporary folder, loads the folder (one demonstration per file, markers in metres),
fits an Interaction Primitive (A observed, B's hand controlled) on eight takes, and predicts B's hand in the
four others from the first half of A's movement.  Needs ``pip install 'interprim[mocap]'``.
"""

import tempfile
from pathlib import Path

import ezc3d
import numpy as np

import interprim as ip
from interprim.core.preprocessing import time_normalise
from interprim.datasets import load_c3d

LABELS = ["A:RHand", "A:RWrist", "B:RHand", "B:RWrist"]


def write_take(path, rng, rate=100.0):
    """One take: both right hands move (minimum jerk) to a meeting point that varies from take to take."""
    T = int(rng.integers(80, 120))
    s = np.linspace(0, 1, T)
    s = 10 * s**3 - 15 * s**4 + 6 * s**5
    meet = np.array([700.0, 0.0, 1100.0]) + rng.normal(0, [60, 80, 60])  # mm
    a0, b0 = np.array([200.0, 150.0, 900.0]), np.array([1200.0, -150.0, 900.0])
    a = a0 + s[:, None] * (meet - a0)
    b = b0 + s[:, None] * (meet + [80.0, 0, 0] - b0)
    xyz = np.stack([a, a - [0, 0, 80], b, b - [0, 0, 80]], axis=1)  # (T, 4 markers, 3)
    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [rate]
    c["parameters"]["POINT"]["LABELS"]["value"] = LABELS
    c["parameters"]["POINT"]["UNITS"]["value"] = ["mm"]
    pts = np.ones((4, len(LABELS), T))  # x, y, z, 1 per marker and frame
    pts[:3] = np.transpose(xyz, (2, 1, 0))
    c["data"]["points"] = pts
    c.write(str(path))


def main():
    rng = np.random.default_rng(1)
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(12):
            write_take(Path(tmp) / f"take{k:02d}.c3d", rng)
        ds = load_c3d(tmp, markers=["A:RHand", "A:RWrist", "B:RHand"])  # B's wrist is not needed
    observed = [ds.columns.index(c) for c in ds.columns if c.startswith("A:")]
    n_obs = len(observed)
    model = ip.InteractionPrimitive(observed_dofs=observed, n_basis=8).fit(ds.demos[:8], dt=ds.dt)
    err, err0 = [], []  # squared errors of B's hand on the four held-out takes
    for test in ds.demos[8:]:
        seen, truth = test[: len(test) // 2, :n_obs], time_normalise(test, 100)[:, n_obs:]  # half of A's reach
        err.append(np.mean((model.predict(seen).trajectory(100)[:, n_obs:] - truth) ** 2))
        err0.append(np.mean((model.predict(seen[:1]).trajectory(100)[:, n_obs:] - truth) ** 2))
    print(f"C3D: {len(ds)} takes at {1 / ds.dt:.0f} Hz, {ds.n_dofs} columns in {ds.units[0]}; B's hand from half of "
          f"A's reach: RMSE {1000 * np.sqrt(np.mean(err)):.1f} mm "
          f"(from A's first frame only: {1000 * np.sqrt(np.mean(err0)):.1f} mm)")


if __name__ == "__main__":
    main()

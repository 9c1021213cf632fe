"""Learn a handover from BVH skeleton motion capture (two skeletons in one file).

Writes twelve small synthetic two-person takes as BVH files (lengths in centimetres, angles in degrees) into a
temporary folder, loads the folder with joint positions by forward kinematics converted to metres, fits an
Interaction Primitive (A's arm observed, B's hand controlled) on eight takes, and predicts B's hand in the four
others from the first half of A's movement.  BVH needs no optional extra.
"""

import tempfile
from pathlib import Path

import numpy as np

import interprim as ip
from interprim.core.preprocessing import time_normalise
from interprim.datasets import load_bvh


def person(p, x):
    """One arm: hips (root, translated), shoulder, elbow, hand; B faces A (rotated 180 degrees about y)."""
    return f"""ROOT {p}_Hips
{{
  OFFSET {x} 95 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT {p}_Shoulder
  {{
    OFFSET 0 45 18
    CHANNELS 3 Zrotation Xrotation Yrotation
    JOINT {p}_Elbow
    {{
      OFFSET 0 -30 0
      CHANNELS 3 Zrotation Xrotation Yrotation
      JOINT {p}_Hand
      {{
        OFFSET 0 -28 0
        CHANNELS 0
      }}
    }}
  }}
}}
"""


def write_take(path, rng, fps=60):
    T = int(rng.integers(70, 100))
    s = np.linspace(0, 1, T)
    s = 10 * s**3 - 15 * s**4 + 6 * s**5
    lift, bend = rng.uniform(60, 85), rng.uniform(20, 50)  # how far A reaches; B answers in kind
    zeros = np.zeros(T)
    a = [zeros, zeros + 95, zeros, zeros, zeros, zeros, lift * s, zeros, zeros, bend * s, zeros, zeros]
    b = [zeros + 120, zeros + 95, zeros, zeros, zeros, zeros + 180,
         (0.9 * lift + 5) * s, zeros, zeros, (1.1 * bend) * s, zeros, zeros]
    rows = np.column_stack(a + b)
    motion = "\n".join(" ".join(f"{v:.4f}" for v in r) for r in rows)
    path.write_text("HIERARCHY\n" + person("A", 0) + person("B", 120)
                    + f"MOTION\nFrames: {T}\nFrame Time: {1 / fps:.8f}\n{motion}\n")


def main():
    rng = np.random.default_rng(2)
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(12):
            write_take(Path(tmp) / f"handover{k:02d}.bvh", rng)
        ds = load_bvh(tmp, joints=["A_Elbow", "A_Hand", "B_Hand"], length_unit="cm")
    n_obs = 6  # A's elbow and hand, x/y/z each
    model = ip.InteractionPrimitive(observed_dofs=list(range(n_obs)), n_basis=8).fit(ds.demos[:8], dt=ds.dt)
    err, err0 = [], []  # squared errors of B's hand on the four held-out takes
    for test in ds.demos[8:]:
        seen, truth = test[: len(test) // 2, :n_obs], time_normalise(test, 100)[:, n_obs:]
        err.append(np.mean((model.predict(seen).trajectory(100)[:, n_obs:] - truth) ** 2))
        err0.append(np.mean((model.predict(seen[:1]).trajectory(100)[:, n_obs:] - truth) ** 2))
    print(f"BVH: {len(ds)} takes at {1 / ds.dt:.0f} fps, columns {', '.join(ds.columns[:3])}, ... in m; B's hand "
          f"from half of A's reach: RMSE {100 * np.sqrt(np.mean(err)):.1f} cm "
          f"(from A's first frame only: {100 * np.sqrt(np.mean(err0)):.1f} cm)")


if __name__ == "__main__":
    main()

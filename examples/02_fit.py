"""Step 2 - fit an Interaction Primitive to recordings and predict the robot's response from a partial observation.

    python examples/02_fit.py

Observed DoFs: the partner's hand (metres); controlled: the robot's three joints (radians).  The same as
`interprim fit recordings.csv --observed human_x,human_y --n-basis 10 -o model.npz`.
"""
import time

import numpy as np

import interprim as ip
from interprim.sim import highfive_recordings

train = highfive_recordings(30, seed=0)  # a Demonstrations: arrays + time stamps + column names
test = highfive_recordings(1, seed=7, region="test")[0]  # a held-out interaction (goal not in the training set)

tic = time.perf_counter()
model = ip.InteractionPrimitive(observed_dofs=train.observed_dofs, n_basis=10).fit(train)
print(f"fitted in {time.perf_counter() - tic:.1f} s: dt {model.dt_} s, mean duration {model.mean_duration_:.2f} s")
sel = model.selection_
print(f"  cross-validated noise sigma2 = {sel['sigma2']:.3g} (data units^2; ~ tracker noise^2 + model error), "
      f"shrinkage {sel['shrinkage']:.2f}, held-out error {sel['cv_error']:.4f} "
      f"vs prior mean {sel['cv_error_prior']:.4f}")

ctrl = model.controlled_dofs_
T = len(test)
for frac in (0.3, 0.6, 0.9):
    k = int(frac * T)
    pred = model.predict(test[:k, :2])  # the partner's first k frames
    final = pred.trajectory(100)[-1, ctrl]
    sd = pred.std(100)[-1, ctrl]
    err = np.abs(final - test[-1, ctrl]).max()
    print(f"  seen {100 * k / T:3.0f} %: phase {pred.phase:.2f}, speed {pred.speed:.2f}, final robot posture "
          f"{np.round(final, 2)} +- {np.round(sd, 2)} rad, max error {err:.3f} rad")
t, response = pred.response(50)  # what the robot does from now on, time in seconds from now
print(f"response: {len(t)} points over the next {t[-1]:.2f} s")

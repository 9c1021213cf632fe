"""Step 4 - save a model, load it elsewhere (same predictions), and see the out-of-range check at work.

    python examples/04_save_load.py [OUT_DIR]

Model files are .npz arrays + JSON metadata (never pickle): safe to load from anyone.
"""
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np

import interprim as ip
from interprim.sim import highfive_recordings

out = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(tempfile.mkdtemp(prefix="interprim-model-"))
out.mkdir(parents=True, exist_ok=True)
train = highfive_recordings(20, seed=0)
model = ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=10).fit(train)
path = out / "highfive.npz"
model.save(path)
loaded = ip.InteractionPrimitive.load(path)
print(f"saved {path} ({path.stat().st_size / 1024:.0f} KiB); loaded: {loaded!r}")

partial = highfive_recordings(1, seed=7, region="test")[0][:80, :2]
a, b = model.predict(partial), loaded.predict(partial)
assert np.array_equal(a.trajectory(100), b.trajectory(100)) and a.phase == b.phase
print("loaded model gives identical predictions")

# the same partner in millimetres: far outside the training frames -> a warning and a flag, never silence
with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter("always")
    bad = loaded.predict(1000 * partial)
print(f"millimetres: out_of_range={bad.out_of_range}, input_distance={bad.input_distance:.0f} training stds; "
      f"warning: {caught[0].category.__name__ if caught else None}")
print(f"metres:      out_of_range={a.out_of_range}, input_distance={a.input_distance:.1f}")

"""The core stays light: ``import interprim`` and the robot-side path (fit, predict, stream) never import
the plotting, progress-bar or parallel-job libraries (they are extras: ``[plot]``, ``[experiments]``)."""

import os
import subprocess
import sys

OPTIONAL = ("matplotlib", "tqdm", "joblib")


def _imported(code: str) -> list:
    probe = code + f"\nprint(','.join(m for m in {OPTIONAL!r} if m in sys.modules))"
    env = dict(os.environ, INTERPRIM_JIT="0")
    out = subprocess.run([sys.executable, "-c", "import sys\n" + probe], capture_output=True, text=True, env=env,
                         check=True, timeout=300)
    return [m for m in out.stdout.strip().splitlines()[-1].split(",") if m] if out.stdout.strip() else []


def test_import_interprim_imports_no_optional_library():
    assert _imported("import interprim\ninterprim.InteractionPrimitive, interprim.Prediction, interprim.Stream") == []


def test_fit_predict_stream_import_no_optional_library():
    code = """
import interprim as ip
from interprim.synthetic import two_agent_demos
demos = two_agent_demos(6, seed=0, frames=60)
m = ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=6).fit(demos[:5], dt=0.01)
m.predict(demos[5][:30, :2]).trajectory(10)
st = m.stream()
for f in demos[5][:5, :2]:
    st.update(f)
"""
    assert _imported(code) == []

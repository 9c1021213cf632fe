"""Every script in examples/ runs: exit status 0 and its expected line on stdout.

Each example runs in a fresh subprocess with a temporary working directory (and TMPDIR inside it, so the
temporary folders the examples write to are removed with it): nothing is written into the repository.
Examples added later are picked up by the glob; add their expected line to EXPECTED.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

EXAMPLES = sorted((Path(__file__).resolve().parents[1] / "examples").glob("*.py"))

#: a regular expression each example's stdout must match (examples not listed: exit status 0 and some output)
EXPECTED = {
    "01_check_data.py": r"as recorded: .*missing value[\s\S]*\nchecked 20 demonstrations; plot: .*check\.png",
    "02_fit.py": r"fitted in .* s: dt 0\.01 s.*\n[\s\S]*seen +90 %: phase 0\.\d+",
    "03_evaluate.py": r"verdict: chosen inside the training folds: .*Conditioning on the human helps[\s\S]*"
                      r"forward check: Your latest 6 of 16 recordings[\s\S]*forward in recording order: the default "
                      r"blend .* predicts the rest of the movement of the latest third with [\d.]+x",
    "04_save_load.py": r"loaded model gives identical predictions\nmillimetres: out_of_range=True.*OutOfRangeWarning",
    "05_stream_control_loop.py": r"ticks at 100 Hz, \d+ updates: latency median [\d.]+ ms, p99 [\d.]+ ms\n"
                                 r"final joint error [\d.]+ rad; robot hand [\d.]+ cm",
    "06_serve_and_client.py": r"round trip median .*\n(.*\n)*server stopped cleanly \(exit status 0\)",
    "07_mujoco_arm.py": r"hands met at t = [\d.]+ s .*\n.*\nfigure: .*highfive\.png",
}


def test_examples_exist():
    names = {p.name for p in EXAMPLES}
    assert set(EXPECTED) <= names, f"missing examples: {sorted(set(EXPECTED) - names)}"


@pytest.mark.slow  # one subprocess per example, some run for a minute
@pytest.mark.parametrize("script", EXAMPLES, ids=[p.name for p in EXAMPLES])
def test_example_runs(script, tmp_path):
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    env = dict(os.environ, MPLBACKEND="Agg", TMPDIR=str(tmp), PYTHONUNBUFFERED="1")
    try:
        r = subprocess.run([sys.executable, str(script)], cwd=tmp_path, env=env, capture_output=True, text=True,
                           timeout=900)
    except subprocess.TimeoutExpired as exc:
        pytest.fail(f"{script.name} did not finish in {exc.timeout} s; output so far: {exc.stdout!r}")
    assert r.returncode == 0, f"{script.name} exited with {r.returncode}\nstdout:\n{r.stdout}\nstderr:\n{r.stderr}"
    assert r.stdout.strip(), f"{script.name} printed nothing"
    pattern = EXPECTED.get(script.name)
    if pattern is not None:
        assert re.search(pattern, r.stdout), f"{script.name}: no match for {pattern!r} in\n{r.stdout}"
    assert "Traceback" not in r.stderr, r.stderr

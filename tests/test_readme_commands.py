"""The README's commands in a fresh virtual environment with exactly the extras the README names.

``bash scripts/demo.sh`` installs the ``[experiments]`` extra and nothing else; a plain ``pip install`` gives the
core.  In both, every command either works or stops with one line naming the ``pip install`` to run, and a
method whose peer package is missing (the Interaction ProMP of ``[bench]``) is skipped with a note.

Builds a venv and installs from PyPI (several minutes; marked ``slow``, and run in CI like every test).  The
same behaviour is tested in this process, with the modules hidden, by ``tests/cli/test_cli_usability.py``.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _run(cmd, cwd, timeout=1800):
    env = dict(os.environ, INTERPRIM_JIT="0", MPLBACKEND="Agg")
    env.pop("PYTHONPATH", None)
    return subprocess.run([str(c) for c in cmd], cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)


def _ok(r):
    assert r.returncode == 0, f"exit {r.returncode}\n{r.stdout[-3000:]}\n{r.stderr[-3000:]}"
    assert "Traceback" not in r.stderr, r.stderr[-3000:]
    return r


def _one_line(r, *needles):
    assert r.returncode == 1, f"exit {r.returncode}\n{r.stdout[-2000:]}\n{r.stderr[-2000:]}"
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and "Traceback" not in r.stderr, r.stderr[-3000:]
    for n in needles:
        assert n in lines[0], (n, lines[0])


@pytest.mark.slow
def test_readme_commands_with_the_extras_the_readme_names(tmp_path):
    venv = tmp_path / "venv"
    _ok(_run([sys.executable, "-m", "venv", venv], tmp_path))
    py, cli = venv / "bin" / "python", venv / "bin" / "interprim"
    pip = [py, "-m", "pip", "install", "--quiet", "--disable-pip-version-check"]

    # the core: what a robot needs; the rest says which extra to install
    _ok(_run([*pip, ROOT], tmp_path))
    _one_line(_run([cli, "demo", "--quick", "--out", "d"], tmp_path), "interprim demo: error:", "matplotlib",
              "pip install 'interprim[experiments]'")
    _one_line(_run([cli, "serve", "--demo"], tmp_path), "interprim serve: error:", "pip install 'interprim[serve]'")
    _one_line(_run([cli, "evaluate", "--data", "synthetic", "--quick"], tmp_path), "interprim evaluate: error:",
              "pip install 'interprim[experiments]'")

    # what scripts/demo.sh installs
    _ok(_run([*pip, f"{ROOT}[experiments]"], tmp_path))
    r = _ok(_run([cli, "demo", "--quick", "--no-gif", "--quiet", "--out", "d"], tmp_path))
    assert (tmp_path / "d" / "fig7_mse.png").is_file() and "wrote" in r.stdout
    r = _ok(_run([cli, "evaluate", "--data", "synthetic", "--quick", "--methods", "ip-position,iprompt,nn,prior",
                  "--n-basis", "8", "--no-recognition", "--out", "ev"], tmp_path))
    assert "note: skipping iprompt: it needs movement_primitives, gmr (pip install 'interprim[bench]')" in r.stderr
    assert "| synthetic | ip-position |" in r.stdout and "iprompt" not in r.stdout
    _ok(_run([py, "-m", "interprim.experiments.quickstart"], tmp_path))


@pytest.mark.slow
def test_readme_simulated_high_five_numbers_are_those_of_the_demo(tmp_path):
    """The README's table, Fig. 6/8 sentences and animation caption: what a full ``interprim demo`` computes
    (``python scripts/doc_outputs.py --readme-demo interprim-demo/results.json`` checks a run of your own)."""
    import json

    from interprim.cli import main

    sys.path.insert(0, str(ROOT / "scripts"))
    from doc_outputs import check_readme_demo, readme_demo_numbers

    assert main(["demo", "--out", str(tmp_path), "--quiet"]) == 0
    results = json.loads((tmp_path / "results.json").read_text())
    assert len(readme_demo_numbers(results)) == 13
    problems = check_readme_demo((ROOT / "README.md").read_text(), results)
    assert not problems, "\n".join(problems)

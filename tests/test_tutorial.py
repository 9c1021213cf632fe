"""docs/tutorial.md runs: every ```bash and ```python block, in order, in one fresh working directory.

Blocks run as a reader would run them: bash blocks with ``bash -e`` (``python`` and ``interprim`` from this
environment, ``examples/`` linked into the folder), python blocks each as its own script.  A comment line
right before a block changes that:

* ``<!-- tutorial: skip REASON -->`` - not run (REASON is required and shown in the test's output);
* ``<!-- tutorial: fails -->`` - must exit with a non-zero status and a one-line error, no traceback;
* ``<!-- tutorial: background -->`` - started in the background (a server); it must print a line before the
  next block runs, and is stopped with SIGINT (Ctrl-C) after the last block, exiting with status 130 (128 + SIGINT).

The tutorial's server port 8765 is replaced by a free port, so that the test does not depend on it being free.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import socket

import pytest

ROOT = Path(__file__).resolve().parents[1]
TUTORIAL = ROOT / "docs" / "tutorial.md"
FENCE = re.compile(r"(?:<!-- tutorial: (?P<mark>\w+)(?P<why>[^>]*)-->\s*\n)?```(?P<lang>\w*)\n(?P<body>.*?)\n```",
                   re.S)


def blocks(text: str):
    """``(line, lang, mark, reason, body)`` of every fenced block."""
    out = []
    for m in FENCE.finditer(text):
        line = text.count("\n", 0, m.start("lang")) + 1
        out.append((line, m["lang"], m["mark"], (m["why"] or "").strip(), m["body"]))
    return out


def test_markers_are_known_and_skips_explained():
    for line, lang, mark, why, _ in blocks(TUTORIAL.read_text()):
        assert mark in (None, "skip", "fails", "background"), f"line {line}: unknown marker {mark!r}"
        if mark == "skip":
            assert why, f"line {line}: a skipped block needs a reason"
        if mark:
            assert lang in ("bash", "python"), f"line {line}: marker on a ```{lang} block"


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.slow  # runs every block of the tutorial in subprocesses
def test_every_block_runs(tmp_path, capsys):
    port = str(_free_port())
    work = tmp_path / "work"
    work.mkdir()
    (work / "examples").symlink_to(ROOT / "examples")
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    bindir = str(Path(sys.executable).parent)
    env = dict(os.environ, MPLBACKEND="Agg", TMPDIR=str(tmp), PYTHONUNBUFFERED="1",
               PATH=bindir + os.pathsep + os.environ.get("PATH", ""))
    background, ran, skipped = [], 0, []
    try:
        for i, (line, lang, mark, why, body) in enumerate(blocks(TUTORIAL.read_text())):
            if lang not in ("bash", "python"):
                continue
            if mark == "skip":
                skipped.append(f"line {line}: {why}")
                continue
            body = body.replace("8765", port)
            if lang == "python":
                script = tmp_path / f"block_{i:02d}.py"
                script.write_text(body + "\n")
                cmd = [sys.executable, str(script)]
            else:
                cmd = ["bash", "-e", "-c", body]
            if mark == "background":
                proc = subprocess.Popen(cmd, cwd=work, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                        text=True, start_new_session=True)
                first = proc.stdout.readline()  # waits for the server's address line (state, not a sleep)
                assert first.strip(), f"line {line}: background block printed nothing: {proc.stderr.read()}"
                background.append((line, proc))
                ran += 1
                continue
            r = subprocess.run(cmd, cwd=work, env=env, capture_output=True, text=True, timeout=900)
            ran += 1
            where = f"docs/tutorial.md line {line} ({lang})\nstdout:\n{r.stdout}\nstderr:\n{r.stderr}"
            if mark == "fails":
                assert r.returncode != 0, f"expected a failure: {where}"
                assert "Traceback" not in r.stderr and "error:" in r.stderr, where
            else:
                assert r.returncode == 0, where
                assert "Traceback" not in r.stderr, where
    finally:
        for line, proc in background:
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGINT)  # bash and the server it started: what Ctrl-C does
            try:
                out, err = proc.communicate(timeout=60)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                out, err = proc.communicate()
                pytest.fail(f"line {line}: background block did not stop on SIGINT")
            assert proc.returncode == 130, f"line {line}: background block exited {proc.returncode}: {err}"  # 128 + SIGINT
            assert "Traceback" not in err, err
    assert ran >= 10
    with capsys.disabled():
        print(f"\ntutorial: {ran} blocks run; not run: {skipped}")

"""docs/tutorial.md runs: every ```bash and ```python block, in order, in one fresh working directory.

Blocks run as a reader would run them: bash blocks with ``bash -e`` (``python`` and ``interprim`` from this
environment, ``examples/`` linked into the folder), python blocks each as its own script.  A comment line
right before a block changes that:

* ``<!-- tutorial: skip REASON -->`` - not run (REASON is required and shown in the test's output);
* ``<!-- tutorial: fails -->`` - must exit with a non-zero status and a one-line error, no traceback;
* ``<!-- tutorial: background -->`` - started in the background (a server); it must print a line before the
  next block runs, and is stopped with SIGINT (Ctrl-C) after the last block, exiting with status 130 (128 + SIGINT).

A ```text block right after a block shows its output: it must be what the block prints (numbers within rounding,
timings excepted; ``scripts/doc_outputs.py``, which also rewrites them with ``--update``).

The tutorial's server port 8765 is replaced by a free port, so that the test does not depend on it being free.
"""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "scripts"))
from doc_outputs import TUTORIAL, Runner, blocks, compare, printed, shown_output  # noqa: E402


def test_markers_are_known_and_skips_explained():
    for b in blocks(TUTORIAL.read_text()):
        assert b.mark in (None, "skip", "fails", "background"), f"line {b.line}: unknown marker {b.mark!r}"
        if b.mark == "skip":
            assert b.why, f"line {b.line}: a skipped block needs a reason"
        if b.mark:
            assert b.lang in ("bash", "python"), f"line {b.line}: marker on a ```{b.lang} block"


def test_every_fence_opens_or_closes_a_block_found():
    """A fence the parser misreads (one indented inside a list item, once) pairs the wrong fences from there on, and
    the blocks after it were neither run nor compared: every fence line belongs to exactly one block found."""
    text = TUTORIAL.read_text()
    fences = [n for n, ln in enumerate(text.splitlines(), 1) if ln.lstrip().startswith("```")]
    bl = blocks(text)
    assert len(fences) == 2 * len(bl)
    assert [b.line for b in bl] == fences[::2]
    indented = "1. a list item:\n\n   ```text\n   shown\n   ```\n\n```bash\necho hi\n```\n"
    assert [(b.lang, b.body) for b in blocks(indented)] == [("text", "   shown"), ("bash", "echo hi")]


def test_compare_catches_drift_and_ignores_timings():
    assert compare("held-out error 0.0598 (prior 0.1284)", "held-out error 0.0598 (prior 0.1285)") == []
    assert compare("held-out error 0.0598", "held-out error 0.0889")  # the drift of issue 21
    assert compare("0,0.0,0.1194", "0,0.0,0.1183")
    assert compare("fitted 20 demonstrations", "fitted 20 demonstration")  # the text, too
    assert compare("a\nb", "a")  # and the number of lines
    assert compare("latency median 0.39 ms, p99 5.22 ms; fit in 4.5 s; error 0.123 rad",
                   "latency median 0.52 ms, p99 9.10 ms; fit in 8.1 s; error 0.123 rad") == []
    assert compare("simulated 1.91 s in 0.3 s", "simulated 1.95 s in 0.9 s")  # a duration is not a timing


@pytest.mark.slow  # runs every block of the tutorial in subprocesses
def test_every_block_runs_and_prints_what_the_guide_shows(tmp_path, capsys):
    text = TUTORIAL.read_text()
    bl = blocks(text)
    ran, skipped, drift = 0, [], []
    with Runner(tmp_path) as runner:
        for i, b in enumerate(bl):
            if b.lang not in ("bash", "python"):
                continue
            if b.mark == "skip":
                skipped.append(f"line {b.line}: {b.why}")
                continue
            r = runner.run(b)
            ran += 1
            if b.mark == "background":
                assert r.strip(), f"line {b.line}: background block printed nothing"
                continue
            where = f"docs/tutorial.md line {b.line} ({b.lang})\nstdout:\n{r.stdout}\nstderr:\n{r.stderr}"
            if b.mark == "fails":
                assert r.returncode != 0, f"expected a failure: {where}"
                assert "Traceback" not in r.stderr and "error:" in r.stderr, where
            else:
                assert r.returncode == 0, where
                assert "Traceback" not in r.stderr, where
            out = shown_output(text, bl, i)
            if out is not None:
                problems = compare(out.body, printed(b, r))
                if problems:
                    drift.append(f"docs/tutorial.md line {out.line}:\n" + "\n".join(problems))
    for line, code, err in runner.stopped:
        assert code == 130, f"line {line}: background block exited {code}: {err}"  # 128 + SIGINT
        assert "Traceback" not in err, err
    assert ran >= 10
    assert not drift, ("the outputs shown drifted from what the code prints; regenerate them with "
                       "'python scripts/doc_outputs.py --update' and review the diff:\n" + "\n".join(drift))
    with capsys.disabled():
        print(f"\ntutorial: {ran} blocks run; not run: {skipped}")

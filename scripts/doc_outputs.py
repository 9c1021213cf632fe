"""Run the code blocks of a Markdown guide (docs/tutorial.md) and check or rewrite the outputs it shows.

A ```text block right after a ```bash or ```python block (nothing but blank lines between them) is that block's
output as printed: standard output, or standard error for a block marked ``<!-- tutorial: fails -->``.

    python scripts/doc_outputs.py             # run every block, report the outputs that drifted (exit 1 if any)
    python scripts/doc_outputs.py --update    # the same, and write the printed outputs into the guide
                                              # (timings keep the values shown: a quiet machine's)
    python scripts/doc_outputs.py --readme-demo interprim-demo/results.json
                                              # the README's simulated high-five numbers against a full demo run

``tests/test_tutorial.py`` runs the blocks with :class:`Runner` and checks every shown output with
:func:`compare`: the text must match with the numbers taken out, and every number must equal the printed one
within one unit of its last shown digit or 0.1 % (rounding on another machine), except timings (``12.3 ms``,
``in 4.5 s``), which depend on the machine.  So the guide cannot drift from what the code prints.

Markers (an HTML comment on the line before a block): ``<!-- tutorial: skip REASON -->`` (not run),
``<!-- tutorial: fails -->`` (must exit non-zero with a one-line error), ``<!-- tutorial: background -->``
(a server: started in the background, stopped with SIGINT after the last block).
"""

from __future__ import annotations

import os
import re
import signal
import socket
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TUTORIAL = ROOT / "docs" / "tutorial.md"
#: a fenced block; its fences may be indented (up to 3 spaces, as Markdown allows inside a list item)
FENCE = re.compile(r"(?:<!-- tutorial: (?P<mark>\w+)(?P<why>[^>]*)-->\s*\n)?```(?P<lang>\w*)\n(?P<body>.*?)"
                   r"\n[ ]{0,3}```", re.S)
NUMBER = re.compile(r"(?<![\w.])-?\d+(?:\.\d+)?(?:e[-+]?\d+)?")
TIMING = re.compile(r"(?<![\w.])-?\d+(?:\.\d+)?(?= ?ms\b)|(?<=\bin )\d+(?:\.\d+)?(?= s\b)")


@dataclass
class Block:
    line: int
    lang: str
    mark: str | None
    why: str
    body: str
    body_span: tuple  # (start, end) of the body in the file's text
    end: int  # end of the closing fence


def blocks(text: str) -> list:
    """Every fenced block of ``text``, in order."""
    out = []
    for m in FENCE.finditer(text):
        line = text.count("\n", 0, m.start("lang")) + 1
        out.append(Block(line, m["lang"], m["mark"], (m["why"] or "").strip(), m["body"], m.span("body"), m.end()))
    return out


def shown_output(text: str, bl: list, i: int):
    """The ```text block that shows block ``i``'s output (the next block, only blank lines between), or None."""
    if i + 1 < len(bl) and bl[i + 1].lang == "text" and bl[i + 1].mark is None:
        between = text[bl[i].end:text.rfind("```", 0, bl[i + 1].body_span[0])]
        if not between.strip():
            return bl[i + 1]
    return None


def _numbers(s: str):
    timings = {m.start() for m in TIMING.finditer(s)}
    nums = [(m.start(), m.group()) for m in NUMBER.finditer(s)]
    skeleton = NUMBER.sub("#", s)
    return skeleton, [(v, start in timings) for start, v in nums]


def _close(shown: str, printed: str) -> bool:
    a, b = float(shown), float(printed)
    digits = len(shown.split("e")[0].partition(".")[2])
    unit = 10.0 ** -digits * (10.0 ** int(shown.split("e")[1]) if "e" in shown else 1.0)
    return abs(a - b) <= max(1.0001 * unit, 1e-3 * abs(a))


def compare(shown: str, printed: str) -> list:
    """What differs between an output shown in the guide and the one printed (empty: they agree).

    Lines are compared with the numbers taken out (trailing spaces ignored), then each number within one unit
    of its last shown digit or 0.1 %; timings are not compared.
    """
    a = [ln.rstrip() for ln in shown.strip("\n").splitlines()]
    b = [ln.rstrip() for ln in printed.strip("\n").splitlines()]
    if len(a) != len(b):
        return [f"{len(a)} lines shown, {len(b)} printed:\n  shown:   {a}\n  printed: {b}"]
    problems = []
    for k, (x, y) in enumerate(zip(a, b), 1):
        sx, nx = _numbers(x)
        sy, ny = _numbers(y)
        if sx != sy or len(nx) != len(ny):
            problems.append(f"line {k}: text differs\n  shown:   {x}\n  printed: {y}")
            continue
        bad = [f"{u} shown, {v} printed" for (u, timing), (v, _) in zip(nx, ny) if not timing and not _close(u, v)]
        if bad:
            problems.append(f"line {k}: {'; '.join(bad)}\n  shown:   {x}\n  printed: {y}")
    return problems


def merged(shown: str, printed: str) -> str:
    """``printed``, with the timings of ``shown`` kept on lines that otherwise have the same text: a guide shows
    the timings of a quiet machine, not those of the run that regenerated it."""
    a, b = shown.strip("\n").splitlines(), printed.rstrip("\n").splitlines()
    if len(a) != len(b):
        return "\n".join(b)
    out = []
    for x, y in zip(a, b):
        sx, nx = _numbers(x)
        sy, ny = _numbers(y)
        if sx != sy or len(nx) != len(ny) or not any(t for _, t in nx):
            out.append(y)
            continue
        vals = iter([u if t else v for (u, t), (v, _) in zip(nx, ny)])
        out.append(NUMBER.sub(lambda m: next(vals), y))
    return "\n".join(out)


# ----------------------------------------------------------------------------- README: the demo's numbers
#: README table rows of the simulated high five -> (agent, method) in ``results.json``'s ``fig7``
README_MSE_ROWS = {
    "robot, IP as in the paper": ("controlled", "ip"),
    "robot, IP library defaults": ("controlled", "ip_default"),
    "robot, IP paper + likelihood phase": ("controlled", "ip_likelihood"),
    "robot, prior mean": ("controlled", "prior"),
    "robot, nearest neighbour (DTW)": ("controlled", "nn"),
    "human (completion), IP as in the paper": ("observed", "ip"),
    "human (completion), IP library defaults": ("observed", "ip_default"),
}


def readme_demo_numbers(results: dict) -> list:
    """``(template, values)`` of the README's simulated high-five numbers, from ``interprim demo``'s
    ``results.json`` (full run: 100 training and 30 test interactions).  ``{}`` in a template is a number."""
    pc = list(results["percents"])
    cols = [pc.index(p) for p in (20, 40, 60, 80, 100)]
    out = []
    for label, (agent, m) in README_MSE_ROWS.items():
        mean = results["fig7"][agent][m]["mean"]
        out.append((f"| {label} " + r"[^|]*" + "| {} | {} | {} | {} | {} |", [f"{mean[j]:.4f}" for j in cols]))
    d8 = results["fig8"]["mean_distance_m"]
    out.append(("mean distance to the true one: library defaults {} cm, paper + likelihood phase {} cm, the paper's "
                "IP {} cm, prior mean {} cm, nearest neighbour {} cm",
                [f"{100 * d8[m]:.1f}" for m in ("ip_default", "ip_likelihood", "ip", "prior", "nn")]))
    s6 = results["fig6"]["goal_spread_m_mean_over_test"]
    out.append(("Spread of the posterior samples' goal (Fig. 6): {} cm at 40 %, {} cm at 60 %",
                [f"{100 * s6[0]:.1f}", f"{100 * s6[1]:.1f}"]))
    a = results["animation"]
    de, pa = a["default"], a["paper"]
    out.append(("the library's defaults estimate phase {} and end with the robot's hand {} cm from the high-five "
                "point; the paper's IP estimates phase {} and misses by {} cm",
                [f"{de['phase']:.2f}", f"{100 * de['distance_m']:.1f}", f"{pa['phase']:.2f}",
                 f"{100 * pa['distance_m']:.1f}"]))
    out.append(("passes through that posture at {} % of its way", [f"{100 * pa['phase']:.0f}"]))
    out.append(("conditioned at the true phase, the same model misses by {} cm",
                [f"{100 * pa['distance_at_true_phase_m']:.1f}"]))
    g = results["goal_distance_m"]
    j = pc.index(100)
    out.append(("with 100 % seen: {} cm (defaults) and {} cm (paper), medians {} and {} cm",
                [f"{100 * g['ip_default']['mean'][j]:.1f}", f"{100 * g['ip']['mean'][j]:.1f}",
                 f"{100 * g['ip_default']['median'][j]:.1f}", f"{100 * g['ip']['median'][j]:.1f}"]))
    return out


def check_readme_demo(readme: str, results: dict) -> list:
    """The README's simulated high-five numbers that differ from ``results`` (empty: none)."""
    text = " ".join(readme.replace("**", "").split())
    problems = []
    for template, values in readme_demo_numbers(results):
        parts = [re.escape(re.sub(r"\s+", " ", p)).replace(re.escape("[^|]*"), "[^|]*") for p in template.split("{}")]
        m = re.search(r"(-?\d+(?:\.\d+)?)".join(parts), text)
        if m is None:
            problems.append(f"not found in the README: {template.format(*values)}")
            continue
        bad = [f"{u} shown, {v} computed" for u, v in zip(m.groups(), values) if not _close(u, v)]
        if bad:
            problems.append(f"{'; '.join(bad)}: {m.group(0)}")
    return problems


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Runner:
    """Runs blocks as a reader would, in one working directory: bash blocks with ``bash -e``, python blocks each
    as its own script; ``examples/`` is linked into the directory and the server port 8765 is replaced by a free
    one.  A context manager: background blocks are stopped (SIGINT, what Ctrl-C sends) on exit, and their
    ``(line, returncode, stderr)`` are in ``stopped``."""

    def __init__(self, tmp: Path, python: str = sys.executable):
        self.tmp = Path(tmp)
        self.work = self.tmp / "work"
        self.work.mkdir(parents=True, exist_ok=True)
        if not (self.work / "examples").exists():
            (self.work / "examples").symlink_to(ROOT / "examples")
        (self.tmp / "tmp").mkdir(exist_ok=True)
        self.python = python
        self.port = str(free_port())
        bindir = str(Path(python).parent)
        self.env = dict(os.environ, MPLBACKEND="Agg", TMPDIR=str(self.tmp / "tmp"), PYTHONUNBUFFERED="1",
                        PATH=bindir + os.pathsep + os.environ.get("PATH", ""))
        self.background, self.stopped, self.count = [], [], 0

    def __enter__(self):
        return self

    def run(self, block: Block, timeout: float = 900):
        """Run one block: a ``CompletedProcess``, or for a background block the first line it printed."""
        body = block.body.replace("8765", self.port)
        self.count += 1
        if block.lang == "python":
            script = self.tmp / f"block_{self.count:02d}.py"
            script.write_text(body + "\n")
            cmd = [self.python, str(script)]
        else:
            cmd = ["bash", "-e", "-c", body]
        if block.mark == "background":
            proc = subprocess.Popen(cmd, cwd=self.work, env=self.env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                    text=True, start_new_session=True)
            self.background.append((block.line, proc))
            return proc.stdout.readline()  # waits for the server's address line (state, not a sleep)
        return subprocess.run(cmd, cwd=self.work, env=self.env, capture_output=True, text=True, timeout=timeout)

    def __exit__(self, *exc):
        for line, proc in self.background:
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGINT)  # bash and the server it started: what Ctrl-C does
            try:
                _, err = proc.communicate(timeout=60)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                _, err = proc.communicate()
                err = "did not stop on SIGINT\n" + err
            self.stopped.append((line, proc.returncode, err))
        return False


def printed(block: Block, result) -> str:
    """The output a ```text block shows for ``block``: stderr of a failing block, stdout otherwise."""
    return result.stderr if block.mark == "fails" else result.stdout


def main(argv=None) -> int:
    import argparse
    import tempfile

    ap = argparse.ArgumentParser(description="Check (or --update) the outputs shown in a Markdown guide.")
    ap.add_argument("guide", nargs="?", default=str(TUTORIAL))
    ap.add_argument("--update", action="store_true", help="write the printed outputs into the guide")
    ap.add_argument("--readme-demo", metavar="RESULTS_JSON",
                    help="instead: check the README's simulated high-five numbers against the results.json of a "
                         "full 'interprim demo' run")
    args = ap.parse_args(argv)
    if args.readme_demo:
        import json

        problems = check_readme_demo((ROOT / "README.md").read_text(), json.loads(Path(args.readme_demo).read_text()))
        print("\n".join(problems) or "the README's simulated high-five numbers are those of the run", file=sys.stderr)
        return 1 if problems else 0
    path = Path(args.guide)
    text = path.read_text()
    bl = blocks(text)
    edits, drift = [], 0
    with tempfile.TemporaryDirectory() as tmp, Runner(Path(tmp)) as runner:
        for i, b in enumerate(bl):
            if b.lang not in ("bash", "python") or b.mark == "skip":
                continue
            print(f"{path.name} line {b.line} ({b.lang}) ...", file=sys.stderr, flush=True)
            r = runner.run(b)
            if b.mark == "background":
                continue
            ok = (r.returncode != 0) if b.mark == "fails" else (r.returncode == 0)
            if not ok:
                print(f"line {b.line}: exit status {r.returncode}\n{r.stdout}\n{r.stderr}", file=sys.stderr)
                return 2
            out = shown_output(text, bl, i)
            if out is None:
                continue
            problems = compare(out.body, printed(b, r))
            if problems:
                drift += 1
                print(f"line {out.line}: the output shown drifted:\n" + "\n".join(problems), file=sys.stderr)
            edits.append((out.body_span, merged(out.body, printed(b, r))))
    if args.update:
        for (start, end), new in sorted(edits, reverse=True):
            text = text[:start] + new + text[end:]
        path.write_text(text)
        print(f"wrote the printed outputs of {len(edits)} blocks into {path}", file=sys.stderr)
        return 0
    return 1 if drift else 0


if __name__ == "__main__":
    sys.exit(main())

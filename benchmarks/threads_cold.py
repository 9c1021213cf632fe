"""Benchmark rows of the BLAS thread pools under load and of the first run after an install, run by
:mod:`benchmarks.run` (the helpers are passed in to keep one timing code).

* **Threads**: every public numeric call runs with one BLAS thread (:mod:`interprim.core.blas`), so a caller that
  leaves BLAS at its default (one thread per core) and one that limits it to one thread must see the same
  times, also while other work runs.  Two busy-loop processes (one per core of the reference machine, each
  ending by itself after at most ``BUSY_SECONDS``, and stopped when the rows are done) run during these rows.
* **First run**: ``import interprim`` + ``fit`` (12 demonstrations) + ``predict`` + 60 streamed frames in a
  fresh process, with an empty numba cache (``NUMBA_CACHE_DIR`` a new temporary directory: a fresh install)
  and then with the cache that run left; also with ``INTERPRIM_JIT=1`` (waits for the compiler: the
  behaviour before the background compilation).  The outputs of the cold and warm runs are compared.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

BUSY_SECONDS = 240
BUSY_CODE = "import time, sys\nt = time.time() + float(sys.argv[1])\nwhile time.time() < t:\n    pass\n"


def _busy(n):
    return [subprocess.Popen([sys.executable, "-c", BUSY_CODE, str(BUSY_SECONDS)]) for _ in range(n)]


def bench_threads(quick, fitted_model, make_demos, row, rel):
    """Default BLAS threads vs one thread (the caller's threadpool_limits(1)) for the public calls, under load."""
    from threadpoolctl import threadpool_limits

    import interprim as ip

    print("BLAS threads: default vs one, with 2 busy-loop processes running")
    model, test = fitted_model(Do=9, Dc=9, n_basis=25, S=30, T=500)
    demos = make_demos(12, 9, 9, 200, seed=3)
    partial = test[:250, :9]
    default = os.cpu_count() or 2
    n_rep = 5 if quick else 15

    def stream_step():
        st = model.stream()
        out = []
        for f in test[:60, :9]:
            t0 = time.perf_counter()
            st.update(f).response(100)
            out.append(time.perf_counter() - t0)
        return np.array(out[10:])

    ops = {
        "predict (250 frames)": lambda: model.predict(partial),
        "std(50) (covariance included)": lambda: model.predict(partial).std(50),
        "samples(20, 50) (covariance included)": lambda: model.predict(partial).samples(20, 50, random_state=0),
        "fit (12 demos x 200 frames, defaults)": lambda: ip.InteractionPrimitive(observed_dofs=list(range(9)),
                                                                                 n_basis=25).fit(demos, dt=0.01),
    }
    procs = _busy(2)
    try:
        time.sleep(0.5)
        for name, fn in ops.items():
            res = {"default": [], "one": []}
            outs = {}
            n = (1 if quick else 3) if name.startswith("fit") else n_rep
            for _ in range(n):  # interleaved: a drift of the load hits both settings alike
                for key, lim in (("default", default), ("one", 1)):
                    with threadpool_limits(lim, user_api="blas"):
                        t0 = time.perf_counter()
                        o = fn()
                        res[key].append(time.perf_counter() - t0)
                    if key not in outs:
                        outs[key] = o if isinstance(o, np.ndarray) else (
                            o.prior_.mean if hasattr(o, "prior_") else o.std(50))
            err = rel(outs["default"], outs["one"])
            _row(row, name, res, err)
        # the same std(50) with the library's limiter switched off: what the caller's BLAS setting did before
        from interprim.core import blas as _blas

        saved = _blas._controllers
        _blas._controllers = lambda: []
        try:
            res, outs = {"default": [], "one": []}, {}
            for _ in range(n_rep):
                for key, lim in (("default", default), ("one", 1)):
                    with threadpool_limits(lim, user_api="blas"):
                        p = model.predict(partial)
                        t0 = time.perf_counter()
                        outs[key] = p.std(50)
                        res[key].append(time.perf_counter() - t0)
        finally:
            _blas._controllers = saved
        _row(row, "std(50), library limiter switched off (before)", res, rel(outs["default"], outs["one"]),
             note="the behaviour before; not a target")
        res = {"default": [], "one": []}
        for _ in range(2 if quick else 5):
            for key, lim in (("default", default), ("one", 1)):
                with threadpool_limits(lim, user_api="blas"):
                    res[key].append(stream_step())
        res = {k: np.concatenate(v) for k, v in res.items()}
        _row(row, "streamed step (update + response(100))", res, 0.0, per_call=True)
    finally:
        for p in procs:
            p.kill()
            p.wait()


def _row(row, name, res, err, per_call=False, note=None):
    d, o = np.asarray(res["default"]), np.asarray(res["one"])
    ratio = max(np.median(d), np.median(o)) / min(np.median(d), np.median(o))
    r = row(f"BLAS threads under load: {name}", "9+9 DoF, 25 basis; 2 busy-loop processes", d,
        "same call inside threadpool_limits(1)", o,
        f"{'yes' if err <= 1e-10 else 'NO'} ({err:.1e})",
        note=f"ours = BLAS left at its default ({os.cpu_count()} threads); {ratio:.2f}x apart "
             + (f"({note})" if note else "(target <= 1.5x)") + ("; per frame, frames 10-59" if per_call else ""))
    r["section"] = "threads"


FIRST_RUN = r"""
import json, sys, time
t0 = time.perf_counter()
sys.path.insert(0, sys.argv[1])
import numpy as np
import interprim as ip
from interprim.synthetic import two_agent_demos
demos = two_agent_demos(12, seed=0)
m = ip.InteractionPrimitive(observed_dofs=[0, 1]).fit(demos, dt=0.01)
test = two_agent_demos(1, seed=7)[0]
p = m.predict(test[:100, :2])
tr, sd = p.trajectory(50), p.std(50)
s = m.stream()
for f in test[:60, :2]:
    q = s.update(f)
t_, r = q.response(50)
wall = time.perf_counter() - t0
cpu = time.process_time()
from interprim.core._compiled import loader
compiled = bool(loader._READY)
print(json.dumps({"wall": wall, "cpu": cpu, "compiled": compiled, "out": [tr.tolist(), sd.tolist(), r.tolist(),
                  [p.phase, q.phase]]}), flush=True)
loader.warmup()  # after the timing: wait for a background compilation to finish (the next run is warm)
"""


def bench_first_run(quick, tmp, row, rel, root):
    """import + fit (12 demos) + predict + 60 streamed frames in a fresh process: empty numba cache vs warm."""
    print("first run after an install (empty numba cache) vs warm")
    src = str(root / "src")

    def run(cache, jit=None):
        env = dict(os.environ, NUMBA_CACHE_DIR=cache)
        env.pop("INTERPRIM_JIT", None)
        if jit is not None:
            env["INTERPRIM_JIT"] = jit
        t0 = time.perf_counter()
        res = subprocess.run([sys.executable, "-c", FIRST_RUN, src], env=env, check=True, capture_output=True,
                             text=True, cwd=str(root))
        d = json.loads(res.stdout.strip().splitlines()[-1])
        d["process"] = time.perf_counter() - t0
        return d

    n_cold = 2 if quick else 3
    cold, warm = [], []
    for _ in range(n_cold):
        cache = tempfile.mkdtemp(dir=tmp)
        cold.append(run(cache))
        warm += [run(cache) for _ in range(2)]
    strict = [run(tempfile.mkdtemp(dir=tmp), jit="1") for _ in range(1 if quick else 2)]
    ref = warm[0]["out"]
    err = max(rel(np.asarray(c["out"][i], float), np.asarray(ref[i], float)) for c in cold for i in range(4))
    err_w = max(rel(np.asarray(w["out"][i], float), np.asarray(ref[i], float)) for w in warm for i in range(4))
    w_med = float(np.median([w["wall"] for w in warm]))
    c_med = float(np.median([c["wall"] for c in cold]))
    size = "import + fit 12 demos + predict + 60 frames"
    r1 = row("first run: empty numba cache (fresh install)", size, np.array([c["wall"] for c in cold]),
        "warm cache", np.array([w["wall"] for w in warm]), f"{'yes' if err <= 1e-6 else 'NO'} ({err:.1e})",
        note=f"{c_med / w_med:.1f}x the warm run (target <= 4x); numpy while a background process compiles; "
             f"agree = cold vs warm outputs (trajectory, std, response, phases; tolerance 1e-6), warm runs "
             f"among themselves {err_w:.1e}")
    r2 = row("first run: empty cache, INTERPRIM_JIT=1 (waits for the compiler; before)", size,
        np.array([s["wall"] for s in strict]), "warm cache", np.array([w["wall"] for w in warm]),
        note=f"{float(np.median([s['wall'] for s in strict])) / w_med:.1f}x the warm run")
    r1["section"] = r2["section"] = "first"
    return {"cold": cold, "warm": warm, "strict": strict}


def section_md(rows, table_md, load=None):
    """The RESULTS.md section of these rows (``rows``: every row of the run; those of this module are picked)."""
    th = [r for r in rows if r.get("section") == "threads"]
    fr = [r for r in rows if r.get("section") == "first"]
    if not th and not fr:
        return []
    md = ["## BLAS threads under load, and the first run after an install", ""]
    if load is not None:
        md += [f"Load average when these rows ran: {tuple(round(x, 2) for x in load)}.", ""]
    if th:
        md += ["Each public call with BLAS left at its default (one thread per core; *ours*) and inside the "
               "caller's `threadpool_limits(1)` (*peer*), interleaved, while two busy-loop processes (one per "
               "core, started by the benchmark, each ending by itself after at most "
               f"{BUSY_SECONDS} s) compete for the CPU.  The library runs its linear algebra with one thread "
               "either way (`interprim.core.blas`), so the two must agree in time (target: within 1.5x) and in "
               "value (*agree*: largest relative difference of the outputs).", "", table_md(th, True), ""]
    if fr:
        md += ["`import interprim` + `fit` (12 demonstrations, defaults) + `predict` + 60 streamed frames in a fresh "
               "process: with an empty numba cache (`NUMBA_CACHE_DIR` a new temporary directory, as after an "
               "install), and again with the cache that run left (*peer*: warm).  With an empty cache the process "
               "computes with the numpy equivalents while a background process compiles the kernels; "
               "`INTERPRIM_JIT=1` waits for the compiler instead (the behaviour before).", "", table_md(fr, True), ""]
    return md

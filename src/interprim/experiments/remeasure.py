"""The development-set tables of docs/evaluation.md, re-measured with the honest yardsticks.

The tables written before 2026-11-26 used look-ahead prefixes of the interpolated NuiSI recordings, all
recordings (the later hold-out included) and the old ``two_agent_demos`` smoke set.  This module measures the
same tables again on the **development recordings only** (the hold-out stays untouched:
:data:`interprim.evaluation.nested.HOLDOUT`), with **causal prefixes** (every prediction sees only the raw
samples recorded by its last frame) and the synthetic **benchmark** (:func:`interprim.synthetic.benchmark_tasks`,
development seed) in place of the smoke set:

* ``realtime``: the 5-fold real-time protocol (:func:`interprim.evaluation.realtime.realtime_sweep`) on NuiSI
  (agent 1's right arm observed, agent 2's right hand predicted, 20 Hz), the synthetic benchmark and the
  simulated high five; real time 0.25 s ahead, phase, bands over the horizon, whole movement at 40/60/80 %.
* ``upperbody``: the same real-time protocol on NuiSI with agent 1's upper body observed (24 columns) and agent 2's
  right arm predicted (9 columns), the defaults and the prior mean.
* ``sweep``: the normalised-time protocol of the paper's Fig. 7 (:func:`interprim.evaluation.sweep.run_sweep`,
  NuiSI with agent 1's upper body observed) on ``--max-demos`` evenly spread held-out development recordings
  per interaction (each predicted by models fitted on the other development recordings), with recognition.

Run::

    python -m interprim.experiments.remeasure --out remeasured [--part realtime,sweep] [--max-demos 8]

Writes ``realtime.json`` / ``realtime.md`` and ``sweep.json`` / ``sweep.md`` to ``--out``.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from ..evaluation.nested import HOLDOUT, split_holdout
from ..evaluation.realtime import RealTimeConfig, default_methods, realtime_sweep, summarise_realtime

__all__ = ["realtime_tasks", "run_realtime", "realtime_tables", "run_nuisi_sweep", "main"]

NUISI_ACTIONS = ("highfive1", "handshake2", "fistbump2", "clapfist2", "rocket1", "wave1")
METHODS = ("ip", "learned", "ip-paper", "kernel", "nn", "prior")
#: (summary key, title) of the real-time tables, in the order of docs/evaluation.md.
COLUMNS = (("rt_ctrl_vs_clock", "Real time (agent 2 / the robot, next 0.25 s), RMSE ÷ the clock's"),
           ("rt_ctrl_vs_oracle", "Real time, RMSE ÷ the oracle-duration mean's"),
           ("rt_ctrl_vs_floor", "Real time, RMSE ÷ the oracle's (the best possible prediction; synthetic)"),
           ("rt_obs_vs_clock", "Real time, agent 1 (the human's own next 0.25 s), RMSE ÷ the clock's"),
           ("phase_err_vs_clock", "Phase error ÷ the clock's"),
           ("wm_ctrl_vs_prior", "Whole movement (40/60/80 %), agent 2 RMSE ÷ the prior mean's"),
           ("cov_ctrl", "Coverage of the 90 % band over the horizon, agent 2"),
           ("cov_obs", "Coverage of the 90 % band over the horizon, agent 1"),
           ("z_ctrl", "RMS error ÷ RMS predicted std over the horizon, agent 2 (1 = calibrated)"),
           ("z_obs", "RMS error ÷ RMS predicted std over the horizon, agent 1"))


def realtime_tasks(which=("nuisi", "synthetic", "highfive-sim"), data_path=None, observed="right_arm",
                   controlled="right_hand"):
    """``[(name, demos, observed_dofs, dt, point_dim, oracles or None)]``: the development recordings only.

    ``observed``, ``controlled``: NuiSI's joints (:func:`interprim.datasets.load_nuisi`)."""
    out = []
    if "nuisi" in which:
        from ..datasets import load_nuisi

        for a in NUISI_ACTIONS:
            d = load_nuisi(data_path, action=a, observed=observed, controlled=controlled, dt=0.05)
            dev = d.take(split_holdout(len(d))[0])
            out.append((a, dev, list(d.observed_dofs), float(d.dt), 3, None))
    if "synthetic" in which:
        from ..synthetic import benchmark_tasks

        for name, task in benchmark_tasks(30, seed=HOLDOUT["synthetic_dev_seed"]).items():
            out.append((f"synthetic/{name}", task.demos, task.observed_dofs, task.dt, 1, task.oracles))
    if "highfive-sim" in which:
        from ..sim import generate_highfive

        data = generate_highfive(30, seed=0, progress=False)
        out.append(("highfive-sim", list(data.demos), list(data.observed_dofs), float(data.dt), 1, None))
    return out


def run_realtime(tasks, methods=METHODS, k: int = 5, log=print) -> dict:
    """``{task: {"summary": ..., "deciles": ..., "seconds": ...}}``: the 5-fold real-time sweep of every task."""
    out: dict = {}
    for name, demos, obs, dt, point_dim, oracles in tasks:
        t0 = time.perf_counter()
        make = {m: f for m, f in default_methods(obs).items() if m in methods}
        recs = realtime_sweep(make, demos, obs, dt, RealTimeConfig(point_dim=point_dim), k=k,
                              whole_movement=(0.4, 0.6, 0.8), oracles=oracles)
        out[name] = {"summary": summarise_realtime(recs), "deciles": calibration_deciles(recs),
                     "n": len(demos), "seconds": time.perf_counter() - t0}
        s = out[name]["summary"]
        log(f"  {name} ({len(demos)} recordings): "
            + ", ".join(f"{m} {s[m].get('rt_ctrl_vs_clock', np.nan):.2f}" for m in methods if m in s)
            + f" x clock, in {out[name]['seconds']:.0f} s")
    return out


def calibration_deciles(records, edges=(0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9)) -> dict:
    """Mean RMS error ÷ RMS std over the frames of each 10 % of the movement seen, per method and agent."""
    out: dict = {}
    for r in records:
        if r.get("protocol") == "whole" or "z_ctrl" not in r:
            continue
        f = r["fraction"]
        for lo, hi in zip(edges[:-1], edges[1:]):
            if lo <= f < hi or (hi == edges[-1] and f == hi):
                for agent in ("ctrl", "obs"):
                    z = r.get(f"z_{agent}", np.nan)
                    if np.isfinite(z):
                        out.setdefault(r["method"], {}).setdefault(agent, {}).setdefault(f"{lo:.1f}", []).append(z)
    return {m: {a: {b: float(np.mean(v)) for b, v in d.items()} for a, d in ag.items()} for m, ag in out.items()}


def _geo(vals, arithmetic=False):
    ok = [v for v in vals if np.isfinite(v) and v > 0]
    if not ok:
        return float("nan")
    return float(np.mean(ok)) if arithmetic else float(np.exp(np.mean(np.log(ok))))


def realtime_tables(results, methods=METHODS) -> str:
    """Markdown: one table per metric (methods x tasks, NuiSI geometric mean), then the per-decile calibration."""
    names = list(results)
    nuisi = [n for n in names if n in NUISI_ACTIONS]
    lines = []
    for key, title in COLUMNS:
        rows = []
        for m in (*methods, "clock", "oracle-duration", "oracle"):
            vals = [results[n]["summary"].get(m, {}).get(key, np.nan) for n in names]
            if not np.any(np.isfinite(vals)):
                continue
            agg = _geo([results[n]["summary"].get(m, {}).get(key, np.nan) for n in nuisi],
                       arithmetic=key.startswith(("cov", "z_")))
            cells = ["—" if not np.isfinite(v) else f"{v:.2f}" for v in vals]
            rows.append(f"| {m} | " + " | ".join(cells) + f" | {'—' if not np.isfinite(agg) else f'{agg:.2f}'} |")
        if rows:
            lines += [f"**{title}**", "", "| method | " + " | ".join(names) + " | NuiSI mean |",
                      "|---" * (len(names) + 2) + "|", *rows, ""]
    lines += ["**RMS error ÷ RMS std per 10 % of the movement seen, the library's defaults (`ip`)**", "",
              "| data | agent | 20-30 % | 30-40 % | 40-50 % | 50-60 % | 60-70 % | 70-80 % | 80-90 % |",
              "|---|---|---|---|---|---|---|---|---|"]
    for n in names:
        d = results[n]["deciles"].get("ip", {})
        for agent, label in (("obs", "human"), ("ctrl", "robot")):
            row = d.get(agent, {})
            lines.append(f"| {n} | {label} | " + " | ".join(
                f"{row[b]:.2f}" if b in row else "—" for b in ("0.2", "0.3", "0.4", "0.5", "0.6", "0.7", "0.8"))
                + " |")
    return "\n".join(lines)


def run_nuisi_sweep(max_demos: int = 8, n_jobs: int = 1, data_path=None) -> dict:
    """The normalised-time sweep on NuiSI's development recordings: ``{"results", "summary", "markdown"}``."""
    from ..evaluation import EvalConfig, recognition_table, run_sweep, summarise
    from ..evaluation.sweep import markdown_tables

    cfg = EvalConfig(data_path=data_path, development_only=True, fractions=(0.1, 0.2, 0.4, 0.6, 0.8, 1.0))
    res = run_sweep(("nuisi",), cfg=cfg, n_jobs=n_jobs, recognition=True, max_demos=max_demos, progress=False)
    summary = summarise(res)
    parts = []
    for metric in ("rmse_ctrl", "rmse_obs", "contact_err", "final_err", "coverage", "phase_err"):
        fr = (0.2, 0.4, 0.6, 0.8) if metric == "phase_err" else (0.4, 0.6, 0.8)
        parts += [markdown_tables(summary, fractions=fr, metric=metric), ""]
    parts += ["**Recognition accuracy among the six interactions**", "", recognition_table(summary), ""]
    return {"results": res, "summary": summary, "markdown": "\n".join(parts)}


def main(argv=None) -> int:
    """The command line of this module (see the module docstring); returns the exit status."""
    ap = argparse.ArgumentParser(prog="python -m interprim.experiments.remeasure", description=__doc__.split("\n")[0])
    ap.add_argument("--out", default="remeasured", help="output folder (outside the repository)")
    ap.add_argument("--part", default="realtime,sweep", help="comma-separated: realtime, sweep, upperbody (agent 1's "
                    "upper body observed, agent 2's right arm predicted)")
    ap.add_argument("--tasks", default="nuisi,synthetic,highfive-sim", help="real-time part: which data")
    ap.add_argument("--max-demos", type=int, default=8, help="sweep: held-out recordings per interaction")
    ap.add_argument("--jobs", type=int, default=1, help="sweep: parallel workers")
    ap.add_argument("--data", default=None, help="NuiSI file (default: the shared data folder)")
    args = ap.parse_args(argv)
    from ..core.blas import single_thread

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    parts = {p.strip() for p in args.part.split(",") if p.strip()}
    if "realtime" in parts:
        with single_thread():
            res = run_realtime(realtime_tasks(tuple(t.strip() for t in args.tasks.split(",")), args.data))
        (out / "realtime.json").write_text(json.dumps(res, indent=1, default=float))
        (out / "realtime.md").write_text(realtime_tables(res))
        print(f"wrote {out / 'realtime.md'}")
    if "upperbody" in parts:  # the second configuration: agent 1's upper body observed, agent 2's right arm
        with single_thread():
            res = run_realtime(realtime_tasks(("nuisi",), args.data, observed="upper_body", controlled="right_arm"),
                               methods=("ip", "prior"))
        (out / "upperbody.json").write_text(json.dumps(res, indent=1, default=float))
        (out / "upperbody.md").write_text(realtime_tables(res, methods=("ip", "prior")))
        print(f"wrote {out / 'upperbody.md'}")
    if "sweep" in parts:
        t0 = time.perf_counter()
        res = run_nuisi_sweep(args.max_demos, args.jobs, args.data)
        (out / "sweep.json").write_text(json.dumps({"summary": res["summary"]}, indent=1, default=float))
        (out / "sweep.md").write_text(res["markdown"])
        print(f"wrote {out / 'sweep.md'} in {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())

"""The final numbers: every method fitted on the development recordings, measured once on the untouched hold-out.

The hold-out was fixed before any new model was developed (:data:`interprim.evaluation.nested.HOLDOUT`): the
last third of each NuiSI interaction's recordings (highest demo numbers), and the synthetic benchmark drawn
with seed 1 (:func:`interprim.synthetic.benchmark_tasks`; development uses seed 0).  Every choice is made on
the development recordings: each estimator's own hyper-parameters in its ``fit``, and the ``chosen`` method
by a 3-fold cross-validation on them (:func:`interprim.evaluation.realtime.choose_method`).  Predictions see
causal prefixes (:mod:`interprim.model_selection.prefixes`); ``--lookahead`` adds the same figures with the
uncut interpolation (the old, flattering protocol) for NuiSI, to show what causality changes.

Run::

    python -m interprim.experiments.holdout --out holdout-results [--tasks nuisi,synthetic] [--lookahead]

Writes ``holdout.json`` (every record and summary), ``holdout.md`` (the tables, with standard errors) and
``readme_table.md`` (the README's accuracy table) to ``--out``; ``--tables-from DIR`` writes the tables again from
a ``holdout.json`` without measuring anything.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from ..evaluation.nested import HOLDOUT, measure_fitted, split_holdout, standard_error_ratio, yardstick_table
from ..evaluation.realtime import RealTimeConfig, default_methods, summarise_with_rest
from ..model_selection.prefixes import Prefixes
from ..models.registry import FAMILIES

__all__ = ["holdout_tasks", "run_task", "tables", "yardstick_tables", "readme_table", "main"]

NUISI_ACTIONS = ("highfive1", "handshake2", "fistbump2", "clapfist2", "rocket1", "wave1")
#: the families the real-time evaluation compares by default (all but the peer, Interaction ProMP, which needs the
#: [bench] extra, and the leave-one-out sweep's variants)
METHODS = tuple(n for n, f in FAMILIES.items() if f.default_method)


def holdout_tasks(which=("nuisi", "synthetic"), data_path=None):
    """``[(name, dev, hold, observed_dofs, dt, point_dim, oracles or None)]`` for the hold-out evaluation.

    NuiSI: agent 1's right arm observed (shoulder, elbow, hand: 9 columns), agent 2's right hand predicted,
    20 Hz; ``dev``/``hold`` are :class:`~interprim.datasets.Demonstrations` (raw samples kept: causal prefixes).
    """
    out = []
    if "nuisi" in which:
        from ..datasets import load_nuisi

        for a in NUISI_ACTIONS:
            d = load_nuisi(data_path, action=a, observed="right_arm", controlled="right_hand", dt=0.05)
            dev_i, hold_i = split_holdout(len(d))
            out.append((a, d.take(dev_i), d.take(hold_i), list(d.observed_dofs), float(d.dt), 3, None))
    if "synthetic" in which:
        from ..synthetic import benchmark_tasks

        dev = benchmark_tasks(30, seed=HOLDOUT["synthetic_dev_seed"])
        hold = benchmark_tasks(15, seed=HOLDOUT["synthetic_holdout_seed"])
        for name in dev:
            out.append((f"synthetic/{name}", dev[name].demos, hold[name].demos, dev[name].observed_dofs,
                        dev[name].dt, 1, hold[name].oracles))
    return out


def run_task(name, dev, hold, obs, dt, point_dim, oracles=None, methods=METHODS, lookahead=False,
             fractions=(0.6,), log=print, folds: int = 3):
    """Fit every method on ``dev``, choose one by inner CV on ``dev``, measure all on ``hold``.

    Returns ``{"records": [...], "summary": {protocol: summary}, "chosen": name, "inner": scores}``.
    """
    from ..models.auto import CANDIDATES, AutoInteraction

    cfg = RealTimeConfig(point_dim=point_dim)
    make = {m: f for m, f in default_methods(obs).items() if m in methods}
    t0 = time.perf_counter()
    # what AutoInteraction.fit(dev) makes: its inner cross-validation on the development recordings chooses the
    # "chosen" family and fits the blend ("auto") of its candidate families among the methods
    train = [np.asarray(x, dtype=np.float64) for x in dev]
    blend = AutoInteraction(obs, candidates=[(m, make[m]) for m in make if m in CANDIDATES], folds=folds,
                            horizon=cfg.horizon, stride=3, point_dim=point_dim).fit(dev, dt=dt)
    chosen = blend.chosen_
    inner = dict(blend.selection_["cv_errors"])
    weights = blend.weights_
    inner["blend"] = blend.selection_["blend_cv_error"]
    lr = blend.selection_.get("long_range", {})
    log(f"  {name}: chose {chosen} on the development recordings "
        f"({', '.join(f'{m} {v:.4g}' for m, v in inner.items())}), blend "
        f"{', '.join(f'{m} {x:.2f}' for m, x in weights.items())}; beyond the real-time band "
        f"{lr.get('beyond', '-')}, remaining duration {lr.get('remaining', '-')}, the robot's past "
        f"{lr.get('past', '-')}; in {time.perf_counter() - t0:.0f} s")
    prefixes = {"causal": Prefixes(hold, obs)}
    if lookahead and prefixes["causal"].causal:
        prefixes["lookahead"] = Prefixes([np.asarray(x) for x in hold], obs)
    records: dict[str, list] = {p: [] for p in prefixes}

    # fitted as a user fits them: on the recordings with their raw samples when they have them (the same arrays;
    # the Interaction Primitive's calibration then sees causal prefixes)
    fit_on = dev if getattr(dev, "raw", None) is not None else train

    def models():
        for m, factory in make.items():
            yield m, factory().fit(fit_on, dt=dt)
        yield "auto", blend

    for first, (m, est) in enumerate(models()):
        t1 = time.perf_counter()
        # real time after every frame, the rest of the movement after every 3rd frame (every remaining frame)
        got = measure_fitted(est, m, train, prefixes["causal"], obs, dt, point_dim, horizon=cfg.horizon,
                             rest_stride=3, fractions=fractions, oracles=oracles, references=first == 0,
                             prefix_sets=prefixes)
        for p in records:
            records[p] += got[p]
        log(f"    {m}: fitted and measured in {time.perf_counter() - t1:.0f} s")
    for p in records:
        records[p] += [dict(r, method="chosen", chosen=chosen) for r in records[p] if r["method"] == chosen]
    # the rest of the movement, in seconds from now (error and band coverage), beside the real-time figures
    summary = {p: summarise_with_rest(records[p]) for p in records}
    lr = blend.selection_.get("long_range", {})
    return {"records": records, "summary": summary,
            "chosen": chosen, "inner": inner, "weights": weights,
            "long_range": {k: lr[k] for k in ("remaining", "beyond") if k in lr},
            "inner_yardsticks": blend.selection_.get("inner_yardsticks", {}),
            "se": {p: {f"{a}|{b}": standard_error_ratio(records[p], a, b) for a in ("chosen", "auto")
                       for b in ("nn", "clock", "oracle-duration", "prior")}
                   | {f"{a}|wm_{b}": standard_error_ratio(records[p], a, b, key="wm_ctrl") for a in ("chosen", "auto")
                      for b in ("prior", "nn")}
                   | {f"{a}|rest_{b}": standard_error_ratio(records[p], a, b, protocol="rest")
                      for a in ("chosen", "auto") for b in METHODS}
                   for p in records},
            "yardsticks": {p: yardstick_table(records[p], ["auto", "chosen", *METHODS, "clock", "oracle-duration"])
                           for p in records}}


COLUMNS = (("rest_rt_ctrl_vs_clock", "robot, rest of the movement in seconds ÷ clock"),
           ("rest_rt_ctrl_vs_oracle", "robot, rest of the movement in seconds ÷ mean at true duration"),
           ("rest_cov_ctrl", "90 % band over the rest, robot"), ("rest_cov_obs", "90 % band over the rest, human"),
           ("rt_ctrl_vs_clock", "robot real time ÷ clock"), ("rt_ctrl_vs_oracle", "÷ mean at true duration"),
           ("rt_ctrl_vs_floor", "÷ oracle (floor)"), ("rt_obs_vs_clock", "human real time ÷ clock"),
           ("phase_err_vs_clock", "phase ÷ clock"), ("wm_ctrl_vs_prior", "robot whole movement (60 %) ÷ mean"),
           ("wm_ctrl_vs_floor", "whole ÷ oracle"), ("cov_ctrl", "90 % band, robot"), ("cov_obs", "90 % band, human"))


def tables(results, protocol="causal") -> str:
    """Markdown: one table per metric, tasks as columns, methods as rows, and the geometric mean over tasks."""
    names = [n for n in results if protocol in results[n]["summary"]]
    methods = ["auto", "chosen", *METHODS, "clock", "oracle-duration", "oracle"]
    lines = []
    for key, title in COLUMNS:
        rows = []
        for m in methods:
            vals = [results[n]["summary"][protocol].get(m, {}).get(key, np.nan) for n in names]
            if not np.any(np.isfinite(vals)):
                continue
            ok = [v for v in vals if np.isfinite(v) and v > 0]
            geo = float(np.exp(np.mean(np.log(ok)))) if ok and "cov" not in key else (
                float(np.mean(ok)) if ok else np.nan)
            cells = ["—" if not np.isfinite(v) else f"{v:.2f}" for v in vals] + [f"{geo:.2f}"]
            rows.append(f"| {m} | " + " | ".join(cells) + " |")
        if rows:
            agg = "mean" if "cov" in key else "geo-mean"
            lines += [f"**{title}** ({protocol} prefixes)", "",
                      "| method | " + " | ".join(names) + f" | {agg} |", "|---" * (len(names) + 2) + "|", *rows, ""]
    chosen = ", ".join(f"{n}: {results[n]['chosen']}" for n in names)
    lines.append(f"Chosen on the development recordings: {chosen}.")
    blends = "; ".join(f"{n}: " + ", ".join(f"{m} {x:.2f}" for m, x in results[n].get("weights", {}).items())
                       for n in names)
    lines.append(f"Blend weights (auto), fitted on the development recordings: {blends}.")
    return "\n".join(lines)


def yardstick_tables(results, protocol="causal") -> str:
    """Markdown: per yardstick (:data:`interprim.evaluation.nested.YARDSTICKS`), every method's ratio to the
    reference ± its standard error over the held-out recordings, per task, and the geometric mean over tasks."""
    names = [n for n in results if protocol in results[n].get("yardsticks", {})]
    if not names:
        return ""
    labels = list(results[names[0]]["yardsticks"][protocol])
    methods = list(results[names[0]]["yardsticks"][protocol][labels[0]])
    lines = []
    for label in labels:
        rows = []
        for m in methods:
            cells = [results[n]["yardsticks"][protocol][label].get(m, (np.nan, np.nan)) for n in names]
            ok = [r for r, _ in cells if np.isfinite(r) and r > 0]
            if not ok or all(abs(r - 1.0) < 1e-12 for r in ok):  # the reference itself
                continue
            geo = float(np.exp(np.mean(np.log(ok))))
            txt = ["—" if not np.isfinite(r) else (f"{r:.2f} ± {se:.2f}" if np.isfinite(se) else f"{r:.2f}")
                   for r, se in cells]
            rows.append(f"| {m} | " + " | ".join(txt) + f" | {geo:.2f} |")
        lines += [f"**{label}** (± one standard error over the held-out recordings; {protocol} prefixes)", "",
                  "| method | " + " | ".join(names) + " | geo-mean |", "|---" * (len(names) + 2) + "|", *rows, ""]
    return "\n".join(lines)


#: The README's accuracy table: ``(column title, summary key)``, each as NuiSI's geometric mean / all tasks'.
README_COLUMNS = (("next 0.25 s ÷ clock", "rt_ctrl_vs_clock"),
                  ("next 0.25 s ÷ mean at true duration", "rt_ctrl_vs_oracle"),
                  ("rest of the movement ÷ clock", "rest_rt_ctrl_vs_clock"),
                  ("rest ÷ mean at true duration", "rest_rt_ctrl_vs_oracle"),
                  ("whole movement at 60 % ÷ mean", "wm_ctrl_vs_prior"))
#: Its rows: ``(label, method)``.
README_ROWS = (("`AutoInteraction` (what `interprim fit` makes)", "auto"), ("`InteractionPrimitive`, defaults", "ip"),
               ("`LearnedInteraction`", "learned"), ("kernel-weighted demonstrations", "kernel"),
               ("nearest demonstration", "nn"))


def readme_table(results, protocol="causal") -> str:
    """The README's accuracy table from the hold-out's results: geometric means over NuiSI's tasks / over all."""
    names = [n for n in results if protocol in results[n]["summary"]]
    nuisi = [n for n in names if not n.startswith("synthetic/")]

    def geo(m, key, tasks):
        v = [results[n]["summary"][protocol].get(m, {}).get(key, np.nan) for n in tasks]
        v = [x for x in v if np.isfinite(x) and x > 0]
        return f"{np.exp(np.mean(np.log(v))):.2f}" if v else "—"

    head = ("| model | " + " | ".join(f"{t}, NuiSI ({len(nuisi)}) / all {len(names)} tasks" if i == 0 else
                                       f"{t}, NuiSI / {len(names)}" for i, (t, _) in enumerate(README_COLUMNS)) + " |")
    lines = [head, "|---" * (len(README_COLUMNS) + 1) + "|"]
    for label, m in README_ROWS:
        lines.append(f"| {label} | " + " | ".join(f"{geo(m, k, nuisi)} / {geo(m, k, names)}" for _, k in README_COLUMNS)
                     + " |")
    return "\n".join(lines)


def main(argv=None) -> int:
    """The command line of this module (see the module docstring); returns the exit status."""
    ap = argparse.ArgumentParser(prog="python -m interprim.experiments.holdout", description=__doc__.split("\n")[0])
    ap.add_argument("--out", default="holdout-results", help="output folder (outside the repository)")
    ap.add_argument("--tasks", default="nuisi,synthetic", help="nuisi, synthetic or both")
    ap.add_argument("--only", default=None, help="comma-separated task names to run (default all)")
    ap.add_argument("--data", default=None, help="NuiSI file (default: the shared data folder)")
    ap.add_argument("--lookahead", action="store_true", help="also measure with the uncut interpolation (NuiSI)")
    ap.add_argument("--tables-from", default=None, help="only write the tables again from DIR/holdout.json")
    args = ap.parse_args(argv)
    from ..core.blas import single_thread

    if args.tables_from is not None:
        results = json.loads((Path(args.tables_from) / "holdout.json").read_text())
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        (out / "holdout.md").write_text(tables(results) + "\n\n" + yardstick_tables(results) + "\n")
        (out / "readme_table.md").write_text(readme_table(results) + "\n")
        print(f"wrote {out / 'holdout.md'} and {out / 'readme_table.md'}")
        return 0

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    results = {}
    only = None if args.only is None else set(args.only.split(","))
    with single_thread():
        for (name, dev, hold, obs, dt, pdim, orc) in holdout_tasks(tuple(args.tasks.split(",")), args.data):
            if only is not None and name not in only:
                continue
            print(f"{name}: {len(dev)} development, {len(hold)} hold-out recordings", flush=True)
            results[name] = run_task(name, dev, hold, obs, dt, pdim, orc, lookahead=args.lookahead,
                                     log=lambda s: print(s, flush=True))
            (out / "holdout.json").write_text(json.dumps(results, default=float))
    md = (tables(results) + "\n\n" + yardstick_tables(results)
          + ("\n\n" + tables(results, "lookahead") if args.lookahead else ""))
    (out / "holdout.md").write_text(md + "\n")
    (out / "readme_table.md").write_text(readme_table(results) + "\n")
    print(md)
    print(f"wrote {out / 'holdout.json'} and {out / 'holdout.md'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

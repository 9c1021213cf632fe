"""NuiSI leave-one-out: the coupling model against the default IP, the prior mean and nearest neighbour.

Run::

    python -m interprim.experiments.coupling_nuisi --out /tmp/coupling

For every NuiSI v1 interaction and every demonstration ``j``: fit each method on the other
demonstrations; observe the first ``p`` % of ``j``'s observed agent (agent 1's right shoulder,
elbow and hand by default: 9 columns; the controlled agent is agent 2's same joints), ``p`` = 20 ... 90;
predict the whole movement of both agents on a normalised-time grid of 100 points and compare with
the truth (``M = round(p T)`` frames seen, true phase ``(M - 1) / (T - 1)``, as
:func:`interprim.evaluation.evaluate_fold`).

Methods:

- ``coupling`` - :class:`interprim.models.coupling.CouplingModel` with its defaults;
- ``ip`` - :class:`interprim.InteractionPrimitive` with its defaults;
- ``prior`` - :class:`interprim.models.demonstrations.PriorMean`; ``nn`` -
  :class:`interprim.models.demonstrations.NearestNeighbour`.

``coupling`` and ``ip`` are given the phase in two ways: ``true`` (the true fraction seen; the
coupling is told its std is 0) and ``clock`` (elapsed time / mean training duration, clipped to 1;
the coupling uses its own clock-error model for the phase std).

Metrics per (interaction, method, phase source, held-out demo, fraction): agent 2's whole-movement
RMSE (3-D point errors, metres), agent 1's RMSE over the part still to come; coverage of the 90 %
band for agent 2 (whole movement) and agent 1 (part still to come); RMS error / mean predicted std
per agent.  Prints per-interaction ratios to the prior mean and a calibration table, writes JSON.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

ACTIONS = ("highfive1", "handshake2", "fistbump2", "clapfist2", "rocket1", "wave1")
FRACTIONS = (0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9)
Z90 = 1.6448536269514722
N_GRID = 100


def _point_rms(err):
    n, C = err.shape
    return float(np.sqrt(np.mean(np.sum(err.reshape(n, C // 3, 3) ** 2, axis=2))))


def _fmt_param(p):
    if p is None:
        return ""
    if isinstance(p, (list, tuple)):
        return ":" + ",".join(f"{x:g}" for x in p)
    return f":{p:g}"


def run_fold(demos, obs, dt, j, fractions=FRACTIONS, methods=("coupling", "ip", "prior", "nn"), coupling_kw=None):
    """Fit every method without demonstration ``j``; records for every fraction and phase source."""
    import interprim
    from interprim.core.preprocessing import time_normalise
    from interprim.model_selection.prefixes import observed_frames
    from interprim.models.coupling import CouplingModel
    from interprim.models.demonstrations import NearestNeighbour, PriorMean

    train = [d for i, d in enumerate(demos) if i != j]
    test = demos[j]
    D = test.shape[1]
    ctrl = [i for i in range(D) if i not in set(obs)]
    truth = time_normalise(test, N_GRID)
    T = test.shape[0]
    mean_dur = float(np.mean([(d.shape[0] - 1) * dt for d in train]))
    t_grid = np.linspace(0.0, 1.0, N_GRID)
    models, fit_time = {}, {}
    for m in methods:
        t0 = time.perf_counter()
        if m == "coupling":
            models[m] = CouplingModel(obs, **(coupling_kw or {})).fit(train, dt=dt)
        elif m == "ip":
            models[m] = interprim.InteractionPrimitive(obs).fit(train, dt=dt)
        elif m == "prior":
            models[m] = PriorMean(obs).fit(train)
        elif m == "nn":
            models[m] = NearestNeighbour(obs).fit(train)
        fit_time[m] = time.perf_counter() - t0
    out = []
    for p in fractions:
        M = observed_frames(T, p)
        s_true = (M - 1) / (T - 1)
        s_clock = float(min(1.0, max((M - 1) * dt / mean_dur, 1e-3)))
        part = test[:M, obs]
        for m in methods:
            sources = ("true", "clock") if m in ("coupling", "ip") else ("none",)
            for src in sources:
                s = s_true if src == "true" else s_clock
                t0 = time.perf_counter()
                if m == "coupling":
                    pred = models[m].predict(part, max(s, 1e-3), phase_std=0.0 if src == "true" else None)
                elif m == "ip":
                    pred = models[m].predict(part, phase=max(s, 1e-3))
                else:
                    pred = models[m].predict(part)
                pt = time.perf_counter() - t0
                Y = pred.trajectory(N_GRID)
                S = pred.std(N_GRID)
                err = Y - truth
                rest = t_grid > s_true
                rec = {"demo": int(j), "fraction": float(p), "method": m, "phase_source": src,
                       "phase": float(s), "phase_true": float(s_true),
                       "rmse_ctrl": _point_rms(err[:, ctrl]), "rmse_obs_rest": _point_rms(err[rest][:, obs]),
                       "predict_time": pt, "fit_time": fit_time[m]}
                if S is not None:
                    ec, sc = err[:, ctrl], S[:, ctrl]
                    eo, so = err[rest][:, obs], S[rest][:, obs]
                    rec.update({
                        "coverage_ctrl": float(np.mean(np.abs(ec) <= Z90 * sc + 1e-12)),
                        "coverage_obs": float(np.mean(np.abs(eo) <= Z90 * so + 1e-12)),
                        "ms_ctrl": float(np.mean(ec**2)), "std_ctrl": float(np.mean(sc)),
                        "ms_obs": float(np.mean(eo**2)), "std_obs": float(np.mean(so)),
                        # a calibrated Gaussian with this std profile has RMS / mean std = sqrt(var_*) / std_*
                        "var_ctrl": float(np.mean(sc**2)), "var_obs": float(np.mean(so**2)),
                        # standardised errors (1 = calibrated whatever the profile)
                        "z2_ctrl": float(np.mean((ec / np.maximum(sc, 1e-12)) ** 2)),
                        "z2_obs": float(np.mean((eo / np.maximum(so, 1e-12)) ** 2)),
                    })
                if m == "coupling":
                    rec["coupling_method"] = models[m].method_
                    rec["coupling_param"] = models[m].param_
                out.append(rec)
    return out


def summarise(records):
    """Means over held-out demos: ``{action: {label: {fraction: {metric: value}}}}``."""
    acc = {}
    for r in records:
        label = r["method"] if r["phase_source"] == "none" else f"{r['method']}-{r['phase_source']}"
        d = acc.setdefault(r["action"], {}).setdefault(label, {}).setdefault(r["fraction"], {})
        for k in ("rmse_ctrl", "rmse_obs_rest", "coverage_ctrl", "coverage_obs", "ms_ctrl", "std_ctrl", "ms_obs",
                  "std_obs", "var_ctrl", "var_obs", "z2_ctrl", "z2_obs"):
            if k in r:
                d.setdefault(k, []).append(r[k])
    return {a: {lab: {f: {k: float(np.mean(v)) for k, v in md.items()} for f, md in fm.items()}
                for lab, fm in am.items()} for a, am in acc.items()}


def tables(summary, fractions):
    labels = ["coupling-true", "coupling-clock", "ip-true", "ip-clock", "nn"]
    lines = ["## agent 2 whole-movement RMSE, ratio to the prior mean (prior RMSE in m in the last column)", ""]
    head = ("| interaction | method | " + " | ".join(f"{int(round(f * 100))} %" for f in fractions)
            + " | mean 40/60/80 |")
    lines += [head, "|" + "---|" * (len(fractions) + 3)]
    agg = {lab: [] for lab in labels}
    for a, am in summary.items():
        prior = am["prior"]
        for lab in labels:
            if lab not in am:
                continue
            r = [am[lab][f]["rmse_ctrl"] / prior[f]["rmse_ctrl"] for f in fractions]
            key = [am[lab][f]["rmse_ctrl"] / prior[f]["rmse_ctrl"] for f in (0.4, 0.6, 0.8) if f in fractions]
            agg[lab].append(r)
            lines.append(f"| {a} | {lab} | " + " | ".join(f"{x:.3f}" for x in r) + f" | {np.mean(key):.3f} |")
        lines.append(f"| {a} | prior (m) | " + " | ".join(f"{prior[f]['rmse_ctrl']:.4f}" for f in fractions) + " | |")
    lines.append("")
    lines.append("### mean over interactions of the ratio to the prior mean")
    lines.append("")
    lines += [head, "|" + "---|" * (len(fractions) + 3)]
    idx = [i for i, f in enumerate(fractions) if f in (0.4, 0.6, 0.8)]
    for lab, rows in agg.items():
        if rows:
            m = np.mean(rows, axis=0)
            lines.append(f"| all | {lab} | " + " | ".join(f"{x:.3f}" for x in m) + f" | {np.mean(m[idx]):.3f} |")
    lines.append("")
    lines.append("## calibration (pooled over interactions and demos): coverage of the 90 % band, RMS error / mean std")
    lines.append("")
    lines.append("| method | agent | metric | " + " | ".join(f"{int(round(f * 100))} %" for f in fractions) + " |")
    lines.append("|" + "---|" * (len(fractions) + 3))
    for lab in ("coupling-true", "coupling-clock", "ip-true", "ip-clock"):
        for agent in ("ctrl", "obs"):
            cov, ratio, ideal, zrms = [], [], [], []
            for f in fractions:
                vals = [am[lab][f] for am in summary.values() if lab in am and f"coverage_{agent}" in am[lab][f]]
                if not vals:
                    break
                cov.append(np.mean([v[f"coverage_{agent}"] for v in vals]))
                mstd = np.mean([v[f"std_{agent}"] for v in vals])
                ratio.append(math.sqrt(np.mean([v[f"ms_{agent}"] for v in vals])) / mstd)
                if all(f"var_{agent}" in v for v in vals):
                    ideal.append(math.sqrt(np.mean([v[f"var_{agent}"] for v in vals])) / mstd)
                    zrms.append(math.sqrt(np.mean([v[f"z2_{agent}"] for v in vals])))
            if cov:
                name = "agent 2" if agent == "ctrl" else "agent 1 (rest)"
                lines.append(f"| {lab} | {name} | coverage | " + " | ".join(f"{x:.3f}" for x in cov) + " |")
                lines.append(f"| {lab} | {name} | RMS/std | " + " | ".join(f"{x:.2f}" for x in ratio) + " |")
                if ideal:
                    lines.append(f"| {lab} | {name} | same for a calibrated Gaussian | "
                                 + " | ".join(f"{x:.2f}" for x in ideal) + " |")
                    lines.append(f"| {lab} | {name} | RMS of error/std | "
                                 + " | ".join(f"{x:.2f}" for x in zrms) + " |")
    return "\n".join(lines) + "\n"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", required=True, help="output folder (results.json, summary.json, tables.md)")
    ap.add_argument("--actions", default=",".join(ACTIONS))
    ap.add_argument("--methods", default="coupling,ip,prior,nn")
    ap.add_argument("--max-demos", type=int, default=None, help="hold out only this many demos per interaction")
    ap.add_argument("--observed", default="right_arm", help="agent-1 joints (a load_nuisi group or list)")
    ap.add_argument("--controlled", default="right_arm", help="agent-2 joints")
    ap.add_argument("--data", default=None, help="NuiSI file or data folder")
    ap.add_argument("--coupling-kw", default="{}", help="JSON dict of CouplingModel keyword arguments")
    ap.add_argument("--from-results", default=None, nargs="+",
                    help="only summarise these results.json files (of earlier runs) into --out")
    args = ap.parse_args(argv)
    from interprim.core.blas import single_thread
    from interprim.datasets import load_nuisi

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    methods = tuple(m for m in args.methods.split(",") if m)
    records = []
    t_start = time.time()
    if args.from_results:
        for f in args.from_results:
            records += json.loads(Path(f).read_text())
        methods = tuple(dict.fromkeys(r["method"] for r in records))
    else:
        records = _run(args, methods, out, load_nuisi, single_thread, t_start)
    return _report(records, methods, out, args)


def _run(args, methods, out, load_nuisi, single_thread, t_start):
    records = []
    with single_thread():
        for a in args.actions.split(","):
            d = load_nuisi(args.data, action=a, observed=args.observed, controlled=args.controlled)
            demos, obs = list(d.demos), list(d.observed_dofs)
            n = len(demos)
            idx = (range(n) if args.max_demos is None
                   else np.unique(np.linspace(0, n - 1, min(args.max_demos, n)).astype(int)))
            for j in idx:
                for r in run_fold(demos, obs, float(d.dt), int(j), methods=methods,
                                  coupling_kw=json.loads(args.coupling_kw)):
                    r["action"] = a
                    records.append(r)
            print(f"{a}: {len(idx)} folds done ({time.time() - t_start:.0f} s)", file=sys.stderr, flush=True)
            (out / "results.json").write_text(json.dumps(records, indent=0, default=float))
    return records


def _report(records, methods, out, args):
    (out / "results.json").write_text(json.dumps(records, indent=0, default=float))
    summary = summarise(records)
    fractions = tuple(sorted({r["fraction"] for r in records}))
    txt = tables(summary, fractions)
    timing = {m: {"fit_s": float(np.median([r["fit_time"] for r in records if r["method"] == m])),
                  "predict_ms": 1e3 * float(np.median([r["predict_time"] for r in records if r["method"] == m]))}
              for m in methods}
    choices = {}
    for r in records:
        if r["method"] == "coupling" and r["fraction"] == fractions[0] and r["phase_source"] == "true":
            key = r["coupling_method"] + _fmt_param(r["coupling_param"])
            choices.setdefault(r["action"], {}).setdefault(key, 0)
            choices[r["action"]][key] += 1
    txt += "\n## timing (median per fold)\n\n" + "\n".join(
        f"- {m}: fit {v['fit_s']:.2f} s, one prediction {v['predict_ms']:.2f} ms" for m, v in timing.items()) + "\n"
    txt += "\n## coupling chosen by the inner CV (folds per choice)\n\n" + "\n".join(
        f"- {a}: {c}" for a, c in choices.items()) + "\n"
    print(txt)
    (out / "summary.json").write_text(json.dumps({"summary": summary, "timing": timing, "choices": choices,
                                                  "args": vars(args)}, indent=1, default=float))
    (out / "tables.md").write_text(txt)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

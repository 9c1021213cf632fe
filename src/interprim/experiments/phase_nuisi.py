"""Phase estimation on NuiSI v1: the clock, the library's phase, the paper's DTW and :class:`LearnedPhase`.

Run ``python -m interprim.experiments.phase_nuisi [--out /tmp/phase_nuisi.json] [--realtime]``.

Protocol (issue 11; ``docs/GUIDE`` Sec. 4 "Phase"): for every NuiSI interaction and every
demonstration ``j`` (leave-one-out), everything is fitted on the other demonstrations; the first
``M = round(p T)`` frames of ``j``'s observed agent (agent 1's right shoulder, elbow and hand: 9
columns, as in the issue's measurement; ``--observed upper_body`` for the 24 columns of
``docs/evaluation.md``) are seen, ``p`` = 0.3, 0.4, ..., 0.9, and the estimated normalised time of the
last seen frame is compared with the true one, ``(M - 1) / (T - 1)``.  Methods:

* ``clock``: ``t / mean duration`` of the training demonstrations (clipped at 1);
* ``default``: the phase of ``InteractionPrimitive(...).predict`` with the library's defaults
  (likelihood phase; 20 basis functions, Savitzky-Golay window 7 as in ``docs/evaluation.md``;
  agent 2's right hand controlled);
* ``dtw``: the same fitted model with ``phase_method="dtw"`` (the paper's Eq. 5-9);
* ``learned``: :class:`interprim.phase.learned.LearnedPhase` with its defaults, fitted on the
  training demonstrations' observed columns only;
* ``learned+default``: the mean of the two (a measurement of whether they carry different information).

``--realtime`` adds the real-time protocol (issue 11, protocol 1): after each observed frame ``k``
with ``k / (T - 1)`` in [0.2, 0.9], agent 2's hand at the next frames up to 0.25 s ahead, placed in
seconds by each method's phase and duration; RMSE (3-D point error) against the truth for the
clock-driven mean, the oracle-duration mean (a floor, not available online), the mean played with
the learned duration, the IP with its own phase, and the IP conditioned at the learned phase
(``predict(partial, phase=...)``).

Prints one table per protocol (mean error per interaction, ratio to the clock, geometric mean of the
ratios) and writes everything to ``--out`` as JSON.
"""

from __future__ import annotations

import argparse
import json
import math
import time

import numpy as np

ACTIONS = ("clapfist2", "fistbump2", "handshake2", "highfive1", "rocket1", "wave1")
FRACTIONS = tuple(round(0.1 * k, 1) for k in range(3, 10))
PHASE_METHODS = ("clock", "default", "dtw", "learned", "learned+default")
RT_METHODS = ("clock-mean", "oracle-mean", "learned-mean", "ip-default", "ip-learned")


def _mean_ctrl(train, ctrl, n=201):
    from interprim.core.preprocessing import time_normalise

    return np.mean([time_normalise(d[:, ctrl], n) for d in train], axis=0)


def _at(traj, u):
    """Rows of a trajectory on a uniform [0, 1] grid at normalised times ``u`` (clipped), linearly."""
    g = np.linspace(0.0, 1.0, traj.shape[0])
    from interprim.core.preprocessing import interp_columns

    return interp_columns(np.clip(u, 0.0, 1.0), g, traj)


def run_fold(demos, obs, ctrl, dt, j, ip_methods=True, realtime=False, horizon=0.25, learned_kwargs=None,
             ip_kwargs=None):
    """Phase errors (and real-time errors) of held-out demonstration ``j``; returns a dict of lists."""
    from interprim import InteractionPrimitive
    from interprim.model_selection.prefixes import observed_frames
    from interprim.phase.learned import LearnedPhase

    train = [d for i, d in enumerate(demos) if i != j]
    test = demos[j]
    T = test.shape[0]
    mean_dur = float(np.mean([(d.shape[0] - 1) * dt for d in train]))
    lp = LearnedPhase(**(learned_kwargs or {})).fit([d[:, obs] for d in train], dt=dt)
    ip = None
    if ip_methods or realtime:
        kw = dict(n_basis=20, smoothing_window=7)
        kw.update(ip_kwargs or {})
        ip = InteractionPrimitive(observed_dofs=list(obs), **kw).fit(train, dt=dt)
    out = {"phase": {m: [] for m in PHASE_METHODS}, "phase_true": [], "fractions": [],
           "learned_method": lp.method_, "learned_features": list(lp.features_), "learned_std": [],
           "learned_time_ms": []}
    for p in FRACTIONS:
        M = observed_frames(T, p)
        prefix = test[:M, obs]
        out["phase_true"].append((M - 1) / (T - 1))
        out["fractions"].append(p)
        out["phase"]["clock"].append(min((M - 1) * dt / mean_dur, 1.0))
        t0 = time.perf_counter()
        est = lp.estimate(prefix)
        out["learned_time_ms"].append(1e3 * (time.perf_counter() - t0))
        out["phase"]["learned"].append(est.phase)
        out["learned_std"].append(est.std)
        if ip_methods:
            out["phase"]["default"].append(float(ip.predict(prefix).phase))
            ip.phase_method = "dtw"
            out["phase"]["dtw"].append(float(ip.predict(prefix).phase))
            ip.phase_method = "likelihood"
            out["phase"]["learned+default"].append(0.5 * (est.phase + out["phase"]["default"][-1]))
    if realtime:
        H = max(1, int(round(horizon / dt)))
        mean_c = _mean_ctrl(train, ctrl)
        true_dur = (T - 1) * dt
        rt = {m: [] for m in RT_METHODS}
        for k in range(2, T - 1):
            if not 0.2 <= k / (T - 1) <= 0.9:
                continue
            fut = np.arange(k + 1, min(k + H, T - 1) + 1)
            tf = fut * dt
            truth = test[fut][:, ctrl]
            prefix = test[: k + 1, obs]
            est = lp.estimate(prefix)
            pred = ip.predict(prefix)
            pred_l = ip.predict(prefix, phase=max(est.phase, 1e-3))
            cands = {
                "clock-mean": _at(mean_c, tf / mean_dur),
                "oracle-mean": _at(mean_c, tf / true_dur),
                "learned-mean": _at(mean_c, tf / est.duration),
                "ip-default": _at(pred.trajectory(201)[:, ctrl], tf / pred.duration),
                "ip-learned": _at(pred_l.trajectory(201)[:, ctrl], tf / est.duration),
            }
            for m, y in cands.items():
                rt[m].extend(np.sum((y - truth) ** 2, axis=1).tolist())
        out["realtime_sq"] = rt
    return out


def run(actions=ACTIONS, observed="right_arm", ip_methods=True, realtime=False, data_path=None, max_demos=None,
        learned_kwargs=None, n_jobs=1, progress=True):
    """Leave-one-out over every interaction; returns ``{action: {...}}`` (see the module docstring)."""
    from joblib import Parallel, delayed

    from interprim.datasets import load_nuisi

    results = {}
    for a in actions:
        d = load_nuisi(data_path, action=a, observed=observed, controlled="right_hand")
        demos = list(d.demos)
        obs = list(d.observed_dofs)
        ctrl = [c for c in range(demos[0].shape[1]) if c not in set(obs)]
        idx = range(len(demos)) if max_demos is None else \
            np.unique(np.linspace(0, len(demos) - 1, min(max_demos, len(demos))).astype(int))
        t0 = time.perf_counter()
        folds = Parallel(n_jobs=n_jobs)(delayed(run_fold)(demos, obs, ctrl, d.dt, int(j), ip_methods, realtime,
                                                          learned_kwargs=learned_kwargs) for j in idx)
        res = {"n_demos": len(demos), "seconds": time.perf_counter() - t0, "phase_error": {}, "by_fraction": {}}
        for m in PHASE_METHODS:
            errs = np.array([np.abs(np.array(f["phase"][m]) - np.array(f["phase_true"])) for f in folds
                             if f["phase"][m]])
            if errs.size:
                res["phase_error"][m] = float(errs.mean())
                res["by_fraction"][m] = dict(zip(map(str, FRACTIONS), errs.mean(axis=0).tolist()))
        res["folds"] = [{"phase": f["phase"], "phase_true": f["phase_true"], "learned_std": f["learned_std"]}
                        for f in folds]
        res["learned_methods"] = [f["learned_method"] for f in folds]
        res["learned_features"] = [f["learned_features"] for f in folds]
        res["learned_std_mean"] = float(np.mean([f["learned_std"] for f in folds]))
        res["learned_rms_error"] = float(np.sqrt(np.mean([(np.array(f["phase"]["learned"]) -
                                                           np.array(f["phase_true"])) ** 2 for f in folds])))
        res["learned_ms_per_estimate"] = float(np.median([t for f in folds for t in f["learned_time_ms"]]))
        if realtime:
            res["realtime_rmse"] = {m: float(np.mean([math.sqrt(np.mean(f["realtime_sq"][m])) for f in folds
                                                      if f["realtime_sq"][m]])) for m in RT_METHODS}
        results[a] = res
        if progress:
            pe = res["phase_error"]
            print(f"  {a}: " + ", ".join(f"{m} {v:.4f}" for m, v in pe.items()) + f"  ({res['seconds']:.0f} s)",
                  flush=True)
    return results


def run_builtin(datasets=("synthetic", "synthetic-noisy", "highfive-sim"), max_demos=10, learned_kwargs=None,
                progress=True):
    """The phase protocol on built-in data sets (:func:`interprim.evaluation.task_names`), for comparison."""
    from interprim.evaluation import EvalConfig, load_task

    results = {}
    for ds in datasets:
        t = load_task(ds, ds, EvalConfig())
        demos, obs = list(t.demos), list(t.observed_dofs)
        ctrl = [c for c in range(demos[0].shape[1]) if c not in set(obs)]
        idx = np.unique(np.linspace(0, len(demos) - 1, min(max_demos, len(demos))).astype(int))
        folds = [run_fold(demos, obs, ctrl, t.dt, int(j), True, False, learned_kwargs=learned_kwargs,
                          ip_kwargs={"n_basis": 20, "smoothing_window": None}) for j in idx]
        res = {"n_demos": len(demos), "phase_error": {}}
        for m in PHASE_METHODS:
            errs = np.array([np.abs(np.array(f["phase"][m]) - np.array(f["phase_true"])) for f in folds])
            res["phase_error"][m] = float(errs.mean())
        results[ds] = res
        if progress:
            print(f"  {ds}: " + ", ".join(f"{m} {v:.4f}" for m, v in res["phase_error"].items()), flush=True)
    return results


def _table(results, key, methods, base):
    lines = ["| interaction | " + " | ".join(methods) + " | " + " | ".join(f"{m}/{base}" for m in methods
                                                                           if m != base) + " |",
             "|---" * (2 * len(methods)) + "|"]
    ratios = {m: [] for m in methods}
    for a, r in results.items():
        v = r.get(key, {})
        if base not in v:
            continue
        row = [f"{v[m]:.4f}" if m in v else "–" for m in methods]
        rr = []
        for m in methods:
            if m == base:
                continue
            if m in v:
                ratios[m].append(v[m] / v[base])
                rr.append(f"{v[m] / v[base]:.2f}")
            else:
                rr.append("–")
        lines.append(f"| {a} | " + " | ".join(row) + " | " + " | ".join(rr) + " |")
    geo = [f"{math.exp(np.mean(np.log(ratios[m]))):.2f}" if ratios[m] else "–" for m in methods if m != base]
    lines.append("| geo-mean ratio | " + " | ".join("" for _ in methods) + " | " + " | ".join(geo) + " |")
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m interprim.experiments.phase_nuisi", description=__doc__.split("\n")[0])
    ap.add_argument("--out", default="/tmp/phase_nuisi.json", help="JSON output path (default %(default)s)")
    ap.add_argument("--actions", default=",".join(ACTIONS))
    ap.add_argument("--observed", default="right_arm", help="agent 1 joints (NuiSI group or list; default right_arm)")
    ap.add_argument("--no-ip", action="store_true", help="skip the IP phases (default, dtw): no IP fits, fast")
    ap.add_argument("--realtime", action="store_true", help="also run the real-time protocol (0.25 s ahead)")
    ap.add_argument("--max-demos", type=int, default=None, help="hold out only this many demos per interaction")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--data-path", default=None)
    ap.add_argument("--builtin", default=None,
                    help="instead of NuiSI: built-in data sets, e.g. synthetic,synthetic-noisy,highfive-sim "
                         "(phase protocol only, --max-demos held out, default 10)")
    args = ap.parse_args(argv)
    if args.builtin:
        res = run_builtin([d.strip() for d in args.builtin.split(",") if d.strip()], max_demos=args.max_demos or 10)
        print("\nPhase error (30-90 % observed)\n")
        print(_table(res, "phase_error", list(PHASE_METHODS), "clock"))
        with open(args.out, "w") as fh:
            json.dump({"builtin": True, "fractions": FRACTIONS, "results": res}, fh, indent=1)
        print(f"wrote {args.out}")
        return res
    res = run(actions=[a.strip() for a in args.actions.split(",") if a.strip()], observed=args.observed,
              ip_methods=not args.no_ip, realtime=args.realtime, data_path=args.data_path,
              max_demos=args.max_demos, n_jobs=args.jobs)
    print("\nPhase error (mean |estimated - true| normalised time, 30-90 % observed, leave-one-out)\n")
    print(_table(res, "phase_error", [m for m in PHASE_METHODS
                                      if not (args.no_ip and m in ("default", "dtw", "learned+default"))], "clock"))
    if args.realtime:
        print("\nReal time: agent 2 hand RMSE (m) over the next 0.25 s, 20-90 % observed\n")
        print(_table(res, "realtime_rmse", list(RT_METHODS), "clock-mean"))
    ms = [r["learned_ms_per_estimate"] for r in res.values()]
    print(f"\nLearnedPhase.estimate: median {np.median(ms):.3f} ms per call (batch, from the prefix)")
    with open(args.out, "w") as fh:
        json.dump({"observed": args.observed, "fractions": FRACTIONS, "results": res}, fh, indent=1)
    print(f"wrote {args.out}")
    return res


if __name__ == "__main__":
    main()

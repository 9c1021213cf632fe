"""Handwriting completion with a single-agent Interaction Primitive (paper Sec. III-B/C, Fig. 3-4).

One model is learned per letter of the UCI Character Trajectories and per shape of the LASA
handwriting data set, with every column observed (``observed_dofs`` = all: the "single-agent"
IP, whose prediction is the completion of the observed movement).  Held-out samples are
observed for 20-80 % of their frames; the model estimates the phase by DTW and completes the
movement.  The completion is compared with the held-out sample on a normalised-time grid.

Protocol (fixed seed everywhere)
--------------------------------
- Letters: ``max_per_letter`` samples per letter (default 30, the first in file order, to
  keep the run short), ``n_folds``-fold cross-validation (default 5, folds from a seeded
  permutation).  LASA: leave-one-out over the 7 demonstrations of each shape, each
  demonstration resampled onto a common interval (``lasa_subsample`` x the data set's mean
  interval), so durations still differ.
- For each held-out sample of ``T`` frames and each ``p`` in ``percents``: observe the first
  ``max(3, round(p/100 T))`` frames, predict, and evaluate the posterior mean
  ``pred.trajectory(n_points)`` (normalised time 0..1 over the whole movement).
- Error: root-mean-square Euclidean distance between predicted and true positions over the
  ``n_points`` grid (``rmse``: whole movement; ``rmse_unseen``: grid points after ``p``),
  in the data's units (letters: integrated normalised tablet units; LASA: the positions as distributed).
- Methods: the IP with the paper's forcing-term observation (Eq. 15, ``ip_forcing``) and with
  position observations (``ip_position``), both with the DTW phase; as a diagnostic, the
  position IP given the *true* phase (``ip_position_true_phase``), which shows how much of
  the error is phase estimation.
- Baselines on the same splits: the **prior mean** (mean of the time-normalised training
  samples, no conditioning) and the **nearest neighbour**: the training sample with the
  smallest open-end DTW cost (paper Eq. 5-8, squared Euclidean local cost) against the
  observed prefix, time-normalised.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..core.cv import folds
from ..core.preprocessing import resample_step, time_normalise
from ..model_selection.prefixes import observed_frames

__all__ = [
    "run_handwriting",
    "open_end_dtw",
    "write_report",
    "summary_lines",
    "DEFAULT_LASA_SHAPES",
    "DEFAULT_PERCENTS",
    "BEYOND_PAPER",
]

DEFAULT_PERCENTS = (20, 30, 40, 50, 60, 70, 80)
DEFAULT_LASA_SHAPES = ("GShape", "Angle", "Sshape", "WShape", "NShape", "Snake")
_FIG_LETTERS = ("a", "b", "e", "g", "s", "z")
_FIG_PERCENTS = (20, 40, 60, 80)


# ----------------------------------------------------------------------------- DTW baseline
def open_end_dtw(query, ref):
    """Open-end DTW of a partial movement against a reference (paper Eq. 5-8).

    Parameters
    ----------
    query : ndarray, shape (t, D)
        The observed prefix.
    ref : ndarray, shape (N, D)
        A complete reference movement.

    Returns
    -------
    cost : float
        ``min_n D(n, t)``, the accumulated squared-Euclidean cost of the best alignment of
        the whole query with the reference prefix ``ref[:n* + 1]``.
    n_star : int
        0-based index of the reference frame the query's last frame is aligned to (Eq. 8).
    """
    from ..phase.dtw import open_end_dtw as _core_open_end_dtw  # the compiled kernels of the core (Sec. III-B)

    res = _core_open_end_dtw(ref, query, return_path=False)
    return float(res.cost), int(res.n_star)


#: Extra variant using the core's options beyond the paper: phase by likelihood and
#: ``sigma2`` chosen by cross-validation on the training demonstrations (slower).
BEYOND_PAPER = {"ip_forcing_likelihood_cv": {"observation": "forcing", "sigma2": "cv", "phase_method": "likelihood"},
                "ip_defaults": {}}  # the library's defaults


# ----------------------------------------------------------------------------- helpers
def _rmse(pred, truth, mask=None):
    d2 = ((pred - truth) ** 2).sum(axis=1)
    if mask is not None:
        if not mask.any():
            return float("nan")
        d2 = d2[mask]
    return float(np.sqrt(d2.mean()))


def _folds(n, n_folds, rng):
    """Leave-one-out (``n_folds`` None or >= n) or a seeded ``"shuffled"`` split (:func:`interprim.core.cv.folds`)."""
    return folds(n, n_folds, "shuffled", rng)


def _resample_common(demos, times, dt):
    return [resample_step(y, t - t[0], dt)[0] for y, t in zip(demos, times)]


@dataclass
class _Item:
    kind: str  # "letter" or "lasa"
    name: str
    demos: list
    dt: float
    units: str


def _load_items(letters, max_per_letter, lasa_shapes, lasa_subsample, data_path):
    from ..datasets import load_character_trajectories

    items = []
    if letters is None or len(letters) > 0:
        ct = load_character_trajectories(data_path, letters=letters, max_per_letter=max_per_letter)
        for k, ds in ct.items():
            items.append(_Item("letter", k, list(ds.demos), float(ds.dt), "tablet units"))
    if lasa_shapes:
        from ..datasets import load_lasa

        for s in lasa_shapes:
            ds = load_lasa(s, subsample=lasa_subsample)
            dt = float(np.mean([np.mean(np.diff(t)) for t in ds.times]))
            items.append(_Item("lasa", s, _resample_common(ds.demos, ds.times, dt), dt, "LASA units"))
    return items


# ----------------------------------------------------------------------------- experiment
def run_handwriting(
    out_dir=None,
    *,
    letters=None,
    max_per_letter: int | None = 30,
    n_folds: int = 5,
    lasa_shapes=DEFAULT_LASA_SHAPES,
    lasa_subsample: int = 5,
    percents=DEFAULT_PERCENTS,
    n_basis: int = 20,
    n_points: int = 100,
    observations=("forcing", "position"),
    true_phase: bool = True,
    extra_variants: dict | None = None,
    model_kwargs: dict | None = None,
    seed: int = 0,
    data_path=None,
    figures: bool = True,
    progress: bool = True,
) -> dict:
    """Run the handwriting-completion experiment and return its numbers.

    Parameters
    ----------
    out_dir : str or Path, optional
        If given, write ``results.json``, ``report.md`` and (with ``figures``) the figures
        ``handwriting_letters.png``, ``handwriting_lasa.png`` and ``handwriting_error.png``.
    letters : str or sequence of str, optional
        Letters of the Character Trajectories to use (default all 20; ``""`` for none).
    max_per_letter : int or None
        Samples per letter (first in file order; default 30; ``None`` for all 57-96).
    n_folds : int
        Folds of the cross-validation per letter (default 5).  LASA uses leave-one-out.
    lasa_shapes : sequence of str
        LASA shapes (default six; empty to skip LASA, which needs ``interprim[lasa]``).
    lasa_subsample : int
        LASA sampling-rate reduction (default 5: 200 frames per demonstration).
    percents : sequence of int
        Percentages of the held-out sample observed (default 20, 30, ..., 80).
    n_basis : int
        Basis functions per DoF of each model (default 20).
    n_points : int
        Size of the normalised-time evaluation grid (default 100).
    observations : sequence of {"forcing", "position"}
        Observation models of the IP to evaluate, one method ``ip_<observation>`` each
        (default both: ``"forcing"`` is the paper's Eq. 15, ``"position"`` conditions on
        positions).
    true_phase : bool
        Also evaluate the last IP variant with the *true* phase of the held-out sample
        instead of DTW (method ``ip_<observation>_true_phase``): a diagnostic that
        separates the error of phase estimation from the error of conditioning, not a
        method one could use online.
    extra_variants : dict, optional
        More IP variants to evaluate, ``{method_name: InteractionPrimitive keyword
        arguments}``, e.g. :data:`BEYOND_PAPER` (likelihood phase and cross-validated
        ``sigma2``, the core's options beyond the paper).
    model_kwargs : dict, optional
        Further keyword arguments of :class:`interprim.InteractionPrimitive` for every
        variant.
    seed : int
        Seed of the fold permutations.
    data_path : str or Path, optional
        The Character Trajectories ``.mat`` file (default from the data folder).
    figures : bool
        Draw figures (only with ``out_dir``).
    progress : bool
        Show a progress bar.

    Returns
    -------
    dict
        ``{"config": ..., "percents": [...], "methods": ["ip_forcing", "ip_position",
        "ip_position_true_phase", "prior_mean", "nearest_neighbour"],
        "letters": {letter: {method: {"rmse": [...], "rmse_unseen": [...]}, "phase_error": [...],
        "n": int}}, "lasa": {...same per shape...}, "overall": {"letters": {method: {"rmse":
        [...], "rmse_unseen": [...]}}, "lasa": {...}}, "seconds": float}``; every list has one
        entry per percentage (means over held-out samples).
    """
    import interprim as ip

    t_start = time.perf_counter()
    percents = [int(p) for p in percents]
    if not percents or any(not 0 < p < 100 for p in percents):
        raise ValueError(f"percents must be between 0 and 100 (exclusive), got {percents}")
    kwargs = dict(model_kwargs or {})
    rng = np.random.default_rng(seed)
    observations = list(observations)
    if not observations or any(o not in ("forcing", "position") for o in observations):
        raise ValueError(f"observations must be a non-empty list of 'forcing'/'position', got {observations}")
    # the paper's method per observation model: DTW phase, sigma2 from the fit residual
    variants = {f"ip_{o}": {"sigma2": "residual", **kwargs, "observation": o, "phase_method": "dtw"}
                for o in observations}
    for name, kw in (extra_variants or {}).items():
        if name in variants or name in ("prior_mean", "nearest_neighbour"):
            raise ValueError(f"extra_variants: the name {name!r} is already used")
        variants[str(name)] = {**kwargs, **dict(kw)}
    ip_methods = list(variants)
    oracle = f"ip_{observations[-1]}_true_phase" if true_phase else None
    oracle_of = f"ip_{observations[-1]}"
    methods = tuple(ip_methods + ([oracle] if oracle else []) + ["prior_mean", "nearest_neighbour"])
    shown = ("ip_defaults" if "ip_defaults" in variants
             else f"ip_{'position' if 'position' in observations else observations[0]}")
    items = _load_items(letters, max_per_letter, tuple(lasa_shapes or ()), lasa_subsample, data_path)
    s_grid = np.linspace(0.0, 1.0, n_points)

    folds_of = {it.name: _folds(len(it.demos), n_folds if it.kind == "letter" else None, rng) for it in items}
    total = sum(len(f) for f in folds_of.values())
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=total, desc="handwriting folds", unit="fold", leave=False)
    per_item = {}
    examples: dict = {}
    for it in items:
        D = it.demos[0].shape[1]
        err: dict[str, dict[str, list[list]]] = {
            m: {"rmse": [[] for _ in percents], "rmse_unseen": [[] for _ in percents]} for m in methods}
        phase_err: list[list] = [[] for _ in percents]
        for fi, test_idx in enumerate(folds_of[it.name]):
            train = [it.demos[i] for i in range(len(it.demos)) if i not in set(test_idx.tolist())]
            models = {
                m: ip.InteractionPrimitive(observed_dofs=list(range(D)), **{"n_basis": n_basis, **kw}).fit(
                    train, dt=it.dt
                )
                for m, kw in variants.items()
            }
            train_norm = np.stack([time_normalise(y, n_points) for y in train])
            prior = train_norm.mean(axis=0)
            for k, i in enumerate(test_idx):
                y = it.demos[i]
                T = y.shape[0]
                truth = time_normalise(y, n_points)
                for pi, p in enumerate(percents):
                    t_obs = observed_frames(T, p / 100.0)
                    prefix = y[:t_obs]
                    preds = {m: models[m].predict(prefix) for m in ip_methods}
                    ests = {m: np.asarray(pr.trajectory(n_points)) for m, pr in preds.items()}
                    if oracle:
                        ests[oracle] = np.asarray(
                            models[oracle_of].predict(prefix, phase=t_obs / T).trajectory(n_points)
                        )
                    pred = preds[shown]
                    costs = [open_end_dtw(prefix, r)[0] for r in train]
                    nn = train_norm[int(np.argmin(costs))]
                    unseen = s_grid > (t_obs - 1) / (T - 1)
                    ests["prior_mean"] = prior
                    ests["nearest_neighbour"] = nn
                    for m, est in ests.items():
                        err[m]["rmse"][pi].append(_rmse(est, truth))
                        err[m]["rmse_unseen"][pi].append(_rmse(est, truth, unseen))
                    phase_err[pi].append(abs(float(pred.phase) - t_obs / T))
                    if fi == 0 and k == 0:
                        ex = examples.setdefault((it.kind, it.name), {"train": train, "truth": y, "by_p": {}})
                        ex["by_p"][p] = {
                            "prefix": prefix,
                            "traj": ests[shown],
                            "samples": np.asarray(pred.samples(8, n_points, random_state=seed)),
                            "phase": float(pred.phase),
                        }
            if bar is not None:
                bar.update(1)
        per_item[(it.kind, it.name)] = {
            "n": len(it.demos),
            "units": it.units,
            **{m: {key: [float(np.nanmean(v)) for v in err[m][key]] for key in err[m]} for m in methods},
            "phase_error": [float(np.mean(v)) for v in phase_err],
            "_raw": err,
        }
    if bar is not None:
        bar.close()

    def overall(kind):
        sel = [v for (k, _), v in per_item.items() if k == kind]
        if not sel:
            return {}
        out = {}
        for m in methods:
            out[m] = {}
            for key in ("rmse", "rmse_unseen"):
                # mean over all held-out samples of all letters/shapes (each sample weighs the same)
                out[m][key] = [
                    float(np.nanmean(np.concatenate([np.asarray(v["_raw"][m][key][pi]) for v in sel])))
                    for pi in range(len(percents))
                ]
        out["phase_error"] = [float(np.mean([v["phase_error"][pi] for v in sel])) for pi in range(len(percents))]
        out["n_items"] = len(sel)
        out["n_samples"] = int(sum(v["n"] for v in sel))
        return out

    results = {
        "config": {
            "figure_method": shown,
            "letters": "".join(n for (k, n) in per_item if k == "letter"),
            "max_per_letter": max_per_letter,
            "n_folds": n_folds,
            "lasa_shapes": [n for (k, n) in per_item if k == "lasa"],
            "lasa_subsample": lasa_subsample,
            "n_basis": n_basis,
            "n_points": n_points,
            "model_kwargs": kwargs,
            "variants": {m: {k: v for k, v in kw.items()} for m, kw in variants.items()},
            "seed": seed,
            "error": "RMS Euclidean distance over the normalised-time grid (rmse: whole movement; "
            "rmse_unseen: after the observed fraction)",
        },
        "percents": percents,
        "methods": list(methods),
        "letters": {n: _public(v) for (k, n), v in per_item.items() if k == "letter"},
        "lasa": {n: _public(v) for (k, n), v in per_item.items() if k == "lasa"},
        "overall": {"letters": overall("letter"), "lasa": overall("lasa")},
    }
    results["seconds"] = round(time.perf_counter() - t_start, 2)
    if out_dir is not None:
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        if figures:
            results["figures"] = _figures(out, examples, results)
        write_report(out, results)
    return results


def _public(v):
    return {k: val for k, val in v.items() if not k.startswith("_")}


# ----------------------------------------------------------------------------- output
def _figures(out: Path, examples, results):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    written = []
    for kind, fname, prefer in (
        ("letter", "handwriting_letters.png", _FIG_LETTERS),
        ("lasa", "handwriting_lasa.png", DEFAULT_LASA_SHAPES),
    ):
        names = [n for (k, n) in examples if k == kind]
        if not names:
            continue
        shown = [n for n in prefer if n in names] or names
        shown = shown[:6]
        cols = [p for p in _FIG_PERCENTS if p in results["percents"]] or results["percents"][:4]
        fig, axes = plt.subplots(len(shown), len(cols), figsize=(2.2 * len(cols), 2.2 * len(shown)), squeeze=False)
        for r, name in enumerate(shown):
            ex = examples[(kind, name)]
            for c, p in enumerate(cols):
                ax = axes[r, c]
                for y in ex["train"]:
                    ax.plot(y[:, 0], y[:, 1], color="0.75", lw=0.6)
                ax.plot(ex["truth"][:, 0], ex["truth"][:, 1], color="k", lw=0.6, ls=":")
                e = ex["by_p"][p]
                for smp in e["samples"]:
                    ax.plot(smp[:, 0], smp[:, 1], color="tab:red", lw=0.5, alpha=0.25)
                ax.plot(e["traj"][:, 0], e["traj"][:, 1], color="tab:red", lw=1.6)
                ax.plot(e["prefix"][:, 0], e["prefix"][:, 1], color="k", lw=2.2)
                ax.set_xticks([])
                ax.set_yticks([])
                pts = np.vstack(list(ex["train"]) + [ex["truth"]])
                lo, hi = pts.min(axis=0), pts.max(axis=0)
                pad = 0.15 * (hi - lo).max()
                ax.set_xlim(lo[0] - pad, hi[0] + pad)
                ax.set_ylim(lo[1] - pad, hi[1] + pad)
                ax.set_aspect("equal", adjustable="datalim")
                if r == 0:
                    ax.set_title(f"{p}% observed", fontsize=9)
                if c == 0:
                    ax.set_ylabel(name, fontsize=10)
        fig.suptitle(
            f"Completion ({results['config']['figure_method']}): observed (black), prediction "
            "(red: mean and samples), demonstrations (grey), hidden truth (dotted)",
            fontsize=8,
        )
        fig.tight_layout()
        fig.savefig(out / fname, dpi=110)
        plt.close(fig)
        written.append(fname)

    panels = [k for k in ("letters", "lasa") if results["overall"].get(k)]
    if panels:
        fig, axes = plt.subplots(1, len(panels), figsize=(4.6 * len(panels), 3.4), squeeze=False)
        style = {
            "ip_forcing": ("IP, forcing obs. (Eq. 15), DTW phase", "tab:orange", "o-"),
            "ip_position": ("IP, position obs., DTW phase", "tab:red", "o-"),
            "ip_forcing_true_phase": ("IP, forcing obs., true phase (diagnostic)", "tab:orange", "s--"),
            "ip_position_true_phase": ("IP, position obs., true phase (diagnostic)", "tab:red", "s--"),
            "prior_mean": ("prior mean", "0.4", "o-"),
            "nearest_neighbour": ("nearest neighbour (DTW)", "tab:blue", "o-"),
        }
        extra_colors = iter(["tab:green", "tab:purple", "tab:brown", "tab:olive", "tab:cyan"])
        for ax, k in zip(axes[0], panels):
            for m in results["methods"]:
                if m not in style:
                    style[m] = (m, next(extra_colors, "k"), "^-")
                label, color, ls = style[m]
                ax.plot(results["percents"], results["overall"][k][m]["rmse"], ls, color=color, label=label, ms=4)
            unit = "tablet units" if k == "letters" else "LASA units"
            ax.set_title("UCI letters" if k == "letters" else "LASA shapes")
            ax.set_xlabel("% of the sample observed")
            ax.set_ylabel(f"completion RMSE ({unit})")
            ax.grid(alpha=0.3)
            ax.set_yscale("log")
            ax.legend(fontsize=7)
        fig.tight_layout()
        fig.savefig(out / "handwriting_error.png", dpi=110)
        plt.close(fig)
        written.append("handwriting_error.png")
    return written


def _table(res_kind, percents, methods, key="rmse"):
    lines = ["| method | " + " | ".join(f"{p}%" for p in percents) + " |", "|---|" + "---|" * len(percents)]
    for m in methods:
        lines.append(f"| {m} | " + " | ".join(f"{v:.3g}" for v in res_kind[m][key]) + " |")
    return lines


def write_report(out_dir, results) -> None:
    """Write ``results.json`` and a Markdown ``report.md`` for :func:`run_handwriting`'s results."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    (out / "results.json").write_text(json.dumps(results, indent=2))
    P, M = results["percents"], results["methods"]
    cfg = results["config"]
    lines = [
        "# Handwriting completion (paper Fig. 3-4)",
        "",
        f"Single-agent IP per letter/shape, {cfg['n_basis']} basis functions per DoF; phase by DTW. "
        f"Letters `{cfg['letters']}` ({cfg['max_per_letter']} samples each, {cfg['n_folds']}-fold CV); "
        f"LASA shapes {', '.join(cfg['lasa_shapes']) or 'none'} (leave-one-out). Seed {cfg['seed']}. "
        f"Error: {cfg['error']}. Run time {results['seconds']} s.",
        "",
    ]
    for k, title, unit in (("letters", "UCI Character Trajectories", "tablet units"), ("lasa", "LASA", "LASA units")):
        o = results["overall"].get(k)
        if not o:
            continue
        lines += [f"## {title}: whole-movement RMSE ({unit}), mean over {o['n_samples']} held-out samples", ""]
        lines += _table(o, P, M)
        lines += ["", f"Unseen part only ({unit}):", ""]
        lines += _table(o, P, M, "rmse_unseen")
        lines += ["", "Mean |estimated - true phase|: "
                  + ", ".join(f"{p}%: {v:.3f}" for p, v in zip(P, o["phase_error"])), ""]
        per = results[k]
        ipm = [m for m in M if m.startswith("ip_") and not m.endswith("_true_phase")]
        cols = ipm + ["prior_mean", "nearest_neighbour"]
        lines += [f"Per {'letter' if k == 'letters' else 'shape'} (whole-movement RMSE, {' / '.join(cols)}):", ""]
        lines.append("| name | " + " | ".join(f"{p}%" for p in P) + " |")
        lines.append("|---|" + "---|" * len(P))
        for name, v in per.items():
            cells = [" / ".join(f"{v[m]['rmse'][i]:.3g}" for m in cols) for i in range(len(P))]
            lines.append(f"| {name} | " + " | ".join(cells) + " |")
        lines.append("")
    for f in results.get("figures", []):
        lines += [f"![{f}]({f})", ""]
    (out / "report.md").write_text("\n".join(lines))


def summary_lines(results) -> list:
    """A short text table of the overall errors (used by ``interprim handwriting``)."""
    P, M = results["percents"], results["methods"]
    out = []
    for k in ("letters", "lasa"):
        o = results["overall"].get(k)
        if not o:
            continue
        out.append(f"{k}: completion RMSE (whole movement) vs % observed, {o['n_samples']} samples")
        out.append(f"  {'method':<24}" + "".join(f"{p:>8}%" for p in P))
        for m in M:
            out.append(f"  {m:<24}" + "".join(f"{v:>9.3g}" for v in o[m]["rmse"]))
    return out

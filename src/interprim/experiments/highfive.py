"""The simulated high-five experiments of the paper (Sec. IV, Fig. 5-8).

Protocol (fixed seeds everywhere)
---------------------------------
1. Data (:mod:`interprim.sim`): ``n_train`` training interactions with goals outside the
   held-out cells of the goal box, ``n_test`` test interactions with goals inside them
   ("goal positions that were not part of the original training data", Sec. IV), and
   ``n_val`` validation interactions drawn like the training data (another seed).
2. Model: ``InteractionPrimitive(observed_dofs=[0, 1])`` fitted on the training
   demonstrations.  The observation noise ``sigma2`` (Eq. 16) is chosen from a small grid
   by the mean controlled-agent MSE on the validation set (never on the test set).
3. For each test interaction of ``T`` frames and each ``p`` in 10 %, 20 %, ..., 100 %: the
   first ``max(3, round(p T / 100))`` frames of the observed agent are given to
   ``model.predict``; ``pred.trajectory(n_points)`` (normalised time 0..1 over the whole
   movement) is compared with the ground truth resampled to the same normalised grid.
   **MSE** (rad^2) is the mean over grid points and joints, separately for the observed
   agent (its completion) and for the controlled agent (the inferred response).
4. Baselines on the same splits and grid: the **prior mean** (mean of the time-normalised
   training demonstrations; no observation used) and the **nearest neighbour** (the training
   demonstration whose observed-agent part has the smallest open-end DTW cost, Eq. 5-8 with
   squared Euclidean local cost, against the observed prefix; its whole time-normalised
   trajectory is the prediction).  A fourth curve, **IP with known phase**, gives the model
   the true fraction observed instead of the DTW estimate: the gap between the two curves is
   what phase estimation costs.
5. Goals (Fig. 8): forward kinematics of the controlled agent's posterior goal attractor
   ``pred.goal`` (joint space) against the true high-five point, metres.  Baselines: FK of
   the prior-mean final posture and the nearest neighbour's goal.
6. Fig. 6: ``n_samples`` posterior samples of the controlled agent's trajectory (FK to task
   space) after 40 % and 60 % observed; the *goal spread* is the root-mean-square distance of
   the samples' end points from their mean, metres.
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from ..core.preprocessing import time_normalise
from .highfive_common import METHOD_LABELS, METHODS, goal_spread, n_observed
from .highfive_figures import animate, plot_fig6, plot_fig7, plot_fig8, plot_setup

__all__ = [
    "HighFiveConfig",
    "run_highfive",
    "open_end_dtw_prefix_costs",
    "nearest_neighbours",
    "format_summary",
    "DEFAULT_PERCENTS",
]

DEFAULT_PERCENTS = (10, 20, 30, 40, 50, 60, 70, 80, 90, 100)
@dataclass
class HighFiveConfig:
    """Settings of :func:`run_highfive`.

    Attributes
    ----------
    n_train, n_test, n_val : int
        Number of training, test and validation interactions.
    seed : int
        Seed of the data (train ``seed``, test ``seed + 1_000_003``, validation
        ``seed + 2_000_003``) and of the posterior samples.
    n_basis : int
        Basis functions per DoF of the IP.
    sigma2_grid : tuple
        Candidate observation-noise variances (Eq. 16), ``"residual"`` (the fit residual) allowed; the
        one with the lowest validation MSE of the controlled agent is used.
    percents : tuple of int
        Fractions of the observed agent's movement that are observed.
    n_points : int
        Normalised-time grid on which trajectories are compared.
    n_samples : int
        Posterior samples for Fig. 6.
    gif_frames : int
        Frames of the animation (0: no animation).
    n_jobs : int
        Processes for the data generation.
    dt, duration, duration_jitter : float
        Sampling interval and mean duration (s) and relative duration spread of the data.
    """

    n_train: int = 100
    n_test: int = 30
    n_val: int = 20
    seed: int = 0
    n_basis: int = 10
    sigma2_grid: tuple = ("residual", 10.0, 100.0, 1000.0, 10000.0)
    percents: tuple = DEFAULT_PERCENTS
    n_points: int = 100
    n_samples: int = 30
    gif_frames: int = 60
    n_jobs: int = 2
    dt: float = 0.01
    duration: float = 1.5
    duration_jitter: float = 0.25
    extra: dict = field(default_factory=dict)

    @classmethod
    def quick(cls, **kw) -> HighFiveConfig:
        """A smaller run for tests and smoke checks (about a quarter of the work)."""
        base: dict = dict(n_train=30, n_test=8, n_val=6, sigma2_grid=(100.0, 1000.0), n_samples=20, gif_frames=16)
        base.update(kw)
        return cls(**base)


# ----------------------------------------------------------------------------- DTW baseline
def open_end_dtw_prefix_costs(query, ref, use_numba: bool = True) -> np.ndarray:
    """Open-end DTW cost of every prefix of ``query`` against ``ref`` (paper Eq. 5-8).

    Parameters
    ----------
    query : ndarray, shape (M, D)
        The observed movement.
    ref : ndarray, shape (N, D)
        A complete reference movement.
    use_numba : bool
        Use the core's compiled incremental DTW (:class:`interprim.phase.dtw.IncrementalDTW`, default) or the
        core's numpy reference of the accumulated cost (``interprim.phase.dtw.accumulate_np``).

    Returns
    -------
    costs : ndarray, shape (M,)
        ``costs[k - 1] = min_n D(n, k)``: the cost of matching the first ``k``
        query frames to the best-matching prefix of ``ref`` (squared Euclidean
        local cost).  One accumulated-cost matrix gives every prefix.
    """
    q = np.ascontiguousarray(query, dtype=np.float64)
    r = np.ascontiguousarray(ref, dtype=np.float64)
    out = np.empty(q.shape[0])
    if use_numba:  # the core's incremental open-end DTW (compiled): one column per query frame
        from ..phase.dtw import IncrementalDTW

        inc = IncrementalDTW(r)
        for m in range(q.shape[0]):
            out[m] = inc.update(q[m], check=False)[1]
        return out
    from ..phase.dtw import accumulate_np

    return accumulate_np(r, q).min(axis=1)  # Eq. 8: open end over the reference, for every prefix


def nearest_neighbours(query, refs, prefix_lengths) -> np.ndarray:
    """Index of the reference with the smallest open-end DTW cost for each prefix length.

    Parameters
    ----------
    query : ndarray, shape (M, D)
    refs : list of ndarray, shape (N_j, D)
    prefix_lengths : sequence of int
        Numbers of observed frames ``k`` (1..M).

    Returns
    -------
    idx : ndarray of int, shape (len(prefix_lengths),)
    """
    ks = np.asarray(prefix_lengths, dtype=int)
    costs = np.stack([open_end_dtw_prefix_costs(query, r) for r in refs])  # (J, M)
    return np.argmin(costs[:, ks - 1], axis=0)


# ----------------------------------------------------------------------------- helpers
def _fit(train, n_basis, sigma2, **kw):
    """The paper's model (forcing-value observation, Eq. 15; open-end DTW phase, Eq. 5-9) unless ``kw`` overrides it."""
    import interprim as ip

    kw.setdefault("observation", "forcing")
    kw.setdefault("phase_method", "dtw")
    return ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=n_basis, sigma2=sigma2, **kw).fit(
        train.demos, dt=train.dt)


def _fit_optional(train, cfg, sigma2, log):
    """The variants beyond the paper, when the installed core/extras provide them (else ``None``).

    - ``ip_likelihood``: the same IP with ``phase_method="likelihood"`` (phase by the marginal
      likelihood of the observation instead of DTW), same ``sigma2``.
    - ``ip_default``: the library's defaults (conditioning on positions, ``sigma2`` and shrinkage
      chosen by cross-validation on the training demonstrations, no validation set needed).
    - ``promp``: :class:`interprim.models.promp.InteractionProMP` (needs the ``bench`` extra).
    """
    import interprim as ip

    extra = {}
    extra["ip_default"] = ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=cfg.n_basis).fit(
        train.demos, dt=train.dt)
    try:
        extra["ip_likelihood"] = _fit(train, cfg.n_basis, sigma2, phase_method="likelihood")
    except (TypeError, ValueError) as exc:  # a core without likelihood phase estimation
        log(f"(skipping the likelihood-phase IP: {exc})")
    try:
        from ..models.promp import InteractionProMP

        extra["promp"] = InteractionProMP(observed_dofs=[0, 1]).fit(train.demos, dt=train.dt)
    except Exception as exc:  # ImportError without the bench extra, or an incompatible peer version
        log(f"(skipping the Interaction ProMP peer baseline: {type(exc).__name__}: {exc})")
    return extra


def _predict(model, partial, phase=None):
    if phase is None:
        return model.predict(partial)
    try:
        return model.predict(partial, phase=phase)
    except TypeError:  # a core without the oracle-phase option
        return None


def _select_sigma2(train, val, cfg, progress):
    """Fit one model per candidate ``sigma2``; pick the lowest mean validation MSE of the controlled agent."""
    from tqdm.auto import tqdm

    gts = [time_normalise(d, cfg.n_points) for d in val.demos]
    scores = {}
    models = {}
    for s2 in tqdm(cfg.sigma2_grid, desc="selecting sigma2 (validation)", disable=not progress, leave=False):
        model = _fit(train, cfg.n_basis, s2)
        errs = []
        for d, gt in zip(val.demos, gts):
            for p in (20, 40, 60, 80, 100):
                pred = model.predict(d[: n_observed(len(d), p), :2])
                errs.append(np.mean((pred.trajectory(cfg.n_points)[:, 2:] - gt[:, 2:]) ** 2))
        scores[str(s2)] = float(np.mean(errs))
        models[str(s2)] = model
    best = min(scores, key=scores.get)
    return models[best], best, scores


# ----------------------------------------------------------------------------- evaluation
def evaluate(model, train, test, cfg, progress=True, extra_models=None) -> dict:
    """The "% observed" sweep of Fig. 7/8 on the test interactions (see the module docstring).

    ``extra_models`` maps method names (``"ip_likelihood"``, ``"promp"``) to fitted models
    whose ``predict(partial)`` returns an object with ``trajectory(n)`` (and ``goal`` for IPs).

    Returns
    -------
    dict
        ``mse_obs[method]`` and ``mse_ctrl[method]``: arrays ``(n_test, n_percents)`` in rad^2;
        ``goal_err[method]``: ``(n_test, n_percents)`` metres; ``pred_goals[method]``:
        ``(n_test, n_percents, 2)``; ``phase_est``/``phase_true``: ``(n_test, n_percents)``.
    """
    from tqdm.auto import tqdm

    P = list(cfg.percents)
    n_te, n_p = len(test), len(P)
    ca = test.controlled_arm
    train_norm = np.stack([time_normalise(d, cfg.n_points) for d in train.demos])  # (J, n, 5)
    prior = train_norm.mean(axis=0)
    train_goal_pts = ca.hand(np.stack([d[-1, 2:] for d in train.demos]))
    prior_goal = ca.hand(prior[-1, 2:])
    train_obs = [d[:, :2] for d in train.demos]

    out: dict = {
        "mse_obs": {m: np.full((n_te, n_p), np.nan) for m in METHODS},
        "mse_ctrl": {m: np.full((n_te, n_p), np.nan) for m in METHODS},
        "goal_err": {m: np.full((n_te, n_p), np.nan) for m in METHODS},
        "pred_goals": {m: np.full((n_te, n_p, 2), np.nan) for m in METHODS},
        "phase_est": np.full((n_te, n_p), np.nan),
        "phase_true": np.full((n_te, n_p), np.nan),
        "nn_index": np.zeros((n_te, n_p), dtype=int),
    }
    for i in tqdm(range(n_te), desc="evaluating % observed", disable=not progress, leave=False):
        d = test.demos[i]
        T = len(d)
        gt = time_normalise(d, cfg.n_points)
        ks = [n_observed(T, p) for p in P]
        nn = nearest_neighbours(d[:, :2], train_obs, ks)
        out["nn_index"][i] = nn
        for j, k in enumerate(ks):
            partial = d[:k, :2]
            true_phase = (k - 1) / (T - 1)
            preds = {}
            pred = _predict(model, partial)
            preds["ip"] = (pred.trajectory(cfg.n_points), ca.hand(pred.goal[2:]))
            out["phase_est"][i, j] = pred.phase
            out["phase_true"][i, j] = true_phase
            pk = _predict(model, partial, phase=max(true_phase, 1e-6))
            if pk is not None:
                preds["ip_known_phase"] = (pk.trajectory(cfg.n_points), ca.hand(pk.goal[2:]))
            for name, em in (extra_models or {}).items():
                pe = em.predict(partial)
                traj_e = pe.trajectory(cfg.n_points)
                goal_e = ca.hand(pe.goal[2:]) if hasattr(pe, "goal") else ca.hand(traj_e[-1, 2:])
                preds[name] = (traj_e, goal_e)
            preds["prior"] = (prior, prior_goal)
            preds["nn"] = (train_norm[nn[j]], train_goal_pts[nn[j]])
            for m, (traj, goal_pt) in preds.items():
                out["mse_obs"][m][i, j] = np.mean((traj[:, :2] - gt[:, :2]) ** 2)
                out["mse_ctrl"][m][i, j] = np.mean((traj[:, 2:] - gt[:, 2:]) ** 2)
                out["pred_goals"][m][i, j] = goal_pt
                out["goal_err"][m][i, j] = np.linalg.norm(goal_pt - test.goals[i])
    return out


def _summary_stats(a):
    """Mean, std, median, 25th and 75th percentile over test interactions (axis 0), as lists."""
    if np.all(np.isnan(a)):
        return None
    return {
        "mean": np.nanmean(a, axis=0).tolist(),
        "std": np.nanstd(a, axis=0).tolist(),
        "median": np.nanmedian(a, axis=0).tolist(),
        "q25": np.nanpercentile(a, 25, axis=0).tolist(),
        "q75": np.nanpercentile(a, 75, axis=0).tolist(),
    }


# ----------------------------------------------------------------------------- main entry
def run_highfive(out_dir="interprim-demo", config: HighFiveConfig | None = None, progress: bool = True,
                 log=print) -> dict:
    """Run the whole high-five experiment: data, model, Fig. 5-8, animation, report.

    Parameters
    ----------
    out_dir : str or Path
        Output folder (created).  Written: ``fig5_setup.png``, ``fig6_samples.png``,
        ``fig7_mse.png``, ``fig8_goals.png``, ``highfive.gif`` (unless
        ``gif_frames == 0``), ``results.json``, ``report.md``.
    config : HighFiveConfig, optional
    progress : bool
        Show tqdm progress bars.
    log : callable
        Where progress messages go (``print`` by default; ``None`` silences them).

    Returns
    -------
    dict
        The content of ``results.json``.
    """
    import matplotlib

    matplotlib.use("Agg", force=True)

    from ..core.blas import single_thread

    with single_thread():  # small matrices: one BLAS thread is fastest
        return _run_highfive(out_dir, config, progress, log)


def _run_highfive(out_dir, config, progress, log):
    from ..sim import generate_highfive, highfive_split

    cfg = config or HighFiveConfig()
    log = log or (lambda *a, **k: None)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    timing = {}
    t_all = time.perf_counter()

    t0 = time.perf_counter()
    gen_kw = dict(dt=cfg.dt, duration=cfg.duration, duration_jitter=cfg.duration_jitter, progress=progress,
                  n_jobs=cfg.n_jobs)
    train, test = highfive_split(cfg.n_train, cfg.n_test, seed=cfg.seed, **gen_kw)
    val = generate_highfive(cfg.n_val, seed=cfg.seed + 2_000_003, region="train", **gen_kw)
    timing["data_s"] = time.perf_counter() - t0
    log(f"data: {cfg.n_train} train / {cfg.n_test} test / {cfg.n_val} validation interactions "
        f"in {timing['data_s']:.1f} s "
        f"(max hand error {1000 * max(train.hand_errors.max(), test.hand_errors.max()):.2g} mm)")

    t0 = time.perf_counter()
    model, sigma2, scores = _select_sigma2(train, val, cfg, progress)
    timing["model_s"] = time.perf_counter() - t0
    log(f"model: n_basis={cfg.n_basis}, sigma2={sigma2} (validation MSE per candidate: "
        + ", ".join(f"{k}: {v:.4f}" for k, v in scores.items()) + ")")

    t0 = time.perf_counter()
    extra = _fit_optional(train, cfg, sigma2, log)
    ev = evaluate(model, train, test, cfg, progress, extra_models=extra)
    timing["evaluation_s"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    files = {}
    plot_setup(train, test, out / "fig5_setup.png")
    files["fig5"] = "fig5_setup.png"
    # Fig. 6 example: the first test interaction (no cherry picking); spreads also over all test interactions
    ex = 0
    spreads_ex = plot_fig6(model, test, ex, cfg, out / "fig6_samples.png")
    files["fig6"] = "fig6_samples.png"
    spreads_all = {40: [], 60: []}
    for i, d in enumerate(test.demos):
        for p in (40, 60):
            pred = model.predict(d[: n_observed(len(d), p), :2])
            S = pred.samples(cfg.n_samples, cfg.n_points, random_state=cfg.seed + i)
            spreads_all[p].append(goal_spread(S[:, :, 2:], test.controlled_arm)[0])
    plot_fig7(ev, cfg, out / "fig7_mse.png")
    files["fig7"] = "fig7_mse.png"
    p8 = 60 if 60 in cfg.percents else cfg.percents[len(cfg.percents) // 2]
    plot_fig8(ev, test, cfg, out / "fig8_goals.png", percent=p8)
    files["fig8"] = "fig8_goals.png"
    timing["figures_s"] = time.perf_counter() - t0
    anim = None
    if cfg.gif_frames > 0:  # the library's defaults beside the paper's IP on the Fig. 6 example
        t0 = time.perf_counter()
        anim = animate({"default": extra["ip_default"], "paper": model}, test, ex, cfg, out / "highfive.gif")
        files["animation"] = "highfive.gif"
        timing["animation_s"] = time.perf_counter() - t0
    timing["total_s"] = time.perf_counter() - t_all

    j8 = list(cfg.percents).index(p8)
    phase_err = np.abs(ev["phase_est"] - ev["phase_true"])
    results = {
        "paper": "Ben Amor et al., Interaction Primitives for Human-Robot Cooperation Tasks, ICRA 2014, Sec. IV",
        "config": {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(cfg).items()},
        "data": {
            "n_train": len(train), "n_test": len(test), "n_val": len(val), "dt": train.dt,
            "duration_range_s": [float(min(train.durations.min(), test.durations.min())),
                                 float(max(train.durations.max(), test.durations.max()))],
            "max_hand_error_m": float(max(train.hand_errors.max(), test.hand_errors.max(), val.hand_errors.max())),
            "test_goals_in_heldout_region": True,
        },
        "model": {"n_basis": cfg.n_basis, "sigma2": sigma2, "sigma2_validation_mse_ctrl": scores,
                  "observed_dofs": [0, 1]},
        "percents": list(cfg.percents),
        "units": {"mse": "rad^2 (mean over a 100-point normalised-time grid and the agent's joints)",
                  "distance": "m"},
        "fig7": {
            "observed": {m: _summary_stats(ev["mse_obs"][m]) for m in METHODS},
            "controlled": {m: _summary_stats(ev["mse_ctrl"][m]) for m in METHODS},
        },
        "phase": {"mean_abs_error": np.mean(phase_err, axis=0).tolist(),
                  "mean_estimate": np.mean(ev["phase_est"], axis=0).tolist(),
                  "mean_true": np.mean(ev["phase_true"], axis=0).tolist()},
        "goal_distance_m": {m: _summary_stats(ev["goal_err"][m]) for m in METHODS},
        "fig8": {
            "percent": p8,
            # a method that did not run (the optional ProMP baseline skipped) has no value: None, not a warning
            "mean_distance_m": {m: (float(np.nanmean(ev["goal_err"][m][:, j8]))
                                    if np.isfinite(ev["goal_err"][m][:, j8]).any() else None) for m in METHODS},
            "true_goals": test.goals.tolist(),
            "predicted_goals": ev["pred_goals"]["ip"][:, j8].tolist(),
        },
        "fig6": {
            "example_test_index": ex,
            "percents": [40, 60],
            "n_samples": cfg.n_samples,
            "goal_spread_m_example": [float(s) for s in spreads_ex],
            "goal_spread_m_mean_over_test": [float(np.mean(spreads_all[40])), float(np.mean(spreads_all[60]))],
            "fraction_of_test_where_spread_shrinks_40_to_60": float(
                np.mean(np.array(spreads_all[60]) < np.array(spreads_all[40]))),
        },
        "animation": anim,
        "timing_s": timing,
        "files": files,
    }
    with open(out / "results.json", "w") as fh:
        json.dump(_jsonable(results), fh, indent=1)
    (out / "report.md").write_text(write_report(results))
    files["results"] = "results.json"
    files["report"] = "report.md"
    return results


def _jsonable(x):
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, (np.floating, float)):
        return None if not math.isfinite(float(x)) else float(x)
    if isinstance(x, (np.integer,)):
        return int(x)
    return x


_SUMMARY_METHODS = ("ip", "ip_likelihood", "ip_default", "prior", "nn")


def _row(results, p):
    j = results["percents"].index(p)
    r = []
    for agent in ("observed", "controlled"):
        for m in _SUMMARY_METHODS:
            s = results["fig7"][agent].get(m)
            r.append(s["mean"][j] if s else float("nan"))
    return r


def format_summary(results) -> str:
    """A short plain-text table of the main numbers (printed by ``interprim demo``)."""
    P = [p for p in (20, 40, 60, 80, 100) if p in results["percents"]]
    head = f"{'IP':>7} {'IP-lik':>7} {'IP-def':>7} {'prior':>7} {'NN':>7}"
    lines = [
        "MSE of joint angles [rad^2], mean over held-out interactions "
        "(IP: paper's DTW phase; IP-lik: likelihood phase; IP-def: library defaults; NN: nearest neighbour)",
        f"{'% seen':>6} | {'observed agent':^39} | {'controlled agent':^39}",
        f"{'':>6} | {head} | {head}",
    ]
    for p in P:
        r = _row(results, p)
        lines.append(f"{p:>6} | " + " ".join(f"{x:7.4f}" for x in r[:5]) + " | " + " ".join(f"{x:7.4f}" for x in r[5:]))
    f8 = results["fig8"]
    md = f8["mean_distance_m"]

    def cm(v):
        return "n/a" if v is None or (isinstance(v, float) and math.isnan(v)) else f"{100 * v:.1f} cm"

    lines.append(
        f"Fig. 8: mean goal distance at {f8['percent']} % seen: IP {cm(md['ip'])}, "
        f"IP-lik {cm(md.get('ip_likelihood'))}, "
        f"IP-def {cm(md.get('ip_default'))}, "
        f"prior {cm(md['prior'])}, NN {cm(md['nn'])}"
    )
    f6 = results["fig6"]
    lines.append(
        "Fig. 6: goal spread of posterior samples (mean over test) at 40 % / 60 % seen: "
        f"{100 * f6['goal_spread_m_mean_over_test'][0]:.1f} cm / {100 * f6['goal_spread_m_mean_over_test'][1]:.1f} cm"
    )
    a = results.get("animation")
    if a:
        lines.append(f"Animation (test interaction {a['test_index']}, 100 % seen): " + "; ".join(
            f"{a[k]['label'].split(' (')[0]} estimated phase {a[k]['phase']:.2f}, robot hand "
            f"{100 * a[k]['distance_m']:.1f} cm from the high-five point" for k in ("default", "paper") if k in a))
    return "\n".join(lines)


def write_report(results) -> str:
    """``report.md``: the numbers of ``results.json`` as tables, with the figures."""
    P = results["percents"]
    d = results["data"]
    m = results["model"]
    t = results["timing_s"]
    L = [
        "# Simulated high-five (Ben Amor et al., ICRA 2014, Sec. IV, Fig. 5-8)",
        "",
        f"- Data: {d['n_train']} training, {d['n_test']} test and {d['n_val']} validation interactions synthesised "
        f"by optimal control (minimum squared joint accelerations + attractor cost, hand exactly at the goal: "
        f"max error {1000 * d['max_hand_error_m']:.2g} mm); durations {d['duration_range_s'][0]:.2f}-"
        f"{d['duration_range_s'][1]:.2f} s at dt = {d['dt']} s.  Test goals lie in held-out cells of the goal box "
        "that contain no training goal.",
        f"- Model: `InteractionPrimitive(observed_dofs=[0, 1], n_basis={m['n_basis']}, sigma2={m['sigma2']})`; "
        "sigma2 chosen on the validation set (controlled-agent MSE: "
        + ", ".join(f"{k}: {v:.4f}" for k, v in m["sigma2_validation_mse_ctrl"].items()) + ").",
        "- Protocol: observe the first p % of the observed agent's frames, predict, compare "
        "`pred.trajectory(100)` with the time-normalised ground truth (MSE in rad^2, mean over grid and joints). "
        "Baselines: prior mean (mean time-normalised training demonstration) and nearest neighbour "
        "(open-end DTW on the observed prefix). *IP (known phase)* replaces the DTW phase estimate by the "
        "true fraction observed.",
        "",
        "![setup](fig5_setup.png)",
        "",
        "## Fig. 7: MSE versus % observed",
        "",
    ]
    for agent in ("observed", "controlled"):
        L.append(f"**{agent} agent** (mean ± std over test interactions, rad^2)")
        L.append("")
        hdr = "| method | " + " | ".join(f"{p} %" for p in P) + " |"
        L += [hdr, "|---|" + "---|" * len(P)]
        for meth in METHODS:
            s = results["fig7"][agent][meth]
            if not s:
                continue
            cells = " | ".join(f"{a:.4f} ± {b:.4f}" for a, b in zip(s["mean"], s["std"]))
            L.append(f"| {METHOD_LABELS[meth]} | {cells} |")
        L.append("")
    L += ["![fig7](fig7_mse.png)", "", "## Phase estimation (DTW)", "",
          "| % seen | " + " | ".join(str(p) for p in P) + " |", "|---|" + "---|" * len(P),
          "| mean estimated phase | " + " | ".join(f"{x:.3f}" for x in results["phase"]["mean_estimate"]) + " |",
          "| mean true phase | " + " | ".join(f"{x:.3f}" for x in results["phase"]["mean_true"]) + " |",
          "| mean abs. error | " + " | ".join(f"{x:.3f}" for x in results["phase"]["mean_abs_error"]) + " |", ""]
    f8 = results["fig8"]
    L += [f"## Fig. 8: predicted vs true high-five points at {f8['percent']} % observed", "",
          "| method | mean distance [cm] |", "|---|---|"]
    for meth in METHODS:
        v = f8["mean_distance_m"][meth]
        if v is not None and not (isinstance(v, float) and math.isnan(v)):
            L.append(f"| {METHOD_LABELS[meth]} | {100 * v:.1f} |")
    L += ["", "Goal distance (cm, mean over test) versus % observed:", "",
          "| method | " + " | ".join(f"{p} %" for p in P) + " |", "|---|" + "---|" * len(P)]
    for meth in METHODS:
        s = results["goal_distance_m"][meth]
        if s:
            L.append(f"| {METHOD_LABELS[meth]} | " + " | ".join(f"{100 * x:.1f}" for x in s["mean"]) + " |")
    f6 = results["fig6"]
    L += ["", "![fig8](fig8_goals.png)", "", "## Fig. 6: posterior samples after 40 % and 60 % observed", "",
          f"Goal spread (RMS distance of the {f6['n_samples']} sampled end points from their mean): example "
          f"(test interaction {f6['example_test_index']}) {100 * f6['goal_spread_m_example'][0]:.1f} cm at 40 %, "
          f"{100 * f6['goal_spread_m_example'][1]:.1f} cm at 60 %; mean over all test interactions "
          f"{100 * f6['goal_spread_m_mean_over_test'][0]:.1f} cm and "
          f"{100 * f6['goal_spread_m_mean_over_test'][1]:.1f} cm "
          f"(spread shrinks in {100 * f6['fraction_of_test_where_spread_shrinks_40_to_60']:.0f} % "
          "of test interactions).",
          "", "![fig6](fig6_samples.png)", ""]
    if "animation" in results["files"]:
        a = results.get("animation") or {}
        L += ["## The human matters: library defaults beside the paper's IP", "",
              f"Test interaction {a.get('test_index', 0)} (the Fig. 6 example), predicted from the frames seen so far; "
              "after the human's last frame the robot completes its predicted response.", ""]
        for key in ("default", "paper"):
            if key in a:
                L.append(f"- {a[key]['label']}: with 100 % seen, estimated phase {a[key]['phase']:.2f} (true 1.00), "
                         f"robot hand {100 * a[key]['distance_m']:.1f} cm from the high-five point "
                         f"({100 * a[key]['distance_at_true_phase_m']:.1f} cm when conditioned at the true phase)")
        L += ["", "![animation](highfive.gif)", ""]
    L += ["## Run time", "", ", ".join(f"{k.replace('_s', '')}: {v:.1f} s" for k, v in t.items()), ""]
    return "\n".join(L)

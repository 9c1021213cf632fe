"""Evaluation protocols in seconds, not in normalised time: real-time prediction, phase, calibration.

The paper's Fig. 7 compares predictions with the truth on a normalised-time grid, which hides every
timing error: a method that predicts the right shape at the wrong speed looks perfect.  A robot needs
the partner's positions *in seconds from now*.  This module measures that, for any estimator with the
small interface of :mod:`interprim.evaluation.baselines` (``fit(demos, dt)``, ``predict(partial)`` returning an
object with ``trajectory(n)``, ``std(n)`` and, when it estimates timing, ``phase`` and ``duration``),
on any set of demonstrations (built-in data or a user's own recordings).

Protocols (per held-out demonstration of ``T`` frames at ``dt``; leave-one-out or k-fold):

* **Real time.** After each observed frame ``k`` (the first ``k`` frames seen, ``k/T`` from ``start`` to
  ``stop``, default 20 ... 90 %), predict the controlled agent's positions at the next frames up to
  ``horizon`` seconds ahead (default 0.25 s), placed in time by the method's own estimate of the phase
  ``s`` (fraction of the movement at frame ``k``) and of the duration ``D``: the position at ``t`` seconds
  after frame ``k`` is the prediction at normalised time ``s + t / D``.  Error: root mean square of the
  point errors over the horizon frames.
* **Phase.** ``|s - (k - 1) / (T - 1)|`` for the method's phase, and for the clock.
* **Calibration.** Over the same horizon frames, both agents: the fraction of true coordinates inside the
  pointwise 90 % predictive band ``mean +- 1.645 std`` (coverage) and RMS error / RMS predicted std
  (1 = calibrated; > 1 over-confident).

Baselines, always on the same splits:

* ``clock``: the mean of the time-normalised training demonstrations, played from the first frame at the
  mean training duration (what a robot without any perception of timing would do);
* ``oracle-duration``: the same mean stretched to the true duration of the held-out demonstration (not
  available online: a floor that shows how much of the error is timing).

A method without a ``duration`` but with a ``phase`` (e.g. nearest neighbour) is placed in time at the
speed implied by its phase (elapsed time / phase); a method with neither (the prior mean) is played by the
clock.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..contract import place_in_time
from ..cv import folds as cv_folds
from ..preprocessing import interp_columns, time_normalise
from .nested import standard_error_ratio
from .protocol import Prefixes, observed_frames
from .sweep import _point_rms

__all__ = ["RealTimeConfig", "mean_demo", "realtime_fold", "whole_movement_fold", "realtime_sweep", "summarise_realtime",
           "default_methods", "verdict", "nested_verdict", "choose_method", "markdown_table",
           "save_report", "folds", "Z90", "MIN_DEMONSTRATIONS", "ALL_METHODS_FROM"]

Z90 = 1.6448536269514722  # two-sided 90 % band of a normal distribution
#: the fewest demonstrations :func:`interprim.assessment.evaluate_demonstrations` takes (every fold trains on at least 2)
MIN_DEMONSTRATIONS = 3
#: from this many demonstrations (leave-one-out), every default method can be fitted on every training fold
ALL_METHODS_FROM = 5


@dataclass(frozen=True)
class RealTimeConfig:
    """Settings of the real-time protocol.

    Parameters
    ----------
    horizon : float
        Seconds ahead that are predicted after each observed frame.
    start, stop : float
        Fractions of the held-out movement between which frames are evaluated.
    stride : int
        Evaluate every ``stride``-th frame in that range (1 = every frame).
    n_grid : int
        Points of the normalised-time grid on which predictions are interpolated.
    point_dim : int
        Columns per point (3 for 3-D positions: errors are Euclidean distances of points), 1 for scalars.
    """

    horizon: float = 0.25
    start: float = 0.2
    stop: float = 0.9
    stride: int = 1
    n_grid: int = 201
    point_dim: int = 1


def mean_duration(demos) -> float:
    """Mean duration of the demonstrations in frames - 1 (the clock's)."""
    return float(np.mean([len(d) - 1 for d in demos]))


def mean_demo(demos, n: int = 201):
    """``(mean (n, D), mean duration in frames - 1)`` of time-normalised demonstrations."""
    Y = np.stack([time_normalise(np.asarray(d, dtype=np.float64), n) for d in demos])
    return Y.mean(axis=0), mean_duration(demos)


def _interp_rows(u, grid, Y):
    """Rows of ``Y`` (on ``grid``) at normalised times ``u`` (clipped to [0, 1])."""
    return interp_columns(np.clip(u, 0.0, 1.0), grid, Y)


def _timing(pred, k, dt, mean_dur_s):
    """``(phase s at frame k, duration in s)`` of a prediction (:func:`interprim.contract.place_in_time`)."""
    return place_in_time(pred, k, dt, mean_dur_s)


def realtime_fold(estimator, train, test, observed_dofs, dt: float, cfg: RealTimeConfig = RealTimeConfig(),
                  name: str = "method", fitted: bool = False, frames=None, trace: bool = False,
                  prefix=None, oracle=None, std: bool = True, references: bool = True) -> list:
    """Fit ``estimator`` on ``train`` (unless ``fitted``) and run the real-time protocol on one held-out demo.

    Returns one record per evaluated frame ``k`` for the method, the clock and the oracle-duration mean:
    ``{"method", "k", "fraction", "phase_true", "phase", "phase_err", "rt_ctrl", "rt_obs", "cov_ctrl",
    "cov_obs", "z_ctrl", "z_obs"}`` (``z_*``: RMS error / RMS std over the horizon; NaN without a std).

    ``frames``: the numbers of frames seen ``k`` to evaluate instead of the protocol's (``cfg.start`` to
    ``cfg.stop``, every ``cfg.stride``-th), e.g. every frame for a figure.  ``trace=True`` adds what the
    numbers were computed from to every record (for figures; not JSON-serialisable): ``"t_ahead"`` (seconds
    after frame ``k``, ``(H,)``), ``"truth"`` (the held-out frames there, ``(H, D)``), ``"mean"`` and ``"std"``
    (the prediction placed in time there, ``(H, D)``; ``std`` None without one).

    ``prefix``: ``prefix(k)`` returns the observed columns of the first ``k`` frames as a robot had them at
    frame ``k`` (:class:`~interprim.evaluation.protocol.Prefixes`; causal prefixes of interpolated recordings);
    default ``test[:k, observed_dofs]``, which is causal only when ``test`` holds the recorded samples.
    ``oracle``: ``(T, D)``, the best possible prediction of ``test`` (synthetic data,
    :class:`~interprim.synthetic.SyntheticTask`); adds ``"oracle"`` records, the floor.

    ``std=False`` skips the method's std (``cov_*`` and ``z_*`` are then NaN, ``"std"`` None) and
    ``references=False`` the clock and oracle-duration records, for a caller that needs only the method's errors
    and placed means (:class:`interprim.auto.CrossValidation`); the method's records are unchanged.

    When the estimator's stream gives exactly what ``predict`` gives (``exact_stream = True``, e.g.
    :class:`~interprim.evaluation.kernel.KernelDemonstrations`, whose stream updates its alignments one frame
    at a time), the frames are fed through one stream instead of predicting every prefix anew, provided every
    evaluated prefix is the start of the longest one (always so for recorded samples; a causal prefix of an
    interpolated recording may differ, and is then predicted anew): the same predictions, cheaper.
    """
    test = np.asarray(test, dtype=np.float64)
    obs = [int(i) for i in observed_dofs]
    ctrl = [i for i in range(test.shape[1]) if i not in set(obs)]
    if not fitted:
        estimator.fit(train, dt=dt)
    grid = np.linspace(0.0, 1.0, cfg.n_grid)
    if references:
        mean, mean_dur = mean_demo(train, cfg.n_grid)
    else:
        mean, mean_dur = None, mean_duration(train)
    mean_dur_s = mean_dur * dt
    T = test.shape[0]
    true_dur_s = (T - 1) * dt
    H = max(1, int(round(cfg.horizon / dt)))
    if frames is None:
        k0 = max(3, int(math.ceil(cfg.start * T)))
        k1 = max(k0, int(math.floor(cfg.stop * T)))
        frames = range(k0, k1 + 1, max(1, int(cfg.stride)))
    frames = [int(k) for k in frames]
    for k in frames:
        if not 1 <= k <= T:
            raise ValueError(f"frames must be numbers of frames seen in 1..{T}, got {k}")
    predict = _prefix_predictions(estimator, test, obs, frames, prefix)
    out = []
    for k in frames:
        idx = np.minimum(np.arange(k, k + H), T - 1)  # frames k .. k+H-1 (0-based), held at the end
        t_ahead = (np.arange(1, H + 1)) * dt  # seconds after frame k-1 (0-based index k-1)
        truth = test[idx]
        phase_true = (k - 1) / (T - 1)
        elapsed = (k - 1) * dt
        pred = predict(k)
        s, dur = _timing(pred, k, dt, mean_dur_s)
        Y = pred.trajectory(cfg.n_grid)
        S = pred.std(cfg.n_grid) if std else None
        rows = {
            name: (s, _interp_rows(s + t_ahead / dur, grid, Y),
                   None if S is None else _interp_rows(s + t_ahead / dur, grid, S)),
        }
        if references:
            rows["clock"] = (min(elapsed / mean_dur_s, 1.0), _interp_rows((elapsed + t_ahead) / mean_dur_s, grid, mean),
                             None)
            rows["oracle-duration"] = (phase_true, _interp_rows((elapsed + t_ahead) / true_dur_s, grid, mean), None)
        if oracle is not None:
            rows["oracle"] = (phase_true, np.asarray(oracle, dtype=np.float64)[idx], None)
        for method, (sm, Yh, Sh) in rows.items():
            err = Yh - truth
            rec = {"method": method, "k": int(k), "fraction": k / T, "phase_true": phase_true, "phase": float(sm),
                   "phase_err": abs(float(sm) - phase_true)}
            for agent, cols in (("ctrl", ctrl), ("obs", obs)):
                if not cols:
                    continue
                e = err[:, cols]
                rec[f"rt_{agent}"] = _point_rms(e, cfg.point_dim)
                if Sh is not None:
                    sd = Sh[:, cols]
                    rec[f"cov_{agent}"] = float(np.mean(np.abs(e) <= Z90 * sd + 1e-12))
                    rec[f"z_{agent}"] = float(np.sqrt(np.mean(e ** 2)) / max(np.sqrt(np.mean(sd ** 2)), 1e-300))
                else:
                    rec[f"cov_{agent}"] = float("nan")
                    rec[f"z_{agent}"] = float("nan")
            if trace:
                rec.update(t_ahead=t_ahead, truth=truth, mean=Yh, std=Sh)
            out.append(rec)
    return out


def _prefix_predictions(estimator, test, obs, frames, prefix):
    """``predict(k)``: the estimator's prediction from the first ``k`` frames (``prefix(k)``, default
    ``test[:k, obs]``) for the increasing ``frames``, through one stream when that gives the same answers
    (see :func:`realtime_fold`)."""
    get = (lambda k: test[:k, obs]) if prefix is None else prefix
    if not (getattr(estimator, "exact_stream", False) and len(frames) > 1
            and all(a < b for a, b in zip(frames, frames[1:]))):
        return lambda k: estimator.predict(get(k))
    last = np.asarray(get(frames[-1]), dtype=np.float64)
    if prefix is not None:  # each prefix computed once, for the check and, if it fails, for predict
        seen = {k: get(k) for k in frames[:-1]}
        if not all(np.array_equal(np.asarray(x, dtype=np.float64), last[:k]) for k, x in seen.items()):
            seen[frames[-1]] = last
            return lambda k: estimator.predict(seen[k])
    stream = estimator.stream()
    fed = [0]  # frames fed to the stream so far

    def predict(k):
        pred = stream.extend(last[fed[0]:k])
        fed[0] = k
        return pred

    return predict


def whole_movement_fold(estimator, test, observed_dofs, fractions=(0.4, 0.6, 0.8), n: int = 100,
                        point_dim: int = 1, name: str = "method", prefix=None, oracle=None) -> list:
    """The paper's Fig. 7 protocol for one held-out demonstration and a fitted ``estimator``: observe the first
    ``p`` of the observed agent, predict the whole movement, RMSE of each agent on a normalised-time grid
    (timing errors hidden by construction: compare with :func:`realtime_fold`).  ``prefix`` as in
    :func:`realtime_fold`; with ``oracle`` (``(T, D)``), ``"oracle"`` records are added too."""
    test = np.asarray(test, dtype=np.float64)
    obs = [int(i) for i in observed_dofs]
    ctrl = [i for i in range(test.shape[1]) if i not in set(obs)]
    truth = time_normalise(test, n)
    T = test.shape[0]
    out = []
    for p in fractions:
        M = observed_frames(T, p)
        rows = [(name, estimator.predict(test[:M, obs] if prefix is None else prefix(M)).trajectory(n))]
        if oracle is not None:
            rows.append(("oracle", time_normalise(np.asarray(oracle, dtype=np.float64), n)))
        for method, Y in rows:
            err = Y - truth
            rec = {"method": method, "fraction": float(p), "wm_obs": _point_rms(err[:, obs], point_dim)}
            if ctrl:
                rec["wm_ctrl"] = _point_rms(err[:, ctrl], point_dim)
            out.append(rec)
    return out


def folds(n: int, k: int | None = None):
    """Held-out index sets (lists of int): leave-one-out (``k`` None or >= n) or ``k`` contiguous folds
    (:func:`interprim.cv.folds`, ``order="contiguous"``)."""
    if k is not None and k < n and k < 2:
        raise ValueError(f"k-fold needs k >= 2, got {k}")
    return [f.tolist() for f in cv_folds(n, k, "contiguous")]


def realtime_sweep(make_estimators, demos, observed_dofs, dt: float, cfg: RealTimeConfig = RealTimeConfig(),
                   k: int | None = None, progress: bool = False, whole_movement=None, oracles=None,
                   test=None, trace: bool = False, std: bool = True, references: bool = True) -> list:
    """Cross-validated real-time protocol for several methods on one set of demonstrations.

    ``make_estimators`` maps a method name to a zero-argument factory of an unfitted estimator.  Each fold
    fits every method on the other demonstrations; clock and oracle rows are added once (from the first
    method's pass).  ``whole_movement``: fractions at which :func:`whole_movement_fold` records (with
    ``"protocol": "whole"``) are added too.  Returns records with ``"demo"`` added.

    ``demos`` may be a :class:`~interprim.datasets.Demonstrations` with raw samples (NuiSI, resampled
    recordings): every prediction then sees a causal prefix (:class:`~interprim.evaluation.protocol.Prefixes`).
    ``oracles``: one ``(T_i, D)`` best possible prediction per demonstration (synthetic data); adds the floor.

    ``test``: evaluate on a fixed hold-out instead of cross-validating: ``demos`` are then the training
    demonstrations (every method is fitted once on all of them) and ``test`` the held-out ones (a
    :class:`~interprim.datasets.Demonstrations` gives causal prefixes); ``oracles`` then belong to ``test``.
    ``trace``: as in :func:`realtime_fold` (the placed predictions with every real-time record); ``std`` and
    ``references`` as there too (``references=False``: no clock and oracle-duration records at all).
    """
    if test is not None:
        train = [np.asarray(d, dtype=np.float64) for d in demos]
        prefixes = test if isinstance(test, Prefixes) else Prefixes(test, observed_dofs)
        demos = train + prefixes.demos
        n_train = len(train)
        prefixes = _Offset(prefixes, n_train)
        sets = [list(range(n_train, len(demos)))]
        oracles = None if oracles is None else [None] * n_train + list(oracles)
    else:
        prefixes = demos if isinstance(demos, Prefixes) else Prefixes(demos, observed_dofs)
        demos = prefixes.demos
        sets = None
    if len(demos) < 3:
        raise ValueError(f"the real-time protocol needs at least 3 demonstrations, got {len(demos)}")
    recs = []
    sets = sets or folds(len(demos), k)
    it = sets
    if progress:
        try:
            from tqdm import tqdm  # the [experiments] extra
        except ImportError:
            tqdm = None
        if tqdm is not None:
            it = tqdm(sets, desc="folds", unit="fold")
    for held in it:
        train = [d for i, d in enumerate(demos) if i not in set(held)]
        for first, (name, factory) in enumerate(make_estimators.items()):
            est = factory().fit(train, dt=dt)
            for j in held:
                pre = (lambda k, j=j: prefixes(j, k))
                orc = None if oracles is None else oracles[j]
                for r in realtime_fold(est, train, demos[j], observed_dofs, dt, cfg, name=name, fitted=True,
                                       prefix=pre, oracle=orc if not first else None, trace=trace, std=std,
                                       references=references and not first):
                    if r["method"] in ("clock", "oracle-duration", "oracle") and first:
                        continue
                    r["demo"] = int(j)
                    recs.append(r)
                if whole_movement:
                    for r in whole_movement_fold(est, demos[j], observed_dofs, whole_movement,
                                                 point_dim=cfg.point_dim, name=name, prefix=pre,
                                                 oracle=orc if not first else None):
                        r["demo"] = int(j)
                        r["protocol"] = "whole"
                        recs.append(r)
    return recs


class _Offset:
    """Prefixes of a hold-out numbered after the training demonstrations."""

    def __init__(self, prefixes, n_train):
        self.prefixes, self.n_train = prefixes, n_train

    def __call__(self, j, k):
        return self.prefixes(j - self.n_train, k)


#: Below this phase error (a fraction of the movement) the clock is exact: no ratio to it is given (equal lengths).
PHASE_ERROR_FLOOR = 1e-6


def summarise_realtime(records) -> dict:
    """Per method: means over all evaluated frames of every metric, and ratios of the real-time error and of
    the phase error to the clock's (means of per-demo ratios would overweight easy demos: ratios of means)."""
    by = {}
    whole = {}
    for r in records:
        if r.get("protocol") == "whole":
            whole.setdefault(r["method"], []).append(r)
        else:
            by.setdefault(r["method"], []).append(r)
    out = {}
    keys = ("phase_err", "rt_ctrl", "rt_obs", "cov_ctrl", "cov_obs", "z_ctrl", "z_obs")
    for m, rs in by.items():
        out[m] = {key: float(np.nanmean([r.get(key, np.nan) for r in rs])) if any(
            np.isfinite(r.get(key, np.nan)) for r in rs) else float("nan") for key in keys}
        out[m]["n"] = len(rs)
    clock = out.get("clock")
    oracle = out.get("oracle-duration")
    for m in out:
        if clock:
            for key in ("rt_ctrl", "rt_obs", "phase_err"):
                if key in clock and clock[key] > 0:
                    out[m][f"{key}_vs_clock"] = out[m][key] / clock[key]
            if clock.get("phase_err", np.nan) <= PHASE_ERROR_FLOOR:  # a ratio to ~0 is a meaningless huge number
                out[m].pop("phase_err_vs_clock", None)
                out[m]["phase_err_vs_clock_why"] = (
                    f"the clock's phase error is {clock['phase_err']:.1g}: the demonstrations last (almost) equally "
                    "long, so elapsed time alone gives the phase and a ratio to it says nothing")
        if oracle and oracle.get("rt_ctrl", 0) > 0:
            out[m]["rt_ctrl_vs_oracle"] = out[m]["rt_ctrl"] / oracle["rt_ctrl"]
    prior = whole.get("prior")
    for m, rs in whole.items():  # whole movement (Fig. 7): mean over demos per fraction, ratio to the prior mean
        w = out.setdefault(m, {})
        for key in ("wm_ctrl", "wm_obs"):
            vals = [r[key] for r in rs if key in r]
            if vals:
                w[key] = float(np.mean(vals))
                if prior and any(key in r for r in prior):
                    w[f"{key}_vs_prior"] = w[key] / float(np.mean([r[key] for r in prior if key in r]))
    floor = out.get("oracle")
    if floor:  # synthetic data: the gap to the best possible prediction
        for m in out:
            for key in ("rt_ctrl", "rt_obs", "wm_ctrl", "wm_obs"):
                if floor.get(key, 0) > 0 and key in out[m]:
                    out[m][f"{key}_vs_floor"] = out[m][key] / floor[key]
    return out


def default_methods(observed_dofs, smoothing_window=None, n_basis: int = 20, phase_method: str | None = None):
    """Factories of the methods compared by default: the library's defaults (``ip``), learned timing + coupling
    (``learned``: :class:`~interprim.learned.LearnedInteraction`), the paper exactly (``ip-paper``: forcing
    observation, DTW phase, ``sigma2="auto"``), the kernel-weighted demonstrations (``kernel``:
    :class:`~interprim.evaluation.kernel.KernelDemonstrations`), nearest neighbour and the prior mean."""
    from .baselines import NearestNeighbour, PriorMean
    from .kernel import KernelDemonstrations
    from ..primitive import InteractionPrimitive

    obs = [int(i) for i in observed_dofs]
    common = dict(observed_dofs=obs, n_basis=n_basis, smoothing_window=smoothing_window)
    extra = {} if phase_method is None else {"phase_method": phase_method}
    from ..learned import LearnedInteraction

    return {
        "ip": lambda: InteractionPrimitive(**common, **extra),
        "learned": lambda: LearnedInteraction(obs),
        "ip-paper": lambda: InteractionPrimitive(**common, observation="forcing", sigma2="auto", phase_method="dtw"),
        "kernel": lambda: KernelDemonstrations(obs),
        "nn": lambda: NearestNeighbour(obs),
        "prior": lambda: PriorMean(obs),
    }


def verdict(summary, method: str = "ip", threshold: float = 0.03) -> str:
    """One plain sentence: does conditioning on the human help the robot's real-time prediction here?

    Compares ``method``'s real-time error of the controlled agent with the clock's (the mean played at the
    mean duration) and the prior mean's; ``threshold`` is the relative gain below which the answer is "no".
    """
    m = summary.get(method)
    if m is None or "rt_ctrl_vs_clock" not in m:
        return f"no verdict: {method!r} or the clock is missing from the results"
    r = m["rt_ctrl_vs_clock"]
    ph = m.get("phase_err_vs_clock", float("nan"))
    timing = (f"its timing is {100 * (1 - ph):.0f} % closer to the truth than the clock's" if ph < 1 - threshold
              else "its timing is no better than the clock's")
    if "phase_err_vs_clock_why" in m:
        timing = f"its timing cannot be compared with the clock's ({m['phase_err_vs_clock_why']})"
    if r <= 1 - threshold:
        return (f"conditioning on the human improves the robot's real-time prediction by {100 * (1 - r):.0f} % "
                f"over the clock (RMSE {m['rt_ctrl']:.4g} vs {summary['clock']['rt_ctrl']:.4g}); {timing}.")
    if r < 1 + threshold:
        return (f"does not help on this data: the model does no better than replaying the mean at the mean "
                f"speed (real-time RMSE {r:.2f}x the clock's); {timing}.")
    return (f"hurts on this data: the model's real-time prediction is {100 * (r - 1):.0f} % worse than replaying "
            f"the mean at the mean speed; {timing}. Use the mean (or more demonstrations).")


def markdown_table(summary) -> str:
    """The summary as a Markdown table (one row per method)."""
    cols = [("rt_ctrl", "real-time RMSE, controlled", 4), ("rt_ctrl_vs_clock", "x clock", 2),
            ("rt_ctrl_vs_oracle", "x oracle-duration", 2), ("phase_err", "phase error", 3),
            ("phase_err_vs_clock", "x clock", 2), ("cov_ctrl", "90 % band coverage, controlled", 2),
            ("cov_obs", "coverage, observed", 2), ("z_ctrl", "RMSE / std, controlled", 2),
            ("z_obs", "RMSE / std, observed", 2), ("wm_ctrl", "whole movement RMSE, controlled", 4),
            ("wm_ctrl_vs_prior", "x prior", 2)]
    lines = ["| method | " + " | ".join(c[1] for c in cols) + " |", "|---" * (len(cols) + 1) + "|"]
    order = [m for m in ("clock", "oracle-duration") if m in summary] + [m for m in summary
                                                                          if m not in ("clock", "oracle-duration")]
    for m in order:
        v = summary[m]
        cells = []
        for key, _, dg in cols:
            x = v.get(key, float("nan"))
            cells.append("—" if not np.isfinite(x) else f"{x:.{dg}f}")
        lines.append(f"| {m} | " + " | ".join(cells) + " |")
    why = next((v["phase_err_vs_clock_why"] for v in summary.values() if "phase_err_vs_clock_why" in v), None)
    if why:
        lines += ["", f"Phase error x clock: not given, {why}."]
    return "\n".join(lines)


def choose_method(make_estimators, demos, observed_dofs, dt: float, cfg=None, k: int = 3,
                  metric: str = "rt_ctrl") -> tuple:
    """The method with the smallest cross-validated error on ``demos`` (training demonstrations only).

    Parameters
    ----------
    make_estimators : dict
        ``{name: factory}`` of the candidate methods (see :func:`~interprim.evaluation.realtime.realtime_sweep`).
    demos : sequence of ndarray, Demonstrations or Prefixes
        The training demonstrations (causal prefixes when their raw samples are known).
    observed_dofs, dt, cfg
        As in :func:`~interprim.evaluation.realtime.realtime_sweep` (``cfg`` default: every 3rd frame).
    k : int
        Inner folds.
    metric : str
        ``"rt_ctrl"`` (real time, the controlled agent) or ``"wm_ctrl"`` (whole movement at 60 %).

    Returns
    -------
    (str, dict)
        The chosen name and ``{name: mean inner error}`` (``inf`` for a method that cannot be fitted on an
        inner training fold, e.g. with too few demonstrations).
    """
    cfg = cfg or RealTimeConfig(stride=3)
    whole = (0.6,) if metric.startswith("wm") else None
    scores = {}
    for name, factory in make_estimators.items():
        try:
            recs = realtime_sweep({name: factory}, demos, observed_dofs, dt, cfg, k=k, whole_movement=whole)
        except ValueError:  # e.g. too few demonstrations in an inner training fold for this method
            scores[name] = float("inf")
            continue
        scores[name] = float(summarise_realtime(recs).get(name, {}).get(metric, np.inf))
    if not np.isfinite(min(scores.values())):
        return next(iter(make_estimators)), scores
    return min(scores, key=lambda m: (scores[m], list(make_estimators).index(m))), scores


BASELINES = ("nn", "prior", "clock")

#: How each method of :func:`default_methods` is fitted outside the evaluation.
FIT_COMMANDS = {
    "auto": "interprim fit {data} --observed {observed} -o model.npz",
    "ip": "interprim fit {data} --observed {observed} --model ip -o model.npz",
    "ip-paper": "interprim fit {data} --observed {observed} --model ip --observation forcing --sigma2 auto "
                "--phase-method dtw -o model.npz",
    "learned": "interprim fit {data} --observed {observed} --model learned -o model.npz",
    "kernel": "interprim fit {data} --observed {observed} --model kernel -o model.npz",
    "nn": "interprim fit {data} --observed {observed} --model nn -o model.npz (replays the nearest demonstration)",
    "prior": "interprim fit {data} --observed {observed} --model prior -o model.npz (replays the mean demonstration)",
}


def nested_verdict(summary, records, method: str = "chosen", threshold: float = 0.03, data: str = "DEMOS",
                   observed: str = "COLS") -> str:
    """The verdict of an evaluation whose choice was made inside the training folds (nested).

    Says which method the inner cross-validation chose (per outer fold), how the chosen model compares with the
    clock and with the mean stretched to the true duration (a floor no online method has), names the best method
    among all rows and says plainly when a baseline beats the chosen model by more than one standard error, and
    gives the command that fits the chosen method.
    """
    m = summary.get(method)
    if m is None or "rt_ctrl_vs_clock" not in m:
        return verdict(summary, next((x for x in ("ip", "learned") if x in summary), "ip"), threshold)
    picks = {}
    for r in records:
        if r["method"] == method and r.get("protocol") != "whole":
            picks.setdefault(r["chosen"], set()).add(r["demo"])
    order = sorted(picks, key=lambda c: -len(picks[c]))
    n_demo = sum(len(v) for v in picks.values())
    chosen = ", ".join(f"{c} ({len(picks[c])} of {n_demo} held-out demonstrations)" for c in order)
    r = m["rt_ctrl_vs_clock"]
    parts = [f"chosen inside the training folds: {chosen}."]
    ro = m.get("rt_ctrl_vs_oracle", float("nan"))
    parts.append(f"Real time: {r:.2f}x the clock's error and {ro:.2f}x the mean stretched to the true duration "
                 f"(a floor that needs the future).")
    online = [x for x in summary if x not in ("oracle-duration", "oracle", method) and "rt_ctrl" in summary[x]]
    best = min(online, key=lambda x: summary[x]["rt_ctrl"]) if online else None
    if best is not None:
        rb, se = standard_error_ratio(records, best if best != "clock" else "clock", method)
        if best in BASELINES and np.isfinite(rb) and rb < 1 - (se if np.isfinite(se) else 0):
            parts.append(f"A baseline beats it: {best} has {rb:.2f}x (± {se:.2f}) the chosen model's real-time "
                         f"error; use {best} on this data.")
        else:
            parts.append(f"Best method: {best} ({summary[best]['rt_ctrl_vs_clock']:.2f}x the clock).")
    if r <= 1 - threshold:
        parts.append(f"Conditioning on the human helps: {100 * (1 - r):.0f} % less real-time error than the clock.")
    elif r < 1 + threshold:
        parts.append("It does not help on this data: no better than the mean at the mean speed.")
    else:
        parts.append(f"It hurts on this data: {100 * (r - 1):.0f} % worse than the mean at the mean speed.")
    w = m.get("wm_ctrl_vs_prior")
    if w is not None and np.isfinite(w):
        parts.append(f"Whole movement: {w:.2f}x the mean demonstration's error.")
    a = summary.get("auto")
    if a is not None and "rt_ctrl_vs_clock" in a:  # what interprim fit makes by default, fitted inside the folds
        ra, se = standard_error_ratio(records, "auto", method)
        parts.append(f"The blend that 'interprim fit' makes by default (auto): {a['rt_ctrl_vs_clock']:.2f}x the clock "
                     f"and {a.get('rt_ctrl_vs_oracle', float('nan')):.2f}x the mean at the true duration in real "
                     f"time ({ra:.2f}x ± {se:.2f} the chosen family's error)"
                     + (f", {a['wm_ctrl_vs_prior']:.2f}x the mean demonstration on the whole movement."
                        if np.isfinite(a.get("wm_ctrl_vs_prior", np.nan)) else "."))
        online = [x for x in summary if x in BASELINES and "rt_ctrl" in summary[x]]
        if online:
            b = min(online, key=lambda x: summary[x]["rt_ctrl"])
            rb, seb = standard_error_ratio(records, b, "auto")
            if np.isfinite(rb) and rb < 1 - (seb if np.isfinite(seb) else 0):
                parts.append(f"A baseline beats the blend: {b} has {rb:.2f}x (± {seb:.2f}) its real-time error.")
    if order and a is not None and "rt_ctrl_vs_clock" in a:
        parts.append("To fit the blend: " + FIT_COMMANDS["auto"].format(data=data, observed=observed)
                     + "; the chosen family alone: "
                     + FIT_COMMANDS.get(order[0], order[0]).format(data=data, observed=observed))
    elif order:
        parts.append("To fit it: " + FIT_COMMANDS.get(order[0], order[0]).format(data=data, observed=observed))
    return " ".join(parts)


def save_report(records, summary, sentence, out_dir, title: str = "", horizon: float = 0.25, notes=(),
                unit: str = "data units") -> list:
    """Write ``realtime.json`` (records + summary), ``report.md`` (table + verdict) and, with matplotlib,
    ``realtime.png`` (real-time error of the controlled agent against the fraction seen, per method).
    ``notes``: lines added to the report (e.g. methods left out); ``unit``: the controlled columns' unit, for the
    figure's y-axis."""
    import json
    from pathlib import Path

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = [out / "realtime.json", out / "report.md"]
    paths[0].write_text(json.dumps({"summary": summary, "verdict": sentence, "records": records,
                                    "notes": list(notes)}, indent=1))
    paths[1].write_text((f"# {title}\n\n" if title else "") + markdown_table(summary) + f"\n\n**Verdict:** {sentence}\n"
                        + "".join(f"\nNote: {n}\n" for n in notes))
    try:
        import matplotlib

        matplotlib.use("Agg", force=False)
        import matplotlib.pyplot as plt
    except ImportError:  # plotting is optional
        return paths
    fig, ax = plt.subplots(figsize=(6, 3.6))
    bins = np.linspace(0.2, 0.9, 8)
    mids = 0.5 * (bins[:-1] + bins[1:])
    curves = {}
    for m in summary:
        rs = [r for r in records if r["method"] == m and "rt_ctrl" in r and r.get("protocol") != "whole"]
        if not rs:
            continue
        f = np.array([r["fraction"] for r in rs])
        e = np.array([r["rt_ctrl"] for r in rs])
        idx = np.clip(np.digitize(f, bins) - 1, 0, len(bins) - 2)
        curves[m] = np.array([e[idx == i].mean() if np.any(idx == i) else np.nan for i in range(len(mids))])
    drawn = []
    for m, y in curves.items():
        # a curve equal (to 0.1 %) to one drawn before (the prior mean is played by the clock) would hide under it:
        # say so in its label and draw it dotted with open markers, so that both stay visible
        same = next((o for o in drawn if np.allclose(y, curves[o], rtol=1e-3, atol=1e-12, equal_nan=True)), None)
        style = dict(marker="o", ms=3, ls="--" if m in ("clock", "oracle-duration") else "-")
        if same is not None:
            style = dict(marker="s", ms=6, mfc="none", ls=":", lw=2.5)
        ax.plot(mids, y, label=m if same is None else f"{m} (= {same})", zorder=3 if same is None else 2, **style)
        drawn.append(m)
    ax.set_xlabel("fraction of the movement seen")
    ax.set_ylabel(f"RMSE over the next {horizon:g} s ({unit})")
    ax.legend(fontsize=7)
    ax.set_title(f"controlled agent: {title}" if title else "real-time prediction of the controlled agent",
                 fontsize=9)
    fig.tight_layout()
    fig.savefig(out / "realtime.png", dpi=110)
    plt.close(fig)
    return paths + [out / "realtime.png"]


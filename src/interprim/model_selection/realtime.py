"""The scorer of the real-time protocol (a robot's view: predictions in seconds from now, from causal prefixes).

:func:`realtime_fold` scores one fitted estimator on one held-out demonstration, :func:`realtime_sweep` runs it
over folds, :func:`summarise_realtime` averages the records.  It takes factories of estimators and names no model:
the default model's inner cross-validation (:mod:`interprim.model_selection.stacking`) and the reports
(:mod:`interprim.evaluation.realtime`, which documents the protocol) both use it.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping, Sequence, Sized
from dataclasses import dataclass, replace
from typing import Any, Protocol, cast

import numpy as np
from numpy.typing import ArrayLike

from ..core.cv import DEFAULT_HORIZON
from ..core.cv import folds as cv_folds
from ..core.preprocessing import interp_columns, time_normalise
from ..core.progress import Progress
from .metrics import Z90, coverage, point_rms, z_ratio
from .prefixes import Prefixes, observed_frames

__all__ = ["place_in_time", "RealTimeConfig", "mean_duration", "mean_demo", "realtime_fold", "whole_movement_fold",
           "folds", "realtime_sweep", "summarise_realtime", "MIN_DEMONSTRATIONS", "ALL_METHODS_FROM", "Z90",
           "PredictionLike", "StreamLike", "EstimatorLike"]


class PredictionLike(Protocol):
    """What the protocol reads of a prediction: any :class:`~interprim.models.base.BasePrediction` (the package's
    contract, which this layer below the models names only through this structural type)."""

    @property
    def normalised_time(self) -> float:
        """Normalised time of the last observed frame (NaN: played by the clock, :func:`place_in_time`)."""
        ...

    @property
    def duration(self) -> float:
        """Predicted duration of the whole movement in seconds (NaN: not estimated)."""
        ...

    def trajectory(self, n: int = 100) -> np.ndarray:
        """Mean of every column on ``linspace(0, 1, n)``, shape ``(n, D)``."""
        ...

    def std(self, n: int = 100, calibrated: bool = True) -> np.ndarray | None:
        """Pointwise standard deviation of :meth:`trajectory` (``None``: no uncertainty)."""
        ...


class StreamLike(Protocol):
    """What the protocol uses of an online predictor (:class:`~interprim.models.base.BaseStream`)."""

    def extend(self, frames: ArrayLike, need_cov: bool = False) -> PredictionLike:
        """Add observed frames ``(k, n_observed)``; the prediction after the last of them."""
        ...


class EstimatorLike(Protocol):
    """What the protocol uses of an estimator: any :class:`~interprim.models.base.Predictor`."""

    def fit(self, demos: Any, dt: float | None = None) -> Any:
        """Learn from demonstrations sampled every ``dt`` seconds; returns the estimator."""
        ...

    def predict(self, partial: ArrayLike) -> PredictionLike:
        """The prediction from the observed frames ``partial`` since the start of the movement."""
        ...

    def stream(self) -> StreamLike:
        """An online predictor whose answers equal :meth:`predict` of the frames seen."""
        ...

#: the fewest demonstrations :func:`interprim.assessment.evaluate_demonstrations` takes (every fold trains on at
#: least 2)
MIN_DEMONSTRATIONS = 3
#: from this many demonstrations (leave-one-out), every default method can be fitted on every training fold
ALL_METHODS_FROM = 5


def place_in_time(pred: PredictionLike, n_frames: int, dt: float, mean_duration: float) -> tuple[float, float]:
    """``(s, D)``: where a prediction puts "now" in its normalised time and how long it thinks the movement lasts.

    The one rule by which a prediction on normalised time is placed in seconds (the real-time protocol of
    :func:`realtime_fold` and the blend of :mod:`interprim.models.blend` use it): the position ``t`` seconds
    after the last of ``n_frames`` observed frames is the prediction at normalised time ``s + t / D``.

    * ``s`` is ``pred.normalised_time``; a prediction without one (NaN, e.g. the prior mean) is played by the
      clock: ``s = elapsed / mean_duration`` (at most 1) and ``D = mean_duration``.
    * ``D`` is ``pred.duration``; a prediction with a phase but no duration (e.g. the nearest demonstration) moves
      at the speed its phase implies: ``D = elapsed / s`` (``mean_duration`` when ``s`` is 0).

    ``elapsed = (n_frames - 1) * dt`` seconds; ``mean_duration`` is the demonstrations' mean duration in seconds.
    """
    elapsed = (int(n_frames) - 1) * float(dt)
    s = float(pred.normalised_time)
    dur = float(pred.duration)
    if not math.isfinite(s):
        return min(elapsed / mean_duration, 1.0), float(mean_duration)
    if not math.isfinite(dur) or dur <= 0:
        dur = elapsed / s if s > 0 else float(mean_duration)
    return s, float(dur)



@dataclass(frozen=True)
class RealTimeConfig:
    """Settings of the real-time protocol.

    Parameters
    ----------
    horizon : float
        Seconds ahead that are predicted after each observed frame (``math.inf``: every remaining frame of the
        held-out movement, the "rest of the movement" protocol).
    start, stop : float
        Fractions of the held-out movement between which frames are evaluated.
    stride : int
        Evaluate every ``stride``-th frame in that range (1 = every frame).
    n_grid : int
        Points of the normalised-time grid on which predictions are interpolated.
    point_dim : int
        Columns per point (3 for 3-D positions: errors are Euclidean distances of points), 1 for scalars.
    max_frames : int or None
        At most this many evaluated frames per held-out movement: a longer movement is evaluated every
        ``ceil(frames in range / max_frames)``-th frame if that is more than ``stride``, so the protocol's cost does
        not grow with the sampling rate (None: every ``stride``-th frame, however many).
    """

    horizon: float = DEFAULT_HORIZON
    start: float = 0.2
    stop: float = 0.9
    stride: int = 1
    n_grid: int = 201
    point_dim: int = 1
    max_frames: int | None = None

    def rest(self, stride: int) -> RealTimeConfig:
        """The same protocol over the rest of the movement: every remaining frame of the held-out movement
        (``horizon`` infinite), after every ``stride``-th frame seen."""
        return replace(self, horizon=math.inf, stride=int(stride))


def mean_duration(demos: Iterable[Sized]) -> float:
    """Mean duration of the demonstrations in frames - 1 (the clock's)."""
    return float(np.mean([len(d) - 1 for d in demos]))


def mean_demo(demos: Iterable[np.ndarray], n: int = 201) -> tuple[np.ndarray, float]:
    """``(mean (n, D), mean duration in frames - 1)`` of time-normalised demonstrations."""
    Y = np.stack([time_normalise(np.asarray(d, dtype=np.float64), n) for d in demos])
    return Y.mean(axis=0), mean_duration(demos)


def _interp_rows(u: ArrayLike, grid: np.ndarray, Y: ArrayLike) -> np.ndarray:
    """Rows of ``Y`` (on ``grid``) at normalised times ``u`` (clipped to [0, 1])."""
    return interp_columns(np.clip(u, 0.0, 1.0), grid, Y)


def _timing(pred: PredictionLike, k: int, dt: float, mean_dur_s: float) -> tuple[float, float]:
    """``(phase s at frame k, duration in s)`` of a prediction (:func:`place_in_time`)."""
    return place_in_time(pred, k, dt, mean_dur_s)


def scored_frames(T: int, cfg: RealTimeConfig) -> range:
    """The numbers of frames seen ``k`` at which the protocol scores a held-out movement of ``T`` frames: from
    ``cfg.start`` to ``cfg.stop`` of it (at least 3 frames seen), every ``cfg.stride``-th, at most
    ``cfg.max_frames`` of them."""
    k0 = max(3, int(math.ceil(cfg.start * T)))
    k1 = max(k0, int(math.floor(cfg.stop * T)))
    step = max(1, int(cfg.stride))
    if cfg.max_frames is not None:
        step = max(step, -(-(k1 - k0 + 1) // max(1, int(cfg.max_frames))))
    return range(k0, k1 + 1, step)


def realtime_fold(estimator: EstimatorLike, train: Iterable[np.ndarray], test: ArrayLike, observed_dofs: Iterable[int],
                  dt: float, cfg: RealTimeConfig = RealTimeConfig(), name: str = "method", fitted: bool = False,
                  frames: Iterable[int] | None = None, trace: bool = False,
                  prefix: Callable[[int], ArrayLike] | None = None, oracle: ArrayLike | None = None, std: bool = True,
                  references: bool = True, metrics: bool = True) -> list[dict[str, Any]]:
    """Fit ``estimator`` on ``train`` (unless ``fitted``) and run the real-time protocol on one held-out demo.

    Returns one record per evaluated frame ``k`` for the method, the clock and the oracle-duration mean:
    ``{"method", "k", "fraction", "phase_true", "phase", "phase_err", "rt_ctrl", "rt_obs", "cov_ctrl",
    "cov_obs", "z_ctrl", "z_obs"}`` (``z_*``: RMS error / RMS std over the horizon; NaN without a std).

    ``frames``: the numbers of frames seen ``k`` to evaluate instead of the protocol's (``cfg.start`` to
    ``cfg.stop``, every ``cfg.stride``-th, at most ``cfg.max_frames``), e.g. every frame for a figure.
    ``trace=True`` adds what the
    numbers were computed from to every record (for figures; not JSON-serialisable): ``"t_ahead"`` (seconds
    after frame ``k``, ``(H,)``), ``"truth"`` (the held-out frames there, ``(H, D)``), ``"mean"`` and ``"std"``
    (the prediction placed in time there, ``(H, D)``; ``std`` None without one); the method's records also
    carry ``"trajectory"`` (its prediction on the normalised-time grid, ``(n_grid, D)``), ``"duration"`` (the
    duration ``D`` in seconds that placed it) and ``"n_frames"`` (the held-out movement's length ``T``).

    ``prefix``: ``prefix(k)`` returns the observed columns of the first ``k`` frames as a robot had them at
    frame ``k`` (:class:`~interprim.model_selection.prefixes.Prefixes`; causal prefixes of interpolated recordings);
    default ``test[:k, observed_dofs]``, which is causal only when ``test`` holds the recorded samples.
    ``oracle``: ``(T, D)``, the best possible prediction of ``test`` (synthetic data,
    :class:`~interprim.synthetic.SyntheticTask`); adds ``"oracle"`` records, the floor.

    ``std=False`` skips the method's std (``cov_*`` and ``z_*`` are then NaN, ``"std"`` None) and
    ``references=False`` the clock and oracle-duration records, for a caller that needs only the method's errors
    and placed means (:class:`interprim.model_selection.stacking.CrossValidation`); the method's records are unchanged.
    ``metrics=False`` leaves the errors out of the records (no ``rt_*``, ``cov_*``, ``z_*``), for a caller that
    scores the placed means itself (with ``trace=True``).

    When the estimator's stream gives exactly what ``predict`` gives (``exact_stream = True``, e.g.
    :class:`~interprim.models.kernel.KernelDemonstrations`, whose stream updates its alignments one frame
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
    mean: np.ndarray | None  # None without the references (only the method's records)
    if references:
        mean, mean_dur = mean_demo(train, cfg.n_grid)
    else:
        mean, mean_dur = None, mean_duration(train)
    mean_dur_s = mean_dur * dt
    T = test.shape[0]
    true_dur_s = (T - 1) * dt
    to_end = math.isinf(cfg.horizon)
    H = 0 if to_end else max(1, int(round(cfg.horizon / dt)))
    frames = [int(k) for k in (scored_frames(T, cfg) if frames is None else frames)]
    for k in frames:
        if not 1 <= k <= T:
            raise ValueError(f"frames must be numbers of frames seen in 1..{T}, got {k}")
    predict = _prefix_predictions(estimator, test, obs, frames, prefix)
    out = []
    for k in frames:
        Hk = max(1, T - k) if to_end else H  # horizon=inf: every remaining frame of the held-out movement
        idx = np.minimum(np.arange(k, k + Hk), T - 1)  # frames k .. k+H-1 (0-based), held at the end
        t_ahead = (np.arange(1, Hk + 1)) * dt  # seconds after frame k-1 (0-based index k-1)
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
            mean_y = cast(np.ndarray, mean)  # computed with the references
            rows["clock"] = (min(elapsed / mean_dur_s, 1.0), _interp_rows((elapsed + t_ahead) / mean_dur_s, grid,
                                                                          mean_y), None)
            rows["oracle-duration"] = (phase_true, _interp_rows((elapsed + t_ahead) / true_dur_s, grid, mean_y), None)
        if oracle is not None:
            rows["oracle"] = (phase_true, np.asarray(oracle, dtype=np.float64)[idx], None)
        for method, (sm, Yh, Sh) in rows.items():
            err = Yh - truth if metrics else None  # without the metrics the errors are not read
            rec: dict[str, Any] = {"method": method, "k": int(k), "fraction": k / T, "phase_true": phase_true,
                                   "phase": float(sm), "phase_err": abs(float(sm) - phase_true)}
            for agent, cols in (("ctrl", ctrl), ("obs", obs)) if metrics else ():
                if not cols:
                    continue
                e = cast(np.ndarray, err)[:, cols]
                rec[f"rt_{agent}"] = point_rms(e, cfg.point_dim)
                if Sh is not None:
                    sd = Sh[:, cols]
                    rec[f"cov_{agent}"] = coverage(e, sd)
                    rec[f"z_{agent}"] = z_ratio(e, sd)
                else:
                    rec[f"cov_{agent}"] = float("nan")
                    rec[f"z_{agent}"] = float("nan")
            if trace:
                rec.update(t_ahead=t_ahead, truth=truth, mean=Yh, std=Sh)
                if method == name:  # the prediction on normalised time and its timing (re-placed by the selection)
                    rec.update(trajectory=Y, duration=float(dur), n_frames=int(T))
            out.append(rec)
    return out


def _prefix_predictions(estimator: EstimatorLike, test: np.ndarray, obs: list[int], frames: list[int],
                        prefix: Callable[[int], ArrayLike] | None) -> Callable[[int], PredictionLike]:
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

    def predict(k: int) -> PredictionLike:
        pred = stream.extend(last[fed[0]:k])
        fed[0] = k
        return pred

    return predict


def whole_movement_fold(estimator: EstimatorLike, test: ArrayLike, observed_dofs: Iterable[int],
                        fractions: Iterable[float] = (0.4, 0.6, 0.8), n: int = 100, point_dim: int = 1,
                        name: str = "method", prefix: Callable[[int], ArrayLike] | None = None,
                        oracle: ArrayLike | None = None) -> list[dict[str, Any]]:
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
            rec: dict[str, Any] = {"method": method, "fraction": float(p), "wm_obs": point_rms(err[:, obs], point_dim)}
            if ctrl:
                rec["wm_ctrl"] = point_rms(err[:, ctrl], point_dim)
            out.append(rec)
    return out


def folds(n: int, k: int | None = None) -> list[list[int]]:
    """Held-out index sets (lists of int): leave-one-out (``k`` None or >= n) or ``k`` contiguous folds
    (:func:`interprim.core.cv.folds`, ``order="contiguous"``)."""
    if k is not None and k < n and k < 2:
        raise ValueError(f"k-fold needs k >= 2, got {k}")
    return [f.tolist() for f in cv_folds(n, k, "contiguous")]


def realtime_sweep(make_estimators: Mapping[str, Callable[[], EstimatorLike]], demos: Prefixes | Iterable[ArrayLike],
                   observed_dofs: Sequence[int], dt: float, cfg: RealTimeConfig = RealTimeConfig(),
                   k: int | None = None, progress: bool = False, whole_movement: Iterable[float] | None = None,
                   oracles: Sequence[ArrayLike | None] | None = None,
                   test: Prefixes | Iterable[ArrayLike] | None = None, trace: bool = False, std: bool = True,
                   references: bool = True, metrics: bool = True, rest_stride: int | None = None
                   ) -> list[dict[str, Any]]:
    """Cross-validated real-time protocol for several methods on one set of demonstrations.

    ``make_estimators`` maps a method name to a zero-argument factory of an unfitted estimator.  Each fold
    fits every method on the other demonstrations; clock and oracle rows are added once (from the first
    method's pass).  ``whole_movement``: fractions at which :func:`whole_movement_fold` records (with
    ``"protocol": "whole"``) are added too.  Returns records with ``"demo"`` added.

    ``demos`` may be a :class:`~interprim.datasets.Demonstrations` with raw samples (NuiSI, resampled
    recordings): every prediction then sees a causal prefix (:class:`~interprim.model_selection.prefixes.Prefixes`),
    and every method is fitted on the training demonstrations with their raw samples (the same arrays; a model's
    own cross-validation, the Interaction Primitive's calibration, then sees causal prefixes too).
    ``oracles``: one ``(T_i, D)`` best possible prediction per demonstration (synthetic data); adds the floor.

    ``test``: evaluate on a fixed hold-out instead of cross-validating: ``demos`` are then the training
    demonstrations (every method is fitted once on all of them) and ``test`` the held-out ones (a
    :class:`~interprim.datasets.Demonstrations` gives causal prefixes); ``oracles`` then belong to ``test``.
    ``trace``: as in :func:`realtime_fold` (the placed predictions with every real-time record); ``std`` and
    ``references`` as there too (``references=False``: no clock and oracle-duration records at all), and
    ``metrics``.  ``rest_stride``: the rest of the movement too (every remaining frame of the held-out movement,
    after every ``rest_stride``-th frame seen from ``cfg.start`` to ``cfg.stop``; records with ``"protocol":
    "rest"``), from the same fitted estimators.
    """
    # demonstrations with their raw samples (a Demonstrations or TrainingSet that can ``take`` a subset) are fitted
    # with them, so that a model's own cross-validation (the Interaction Primitive's calibration) sees causal prefixes
    # as a robot does; the arrays are the same
    source = demos if getattr(demos, "raw", None) is not None and hasattr(demos, "take") else None
    if test is not None:
        # with a hold-out ``test``, ``demos`` are the training demonstrations themselves (arrays, not Prefixes)
        train = [np.asarray(d, dtype=np.float64) for d in cast("Iterable[ArrayLike]", demos)]
        given = test if isinstance(test, Prefixes) else Prefixes(test, observed_dofs)
        demos = train + given.demos
        n_train = len(train)
        prefixes: Prefixes | _Offset = _Offset(given, n_train)
        sets = [list(range(n_train, len(demos)))]
        oracles = None if oracles is None else [None] * n_train + list(oracles)
    else:
        whole = demos if isinstance(demos, Prefixes) else Prefixes(demos, observed_dofs)
        demos = whole.demos
        prefixes = whole
        sets = None
    if len(demos) < 3:
        raise ValueError(f"the real-time protocol needs at least 3 demonstrations, got {len(demos)}")
    recs = []
    protocols = [(cfg, None)] + ([] if rest_stride is None else [(cfg.rest(rest_stride), "rest")])
    sets = sets or folds(len(demos), k)
    bar = Progress(progress, len(sets), desc="folds", unit="fold", lines=False)  # a bar with the [experiments] extra
    for held in sets:
        kept = [i for i in range(len(demos)) if i not in set(held)]
        train = [demos[i] for i in kept]
        if source is None:
            fit_on: Any = train
        elif test is None:  # the fold's training demonstrations, with their raw samples
            fit_on = cast(Any, source).take(kept)
        else:  # a fixed hold-out: every method is fitted on all of ``source``
            fit_on = source
        for first, (name, factory) in enumerate(make_estimators.items()):
            est = factory().fit(fit_on, dt=dt)
            for j in held:
                def pre(k: int, j: int = j) -> np.ndarray:
                    return prefixes(j, k)

                orc = None if oracles is None else oracles[j]
                # real time, then (with rest_stride) every remaining frame, from the same fit; the references and
                # the oracle come with the first method only
                for c, protocol in protocols:
                    for r in realtime_fold(est, train, demos[j], observed_dofs, dt, c, name=name, fitted=True,
                                           prefix=pre, oracle=orc if not first else None,
                                           trace=trace and protocol is None, std=std,
                                           references=references and not first, metrics=metrics):
                        r["demo"] = int(j)
                        if protocol is not None:
                            r["protocol"] = protocol
                        recs.append(r)
                if whole_movement:
                    for r in whole_movement_fold(est, demos[j], observed_dofs, whole_movement,
                                                 point_dim=cfg.point_dim, name=name, prefix=pre,
                                                 oracle=orc if not first else None):
                        r["demo"] = int(j)
                        r["protocol"] = "whole"
                        recs.append(r)
        bar.step()
    bar.close()
    return recs


class _Offset:
    """Prefixes of a hold-out numbered after the training demonstrations."""

    def __init__(self, prefixes: Prefixes, n_train: int) -> None:
        self.prefixes, self.n_train = prefixes, n_train

    def __call__(self, j: int, k: int) -> np.ndarray:
        return self.prefixes(j - self.n_train, k)


#: Below this phase error (a fraction of the movement) the clock is exact: no ratio to it is given (equal lengths).
PHASE_ERROR_FLOOR = 1e-6


def summarise_realtime(records: Iterable[Mapping[str, Any]]) -> dict[str, dict[str, Any]]:
    """Per method: means over all evaluated frames of every metric, and ratios of the real-time error and of
    the phase error to the clock's (means of per-demo ratios would overweight easy demos: ratios of means)."""
    by: dict[Any, list[Mapping[str, Any]]] = {}
    whole: dict[Any, list[Mapping[str, Any]]] = {}
    for r in records:
        if r.get("protocol") == "whole":
            whole.setdefault(r["method"], []).append(r)
        else:
            by.setdefault(r["method"], []).append(r)
    out: dict[str, dict[str, Any]] = {}
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
                why: Any = (f"the clock's phase error is {clock['phase_err']:.1g}: the demonstrations last (almost) "
                            "equally long, so elapsed time alone gives the phase and a ratio to it says nothing")
                out[m]["phase_err_vs_clock_why"] = why
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

"""A phase estimator learned from the demonstrations (extends paper Sec. III-B, Eq. 8-9).

The paper estimates the phase of a partial observation by open-end DTW of the
observed prefix against one reference movement (Eq. 5-8) and maps the matched
index to the canonical phase (Eq. 9).  On recordings of people that is no
better than a clock that assumes the mean duration (issue 11): DTW matches
*shape*, and people differ more in shape than in the timing cues DTW sees.

:class:`LearnedPhase` instead *learns* the map from what has been seen to how
far along the movement is, from the demonstrations themselves.  For every
demonstration ``i`` and every elapsed time ``t`` on a grid of step ``dt``, the
prefix ``y_i(0..t)`` is summarised by a few features (last position,
displacement from the first frame, velocity over a short window, and the
displacement at a few fractions of the elapsed time, i.e. how the prefix
unfolded; optionally path length and peak speed so far; all on DoFs scaled by
the demonstrations' spread) and paired
with its true normalised time ``s_i(t) = min(t / T_i, 1)`` (``T_i`` the
demonstration's duration).  A query seen for ``t`` seconds is compared only with
the demonstrations' prefixes *of the same elapsed time*, so that the
regression answers "given that ``t`` seconds have passed and the movement looks
like this, how far along is it?".  Two regressors are available at each
elapsed time:

* ``"kernel"``: Nadaraya-Watson kernel regression (Gaussian kernel on the
  standardised features, bandwidth ``h``).  As ``h -> inf`` every demonstration
  gets the same weight and the estimate becomes the demonstrations' mean
  normalised time at ``t``: a clock.
* ``"ridge"``: linear ridge regression on the standardised features; as the
  penalty grows it also becomes the clock.

The target is either the normalised time itself or the log duration
``log T_i`` (then ``s = t / T_hat``), and a speed/duration estimate comes with
either.  Everything that is chosen (regressor, bandwidth or penalty, target,
which feature groups to use) is chosen by leave-one-demonstration-out
cross-validation on the training demonstrations, in closed form.  The chosen
model is used only if it beats both the leave-one-out clock (the mean duration
of the other demonstrations) and the featureless mean normalised time by one
paired standard error; otherwise the estimator *is* the clock and says so
(``method_ == "clock"``, ``fallback_ is True``).  A query's features are
clipped to the demonstrations' range at the same elapsed time, so that a
tracking glitch is not extrapolated.

Measured (``python -m interprim.experiments.phase_nuisi``, ``docs/phase-learned.md``):
on NuiSI v1 (leave-one-out, 9 observed columns) the phase error is 0.68x the
clock's (0.62-0.79 over the six interactions; the likelihood phase 1.06x, the
paper's DTW 1.22x).  On clean or simulated data the likelihood phase is better
(synthetic 0.20x the clock's against 0.30x, simulated high five 0.04x against
0.36x): choose between the two per data set (e.g. by cross-validation).

The uncertainty reported with each estimate is the root mean square
leave-one-out error of the chosen model at that elapsed time (smoothed over
neighbouring times), i.e. an honest error bar measured on held-out
demonstrations, not a model-internal variance.

Online, :meth:`LearnedPhase.tracker` returns a :class:`PhaseTracker` that
updates the features in ``O(D)`` per frame (running sums, a ring buffer for the
velocity window, the frames kept for the history group) and evaluates the
regression in ``O(n_demos * n_features)`` (0.05-0.1 ms at 30 demonstrations x
20 frames x 9 DoFs).

Assumption (as for the paper's DTW): the observation starts where the
demonstrations start; online, the start of the movement must be detected the
way the demonstrations were cut.
"""

from __future__ import annotations

import math

import numpy as np

from ..core.cache import DerivedCache, fitted_once
from ..core.cv import paired_gain
from ..core.preprocessing import resample_step
from ..core.validation import as_2d_finite, as_demonstrations, as_frame, check_positive, check_times
from ._learned_features import group_dims, jsonable, kernel_loo, prefix_features, ridge_loo
from .estimate import PhaseEstimate

__all__ = ["LearnedPhase", "PhaseEstimate", "PhaseTracker", "FEATURE_GROUPS", "DEFAULT_FEATURES"]

#: Feature groups of a prefix (``D`` = number of observed DoFs).
FEATURE_GROUPS = ("position", "displacement", "velocity", "path", "peak_speed", "history")
#: The default groups: the ones that do not accumulate tracking noise (path length and peak speed grow with
#: the sensor's noise and sampling rate; on NuiSI they made the estimate worse: 0.72x the clock with them,
#: 0.68x without).
DEFAULT_FEATURES = ("position", "displacement", "velocity", "history")
_MODELS = ("kernel", "ridge")
_TARGETS = ("phase", "log_duration")


class LearnedPhase:
    """Phase (normalised time) of a partial observation, learned from the demonstrations.

    Extends the paper's phase estimation (Sec. III-B, Eq. 5-9: open-end DTW against
    one reference) by a regression trained on the demonstrations' own prefixes; see
    the module docstring for the method.  The estimate plugs into the Interaction
    Primitive where DTW's does: ``InteractionPrimitive.predict(partial, phase=est.phase)``
    (Eq. 9 then gives the canonical phase; the observed frames are spread over
    ``[0, phase]``).

    Parameters
    ----------
    features : sequence of str, default :data:`DEFAULT_FEATURES`
        Feature groups of the observed prefix, from :data:`FEATURE_GROUPS`:
        ``"position"`` (last frame), ``"displacement"`` (last minus first
        frame), ``"velocity"`` (over the last ``velocity_window`` seconds),
        ``"history"`` (displacement from the first frame at ``history`` equally
        spaced fractions of the elapsed time: how the prefix unfolded, e.g. a
        late or an early start), ``"path"`` (path length so far),
        ``"peak_speed"`` (largest windowed speed so far).  DoFs are divided by
        their spread over the demonstrations first, so any units and any number
        of DoFs work.  Each group weighs the same whatever its number of columns.
    model : {"auto", "kernel", "ridge"}, default "auto"
        Regressor at each elapsed time; ``"auto"`` picks by cross-validation.
    target : {"auto", "phase", "log_duration"}, default "phase"
        Regress the normalised time directly, or the log duration (then
        ``phase = t / duration``); ``"auto"`` picks by cross-validation.
    select_features : bool, default False
        Greedy forward selection of feature groups by cross-validation (starting
        from none, which is the clock); by default all of ``features`` are used
        (on NuiSI the selection overfitted: 0.75x the clock's error with it,
        0.72x without).
    bandwidths : sequence of float, optional
        Kernel bandwidths (in standard deviations of the features) to try; the
        default ``0.25 .. 8`` (geometric) ends wide enough to be the clock.
    alphas : sequence of float, optional
        Ridge penalties to try (on standardised features; default ``0.1 .. 1e4``).
    velocity_window : float, default 0.15
        Window of the velocity feature in seconds.
    standardise : {"time", "global"}, default "time"
        Standardise each feature over the demonstrations at each elapsed time, or
        once over all times.
    fallback_se : float, default 1.0
        A learned model is used only if its cross-validated error is below the
        clock's and the featureless estimate's (the demonstrations' mean
        normalised time at that elapsed time) by more than this many standard
        errors of the paired per-demonstration difference (otherwise: the clock).  ``0`` uses it
        whenever it is better at all.
    cv_range : (float, float), default (0.1, 1.0)
        Normalised times of the training prefixes that count in the
        cross-validation error.
    history : int, default 3
        Points of the ``"history"`` group: the prefix at elapsed-time fractions
        ``1/(history+1), ..., history/(history+1)`` (1, 3, 6 and 10 gave the same
        error on NuiSI within 0.02x of the clock's).

    Attributes
    ----------
    method_ : {"kernel", "ridge", "clock"}
        The chosen regressor (``"clock"``: nothing beat the clock in cross-validation).
    fallback_ : bool
        ``method_ == "clock"``.
    target_ : str
    features_ : tuple of str
        The selected feature groups (empty for the clock).
    bandwidth_, alpha_ : float or None
        The chosen hyper-parameter of the kernel / ridge model.
    cv_error_, cv_error_clock_ : float
        Mean absolute leave-one-demonstration-out phase error of the chosen model and of the clock.
    cv_error_featureless_ : float
        The same for the demonstrations' mean normalised time at each elapsed
        time (no features).
    cv_improvement_se_ : float
        The best learned model's improvement over the better of the clock and
        the featureless estimate, in standard errors (paired over the training
        demonstrations; see ``fallback_se``).
    cv_table_ : list of dict
        Every candidate tried and its cross-validated error.
    dt_ : float
        Time step of the elapsed-time grid (s).
    mean_duration_ : float
        Mean duration of the demonstrations (s).
    durations_ : ndarray (n_demos,)
    n_demos_, n_dofs_ : int
    """

    def __init__(self, features=DEFAULT_FEATURES, model: str = "auto", target: str = "phase",
                 select_features: bool = False, bandwidths=None, alphas=None, velocity_window: float = 0.15,
                 standardise: str = "time", fallback_se: float = 1.0, cv_range=(0.1, 1.0), history: int = 3):
        self.features = features
        self.model = model
        self.target = target
        self.select_features = select_features
        self.bandwidths = bandwidths
        self.alphas = alphas
        self.velocity_window = velocity_window
        self.standardise = standardise
        self.fallback_se = fallback_se
        self.cv_range = cv_range
        self.history = history

    # ------------------------------------------------------------------ parameters
    def get_params(self) -> dict:
        """The constructor's arguments as a dict (what a copy or a model file needs to rebuild the estimator)."""
        return {k: getattr(self, k) for k in ("features", "model", "target", "select_features", "bandwidths",
                                              "alphas", "velocity_window", "standardise", "fallback_se", "history",
                                              "cv_range")}

    def _check_params(self):
        feats = (self.features,) if isinstance(self.features, str) else tuple(self.features)
        bad = [f for f in feats if f not in FEATURE_GROUPS]
        if bad:
            raise ValueError(f"features: unknown group(s) {bad}; expected a subset of {FEATURE_GROUPS}")
        if len(set(feats)) != len(feats):
            raise ValueError(f"features: group listed twice in {feats}")
        if self.model not in ("auto",) + _MODELS:
            raise ValueError(f"model must be 'auto', 'kernel' or 'ridge', got {self.model!r}")
        if self.target not in ("auto",) + _TARGETS:
            raise ValueError(f"target must be 'auto', 'phase' or 'log_duration', got {self.target!r}")
        if self.standardise not in ("time", "global"):
            raise ValueError(f"standardise must be 'time' or 'global', got {self.standardise!r}")
        check_positive(self.velocity_window, "velocity_window")
        if not (isinstance(self.history, (int, np.integer)) and self.history >= 1):
            raise ValueError(f"history must be an int >= 1, got {self.history!r}")
        if not (isinstance(self.fallback_se, (int, float)) and self.fallback_se >= 0):
            raise ValueError(f"fallback_se must be a number >= 0, got {self.fallback_se!r}")
        bw = np.geomspace(0.03, 8.0, 17) if self.bandwidths is None else np.asarray(self.bandwidths, float)
        al = np.geomspace(0.1, 1e4, 11) if self.alphas is None else np.asarray(self.alphas, float)
        for name, v in (("bandwidths", bw), ("alphas", al)):
            if v.ndim != 1 or v.size == 0 or not np.all(np.isfinite(v)) or np.any(v <= 0):
                raise ValueError(f"{name} must be a non-empty 1-D sequence of positive numbers, got {v!r}")
        lo, hi = (float(x) for x in self.cv_range)
        if not 0.0 <= lo < hi <= 1.0:
            raise ValueError(f"cv_range must be (lo, hi) with 0 <= lo < hi <= 1, got {self.cv_range!r}")
        return feats, bw, al, (lo, hi)

    # ------------------------------------------------------------------ fit
    def fit(self, demos, dt: float | None = None, times=None) -> LearnedPhase:
        """Learn the phase map from demonstrations of the observed agent.

        Parameters
        ----------
        demos : list of array_like, each (T_i, D)
            The observed agent's demonstrations (only the observed DoFs), each
            from the start to the end of the movement, at least 3 of them.
        dt : float, optional
            Sampling interval in seconds of uniformly sampled ``demos``.
        times : list of array_like (T_i,), optional
            Time stamps instead of ``dt`` (irregular sampling); the demonstrations
            are resampled onto a uniform grid of the median interval.

        Returns
        -------
        self
        """
        feats, bw, al, (lo, hi) = self._check_params()
        if isinstance(demos, np.ndarray) and demos.ndim == 3:
            demos = list(demos)
        if not isinstance(demos, (list, tuple)):
            raise TypeError(f"demos must be a list of (T_i, D) arrays, got {type(demos).__name__}")
        if len(demos) < 3:
            raise ValueError(f"demos: at least 3 demonstrations are needed (leave-one-out needs 2 to train on), "
                             f"got {len(demos)}")
        Ys = as_demonstrations(demos, min_rows=2)
        D = Ys[0].shape[1]
        if (dt is None) == (times is None):
            raise ValueError("give exactly one of dt (uniform sampling, seconds) or times (one array per demo)")
        if times is not None:
            if len(times) != len(Ys):
                raise ValueError(f"times has {len(times)} arrays, demos has {len(Ys)}")
            ts = [check_times(t, y.shape[0], f"times[{i}]") for i, (t, y) in enumerate(zip(times, Ys))]
            step = float(np.median(np.concatenate([np.diff(t) for t in ts])))
            Ys = [self._resample(y, t - t[0], step) for y, t in zip(Ys, ts)]
            dt = step
        dt = check_positive(dt, "dt")
        params = self.get_params()

        def learn() -> dict:
            self._learn(Ys, float(dt), D, feats, bw, al, lo, hi)
            return {k: v for k, v in vars(self).items() if k not in params and k != "_kept"}

        # the same fit on the same observed frames within one default model's fit (its IP and its learned
        # interaction, on one inner training fold) is made once (interprim.core.cache.shared_fits)
        self.__dict__.pop("_kept", None)  # estimates of the previous fit
        self.__dict__.update(fitted_once("learned phase", (params, float(dt)), Ys, learn))
        return self

    def same_fit(self, other) -> bool:
        """Whether ``other`` is a fitted :class:`LearnedPhase` with the same settings and fitted arrays, bit for bit
        (:meth:`to_state`): the same estimates of any frames."""
        if not isinstance(other, LearnedPhase):
            return False
        (xa, ma), (xb, mb) = self.to_state(), other.to_state()
        if ma != mb or xa.keys() != xb.keys():
            return False
        return all(u is v or (u.dtype == v.dtype and u.shape == v.shape and u.tobytes() == v.tobytes())
                   for u, v in ((np.asarray(xa[k]), np.asarray(xb[k])) for k in xa))

    def keep_last_estimate(self) -> None:
        """Keep the last estimate from now on (:meth:`estimate`, :meth:`estimate_checked`): an estimate of the same
        frames (those its features read, at the same elapsed time) is then the kept one, not computed again.  For
        a phase model that several models read on the same frames after every frame (a blend's members:
        :func:`interprim.models.blend.share_phase_models`); kept in a
        :class:`~interprim.core.cache.DerivedCache` (not the fitted state, not saved; a new ``fit`` drops it)."""
        if "_kept" not in self.__dict__:
            self._kept = DerivedCache()

    def _learn(self, Ys: list, dt: float, D: int, feats: tuple, bw: np.ndarray, al: np.ndarray, lo: float,
               hi: float) -> None:
        """:meth:`fit` on the validated demonstrations ``Ys`` sampled every ``dt`` seconds (``feats``, ``bw``,
        ``al``, ``(lo, hi)``: the checked parameters)."""
        durations = np.array([(y.shape[0] - 1) * dt for y in Ys])
        allY = np.concatenate(Ys, axis=0)
        scale = allY.std(axis=0)
        scale = np.where(scale > 1e-12 * (1.0 + np.abs(allY).max()), scale, 1.0)
        self.dt_ = dt
        self.n_dofs_ = D
        self.n_demos_ = len(Ys)
        self.scale_ = scale
        self.durations_ = durations
        self.mean_duration_ = float(durations.mean())
        self._w = max(1, int(round(self.velocity_window / dt)))
        n = len(Ys)
        K = int(max(y.shape[0] for y in Ys))  # grid k = 0 .. K-1; beyond: every demonstration has ended
        self.n_grid_ = K
        grid = np.arange(K) * dt
        # per-group training features on the grid, frozen after each demonstration's end
        F = {}
        for g in FEATURE_GROUPS:
            arr = None
            for i, y in enumerate(Ys):
                f = prefix_features(y / scale, dt, self._w, (g,), self.history)
                if arr is None:
                    arr = np.empty((K, n, f.shape[1]))
                arr[: f.shape[0], i] = f
                arr[f.shape[0]:, i] = f[-1]
            F[g] = arr
        S = np.minimum(grid[:, None] / durations[None, :], 1.0)  # (K, n) true normalised time
        logT = np.broadcast_to(np.log(durations)[None, :], (K, n))
        # which (time, demo) pairs count in the CV error
        mask = (S >= lo - 1e-12) & (S <= hi + 1e-12) & (grid[:, None] <= durations[None, :] + 1e-9)
        # clock, leave-one-out: mean duration of the other demonstrations
        loo_mean = (durations.sum() - durations) / (n - 1)
        clock_loo = np.minimum(grid[:, None] / loo_mean[None, :], 1.0)
        clock_err = float(np.mean(np.abs(clock_loo - S)[mask]))
        self.cv_error_clock_ = clock_err
        models = _MODELS if self.model == "auto" else (self.model,)
        targets = _TARGETS if self.target == "auto" else (self.target,)
        table = []

        def evaluate(groups):
            """Best (error, model, target, hyper, loo predictions of s) for a set of groups."""
            Z = self._standardise_train(np.concatenate([F[g] for g in groups], axis=2), groups, D)[0]
            best = None
            for tg in targets:
                y = S if tg == "phase" else logT
                for m in models:
                    hyp = bw if m == "kernel" else al
                    P = kernel_loo(Z, y, hyp) if m == "kernel" else ridge_loo(Z, y, hyp)
                    if tg == "log_duration":
                        P = np.minimum(grid[None, :, None] / np.exp(P), 1.0)
                    P = np.clip(P, 0.0, 1.0)
                    err = np.array([np.mean(np.abs(P[a] - S)[mask]) for a in range(len(hyp))])
                    a = int(np.argmin(err))
                    table.append({"features": tuple(groups), "model": m, "target": tg, "hyper": float(hyp[a]),
                                  "cv_error": float(err[a])})
                    if best is None or err[a] < best[0] - 1e-15:
                        best = (float(err[a]), m, tg, float(hyp[a]), P[a])
            return best

        if self.select_features:
            chosen: list = []
            best = None
            remaining = list(feats)
            while remaining:
                cands = [(evaluate(chosen + [g]), g) for g in remaining]
                (res, g) = min(cands, key=lambda c: c[0][0])
                if best is not None and res[0] >= best[0]:
                    break
                chosen.append(g)
                remaining.remove(g)
                best = res
            groups = [g for g in feats if g in chosen]  # keep a canonical order
            best = evaluate(groups) if groups else None
        else:
            groups = list(feats)
            best = evaluate(groups) if groups else None
        self.cv_table_ = table
        use = False
        self.cv_improvement_se_ = 0.0
        # featureless reference: the other demonstrations' mean normalised time at the same elapsed time (what
        # either regressor becomes without information); it can beat t / mean duration by itself (Jensen), so
        # a learned model must beat the better of the two to count as using the features
        flat_loo = (S.sum(axis=1, keepdims=True) - S) / (n - 1)
        cnt = np.maximum(mask.sum(axis=0), 1)
        e_c = np.sum(np.where(mask, np.abs(clock_loo - S), 0.0), axis=0) / cnt
        e_f = np.sum(np.where(mask, np.abs(flat_loo - S), 0.0), axis=0) / cnt
        self.cv_error_featureless_ = float(np.mean(np.abs(flat_loo - S)[mask]))
        e_ref = e_f if self.cv_error_featureless_ < clock_err else e_c
        if best is not None and best[0] < min(clock_err, self.cv_error_featureless_):
            # paired per-demonstration comparison (one-standard-error rule, interprim.core.cv)
            e_m = np.sum(np.where(mask, np.abs(best[4] - S), 0.0), axis=0) / cnt
            gain, se = paired_gain(e_ref, e_m)
            se = float(se)
            self.cv_improvement_se_ = float(gain / se) if se > 0 else math.inf
            use = self.cv_improvement_se_ > float(self.fallback_se)
        if use:
            assert best is not None  # use needs a best candidate
            err, m, tg, hyp, P = best
            self.method_, self.target_ = m, tg
            self.features_ = tuple(groups)
            self.bandwidth_ = hyp if m == "kernel" else None
            self.alpha_ = hyp if m == "ridge" else None
            self.cv_error_ = err
            resid = P - S
        else:
            self.method_, self.target_ = "clock", "phase"
            self.features_ = ()
            self.bandwidth_ = self.alpha_ = None
            self.cv_error_ = clock_err
            resid = clock_loo - S
        self.fallback_ = self.method_ == "clock"
        # phase uncertainty per elapsed time: RMS leave-one-out error over demonstrations still moving,
        # smoothed over +-2 grid steps; after every demonstration has ended the error is that of the last step
        moving = grid[:, None] <= durations[None, :] + 1e-9
        num = np.sum(np.where(moving, resid * resid, 0.0), axis=1)
        cnt = np.sum(moving, axis=1).astype(float)
        ker = np.ones(5)
        num_s = np.convolve(num, ker, mode="same")
        cnt_s = np.convolve(cnt, ker, mode="same")
        std = np.sqrt(num_s / np.maximum(cnt_s, 1.0))
        last = np.nonzero(cnt_s > 0)[0]
        if last.size:
            std[last[-1] + 1:] = std[last[-1]]
        std[0] = 0.0
        self.std_grid_ = std
        # the chosen model's training arrays, per elapsed time
        self._y = (S if self.target_ == "phase" else logT).copy()
        if not self.fallback_:
            Zraw = np.concatenate([F[g] for g in self.features_], axis=2)
            Z, mu, sd = self._standardise_train(Zraw, self.features_, D)
            self._mu, self._sd = mu, sd
            # a query's features are clipped to the demonstrations' range at the same elapsed time: one glitch
            # of the tracker in one DoF must not be extrapolated linearly (on NuiSI with 24 observed columns
            # a single held-out rocket1 demonstration got a phase error of 0.23 without this)
            self._fmin = np.ascontiguousarray(Zraw.min(axis=1))
            self._fmax = np.ascontiguousarray(Zraw.max(axis=1))
            if self.method_ == "kernel":
                p = Z.shape[2]
                self._Z = np.ascontiguousarray(Z / math.sqrt(max(p, 1)))
                assert self.bandwidth_ is not None  # set with the kernel method
                self._inv2h2 = 1.0 / (2.0 * float(self.bandwidth_) ** 2)
                self._nrm = np.einsum("knp,knp->kn", self._Z, self._Z)
                self._isd = 1.0 / (sd * math.sqrt(max(p, 1)))  # sd = inf (no variation) -> 0
                self._mis = mu * self._isd
            else:
                Zm = Z.mean(axis=1, keepdims=True)
                Zc = Z - Zm
                ym = self._y.mean(axis=1)
                p = Z.shape[2]
                assert self.alpha_ is not None  # set with the ridge method
                A = np.einsum("knp,knq->kpq", Zc, Zc) + float(self.alpha_) * np.eye(p)[None]
                b = np.einsum("knp,kn->kp", Zc, self._y - ym[:, None])
                beta = np.linalg.solve(A, b[..., None])[..., 0]
                self._beta = beta
                self._c = ym - np.einsum("kp,kp->k", beta, Zm[:, 0, :])
                self._beta_raw = beta / sd
                self._c_raw = self._c - np.einsum("kp,kp->k", self._beta_raw, mu)

    @staticmethod
    def _resample(y, t, step):
        """``y`` (times ``t`` from 0) at the times ``0, step, 2 step, ...`` up to ``t[-1]``."""
        return resample_step(y, t, step)[0]

    def _standardise_train(self, X, groups, D):
        """Standardise features (K, n, p) and weight groups equally; returns ``(Z, mu, sd)``."""
        if self.standardise == "time":
            mu = X.mean(axis=1, keepdims=True)
            sd = X.std(axis=1, keepdims=True)
        else:
            mu = X.mean(axis=(0, 1), keepdims=True)
            sd = X.std(axis=(0, 1), keepdims=True)
            mu = np.broadcast_to(mu, (X.shape[0], 1, X.shape[2]))
            sd = np.broadcast_to(sd, (X.shape[0], 1, X.shape[2]))
        gsd = X.reshape(-1, X.shape[2]).std(axis=0)
        floor = 1e-6 * gsd + 1e-12
        sd = np.where(sd > floor, sd, np.inf)  # a feature that does not vary at a time carries no information
        # each group weighs the same in the distance, whatever its number of columns
        wcol = np.concatenate([np.full(k, 1.0 / math.sqrt(k)) for k in group_dims(groups, D, self.history)]) \
            if len(groups) else np.zeros(0)
        sd = sd / wcol
        Z = (X - mu) / sd
        return Z, mu[:, 0, :].copy(), sd[:, 0, :].copy()

    # ------------------------------------------------------------------ estimate
    def _check_fitted(self):
        if not hasattr(self, "method_"):
            from ..core.errors import NotFittedError

            raise NotFittedError("this LearnedPhase is not fitted yet; call fit(demos, dt=...) first")

    def _raw_features(self, Y, scale):
        """Features (p,) of a uniformly sampled prefix (T, D) divided by ``scale`` (D,), for the selected groups.

        Only the frames the features read are divided (the first and last frames, the frame one velocity window
        back and two per history point; every frame for ``"path"`` and ``"peak_speed"``): each element is the same
        quotient as in ``Y / scale``, so the features are those of the scaled prefix, at a cost that does not grow
        with ``T``."""
        if "path" in self.features_ or "peak_speed" in self.features_:  # these need every frame
            return prefix_features(Y / scale, self.dt_, self._w, self.features_, self.history)[-1]
        rows, f = self._feature_rows(Y.shape[0] - 1)
        return self._row_features(Y[rows], scale, Y.shape[0] - 1, f)

    def _feature_rows(self, k: int) -> tuple:
        """``(rows, f)``: the frames the features of a prefix of ``k + 1`` frames read (0, ``k``, one velocity
        window back, then each history point's two neighbours) and the history points' interpolation weights
        (``"path"`` and ``"peak_speed"`` read every frame: not for them)."""
        back = max(k - self._w, 0)
        h = self.history
        if "history" in self.features_:
            x = np.arange(1, h + 1) / (h + 1) * k
            lo = x.astype(np.int64)
            f = (x - lo)[:, None]
            rows = np.concatenate([np.array([0, k, back], dtype=np.int64), lo, np.minimum(lo + 1, k)])
        else:
            f = None
            rows = np.array([0, k, back], dtype=np.int64)
        return rows, f

    def _row_features(self, G, scale, k: int, f):
        """The features (p,) of :meth:`_raw_features` from the frames ``G = Y[rows]`` it reads
        (:meth:`_feature_rows` of ``k``)."""
        back = max(k - self._w, 0)
        h = self.history
        Ys = G / scale  # rows 0, k, back, then the history points' two neighbours
        first, last = Ys[0], Ys[1]
        parts = []
        for g in self.features_:
            if g == "position":
                parts.append(last)
            elif g == "displacement":
                parts.append(last - first)
            elif g == "velocity":
                parts.append((last - Ys[2]) / ((k - back) * self.dt_))
            else:  # history
                parts.append(((1.0 - f) * Ys[3:3 + h] + f * Ys[3 + h:] - first).ravel())
        return np.concatenate(parts)

    def _predict_at(self, k: int, f) -> float:
        """Normalised time at grid index ``k`` (0..n_grid_-1) from raw features ``f``."""
        if self.method_ == "clock":
            return min(k * self.dt_ / self.mean_duration_, 1.0)
        f = np.minimum(np.maximum(f, self._fmin[k]), self._fmax[k])
        if self.method_ == "kernel":
            # |Z_i - z|^2 - min_j |Z_j - z|^2 = e_i - min(e) with e_i = |Z_i|^2 - 2 Z_i . z (|z|^2 cancels)
            u = f * self._isd[k] - self._mis[k]
            e = self._nrm[k] - 2.0 * (self._Z[k] @ u)
            w = np.exp((e.min() - e) * self._inv2h2)
            v = float(w @ self._y[k]) / float(w.sum())
        else:
            v = float(self._c_raw[k] + self._beta_raw[k] @ f)  # standardisation folded into the coefficients
        if self.target_ == "log_duration":
            return min(k * self.dt_ / math.exp(v), 1.0)
        return min(max(v, 0.0), 1.0)

    @property
    def window_(self) -> int:
        """Frames of the windowed velocity feature (``velocity_window / dt``, at least 1)."""
        return self._w

    def estimate_at(self, t: float, f) -> PhaseEstimate:
        """Estimate at elapsed time ``t`` (s) from the features ``f`` of the prefix (``None``: the clock's)."""
        K = self.n_grid_
        k = int(round(t / self.dt_))
        if k <= 0:
            return PhaseEstimate(0.0, self.mean_duration_, 1.0, 0.0, float(t))
        if k >= K:  # longer than every demonstration: it has ended
            s_k, kk = self._predict_at(K - 1, f), K - 1
        else:
            s_k, kk = self._predict_at(k, f), k
        gk = kk * self.dt_
        if s_k > 0:
            duration = gk / s_k
            s = min(t / duration, 1.0)
        else:
            duration, s = math.inf, 0.0
        if s >= 1.0:
            duration = t if t > 0 else self.mean_duration_
        std = float(self.std_grid_[min(k, K - 1)])
        return PhaseEstimate(float(s), float(duration), float(self.mean_duration_ / duration), std, float(t))

    _finish = estimate_at

    def estimate(self, partial, dt: float | None = None, times=None) -> PhaseEstimate:
        """Phase of a partial observation of the observed agent.

        Parameters
        ----------
        partial : array_like, shape (M, D)
            Frames seen so far, from the start of the movement.
        dt : float, optional
            Their sampling interval in seconds (default: the training ``dt_``);
            a different rate is resampled to ``dt_``.
        times : array_like (M,), optional
            Time stamps instead of ``dt``.

        Returns
        -------
        PhaseEstimate
            ``phase`` in [0, 1], ``duration`` (s), ``speed`` and ``std`` of the phase.
        """
        self._check_fitted()
        Y = as_2d_finite(partial, "partial", n_cols=self.n_dofs_, min_rows=1)
        if times is not None:
            t = check_times(times, Y.shape[0], "times")
            t = t - t[0]
        elif dt is not None:
            t = np.arange(Y.shape[0]) * check_positive(dt, "dt")
        else:
            t = None
        if t is not None and Y.shape[0] > 1 and not np.allclose(np.diff(t), self.dt_, rtol=1e-9, atol=0):
            elapsed = float(t[-1])
            Y = self._resample(Y, t, self.dt_)
        else:
            elapsed = (Y.shape[0] - 1) * self.dt_
        return self._estimate_at(Y, elapsed)

    def estimate_checked(self, partial: np.ndarray) -> PhaseEstimate:
        """:meth:`estimate` (at the training ``dt_``) of frames already checked: a finite float64 array ``(M,
        n_dofs_)``, not scanned again (:class:`~interprim.models.learned.LearnedInteraction`'s stream checks each
        frame once, as it enters); the features read only the frames they need, so the cost does not grow with
        ``M`` (the same numbers as :meth:`estimate`)."""
        return self._estimate_at(partial, (partial.shape[0] - 1) * self.dt_)

    def _estimate_at(self, Y: np.ndarray, elapsed: float) -> PhaseEstimate:
        """The estimate of checked frames ``Y`` sampled at ``dt_``, ``elapsed`` seconds after the first (the clock's
        phase for a clock model or a single frame); only the frames the features read are scaled (each the same
        quotient as in ``Y / scale_``)."""
        if self.method_ == "clock" or Y.shape[0] < 2:
            return self._finish(elapsed, None)
        if "path" in self.features_ or "peak_speed" in self.features_:  # every frame read: not kept
            return self._finish(elapsed, self._raw_features(Y, self.scale_))
        # the estimate is a function of the frames the features read and of the elapsed time: with
        # keep_last_estimate the last one is kept, so that the models that read the same phase model on the same
        # frames (a blend's Interaction Primitive and learned members share one,
        # :func:`interprim.models.blend.share_phase_models`) compute it once a frame
        kept = self.__dict__.get("_kept")
        if kept is None:
            return self._finish(elapsed, self._raw_features(Y, self.scale_))
        k = Y.shape[0] - 1
        last: tuple = kept.get("estimate", ((), ()))[1]  # (k, rows, f, key, estimate)
        same_k = bool(last) and last[0] == k
        rows, f = (last[1], last[2]) if same_k else self._feature_rows(k)
        G = Y[rows]
        key = (float(elapsed), G.tobytes())
        if same_k and last[3] == key:
            return last[4]
        est = self._finish(elapsed, self._row_features(G, self.scale_, k, f))
        kept["estimate"] = ((), (k, rows, f, key, est))  # one assignment: another thread reads a whole tuple
        return est

    def to_state(self):
        """``(arrays, meta)``: everything of a fitted estimator, arrays apart and the rest JSON-friendly (for the
        model files of :mod:`interprim.io`; no pickle).  :meth:`from_state` restores it."""
        self._check_fitted()
        arrays, meta = {}, {}
        for k, v in vars(self).items():
            if k == "_kept":  # the last estimate kept (:meth:`_estimate_at`), not the fitted state
                continue
            if isinstance(v, np.ndarray):
                arrays[k] = v
            else:
                meta[k] = jsonable(v)
        return arrays, meta

    @classmethod
    def from_state(cls, arrays, meta) -> LearnedPhase:
        """The estimator saved by :meth:`to_state`."""
        obj = cls.__new__(cls)
        for k, v in meta.items():
            setattr(obj, k, tuple(v) if k in ("features", "features_", "cv_range") and isinstance(v, list) else v)
        for k, v in arrays.items():
            setattr(obj, k, np.asarray(v))
        cls._check_fitted(obj)
        cls._check_state(obj)
        return obj

    def _check_state(self) -> None:
        """The values a model file gave (:meth:`from_state`), checked before any estimate divides by or allocates
        with them: :class:`~interprim.core.errors.ModelFileError` naming the field and its value."""
        from ..core import state_checks as check
        from ..core.errors import ModelFileError

        try:
            self._check_params()
        except (TypeError, ValueError) as exc:
            raise ModelFileError(f"inconsistent parameters of the learned phase: {exc}") from None
        self.dt_ = check.number("phase.dt_", self.dt_, positive=True)
        self.mean_duration_ = check.number("phase.mean_duration_", self.mean_duration_, positive=True)
        D = check.integer("phase.n_dofs_", self.n_dofs_, 1, check.MAX_GRID)
        S = check.integer("phase.n_demos_", self.n_demos_, 1, check.MAX_GRID)
        K = check.integer("phase.n_grid_", self.n_grid_, 1, check.MAX_GRID)
        check.integer("phase._w", self._w, 1, check.MAX_GRID)
        check.integer("phase.history", self.history, 1, check.MAX_GRID)
        check.size("phase.history", (self.history + 1) * D)
        self.scale_ = check.array("phase.scale_", self.scale_, (D,), positive=True)
        self.durations_ = check.array("phase.durations_", self.durations_, (S,), positive=True)
        self.std_grid_ = check.array("phase.std_grid_", self.std_grid_, (K,), nonneg=True)
        if self.method_ not in ("clock",) + _MODELS:
            check.fail("phase.method_", self.method_, f"not one of {('clock',) + _MODELS}")
        feats = self.features_
        if not isinstance(feats, tuple) or (not feats and self.method_ != "clock") or any(
                f not in FEATURE_GROUPS for f in feats):
            check.fail("phase.features_", feats, f"not a list of the feature groups {FEATURE_GROUPS}")

    def tracker(self) -> PhaseTracker:
        """An online estimator fed one frame at a time (features updated in ``O(D)`` per frame)."""
        self._check_fitted()
        return PhaseTracker(self)

    def __repr__(self):
        if not hasattr(self, "method_"):
            return "LearnedPhase()"
        hyp = f", bandwidth={self.bandwidth_:.3g}" if self.bandwidth_ is not None else (
            f", alpha={self.alpha_:.3g}" if self.alpha_ is not None else "")
        return (f"LearnedPhase(method={self.method_!r}, target={self.target_!r}, features={self.features_}{hyp}, "
                f"cv_error={self.cv_error_:.4f}, clock={self.cv_error_clock_:.4f})")


class PhaseTracker:
    """Online :class:`LearnedPhase`: one frame at a time, at the training sampling interval.

    The features are updated incrementally (first frame, last frame, a ring buffer of
    the last ``w + 1`` frames for the windowed velocity, running path length and peak
    speed), so an update costs ``O(D)`` plus the regression's ``O(n_demos * p)``; the
    estimate equals :meth:`LearnedPhase.estimate` on all frames seen (to rounding).
    Frames are assumed to arrive every ``dt_`` seconds (resample otherwise).
    """

    def __init__(self, model: LearnedPhase):
        self.model = model
        self._inv_scale = 1.0 / model.scale_
        self._buf = np.zeros((model.window_ + 1, model.n_dofs_))
        self._hist = np.zeros((64, model.n_dofs_)) if "history" in model.features_ else None
        self._q = np.arange(1, model.history + 1) / (model.history + 1)
        self._shape = (model.n_dofs_,)
        dims = group_dims(model.features_, model.n_dofs_, model.history)
        self._slices = dict(zip(model.features_, (slice(a - b, a) for a, b in zip(np.cumsum(dims), dims))))
        self._f = np.zeros(int(sum(dims)))
        self.reset()

    def reset(self):
        """Forget all frames (start a new movement)."""
        self.n_frames = 0
        self._path = 0.0
        self._peak = 0.0

    def update(self, frame) -> PhaseEstimate:
        """Add the next frame (shape ``(D,)``); returns the estimate after it."""
        m = self.model
        if type(frame) is np.ndarray and frame.dtype == np.float64 and frame.shape == self._shape:
            y = frame * self._inv_scale
            if not math.isfinite(float(y.sum())):
                as_frame(frame, "frame", m.n_dofs_)  # raises the usual message
                raise ValueError("frame contains NaN or inf")
        else:
            y = as_frame(frame, "frame", m.n_dofs_) * self._inv_scale
        w = m.window_
        k = self.n_frames
        buf = self._buf
        if k == 0:
            self._first = y.copy()
            self._last = y.copy()
        else:
            d = y - self._last
            self._path += math.sqrt(float(d @ d))
            self._last = y.copy()
        buf[k % (w + 1)] = y
        if self._hist is not None:  # every frame is kept (amortised O(D)): the history group looks back at q k
            if k >= self._hist.shape[0]:
                self._hist = np.concatenate([self._hist, np.zeros_like(self._hist)])
            self._hist[k] = y
        self.n_frames = k + 1
        if k == 0 or m.method_ == "clock":
            return m.estimate_at(k * m.dt_, None)
        back = max(k - w, 0)
        vel = (y - buf[back % (w + 1)]) / ((k - back) * m.dt_)
        sp = math.sqrt(float(vel @ vel))
        if sp > self._peak:
            self._peak = sp
        out = self._f
        for g, sl in self._slices.items():
            if g == "position":
                out[sl] = y
            elif g == "displacement":
                np.subtract(y, self._first, out=out[sl])
            elif g == "velocity":
                out[sl] = vel
            elif g == "path":
                out[sl] = self._path
            elif g == "peak_speed":
                out[sl] = self._peak
            elif g == "history":
                x = self._q * k
                lo = x.astype(np.int64)  # floor (x >= 0)
                f = (x - lo)[:, None]
                h = self._hist
                assert h is not None  # kept when the model uses the history group
                out[sl] = ((1.0 - f) * h[lo] + f * h[np.minimum(lo + 1, k)] - self._first).ravel()
        return m.estimate_at(k * m.dt_, out)

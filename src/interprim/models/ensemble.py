"""The model chosen on the user's own demonstrations: several families compared on held-out folds, then blended.

:class:`AutoInteraction` (what ``interprim fit`` gives by default) runs the real-time protocol of
:mod:`interprim.model_selection.realtime` in a ``folds``-fold cross-validation on the *training* demonstrations for
each candidate family -- the Interaction Primitive with the library's defaults (``ip``),
:class:`~interprim.models.learned.LearnedInteraction` (``learned``), the kernel-weighted demonstrations (``kernel``,
:class:`~interprim.models.kernel.KernelDemonstrations`), the nearest demonstration (``nn``) and the mean
demonstration at the mean speed (``prior``) -- and keeps, for every held-out case, each family's prediction of the
controlled agent over the next ``horizon`` seconds (:class:`CrossValidation`).  From them it fits a :class:`Blend`:
the convex weights that minimise the protocol's own error (stacking; a choice of one family made on 12-20
demonstrations proved noisy: on the project's hold-out it picked a worse family on one NuiSI interaction of six),
and a variance fitted to the held-out errors step by step over the look-ahead.  ``combine="best"`` keeps the
family with the smallest held-out error alone.  Predictions, streams and model files follow
:mod:`interprim.models.base`; ``selection_`` says what was compared and chosen, and by how much.
"""

from __future__ import annotations

import warnings

import numpy as np

from ..core.blas import one_blas_thread
from ..model_selection.metrics import Z90, point_rms
from ..model_selection.realtime import RealTimeConfig, place_in_time, realtime_sweep
from . import registry
from ..core.errors import OutOfRangeWarning
from ..core.input_range import fit_input_range, mark
from .base import BaseStream, CheckedStream, GridPrediction, Predictor, uniform_demonstrations
from ..core.preprocessing import interp_columns, unit_grid

__all__ = ["AutoInteraction", "Blend", "CrossValidation", "CANDIDATES", "COMBINE"]

#: The families compared by default (:data:`interprim.models.registry.CANDIDATES`).
CANDIDATES = registry.CANDIDATES


def look_ahead_bands(horizon: float, longest: float) -> np.ndarray:
    """Upper edges (s) of the look-ahead bands over which the blend's weights are fitted: ``horizon`` (the real-time
    band), then doubling, up to ``longest`` (the rest of the longest movement)."""
    edges = [float(horizon)]
    while edges[-1] < longest:
        edges.append(edges[-1] * 2.0)
    return np.array(edges)


def weights_at(ahead, edges, W) -> np.ndarray:
    """Blend weights ``(len(ahead), families)`` at ``ahead`` seconds after now, from the weights ``W`` ``(bands,
    families)`` fitted per look-ahead band (upper edges ``edges``): linear between the bands' middles, held beyond
    the first and the last, renormalised onto the simplex (so the blend moves smoothly from the real-time weights
    to the whole-movement weights, with no jump at a band's edge)."""
    W = np.atleast_2d(np.asarray(W, dtype=np.float64))
    ahead = np.asarray(ahead, dtype=np.float64)
    if W.shape[0] == 1:
        return np.broadcast_to(W[0], (ahead.size, W.shape[1])).copy()
    edges = np.asarray(edges, dtype=np.float64)
    mids = 0.5 * (np.concatenate([[0.0], edges[:-1]]) + edges)
    out = interp_columns(ahead, mids, W)
    out = np.clip(out, 0.0, None)
    return out / np.maximum(out.sum(axis=1, keepdims=True), 1e-300)


def scoring_config(horizon: float, train, dt: float, **kw) -> RealTimeConfig:
    """The inner cross-validation's protocol: every case scored from the next frame to the end of the longest
    training movement, so that the blend's weights and variance are fitted for every look-ahead, not only for the
    real-time ``horizon`` (``kw``: other :class:`~interprim.model_selection.realtime.RealTimeConfig` fields)."""
    longest = max((len(d) - 1) * float(dt) for d in train)
    return RealTimeConfig(horizon=max(float(horizon), longest), **kw)


#: The smallest weight (in some look-ahead band) for which a family stays a member of the blend.
MIN_WEIGHT = 0.05


def blend_from_cv(cv: "CrossValidation", make: dict, train, dt: float, observed_dofs, horizon: float,
                  n_basis: int = 20, smoothing_window=None, progress=None) -> tuple:
    """``(Blend, record)``: the blend of the families compared by ``cv``, fitted on ``train``.

    Weights are fitted per look-ahead band (:func:`look_ahead_bands`: ``horizon``, then doubling to the longest
    look-ahead ``cv`` scored) by :meth:`CrossValidation.blend_weights` on that band's steps; the variance model on
    every step with the weights there (:func:`weights_at`).  ``record``: ``weights`` (the real-time band's),
    ``band_weights``, ``bands``, ``blend_cv_error`` (real-time band, in-sample for the weights) and
    ``variance_model``."""
    edges = look_ahead_bands(float(horizon), float(cv.t_ahead[-1]))
    steps = [s for i, s in enumerate(cv.band_steps(edges)) if i == 0 or cv.valid[:, s].any()]
    edges = [float(cv.t_ahead[s[-1]]) for s in steps]  # the bands with held-out frames, up to their last step
    W = np.array([cv.blend_weights(s) for s in steps])  # (bands, families)
    # a member that never carries MIN_WEIGHT of any band costs a stream per frame for almost nothing: the
    # weights are fitted again without it
    keep = [i for i in range(len(cv.names)) if np.max(W[:, i]) >= MIN_WEIGHT] or [int(np.argmax(W.max(axis=0)))]
    names = [cv.names[i] for i in keep]
    sub = cv.subset(names)
    if len(keep) < len(cv.names):
        W = np.array([sub.blend_weights(s) for s in steps])
    W = W / W.sum(axis=1, keepdims=True)
    per_step = weights_at(cv.t_ahead, edges, W)
    scales = sub.blend_scales(per_step)
    scales["t"] = cv.t_ahead
    band_weights = {m: [float(x) for x in W[:, i]] for i, m in enumerate(names)}
    members = {}
    if progress is not None:
        progress.grow(len(names))
    for m in names:
        members[m] = make[m]().fit(train, dt=dt)
        if progress is not None:
            progress.step(f"fitted {m}")
    blend = Blend.from_fitted(observed_dofs, members, band_weights, scales, train, dt, horizon, bands=edges,
                              n_basis=n_basis, smoothing_window=smoothing_window)
    record = {"weights": {m: float(W[0, i]) for i, m in enumerate(names)}, "band_weights": band_weights,
              "bands": edges, "blend_cv_error": sub.blend_error(per_step),
              "variance_model": {k: np.asarray(v).tolist() for k, v in scales.items()}}
    return blend, record


class _Progress:
    """A progress bar (tqdm, when installed and asked for) over the steps of a fit; silent otherwise."""

    def __init__(self, on: bool, total: int):
        self.bar = None
        if on:
            try:
                from tqdm import tqdm
            except ImportError:  # the [experiments] extra; without it, one line per step on stderr
                tqdm = None
            self.bar = tqdm(total=total, desc="fit", unit="step", leave=False) if tqdm else _Lines(total)

    def grow(self, n: int):
        """``n`` more steps than announced (the members to fit, known once the weights are)."""
        if self.bar is not None:
            self.bar.total += int(n)

    def step(self, what: str = ""):
        if self.bar is not None:
            if what:
                self.bar.set_postfix_str(what, refresh=False)
            self.bar.update(1)

    def close(self):
        if self.bar is not None:
            self.bar.close()


class _Lines:
    def __init__(self, total):
        self.total, self.n, self.what = total, 0, ""

    def set_postfix_str(self, what, refresh=False):
        self.what = what

    def update(self, k):
        import sys

        self.n += k
        print(f"fit: step {self.n}/{self.total} {self.what}", file=sys.stderr, flush=True)

    def close(self):
        pass


#: How the compared families are used: a weighted blend of them (``"blend"``) or the best one alone (``"best"``).
COMBINE = ("blend", "best")


class CrossValidation:
    """What the inner cross-validation of :class:`AutoInteraction` saw, case by case.

    One case is one evaluated frame of one held-out training demonstration; for every family that could be
    fitted on every inner fold, the prediction of the next ``horizon`` seconds placed in time by the family's own
    timing (:func:`interprim.model_selection.realtime.place_in_time`), and the truth.

    Attributes
    ----------
    errors : dict
        ``{family: mean real-time error of the controlled agent}`` (``inf``: could not be fitted on a fold).
    names : list of str
        The families with finite errors, in the order of the arrays below.
    mean : ndarray, shape (n_families, n_cases, H, D)
        Placed predictions.
    truth : ndarray, shape (n_cases, H, D)
    controlled, observed : list of int
        Columns of the two agents.
    """

    def __init__(self, make, demos, observed_dofs, dt, cfg, k, horizon=None, progress=None):
        import warnings

        from ..core.errors import OutOfRangeWarning, RepresentationWarning

        self.observed = [int(i) for i in observed_dofs]
        self.point_dim = int(cfg.point_dim)
        self.dt = float(dt)
        #: seconds of the real-time band (the protocol's look-ahead; ``cfg.horizon`` may reach further)
        self.horizon = float(cfg.horizon if horizon is None else horizon)
        self.errors, per = {}, {}
        #: ``{family: why it could not be compared}`` for the families with an infinite error
        self.why = {}
        for name, factory in make.items():
            try:
                # only the family's errors and placed means are kept: its std and the clock's records are skipped
                with warnings.catch_warnings():  # about held-out training folds, not the user's data
                    warnings.simplefilter("ignore", OutOfRangeWarning)
                    warnings.simplefilter("ignore", RepresentationWarning)
                    recs = realtime_sweep({name: factory}, demos, self.observed, dt, cfg, k=k, trace=True,
                                          std=False, references=False)
            except ValueError as exc:  # e.g. too few demonstrations in an inner training fold for this family
                self.errors[name] = float("inf")
                self.why[name] = str(exc).splitlines()[0]
                continue
            finally:
                if progress is not None:
                    progress.step(f"compared {name}")
            per[name] = {(r["demo"], r["k"]): r for r in recs if r["method"] == name}
            self.errors[name] = float(np.mean([self._rt_error(r["mean"], r["truth"]) for r in per[name].values()])
                                      ) if per[name] else float("inf")
        self.names = [m for m in per if np.isfinite(self.errors[m])]
        cases = sorted(set.intersection(*(set(per[m]) for m in self.names))) if self.names else []
        first = per[self.names[0]] if self.names else {}
        self.truth = np.array([first[c]["truth"] for c in cases], dtype=np.float64)
        self.mean = np.array([[per[m][c]["mean"] for c in cases] for m in self.names], dtype=np.float64)
        D = self.truth.shape[-1] if self.truth.size else len(self.observed)
        self.controlled = [i for i in range(D) if i not in set(self.observed)]
        H = self.truth.shape[1] if self.truth.ndim == 3 else 0
        #: seconds ahead of every step of the arrays
        self.t_ahead = np.arange(1, H + 1) * self.dt
        #: ``(cases, H)``: whether the step is a frame of the held-out movement (not past its end, where the
        #: protocol holds the last frame); the weights and the band beyond the real-time horizon are fitted on these
        n_left = np.array([int(round(c[1] / first[c]["fraction"])) - c[1] for c in cases], dtype=np.int64)
        self.valid = np.arange(H)[None, :] < n_left[:, None] if H else np.zeros((len(cases), 0), dtype=bool)

    def _rt_error(self, mean, truth):
        """Real-time error of one case: RMS point error of the controlled agent over the real-time band."""
        n = max(1, int(round(self.horizon / self.dt)))
        cols = self.controlled_cols(np.asarray(truth).shape[-1])
        return point_rms((np.asarray(mean) - np.asarray(truth))[:n][:, cols], self.point_dim)

    def controlled_cols(self, D):
        """The controlled agent's columns (the observed ones for a single-agent model)."""
        ctrl = [i for i in range(D) if i not in set(self.observed)]
        return ctrl or self.observed

    def band_steps(self, edges) -> list:
        """Step indices of each look-ahead band (upper edges ``edges`` in seconds; each band non-empty)."""
        out, lo = [], 0.0
        for e in edges:
            idx = np.flatnonzero((self.t_ahead > lo + 1e-12) & (self.t_ahead <= e + 1e-12))
            if idx.size:
                out.append(idx)
            lo = e
        return out

    def subset(self, names) -> "CrossValidation":
        """The same cases restricted to the families ``names`` (those with finite errors, in this order)."""
        keep = [i for i, m in enumerate(self.names) if m in set(names)]
        out = object.__new__(type(self))
        out.__dict__.update(self.__dict__)
        out.errors = {m: e for m, e in self.errors.items() if m in set(names)}
        out.names = [self.names[i] for i in keep]
        out.mean = self.mean[keep]
        return out

    def blend_weights(self, steps=None) -> np.ndarray:
        """Weights on the simplex (one per family of :attr:`names`) that minimise the blend's mean error of the
        controlled agent over the cases at the look-ahead ``steps`` (default: every step): the RMS over the case's
        steps inside its held-out movement (:attr:`valid`; the real-time band counts every step, as the protocol
        does), averaged over cases -- for the real-time band the very figure :attr:`errors` reports (stacking,
        Breiman 1996, on the protocol's own loss: a convex problem whose solution is a convex combination, so the
        blend can always fall back on a single family).  Squared-error stacking was tried first: a few large errors
        decided the weights and the blend came out worse than its best member on the protocol's loss."""
        from scipy.optimize import minimize

        M = len(self.names)
        if M == 1:
            return np.ones(1)
        c = self.controlled or self.observed
        sel = np.arange(self.truth.shape[1]) if steps is None else np.asarray(steps)
        n_rt = max(1, int(round(self.horizon / self.dt)))
        mask = self.valid[:, sel] | (sel < n_rt)[None, :]  # (cases, S)
        keep = mask.any(axis=1)
        mask = mask[keep]
        C = len(c)
        P = self.mean[:, keep][:, :, sel][..., c]  # (M, cases, S, C)
        T = self.truth[keep][:, sel][..., c]
        scale = max(float(np.sqrt(np.mean(T * T))), 1e-300)
        P, T = P / scale, T / scale
        W = mask[:, :, None].astype(np.float64)  # (cases, S, 1)
        count = W.sum(axis=(1, 2)) * C

        def loss(w):
            e = (np.tensordot(w, P, axes=1) - T) * W
            r = np.sqrt(np.sum(e * e, axis=(1, 2)) / count) + 1e-12
            grad = np.einsum("mcsj,csj->m", P, e / (r * count)[:, None, None]) / len(r)
            return float(np.mean(r)), grad

        start = np.full(M, 1.0 / M)
        best = min(range(M), key=lambda m: loss(np.eye(M)[m])[0])
        res = minimize(loss, start, jac=True, bounds=[(0.0, 1.0)] * M, method="SLSQP",
                       constraints=({"type": "eq", "fun": lambda w: w.sum() - 1.0},),
                       options={"ftol": 1e-10, "maxiter": 300})
        w = np.clip(res.x, 0.0, None)
        w[w < 1e-3] = 0.0
        w = w / w.sum()
        vertex = np.eye(M)[best]
        return w if loss(w)[0] <= loss(vertex)[0] else vertex

    def blend_scales(self, w) -> dict:
        """The blend's variance model over the look-ahead, fitted to its held-out errors: per step ahead ``h`` and
        column ``j``, ``var = a[h, j] * spread^2 + b[h, j]`` with ``spread^2`` the weighted disagreement of the
        members, ``sum_m w_m (y_m - mean)^2``.  Where the spread alone is narrower than the held-out error,
        ``a = 1`` and ``b`` adds the rest; where it is wider, ``b = 0`` and ``a < 1`` narrows it, so that the mean
        predicted variance equals the mean squared held-out error at every step and column.  Held-out errors are
        heavier-tailed than a normal distribution, so matching the variance alone leaves the 90 % band short (72-91
        % on the synthetic hold-out over the rest of the movement); both ``a`` and ``b`` are then scaled, per step
        and agent, by ``(q90 / 1.645)^2`` with ``q90`` the 90th percentile of the standardised held-out errors
        ``|e| / sd``: the band ``mean +- 1.645 sd`` covers 90 % of the held-out cases at every step ahead.

        The members' own std is not used: it does not carry over from the inner folds' smaller training sets to
        the final fit (``LearnedInteraction``'s was 4x its error when fitted on 9 NuiSI demonstrations, about
        right on 13), whereas their disagreement and the residual do.

        Returns ``{"a": (H, D), "b": (H, D)}``.
        """
        w = np.asarray(w, dtype=np.float64)
        w = (w[:, None] if w.ndim == 1 else w.T)[:, None, :, None]  # (M, 1, H or 1, 1)
        mix = np.sum(w * self.mean, axis=0)
        n_rt = max(1, int(round(self.horizon / self.dt)))
        valid = self.valid | (np.arange(self.truth.shape[1]) < n_rt)[None, :]  # (cases, H)
        n_valid = valid.sum(axis=0)
        has = n_valid > 0
        last = int(np.flatnonzero(has)[-1]) if has.any() else 0
        vw = valid[:, :, None].astype(np.float64)

        def step_mean(x):  # mean over the valid cases of every step, held from the last step that has any
            m = np.sum(x * vw, axis=0) / np.maximum(n_valid, 1)[:, None]
            m[~has] = m[last]
            return m

        case_spread = np.sum(w * (self.mean - mix) ** 2, axis=0)  # (cases, H, D)
        spread = step_mean(case_spread)
        err2 = step_mean((mix - self.truth) ** 2)
        wide = spread > err2
        a = np.where(wide, err2 / np.where(spread > 0, spread, 1.0), 1.0)
        b = np.where(wide, 0.0, err2 - spread)

        sd = np.sqrt(np.maximum(a * case_spread + b, 1e-300))
        z = np.abs(mix - self.truth) / sd
        for cols in (self.controlled, self.observed):
            if cols and z.shape[0]:
                q = np.ones(z.shape[1]) * Z90
                for h in np.flatnonzero(has):
                    q[h] = np.quantile(z[valid[:, h]][:, h][:, cols], 0.9, method="higher")
                q[~has] = q[last]
                r2 = (np.maximum(q, 1e-6) / Z90)[:, None] ** 2
                a[:, cols] *= r2
                b[:, cols] *= r2
        return {"a": a, "b": b}

    def blend_error(self, w) -> float:
        """The blend's mean real-time error of the controlled agent over the cases, as :attr:`errors` measures it
        (in-sample for the weights: an optimistic figure)."""
        w = np.asarray(w, dtype=np.float64)
        if w.ndim == 2:  # per-step weights (H, M): the real-time band's
            w = w[0]
        n = max(1, int(round(self.horizon / self.dt)))
        mix = np.tensordot(w, self.mean[:, :, :n], axes=1)
        e = (mix - self.truth[:, :n])[..., self.controlled or self.observed]
        n_case, H, C = e.shape
        pd = self.point_dim if C % self.point_dim == 0 else 1
        point2 = np.sum(e.reshape(n_case, H, C // pd, pd) ** 2, axis=3)  # squared point errors
        return float(np.mean(np.sqrt(point2.mean(axis=(1, 2)))))


class AutoInteraction(Predictor):
    """The model chosen on the user's own demonstrations: several families compared on held-out folds.

    ``fit`` runs the real-time protocol of :mod:`interprim.model_selection.realtime` in a ``folds``-fold
    cross-validation on the *training* demonstrations for each candidate family and then, with ``combine="blend"``
    (the default), fits a convex combination of the families' predictions placed in time, with weights that
    minimise the held-out error (stacking) and a std calibrated to the held-out error step by step over the
    look-ahead (:class:`Blend`); with ``combine="best"`` it uses the family with the smallest held-out error alone.
    Predictions, streams and model files follow :mod:`interprim.models.base`; ``selection_`` says what was chosen and
    by how much.

    Parameters
    ----------
    observed_dofs : sequence of int
        The observed agent's columns.
    candidates : sequence of str, default CANDIDATES
        Families to compare, among ``ip``, ``learned``, ``ip-paper``, ``kernel``, ``nn``, ``prior``
        (:data:`interprim.models.registry.FAMILIES`).
    combine : {"blend", "best"}, default "blend"
        Blend the families, or keep the best one.
    folds : int, default 3
        Folds of the cross-validation (at least 2; fewer demonstrations than folds: leave-one-out).
    horizon : float, default 0.25
        Seconds ahead scored by the real-time protocol (and over which the blend's std is calibrated).
    stride : int, default 3
        Score every ``stride``-th frame (speed).
    n_basis : int, default 20
        Basis functions of the Interaction Primitive candidates.
    smoothing_window : int or None
        Savitzky-Golay window of the Interaction Primitive candidates.
    point_dim : int, default 1
        Columns per point in the error (3 for 3-D positions), as in
        :class:`~interprim.model_selection.realtime.RealTimeConfig`.
    progress : bool, default False
        Show the fit's progress (a tqdm bar when installed, else one line per step on stderr); ``interprim fit``
        turns it on.

    Attributes
    ----------
    observed_dofs_, controlled_dofs_, n_dofs_, dt_, mean_duration_, columns_
        The two agents' columns, the number of columns, the sampling interval, the mean duration (s) and the
        column names (``None`` without names) of the demonstrations.
    chosen_ : str
        The family with the smallest held-out error (``"blend"`` is not a family: see ``weights_``).
    weights_ : dict
        ``{family: weight}`` of the blend (``{chosen_: 1.0}`` with ``combine="best"``).
    model_ : Predictor
        The model used: a :class:`Blend` or the chosen family, fitted on all the demonstrations.
    selection_ : dict
        ``chosen``, ``cv_errors`` (``{family: mean held-out real-time error}``, ``inf`` when a family could not be
        fitted on a fold), ``runner_up`` and ``margin`` (its error / the chosen one's), ``vs_prior`` (the chosen
        one's error / the mean demonstration's at the mean speed), ``combine``, ``weights`` and, for a blend,
        ``blend_cv_error`` (in-sample for its weights), ``blend_vs_best`` and ``variance_model`` (``a``, ``b`` of
        :meth:`CrossValidation.blend_scales`).
    """

    _FITTED = "model_"
    _CHECKS_INPUT = True
    #: 2: the training frames' range (the out-of-range check) and per-look-ahead blend weights
    STATE_VERSION = 2
    CANDIDATES = CANDIDATES

    def __init__(self, observed_dofs, candidates=CANDIDATES, combine: str = "blend", folds: int = 3,
                 horizon: float = registry.DEFAULT_HORIZON, stride: int = 3, n_basis: int = 20, smoothing_window=None,
                 point_dim: int = 1, progress: bool = False):
        self.observed_dofs = observed_dofs
        self.candidates = candidates
        self.combine = combine
        self.folds = folds
        self.horizon = horizon
        self.stride = stride
        self.n_basis = n_basis
        self.smoothing_window = smoothing_window
        self.point_dim = point_dim
        self.progress = progress

    def _check(self):
        known = list(registry.FAMILIES)
        bad = [c for c in self.candidates if c not in known]
        if bad or not self.candidates:
            raise ValueError(f"candidates must name some of {known}, got {list(self.candidates)!r}")
        if self.combine not in COMBINE:
            raise ValueError(f"combine must be one of {COMBINE}, got {self.combine!r}")
        if not (isinstance(self.folds, (int, np.integer)) and self.folds >= 2):
            raise ValueError(f"folds must be an integer >= 2, got {self.folds!r}")
        if not (isinstance(self.horizon, (int, float)) and self.horizon > 0):
            raise ValueError(f"horizon must be a positive number of seconds, got {self.horizon!r}")
        if not (isinstance(self.stride, (int, np.integer)) and self.stride >= 1):
            raise ValueError(f"stride must be an integer >= 1, got {self.stride!r}")
        if not (isinstance(self.point_dim, (int, np.integer)) and self.point_dim >= 1):
            raise ValueError(f"point_dim must be an integer >= 1, got {self.point_dim!r}")

    def factories(self) -> dict:
        """``{family: factory of an unfitted estimator}`` of the candidates, with this model's settings."""
        return registry.factories(self.candidates, self.settings())

    def settings(self) -> "registry.Settings":
        """The settings every member is built with (given once here and passed down to each family)."""
        return registry.Settings(tuple(self.observed_dofs), n_basis=self.n_basis,
                                 smoothing_window=self.smoothing_window, horizon=float(self.horizon))

    @one_blas_thread
    def fit(self, demos, dt: float | None = None):
        """Compare the candidate families on held-out folds of ``demos``, then fit the blend (or the best) on all.

        Parameters
        ----------
        demos : list of ndarray, shape (T_j, D), or Demonstrations
            At least 3 demonstrations (a :class:`~interprim.datasets.Demonstrations` with raw samples gives the
            cross-validation causal prefixes).
        dt : float, optional
            Sampling interval in seconds (default: the Demonstrations' ``dt``, else 0.01).

        Returns
        -------
        AutoInteraction
            ``self``.
        """
        self._check()
        source = demos
        train, dt, cols = uniform_demonstrations(demos, dt)
        n = len(train)
        if n < 3:
            raise ValueError(f"AutoInteraction needs at least 3 demonstrations to compare families, got {n}")
        # a Demonstrations sampled at a common interval keeps its raw samples (causal prefixes in the inner CV);
        # irregular stamps were resampled above and the CV sees the resampled frames
        cv_demos = source if getattr(source, "dt", None) is not None and hasattr(source, "times") else train
        make = self.factories()
        cfg = scoring_config(float(self.horizon), train, dt, stride=int(self.stride), point_dim=int(self.point_dim))
        progress = _Progress(self.progress, len(make))
        if len(make) == 1:  # nothing to compare: the one family, fitted (with the file's column names kept)
            cv = None
            chosen = next(iter(make))
            selection = _record(chosen, {chosen: float("nan")})
        else:
            cv = CrossValidation(make, cv_demos, self.observed_dofs, dt, cfg, k=min(int(self.folds), n),
                                 horizon=float(self.horizon), progress=progress)
            chosen, selection = choice(cv, list(make))
            if cv.why:
                selection["not_compared"] = dict(cv.why)
        if self.combine == "blend" and cv is not None and len(cv.names) > 1:
            self.model_, info = blend_from_cv(cv, make, train, dt, self.observed_dofs, float(self.horizon),
                                              n_basis=self.n_basis, smoothing_window=self.smoothing_window,
                                              progress=progress)
            weights = info["weights"]
            selection.update(combine="blend", **info)
            best = selection["cv_errors"][chosen]
            selection["blend_vs_best"] = selection["blend_cv_error"] / best if best > 0 else float("nan")
        else:
            progress.grow(1)
            self.model_ = make[chosen]().fit(train, dt=dt)
            progress.step(f"fitted {chosen}")
            weights = {chosen: 1.0}
            selection.update(combine="best", weights=weights)
        progress.close()
        dt = float(dt)
        self.chosen_ = chosen
        self.weights_ = weights
        self.observed_dofs_ = [int(i) for i in self.observed_dofs]
        self.n_dofs_ = int(train[0].shape[1])
        self.controlled_dofs_ = [i for i in range(self.n_dofs_) if i not in set(self.observed_dofs_)]
        self.dt_ = float(dt)
        self.mean_duration_ = float(np.mean([len(d) - 1 for d in train])) * self.dt_
        self.columns_ = cols
        self.selection_ = selection
        self.set_input_range(fit_input_range(np.concatenate([d[:, self.observed_dofs_] for d in train])))
        return self

    def predict(self, partial, **kwargs):
        """The model's prediction (:meth:`interprim.models.base.Predictor` contract), with ``input_distance`` and
        ``out_of_range`` of the frames against the training demonstrations (:mod:`interprim.core.input_range`;
        an :class:`~interprim.OutOfRangeWarning` when out of range)."""
        self._check_fitted("predict")
        with warnings.catch_warnings():  # the members' own checks: this model warns once, below
            warnings.simplefilter("ignore", OutOfRangeWarning)
            pred = self.model_.predict(partial, **kwargs)
        return mark(self, pred, self.input_distance(partial))

    def stream(self, robot_state=None):
        """The model's online predictor, each prediction marked with the largest input distance of the frames
        seen so far (warned once per stream)."""
        self._check_fitted("stream")
        return CheckedStream(self, self.model_.stream(robot_state))

    def to_state(self):
        """``(arrays, meta)``: the model's state with its class and parameters."""
        self._check_fitted("to_state")
        arrays, meta = self.model_.to_state()
        return ({f"model_{k}": v for k, v in arrays.items()},
                {"chosen": self.chosen_, "class": type(self.model_).__name__, "params": self.model_.json_params(),
                 "state": meta, "selection": self.selection_, "observed_dofs_": self.observed_dofs_,
                 "weights": self.weights_, "n_dofs_": self.n_dofs_, "dt_": self.dt_, "columns_": self.columns_,
                 "mean_duration_": self.mean_duration_,
                 "input_range": [np.asarray(self.input_range_[0]).tolist(), np.asarray(self.input_range_[1]).tolist(),
                                 float(self.input_range_[2])]})

    def load_state(self, arrays, meta):
        """Restore the state written by :meth:`to_state`."""
        inner = {k[len("model_"):]: v for k, v in arrays.items() if k.startswith("model_")}
        self.model_ = _restore(meta["class"], meta["params"], inner, meta["state"])
        self.chosen_ = str(meta["chosen"])
        self.selection_ = dict(meta["selection"])
        self.observed_dofs_ = [int(i) for i in meta["observed_dofs_"]]
        self.weights_ = {str(k): float(v) for k, v in meta.get("weights", {self.chosen_: 1.0}).items()}
        self.n_dofs_ = int(meta["n_dofs_"])
        self.controlled_dofs_ = [i for i in range(self.n_dofs_) if i not in set(self.observed_dofs_)]
        self.dt_ = float(meta["dt_"])
        self.mean_duration_ = float(meta["mean_duration_"])
        cols = meta.get("columns_")
        self.columns_ = None if cols is None else [str(c) for c in cols]
        # a file of version 1 has no statistics: no check (input_distance NaN)
        self.set_input_range(meta.get("input_range"))
        if self.input_range_ is not None and self.input_range_[0].shape != (len(self.observed_dofs_),):
            raise ValueError("input_range does not match the observed columns")

    def __repr__(self):
        if not hasattr(self, "model_"):
            return f"AutoInteraction(observed_dofs={self.observed_dofs!r}, candidates={list(self.candidates)!r})"
        s = self.selection_
        if s.get("runner_up") is None:
            return f"AutoInteraction({self.chosen_!r} alone)"
        best = (f"best family {self.chosen_!r}: held-out real-time error {s['margin']:.2f}x better than "
                f"{s['runner_up']!r}, {s['vs_prior']:.2f}x the mean at the mean speed")
        if s.get("combine") == "blend":
            w = ", ".join(f"{m} {x:.2f}" for m, x in sorted(self.weights_.items(), key=lambda kv: -kv[1]))
            return f"AutoInteraction(blend of {w}; {s['blend_vs_best']:.2f}x the best family's error; {best})"
        return f"AutoInteraction(chose {self.chosen_!r}: {best[len('best family ' + repr(self.chosen_)) + 2:]})"

    def summary(self) -> str:
        """A few lines: what was compared, what was chosen, and by how much."""
        s = self.selection_
        if s.get("runner_up") is None:
            return f"model: {self.chosen_} alone ({type(self.model_).__name__})"
        lines = ["held-out real-time error of the controlled agent, by family (inner cross-validation):"]
        why = s.get("not_compared", {})
        for m, e in sorted(s["cv_errors"].items(), key=lambda kv: kv[1]):
            tag = " <- best" if m == self.chosen_ else ""
            if np.isfinite(e):
                lines.append(f"  {m:10s} {e:.4g}{tag}")
            else:
                lines.append(f"  {m:10s} not compared: {why.get(m, 'could not be fitted on every inner fold')}")
        if s.get("combine") == "blend":
            w = ", ".join(f"{m} {x:.2f}" for m, x in sorted(self.weights_.items(), key=lambda kv: -kv[1]))
            lines.append(f"blend: {w} -> {s['blend_cv_error']:.4g} ({s['blend_vs_best']:.2f}x the best family; "
                         f"in-sample for its weights)")
        else:
            lines.append(f"using {self.chosen_} alone")
        return "\n".join(lines)


def choice(cv: CrossValidation, order) -> tuple:
    """``(best family, selection record)`` from a :class:`CrossValidation` (ties: the earlier in ``order``)."""
    errors = cv.errors
    finite = {m: e for m, e in errors.items() if np.isfinite(e)}
    if not finite:
        why = "; ".join(f"{m}: {w}" for m, w in getattr(cv, "why", {}).items())
        raise ValueError("no candidate family could be fitted on every inner training fold" + (f" ({why})" if why else ""))
    chosen = min(finite, key=lambda m: (finite[m], list(order).index(m)))
    return chosen, _record(chosen, errors)


def _restore(cls_name, params, arrays, state):
    if cls_name == "Blend":
        model = Blend(**params)
        model.load_state(arrays, state)
        return model
    cls = registry.class_named(cls_name)
    if cls is None:
        raise ValueError(f"a blend member of unknown class {cls_name!r}")
    if hasattr(cls, "from_state"):  # the Interaction Primitive restores itself whole
        return cls.from_state(arrays, state)
    model = cls(**params)
    model.load_state(arrays, state)
    return model


class Blend(Predictor):
    """A convex combination of fitted models' predictions, each placed in time by its own timing, with weights that
    depend on how far ahead the prediction is.

    After ``k`` observed frames each member ``m`` says where "now" is in its normalised time (``s_m``) and how long
    the movement lasts (``D_m``; :func:`interprim.model_selection.realtime.place_in_time`).  The blend's own timing is the
    weighted mean ``s = sum w_m(0) s_m``, ``D = sum w_m(0) D_m`` with the real-time weights; its mean at normalised
    time ``u``, ``a = (u - s) D`` seconds ahead of now, is ``sum w_m(a) y_m(u_m)`` with ``u_m = s_m + a / D_m`` (the
    same instant in seconds for every member) and ``u_m = u s_m / s`` before now (where ``a = 0``).  The weights
    ``w(a)`` were fitted per look-ahead band on held-out folds (:func:`weights_at`): the next ``horizon`` seconds,
    then bands doubling in length to the end of the longest demonstration.  Its variance is the members' weighted
    disagreement ``sum w_m(a) (y_m - mean)^2``, scaled per column and per second ahead to the held-out errors
    (``scales``).

    Made by :class:`AutoInteraction`; :meth:`fit` refits the members with the stored weights.

    Parameters
    ----------
    observed_dofs : sequence of int
    weights : dict
        ``{family: weight}``, or ``{family: [weight per band]}`` with ``bands`` (families of
        :data:`interprim.models.registry.FAMILIES`).
    scales : dict, optional
        ``{"a": (H, D), "b": (H, D), "t": (H,)}``: the variance ``a * spread + b`` at ``t`` seconds ahead (default
        ``a = 1, b = 0``: the spread alone; without ``t``, ``H`` steps spanning ``horizon``).
    horizon : float
        Seconds of the real-time band.
    n_basis, smoothing_window
        Settings of the Interaction Primitive members.
    bands : list of float, optional
        Upper edges (s) of the look-ahead bands of the weights (None: one set of weights for every look-ahead).
    """

    _FITTED = "members_"
    #: 2: weights per look-ahead band, the variance model's own time axis
    STATE_VERSION = 2
    #: points of the normalised-time grid on which the members' predictions are read
    N_GRID = 201

    def __init__(self, observed_dofs, weights, scales=None, horizon: float = registry.DEFAULT_HORIZON,
                 n_basis: int = 20, smoothing_window=None, bands=None):
        self.observed_dofs = observed_dofs
        self.weights = weights
        self.scales = scales
        self.horizon = horizon
        self.n_basis = n_basis
        self.smoothing_window = smoothing_window
        self.bands = bands

    @classmethod
    def from_fitted(cls, observed_dofs, members: dict, weights: dict, scales, demos, dt: float,
                    horizon: float = registry.DEFAULT_HORIZON, bands=None, n_basis: int = 20,
                    smoothing_window=None) -> "Blend":
        """A blend of already fitted ``members`` (``{family: model}``) trained on ``demos`` at ``dt``."""
        sc = None if scales is None else {k: np.asarray(v, dtype=np.float64).tolist() for k, v in scales.items()}
        blend = cls(list(observed_dofs), dict(weights), sc, horizon, n_basis, smoothing_window,
                    None if bands is None else [float(b) for b in bands])
        blend.adopt(members, demos, dt)
        return blend

    def _weight_table(self):
        """``(names, W (bands, M), edges)`` of the stored weights."""
        names = list(self.weights)
        if self.bands is None:
            W = np.array([[float(self.weights[m]) for m in names]])
            return names, W, np.array([np.inf])
        W = np.array([[float(x) for x in self.weights[m]] for m in names]).T
        if W.shape[0] != len(self.bands):
            raise ValueError(f"weights have {W.shape[0]} bands, bands has {len(self.bands)} edges")
        return names, W, np.asarray(self.bands, dtype=np.float64)

    def adopt(self, members, demos, dt):
        """Take ``members`` (``{family: fitted model}``, trained on ``demos`` at ``dt``) as the fitted blend."""
        names, W, edges = self._weight_table()
        if np.any(W < 0) or not np.all(np.isfinite(W)) or np.any(W.sum(axis=1) <= 0):
            raise ValueError("weights must be finite, non-negative and not all zero in any band")
        self.members_ = {m: members[m] for m in names}
        self._names, self._W, self._edges = names, W / W.sum(axis=1, keepdims=True), edges
        #: the real-time weights (look-ahead 0), which place the blend in time after every frame
        self._w_now = weights_at(np.zeros(1), edges, self._W)[0]
        self.observed_dofs_ = [int(i) for i in self.observed_dofs]
        self.dt_ = float(dt)
        self.mean_duration_ = float(np.mean([len(d) - 1 for d in demos])) * self.dt_
        self.n_dofs_ = int(np.asarray(demos[0]).shape[1])

    def fit(self, demos, dt: float | None = None):
        """Fit every member on ``demos`` (the weights and scales are kept)."""
        train, dt, _ = uniform_demonstrations(demos, dt)
        bad = [m for m in self.weights if m not in registry.FAMILIES]
        if bad or not self.weights:
            raise ValueError(f"weights must name some of {list(registry.FAMILIES)}, got {list(self.weights)!r}")
        make = registry.factories(list(self.weights), registry.Settings(
            tuple(self.observed_dofs), n_basis=self.n_basis, smoothing_window=self.smoothing_window,
            horizon=float(self.horizon)))
        self.adopt({m: make[m]().fit(train, dt=dt) for m in self.weights}, train, dt)
        return self

    def weights_at(self, ahead) -> np.ndarray:
        """The blend's weights ``(len(ahead), members)`` at ``ahead`` seconds after now (:func:`weights_at`)."""
        self._check_fitted("weights_at")
        return weights_at(np.atleast_1d(ahead), self._edges, self._W)

    def variance(self, spread, ahead):
        """``a * spread + b`` with the variance model at ``ahead`` seconds after now (held at the ends)."""
        if not self.scales:
            return spread
        a = np.asarray(self.scales["a"], dtype=np.float64)
        b = np.asarray(self.scales["b"], dtype=np.float64)
        if "t" in self.scales:
            steps = np.asarray(self.scales["t"], dtype=np.float64)
        else:
            steps = np.arange(1, a.shape[0] + 1) * (float(self.horizon) / a.shape[0])
        return interp_columns(ahead, steps, a) * spread + interp_columns(ahead, steps, b)

    def combine(self, preds: dict, n_frames: int, n_grid: int | None = None):
        """The blended prediction of the members' predictions ``{family: pred}`` after ``n_frames`` observed frames
        (a :class:`~interprim.models.base.GridPrediction` whose std is computed when first asked for)."""
        n_grid = self.N_GRID if n_grid is None else int(n_grid)
        names = self._names
        w0 = self._w_now
        timing = [place_in_time(preds[m], n_frames, self.dt_, self.mean_duration_) for m in names]
        s = float(np.dot(w0, [t[0] for t in timing]))
        D = float(np.dot(w0, [t[1] for t in timing]))
        u = unit_grid(n_grid)
        ahead = np.clip((u - s) * D, 0.0, None)
        W = weights_at(ahead, self._edges, self._W)  # (n_grid, M)
        Y = np.empty((len(names), n_grid, self.n_dofs_))
        for i, (m, (sm, Dm)) in enumerate(zip(names, timing)):
            um = np.where(u >= s, sm + ahead / Dm, u * (sm / s if s > 0 else 1.0))
            Y[i] = interp_columns(np.clip(um, 0.0, 1.0), u, preds[m].trajectory(n_grid))
        mean = np.einsum("gm,mgd->gd", W, Y)
        return BlendPrediction(self, u, mean, Y, W, ahead, phase=s, duration=D, n_observed=n_frames)

    def predict(self, partial, **kwargs):
        """The blend of every member's prediction for the observed frames ``partial`` ``(M, n_observed)``."""
        self._check_fitted("predict")
        if kwargs:
            raise TypeError(f"Blend.predict takes only the observed frames, got {sorted(kwargs)}")
        x = np.asarray(partial, dtype=np.float64)
        return self.combine({m: est.predict(x) for m, est in self.members_.items()}, len(x))

    def stream(self, robot_state=None):
        """An online blend: every member's own stream, combined after each frame (equals :meth:`predict`)."""
        self._check_fitted("stream")
        if robot_state is not None:
            raise ValueError("robot_state: a blend does not roll out from a robot state; pass None")
        return BlendStream(self)

    def to_state(self):
        """``(arrays, meta)``: every member's state, prefixed by its family."""
        self._check_fitted("to_state")
        arrays, members = {}, {}
        for m, est in self.members_.items():
            a, meta = est.to_state()
            arrays.update({f"{m}__{k}": v for k, v in a.items()})
            members[m] = {"class": type(est).__name__, "params": est.json_params(), "state": meta,
                          "version": int(est.STATE_VERSION)}
        return arrays, {"members": members, "dt": self.dt_, "mean_duration": self.mean_duration_,
                        "n_dofs": self.n_dofs_, "observed_dofs_": self.observed_dofs_}

    def load_state(self, arrays, meta):
        """Restore the state written by :meth:`to_state`."""
        members = {}
        for m in self.weights:
            info = meta["members"][m]
            inner = {k[len(m) + 2:]: v for k, v in arrays.items() if k.startswith(f"{m}__")}
            members[m] = _restore(info["class"], info["params"], inner, info["state"])
        n_dofs = int(meta["n_dofs"])
        self.adopt(members, [np.zeros((2, n_dofs))], float(meta["dt"]))
        self.mean_duration_ = float(meta["mean_duration"])
        self.observed_dofs_ = [int(i) for i in meta["observed_dofs_"]]

    def __repr__(self):
        w = ", ".join(f"{m} {np.atleast_1d(x)[0]:.2f}" for m, x in self.weights.items())
        return f"Blend({w}{'' if self.bands is None else f'; {len(self.bands)} look-ahead bands'})"


class BlendPrediction(GridPrediction):
    """The blend's prediction: its mean on the grid, its std (the members' weighted disagreement through the
    variance model) computed when first asked for."""

    def __init__(self, blend, u, mean, Y, W, ahead, phase, duration, n_observed):
        super().__init__(u, mean, None, phase=phase, observed_dofs=blend.observed_dofs_, method="blend",
                         duration=duration, mean_duration=blend.mean_duration_, n_observed=n_observed)
        self._parts = (blend, Y, W, ahead)

    @property
    def std_values(self):
        parts = self.__dict__.get("_parts")
        if parts is None:
            return self.__dict__.get("_std")
        blend, Y, W, ahead = parts
        spread = np.einsum("gm,mgd->gd", W, (Y - self.mean[None]) ** 2)
        var = blend.variance(spread, ahead)
        self.__dict__["_std"] = np.sqrt(np.clip(var, 0.0, None)) if np.any(var > 0) else None
        self.__dict__["_parts"] = None
        return self.__dict__["_std"]

    @std_values.setter
    def std_values(self, value):
        self.__dict__["_std"] = value


class BlendStream(BaseStream):
    """Online :class:`Blend`: one stream per member, combined after every frame (``update`` equals ``predict``;
    ``extend`` is :class:`~interprim.models.base.BaseStream`'s, frame by frame)."""

    def __init__(self, blend: Blend):
        self.blend = blend
        self.streams = {m: est.stream() for m, est in blend.members_.items()}
        self._n = 0

    @property
    def n_frames(self) -> int:
        """Frames received since the stream was created or last reset."""
        return self._n

    def reset(self, robot_state=None):
        """Forget all frames (start a new interaction)."""
        for st in self.streams.values():
            st.reset()
        self._n = 0

    def update(self, frame, need_cov: bool = False):
        """Add one observed frame; returns the blended prediction of every frame seen."""
        preds = {m: st.update(frame) for m, st in self.streams.items()}
        self._n += 1
        return self.blend.combine(preds, self._n)


def _record(chosen, errors) -> dict:
    finite = {m: e for m, e in errors.items() if np.isfinite(e)}
    others = {m: e for m, e in finite.items() if m != chosen}
    runner = min(others, key=others.get) if others else None
    best = finite.get(chosen, float("nan"))
    return {"chosen": chosen, "cv_errors": {m: float(e) for m, e in errors.items()},
            "runner_up": runner, "margin": float(others[runner] / best) if runner and best > 0 else float("nan"),
            "vs_prior": float(best / finite["prior"]) if finite.get("prior", 0) > 0 else float("nan")}

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

import numpy as np

from ..core.blas import one_blas_thread
from ..model_selection.realtime import RealTimeConfig, realtime_sweep, summarise_realtime
from . import registry
from .base import BaseStream, GridPrediction, Predictor, place_in_time
from ..core.preprocessing import interp_columns

__all__ = ["AutoInteraction", "Blend", "CrossValidation", "CANDIDATES", "COMBINE"]

#: The families compared by default.
CANDIDATES = ("ip", "learned", "kernel", "nn", "prior")


def _classes():
    from .demonstrations import NearestNeighbour, PriorMean
    from .kernel import KernelDemonstrations
    from .learned import LearnedInteraction
    from .primitive.estimator import InteractionPrimitive

    return {c.__name__: c for c in (InteractionPrimitive, LearnedInteraction, KernelDemonstrations,
                                    NearestNeighbour, PriorMean)}


#: How the compared families are used: a weighted blend of them (``"blend"``) or the best one alone (``"best"``).
COMBINE = ("blend", "best")


class CrossValidation:
    """What the inner cross-validation of :class:`AutoInteraction` saw, case by case.

    One case is one evaluated frame of one held-out training demonstration; for every family that could be
    fitted on every inner fold, the prediction of the next ``horizon`` seconds placed in time by the family's own
    timing (:func:`interprim.models.base.place_in_time`), and the truth.

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

    def __init__(self, make, demos, observed_dofs, dt, cfg, k):
        self.observed = [int(i) for i in observed_dofs]
        self.point_dim = int(cfg.point_dim)
        self.errors, per = {}, {}
        for name, factory in make.items():
            try:
                # only the family's errors and placed means are kept: its std and the clock's records are skipped
                recs = realtime_sweep({name: factory}, demos, self.observed, dt, cfg, k=k, trace=True, std=False,
                                      references=False)
            except ValueError:  # e.g. too few demonstrations in an inner training fold for this family
                self.errors[name] = float("inf")
                continue
            self.errors[name] = float(summarise_realtime(recs).get(name, {}).get("rt_ctrl", np.inf))
            per[name] = {(r["demo"], r["k"]): r for r in recs if r["method"] == name}
        self.names = [m for m in per if np.isfinite(self.errors[m])]
        cases = sorted(set.intersection(*(set(per[m]) for m in self.names))) if self.names else []
        first = per[self.names[0]] if self.names else {}
        self.truth = np.array([first[c]["truth"] for c in cases], dtype=np.float64)
        self.mean = np.array([[per[m][c]["mean"] for c in cases] for m in self.names], dtype=np.float64)
        D = self.truth.shape[-1] if self.truth.size else len(self.observed)
        self.controlled = [i for i in range(D) if i not in set(self.observed)]

    def subset(self, names) -> "CrossValidation":
        """The same cases restricted to the families ``names`` (those with finite errors, in this order)."""
        keep = [i for i, m in enumerate(self.names) if m in set(names)]
        out = object.__new__(type(self))
        out.__dict__.update(self.__dict__)
        out.errors = {m: e for m, e in self.errors.items() if m in set(names)}
        out.names = [self.names[i] for i in keep]
        out.mean = self.mean[keep]
        return out

    def blend_weights(self) -> np.ndarray:
        """Weights on the simplex (one per family of :attr:`names`) that minimise the blend's mean real-time
        error of the controlled agent over the cases, the very figure :attr:`errors` reports (stacking, Breiman
        1996, on the protocol's own loss: a convex problem whose solution is a convex combination, so the blend can
        always fall back on a single family).  Squared-error stacking was tried first: a few large errors decided
        the weights and the blend came out worse than its best member on the protocol's loss."""
        from scipy.optimize import minimize

        M = len(self.names)
        if M == 1:
            return np.ones(1)
        c = self.controlled or self.observed
        P = self.mean[..., c].reshape(M, self.mean.shape[1], -1)  # (M, cases, H * C)
        T = self.truth[..., c].reshape(self.truth.shape[0], -1)
        scale = max(float(np.sqrt(np.mean(T * T))), 1e-300)
        P, T = P / scale, T / scale

        def loss(w):
            e = np.tensordot(w, P, axes=1) - T
            r = np.sqrt(np.mean(e * e, axis=1)) + 1e-12
            grad = np.einsum("mcj,cj->m", P, e / r[:, None]) / (e.shape[1] * len(r))
            return float(np.mean(r)), grad

        start = np.full(M, 1.0 / M)
        best = min(range(M), key=lambda m: self.errors[self.names[m]])
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
        ``a = 1`` and ``b`` adds the rest; where it is wider, ``b = 0`` and ``a < 1`` narrows it.  So the mean
        predicted variance equals the mean squared held-out error at every step and column: the 90 % band is
        calibrated over the look-ahead.

        The members' own std is not used: it does not carry over from the inner folds' smaller training sets to
        the final fit (``LearnedInteraction``'s was 4x its error when fitted on 9 NuiSI demonstrations, about
        right on 13), whereas their disagreement and the residual do.

        Returns ``{"a": (H, D), "b": (H, D)}``.
        """
        w = np.asarray(w, dtype=np.float64)[:, None, None, None]
        mix = np.sum(w * self.mean, axis=0)
        spread = np.sum(w * (self.mean - mix) ** 2, axis=0).mean(axis=0)  # (H, D)
        err2 = ((mix - self.truth) ** 2).mean(axis=0)
        wide = spread > err2
        a = np.where(wide, err2 / np.where(spread > 0, spread, 1.0), 1.0)
        b = np.where(wide, 0.0, err2 - spread)
        return {"a": a, "b": b}

    def blend_error(self, w) -> float:
        """The blend's mean real-time error of the controlled agent over the cases, as :attr:`errors` measures it
        (in-sample for the weights: an optimistic figure)."""
        mix = np.tensordot(np.asarray(w, dtype=np.float64), self.mean, axes=1)
        e = (mix - self.truth)[..., self.controlled or self.observed]
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
    CANDIDATES = CANDIDATES

    def __init__(self, observed_dofs, candidates=CANDIDATES, combine: str = "blend", folds: int = 3,
                 horizon: float = 0.25, stride: int = 3, n_basis: int = 20, smoothing_window=None, point_dim: int = 1):
        self.observed_dofs = observed_dofs
        self.candidates = candidates
        self.combine = combine
        self.folds = folds
        self.horizon = horizon
        self.stride = stride
        self.n_basis = n_basis
        self.smoothing_window = smoothing_window
        self.point_dim = point_dim

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
        if dt is None:
            dt = getattr(demos, "dt", None) or 0.01
        n = len(demos)
        if n < 3:
            raise ValueError(f"AutoInteraction needs at least 3 demonstrations to compare families, got {n}")
        make = self.factories()
        cfg = RealTimeConfig(horizon=float(self.horizon), stride=int(self.stride), point_dim=int(self.point_dim))
        train = [np.asarray(d, dtype=np.float64) for d in demos]
        if len(make) == 1:  # nothing to compare: the one family, fitted (with the file's column names kept)
            cv = None
            chosen = next(iter(make))
            selection = _record(chosen, {chosen: float("nan")})
        else:
            cv = CrossValidation(make, demos, self.observed_dofs, float(dt), cfg, k=min(int(self.folds), n))
            chosen, selection = choice(cv, list(make))
        if self.combine == "blend" and cv is not None and len(cv.names) > 1:
            w = cv.blend_weights()
            weights = {m: float(x) for m, x in zip(cv.names, w) if x > 0}
            scales = cv.blend_scales(w)
            members = {m: make[m]().fit(train, dt=float(dt)) for m in weights}
            self.model_ = Blend.from_fitted(self.observed_dofs, members, weights, scales, train, float(dt),
                                            float(self.horizon))
            selection.update(combine="blend", weights=weights, blend_cv_error=cv.blend_error(w),
                             variance_model={k: np.asarray(v).tolist() for k, v in scales.items()})
            best = selection["cv_errors"][chosen]
            selection["blend_vs_best"] = selection["blend_cv_error"] / best if best > 0 else float("nan")
        else:
            self.model_ = make[chosen]().fit(train, dt=float(dt))
            weights = {chosen: 1.0}
            selection.update(combine="best", weights=weights)
        self.chosen_ = chosen
        self.weights_ = weights
        self.observed_dofs_ = [int(i) for i in self.observed_dofs]
        self.n_dofs_ = int(train[0].shape[1])
        self.controlled_dofs_ = [i for i in range(self.n_dofs_) if i not in set(self.observed_dofs_)]
        self.dt_ = float(dt)
        self.mean_duration_ = float(np.mean([len(d) - 1 for d in train])) * self.dt_
        cols = getattr(demos, "columns", None)
        self.columns_ = None if cols is None else [str(c) for c in cols]
        self.selection_ = selection
        return self

    def predict(self, partial, **kwargs):
        """The model's prediction (:meth:`interprim.models.base.Predictor` contract)."""
        self._check_fitted("predict")
        return self.model_.predict(partial, **kwargs)

    def stream(self, robot_state=None):
        """The model's online predictor."""
        self._check_fitted("stream")
        return self.model_.stream(robot_state)

    def to_state(self):
        """``(arrays, meta)``: the model's state with its class and parameters."""
        self._check_fitted("to_state")
        arrays, meta = self.model_.to_state()
        return ({f"model_{k}": v for k, v in arrays.items()},
                {"chosen": self.chosen_, "class": type(self.model_).__name__, "params": self.model_.json_params(),
                 "state": meta, "selection": self.selection_, "observed_dofs_": self.observed_dofs_,
                 "weights": self.weights_, "n_dofs_": self.n_dofs_, "dt_": self.dt_, "columns_": self.columns_,
                 "mean_duration_": self.mean_duration_})

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
        for m, e in sorted(s["cv_errors"].items(), key=lambda kv: kv[1]):
            tag = " <- best" if m == self.chosen_ else ""
            lines.append(f"  {m:10s} {e:.4g}{tag}")
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
        raise ValueError("no candidate family could be fitted on every inner training fold")
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
    """A convex combination of fitted models' predictions, each placed in time by its own timing.

    After ``k`` observed frames each member ``m`` says where "now" is in its normalised time (``s_m``) and how long
    the movement lasts (``D_m``; :func:`interprim.models.base.place_in_time`).  The blend's own timing is the weighted
    mean ``s = sum w_m s_m``, ``D = sum w_m D_m``; its mean at normalised time ``u`` is ``sum w_m y_m(u_m)``
    with ``u_m = s_m + (u - s) D / D_m`` ahead of now (the same instant in seconds for every member) and
    ``u_m = u s_m / s`` before it.  Its variance is the mixture's, ``sum w_m (sd_m^2 + (y_m - mean)^2)``,
    times a factor per agent and per step ahead fitted to held-out errors (``scales``).

    Made by :class:`AutoInteraction`; :meth:`fit` refits the members with the stored weights.

    Parameters
    ----------
    observed_dofs : sequence of int
    weights : dict
        ``{family: weight}`` (families of :data:`interprim.models.registry.FAMILIES`).
    scales : dict, optional
        ``{"a": (H, D), "b": (H, D)}``, the variance model per step ahead and column (default ``a = 1, b = 0``:
        the spread alone).
    horizon : float
        Seconds spanned by the ``H`` steps of ``scales``.
    n_basis, smoothing_window
        Settings of the Interaction Primitive members.
    """

    _FITTED = "members_"

    def __init__(self, observed_dofs, weights, scales=None, horizon: float = 0.25, n_basis: int = 20,
                 smoothing_window=None):
        self.observed_dofs = observed_dofs
        self.weights = weights
        self.scales = scales
        self.horizon = horizon
        self.n_basis = n_basis
        self.smoothing_window = smoothing_window

    @classmethod
    def from_fitted(cls, observed_dofs, members: dict, weights: dict, scales, demos, dt: float,
                    horizon: float = 0.25) -> "Blend":
        """A blend of already fitted ``members`` (``{family: model}``) trained on ``demos`` at ``dt``."""
        blend = cls(list(observed_dofs), dict(weights), {k: np.asarray(v, dtype=np.float64).tolist()
                                                         for k, v in scales.items()} if scales is not None else None,
                    horizon)
        blend.adopt(members, demos, dt)
        return blend

    def adopt(self, members, demos, dt):
        """Take ``members`` (``{family: fitted model}``, trained on ``demos`` at ``dt``) as the fitted blend."""
        self.members_ = {m: members[m] for m in self.weights}
        self.observed_dofs_ = [int(i) for i in self.observed_dofs]
        self.dt_ = float(dt)
        self.mean_duration_ = float(np.mean([len(d) - 1 for d in demos])) * self.dt_
        self.n_dofs_ = int(np.asarray(demos[0]).shape[1])

    def fit(self, demos, dt: float | None = None):
        """Fit every member with a positive weight on ``demos`` (the weights and scales are kept)."""
        if dt is None:
            dt = getattr(demos, "dt", None) or 0.01
        make = registry.factories([m for m in self.weights if m in registry.FAMILIES], registry.Settings(
            tuple(self.observed_dofs), n_basis=self.n_basis, smoothing_window=self.smoothing_window,
            horizon=float(self.horizon)))
        bad = [m for m in self.weights if m not in make]
        if bad or not self.weights:
            raise ValueError(f"weights must name some of {sorted(make)}, got {list(self.weights)!r}")
        train = [np.asarray(d, dtype=np.float64) for d in demos]
        self.adopt({m: make[m]().fit(train, dt=float(dt)) for m in self.weights}, train, dt)
        return self

    def _variance(self, spread, ahead):
        """``a * spread + b`` with the variance model at ``ahead`` seconds after now (held at the ends)."""
        if not self.scales:
            return spread
        a = np.asarray(self.scales["a"], dtype=np.float64)
        b = np.asarray(self.scales["b"], dtype=np.float64)
        steps = np.arange(1, a.shape[0] + 1) * (float(self.horizon) / a.shape[0])
        return interp_columns(ahead, steps, a) * spread + interp_columns(ahead, steps, b)

    def combine(self, preds: dict, n_frames: int, n_grid: int = 401):
        """The blended :class:`~interprim.models.base.GridPrediction` of the members' predictions ``{family: pred}``
        after ``n_frames`` observed frames."""
        names = list(self.members_)
        w = np.array([self.weights[m] for m in names], dtype=np.float64)
        w = w / w.sum()
        timing = [place_in_time(preds[m], n_frames, self.dt_, self.mean_duration_) for m in names]
        s = float(np.dot(w, [t[0] for t in timing]))
        D = float(np.dot(w, [t[1] for t in timing]))
        u = np.linspace(0.0, 1.0, int(n_grid))
        ahead = np.clip((u - s) * D, 0.0, None)
        Y = []
        for m, (sm, Dm) in zip(names, timing):
            um = np.where(u >= s, sm + ahead / Dm, u * (sm / s if s > 0 else 1.0))
            Y.append(interp_columns(np.clip(um, 0.0, 1.0), u, preds[m].trajectory(int(n_grid))))
        Y = np.array(Y)
        mean = np.tensordot(w, Y, axes=1)
        var = self._variance(np.tensordot(w, (Y - mean) ** 2, axes=1), ahead)
        std = np.sqrt(var) if np.any(var > 0) else None
        return GridPrediction(u, mean, std, phase=s, observed_dofs=self.observed_dofs_, method="blend", duration=D,
                              mean_duration=self.mean_duration_, n_observed=n_frames)

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
            members[m] = {"class": type(est).__name__, "params": est.json_params(), "state": meta}
        return arrays, {"members": members, "dt": self.dt_, "mean_duration": self.mean_duration_,
                        "n_dofs": self.n_dofs_, "observed_dofs_": self.observed_dofs_}

    def load_state(self, arrays, meta):
        """Restore the state written by :meth:`to_state`."""
        self.members_ = {}
        for m in self.weights:
            info = meta["members"][m]
            inner = {k[len(m) + 2:]: v for k, v in arrays.items() if k.startswith(f"{m}__")}
            self.members_[m] = _restore(info["class"], info["params"], inner, info["state"])
        self.dt_ = float(meta["dt"])
        self.mean_duration_ = float(meta["mean_duration"])
        self.n_dofs_ = int(meta["n_dofs"])
        self.observed_dofs_ = [int(i) for i in meta["observed_dofs_"]]

    def __repr__(self):
        w = ", ".join(f"{m} {x:.2f}" for m, x in self.weights.items())
        return f"Blend({w})"


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

"""What an Interaction Primitive learned, and the one path of its predictions (paper Sec. III, Eq. 1-18).

:class:`FittedPrimitive` is the fitted state of an :class:`~interprim.models.primitive.estimator.InteractionPrimitive`:
the hyper-parameters it was fitted with, the DMP basis and rollout (Eq. 1-2), the per-agent PCA and latent maps
(Sec. IV), the demonstrations' parameters and the prior ``p(theta)`` (Eq. 10) with its conditioner
(Eq. 16-18), the observation noise, the phase model and its reference (Sec. III-B), the observation
statistics (Eq. 13-15), the calibration and the input range.  Every ``fit`` builds a new one
(:meth:`FittedPrimitive.learn`), a model file restores one (:meth:`FittedPrimitive.from_state`), and
nothing changes it afterwards: :meth:`with_fitted` and :meth:`with_params` return modified copies.

Values derived from it (latent maps, the low-rank conditioner, the phase likelihood's factored prior) live
in its own store (:meth:`FittedPrimitive.cached`), so a refit, which makes a new state, never sees a value
derived from the previous fit.

Its attribute names are the estimator's fitted attributes (names ending in ``_``, documented in
:class:`~interprim.models.primitive.estimator.InteractionPrimitive`) and constructor parameters, so that a reader finds
one name for one thing; the estimator shows them as read-only views.
:class:`~interprim.models.primitive.prediction.Prediction`, :class:`~interprim.models.primitive.stream.Stream`,
:mod:`interprim.phase`, :mod:`interprim.models.primitive.selection`, :mod:`interprim.models.primitive.calibration` and
:mod:`interprim.models.recognition` work on this object, not on the estimator.
"""

from __future__ import annotations

import copy

import numpy as np

from ...core._compiled import registry as kernels
from ...core.basis import Basis
from ...core.blas import one_blas_thread, single_thread
from ...core.cache import DerivedCache, std_deferred
from ...core.dmp import cached_rollout, fit_weights_stacked, fit_weights_targets, forcing_values, representation_report
from ...core.gaussian import Posterior, fit_prior
from ...core.input_range import checked_by_caller, fit_input_range, input_distance, mark
from ...core.preprocessing import PCA, derivatives, resample_uniform, time_normalise
from ...core.validation import as_2d_finite, check_positive, check_times
from ...phase import estimate_phase, fit_phase_model, movement_prefix
from .prediction import Prediction

__all__ = ["FittedPrimitive", "PARAM_NAMES", "FITTED_NAMES"]


class _PendingCalibration:
    """:func:`~interprim.models.primitive.calibration.fit_calibration` of a state as fitted on ``arrays``, measured
    once (at the end of the fit, or on first use for a fit inside :func:`interprim.core.cache.std_unused`);
    ``prefixes`` (:class:`~interprim.model_selection.prefixes.Prefixes`, or None) gives the held-out cases' causal
    observed prefixes."""

    def __init__(self, origin, arrays, prefixes=None):
        self.origin, self.arrays, self.prefixes, self.done, self.value = origin, arrays, prefixes, False, None

    def resolve(self, reader):
        """The calibration (measured now if not yet), also set on ``reader`` (the state or a copy of it)."""
        if not self.done:
            from .calibration import fit_calibration  # predictive std scaled to held-out errors

            origin = self.origin
            origin.__dict__.pop("_calibration_pending", None)
            origin.__dict__["calibration_"] = None  # as during an eager fit: the folds' copies carry none
            with single_thread():  # many small conditionings (a 252 x 252 covariance each): one BLAS thread
                self.value = fit_calibration(origin, self.arrays, prefixes=self.prefixes)
            self.done, self.origin, self.arrays, self.prefixes = True, None, None, None
            origin.__dict__["calibration_"] = self.value
        reader.__dict__["calibration_"] = self.value
        reader.__dict__.pop("_calibration_pending", None)
        return self.value

#: the estimator's constructor parameters, kept on the state as fitted with
PARAM_NAMES = ("observed_dofs", "n_basis", "alpha_y", "beta_y", "alpha_x", "sigma2", "covariance", "ridge",
               "observation", "smoothing_window", "pca_components", "reference", "min_observed", "n_steps",
               "phase_method", "input_noise", "calibrate")

#: the fitted attributes (learned, or derived from what was learned) the estimator shows as read-only views
FITTED_NAMES = ("observed_dofs_", "controlled_dofs_", "n_dofs_", "columns_", "dt_", "n_demos_", "durations_",
                "mean_duration_", "beta_y_", "pca_observed_", "pca_controlled_", "n_observed_latent_", "n_latent_",
                "basis_", "rollout_", "params_per_dof_", "obs_index_", "thetas_", "start_position_",
                "start_velocity_", "prior_", "representation_", "sigma2_", "phase_sigma2_", "selection_",
                "phase_model_", "phase_method_", "reference_", "input_mean_", "input_std_", "input_limit_",
                "calibration_")


class FittedPrimitive:
    """The fitted state of an Interaction Primitive and the one path of its predictions.

    Parameters
    ----------
    params : dict
        The estimator's constructor parameters as fitted (:meth:`InteractionPrimitive.json_params`); each is
        also an attribute of the same name.
    fitted : dict, optional
        Fitted attributes (names ending in ``_``), as :mod:`interprim.io` reads them from a model file; the
        derived ones (basis, rollout, index tables) are then built.  Empty for a state that
        :meth:`learn` is about to fill.

    Notes
    -----
    Attribute names are those of the estimator's Attributes section.  Public methods: :meth:`predict`,
    :meth:`stream`, :meth:`predict_latent` (the one path of ``predict`` and ``Stream.update``),
    :meth:`condition` (Eq. 16-18), :meth:`latent_map`, :meth:`controlled_map`, :meth:`observed_to_latent`,
    :meth:`robot_start`, :meth:`phase_method_used`, :meth:`input_distance`, :meth:`cached`,
    :meth:`with_fitted`, :meth:`with_params`, :meth:`to_state` / :meth:`from_state`.
    """

    # constructor parameters, installed from ``params`` (PARAM_NAMES) by __init__ and read as attributes
    phase_method: str
    min_observed: int

    def __init__(self, params: dict, fitted: dict | None = None):
        missing = [k for k in PARAM_NAMES if k not in params]
        if missing:
            raise ValueError(f"FittedPrimitive: parameters {missing} missing")
        self.params = {k: params[k] for k in PARAM_NAMES}
        self.__dict__.update(self.params)
        self._derived = DerivedCache()
        if fitted:
            bad = [k for k in fitted if not k.endswith("_") or k.startswith("_")]
            if bad:
                raise ValueError(f"FittedPrimitive: {bad} are not fitted attribute names")
            self.__dict__.update(fitted)
            self.setup_derived()

    # ------------------------------------------------------------------ construction
    def json_params(self) -> dict:
        """The parameters this state was fitted with (JSON types), as a model file stores them."""
        return dict(self.params)

    def setup_derived(self):
        """Derived, non-learned state (basis, rollout map, index tables)."""
        self.basis_ = Basis(int(self.n_basis), float(self.alpha_x))
        self.rollout_ = cached_rollout(int(self.n_basis), float(self.alpha_x), float(self.alpha_y), self.beta_y_,
                                       int(self.n_steps))
        q = self.n_basis + 1
        self.params_per_dof_ = q  # n_basis + 1 entries of theta per DoF (Eq. 2)
        self.obs_index_ = np.arange(self.n_observed_latent_ * q).reshape(self.n_observed_latent_, q)

    def with_fitted(self, **fitted) -> FittedPrimitive:
        """A copy with some fitted attributes (names ending in ``_``) replaced, e.g. the prior re-estimated on a
        subset of the demonstrations (:func:`interprim.models.primitive.calibration.fold_model`).  The copy shares the
        other fitted arrays and has its own store of derived values; ``self`` is unchanged."""
        bad = [k for k in fitted if not k.endswith("_") or k.startswith("_") or not hasattr(self, k)]
        if bad:
            raise ValueError(f"with_fitted: {bad} are not fitted attributes of this model")
        new = copy.copy(self)
        new.__dict__.update(fitted, _derived=DerivedCache())
        return new

    def with_params(self, **params) -> FittedPrimitive:
        """A copy that predicts with some parameters changed after the fit (``phase_method``: the estimator's
        parameter set after ``fit``).  It shares the store of derived values, which depend on the fitted
        arrays only."""
        bad = [k for k in params if k not in PARAM_NAMES]
        if bad:
            raise ValueError(f"with_params: {bad} are not parameters")
        new = copy.copy(self)
        new.params = dict(self.params, **params)
        new.__dict__.update(params)
        return new

    def without_calibration(self) -> FittedPrimitive:
        """A copy whose predictive std is not calibrated, and says so: ``calibrate=False`` in its parameters (and
        so in its model file), ``calibration_`` None, and a calibration a fit inside
        :func:`interprim.core.cache.std_unused` deferred dropped (never measured, its demonstrations not held).

        For a model whose own std nobody reads: a member of a :class:`~interprim.models.blend.Blend`, whose band
        comes from the blend's variance model and the members' means alone
        (:class:`~interprim.models.auto.AutoInteraction` keeps its Interaction Primitive member so).  The
        calibration scales the std only (:meth:`Prediction.std <interprim.models.primitive.prediction.Prediction.std>`,
        ``samples``), so every mean, phase and duration is this state's; ``self`` is unchanged.  It shares the
        store of derived values, which depend on the fitted arrays only."""
        new = self.with_params(calibrate=False)
        new.__dict__.pop("_calibration_pending", None)
        new.__dict__["calibration_"] = None
        return new

    def cached(self, name: str, key: tuple, build):
        """A value derived from the fitted state, computed once by ``build()`` and kept while the objects in
        ``key`` stay the same (compared by identity).

        Every ``fit`` makes a new state (and a loaded or :meth:`with_fitted` copy starts with an empty store),
        so a refit never sees a value derived from the previous fit.  Modules that need derived arrays of the
        model (the phase likelihood's factored prior, for example) keep them here.
        """
        return self._derived.get_or_build(name, key, build)

    # ------------------------------------------------------------------ persistence
    def to_state(self):
        """``(arrays, meta)``: this state as a model file holds it (numeric arrays and JSON metadata;
        :func:`interprim.models.primitive.state_io.model_state`); :meth:`from_state` restores it."""
        from .state_io import model_state

        return model_state(self)

    @classmethod
    def from_state(cls, arrays: dict, meta: dict, params: dict, source="<state>") -> FittedPrimitive:
        """The state of :meth:`to_state`'s ``(arrays, meta)`` (or of a model file's), every array checked
        (:func:`interprim.models.primitive.state_io.fitted_from_state`); ``params``: the estimator's complete parameters
        (a file's ``meta["params"]`` with the defaults filled in)."""
        from .state_io import fitted_from_state

        return cls(params, fitted_from_state(arrays, meta, params, source))

    # ------------------------------------------------------------------ fitting
    @classmethod
    def learn(cls, params: dict, arrays, dt: float, columns, obs, ctrl, kk, prefixes=None) -> FittedPrimitive:
        """Fit a new state on validated demonstrations ``arrays`` (data columns, uniform ``dt``): the DMP
        parameters of each (Eq. 3-4), the prior (Eq. 10), the observation noise (Eq. 16; by cross-validation
        with ``sigma2="cv"``, :mod:`interprim.models.primitive.selection`), the phase model, the DTW reference
        (Sec. III-B), the input range and the calibration (:mod:`interprim.models.primitive.calibration`).  ``obs``,
        ``ctrl``: the agents' columns; ``kk``: PCA components per agent or ``None`` (as the estimator's parameter
        check returns); ``prefixes``: the demonstrations' causal observed prefixes when their raw samples are known
        (:class:`~interprim.model_selection.prefixes.Prefixes`), which the calibration's held-out cases see."""
        st = cls(params)
        cls._learn(st, arrays, dt, columns, obs, ctrl, kk, prefixes)
        return st

    def _learn(self, arrays, dt, columns, obs, ctrl, kk, prefixes=None):
        D = arrays[0].shape[1]
        beta_y = self.alpha_y / 4.0 if self.beta_y is None else float(self.beta_y)
        self.beta_y_ = beta_y
        self.observed_dofs_ = obs
        self.controlled_dofs_ = ctrl
        self.n_dofs_ = D
        self.dt_ = dt
        self.durations_ = np.array([(a.shape[0] - 1) * dt for a in arrays])
        self.mean_duration_ = float(self.durations_.mean())
        self.n_demos_ = len(arrays)
        self.columns_ = columns

        # optional PCA per agent (Sec. IV)
        self.pca_observed_ = self.pca_controlled_ = None
        if kk is not None:
            self.pca_observed_ = PCA(kk[0]).fit(np.vstack([a[:, obs] for a in arrays]))
            if ctrl:
                self.pca_controlled_ = PCA(kk[1]).fit(np.vstack([a[:, ctrl] for a in arrays]))
        self.n_observed_latent_ = (self.pca_observed_.n_components if self.pca_observed_ is not None
                                   else len(self.observed_dofs_))
        n_o = self.n_observed_latent_
        self.setup_derived()
        # Demonstrations of equal length are processed together as one (n, T, D') array
        # (one derivative call, one least-squares solve); latent[j] is a view into it.
        S = len(arrays)
        groups: dict[int, list[int]] = {}
        for j, a in enumerate(arrays):
            groups.setdefault(a.shape[0], []).append(j)
        latent = [None] * S
        ders = [None] * S
        theta = None
        resid = np.full((S, 0), np.nan)
        var_obs = np.empty(S)
        want_resid = isinstance(self.sigma2, str) and self.observation == "forcing"
        for T, idx in groups.items():
            Zg = self.to_latent_stacked([arrays[j] for j in idx])  # (n, T, D')
            # DMP parameters (Eq. 3-4), normalised time s in [0, 1]; derivatives along time (axis 1)
            rdofs = slice(0, n_o) if want_resid else slice(0, 0)
            ftb = kernels.kernel("observation.forcing_targets_batch") if self.smoothing_window is None else None
            if ftb is not None:  # one compiled pass: derivatives + Eq. 3
                F = np.empty_like(Zg)
                yd0 = np.empty((len(idx), Zg.shape[2]))
                ftb(Zg, 1.0 / (T - 1), float(self.alpha_y), beta_y, np.empty(Zg.shape[1:]), F, yd0)
                th, r = fit_weights_targets(F, Zg[:, -1, :], self.basis_, resid_dofs=rdofs)
                y0 = Zg[:, 0, :]
            else:
                y, yd, ydd = derivatives(np.moveaxis(Zg, 1, 0), 1.0 / (T - 1), self.smoothing_window)
                y, yd, ydd = (np.moveaxis(v, 0, 1) for v in (y, yd, ydd))
                th, r = fit_weights_stacked(y, yd, ydd, self.basis_, self.alpha_y, beta_y, resid_dofs=rdofs)
                y0, yd0 = y[:, 0, :], yd[:, 0, :]
            if theta is None:
                theta = np.empty((S,) + th.shape[1:])
                resid = np.empty((S, th.shape[1]))
            theta[idx] = th
            resid[idx] = r
            var_obs[idx] = Zg[:, :, :n_o].reshape(len(idx), -1).var(axis=1)
            for k, j in enumerate(idx):
                latent[j] = Zg[k]
                ders[j] = (y0[k], yd0[k])  # start position and velocity (normalised time)
        self.n_latent_ = latent[0].shape[1]
        self.thetas_ = theta.reshape(S, -1)  # [w_1, g_1, ..., w_N, g_N] (observed DoFs first)
        self.start_position_ = np.mean([z[0] for z in latent], axis=0)
        self.start_velocity_ = np.mean([d[1] for d in ders], axis=0)
        self.prior_ = fit_prior(self.thetas_, self.covariance, self.ridge)
        self.representation_ = representation_report(
            latent, ders, theta, self.rollout_,
            groups={"observed": slice(0, n_o), "controlled": slice(n_o, None)} if ctrl else {"observed": slice(None)})

        # observation noise (Eq. 16)
        if isinstance(self.sigma2, str):
            if self.observation == "forcing":
                s2 = float(np.mean(resid[:, :n_o]))
            else:
                errs, designs = [], {}  # one design matrix per demonstration length
                for z, d, th in zip(latent, ders, theta):
                    T_z = z.shape[0]
                    if T_z not in designs:
                        designs[T_z] = self.rollout_.design(0.0, np.linspace(0.0, 1.0, T_z))
                    free, H = designs[T_z]
                    y = free @ np.stack([d[0][:n_o], d[1][:n_o]]) + H @ th[:n_o].T  # = rollout_.rollout(...)
                    errs.append(np.mean((y - z[:, :n_o]) ** 2))
                s2 = float(np.mean(errs))
            scale = float(np.mean(var_obs))
            self.sigma2_ = max(s2, 1e-10 * max(scale, 1e-12))
        else:
            self.sigma2_ = float(self.sigma2)
        self.phase_sigma2_ = None
        if self.sigma2 == "cv" and len(latent) < 3:
            raise ValueError(f"choosing the noise and shrinkage by cross-validation (sigma2='cv', the default) needs "
                             f"at least 3 demonstrations, got {len(latent)}: record more, or give sigma2 and "
                             f"covariance explicitly (e.g. sigma2=1e-3, covariance='ridge')")
        if (self.sigma2 == "cv" or self.phase_method in ("likelihood", "cv")) and len(latent) >= 3:
            from .selection import select_hyperparameters  # sigma2, shrinkage, phase noise from data
            chosen = select_hyperparameters(self, latent, select_sigma2=self.sigma2 == "cv")
            if chosen.sigma2 is not None:
                self.sigma2_, self.prior_ = chosen.sigma2, chosen.prior
            self.phase_sigma2_, self.selection_ = chosen.phase_sigma2, chosen.record
        with single_thread():  # small matrices: BLAS threads only oversubscribe a loaded machine
            self.phase_model_, self.phase_method_, figures = fit_phase_model(self, [z[:, :n_o] for z in latent], dt)
        if figures:  # both phase errors of the "cv" choice, for the user
            self.selection_.update(figures)
        if hasattr(self, "selection_"):  # how well the DMPs represent the demonstrations (kept in the model file)
            self.selection_["representation"] = self.representation_
        if self.input_noise is not None:  # sensor noise of the online input that the demonstrations lack
            e2 = float(self.input_noise) ** 2
            if self.observation == "position":
                self.sigma2_ += e2
            if self.phase_sigma2_ is not None:
                self.phase_sigma2_ += e2
        # DTW reference of the observed agent (Sec. III-B) at the training sampling rate
        n_ref = max(int(round(self.mean_duration_ / dt)) + 1, 2)
        if isinstance(self.reference, str):  # "mean" (checked with the other parameters, before any work)
            self.reference_ = np.mean([time_normalise(z[:, :n_o], n_ref) for z in latent], axis=0)
        else:
            self.reference_ = time_normalise(latent[int(self.reference)][:, :n_o], n_ref)
        # what the observed agent's frames look like in training (the out-of-range check, interprim.core.input_range)
        self.input_mean_, self.input_std_, self.input_limit_ = fit_input_range(
            np.concatenate([a[:, obs] for a in arrays], axis=0))
        self.calibration_ = None
        if self.calibrate is True or (self.calibrate == "with-cv" and self.sigma2 == "cv"):
            if prefixes is not None:  # what the calibration's held-out cases see (summary() says it)
                self.__dict__.setdefault("selection_", {})["calibration_prefixes"] = "causal"
            if std_deferred():  # a cross-validation that reads the means only: measured if the std is ever asked
                del self.calibration_
                self._calibration_pending = _PendingCalibration(self, arrays, prefixes)
            else:
                self.calibration_ = _PendingCalibration(self, arrays, prefixes).resolve(self)

    def measure_deferred(self) -> None:
        """Measure now what a fit inside :func:`interprim.core.cache.std_unused` deferred (the std's calibration),
        as the fit would have measured it outside; nothing for a state that deferred nothing."""
        pending = self.__dict__.get("_calibration_pending")
        if pending is not None:
            pending.resolve(self)

    def __getattr__(self, name: str):
        # ``calibration_`` of a state fitted inside ``interprim.core.cache.std_unused``: measured on first use, on
        # the state as fitted (a copy made meanwhile reads the same value)
        pending = self.__dict__.get("_calibration_pending") if name == "calibration_" else None
        if pending is None:
            raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")
        return pending.resolve(self)

    def to_latent(self, a):
        """A demonstration ``(T, D)`` in the latent columns the DMPs model (PCA scores when fitted with PCA)."""
        o = a[:, self.observed_dofs_]
        c = a[:, self.controlled_dofs_]
        if self.pca_observed_ is not None:
            o = self.pca_observed_.transform(o)
        if self.pca_controlled_ is not None:
            c = self.pca_controlled_.transform(c)
        return np.hstack([o, c])

    def to_latent_stacked(self, arrays):
        """:meth:`to_latent` of equal-length demonstrations into one ``(n, T, D')`` array."""
        n, T = len(arrays), arrays[0].shape[0]
        if self.pca_observed_ is None and self.pca_controlled_ is None:
            perm = np.asarray(list(self.observed_dofs_) + list(self.controlled_dofs_), dtype=np.intp)
            out = np.empty((n, T, perm.size))
            identity = bool(np.array_equal(perm, np.arange(perm.size)))
            for k, a in enumerate(arrays):
                if identity:
                    out[k] = a
                else:
                    np.take(a, perm, axis=1, out=out[k])
            return out
        return np.stack([self.to_latent(a) for a in arrays])

    # ------------------------------------------------------------------ maps between data and latent DoFs
    def observed_to_latent(self, o):
        """Frames ``(t, len(observed_dofs))`` of the observed agent in the model's latent DoFs (PCA, Sec. IV)."""
        return self.pca_observed_.transform(o) if self.pca_observed_ is not None else o

    def latent_map(self):
        """Linear map ``M`` (D x D_latent) and offset (D,) from latent DoFs to data columns."""
        return self.cached("latent_map", (self.pca_observed_, self.pca_controlled_), self._build_latent_map)

    def _build_latent_map(self):
        D = self.n_dofs_
        M = np.zeros((D, self.n_latent_))
        off = np.zeros(D)
        n_o = self.n_observed_latent_
        obs, ctrl = self.observed_dofs_, self.controlled_dofs_
        if self.pca_observed_ is not None:
            M[np.ix_(obs, range(n_o))] = self.pca_observed_.components_.T
            off[obs] = self.pca_observed_.mean_
        else:
            M[obs, range(n_o)] = 1.0
        if self.pca_controlled_ is not None:
            M[np.ix_(ctrl, range(n_o, self.n_latent_))] = self.pca_controlled_.components_.T
            off[ctrl] = self.pca_controlled_.mean_
        elif ctrl:
            M[ctrl, range(n_o, self.n_latent_)] = 1.0
        return M, off

    def controlled_map(self):
        """``(M_c^T, off_c)`` mapping latent controlled DoFs to their data columns, or ``(None, None)`` if identity."""
        return self.cached("controlled_map", (self.pca_observed_, self.pca_controlled_), self._build_controlled_map)

    def _build_controlled_map(self):
        M, off = self.latent_map()
        n_o = self.n_observed_latent_
        ctrl = self.controlled_dofs_
        Mc = np.ascontiguousarray(M[ctrl, n_o:].T)
        offc = off[ctrl].copy()
        return (None, None) if (self.pca_controlled_ is None and np.array_equal(Mc, np.eye(Mc.shape[0]))
                                and not np.any(offc)) else (Mc, offc)

    def robot_start(self, robot_state):
        """Start ``(y0, v0)`` of the controlled agent's latent DoFs (velocity per unit normalised time) from
        ``robot_state`` (see :meth:`predict`); the demonstrations' mean start when ``None``."""
        n_o = self.n_observed_latent_
        y0 = self.start_position_[n_o:].copy()
        v0 = self.start_velocity_[n_o:].copy()
        if robot_state is None or not self.controlled_dofs_:
            return y0, v0
        rs = np.asarray(robot_state, dtype=np.float64)
        nc = len(self.controlled_dofs_)
        if rs.shape == (nc,):
            pos, vel = rs, None
        elif rs.shape == (2, nc):
            pos, vel = rs[0], rs[1]
        else:
            raise ValueError(f"robot_state must have shape ({nc},) or (2, {nc}), got {rs.shape}")
        if not np.all(np.isfinite(rs)):
            raise ValueError("robot_state contains NaN or inf")
        if self.pca_controlled_ is not None:
            y0 = self.pca_controlled_.transform(pos[None])[0]
            if vel is not None:
                v0 = (vel @ self.pca_controlled_.components_.T) * self.mean_duration_
        else:
            y0 = pos
            if vel is not None:
                v0 = vel * self.mean_duration_
        return y0, v0

    # ------------------------------------------------------------------ prediction
    def phase_method_used(self) -> str:
        """The phase method in use: ``phase_method``, or with ``"cv"`` the one ``fit`` chose (``phase_method_``)."""
        if self.phase_method == "cv":
            return getattr(self, "phase_method_", "likelihood")
        return self.phase_method

    def input_distance(self, frames) -> float:
        """Largest standardised distance of observed frames ``(t, D_o)`` (data columns) from the training frames
        (:mod:`interprim.core.input_range`); NaN for a model file without those statistics."""
        return input_distance(self, frames)

    @one_blas_thread
    def predict(self, partial, robot_state=None, dt: float | None = None, times=None,
                phase: float | None = None) -> Prediction:
        """:meth:`InteractionPrimitive.predict <interprim.models.primitive.estimator.InteractionPrimitive.predict>` (the
        same arguments): validate and resample the partial observation, estimate its phase, condition (Eq. 13-18)."""
        n_cols = len(self.observed_dofs_)
        o = as_2d_finite(partial, "partial", n_cols=n_cols, min_rows=1)
        if times is not None:
            t = check_times(times, o.shape[0], "times")
            o = resample_uniform(o, t, dt=self.dt_)[0] if o.shape[0] > 1 else o
        elif dt is not None and abs(check_positive(dt, "dt") - self.dt_) > 1e-12 * self.dt_ and o.shape[0] > 1:
            o = resample_uniform(o, np.arange(o.shape[0]) * dt, dt=self.dt_)[0]
        # inside CHECKED_BY_CALLER the caller marks the prediction (mark leaves it as it is): no distance to compute
        dist = float("nan") if checked_by_caller() else input_distance(self, o)
        z = self.observed_to_latent(o)
        if phase is not None:
            ph = float(phase)
            if not 0.0 < ph <= 1.0:
                raise ValueError(f"phase must be in (0, 1], got {phase!r}")
            p = self.predict_latent(z, ph * (self.reference_.shape[0] - 1), float("nan"), robot_state)
        else:
            n_star, cost = estimate_phase(self, z, self.phase_method_used())
            p = self.predict_latent(movement_prefix(self, z, n_star), n_star, cost, robot_state)
        return mark(self, p, dist)

    def stream(self, robot_state=None):
        """Online predictor that takes one observed frame at a time
        (:class:`~interprim.models.primitive.stream.Stream`)."""
        from .stream import Stream

        return Stream(self, robot_state)

    def phase_info(self, n_star: int, M: int):
        """``(s_end, duration)``: the fraction seen and the duration (s) from the reference index ``n_star`` matched by
        the ``M``-th observed frame (Eq. 9)."""
        N = self.reference_.shape[0]
        s_end = n_star / (N - 1)
        elapsed = (M - 1) * self.dt_
        if M > 1 and s_end > 0:
            duration = elapsed / s_end
        else:
            duration = self.mean_duration_
        return s_end, duration

    def observation_design(self, z, s_end):
        """Design ``X``, targets ``Y`` and start ``y0`` of the observation model (Eq. 13-15) at the observed frames
        ``z`` placed on ``[0, s_end]`` (numpy; the reference of the compiled statistics)."""
        M = z.shape[0]
        s = np.linspace(0.0, s_end, M)
        ds = s_end / (M - 1)
        y, yd, ydd = derivatives(z, ds, self.smoothing_window)
        if self.observation == "forcing":
            X = self.basis_.phi_tilde(s, self.alpha_y, self.beta_y_)  # Eq. 13 rows
            Y = forcing_values(y, yd, ydd, self.alpha_y, self.beta_y_)  # Eq. 15
            y0 = y[0]
        else:
            free, X = self.rollout_.design(0.0, s)
            y0 = y[0]
            v0 = self.start_velocity_[: self.n_observed_latent_]
            Y = z - free @ np.vstack([y0, v0])
        return X, Y, y0

    def predict_latent(self, z, n_star, cost, robot_state, need_cov=False, robot_start=None,
                       workspace=None) -> Prediction:
        """The :class:`Prediction` for latent observed frames ``z (M, n_observed_latent_)`` at the reference frame
        ``n_star`` (Eq. 9: fraction seen ``n_star / (N - 1)``): Eq. 13-18 when at least ``min_observed`` frames
        were seen, else the prior.  The one path of :meth:`predict` and :meth:`Stream.update`."""
        M = z.shape[0]
        s_end, duration = self.phase_info(n_star, M)
        prior = self.prior_
        stats = None
        if M >= self.min_observed and s_end > 0:
            stats, y0 = self.observation_stats(z, s_end, workspace)
            post = self.condition(stats, need_cov)
        else:
            y0 = z[0]
            post = Posterior(prior.mean, prior.cov, 0.0)
        if robot_start is None:
            robot_start = self.robot_start(robot_state)
        return Prediction(self, post, stats, s_end, duration, n_star, cost, M, y0, robot_start, z[-1])

    def observation_stats(self, z, s_end, workspace=None):
        """Sufficient statistics ``(X^T X, X^T Y, |Y|^2, n)`` of the observation (Eq. 13-15) and the start ``y0``.

        With the compiled kernels loaded, the position observation (any
        ``smoothing_window``; only the smoothed start ``y0`` depends on it) and
        the paper's forcing observation without smoothing run on preallocated
        buffers (``workspace``; fixed-size blocks for positions, grown by
        doubling for forcing values), so nothing proportional to ``M`` is
        allocated.  The work stays ``O(M q (q + D_o))`` for ``M`` frames: every
        frame gets a new phase ``s_j = j s_end / (M - 1)`` whenever the phase
        estimate moves.
        Otherwise :meth:`observation_design` (numpy, the reference) is used; both
        give the same numbers (tested to 1e-12).
        """
        M = z.shape[0]
        if M >= 3 and kernels.in_use():
            from ...core._compiled.observation import StatsWorkspace
            from ...core.preprocessing import start_position

            if self.observation == "position":
                z = np.ascontiguousarray(z, dtype=np.float64)
                ws = workspace if workspace is not None else \
                    StatsWorkspace(M, z.shape[1], self.params_per_dof_, "position")
                y0 = start_position(z, self.smoothing_window)
                v0 = self.start_velocity_[: self.n_observed_latent_]
                G, B, yy = ws.position_stats(z, M, s_end, y0, v0, self.rollout_)
                return (G.copy(), B.copy(), yy, M * z.shape[1]), y0
            if self.observation == "forcing" and self.smoothing_window is None:
                ws = workspace if workspace is not None else StatsWorkspace(M, z.shape[1], self.params_per_dof_)
                G, B, yy = ws.forcing_stats(z, M, s_end, self)
                return (G.copy(), B.copy(), yy, M * z.shape[1]), z[0].copy()
        X, Y, y0 = self.observation_design(z, s_end)
        return (X.T @ X, X.T @ Y, float(np.sum(Y * Y)), Y.size), y0

    def conditioner(self):
        """Precomputed Eq. 18 for the low-rank-plus-diagonal prior
        (:class:`~interprim.core.gaussian.LowRankConditioner`), or ``None`` when the prior has no such form."""
        return self.cached("conditioner", (self.prior_, self.obs_index_), lambda: self.prior_.conditioner(
            self.obs_index_, getattr(self, "thetas_", None), float(self.ridge)))

    def condition(self, stats, need_cov: bool) -> Posterior:
        """Eq. 16-18 with Omega~ = [Omega, 0] from sufficient statistics ``(X^T X, X^T Y, |Y|^2, n)``.

        Uses the exact low-rank form of :class:`~interprim.core.gaussian.LowRankConditioner`
        (compiled) when the prior has it, else the structured dense form of
        :func:`~interprim.core.gaussian.condition`; the covariance is computed only
        when asked for (``need_cov``; :attr:`Prediction.posterior_cov` asks lazily).
        """
        G, B, yy, n = stats
        cond = self.conditioner()
        if cond is not None:
            res = cond.mean_and_evidence(G, B, self.sigma2_, yy, n)
            if res is not None:
                cov = cond.cov(G, self.sigma2_) if need_cov else None
                return Posterior(res[0], cov, res[1])
        return self.prior_.condition(self.obs_index_, G, B, self.sigma2_, yy=yy, n_obs=n, need_cov=need_cov)

    def __repr__(self):
        return (f"<FittedPrimitive {self.n_demos_} demonstrations, {len(self.observed_dofs_)}+"
                f"{len(self.controlled_dofs_)} columns, phase {self.phase_method_used()}>"
                if hasattr(self, "prior_") else "<FittedPrimitive (being fitted)>")

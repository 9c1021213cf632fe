"""Interaction Primitives: both agents, phase, conditioning and prediction (paper Sec. III, Eq. 1-18).

:class:`InteractionPrimitive` is the public estimator.  ``fit`` turns each
demonstration into DMP parameters (Eq. 3-4) of every DoF of both agents and
learns ``p(theta)`` over ``theta = [theta_o, theta_c]`` (Eq. 10).  ``predict``
estimates the phase of a partial observation of the observed agent (by
open-end DTW, Eq. 5-9, or by the likelihood of the observation), conditions
``p(theta)`` on it with ``Omega~ = [Omega, 0]`` (Eq. 15-18, Sec. III-D) and
returns a :class:`Prediction` of the whole interaction.  ``stream`` does the
same one frame at a time (incremental DTW, or a local likelihood search).

Internally the DoFs are ordered observed agent first, then controlled agent
(after the optional PCA of each agent, paper Sec. IV); every output is mapped
back to the demonstrations' column order.
"""

from __future__ import annotations

import copy
import math
import numbers
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ...core.blas import one_blas_thread
from ...core.dmp import check_rollout_size, warn_representation
from ...core.errors import NotFittedError
from ...core.validation import check_min_frames, check_positive
from ...model_selection.prefixes import Prefixes
from ..base import Predictor
from ..training import TrainingSet
from .fitted import FittedPrimitive
from .prediction import Prediction
from .stream import Stream

if TYPE_CHECKING:
    from ...core.basis import Basis
    from ...core.dmp import LinearRollout
    from ...core.gaussian import GaussianPrior
    from ...core.preprocessing import PCA
    from ...phase.learned import LearnedPhase
    from .calibration import Calibration

__all__ = ["InteractionPrimitive", "Prediction", "Stream"]

OBSERVATION_MODELS = ("forcing", "position")
COVARIANCE_METHODS = ("shrinkage", "ridge", "empirical")
PHASE_METHODS = ("dtw", "likelihood", "learned", "cv")
SIGMA2_RULES = ("cv", "residual")
CALIBRATE_RULES = ("with-cv",)
#: the largest prior covariance ``fit`` builds (``n_basis`` is refused beyond it): 2 GiB of float64, e.g. 240 DoFs
#: (two agents of 40 markers) up to 67 basis functions; the fit holds a few arrays of that size
MAX_COVARIANCE_BYTES = 2 << 30
#: Values of releases up to 0.1.0 that model files may still hold: read as their names of today (interprim.io)
OLD_VALUES = {"phase_method": {"auto": "cv"}, "sigma2": {"auto": "residual"}, "calibrate": {"auto": "with-cv"}}


class FittedView:
    """A read-only attribute of the estimator that shows the fitted state's attribute of the same name
    (``InteractionPrimitive.prior_`` is ``InteractionPrimitive.fitted_.prior_``); like a ``property`` without a
    setter, and ``AttributeError`` before ``fit``."""

    def __init__(self, name: str):
        self.name = name
        self.__doc__ = f"``fitted_.{name}``: a read-only view of the fitted state (see the class docstring)."

    def __get__(self, obj, owner=None):
        if obj is None:
            return self
        st = obj.__dict__.get("fitted_")
        if st is None:
            raise AttributeError(f"{self.name} (this InteractionPrimitive is not fitted yet)")
        return getattr(st, self.name)

    def __set__(self, obj, value):
        raise AttributeError(f"{self.name} is a read-only view of the fitted state; use with_fitted({self.name}=...)")


def fitted_view(name: str) -> Any:
    """A :class:`FittedView` of ``name`` (typed ``Any``, so the class body can annotate each view's type)."""
    return FittedView(name)


class InteractionPrimitive(Predictor):
    """An Interaction Primitive (Ben Amor et al., ICRA 2014).

    The parameters marked "(Advanced.)" are rarely changed: their defaults are the paper's or were measured
    to suit every data set we have.

    Parameters
    ----------
    observed_dofs : sequence of int
        Columns of the demonstrations that belong to the observed agent (the
        human).  All other columns are the controlled agent (the robot).
        Listing every column gives the single-agent model of the paper's
        handwriting experiments (Fig. 3-4).
    n_basis : int or "cv", default 20
        Basis functions per DoF (Eq. 2); ``theta`` has ``n_basis + 1`` entries per DoF.  ``"cv"``: chosen from the
        demonstrations by :func:`choose_n_basis` (the fewest of :data:`N_BASIS_GRID` whose held-out error of the
        mean movement is within one standard error of the best; ``selection_["n_basis"]`` says what was compared);
        the fitted state, and a model file, hold the number chosen.
    alpha_y : float, default 25.0
        (Advanced.) Spring constant of Eq. 1.
    beta_y : float, optional
        (Advanced.) Damper constant of Eq. 1; default ``alpha_y / 4`` (critically damped).
    alpha_x : float, default 3.0
        (Advanced.) Canonical system decay; ``x`` falls from 1 to ``exp(-alpha_x)`` over the movement.
    sigma2 : "cv", "residual" or float, default "cv"
        Observation noise variance of Eq. 16.  ``"cv"`` (the default) chooses ``sigma2`` and (with
        ``covariance="shrinkage"``) the shrinkage intensity and a damping of the cross-agent covariance by
        K-fold cross-validation (the observed agent's completion within its noise, then the controlled
        agent's response) on the training demonstrations
        (:func:`interprim.models.primitive.selection.select_hyperparameters`);
        the choice is reported in ``selection_``.  When conditioning does not
        help on held-out training folds it falls back towards the prior mean, at the price of a slower
        ``fit`` (about 3 s at 7+7 DoF, 25 basis functions, 30 demonstrations).
        ``"residual"`` (the paper's setting) uses the mean
        squared residual of the observation model on the training
        demonstrations' own fits (observed DoFs), which sets the noise on the
        scale of the chosen observation; on noisy or recorded data it is
        overconfident (see ``docs/observation-models.md``).
    covariance : {"shrinkage", "ridge", "empirical"}, default "shrinkage"
        Regularisation of Eq. 10's covariance (see :func:`interprim.core.gaussian.fit_prior`).
    ridge : float, default 1e-6
        (Advanced.) Relative diagonal loading of the covariance.
    observation : {"position", "forcing"}, default "position"
        ``"forcing"`` conditions on forcing values of the observation (Eq. 15,
        the paper's method, kept exactly); ``"position"`` (the default) conditions on the observed
        positions themselves, which are linear in ``theta`` given the start
        state (integrated Eq. 1), and needs no second derivatives: better or
        equal on every recorded or noisy data set we measured (``docs/observation-models.md``).
        The paper's method exactly is ``observation="forcing", sigma2="residual", phase_method="dtw"``.
    smoothing_window : int or None, default None
        Savitzky-Golay window (frames) used for the derivatives of Eq. 3 and
        Eq. 15; ``None`` uses central differences (noise-free data).
    pca_components : None, int or (int, int)
        Project each agent onto this many principal components before
        learning (paper Sec. IV); an int applies to both agents.
    reference : "mean" or int, default "mean"
        (Advanced.) Reference movement for DTW: the mean of the time-normalised
        demonstrations of the observed agent, or the demonstration with this index
        (the paper's choice).
    min_observed : int, default 3
        (Advanced.) Fewer observed frames than this give the prior (no conditioning).
    n_steps : int, default 2000
        (Advanced.) Integration steps over the movement (see :class:`interprim.core.dmp.LinearRollout`).
    phase_method : {"cv", "likelihood", "learned", "dtw"}, default "cv"
        How ``predict`` and ``Stream`` estimate the phase (how far through the movement the partner is):

        * ``"likelihood"``: the maximum of the marginal likelihood of the observed positions under the learned
          prior over candidate phases, with a log-normal prior on the partner's speed learned from the
          demonstrations (:mod:`interprim.phase.likelihood`; a stream tracks it by local search and ends where
          the batch search ends unless the log posterior has several peaks).  On demonstrations that differ in
          goal, DTW confuses "further along" with "aiming further" (phase errors 0.1-0.2 of the movement on the
          built-in data), the likelihood does not (0.003-0.016).
        * ``"learned"``: regressed on features of the observed prefix, trained on the demonstrations' own
          prefixes (:class:`~interprim.phase.learned.LearnedPhase`, ``phase_model_``): better than a clock on
          recordings of people (NuiSI: 0.71x its error), where the likelihood phase is not; worse on clean
          simulated data.
        * ``"cv"`` (the default): whichever of the two has
          the smaller held-out phase error on the training
          demonstrations (``phase_method_``; both figures in ``selection_``: ``phase_error_refined`` and
          ``learned_phase_error``).  It picks the likelihood on the built-in simulated and synthetic data and
          the learned phase on all six NuiSI interactions.
        * ``"dtw"``: the paper's open-end DTW (Eq. 5-9); faster, and better for movements much faster or slower
          than every demonstration (0.7x / 1.5x), which the speed prior penalises.
    input_noise : float, optional
        Standard deviation (data units; latent units after PCA) of noise in the
        online observations that the demonstrations do not have: sensor noise
        of the robot's perception, quantised pointer input, a partner tracked by
        another system.  Its variance is added to the position noise of the
        conditioning (``observation="position"``) and of the likelihood phase.
        ``sigma2="cv"`` learns the noise *of the demonstrations*; on clean (e.g.
        simulated) demonstrations that noise is tiny, and a noisier input then
        moves the prediction far more than it should (measured on the simulated
        high five with 0.01 rad input noise: goal error 0.35 m without, 0.05 m
        with ``input_noise=0.01``).
    calibrate : bool or "with-cv", default "with-cv"
        Calibrate the predictive uncertainty on held-out folds of the training demonstrations
        (:mod:`interprim.models.primitive.calibration`): :meth:`Prediction.std` and :meth:`Prediction.samples` are the
        posterior's, scaled per column, fraction seen and look-ahead so that their 90 % band covers about 90 % of
        held-out movements, timing errors included.  ``"with-cv"``: calibrate when ``sigma2="cv"`` (the
        default; the folds re-use what that cross-validation chose), not with the paper's ``sigma2="residual"``
        or a fixed ``sigma2``.  ``True`` calibrates whatever
        ``sigma2``, ``False`` never.  A calibration needs at least 6 demonstrations (with fewer there is
        none); the fitted scales are ``calibration_`` (``None`` when not calibrated).

    Attributes
    ----------
    fitted_ : FittedPrimitive
        The fitted state (:class:`interprim.models.primitive.fitted.FittedPrimitive`), made anew by every
        :meth:`fit` (and by
        :meth:`load`); it computes the predictions.  The attributes below are read-only views of it;
        :meth:`with_fitted` gives a copy with some of them replaced.
    observed_dofs_, controlled_dofs_ : list of int
        Data columns of the observed and the controlled agent.
    n_dofs_ : int
        Columns of the demonstrations.
    columns_ : list of str or None
        Their names, when given to :meth:`fit`.
    dt_ : float
        Sampling interval of the (resampled) demonstrations, seconds.
    n_demos_ : int
        Number of demonstrations.
    durations_ : ndarray, shape (n_demos_,)
        Duration of each demonstration in seconds; ``mean_duration_`` is their mean.
    beta_y_ : float
        Damper constant of Eq. 1 in use.
    pca_observed_, pca_controlled_ : PCA or None
        Per-agent projections (Sec. IV); ``n_observed_latent_`` and ``n_latent_`` count the latent DoFs.
    basis_ : Basis
        The basis functions of Eq. 2; ``rollout_`` integrates Eq. 1 linearly in ``theta``.
    thetas_ : ndarray, shape (n_demos_, n_latent_ * (n_basis + 1))
        DMP parameters ``[w_1, g_1, ..., w_N, g_N]`` of each demonstration (Eq. 3-4), observed DoFs first.
    prior_ : GaussianPrior
        ``p(theta)`` of Eq. 10.
    representation_ : dict
        How well the DMPs represent the demonstrations, per agent (``"observed"``, ``"controlled"``):
        ``reconstruction`` (each demonstration rolled out from its own parameters, Eq. 1) and ``mean_offset``
        (the mean parameters' rollout against the demonstrations' mean), both as RMS error / the RMS spread
        between demonstrations, and ``spread`` (:func:`interprim.core.dmp.representation_report`).  Above 0.5 ``fit``
        warns (:class:`~interprim.RepresentationWarning`); also kept in ``selection_["representation"]``.
    sigma2_ : float
        Observation noise of Eq. 16 in use; ``phase_sigma2_`` the position noise of the likelihood phase
        (``None`` when not chosen).
    selection_ : dict
        What ``fit`` chose and why (:meth:`summary` prints the gist).  Choices: ``sigma2``, ``shrinkage``
        (of Eq. 10's covariance), ``cross_shrinkage`` (the cross-agent damping gamma: 1 = the controlled agent's
        prior mean), ``phase_sigma2``, ``observation``, ``method`` and ``n_folds`` (how), ``fractions`` (fractions
        seen in the held-out cases).  Held-out errors at the choice (mean squared error of the whole movement, each
        DoF divided by its variance): ``cv_error`` / ``cv_error_prior`` (``cv_target``, the controlled agent, and
        its prior mean), ``cv_error_observed`` / ``cv_error_observed_prior``.  Phase (``phase_method="cv"``):
        ``phase_error_refined`` (likelihood), ``learned_phase_error``, ``clock_phase_error``.  Candidates and
        their scores: ``*_grid``, ``cv_errors``, ``cv_errors_observed``, ``cv_within_se``,
        ``cv_observed_within_se``, ``phase_error``, ``phase_log_likelihood`` (``None`` for a fit inside
        :func:`interprim.core.cache.records_unused`, whose records nobody reads); ``representation`` (as
        ``representation_``).  Keys are left out where they do
        not apply (e.g. ``sigma2="residual"`` has no ``cv_*``).
    phase_method_ : str
        The phase method ``fit`` chose (``phase_method="cv"``) or was given; ``phase_model_`` is the
        fitted :class:`~interprim.phase.learned.LearnedPhase` or ``None``.
    reference_ : ndarray, shape (N, n_observed_latent_)
        DTW reference of the observed agent (Sec. III-B).
    start_position_, start_velocity_ : ndarray, shape (n_latent_,)
        Mean start state of the demonstrations (latent DoFs; velocity per unit normalised time).
    input_mean_, input_std_, input_limit_ : ndarray, ndarray, float
        Range of the observed agent's training frames (:mod:`interprim.core.input_range`).
    calibration_ : Calibration or None
        Scales of the predictive std (:mod:`interprim.models.primitive.calibration`).
    """

    _CHECKS_INPUT = True  # its fitted state and stream compute input_distance / out_of_range themselves
    OLD_VALUES = OLD_VALUES

    # the fitted attributes: read-only views of the fitted state (``fitted_``; the Attributes section above)
    observed_dofs_: list[int] = fitted_view("observed_dofs_")
    controlled_dofs_: list[int] = fitted_view("controlled_dofs_")
    n_dofs_: int = fitted_view("n_dofs_")
    columns_: list[str] | None = fitted_view("columns_")
    dt_: float = fitted_view("dt_")
    n_demos_: int = fitted_view("n_demos_")
    durations_: np.ndarray = fitted_view("durations_")
    mean_duration_: float = fitted_view("mean_duration_")
    beta_y_: float = fitted_view("beta_y_")
    pca_observed_: PCA | None = fitted_view("pca_observed_")
    pca_controlled_: PCA | None = fitted_view("pca_controlled_")
    n_observed_latent_: int = fitted_view("n_observed_latent_")
    n_latent_: int = fitted_view("n_latent_")
    basis_: Basis = fitted_view("basis_")
    rollout_: LinearRollout = fitted_view("rollout_")
    params_per_dof_: int = fitted_view("params_per_dof_")
    obs_index_: np.ndarray = fitted_view("obs_index_")
    thetas_: np.ndarray = fitted_view("thetas_")
    start_position_: np.ndarray = fitted_view("start_position_")
    start_velocity_: np.ndarray = fitted_view("start_velocity_")
    prior_: GaussianPrior = fitted_view("prior_")
    representation_: dict = fitted_view("representation_")
    sigma2_: float = fitted_view("sigma2_")
    phase_sigma2_: float | None = fitted_view("phase_sigma2_")
    selection_: dict = fitted_view("selection_")
    phase_model_: LearnedPhase | None = fitted_view("phase_model_")
    phase_method_: str = fitted_view("phase_method_")
    reference_: np.ndarray = fitted_view("reference_")
    input_mean_: np.ndarray = fitted_view("input_mean_")
    input_std_: np.ndarray = fitted_view("input_std_")
    input_limit_: float = fitted_view("input_limit_")
    calibration_: Calibration | None = fitted_view("calibration_")

    def __init__(self, observed_dofs, n_basis: int = 20, alpha_y: float = 25.0, beta_y: float | None = None,
                 alpha_x: float = 3.0, sigma2="cv", covariance: str = "shrinkage", ridge: float = 1e-6,
                 observation: str = "position", smoothing_window: int | None = None, pca_components=None,
                 reference="mean", min_observed: int = 3, n_steps: int = 2000, phase_method: str = "cv",
                 input_noise: float | None = None, calibrate="with-cv"):
        self.observed_dofs = observed_dofs
        self.n_basis = n_basis
        self.alpha_y = alpha_y
        self.beta_y = beta_y
        self.alpha_x = alpha_x
        self.sigma2 = sigma2
        self.covariance = covariance
        self.ridge = ridge
        self.observation = observation
        self.smoothing_window = smoothing_window
        self.pca_components = pca_components
        self.reference = reference
        self.min_observed = min_observed
        self.n_steps = n_steps
        self.phase_method = phase_method
        self.input_noise = input_noise
        self.calibrate = calibrate

    # ------------------------------------------------------------------ parameters
    def json_params(self) -> dict:
        """:meth:`get_params` with JSON types (lists, floats, ints), as stored in a model file."""
        obs = self.observed_dofs
        pca = self.pca_components
        return {
            "observed_dofs": [int(i) for i in obs] if obs is not None else None,
            "n_basis": self.n_basis if isinstance(self.n_basis, str) else int(self.n_basis),
            "alpha_y": float(self.alpha_y),
            "beta_y": None if self.beta_y is None else float(self.beta_y), "alpha_x": float(self.alpha_x),
            "sigma2": self.sigma2 if isinstance(self.sigma2, str) else float(self.sigma2),
            "covariance": self.covariance, "ridge": float(self.ridge), "observation": self.observation,
            "smoothing_window": None if self.smoothing_window is None else int(self.smoothing_window),
            "pca_components": None if pca is None else ([int(pca), int(pca)] if isinstance(pca, numbers.Integral)
                                                        else [int(p) for p in pca]),
            "reference": self.reference if isinstance(self.reference, str) else int(self.reference),
            "min_observed": int(self.min_observed), "n_steps": int(self.n_steps),
            "phase_method": self.phase_method,
            "input_noise": None if self.input_noise is None else float(self.input_noise),
            "calibrate": self.calibrate if isinstance(self.calibrate, str) else bool(self.calibrate),
        }

    def _check_params(self, n_dofs: int, n_demos: int, min_frames: int | None = None):
        """Validate every parameter (cheap; ``fit`` calls it before any expensive work, with ``min_frames`` the
        frames of the shortest demonstration, which bounds ``n_basis``; a model file's load without)."""
        obs = self.observed_dofs
        if obs is None or isinstance(obs, (str, bytes)) or np.ndim(obs) != 1 or len(obs) == 0:
            raise TypeError(f"observed_dofs must be a non-empty sequence of column indices, got {obs!r}")
        if not all(isinstance(i, numbers.Integral) for i in obs):
            raise TypeError(f"observed_dofs must hold integers, got {list(obs)!r}")
        obs = [int(i) for i in obs]
        if len(set(obs)) != len(obs):
            raise ValueError(f"observed_dofs has repeated columns: {obs}")
        bad = [i for i in obs if not 0 <= i < n_dofs]
        if bad:
            raise ValueError(f"observed_dofs {bad} out of range for demonstrations with {n_dofs} columns")
        if not (self.n_basis == "cv" if isinstance(self.n_basis, str) else
                (isinstance(self.n_basis, numbers.Integral) and not isinstance(self.n_basis, bool)
                 and self.n_basis >= 2)):
            raise ValueError(f"n_basis must be an integer >= 2 or 'cv', got {self.n_basis!r}")
        for name in ("alpha_y", "alpha_x"):
            check_positive(getattr(self, name), name)
        if self.beta_y is not None:
            check_positive(self.beta_y, "beta_y")
        if self.observation not in OBSERVATION_MODELS:
            raise ValueError(f"observation must be one of {OBSERVATION_MODELS}, got {self.observation!r}")
        if self.input_noise is not None:
            check_positive(self.input_noise, "input_noise")
        if isinstance(self.sigma2, str) and self.sigma2 not in SIGMA2_RULES:
            try:
                float(self.sigma2)
            except ValueError:
                raise ValueError(f"sigma2 must be one of {SIGMA2_RULES} or a positive number, "
                                 f"got {self.sigma2!r}") from None
        if not (isinstance(self.sigma2, str) and self.sigma2 in SIGMA2_RULES):
            check_positive(self.sigma2, "sigma2")
        if self.phase_method not in PHASE_METHODS:
            raise ValueError(f"phase_method must be one of {PHASE_METHODS}, got {self.phase_method!r}")
        if self.smoothing_window is not None and (not isinstance(self.smoothing_window, numbers.Integral)
                                                  or self.smoothing_window < 3 or self.smoothing_window % 2 == 0):
            raise ValueError(f"smoothing_window must be None or an odd integer >= 3, got {self.smoothing_window!r}")
        if not isinstance(self.min_observed, numbers.Integral) or self.min_observed < 3:
            raise ValueError(f"min_observed must be an integer >= 3, got {self.min_observed!r}")
        if self.covariance not in COVARIANCE_METHODS:
            raise ValueError(f"covariance must be one of {COVARIANCE_METHODS}, got {self.covariance!r}")
        if isinstance(self.ridge, bool) or not isinstance(self.ridge, numbers.Real) or not (
                np.isfinite(self.ridge) and self.ridge >= 0):
            raise ValueError(f"ridge must be a finite number >= 0, got {self.ridge!r}")
        if isinstance(self.n_steps, bool) or not isinstance(self.n_steps, numbers.Integral) or self.n_steps < 1:
            raise ValueError(f"n_steps must be a positive integer, got {self.n_steps!r}")
        if not (self.calibrate is True or self.calibrate is False or isinstance(self.calibrate, np.bool_)
                or (isinstance(self.calibrate, str) and self.calibrate in CALIBRATE_RULES)):
            raise ValueError(f"calibrate must be True, False or 'with-cv', "
                             f"got {self.calibrate!r}")
        ref = self.reference
        if isinstance(ref, str):
            if ref != "mean":
                raise ValueError(f"reference must be 'mean' or a demo index, got {ref!r}")
        elif isinstance(ref, bool) or not isinstance(ref, numbers.Integral):
            raise ValueError(f"reference must be 'mean' or a demo index, got {ref!r}")
        elif not 0 <= int(ref) < n_demos:
            raise ValueError(f"reference={int(ref)} is not a demo index (0..{n_demos - 1})")
        ctrl = [i for i in range(n_dofs) if i not in set(obs)]
        pca = self.pca_components
        if pca is not None:
            kk = [pca, pca] if isinstance(pca, numbers.Integral) else list(pca)
            if len(kk) != 2 or not all(isinstance(k, numbers.Integral) and k >= 1 for k in kk):
                raise ValueError(f"pca_components must be a positive int or a pair of them, got {pca!r}")
            kk = [min(int(kk[0]), len(obs)), min(int(kk[1]), len(ctrl))]
        else:
            kk = None
        if not isinstance(self.n_basis, str):
            check_rollout_size(int(self.n_basis), self.n_steps)
            if min_frames is not None:
                self._check_n_basis(int(self.n_basis), n_dofs if kk is None else sum(kk), min_frames)
        return obs, ctrl, kk

    def check_params(self, n_dofs: int, n_demos: int) -> None:
        """Check every parameter as ``fit`` does for ``n_dofs``-column data of ``n_demos`` demonstrations (a model
        file's parameters, before its state is built); ``ValueError`` or ``TypeError`` naming the parameter."""
        self._check_params(n_dofs, n_demos)

    @staticmethod
    def _check_n_basis(n_basis: int, n_latent: int, min_frames: int) -> None:
        """``ValueError`` naming ``n_basis`` and its limit when the data cannot support it: more basis functions than
        frames of the shortest demonstration, or a prior covariance over :data:`MAX_COVARIANCE_BYTES`."""
        if n_basis > min_frames:
            raise ValueError(f"n_basis={n_basis} is more basis functions than the {min_frames} frames of the "
                             f"shortest demonstration: n_basis must be at most {min_frames}")
        P = n_latent * (n_basis + 1)
        if P * P * 8 > MAX_COVARIANCE_BYTES:
            limit = int(math.isqrt(MAX_COVARIANCE_BYTES // 8) // n_latent) - 1
            raise ValueError(f"n_basis={n_basis} makes {P} parameters ({n_latent} DoFs x {n_basis + 1}), whose "
                             f"covariance takes {P * P * 8 / 2**20:.0f} MiB, over the limit of "
                             f"{MAX_COVARIANCE_BYTES >> 20} MiB: n_basis must be at most {limit} for {n_latent} DoFs")

    # ------------------------------------------------------------------ fitting
    def _fit(self, data: TrainingSet) -> None:
        """Learn the Interaction Primitive from the validated training set (:meth:`fit` of
        :class:`~interprim.models.base.Predictor`: a list of ``(T_j, D)`` arrays with ``dt`` or ``times``, a
        :class:`~interprim.datasets.Demonstrations` or a :class:`~interprim.models.training.TrainingSet`): at
        least 2 demonstrations of at least 5 frames (``smoothing_window`` when larger); the column names are
        kept as ``columns_`` and in the model file."""
        if len(data) < 2:
            raise ValueError(f"at least 2 demonstrations are needed to learn a distribution, got {len(data)}")
        arrays = list(data.arrays)
        D = data.n_dofs
        columns = None if data.columns is None else list(data.columns)
        dt = data.dt
        check_min_frames(arrays, max(5, self.smoothing_window or 0))
        obs, ctrl, kk = self._check_params(D, len(arrays), min(a.shape[0] for a in arrays))
        self.__dict__.pop("fitted_", None)  # a fit that fails leaves the estimator unfitted
        params = self.json_params()
        chosen = None
        if self.n_basis == "cv":  # the representation chosen from the demonstrations
            chosen = choose_n_basis(params, arrays, dt, columns, obs, ctrl, kk)
            params["n_basis"] = chosen["chosen"]
        # with their raw samples (an irregular recording), the calibration's held-out cases see causal prefixes
        recorded = Prefixes(data, obs)
        prefixes = recorded if recorded.causal else None
        self.fitted_ = FittedPrimitive.learn(params, arrays, dt, columns, obs, ctrl, kk, prefixes)
        if chosen is not None:
            self.fitted_.selection_["n_basis"] = chosen  # fit assigns what the choice returned
        # at the caller's line: here, Predictor.fit, its one-BLAS-thread wrapper, the caller
        warn_representation(self.fitted_.representation_, int(params["n_basis"]), stacklevel=5)

    # ------------------------------------------------------------------ the fitted state
    def _state(self) -> FittedPrimitive:
        """The fitted state with the parameters that may change after ``fit`` (``phase_method``) as they are now."""
        st = self.fitted_
        if self.phase_method != st.phase_method:
            st = st.with_params(phase_method=self.phase_method)
        return st

    def _check_fitted(self, what: str):
        if "fitted_" not in self.__dict__:
            raise NotFittedError(f"this InteractionPrimitive is not fitted yet; call fit(demos) before {what}")

    def load_fitted(self, fitted) -> InteractionPrimitive:
        """Take the fitted state ``fitted``: a :class:`~interprim.models.primitive.fitted.FittedPrimitive`, or a
        dict of fitted attributes (names ending in ``_``, as :mod:`interprim.io` reads them from a model file) from
        which one is built with this estimator's parameters; returns ``self``."""
        if not isinstance(fitted, FittedPrimitive):
            fitted = FittedPrimitive(self.json_params(), fitted)
        self.fitted_ = fitted
        return self

    def __copy__(self):
        """A shallow copy whose fitted state has its own (empty) store of derived values."""
        new = type(self).__new__(type(self))
        new.__dict__.update(self.__dict__)
        if "fitted_" in self.__dict__:
            new.fitted_ = self.fitted_.with_fitted()
        return new

    def with_fitted(self, **fitted) -> InteractionPrimitive:
        """A copy of this fitted model with some fitted attributes (names ending in ``_``) replaced
        (:meth:`FittedPrimitive.with_fitted <interprim.models.primitive.fitted.FittedPrimitive.with_fitted>`);
        ``self`` is unchanged."""
        self._check_fitted("with_fitted")
        new = copy.copy(self)
        new.fitted_ = self.fitted_.with_fitted(**fitted)
        return new

    def without_calibration(self) -> InteractionPrimitive:
        """A copy of this fitted model whose predictive std is not calibrated, and says so (``calibrate=False``,
        ``calibration_`` None, in the model and in its file; a calibration deferred by a fit inside
        :func:`interprim.core.cache.std_unused` is dropped, never measured): for a member of a
        :class:`~interprim.models.blend.Blend`, whose band the blend's variance model gives from the members'
        means (:meth:`FittedPrimitive.without_calibration
        <interprim.models.primitive.fitted.FittedPrimitive.without_calibration>`).  Its means are this model's;
        ``self`` is unchanged."""
        self._check_fitted("without_calibration")
        new = copy.copy(self)
        new.calibrate = False
        new.fitted_ = self.fitted_.without_calibration()
        return new

    def phase_method_used(self) -> str:
        """The phase method in use: ``phase_method``, or with ``"cv"`` the one ``fit`` chose (``phase_method_``)."""
        if self.phase_method == "cv":
            return getattr(self, "phase_method_", "likelihood")
        return self.phase_method

    def input_distance(self, frames) -> float:
        """Largest standardised distance of observed frames ``(t, D_o)`` (data columns) from the training frames
        (:mod:`interprim.core.input_range`, the contract of :class:`~interprim.models.base.Predictor`); NaN for a
        model file without those statistics."""
        self._check_fitted("input_distance")
        return self.fitted_.input_distance(frames)

    # ------------------------------------------------------------------ prediction
    @one_blas_thread
    def predict(self, partial, robot_state=None, dt: float | None = None, times=None,  # type: ignore[override]
                phase: float | None = None) -> Prediction:  # (the options it names; an unknown one is a TypeError)
        """Predict the interaction from a partial observation of the observed agent.

        Parameters
        ----------
        partial : array_like, shape (t, len(observed_dofs))
            Frames of the observed agent seen so far, from the start of the
            movement, in the order of ``observed_dofs``.
        robot_state : array_like, optional
            Start position of the controlled agent, shape ``(len(controlled_dofs),)``,
            or start position and velocity (in units per second) as shape ``(2, n)``.
            Default: the mean start of the demonstrations.
        dt : float, optional
            Sampling interval of ``partial`` when it differs from the training ``dt_``.
        times : array_like, shape (t,), optional
            Time stamps of ``partial`` (irregular sampling); resampled to ``dt_``.
        phase : float, optional
            Known normalised time (in (0, 1]) of the last observed frame; skips
            the phase estimation (for experiments with an oracle phase, or
            when the timing is known).

        Returns
        -------
        Prediction
            Computed by the fitted state
            (:meth:`FittedPrimitive.predict <interprim.models.primitive.fitted.FittedPrimitive.predict>`).
        """
        self._check_fitted("predict")
        return self._state().predict(partial, robot_state, dt, times, phase)


    def stream(self, robot_state=None) -> Stream:
        """Online predictor that takes one observed frame at a time (incremental DTW)."""
        self._check_fitted("stream")
        return self._state().stream(robot_state)


    # ------------------------------------------------------------------ persistence
    def save(self, path):
        """Save to a safe ``.npz`` model file (arrays + JSON metadata, no pickle); see :mod:`interprim.io`."""
        self._check_fitted("save")
        from .state_io import save_model

        save_model(self, path)

    def to_state(self):
        """``(arrays, meta)``: the fitted model as its model file holds it (numeric arrays and JSON metadata;
        :mod:`interprim.io`); :meth:`from_state` restores it."""
        self._check_fitted("to_state")
        return self._state().to_state()

    @classmethod
    def from_state(cls, arrays: dict, meta: dict, source="<state>") -> InteractionPrimitive:
        """The model of :meth:`to_state`'s ``(arrays, meta)`` (or of a model file's); raises
        :class:`~interprim.ModelFileError` naming ``source`` when they are inconsistent."""
        from .state_io import model_from_state

        return model_from_state(arrays, meta, cls, source)

    @classmethod
    def load(cls, path) -> InteractionPrimitive:
        """Load a model saved by :meth:`save`; raises :class:`~interprim.ModelFileError` on bad files."""
        from ...core.state_checks import building
        from .state_io import load_model

        with building(Path(path)):  # as Predictor.load: the file's name on every error, inconsistent values named
            return load_model(path, cls)

    def __repr__(self):
        import inspect

        defaults = {k: v.default for k, v in inspect.signature(type(self).__init__).parameters.items()}
        p = self.json_params()
        shown = ", ".join(f"{k}={v!r}" for k, v in p.items()
                          if k in ("observed_dofs", "n_basis") or v != defaults.get(k, inspect.Parameter.empty))
        if getattr(self, "prior_", None) is None:
            return f"InteractionPrimitive({shown})"
        from ..._summary import one_line

        return f"<InteractionPrimitive({shown}) {one_line(self)}>"

    def summary(self, fit_seconds: float | None = None) -> str:
        """What the fitted model chose, in a few lines: phase method, noise ``sigma2``, shrinkage, cross-agent
        damping and the held-out error against the prior mean (from :attr:`selection_`), and whether the
        uncertainty is calibrated.  ``fit_seconds``: a fit time to report (``interprim fit`` passes it)."""
        self._check_fitted("summary")
        from ..._summary import summary

        return summary(self, fit_seconds)


#: The numbers of basis functions per DoF that ``n_basis="cv"`` compares (capped by the demonstrations' length).
N_BASIS_GRID = (10, 15, 20, 30, 40, 60)


def choose_n_basis(params: dict, arrays, dt: float, columns, obs, ctrl, kk, grid=N_BASIS_GRID, n: int = 101) -> dict:
    """The number of basis functions chosen from the demonstrations by held-out error (``n_basis="cv"``).

    For each candidate ``K`` (at most half the shortest demonstration's frames), the DMPs of every
    demonstration are fitted (Eq. 3-4; the paper's residual sigma2, no calibration: only the parameters matter
    here).  Each demonstration ``j`` is then held out in turn: the mean of the *other* demonstrations' parameters
    is rolled out (Eq. 1) from the mean start (of all of them) and compared with demonstration ``j`` on a
    normalised-time grid of ``n`` points (every column divided by its spread over all frames).  This is the error
    of the model's own mean on a movement it did not see: it falls while more basis functions remove the
    representation's bias (a periodic movement that 20 cannot follow) and stops falling once the spread between
    demonstrations dominates.  The smallest ``K`` within one paired standard error of the best
    (:func:`interprim.core.cv.within_one_se`), or within 1 % of it, is kept.

    Returns
    -------
    dict
        ``chosen``, ``candidates``, ``cv_error`` (mean held-out error per candidate) and ``rule``.
    """
    from ...core.cv import within_one_se
    from ...core.preprocessing import time_normalise

    T_min = min(a.shape[0] for a in arrays)
    cands = [int(k) for k in grid if k + 1 <= max(T_min // 2, 3)] or [min(int(k) for k in grid)]
    truth = np.stack([time_normalise(a, n) for a in arrays])  # (S, n, D)
    scale = np.concatenate(arrays).std(axis=0)
    scale = np.where(scale > 0, scale, 1.0)
    S = len(arrays)
    s = np.linspace(0.0, 1.0, n)
    errors = np.empty((S, len(cands)))
    for c, K in enumerate(cands):
        cheap = dict(params, n_basis=K, sigma2="residual", phase_method="dtw", calibrate=False)
        st = FittedPrimitive.learn(cheap, arrays, dt, columns, obs, ctrl, kk)
        th = st.thetas_.reshape(S, st.n_latent_, K + 1)
        free, H = st.rollout_.design(0.0, s)
        M, off = st.latent_map()
        start = free @ np.stack([st.start_position_, st.start_velocity_])  # (n, d)
        total = th.sum(axis=0)
        for j in range(S):
            loo = (total - th[j]) / (S - 1)  # the mean of the other demonstrations' parameters
            y = (start + H @ loo.T) @ M.T + off
            errors[j, c] = float(np.sqrt(np.mean(((y - truth[j]) / scale) ** 2)))
    mean = errors.mean(axis=0)
    ok = within_one_se(errors) | (mean <= 1.01 * mean.min())  # and practically equal (1 %) counts as within
    chosen = cands[int(np.flatnonzero(ok)[0])]  # the fewest basis functions within one SE of the best
    return {"chosen": chosen, "candidates": cands, "cv_error": [float(e) for e in mean],
            "rule": "fewest basis functions whose leave-one-out error of the mean movement is within one "
                    "standard error (or 1 %) of the best"}

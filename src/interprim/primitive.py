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

import numbers

import numpy as np

from ._blas import one_blas_thread, single_thread
from .contract import Predictor
from ._validation import as_2d_finite, check_positive, check_times
from .basis import Basis
from .dmp import cached_rollout, fit_weights_stacked, fit_weights_targets, forcing_values, representation_report, warn_representation
from .errors import NotFittedError
from .input_range import fit_input_range, input_distance, mark
from ._compiled import registry as kernels
from .gaussian import LowRankConditioner, Posterior, condition, fit_prior
from .phase import estimate_phase, fit_phase_model, movement_prefix
from .prediction import Prediction
from .preprocessing import PCA, derivatives, resample_uniform, time_normalise
from .stream import Stream

__all__ = ["InteractionPrimitive", "Prediction", "Stream"]

OBSERVATION_MODELS = ("forcing", "position")
COVARIANCE_METHODS = ("shrinkage", "ridge", "empirical")
PHASE_METHODS = ("dtw", "likelihood", "learned", "cv", "auto")  # "auto": the old name of "cv"
SIGMA2_RULES = ("cv", "residual", "auto")  # "auto": the old name of "residual"
CALIBRATE_RULES = ("with-cv", "auto")  # "auto": the old name of "with-cv"


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
    n_basis : int, default 20
        Basis functions per DoF (Eq. 2); ``theta`` has ``n_basis + 1`` entries per DoF.
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
        agent's response) on the training demonstrations (:func:`interprim.selection.select_hyperparameters`);
        the choice is reported in ``selection_``.  When conditioning does not
        help on held-out training folds it falls back towards the prior mean, at the price of a slower
        ``fit`` (about 3 s at 7+7 DoF, 25 basis functions, 30 demonstrations).
        ``"residual"`` (the paper's setting; ``"auto"`` is its old name, still accepted) uses the mean
        squared residual of the observation model on the training
        demonstrations' own fits (observed DoFs), which sets the noise on the
        scale of the chosen observation; on noisy or recorded data it is
        overconfident (see ``docs/observation-models.md``).
    covariance : {"shrinkage", "ridge", "empirical"}, default "shrinkage"
        Regularisation of Eq. 10's covariance (see :func:`interprim.gaussian.fit_prior`).
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
        (Advanced.) Integration steps over the movement (see :class:`interprim.dmp.LinearRollout`).
    phase_method : {"auto", "cv", "likelihood", "learned", "dtw"}, default "auto"
        How ``predict`` and ``Stream`` estimate the phase (how far through the movement the partner is):

        * ``"likelihood"``: the maximum of the marginal likelihood of the observed positions under the learned
          prior over candidate phases, with a log-normal prior on the partner's speed learned from the
          demonstrations (:mod:`interprim.phase.likelihood`; a stream tracks it and ends where the batch search
          ends).  On demonstrations that differ in goal, DTW confuses "further along" with "aiming further"
          (phase errors 0.1-0.2 of the movement on the built-in data), the likelihood does not (0.003-0.016).
        * ``"learned"``: regressed on features of the observed prefix, trained on the demonstrations' own
          prefixes (:class:`~interprim.phase.learned.LearnedPhase`, ``phase_model_``): better than a clock on
          recordings of people (NuiSI: 0.71x its error), where the likelihood phase is not; worse on clean
          simulated data.
        * ``"cv"``, or ``"auto"`` (the default, the same choice under its old name): whichever of the two has
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
        (:mod:`interprim.calibration`): :meth:`Prediction.std` and :meth:`Prediction.samples` are the
        posterior's, scaled per column, fraction seen and look-ahead so that their 90 % band covers about 90 % of
        held-out movements, timing errors included.  ``"with-cv"``: calibrate when ``sigma2="cv"`` (the
        default; the folds re-use what that cross-validation chose), not with the paper's ``sigma2="residual"``
        or a fixed ``sigma2``; ``"auto"`` is its old name, still accepted.  ``True`` calibrates whatever
        ``sigma2``, ``False`` never.  A calibration needs at least 6 demonstrations (with fewer there is
        none); the fitted scales are ``calibration_`` (``None`` when not calibrated).

    Attributes
    ----------
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
        between demonstrations, and ``spread`` (:func:`interprim.dmp.representation_report`).  Above 0.5 ``fit``
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
        its prior mean), ``cv_error_observed`` / ``cv_error_observed_prior``.  Phase (``phase_method="auto"``):
        ``phase_error_refined`` (likelihood), ``learned_phase_error``, ``clock_phase_error``.  Candidates and
        their scores: ``*_grid``, ``cv_errors``, ``cv_errors_observed``, ``cv_within_se``,
        ``cv_observed_within_se``, ``phase_error``, ``phase_log_likelihood``; ``representation`` (as
        ``representation_``).  Keys are left out where they do
        not apply (e.g. ``sigma2="auto"`` has no ``cv_*``).
    phase_method_ : str
        The phase method ``fit`` chose (``phase_method="auto"``) or was given; ``phase_model_`` is the
        fitted :class:`~interprim.phase.learned.LearnedPhase` or ``None``.
    reference_ : ndarray, shape (N, n_observed_latent_)
        DTW reference of the observed agent (Sec. III-B).
    start_position_, start_velocity_ : ndarray, shape (n_latent_,)
        Mean start state of the demonstrations (latent DoFs; velocity per unit normalised time).
    input_mean_, input_std_, input_limit_ : ndarray, ndarray, float
        Range of the observed agent's training frames (:mod:`interprim.input_range`).
    calibration_ : Calibration or None
        Scales of the predictive std (:mod:`interprim.calibration`).
    """

    def __init__(self, observed_dofs, n_basis: int = 20, alpha_y: float = 25.0, beta_y: float | None = None,
                 alpha_x: float = 3.0, sigma2="cv", covariance: str = "shrinkage", ridge: float = 1e-6,
                 observation: str = "position", smoothing_window: int | None = None, pca_components=None,
                 reference="mean", min_observed: int = 3, n_steps: int = 2000, phase_method: str = "auto",
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
            "n_basis": int(self.n_basis), "alpha_y": float(self.alpha_y),
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

    def _check_params(self, n_dofs: int, n_demos: int):
        """Validate every parameter (cheap; ``fit`` calls it before any expensive work)."""
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
        if not isinstance(self.n_basis, numbers.Integral) or self.n_basis < 2:
            raise ValueError(f"n_basis must be an integer >= 2, got {self.n_basis!r}")
        for name in ("alpha_y", "alpha_x"):
            check_positive(getattr(self, name), name)
        if self.beta_y is not None:
            check_positive(self.beta_y, "beta_y")
        if self.observation not in OBSERVATION_MODELS:
            raise ValueError(f"observation must be one of {OBSERVATION_MODELS}, got {self.observation!r}")
        if self.input_noise is not None:
            check_positive(self.input_noise, "input_noise")
        if not (isinstance(self.sigma2, str) and self.sigma2 in SIGMA2_RULES):
            check_positive(self.sigma2, "sigma2")
        if self.phase_method not in PHASE_METHODS:
            raise ValueError(f"phase_method must be one of {PHASE_METHODS}, got {self.phase_method!r}")
        if self.smoothing_window is not None and (not isinstance(self.smoothing_window, numbers.Integral)
                                                  or self.smoothing_window < 3):
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
            raise ValueError(f"calibrate must be True, False or 'with-cv' ('auto', its old name), "
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
        return obs, ctrl, kk

    # ------------------------------------------------------------------ fitting
    @one_blas_thread
    def fit(self, demos, dt: float | None = None, times=None, columns=None):
        """Learn the Interaction Primitive from demonstrations of both agents.

        Parameters
        ----------
        demos : list of array_like, shape (T_j, D)
            One array per demonstration, time on axis 0, the columns of both
            agents (``observed_dofs`` for the human).  Lengths may differ.
        dt : float, optional
            Sampling interval in seconds of uniformly sampled demos (default 0.01 if
            neither ``dt`` nor ``times`` is given).
            An :class:`interprim.datasets.Demonstrations` (any loader's result) is
            taken as it is: its ``dt`` (or ``times``) and column names are used
            unless given here.
        times : list of array_like, shape (T_j,), optional
            Time stamps in seconds per demonstration; irregular sampling is
            resampled onto a uniform grid at the median interval.
        columns : list of str, optional
            Names of the ``D`` columns; kept as ``columns_`` and in the model file.

        Returns
        -------
        self
        """
        if hasattr(demos, "demos") and hasattr(demos, "times"):  # interprim.datasets.Demonstrations
            if dt is None and times is None:
                if getattr(demos, "dt", None) is not None:
                    dt = demos.dt
                else:
                    times = list(demos.times)
            if columns is None:
                columns = getattr(demos, "columns", None)
            demos = list(demos.demos)
        if isinstance(demos, np.ndarray) and demos.ndim == 3:
            demos = list(demos)
        if not isinstance(demos, (list, tuple)):
            raise TypeError(f"demos must be a list of (T, D) arrays, got {type(demos).__name__}")
        if len(demos) < 2:
            raise ValueError(f"at least 2 demonstrations are needed to learn a distribution, got {len(demos)}")
        arrays = [as_2d_finite(d, f"demos[{j}]") for j, d in enumerate(demos)]
        D = arrays[0].shape[1]
        for j, a in enumerate(arrays):
            if a.shape[1] != D:
                raise ValueError(f"demos[{j}] has {a.shape[1]} columns but demos[0] has {D}")
        if columns is not None:
            columns = [str(c) for c in columns]
            if len(columns) != D:
                raise ValueError(f"columns has {len(columns)} names but the demonstrations have {D} columns")
        obs, ctrl, kk = self._check_params(D, len(arrays))
        self._derived = {}  # a new fit: nothing derived from an earlier one survives (see cached)
        self.__dict__.pop("selection_", None)  # set again below when this fit selects anything
        min_frames = max(5, self.smoothing_window or 0)
        if times is not None:
            if dt is not None:
                raise ValueError("give either dt or times, not both")
            if len(times) != len(arrays):
                raise ValueError(f"times has {len(times)} entries but there are {len(arrays)} demos")
            ts = [check_times(t, a.shape[0], f"times[{j}]") for j, (t, a) in enumerate(zip(times, arrays))]
            dt = float(np.median(np.concatenate([np.diff(t) for t in ts])))
            arrays = [resample_uniform(a, t, dt=dt)[0] for a, t in zip(arrays, ts)]
        dt = 0.01 if dt is None else check_positive(dt, "dt")
        for j, a in enumerate(arrays):
            if a.shape[0] < min_frames:
                raise ValueError(f"demos[{j}] has {a.shape[0]} frames; at least {min_frames} are needed")

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
        self.n_observed_latent_ = self._n_obs_latent()
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
            Zg = self._to_latent_stacked([arrays[j] for j in idx])  # (n, T, D')
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
        warn_representation(self.representation_, int(self.n_basis))

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
        if (self.sigma2 == "cv" or self.phase_method in ("likelihood", "cv", "auto")) and len(latent) >= 3:
            from .selection import select_hyperparameters  # sigma2, shrinkage, phase noise from data
            chosen = select_hyperparameters(self, latent, select_sigma2=self.sigma2 == "cv")
            if chosen.sigma2 is not None:
                self.sigma2_, self.prior_ = chosen.sigma2, chosen.prior
            self.phase_sigma2_, self.selection_ = chosen.phase_sigma2, chosen.record
        with single_thread():  # small matrices: BLAS threads only oversubscribe a loaded machine
            self.phase_model_, self.phase_method_, figures = fit_phase_model(self, [z[:, :n_o] for z in latent], dt)
        if figures:  # both phase errors of the "auto" choice, for the user
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
        # what the observed agent's frames look like in training (the out-of-range check, interprim.input_range)
        self.input_mean_, self.input_std_, self.input_limit_ = fit_input_range(
            np.concatenate([a[:, obs] for a in arrays], axis=0))
        self.calibration_ = None
        if self.calibrate is True or (self.calibrate in CALIBRATE_RULES and self.sigma2 == "cv"):
            from .calibration import fit_calibration  # predictive std scaled to held-out errors
            with single_thread():  # many small conditionings (a 252 x 252 covariance each): one BLAS thread
                self.calibration_ = fit_calibration(self, arrays)
        return self

    def setup_derived(self):
        """Derived, non-learned state (basis, rollout map, index tables)."""
        self.basis_ = Basis(int(self.n_basis), float(self.alpha_x))
        self.rollout_ = cached_rollout(int(self.n_basis), float(self.alpha_x), float(self.alpha_y), self.beta_y_,
                                       int(self.n_steps))
        q = self.n_basis + 1
        self._q = q
        self.params_per_dof_ = q  # n_basis + 1 entries of theta per DoF (Eq. 2)
        self.obs_index_ = np.arange(self.n_observed_latent_ * q).reshape(self.n_observed_latent_, q)

    def _n_obs_latent(self):
        return self.pca_observed_.n_components if self.pca_observed_ is not None else len(self.observed_dofs_)

    def _to_latent(self, a):
        o = a[:, self.observed_dofs_]
        c = a[:, self.controlled_dofs_]
        if self.pca_observed_ is not None:
            o = self.pca_observed_.transform(o)
        if self.pca_controlled_ is not None:
            c = self.pca_controlled_.transform(c)
        return np.hstack([o, c])

    def _to_latent_stacked(self, arrays):
        """:meth:`_to_latent` of equal-length demonstrations into one ``(n, T, D')`` array."""
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
        return np.stack([self._to_latent(a) for a in arrays])

    def observed_to_latent(self, o):
        """Frames ``(t, len(observed_dofs))`` of the observed agent in the model's latent DoFs (PCA, Sec. IV)."""
        return self.pca_observed_.transform(o) if self.pca_observed_ is not None else o

    def cached(self, name: str, key: tuple, build):
        """A value derived from the fitted state, computed once by ``build()`` and kept while the objects in
        ``key`` stay the same (compared by identity).

        The store is replaced by every :meth:`fit` (and is empty in a loaded or copied model), so a refit never
        sees a value derived from the previous fit.  Modules that need derived arrays of the model (the phase
        likelihood's factored prior, for example) keep them here instead of setting attributes on it.
        """
        store = self.__dict__.get("_derived")
        if store is None:
            store = self._derived = {}
        hit = store.get(name)
        if hit is not None and len(hit[0]) == len(key):
            for a, b in zip(hit[0], key):  # per frame of a stream: a plain loop, no generator
                if a is not b:
                    break
            else:
                return hit[1]
        value = build()
        store[name] = (tuple(key), value)
        return value

    def load_fitted(self, fitted: dict) -> "InteractionPrimitive":
        """Set the fitted attributes ``fitted`` (names ending in ``_``, as :mod:`interprim.io` reads them from a
        model file) and build the derived state (:meth:`setup_derived`); returns ``self``."""
        bad = [k for k in fitted if not k.endswith("_") or k.startswith("_")]
        if bad:
            raise ValueError(f"load_fitted: {bad} are not fitted attribute names")
        self.__dict__.update(fitted, _derived={})
        self.setup_derived()
        return self

    def with_fitted(self, **fitted) -> "InteractionPrimitive":
        """A copy of this fitted model with some fitted attributes (names ending in ``_``) replaced, e.g. the
        prior re-estimated on a subset of the demonstrations (:func:`interprim.calibration.fold_model`).  The
        copy shares the other fitted arrays and has its own store of derived values; ``self`` is unchanged."""
        self._check_fitted("with_fitted")
        bad = [k for k in fitted if not k.endswith("_") or k.startswith("_") or not hasattr(self, k)]
        if bad:
            raise ValueError(f"with_fitted: {bad} are not fitted attributes of this model")
        new = self.__copy__()
        new.__dict__.update(fitted)
        return new

    def __copy__(self):
        """A shallow copy with its own (empty) store of derived values (see :meth:`cached`)."""
        new = type(self).__new__(type(self))
        new.__dict__.update(self.__dict__, _derived={})
        return new

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

    _FITTED = "prior_"

    def _check_fitted(self, what: str):
        if not hasattr(self, "prior_"):
            raise NotFittedError(f"this InteractionPrimitive is not fitted yet; call fit(demos) before {what}")

    # ------------------------------------------------------------------ prediction
    @one_blas_thread
    def predict(self, partial, robot_state=None, dt: float | None = None, times=None,
                phase: float | None = None) -> "Prediction":
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
        """
        self._check_fitted("predict")
        n_cols = len(self.observed_dofs_)
        o = as_2d_finite(partial, "partial", n_cols=n_cols, min_rows=1)
        if times is not None:
            t = check_times(times, o.shape[0], "times")
            o = resample_uniform(o, t, dt=self.dt_)[0] if o.shape[0] > 1 else o
        elif dt is not None and abs(check_positive(dt, "dt") - self.dt_) > 1e-12 * self.dt_ and o.shape[0] > 1:
            o = resample_uniform(o, np.arange(o.shape[0]) * dt, dt=self.dt_)[0]
        dist = self.input_distance(o)
        p = self._predict_observed(o, robot_state, phase)
        return mark(self, p, dist)

    def input_distance(self, frames) -> float:
        """Largest standardised distance of observed frames ``(t, D_o)`` (data columns) from the training frames
        (:mod:`interprim.input_range`); NaN for a model file without those statistics."""
        return input_distance(self, frames)

    def _predict_observed(self, o, robot_state, phase):
        z = self.observed_to_latent(o)
        if phase is not None:
            ph = float(phase)
            if not 0.0 < ph <= 1.0:
                raise ValueError(f"phase must be in (0, 1], got {phase!r}")
            return self.predict_latent(z, ph * (self.reference_.shape[0] - 1), float("nan"), robot_state)
        n_star, cost = estimate_phase(self, z, self.phase_method_used())
        return self.predict_latent(movement_prefix(self, z, n_star), n_star, cost, robot_state)

    def phase_method_used(self) -> str:
        """The phase method in use: ``phase_method``, or with ``"auto"`` the one ``fit`` chose (``phase_method_``)."""
        if self.phase_method in ("cv", "auto"):
            return getattr(self, "phase_method_", "likelihood")
        return self.phase_method

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

    def _phase_info(self, n_star: int, M: int):
        N = self.reference_.shape[0]
        s_end = n_star / (N - 1)
        elapsed = (M - 1) * self.dt_
        if M > 1 and s_end > 0:
            duration = elapsed / s_end
        else:
            duration = self.mean_duration_
        return s_end, duration

    def _observation(self, z, s_end):
        """Design ``X`` and targets ``Y`` of the observation model at the observed frames."""
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
                        workspace=None) -> "Prediction":
        """The :class:`Prediction` for latent observed frames ``z (M, n_observed_latent_)`` at the reference frame
        ``n_star`` (Eq. 9: fraction seen ``n_star / (N - 1)``): Eq. 13-18 when at least ``min_observed`` frames
        were seen, else the prior.  The one path of :meth:`predict` and :meth:`Stream.update`."""
        M = z.shape[0]
        s_end, duration = self._phase_info(n_star, M)
        prior = self.prior_
        stats = None
        if M >= self.min_observed and s_end > 0:
            stats, y0 = self._stats(z, s_end, workspace)
            post = self.condition(stats, need_cov)
        else:
            y0 = z[0]
            post = Posterior(prior.mean, prior.cov, 0.0)
        if robot_start is None:
            robot_start = self.robot_start(robot_state)
        return Prediction(self, post, stats, s_end, duration, n_star, cost, M, y0, robot_start, z[-1])

    def _stats(self, z, s_end, workspace=None):
        """Sufficient statistics ``(X^T X, X^T Y, |Y|^2, n)`` of the observation (Eq. 13-15) and the start ``y0``.

        With the compiled kernels loaded, the position observation (any
        ``smoothing_window``; only the smoothed start ``y0`` depends on it) and
        the paper's forcing observation without smoothing run on preallocated
        buffers (``workspace``; fixed-size blocks for positions, grown by
        doubling for forcing values), so nothing proportional to ``M`` is
        allocated.  The work stays ``O(M q (q + D_o))`` for ``M`` frames: every
        frame gets a new phase ``s_j = j s_end / (M - 1)`` whenever the phase
        estimate moves.
        Otherwise :meth:`_observation` (numpy, the reference) is used; both
        give the same numbers (tested to 1e-12).
        """
        M = z.shape[0]
        if M >= 3 and kernels.in_use():
            from ._compiled.observation import StatsWorkspace, start_position

            if self.observation == "position":
                z = np.ascontiguousarray(z, dtype=np.float64)
                ws = workspace if workspace is not None else \
                    StatsWorkspace(M, z.shape[1], self._q, "position")
                y0 = start_position(z, self.smoothing_window)
                v0 = self.start_velocity_[: self.n_observed_latent_]
                G, B, yy = ws.position_stats(z, M, s_end, y0, v0, self.rollout_)
                return (G.copy(), B.copy(), yy, M * z.shape[1]), y0
            if self.observation == "forcing" and self.smoothing_window is None:
                ws = workspace if workspace is not None else StatsWorkspace(M, z.shape[1], self._q)
                G, B, yy = ws.forcing_stats(z, M, s_end, self)
                return (G.copy(), B.copy(), yy, M * z.shape[1]), z[0].copy()
        X, Y, y0 = self._observation(z, s_end)
        return (X.T @ X, X.T @ Y, float(np.sum(Y * Y)), Y.size), y0

    def _conditioner(self):
        """Precomputed Eq. 18 for the low-rank-plus-diagonal prior (:class:`~interprim.gaussian.LowRankConditioner`)."""
        return self.cached("conditioner", (self.prior_, self.obs_index_), lambda: LowRankConditioner.from_prior(
            self.prior_, self.obs_index_, getattr(self, "thetas_", None), float(self.ridge)))

    def condition(self, stats, need_cov: bool) -> Posterior:
        """Eq. 16-18 with Omega~ = [Omega, 0] from sufficient statistics ``(X^T X, X^T Y, |Y|^2, n)``.

        Uses the exact low-rank form of :class:`~interprim.gaussian.LowRankConditioner`
        (compiled) when the prior has it, else the structured dense form of
        :func:`~interprim.gaussian.condition`; the covariance is computed only
        when asked for (``need_cov``; :attr:`Prediction.posterior_cov` asks lazily).
        """
        G, B, yy, n = stats
        cond = self._conditioner()
        if cond is not None:
            res = cond.mean_compiled(G, B, self.sigma2_, yy, n) if kernels.in_use() else \
                cond.mean_numpy(G, B, self.sigma2_, yy, n)
            if res is not None:
                cov = cond.cov(G, self.sigma2_) if need_cov else None
                return Posterior(res[0], cov, res[1])
        return condition(self.prior_.mean, self.prior_.cov, self.obs_index_, G, B, self.sigma2_,
                         yy=yy, n_obs=n, need_cov=need_cov)

    def stream(self, robot_state=None) -> "Stream":
        """Online predictor that takes one observed frame at a time (incremental DTW)."""
        self._check_fitted("stream")
        return Stream(self, robot_state)

    # ------------------------------------------------------------------ persistence
    def save(self, path):
        """Save to a safe ``.npz`` model file (arrays + JSON metadata, no pickle); see :mod:`interprim.io`."""
        self._check_fitted("save")
        from .io import save_model

        save_model(self, path)

    def to_state(self):
        """``(arrays, meta)``: the fitted model as its model file holds it (numeric arrays and JSON metadata;
        :mod:`interprim.io`); :meth:`from_state` restores it."""
        self._check_fitted("to_state")
        from .io import model_state

        return model_state(self)

    @classmethod
    def from_state(cls, arrays: dict, meta: dict, source="<state>") -> "InteractionPrimitive":
        """The model of :meth:`to_state`'s ``(arrays, meta)`` (or of a model file's); raises
        :class:`~interprim.ModelFileError` naming ``source`` when they are inconsistent."""
        from .io import model_from_state

        return model_from_state(arrays, meta, cls, source)

    @classmethod
    def load(cls, path) -> "InteractionPrimitive":
        """Load a model saved by :meth:`save`; raises :class:`~interprim.ModelFileError` on bad files."""
        from .io import load_model

        return load_model(path, cls)

    def __repr__(self):
        import inspect

        defaults = {k: v.default for k, v in inspect.signature(type(self).__init__).parameters.items()}
        p = self.json_params()
        shown = ", ".join(f"{k}={v!r}" for k, v in p.items()
                          if k in ("observed_dofs", "n_basis") or v != defaults.get(k, inspect.Parameter.empty))
        if getattr(self, "prior_", None) is None:
            return f"InteractionPrimitive({shown})"
        from ._summary import one_line

        return f"<InteractionPrimitive({shown}) {one_line(self)}>"

    def summary(self, fit_seconds: float | None = None) -> str:
        """What the fitted model chose, in a few lines: phase method, noise ``sigma2``, shrinkage, cross-agent
        damping and the held-out error against the prior mean (from :attr:`selection_`), and whether the
        uncertainty is calibrated.  ``fit_seconds``: a fit time to report (``interprim fit`` passes it)."""
        self._check_fitted("summary")
        from ._summary import summary

        return summary(self, fit_seconds)

    # the names these methods had while they were private (kept for code written against them)
    _latent_map = latent_map
    _controlled_map = controlled_map
    _robot_start = robot_start
    _condition = condition
    _predict_latent = predict_latent
    _phase = phase_method_used
    _observed_to_latent = observed_to_latent
    _setup = setup_derived

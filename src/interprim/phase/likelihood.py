"""Phase estimation by the marginal likelihood of the observation (beyond the paper's DTW).

The paper estimates the phase of a partial observation with open-end DTW
against one reference movement (Eq. 5-9).  DTW matches *shapes*: when the
demonstrations differ in amplitude or goal, a partner "aiming further" looks
like a partner "further along", and the phase is off by ~10 % of the movement.

Here the phase is instead the normalised time ``s`` of the last observed frame
that makes the observation most probable under the *learned distribution* of
movements (as Interaction ProMPs do, Maeda et al. 2017)::

    s* = argmax_s  log p(y_1..y_M | s) + log p(s)

with the ``M`` observed frames placed at ``s_m = s (m - 1) / (M - 1)`` (a
constant speed over the observed part).  The likelihood is that of the
*positions*: DMP positions are linear in ``theta = [w, g]`` for a given start
state (:meth:`interprim.core.dmp.LinearRollout.design`), so
``y = free(s) z0 + H(s) theta_o + eps`` and ``p(y | s)`` is Gaussian with
covariance ``H Sigma_oo H^T + sigma_p^2 I`` (evaluated in the structured form
of :func:`interprim.core.gaussian.condition`, on the observed block of the prior
only).  Positions are used whatever observation model the model conditions
on, because their likelihoods at different ``s`` are densities of the *same*
data (forcing values of Eq. 15 change with ``s`` through their derivatives).

``log p(s)`` is an optional prior on the partner's speed: the implied duration
``(M - 1) dt / s`` is log-normal with the mean and spread of the training
demonstrations' durations.

The search (:func:`_search`) evaluates a grid of candidates (plus the DTW estimate, when given), adds
candidates inside the grid intervals next to its three best points, and refines the two highest local
maxima of those by a bounded scalar search: the log posterior can have several peaks closer together than
the grid's spacing.  Streams track a maximum frame by frame by local search
(:class:`interprim.phase.tracking.Tracker`).

All candidates of a search are evaluated in one batched computation
(:func:`phase_log_likelihoods`): since the design of every observed DoF is the
same ``H(s)``, each candidate needs only ``H^T H``, ``H^T r`` and ``|r|^2``
(``O(M q (q + D_o))``) and factorisations independent of ``M``
(:mod:`interprim.core._compiled.phase_likelihood`, compiled; a numpy equivalent serves until it
is loaded).  :func:`_phase_log_likelihood_reference` is the per-candidate
evaluation it is tested against.
"""

from __future__ import annotations

import math

import numpy as np

from ..core._compiled import registry as kernels
from ..core.blas import single_thread
from ..core.dmp import forcing_values
from ..core.gaussian import LOG2PI, GaussianPrior, condition
from ..core.preprocessing import derivatives
from .estimate import PhaseEstimate

__all__ = ["PhaseEstimate", "observation_design", "phase_log_likelihood", "phase_log_likelihoods", "estimate_phase",
           "phase_noise"]

S_MIN = 0.02


def observation_design(model, z, s_end: float, kind: str = "position"):
    """Design ``X`` (rows per observed frame) and targets ``Y`` (one column per observed latent DoF).

    ``kind="position"``: ``Y = z - free @ [y0; v0]`` and ``X = H`` of
    :meth:`~interprim.core.dmp.LinearRollout.design` from ``s = 0`` (start position
    = first observed frame, start velocity = the demonstrations' mean);
    ``kind="forcing"``: Eq. 13 rows and Eq. 15 forcing values.
    """
    M = z.shape[0]
    s = np.linspace(0.0, s_end, M)
    n_o = model.n_observed_latent_
    if kind == "position":
        free, X = model.rollout_.design(0.0, s)
        Y = z - free @ np.vstack([z[0], model.start_velocity_[:n_o]])
        return X, Y
    y, yd, ydd = derivatives(z, s_end / (M - 1), model.smoothing_window)
    X = model.basis_.phi_tilde(s, model.alpha_y, model.beta_y_)
    return X, forcing_values(y, yd, ydd, model.alpha_y, model.beta_y_)


def phase_noise(model) -> float:
    """Position noise variance used by the phase likelihood.

    ``model.phase_sigma2_`` when the model has it (chosen in ``fit`` by
    held-out marginal likelihood, see :mod:`interprim.models.primitive.selection`); else the
    model's ``sigma2_`` for the position observation model; else 1 % of the
    observed agent's spread in the DTW reference.
    """
    s2 = getattr(model, "phase_sigma2_", None)
    if s2 is not None:
        return float(s2)
    if model.observation == "position":
        return float(model.sigma2_)
    ref = model.reference_
    return float(max(1e-4 * np.mean(np.var(ref, axis=0)), 1e-12))


def _marginal(model):
    """Mean and covariance of the observed agent's block of the prior (cached per prior object)."""
    prior = model.prior_

    def build():
        n = model.n_observed_latent_ * model.params_per_dof_
        idx = np.arange(n).reshape(model.n_observed_latent_, model.params_per_dof_)
        return np.ascontiguousarray(prior.mean[:n]), np.ascontiguousarray(prior.cov[:n, :n]), idx

    return model.cached("phase_marginal", (prior,), build)


def _factored(model):
    """The observed block of the prior as diagonal + low rank (:meth:`interprim.core.gaussian.GaussianPrior.factored`).

    Exact when ``prior_`` was fitted by :func:`~interprim.core.gaussian.fit_prior` from ``thetas_`` (checked
    once); ``None`` otherwise (then the dense path is used).
    """
    prior = model.prior_
    return model.cached("phase_factored", (prior,), lambda: _build_factored(model, prior))


def _build_factored(model, prior):
    pr = None
    th = getattr(model, "thetas_", None)
    if th is not None:
        n = model.n_observed_latent_ * model.params_per_dof_
        cand = GaussianPrior.factored(th, prior.method, float(model.ridge), prior.shrinkage).marginal(n)
        dense = prior.cov[:n, :n]
        approx = cand.W.T @ cand.W
        approx[np.diag_indices(n)] += cand.d
        if np.allclose(approx, dense, rtol=1e-8, atol=1e-10 * float(np.abs(dense).max())) and np.allclose(
                cand.mean, prior.mean[:n]):
            pr = cand
    return pr


def phase_log_likelihood(model, z, s_end: float, sigma2: float | None = None) -> float:
    """``log p(z | s_end)``: marginal likelihood of the observed latent frames ``z`` (M, n_o) at phase ``s_end``."""
    return float(phase_log_likelihoods(model, z, np.array([float(s_end)]), sigma2)[0])


def phase_log_likelihoods(model, z, s_values, sigma2: float | None = None) -> np.ndarray:
    """:func:`phase_log_likelihood` at every phase in ``s_values`` (one batched evaluation).

    With the diagonal-plus-low-rank prior of :func:`~interprim.core.gaussian.fit_prior` (the usual case) all
    candidates go through one compiled kernel (:mod:`interprim.core._compiled.phase_likelihood`; its numpy equivalent
    until the kernel is loaded): per candidate only ``G = H^T H``, ``H^T r`` and ``|r|^2`` of the
    ``M`` frames are formed, ``O(M q (q + D_o))``, plus ``O(D_o (q^3 + q^2 n + q n^2))`` for the
    factorisations (``n`` demonstrations).  Otherwise (dense prior) each candidate uses the reference
    evaluation.  Both equal :func:`_phase_log_likelihood_reference` to rounding.
    """
    z = np.asarray(z, dtype=np.float64)
    s_values = np.atleast_1d(np.asarray(s_values, dtype=np.float64))
    s2 = phase_noise(model) if sigma2 is None else float(sigma2)
    fs = fast_state(model)
    if fs is None:
        with single_thread():
            return np.array([_phase_log_likelihood_reference(model, z, s, s2) for s in s_values])
    return fs.loglik(z, s_values, s2)


def _phase_log_likelihood_reference(model, z, s_end: float, sigma2: float | None = None) -> float:
    """The per-candidate evaluation (explicit design matrix, :meth:`interprim.core.gaussian.GaussianPrior.evidence` or
    :func:`interprim.core.gaussian.condition`): the reference the batched paths are tested against."""
    X, Y = observation_design(model, z, float(s_end), "position")
    s2 = phase_noise(model) if sigma2 is None else float(sigma2)
    pr = _factored(model)
    if pr is not None:  # O(D_o k^3 + D_o k S^2) instead of O((D_o k)^3)
        return pr.evidence(model.n_observed_latent_, model.params_per_dof_, X, Y, s2)
    mean_o, cov_o, idx = _marginal(model)
    post = condition(mean_o, cov_o, idx, X.T @ X, X.T @ Y, s2, yy=float(np.sum(Y * Y)), n_obs=Y.size,
                     need_cov=False)
    return float(post.log_likelihood)


# ---------------------------------------------------------------------------------------------------------------
# batched evaluation (low-rank prior)

class _FastState:
    """Everything of the batched evaluation that depends only on the model (cached per prior object)."""

    def __init__(self, model, pr):
        n_o, q = model.n_observed_latent_, model.params_per_dof_
        no_q = n_o * q
        ro = model.rollout_
        self.n_o, self.q = n_o, q
        self.Zh = np.ascontiguousarray(ro.Z[:, 0, :])  # (K+1, q): H rows on the grid (s0 = 0)
        self.Pf = np.ascontiguousarray(ro.powers[:, 0, :])  # (K+1, 2): free response rows on the grid
        mu_o = np.asarray(pr.mean[:no_q], dtype=np.float64).reshape(n_o, q)
        self.Hmu = np.ascontiguousarray(self.Zh @ mu_o.T)  # (K+1, n_o)
        self.v0 = np.asarray(model.start_velocity_[:n_o], dtype=np.float64)
        self.sq = np.ascontiguousarray(np.sqrt(pr.d[:no_q]).reshape(n_o, q))
        W = np.asarray(pr.W[:, :no_q], dtype=np.float64)
        n = W.shape[0]
        Wt = W / self.sq.reshape(1, -1)  # (n, n_o q)
        self.Uh = np.ascontiguousarray(Wt.reshape(n, n_o, q).transpose(1, 2, 0))  # (n_o, q, n)
        self.K0 = np.eye(n) + Wt @ Wt.T
        self._rg_key = None
        self._rg = None

    def mean_path(self, z0):
        """``free [z0; v0] + H mu`` on the rollout grid, ``(K+1, n_o)`` (cached for the last ``z0``)."""
        key = z0.tobytes()
        if key != self._rg_key:
            self._rg = np.ascontiguousarray(self.Hmu + self.Pf[:, :1] * z0[None, :] + self.Pf[:, 1:] * self.v0)
            self._rg_key = key
        return self._rg

    def loglik(self, z, s_values, s2):
        z = np.ascontiguousarray(z, dtype=np.float64)
        M = z.shape[0]
        Rg = self.mean_path(z[0])
        kern = kernels.kernel("phase_likelihood.phase_loglik_batch")
        if kern is not None:
            return kern(self.Zh, Rg, z, M, np.ascontiguousarray(s_values, dtype=np.float64), self.sq, self.Uh,
                        self.K0, float(s2), np.empty(s_values.shape[0]))
        with single_thread():
            return _loglik_batch_numpy(self.Zh, Rg, z, s_values, self.sq, self.Uh, self.K0, float(s2))


def prior_state(model, prior):
    """The precomputed state of the batched log-likelihood for ``model`` with ``prior`` (the observed block, diagonal
    plus low rank: :meth:`~interprim.core.gaussian.GaussianPrior.factored`, ``marginal``) in place of its own: the
    model's hyper-parameter selection scores a fold's held-out phase with it (pass it to :class:`make_scorer`)."""
    return _FastState(model, prior)


def fast_state(model):
    """The :class:`_FastState` of ``model`` (``None`` when the prior is not diagonal plus low rank)."""
    def build():
        pr = _factored(model)
        return None if pr is None else _FastState(model, pr)

    return model.cached("phase_fast", (model.prior_, model.rollout_), build)


def _loglik_batch_numpy(Zh, Rg, z, s_values, sq, Uh, K0, s2):
    """Numpy equivalent of :func:`interprim.core._compiled.phase_likelihood.phase_loglik_batch` (all candidates at
    once)."""
    M, n_o = z.shape
    n_steps = Zh.shape[0] - 1
    q = Zh.shape[1]
    n = Uh.shape[2]
    C = s_values.shape[0]
    sm = np.stack([np.linspace(0.0, s, M) for s in s_values]) if M > 1 else np.zeros((C, 1))
    u = np.clip(sm * n_steps, 0, n_steps)
    kf = np.minimum(np.floor(u).astype(np.intp), n_steps - 1)
    a = (u - kf)[:, :, None]
    E = (1.0 - a) * Zh[kf] + a * Zh[kf + 1]  # (C, M, q)
    R = z[None] - ((1.0 - a) * Rg[kf] + a * Rg[kf + 1])  # (C, M, n_o)
    Et = E.transpose(0, 2, 1)
    G = Et @ E
    b = Et @ R  # (C, q, n_o)
    rr = np.einsum("cmi,cmi->c", R, R)
    T = sq[None, :, :, None] * G[:, None] * sq[None, :, None, :]  # (C, n_o, q, q)
    T[..., np.arange(q), np.arange(q)] += s2
    L = np.linalg.cholesky(T)
    ld_T = 2.0 * np.sum(np.log(np.diagonal(L, axis1=-2, axis2=-1)), axis=(1, 2))
    c = sq[None] * b.transpose(0, 2, 1)  # (C, n_o, q)
    rhs = np.concatenate([np.broadcast_to(Uh, (C, n_o, q, n)), c[..., None]], axis=-1)  # (C, n_o, q, n+1)
    V = np.linalg.solve(L, rhs)
    Sacc = np.einsum("ciqa,ciqb->cab", V, V)  # (C, n+1, n+1)
    Kc = K0[None] - s2 * Sacc[:, :n, :n]
    t = Sacc[:, :n, n]
    cTc = Sacc[:, n, n]
    Lk = np.linalg.cholesky(Kc)
    ld_K = 2.0 * np.sum(np.log(np.diagonal(Lk, axis1=-2, axis2=-1)), axis=1)
    w = np.linalg.solve(Lk, t[..., None])[..., 0]
    tKt = np.sum(w * w, axis=1)
    N = M * n_o
    logdet = n_o * (M - q) * np.log(s2) + ld_T + ld_K
    return -0.5 * (N * LOG2PI + logdet + (rr - cTc) / s2 - tKt)


def _loglik_noise_grid_numpy(Zh, Rg, z, s_values, sq, Uh, K0, s2_values):
    """Numpy equivalent of :func:`interprim.core._compiled.phase_likelihood.phase_loglik_noise_grid`: ``(S2, C)``,
    :func:`_loglik_batch_numpy` at each noise."""
    return np.stack([_loglik_batch_numpy(Zh, Rg, z, s_values, sq, Uh, K0, float(v)) for v in s2_values])


def log_speed_prior(model, M: int, s):
    """Log-normal prior on the implied duration ``(M - 1) dt / s`` (density in ``s``)."""
    d = np.log(np.asarray(model.durations_, dtype=np.float64))
    mu = float(d.mean())
    sd = max(float(d.std()), 0.1)
    s = np.asarray(s, dtype=np.float64)
    elapsed = max(M - 1, 1) * model.dt_
    logdur = np.log(elapsed) - np.log(s)
    return -0.5 * ((logdur - mu) / sd) ** 2 - np.log(s)


def estimate_phase(model, z, s_init: float | None = None, n_grid: int = 12, refine: bool = True,
                   speed_prior: bool = True, sigma2: float | None = None, bounds=None) -> PhaseEstimate:
    """Maximum-likelihood (or MAP with ``speed_prior``) phase of a partial observation.

    Parameters
    ----------
    model : FittedPrimitive
        A fitted model.
    z : ndarray, shape (M, n_observed_latent)
        Observed frames in the model's latent space (after PCA), at the training ``dt``.
    s_init : float, optional
        A starting guess (e.g. the DTW estimate), added to the candidates.
    n_grid : int
        Number of grid candidates, spaced evenly in ``log s`` over ``bounds``.  With the refinement the default
        12 attains the maximum of a brute-force search (2000 phases, then finer around the six highest peaks)
        to within 3e-3 in log posterior (6e-3 in phase where the peak is flat) on all 1140 prefixes (5-95 % of
        the movement) of the two-agent set (noise 0, 0.01, 0.03; 10 and 20 basis functions) and all 3490
        prefixes (every length from 3 frames) of 30 NuiSI development recordings; refining only the best grid
        point had ended on a lower peak on 14 and 6 of them (0.1-80 below the maximum, 0.07-0.23 of the
        movement away).
    refine : bool
        Make the grid finer around its best points and refine the highest peaks by Brent's bounded search
        between their neighbours (:func:`_search`); else the best grid point.
    speed_prior : bool
        Add the log-normal duration prior of the training demonstrations.
    sigma2 : float, optional
        Position noise variance (default :func:`phase_noise`).
    bounds : (float, float), optional
        Range of candidates (default ``(0.02, 1)``, further limited by the
        implied duration staying below 4x the longest demonstration).
    """
    z = np.asarray(z, dtype=np.float64)
    M = z.shape[0]
    lo, hi = search_bounds(model, M, bounds)
    if M < 2:
        s = float(np.clip(s_init if s_init is not None else lo, lo, hi))
        return PhaseEstimate(s, log_likelihood=0.0, log_posterior=0.0, grid=np.array([s]), curve=np.array([0.0]))
    s2 = phase_noise(model) if sigma2 is None else float(sigma2)
    scores = make_scorer(model, z, s2, speed_prior)
    if scores.dense:
        with single_thread():
            return maximise(scores, lo, hi, n_grid, s_init, refine)
    return maximise(scores, lo, hi, n_grid, s_init, refine)


def maximise(scores, lo: float, hi: float, n_grid: int = 12, s_init: float | None = None,
             refine: bool = True) -> PhaseEstimate:
    """The search of :func:`estimate_phase` on any objective: ``n_grid`` phases evenly in ``log s`` over
    ``[lo, hi]`` (and ``s_init``), then, with ``refine``, :func:`_search`'s refinement.

    ``scores(s_values)`` returns ``(log posteriors, log likelihoods)`` at the candidate phases (``(C,)`` each).
    The likelihood phase's cross-validation (:mod:`interprim.models.primitive.selection`) scores its held-out
    cases with this same search, on each fold's prior.
    """
    grid = np.exp(np.linspace(np.log(lo), np.log(hi), int(n_grid)))
    if s_init is not None and np.isfinite(s_init):
        grid = np.unique(np.append(grid, np.clip(float(s_init), lo, hi)))
    return _search(grid, scores, refine, lo, hi)


def search_bounds(model, M, bounds=None):
    """``(lo, hi)``: the phases searched for ``M`` frames (default ``(0.02, 1)``, ``lo`` raised so that the implied
    duration stays below 4x the longest demonstration)."""
    lo, hi = (S_MIN, 1.0) if bounds is None else (float(bounds[0]), float(bounds[1]))
    elapsed = (M - 1) * model.dt_
    dur = model.durations_
    longest = model.cached("phase_longest_duration", (dur,), lambda: float(np.max(dur)))
    return max(lo, min(hi, elapsed / (4.0 * longest))), hi


class make_scorer:
    """``s -> (log posterior, log likelihood)`` for one observation, batched over candidate phases."""

    def __init__(self, model, z, s2, speed_prior=True, _parts=None):
        self.z = np.ascontiguousarray(z, dtype=np.float64)
        self.M = self.z.shape[0]
        self.s2 = float(s2)
        if _parts is None:
            self.fs = fast_state(model)
            self.prior = speed_prior_params(model, self.M) if speed_prior else None
        else:  # a caller that already has them for this model and M (the stream's tracker)
            self.fs, self.prior = _parts
        self.dense = self.fs is None
        self.model = model
        if not self.dense:
            self.Rg = self.fs.mean_path(self.z[0])

    def __call__(self, s_values):
        s_values = np.ascontiguousarray(s_values, dtype=np.float64)
        if self.dense:
            ll = np.array([_phase_log_likelihood_reference(self.model, self.z, s, self.s2) for s in s_values])
        else:
            kern = kernels.kernel("phase_likelihood.phase_loglik_batch")
            fs = self.fs
            if kern is not None:
                ll = kern(fs.Zh, self.Rg, self.z, self.M, s_values, fs.sq, fs.Uh, fs.K0, self.s2,
                          np.empty(s_values.shape[0]))
            else:
                with single_thread():
                    ll = _loglik_batch_numpy(fs.Zh, self.Rg, self.z, s_values, fs.sq, fs.Uh, fs.K0, self.s2)
        return self._posterior(ll, s_values), ll

    def _posterior(self, ll, s_values):
        """The log posteriors of the log-likelihoods ``ll`` at ``s_values`` (``ll`` itself without the prior)."""
        if self.prior is None:
            return ll
        logel, mu, sd = self.prior
        # the log-normal prior of log_speed_prior, element by element in floats (a few candidates: cheaper than
        # six numpy operations on arrays of three, and the same IEEE operations in the same order)
        lp = []
        for l_i, ls_i in zip(ll.tolist(), np.log(s_values).tolist()):
            d = ((logel - ls_i) - mu) / sd
            lp.append(l_i + (-0.5 * (d * d) - ls_i))
        return np.array(lp)

    def noise_curves(self, s_values, s2_values):
        """``(C, S2)``: the log posteriors at the phases ``s_values`` under each position noise of ``s2_values``,
        column ``v`` what ``make_scorer(model, z, s2_values[v], ...)(s_values)[0]`` gives, bit for bit (this
        scorer's own noise is not used).  With the compiled kernels, one call of
        :func:`~interprim.core._compiled.phase_likelihood.phase_loglik_noise_grid` computes each phase's statistics
        once for all the noises; the likelihood phase's noise selection (:mod:`interprim.models.primitive.selection`)
        scores its held-out cases so."""
        s_values = np.ascontiguousarray(s_values, dtype=np.float64)
        s2_values = np.ascontiguousarray(s2_values, dtype=np.float64)
        kern = None if self.dense else kernels.kernel("phase_likelihood.phase_loglik_noise_grid")
        if kern is None:
            parts = None if self.dense else (self.fs, self.prior)
            return np.stack([make_scorer(self.model, self.z, float(v), self.prior is not None, _parts=parts)(
                s_values)[0] for v in s2_values], axis=1)
        fs = self.fs
        ll = kern(fs.Zh, self.Rg, self.z, self.M, s_values, fs.sq, fs.Uh, fs.K0, s2_values,
                  np.empty((s2_values.shape[0], s_values.shape[0])))
        return np.stack([self._posterior(row, s_values) for row in ll], axis=1)


def speed_prior_params(model, M):
    """``(log elapsed time, mean, sd)`` of :func:`log_speed_prior` (the log-duration statistics cached per model)."""
    dur = model.durations_

    def build():
        d = np.log(np.asarray(dur, dtype=np.float64))
        return float(d.mean()), max(float(d.std()), 0.1)

    mu, sd = model.cached("phase_speed_prior", (dur,), build)
    return float(np.log(max(M - 1, 1) * model.dt_)), mu, sd


def _search(grid, scores, refine, lo=S_MIN, hi=1.0):
    """Grid search, then (``refine``) the grid made finer around its best points (:func:`_densify`), Brent's
    method on each of the ``_N_PEAKS`` highest local maxima of those candidates (:func:`_brent_peak`) and the last
    steps (:func:`_polish`) on the highest result.

    A log posterior can have several peaks closer together than the grid's spacing (NuiSI and the noisy two-agent
    set: peaks 0.05-0.15 apart in ``s``, a 12-point grid's spacing is 20-40 % of ``s``): refining only the best
    grid point's bracket then ended on a lower peak (14 of 1140 synthetic and 6 of 3490 NuiSI partial
    observations, see :func:`estimate_phase`).
    """
    lp, ll = scores(grid)
    i = int(np.argmax(lp))
    if not (refine and grid.size > 2):
        return PhaseEstimate(float(grid[i]), log_likelihood=float(ll[i]), log_posterior=float(lp[i]), grid=grid,
                             curve=lp)
    cand, clp = _densify(grid, lp, scores)
    best = None
    for j in _local_maxima(clp, _N_PEAKS):  # Brent's method on each peak; the last steps on the highest only
        r = _brent_peak(cand, clp, j, scores)
        if best is None or r[1] > best[1]:
            best = r
    assert best is not None  # a sequence always has a local maximum
    s, lp1, ll1 = _polish(best[0], scores, lo, hi)
    return PhaseEstimate(s, log_likelihood=ll1, log_posterior=lp1, grid=cand, curve=clp)


_N_DENSE = 3  # grid points around which the grid is made finer (_densify)
_N_SUB = 3  # candidates added inside each grid interval next to those points
_N_PEAKS = 2  # local maxima of the candidates refined (_search)


def _densify(grid, lp, scores):
    """The candidates ``grid`` (increasing) with ``_N_SUB`` more, evenly in ``log s``, inside each interval next
    to the ``_N_DENSE`` best grid points (scored in one batch): ``(candidates, log posteriors)``, increasing."""
    n = grid.size
    lg = np.log(grid)
    seg = sorted({j for i in np.argsort(-lp, kind="stable")[:_N_DENSE] for j in (int(i) - 1, int(i)) if 0 <= j < n - 1})
    if not seg:
        return grid, lp
    frac = np.arange(1, _N_SUB + 1) / (_N_SUB + 1.0)
    new = np.exp((lg[seg][:, None] + frac[None, :] * (lg[np.add(seg, 1)] - lg[seg])[:, None]).ravel())
    cand = np.concatenate([grid, new])
    clp = np.concatenate([lp, scores(new)[0]])
    o = np.argsort(cand, kind="stable")
    return cand[o], clp[o]


def _local_maxima(v, k):
    """Indices of the ``k`` highest local maxima of ``v`` (ends included; a plateau's first point), highest first."""
    n = len(v)
    idx = [i for i in range(n) if (i == 0 or v[i] > v[i - 1]) and (i == n - 1 or v[i] >= v[i + 1])]
    if not idx:
        idx = [int(np.argmax(v))]
    return sorted(idx, key=lambda i: -v[i])[:k]


def _brent_peak(grid, lp, i, scores):
    """``(s, log posterior)`` of the peak at candidate ``i`` of ``grid`` (increasing, log posteriors ``lp``):
    Brent's method between its neighbours to ``1e-3 s``."""
    best_s, best_lp = float(grid[i]), float(lp[i])
    a = float(grid[max(i - 1, 0)])
    b = float(grid[min(i + 1, grid.size - 1)])
    if b - a > 1e-4:
        def f(s):
            return -float(scores(np.array([s]))[0][0])

        s, neg = brent_min(f, a, b, best_s, -best_lp, xatol=1e-3 * max(b, 1e-3), maxiter=20)
        if -neg > best_lp:
            best_s, best_lp = s, -neg
    return best_s, best_lp


def _polish(best_s, scores, lo, hi):
    """``(s, log posterior, log likelihood)`` at the maximum near ``best_s``: three points ``_POLISH`` apart around
    it (moved towards the maximum while it is not the middle one) and :func:`finish` on them: the same last step
    as the stream's tracker, whose lattice has that spacing."""
    ss = np.unique(np.clip(best_s * np.exp(np.array([-_POLISH, 0.0, _POLISH])), lo, hi))
    lps = scores(ss)[0]
    k = int(np.argmax(lps))
    for _ in range(8):  # the maximum beyond an end of the three: move them one spacing that way
        if ss.size < 3 or k == 1 or ss[k] <= lo or ss[k] >= hi:
            break
        x = float(np.clip(ss[k] * np.exp(_POLISH if k == 2 else -_POLISH), lo, hi))
        ss = np.array([ss[1], ss[2], x]) if k == 2 else np.array([x, ss[0], ss[1]])
        new = float(scores(np.array([x]))[0][0])
        lps = np.array([lps[1], lps[2], new]) if k == 2 else np.array([new, lps[0], lps[1]])
        k = int(np.argmax(lps))
    s = finish(scores, ss, lps, k, lo, hi)
    lp1, ll1 = scores(np.array([s]))
    return s, float(lp1[0]), float(ll1[0])


_GOLD = 0.5 * (3.0 - 5.0 ** 0.5)
_POLISH = 0.01  # spacing in log s of the last refinement (batch) = the stream's lattice spacing (tracking.Tracker)
_H_FINAL = 2e-3  # spacing in log s of the last parabola (finish)


def brent_min(f, a, b, x, fx, xatol, maxiter):
    """Minimise ``f`` on ``[a, b]`` by Brent's method (golden-section steps, parabolic steps through the
    three best points when they fall inside the bracket and shrink fast enough; Brent 1973, ch. 5), started
    from an interior point ``x`` whose value ``fx`` is known.  Returns ``(x, f(x))``.  Replaces
    ``scipy.optimize.minimize_scalar(method="bounded")`` on the online path: importing ``scipy.optimize``
    costs about 0.5 s of a cold start.
    """
    w = v = x
    fw = fv = fx
    d = e = 0.0
    sqeps = 1.49e-8
    for _ in range(maxiter):
        m = 0.5 * (a + b)
        tol1 = sqeps * abs(x) + xatol / 3.0
        tol2 = 2.0 * tol1
        if abs(x - m) <= tol2 - 0.5 * (b - a):
            break
        golden = True
        if abs(e) > tol1:  # try a parabola through x, w, v
            r = (x - w) * (fx - fv)
            q = (x - v) * (fx - fw)
            p = (x - v) * q - (x - w) * r
            q = 2.0 * (q - r)
            if q > 0.0:
                p = -p
            q = abs(q)
            e_old, e = e, d
            if abs(p) < abs(0.5 * q * e_old) and q * (a - x) < p < q * (b - x):
                d = p / q
                golden = False
                if (x + d - a) < tol2 or (b - x - d) < tol2:
                    d = tol1 if x < m else -tol1
        if golden:
            e = (a - x) if x >= m else (b - x)
            d = _GOLD * e
        u = x + (d if abs(d) >= tol1 else (tol1 if d > 0 else -tol1))
        fu = f(u)
        if fu <= fx:
            if u >= x:
                a = x
            else:
                b = x
            v, fv, w, fw, x, fx = w, fw, x, fx, u, fu
        else:
            if u < x:
                a = u
            else:
                b = u
            if fu <= fw or w == x:
                v, fv, w, fw = w, fw, u, fu
            elif fu <= fv or v == x or v == w:
                v, fv = u, fu
    return x, fx


def _vertex(x, y):
    """Abscissa of the maximum of the parabola through three points ``(x_k, y_k)`` (``x`` increasing), or
    ``None`` when it is not concave (the middle point not above the chord of the outer two)."""
    (x0, x1, x2), (y0, y1, y2) = x, y
    x0, x1, x2, y0, y1, y2 = float(x0), float(x1), float(x2), float(y0), float(y1), float(y2)  # no numpy scalars
    den = (x1 - x0) * (y1 - y2) - (x1 - x2) * (y1 - y0)
    if not (den != 0.0 and y1 * (x2 - x0) > y0 * (x2 - x1) + y2 * (x1 - x0)):
        return None
    return x1 - 0.5 * ((x1 - x0) ** 2 * (y1 - y2) - (x1 - x2) ** 2 * (y1 - y0)) / den


def finish(scores, ss, lps, i, lo, hi, max_rounds: int = 6) -> float:
    """The phase from candidates ``ss`` (increasing, log posteriors ``lps``, best ``i``): the last step of
    both the batch search (:func:`_search`) and the stream's tracker (:class:`~interprim.phase.tracking.Tracker`).

    1. ``u1``: the vertex (in ``log s``) of the parabola through the best candidate and its neighbours,
       within their bracket (the best candidate itself when the parabola is not concave or there is no
       neighbour on one side, i.e. at a clipped bound);
    2. the vertex of the parabola through ``u1 - h, u1, u1 + h`` (``h = _H_FINAL``), the three points moved
       by ``h`` towards the maximum while it is not the middle one.

    Step 2 makes the answer independent of where the candidates of step 1 were (a grid and Brent's method, or
    a lattice of speeds): for a log posterior ``-k d^2 + c d^3`` around its maximum the vertex is off by
    ``c h^2 / (2 k)`` plus ``O(c e^2 / k)`` for a centre ``e`` away from the maximum, so two searches whose
    ``u1`` are within ``e ~ 1e-4`` agree to ``~1e-8``; and points ``h`` apart keep the rounding of the scores
    ``d_lp`` from moving the vertex by more than ``d_lp / (2 k h)``.
    """
    n = len(ss)
    log_ss = np.log(ss)  # elementwise: the same numbers as one logarithm per candidate
    x = float(log_ss[i])
    if 0 < i < n - 1 and math.isfinite(lps[i - 1]) and math.isfinite(lps[i + 1]):
        u = _vertex(log_ss[i - 1:i + 2], lps[i - 1:i + 2])
        if u is not None:
            x = min(max(u, float(log_ss[i - 1])), float(log_ss[i + 1]))
    a, b = float(np.log(lo)), float(np.log(hi))
    h = _H_FINAL
    if b - a < 2.0 * h:
        return float(np.exp(x))
    for _ in range(max_rounds):
        c = min(max(x, a + h), b - h)  # the three points inside [lo, hi]
        us = np.array([c - h, c, c + h])
        lp = scores(np.exp(us))[0]
        k = int(np.argmax(lp))
        if k != 1 and min(max(us[k], a + h), b - h) != c:  # the maximum is beyond an end: move that way
            x = us[k]
            continue
        u = _vertex(us, lp)
        if u is None:
            return float(np.exp(us[k]))
        return float(np.exp(min(max(u, a), b, us[2]) if u > us[0] else us[0]))
    return float(np.exp(x))

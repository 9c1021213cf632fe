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
state (:meth:`interprim.dmp.LinearRollout.design`), so
``y = free(s) z0 + H(s) theta_o + eps`` and ``p(y | s)`` is Gaussian with
covariance ``H Sigma_oo H^T + sigma_p^2 I`` (evaluated in the structured form
of :func:`interprim.gaussian.condition`, on the observed block of the prior
only).  Positions are used whatever observation model the model conditions
on, because their likelihoods at different ``s`` are densities of the *same*
data (forcing values of Eq. 15 change with ``s`` through their derivatives).

``log p(s)`` is an optional prior on the partner's speed: the implied duration
``(M - 1) dt / s`` is log-normal with the mean and spread of the training
demonstrations' durations.

The search evaluates a grid of candidates (plus the DTW estimate, when given),
then refines the best one by a bounded scalar search.  :func:`track_phase` is
the cheap online variant (a few candidates around the previous estimate,
extrapolated at constant speed).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .dmp import forcing_values
from .gaussian import condition
from .preprocessing import derivatives

__all__ = ["PhaseEstimate", "observation_design", "phase_log_likelihood", "estimate_phase", "track_phase",
           "phase_noise"]

_S_MIN = 0.02


def single_thread():
    """Context limiting BLAS to one thread (many tiny factorisations: threads only add overhead,
    up to 100x on a loaded 2-core machine); a no-op without ``threadpoolctl``."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover
        from contextlib import nullcontext

        return nullcontext()
    return threadpool_limits(1)


@dataclass(frozen=True)
class PhaseEstimate:
    """Result of :func:`estimate_phase`.

    Attributes
    ----------
    s_end : float
        Normalised time (in (0, 1]) of the last observed frame.
    log_likelihood : float
        ``log p(observation | s_end)`` (positions, observed block of the prior).
    log_posterior : float
        ``log_likelihood + log p(s_end)`` (equal when there is no speed prior).
    grid, curve : ndarray
        The candidates evaluated and their log posteriors (for plots and diagnostics).
    """

    s_end: float
    log_likelihood: float
    log_posterior: float
    grid: np.ndarray
    curve: np.ndarray


def observation_design(model, z, s_end: float, kind: str = "position"):
    """Design ``X`` (rows per observed frame) and targets ``Y`` (one column per observed latent DoF).

    ``kind="position"``: ``Y = z - free @ [y0; v0]`` and ``X = H`` of
    :meth:`~interprim.dmp.LinearRollout.design` from ``s = 0`` (start position
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
    held-out marginal likelihood, see :mod:`interprim.selection`); else the
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
    cache = getattr(model, "_phase_marginal", None)
    if cache is not None and cache[0] is prior:
        return cache[1], cache[2], cache[3]
    n = model.n_observed_latent_ * model._q
    mean_o = np.ascontiguousarray(prior.mean[:n])
    cov_o = np.ascontiguousarray(prior.cov[:n, :n])
    idx = np.arange(n).reshape(model.n_observed_latent_, model._q)
    model._phase_marginal = (prior, mean_o, cov_o, idx)
    return mean_o, cov_o, idx


def _factored(model):
    """The observed block of the prior as diagonal + low rank (see :class:`interprim.selection._LowRankPrior`).

    Exact when ``prior_`` was fitted by :func:`~interprim.gaussian.fit_prior` from ``thetas_`` (checked
    once); ``None`` otherwise (then the dense path is used).
    """
    prior = model.prior_
    cache = getattr(model, "_phase_factored", None)
    if cache is not None and cache[0] is prior:
        return cache[1]
    from .selection import _LowRankPrior

    pr = None
    th = getattr(model, "thetas_", None)
    if th is not None:
        n = model.n_observed_latent_ * model._q
        cand = _LowRankPrior(th, prior.method, float(model.ridge), prior.shrinkage)
        cand.mean, cand.d, cand.W = cand.mean[:n], cand.d[:n], cand.W[:, :n]
        dense = prior.cov[:n, :n]
        approx = cand.W.T @ cand.W
        approx[np.diag_indices(n)] += cand.d
        if np.allclose(approx, dense, rtol=1e-8, atol=1e-10 * float(np.abs(dense).max())) and np.allclose(
                cand.mean, prior.mean[:n]):
            pr = cand
    model._phase_factored = (prior, pr)
    return pr


def phase_log_likelihood(model, z, s_end: float, sigma2: float | None = None) -> float:
    """``log p(z | s_end)``: marginal likelihood of the observed latent frames ``z`` (M, n_o) at phase ``s_end``."""
    X, Y = observation_design(model, z, float(s_end), "position")
    s2 = phase_noise(model) if sigma2 is None else float(sigma2)
    pr = _factored(model)
    if pr is not None:  # O(D_o k^3 + D_o k S^2) instead of O((D_o k)^3)
        from .selection import _lowrank_case

        return float(_lowrank_case(pr, model.n_observed_latent_, model._q, X, Y, np.array([s2]), need_mean=False,
                                   need_ll=True)[1][0])
    mean_o, cov_o, idx = _marginal(model)
    post = condition(mean_o, cov_o, idx, X.T @ X, X.T @ Y, s2, yy=float(np.sum(Y * Y)), n_obs=Y.size,
                     need_cov=False)
    return float(post.log_likelihood)


def _log_speed_prior(model, M: int, s):
    """Log-normal prior on the implied duration ``(M - 1) dt / s`` (density in ``s``)."""
    d = np.log(np.asarray(model.durations_, dtype=np.float64))
    mu = float(d.mean())
    sd = max(float(d.std()), 0.1)
    s = np.asarray(s, dtype=np.float64)
    elapsed = max(M - 1, 1) * model.dt_
    logdur = np.log(elapsed) - np.log(s)
    return -0.5 * ((logdur - mu) / sd) ** 2 - np.log(s)


def estimate_phase(model, z, s_init: float | None = None, n_grid: int = 40, refine: bool = True,
                   speed_prior: bool = True, sigma2: float | None = None, bounds=None) -> PhaseEstimate:
    """Maximum-likelihood (or MAP with ``speed_prior``) phase of a partial observation.

    Parameters
    ----------
    model : InteractionPrimitive
        A fitted model.
    z : ndarray, shape (M, n_observed_latent)
        Observed frames in the model's latent space (after PCA), at the training ``dt``.
    s_init : float, optional
        A starting guess (e.g. the DTW estimate), added to the candidates.
    n_grid : int
        Number of grid candidates, spaced evenly in ``log s`` over ``bounds``.
    refine : bool
        Refine the best candidate by a bounded scalar search between its neighbours.
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
    lo, hi = (_S_MIN, 1.0) if bounds is None else (float(bounds[0]), float(bounds[1]))
    elapsed = (M - 1) * model.dt_
    lo = max(lo, min(hi, elapsed / (4.0 * float(np.max(model.durations_)))))
    if M < 2:
        s = float(np.clip(s_init if s_init is not None else lo, lo, hi))
        return PhaseEstimate(s, 0.0, 0.0, np.array([s]), np.array([0.0]))
    grid = np.exp(np.linspace(np.log(lo), np.log(hi), int(n_grid)))
    if s_init is not None and np.isfinite(s_init):
        grid = np.unique(np.append(grid, np.clip(float(s_init), lo, hi)))
    s2 = phase_noise(model) if sigma2 is None else float(sigma2)

    def score(s):
        ll = phase_log_likelihood(model, z, s, s2)
        lp = float(_log_speed_prior(model, M, s)) if speed_prior else 0.0
        return ll + lp, ll

    with single_thread():
        return _search(model, z, grid, score, refine, s_init)


def _search(model, z, grid, score, refine, s_init):
    vals = np.array([score(s) for s in grid])
    curve = vals[:, 0]
    i = int(np.argmax(curve))
    best_s, best_lp, best_ll = float(grid[i]), float(curve[i]), float(vals[i, 1])
    if refine and grid.size > 2:
        from scipy.optimize import minimize_scalar

        a = float(grid[max(i - 1, 0)])
        b = float(grid[min(i + 1, grid.size - 1)])
        if b - a > 1e-4:
            res = minimize_scalar(lambda s: -score(s)[0], bounds=(a, b), method="bounded",
                                  options={"xatol": 1e-3 * max(b, 1e-3), "maxiter": 20})
            if res.success and -res.fun > best_lp:
                best_s = float(res.x)
                best_lp, best_ll = score(best_s)
    return PhaseEstimate(best_s, float(best_ll), float(best_lp), grid, curve)


def track_phase(model, z, s_prev: float | None, m_prev: int, n_candidates: int = 7, spread: float = 0.15,
                speed_prior: bool = True) -> float:
    """Cheap online phase update for :class:`~interprim.primitive.Stream`.

    Extrapolates the previous estimate ``s_prev`` (made with ``m_prev``
    frames) at constant speed to the current ``M`` frames and evaluates
    ``n_candidates`` values within a factor ``exp(+-spread)`` of it; the first
    estimate (``s_prev is None``) uses a coarse full grid.
    """
    M = z.shape[0]
    if M < 2:
        return _S_MIN
    if s_prev is None or m_prev < 2:
        return estimate_phase(model, z, n_grid=20, refine=False, speed_prior=speed_prior).s_end
    s_pred = min(1.0, s_prev * (M - 1) / (m_prev - 1))
    cand = np.unique(np.clip(s_pred * np.exp(np.linspace(-spread, spread, int(n_candidates))), _S_MIN, 1.0))
    s2 = phase_noise(model)
    sc = [phase_log_likelihood(model, z, s, s2) + (float(_log_speed_prior(model, M, s)) if speed_prior else 0.0)
          for s in cand]
    return float(cand[int(np.argmax(sc))])

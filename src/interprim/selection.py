"""Choosing the observation noise ``sigma^2`` and the covariance shrinkage from the data.

A plain Interaction Primitive has two numbers that decide whether conditioning
helps or hurts: the observation noise ``sigma^2`` of Eq. 16 and the
regularisation of the covariance of Eq. 10, which is estimated from fewer
demonstrations than it has entries.  A fixed ``sigma^2`` is right for one data
set at most, and an under-regularised covariance holds spurious correlations
that conditioning follows.  :func:`select_hyperparameters` picks both per
model by K-fold cross-validation on the training demonstrations:

1. split the demonstrations into ``n_folds`` folds; for every fold fit the
   prior (Eq. 10) on the others with each candidate shrinkage ``lambda``;
2. for every held-out demonstration observe the first 25/50/75 % of the
   observed agent (at its true phase), condition (Eq. 16-18) with every
   candidate ``sigma^2`` and predict the whole movement of *all* DoFs (both
   agents) by integrating the DMPs from the start;
3. score each ``(lambda, sigma^2)`` by the mean squared error of those
   predictions, each DoF divided by its variance over the demonstrations, and
   keep the best pair.  The largest ``sigma^2`` candidates (1000x the
   observation's scale) leave the prior practically unchanged, so the
   selection can always fall back to the prior mean when conditioning does
   not help on held-out data.

All ``sigma^2`` candidates cost one eigendecomposition per (fold, ``lambda``,
held-out demo, fraction): with ``A0 = L Sigma L^T`` (compressed observation,
see :mod:`interprim.gaussian`) ``= U diag(e) U^T`` the posterior mean for any
``sigma^2`` is ``mu + Sigma L^T U diag(1 / (e + sigma^2)) U^T r``.

The same loop gives the held-out marginal likelihood of the *positions* of the
observation for every ``sigma^2``; its maximiser is the position noise
``phase_sigma2_`` used by the likelihood phase estimator
(:mod:`interprim.phase_likelihood`).

The choice is reported in ``model.selection_``.
"""

from __future__ import annotations

import numpy as np

from .gaussian import fit_prior, shrinkage_intensity
from .phase_likelihood import observation_design
from .preprocessing import time_normalise

__all__ = ["select_hyperparameters", "DEFAULT_FRACTIONS", "DEFAULT_SHRINKAGE_GRID", "DEFAULT_SIGMA2_FACTORS"]

_LOG2PI = float(np.log(2.0 * np.pi))

DEFAULT_FRACTIONS = (0.25, 0.5, 0.75)
DEFAULT_SHRINKAGE_GRID = (0.02, 0.1, 0.3, 0.6, 0.95)
#: ``sigma^2`` candidates relative to the mean square of the observation targets
DEFAULT_SIGMA2_FACTORS = tuple(10.0 ** np.arange(-6.0, 3.01, 0.5))


def _compress(G, B, tol=1e-10):
    e, V = np.linalg.eigh(0.5 * (G + G.T))
    keep = e > tol * max(float(e[-1]), 1e-300)
    e, V = e[keep], V[:, keep]
    se = np.sqrt(e)
    return se[:, None] * V.T, (V.T @ B) / se[:, None]


def _case_terms(cov, mean, n_o, q, X, Y):
    """Everything of one conditioning that does not depend on ``sigma^2``."""
    L, zc = _compress(X.T @ X, X.T @ Y)
    k = L.shape[0]
    mu_o = mean[: n_o * q].reshape(n_o, q)
    Lb = np.kron(np.eye(n_o), L)  # (n_o k, n_o q)
    SLt = cov[:, : n_o * q] @ Lb.T  # (P, n_o k)
    A0 = Lb @ SLt[: n_o * q]
    e, U = np.linalg.eigh(0.5 * (A0 + A0.T))
    e = np.clip(e, 0.0, None)
    r = (zc - L @ mu_o.T).T.reshape(-1)
    Ur = U.T @ r
    resid_total = float(np.sum((Y - X @ mu_o.T) ** 2))
    resid_perp = max(resid_total - float(r @ r), 0.0)
    return SLt, U, e, Ur, resid_perp, Y.size, n_o * k


def _posterior_means(mean, SLt, U, e, Ur, s2):
    """Posterior means for every ``sigma^2`` in ``s2``, shape ``(P, len(s2))``."""
    alpha = U @ (Ur[:, None] / (e[:, None] + s2[None, :]))
    return mean[:, None] + SLt @ alpha


def _log_likelihoods(U, e, Ur, resid_perp, n, dk, s2):
    """Marginal log-likelihood of the observation for every ``sigma^2`` (Eq. 16-18 evidence)."""
    return -0.5 * (n * _LOG2PI + (n - dk) * np.log(s2) + np.sum(np.log(e[:, None] + s2[None, :]), axis=0)
                   + resid_perp / s2 + np.sum(Ur[:, None] ** 2 / (e[:, None] + s2[None, :]), axis=0))


def select_hyperparameters(model, latent, n_folds: int = 5, fractions=DEFAULT_FRACTIONS,
                           shrinkage_grid=DEFAULT_SHRINKAGE_GRID, sigma2_factors=DEFAULT_SIGMA2_FACTORS,
                           select_sigma2: bool = True, n_out: int = 50, phase_cases: int = 16):
    """Choose ``sigma^2`` (and the shrinkage) of a model being fitted by K-fold cross-validation.

    Called by :meth:`InteractionPrimitive.fit` (``sigma2="cv"``, or
    ``phase_method="likelihood"`` for the phase noise alone) after the DMP
    parameters ``model.thetas_`` are known; it sets ``model.prior_``,
    ``model.sigma2_`` (when ``select_sigma2``), ``model.phase_sigma2_`` and
    ``model.selection_``.

    Parameters
    ----------
    model : InteractionPrimitive
        Being fitted: needs ``thetas_``, ``basis_``, ``rollout_``, ``start_velocity_``,
        ``n_observed_latent_``, ``covariance``, ``ridge``, ``observation``.
    latent : list of ndarray, shape (T_j, D_latent)
        The training demonstrations in the model's latent space.
    n_folds : int
        Number of folds (at most the number of demonstrations).
    fractions : sequence of float
        Observed fractions of each held-out demonstration.
    shrinkage_grid : sequence of float
        Candidate shrinkage intensities (the analytic Schaefer-Strimmer value is
        always added); used only with ``covariance="shrinkage"``.
    sigma2_factors : sequence of float
        Candidate ``sigma^2`` relative to the mean square of the observation targets.
    select_sigma2 : bool
        Select ``sigma^2`` and the shrinkage (``False``: only ``phase_sigma2_``).
    n_out : int
        Points of the normalised-time grid on which predictions are scored.
    phase_cases : int
        Held-out cases (demonstration x fraction) on which ``phase_sigma2_`` is
        chosen as the position noise that gives the most accurate likelihood
        phase estimates (0: maximise the held-out marginal likelihood instead).

    Returns
    -------
    dict
        The same as ``model.selection_``: ``sigma2``, ``shrinkage``,
        ``phase_sigma2``, ``cv_error`` (normalised MSE of the choice),
        ``cv_error_prior`` (of the prior mean), ``cv_error_auto``-free grids and scores.
    """
    from .phase_likelihood import single_thread

    with single_thread():
        return _select(model, latent, n_folds, fractions, shrinkage_grid, sigma2_factors, select_sigma2, n_out,
                       phase_cases)


def _select(model, latent, n_folds, fractions, shrinkage_grid, sigma2_factors, select_sigma2, n_out, phase_cases):
    thetas = model.thetas_
    S, P = thetas.shape
    n_o = model.n_observed_latent_
    q = model._q
    n_lat = model.n_latent_
    K = int(min(max(n_folds, 2), S))
    fold = np.arange(S) % K
    method = model.covariance
    if method == "shrinkage" and select_sigma2:
        lam_grid = sorted(set([round(float(shrinkage_intensity(thetas)), 6)] + [float(x) for x in shrinkage_grid]))
    else:
        lam_grid = [None]
    kinds = ["position"] if model.observation == "position" else [model.observation, "position"]

    s_out = np.linspace(0.0, 1.0, n_out)
    free, H = model.rollout_.design(0.0, s_out)
    truths = [time_normalise(z, n_out) for z in latent]
    var_d = np.var(np.vstack(latent), axis=0)
    w_d = 1.0 / np.maximum(var_d, 1e-12 * max(float(var_d.max()), 1e-300))
    v0 = model.start_velocity_

    # observation targets of every held-out case (independent of the fold's prior)
    cases = []
    for j, z in enumerate(latent):
        T = z.shape[0]
        for p in fractions:
            M = int(np.clip(round(p * T), max(3, model.min_observed), T))
            s_end = (M - 1) / (T - 1)
            zo = z[:M, :n_o]
            designs = {kind: observation_design(model, zo, s_end, kind) for kind in kinds}
            y0 = np.concatenate([zo[0], model.start_position_[n_o:]])
            base = free @ np.vstack([y0, v0])  # (n_out, n_lat)
            cases.append((j, designs, base))
    scale = {kind: float(np.mean([np.mean(c[1][kind][1] ** 2) for c in cases])) for kind in kinds}
    s2_grid = {kind: max(scale[kind], 1e-300) * np.asarray(sigma2_factors, dtype=np.float64) for kind in kinds}

    kind0 = kinds[0]
    err = np.zeros((len(lam_grid), len(sigma2_factors)))
    ll = np.zeros((len(lam_grid), len(sigma2_factors)))
    err_prior = np.zeros(len(lam_grid))
    n_cases = 0
    for f in range(K):
        train = fold != f
        if train.sum() < 2:
            continue
        for a, lam in enumerate(lam_grid):
            prior = fit_prior(thetas[train], method, model.ridge, shrinkage=lam)
            for j, designs, base in cases:
                if fold[j] != f:
                    continue
                truth = truths[j]
                if select_sigma2:
                    X, Y = designs[kind0]
                    SLt, U, e, Ur, rp, n, dk = _case_terms(prior.cov, prior.mean, n_o, q, X, Y)
                    Th = _posterior_means(prior.mean, SLt, U, e, Ur, s2_grid[kind0]).reshape(n_lat, q, -1)
                    pred = base[None] + np.einsum("tq,dqs->std", H, Th)
                    err[a] += np.mean(((pred - truth[None]) ** 2) * w_d, axis=(1, 2))
                    pm = base + H @ prior.mean.reshape(n_lat, q).T
                    err_prior[a] += float(np.mean(((pm - truth) ** 2) * w_d))
                    if kind0 == "position":
                        ll[a] += _log_likelihoods(U, e, Ur, rp, n, dk, s2_grid["position"])
                if (kind0 != "position" or not select_sigma2) and phase_cases <= 0:
                    X, Y = designs["position"]
                    _, U, e, Ur, rp, n, dk = _case_terms(prior.cov, prior.mean, n_o, q, X, Y)
                    ll[a] += _log_likelihoods(U, e, Ur, rp, n, dk, s2_grid["position"])
                if a == 0:
                    n_cases += 1
    err /= max(n_cases, 1)
    err_prior /= max(n_cases, 1)

    if select_sigma2:
        a, b = np.unravel_index(int(np.argmin(err)), err.shape)
        lam = lam_grid[a]
        model.sigma2_ = float(s2_grid[kind0][b])
        if lam is not None:
            model.prior_ = fit_prior(thetas, method, model.ridge, shrinkage=lam)
    else:
        a = 0
        lam = None
    phase_err = _phase_noise_by_accuracy(model, latent, fold, K, lam if select_sigma2 else None,
                                         s2_grid["position"], fractions, max_cases=phase_cases)
    if phase_err is not None:
        # the noise under which the likelihood phase estimate is most accurate on held-out demos
        # (the held-out marginal likelihood at the true phase favours too small a noise for this)
        bp = int(np.argmin(phase_err + 1e-9 * np.arange(len(phase_err))[::-1]))
    else:
        bp = int(np.argmax(ll[a]))
    model.phase_sigma2_ = float(s2_grid["position"][bp])
    sel = {
        "method": f"{K}-fold cross-validation" if select_sigma2 else "held-out marginal likelihood",
        "n_folds": K,
        "fractions": [float(p) for p in fractions],
        "sigma2": float(model.sigma2_),
        "shrinkage": float(model.prior_.shrinkage),
        "phase_sigma2": model.phase_sigma2_,
        "observation": kind0,
        "sigma2_grid": [float(x) for x in s2_grid[kind0]],
        "shrinkage_grid": [None if x is None else float(x) for x in lam_grid],
        "phase_sigma2_grid": [float(x) for x in s2_grid["position"]],
        "phase_log_likelihood": [float(x) for x in ll[a]],
        "phase_error": None if phase_err is None else [float(x) for x in phase_err],
    }
    if select_sigma2:
        sel["cv_error"] = float(err[a].min())
        sel["cv_error_prior"] = float(err_prior[a])
        sel["cv_errors"] = err.tolist()
    model.selection_ = sel
    return sel


def _phase_noise_by_accuracy(model, latent, fold, K, lam, s2_grid, fractions, max_cases=24, n_phase=24):
    """Mean absolute phase error of the likelihood estimator on held-out cases, per noise candidate."""
    from .phase_likelihood import _S_MIN, _log_speed_prior

    if max_cases <= 0:
        return None
    n_o, q = model.n_observed_latent_, model._q
    S = len(latent)
    all_cases = [(j, p) for p in fractions for j in range(S)]
    pick = np.unique(np.linspace(0, len(all_cases) - 1, min(max_cases, len(all_cases))).round().astype(int))
    cases = [all_cases[i] for i in pick]
    errs = np.zeros(len(s2_grid))
    priors = {}
    for j, p in cases:
        f = fold[j]
        if f not in priors:
            priors[f] = fit_prior(model.thetas_[fold != f], model.covariance, model.ridge, shrinkage=lam)
        prior = priors[f]
        mean_o = prior.mean[: n_o * q]
        cov_o = prior.cov[: n_o * q, : n_o * q]
        z = latent[j]
        T = z.shape[0]
        M = int(np.clip(round(p * T), max(3, model.min_observed), T))
        s_true = (M - 1) / (T - 1)
        lo = max(_S_MIN, (M - 1) * model.dt_ / (4.0 * float(np.max(model.durations_))))
        grid = np.exp(np.linspace(np.log(lo), 0.0, n_phase))
        curves = np.empty((grid.size, len(s2_grid)))
        for i, s in enumerate(grid):
            X, Y = observation_design(model, z[:M, :n_o], float(s), "position")
            _, U, e, Ur, rp, n, dk = _case_terms(cov_o, mean_o, n_o, q, X, Y)
            curves[i] = _log_likelihoods(U, e, Ur, rp, n, dk, s2_grid) + _log_speed_prior(model, M, s)
        errs += np.abs(grid[np.argmax(curves, axis=0)] - s_true)
    return errs / len(cases)

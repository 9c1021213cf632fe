"""Gaussian distribution over DMP parameters (paper Sec. III-C/D, Eq. 10, 16-18).

``theta = [w_1, g_1, ..., w_N, g_N]`` per agent and ``[theta_o, theta_c]``
for the pair.  :func:`fit_prior` estimates mean and covariance from one
``theta`` per demonstration (Eq. 10) with a regularised covariance;
:func:`condition` is Eq. 18 in a structured form that never builds the
``(T D) x (T D)`` matrix ``A``; :func:`condition_literal` is Eq. 17-18
exactly as printed, kept as the reference the tests compare against.

Structured conditioning
-----------------------
The observation of one observed DoF ``i`` is ``f_i = X theta_i + noise``
with one design matrix ``X`` (rows ``[phi_t^T, alpha_y beta_y]`` for the
paper's forcing observation, Eq. 13) shared by all observed DoFs, so
``Omega = blockdiag(X, ..., X)`` and ``Omega~ = [Omega, 0]`` (Sec. III-D).
The Gaussian likelihood (Eq. 16) depends on the data only through
``G = X^T X`` (size ``q x q``, ``q = n_basis + 1``) and ``b_i = X^T f_i``.
With the eigendecomposition ``G = V diag(e) V^T`` and ``L = diag(sqrt e) V^T``
the likelihood equals that of the compressed observation
``z_i = diag(1/sqrt e) V^T b_i = L theta_i + noise`` (noise ``sigma^2 I``), so
Eq. 18 is applied with ``L`` in place of ``Omega`` and a matrix ``A`` of size
at most ``q N_o`` instead of ``T N_o``.  This is exact, not an approximation.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import cho_factor, cho_solve, solve_triangular

__all__ = ["GaussianPrior", "fit_prior", "shrinkage_intensity", "condition", "condition_literal",
           "Posterior", "sample"]

_LOG2PI = float(np.log(2.0 * np.pi))


@dataclass
class GaussianPrior:
    """``p(theta) = N(mean, cov)`` with how the covariance was regularised."""

    mean: np.ndarray
    cov: np.ndarray
    method: str
    shrinkage: float


def shrinkage_intensity(X: np.ndarray) -> float:
    """Analytic shrinkage intensity towards the diagonal (Schaefer & Strimmer 2005, target D).

    The correlations are shrunk towards zero while the variances are kept:
    ``Sigma = (1 - lambda) S + lambda diag(S)``, with
    ``lambda = sum_{i != j} Var(r_ij) / sum_{i != j} r_ij^2`` estimated from
    the standardised samples, clipped to [0, 1].

    Parameters
    ----------
    X : ndarray, shape (S, P)
        One sample per row.
    """
    S = X.shape[0]
    if S < 3:
        return 1.0
    Xc = X - X.mean(axis=0)
    sd = Xc.std(axis=0, ddof=1)
    keep = sd > 1e-12 * max(sd.max(), 1e-300)
    if keep.sum() < 2:
        return 1.0
    Z = Xc[:, keep] / sd[keep]
    W2 = (Z * Z).T @ (Z * Z)  # sum_k w_kij^2
    R = (Z.T @ Z) / (S - 1)
    wbar = R * (S - 1) / S
    var_r = S / (S - 1) ** 3 * (W2 - S * wbar**2)
    off = ~np.eye(R.shape[0], dtype=bool)
    denom = float(np.sum(R[off] ** 2))
    if denom <= 0:
        return 1.0
    return float(np.clip(np.sum(var_r[off]) / denom, 0.0, 1.0))


def fit_prior(thetas, method: str = "shrinkage", ridge: float = 1e-6, shrinkage: float | None = None) -> GaussianPrior:
    """Gaussian over ``theta`` from one parameter vector per demonstration (Eq. 10).

    Parameters
    ----------
    thetas : ndarray, shape (S, P)
    method : {"shrinkage", "ridge", "empirical"}
        ``"empirical"`` is Eq. 10 as printed (divisor ``S``), singular when
        ``S <= P``; ``"ridge"`` adds ``ridge * mean(diag(S))`` to the
        diagonal; ``"shrinkage"`` (default) shrinks correlations towards zero
        with the analytic intensity of :func:`shrinkage_intensity` (or the
        given ``shrinkage``), then adds the same small ridge.
    ridge : float
        Relative diagonal loading, also the numerical floor for every method.
    shrinkage : float, optional
        Fixed shrinkage intensity in [0, 1] instead of the analytic one.
    """
    X = np.asarray(thetas, dtype=np.float64)
    S, P = X.shape
    mean = X.mean(axis=0)
    Xc = X - mean
    emp = Xc.T @ Xc / S  # Eq. 10
    scale = float(np.mean(np.diag(emp))) if P else 0.0
    floor = max(ridge * scale, 1e-12 * max(scale, 1e-300), 1e-300)
    lam = 0.0
    if method == "empirical":
        cov = emp.copy()
    elif method == "ridge":
        cov = emp.copy()
    elif method == "shrinkage":
        lam = shrinkage_intensity(X) if shrinkage is None else float(shrinkage)
        if not 0.0 <= lam <= 1.0:
            raise ValueError(f"shrinkage must be in [0, 1], got {shrinkage}")
        cov = (1.0 - lam) * emp
        cov[np.diag_indices(P)] = np.diag(emp)
    else:
        raise ValueError(f"covariance method must be 'shrinkage', 'ridge' or 'empirical', got {method!r}")
    cov[np.diag_indices(P)] += floor
    return GaussianPrior(mean=mean, cov=cov, method=method, shrinkage=lam)


@dataclass
class Posterior:
    """``p(theta | tau_o) = N(mean, cov)`` (Eq. 18) and the marginal log-likelihood of the observation."""

    mean: np.ndarray
    cov: np.ndarray
    log_likelihood: float


def _compress(G, B, tol=1e-10):
    e, V = np.linalg.eigh(0.5 * (G + G.T))
    keep = e > tol * max(float(e[-1]), 1e-300)
    e, V = e[keep], V[:, keep]
    se = np.sqrt(e)
    L = se[:, None] * V.T  # (k, q)
    z = (V.T @ B) / se[:, None]  # (k, D_o)
    return L, z


def condition(mean, cov, obs_index, G, B, sigma2: float, yy: float | None = None, n_obs: int | None = None,
              need_cov: bool = True) -> Posterior:
    """Condition ``N(mean, cov)`` on a linear-Gaussian observation of some DoFs (Eq. 16-18, structured).

    Parameters
    ----------
    mean : ndarray, shape (P,)
    cov : ndarray, shape (P, P)
    obs_index : ndarray of int, shape (D_o, q)
        Row ``i`` holds the indices into ``theta`` of observed DoF ``i``
        (its ``[w, g]``); every index not listed belongs to ``Omega~``'s zero block.
    G : ndarray, shape (q, q)
        ``X^T X`` for the design ``X`` shared by the observed DoFs.
    B : ndarray, shape (q, D_o)
        ``X^T f_i`` per observed DoF.
    sigma2 : float
        Observation noise variance of Eq. 16.
    yy, n_obs : float, int, optional
        ``sum_i |f_i|^2`` and the number ``T D_o`` of scalar observations;
        needed only for the marginal log-likelihood (otherwise it is NaN).
    need_cov : bool
        Compute the posterior covariance (``O(P^2 k)``); the mean alone is cheaper.
    """
    obs_index = np.asarray(obs_index)
    D_o, q = obs_index.shape
    L, z = _compress(G, B)
    k = L.shape[0]
    flat = obs_index.reshape(-1)
    P = mean.shape[0]
    # Sigma L~^T, shape (P, D_o k); L~ = blockdiag(L, ..., L) on the observed indices
    SLt = np.einsum("pdq,kq->pdk", cov[:, flat].reshape(P, D_o, q), L).reshape(P, D_o * k)
    LSLt = np.einsum("kq,dqj->dkj", L, SLt[flat].reshape(D_o, q, D_o * k)).reshape(D_o * k, D_o * k)
    A = LSLt
    A[np.diag_indices_from(A)] += sigma2
    cf = cho_factor(A, lower=True)
    mu_o = mean[obs_index]  # (D_o, q)
    r = (z - L @ mu_o.T).T.reshape(-1)  # z_i - L mu_i, stacked per DoF
    alpha = cho_solve(cf, r)
    post_mean = mean + SLt @ alpha
    post_cov = None
    if need_cov:
        Wt = solve_triangular(cf[0], SLt.T, lower=True)  # (D_o k, P)
        post_cov = cov - Wt.T @ Wt
    loglik = float("nan")
    if yy is not None and n_obs is not None:
        # |F - Omega mu|^2 = yy - 2 sum_i mu_i^T b_i + sum_i mu_i^T G mu_i
        resid_total = yy - 2.0 * np.sum(mu_o * B.T) + np.sum((mu_o @ G) * mu_o)
        resid_perp = max(resid_total - float(r @ r), 0.0)
        logdet = 2.0 * float(np.sum(np.log(np.diag(cf[0]))))
        loglik = -0.5 * (n_obs * _LOG2PI + (n_obs - D_o * k) * np.log(sigma2) + logdet
                         + resid_perp / sigma2 + float(r @ alpha))
    return Posterior(post_mean, post_cov, loglik)


def condition_literal(mean, cov, Omega, F, sigma2: float) -> Posterior:
    """Eq. 17-18 exactly as printed: builds ``A = sigma^2 I + Omega Sigma Omega^T`` and inverts it.

    ``Omega`` is the full ``(T D_o) x P`` feature matrix (``Omega~ = [Omega, 0]``)
    and ``F`` the stacked forcing values ``[f_1; ...; f_N]``.  Quadratic in
    the number of observed time steps: for tests and benchmarks only.
    """
    A = sigma2 * np.eye(Omega.shape[0]) + Omega @ cov @ Omega.T
    Ainv = np.linalg.inv(A)
    K = cov @ Omega.T @ Ainv
    post_mean = mean + K @ (F - Omega @ mean)
    post_cov = cov - K @ Omega @ cov
    sign, logdet = np.linalg.slogdet(A)
    r = F - Omega @ mean
    loglik = -0.5 * (F.shape[0] * _LOG2PI + logdet + r @ Ainv @ r)
    return Posterior(post_mean, post_cov, float(loglik))


def sample(mean, cov, n: int, random_state=None) -> np.ndarray:
    """Draw ``n`` samples of ``N(mean, cov)``; robust to a positive semi-definite ``cov``.

    Returns an array of shape ``(n, P)``.
    """
    rng = np.random.default_rng(random_state)
    e, V = np.linalg.eigh(0.5 * (cov + cov.T))
    e = np.clip(e, 0.0, None)
    return mean + (rng.standard_normal((n, mean.shape[0])) * np.sqrt(e)) @ V.T

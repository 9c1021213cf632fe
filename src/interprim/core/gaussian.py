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
With any ``L`` such that ``L^T L = G`` (a thin QR ``X = Q L`` for the hyper-parameter selection's
:func:`compress_observation`) the likelihood equals that of
the compressed observation ``z_i = L theta_i + noise`` (``L^T z_i = b_i``, noise ``sigma^2 I``), up to the
residual outside ``X``'s columns, so
Eq. 18 is applied with ``L`` in place of ``Omega`` and a matrix ``A`` of size
at most ``q N_o`` instead of ``T N_o``.  This is exact, not an approximation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from ._compiled import registry as _kernels  # light: the kernels themselves load on first use

__all__ = ["GaussianPrior", "LowRankConditioner", "fit_prior", "shrinkage_intensity", "condition", "condition_literal",
           "Posterior", "sample"]

LOG2PI = float(np.log(2.0 * np.pi))


class GaussianPrior:
    """``p(theta) = N(mean, cov)`` (Eq. 10) with how the covariance was regularised: the one prior type.

    ``diag`` and ``factor`` (optional) give the same covariance in the diagonal-plus-low-rank form
    ``cov = diag(diag) + factor @ factor.T`` that every method of :func:`fit_prior` produces (``factor`` has at
    most ``S`` columns, ``S`` demonstrations).  A prior made by :meth:`factored` (the folds of cross-validation,
    the phase likelihood's observed block) has only that form; its dense ``cov`` is built on first use.

    Conditioning on an observation of the observed DoFs (Eq. 16-18) and its evidence ``log p(tau_o)`` have one
    home: :meth:`conditioner` (the low-rank form, compiled or numpy chosen inside
    :meth:`LowRankConditioner.mean_and_evidence`), :meth:`condition` (the structured dense form), :meth:`evidence` and
    :meth:`posterior_means` (every ``sigma^2`` candidate at once, :func:`lowrank_case`); :func:`condition_literal`
    is Eq. 17-18 as printed, the reference they are tested against.

    Parameters
    ----------
    mean : ndarray, shape (P,)
    cov : ndarray, shape (P, P) or None
        ``None``: ``diag(diag) + factor factor^T``, built when first asked for.
    method : str
        The covariance method of :func:`fit_prior`.
    shrinkage : float
        The shrinkage intensity ``lambda`` (0 unless ``method="shrinkage"``).
    diag, factor : ndarray, shape (P,) and (P, r), optional
        The diagonal-plus-low-rank form of ``cov``.
    """

    def __init__(self, mean: np.ndarray, cov: np.ndarray | None, method: str, shrinkage: float,
                 diag: np.ndarray | None = None, factor: np.ndarray | None = None) -> None:
        if cov is None and (diag is None or factor is None):
            raise ValueError("GaussianPrior: give cov, or diag and factor")
        self.mean = mean
        if cov is not None:  # else built on first use (__getattr__)
            self.cov = cov
        self.method = method
        self.shrinkage = shrinkage
        self.diag = diag
        self.factor = factor

    @classmethod
    def factored(cls, thetas: ArrayLike, method: str, ridge: float, lam: float | None) -> GaussianPrior:
        """The prior of :func:`fit_prior` in factored form only, ``N(mean, diag(d) + W^T W)``, without the
        ``P x P`` matrix: what the folds of cross-validation condition on (:func:`lowrank_case`).

        Every covariance method of ``fit_prior`` is ``(1 - lam) S + lam diag(S) + floor I`` with the sample
        covariance ``S = Xc^T Xc / n`` of ``n`` demonstrations (``lam = 0`` for ``"ridge"`` and
        ``"empirical"``), i.e. a diagonal plus a rank-``n`` term.  Conditioning then needs only ``k x k``
        eigendecompositions per observed DoF and ``n x n`` solves (Woodbury), for all ``sigma^2`` candidates at
        once, instead of a ``(D_o k)``-sized eigendecomposition.
        """
        X = np.asarray(thetas, dtype=np.float64)
        n, P = X.shape
        mean = X.mean(axis=0)
        Xc = X - mean
        diag = np.sum(Xc * Xc, axis=0) / n
        scale = float(np.mean(diag)) if P else 0.0
        floor = max(ridge * scale, 1e-12 * max(scale, 1e-300), 1e-300)
        lam = 0.0 if (method != "shrinkage" or lam is None) else float(lam)
        W = np.sqrt((1.0 - lam) / n) * Xc  # (n, P)
        return cls(mean, None, method, lam, lam * diag + floor, W.T)

    def __getattr__(self, name: str) -> np.ndarray:
        # ``cov`` of a factored prior: diag(diag) + factor factor^T, built on first use and then kept
        diag, factor = self.__dict__.get("diag"), self.__dict__.get("factor")  # (not through __getattr__ again)
        if name != "cov" or factor is None or diag is None:
            raise AttributeError(f"GaussianPrior has no attribute {name!r}")
        U = np.asarray(factor, dtype=np.float64)
        cov = U @ U.T
        cov[np.diag_indices(cov.shape[0])] += diag
        self.cov = cov
        return cov

    @property
    def d(self) -> np.ndarray:
        """The diagonal part ``d`` of ``cov = diag(d) + W^T W`` (``diag``)."""
        if self.diag is None:
            raise AttributeError("this prior has no diagonal-plus-low-rank form")
        return self.diag

    @property
    def W(self) -> np.ndarray:
        """The low-rank part ``W`` (``r x P``, ``factor.T``) of ``cov = diag(d) + W^T W``."""
        if self.factor is None:
            raise AttributeError("this prior has no diagonal-plus-low-rank form")
        return self.factor.T

    def marginal(self, n: int) -> GaussianPrior:
        """The prior of the first ``n`` parameters (the observed agent's block when ``n = D_o q``), in the forms
        this one has (views, no copies)."""
        def cut(a: np.ndarray | None) -> np.ndarray | None:
            return None if a is None else a[:n]

        cov = self.__dict__.get("cov")
        return GaussianPrior(self.mean[:n], None if cov is None else cov[:n, :n], self.method,
                             self.shrinkage, cut(self.diag), cut(self.factor))

    def conditioner(self, obs_index: np.ndarray, thetas: ArrayLike | None = None,
                    ridge: float | None = None) -> LowRankConditioner | None:
        """Eq. 16-18 precomputed for this prior and the observed parameters ``obs_index`` (``(D_o, q)``):
        :meth:`LowRankConditioner.from_prior`, or ``None`` when the covariance has no low-rank form."""
        return LowRankConditioner.from_prior(self, obs_index, thetas, ridge)

    def condition(self, obs_index: np.ndarray, G: np.ndarray, B: np.ndarray, sigma2: float, yy: float | None = None,
                  n_obs: int | None = None,
                  need_cov: bool = True) -> Posterior:
        """Eq. 16-18 in the structured dense form (:func:`condition`) from the statistics ``G = X^T X``,
        ``B = X^T F`` of an observation of the parameters ``obs_index``."""
        return condition(self.mean, self.cov, obs_index, G, B, sigma2, yy=yy, n_obs=n_obs, need_cov=need_cov)

    def posterior_means(self, n_o: int, q: int, X: np.ndarray, Y: np.ndarray, sigma2: ArrayLike,
                        compressed: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
        """Posterior means ``(len(sigma2), P)`` of Eq. 18 for the observation ``Y = X theta_i + noise`` of the
        first ``n_o`` DoFs (``q`` parameters each), every noise candidate at once (:func:`lowrank_case`)."""
        means = lowrank_case(self, n_o, q, X, Y, np.atleast_1d(np.asarray(sigma2, dtype=np.float64)),
                             compressed=compressed)[0]
        assert means is not None  # need_mean
        return means

    def evidence(self, n_o: int, q: int, X: np.ndarray, Y: np.ndarray, sigma2: ArrayLike,
                 compressed: tuple[np.ndarray, np.ndarray] | None = None) -> float | np.ndarray:
        """The evidence ``log p(tau_o)`` (Eq. 16-17: the marginal log-likelihood) of the observation
        ``Y = X theta_i + noise`` of the first ``n_o`` DoFs: a float for one ``sigma2``, an array for an array of
        candidates (all at once, :func:`lowrank_case`); the structured dense form when the prior has no
        low-rank form."""
        s2 = np.asarray(sigma2, dtype=np.float64)
        many = s2.ndim > 0
        s2 = np.atleast_1d(s2)
        if self.diag is not None and self.factor is not None:
            lls = lowrank_case(self, n_o, q, X, Y, s2, need_mean=False, need_ll=True, compressed=compressed)[1]
            assert lls is not None  # need_ll
            ll = lls
        else:
            idx = np.arange(n_o * q).reshape(n_o, q)
            G, B = X.T @ X, X.T @ Y
            yy = float(np.sum(Y * Y))
            ll = np.array([self.condition(idx, G, B, float(v), yy=yy, n_obs=Y.size, need_cov=False).log_likelihood
                           for v in s2])
        return ll if many else float(ll[0])

    def __repr__(self) -> str:
        return (f"GaussianPrior(P={np.shape(self.mean)[0]}, method={self.method!r}, shrinkage={self.shrinkage:.3g}"
                f"{', low rank' if self.factor is not None else ''})")


def shrink_cross(prior: GaussianPrior, gamma: float, n_first: int) -> GaussianPrior:
    """Shrink the cross-agent block of ``prior.cov`` (first ``n_first`` parameters x the rest) by ``1 - gamma``,
    in place; returns ``prior``.

    The diagonal-plus-low-rank form stays exact: with ``cov = diag(d) + U U^T`` and ``U = [U_o; U_c]`` the
    result is ``diag(d) + V V^T`` with ``V = [[U_o, 0], [(1 - gamma) U_c, sqrt(1 - (1 - gamma)^2) U_c]]`` (the
    rank doubles).  ``gamma = 0`` leaves the prior unchanged; ``gamma = 1`` makes the agents independent.
    """
    gamma = float(gamma)
    if not 0.0 <= gamma <= 1.0:
        raise ValueError(f"gamma must be in [0, 1], got {gamma}")
    if gamma == 0.0:
        return prior
    po = int(n_first)
    prior.cov[:po, po:] *= 1.0 - gamma
    prior.cov[po:, :po] *= 1.0 - gamma
    U = getattr(prior, "factor", None)
    if U is not None:
        U = np.asarray(U, dtype=np.float64)
        r = U.shape[1]
        V = np.zeros((U.shape[0], 2 * r))
        V[:po, :r] = U[:po]
        V[po:, :r] = (1.0 - gamma) * U[po:]
        V[po:, r:] = np.sqrt(1.0 - (1.0 - gamma) ** 2) * U[po:]
        prior.factor = V
    return prior


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
    # Sums over i != j of Var(r_ij) and r_ij^2 without forming the P x P matrices (O(S^2 P), not O(S P^2)):
    # sum_ij W2_ij = sum_k (sum_i z_ki^2)^2 and sum_ij R_ij^2 = |Z Z^T|_F^2 / (S-1)^2.
    Z2 = Z * Z
    rs = Z2.sum(axis=1)
    w2_all = float(rs @ rs)
    w2_diag = float(np.sum(Z2 * Z2))
    Rd = Z2.sum(axis=0) / (S - 1)  # diag of R
    ZZt = Z @ Z.T
    r2_all = float(np.sum(ZZt * ZZt)) / (S - 1) ** 2
    r2_off = r2_all - float(Rd @ Rd)
    wb = (S - 1) / S
    var_off = S / (S - 1) ** 3 * ((w2_all - w2_diag) - S * wb * wb * r2_off)
    if r2_off <= 0:
        return 1.0
    return float(np.clip(var_off / r2_off, 0.0, 1.0))


def fit_prior(thetas: ArrayLike, method: str = "shrinkage", ridge: float = 1e-6,
              shrinkage: float | None = None) -> GaussianPrior:
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
    floor = _floor(emp, ridge)
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
    d, factor = _lowrank(Xc, emp, lam, floor)
    return GaussianPrior(mean=mean, cov=cov, method=method, shrinkage=lam, diag=d, factor=factor)


def _floor(emp: np.ndarray, ridge: float) -> float:
    P = emp.shape[0]
    scale = float(np.mean(np.diag(emp))) if P else 0.0
    return max(ridge * scale, 1e-12 * max(scale, 1e-300), 1e-300)


def _lowrank(Xc: np.ndarray, emp: np.ndarray, lam: float, floor: float) -> tuple[np.ndarray, np.ndarray]:
    """The covariance of :func:`fit_prior` as diagonal + low rank: ``diag(d) + U U^T``, ``U = sqrt((1-lam)/S) Xc^T``."""
    S, P = Xc.shape
    d = lam * np.diag(emp) + floor
    factor = np.sqrt((1.0 - lam) / S) * Xc.T
    if S > P:  # more demonstrations than parameters: a rank-P factor of the same matrix
        e, V = np.linalg.eigh((1.0 - lam) * emp)
        factor = V * np.sqrt(np.clip(e, 0.0, None))
    return d, np.ascontiguousarray(factor)


@dataclass
class Posterior:
    """``p(theta | tau_o) = N(mean, cov)`` (Eq. 18) and the marginal log-likelihood of the observation."""

    mean: np.ndarray
    cov: np.ndarray | None  # None when the covariance was not asked for (need_cov=False)
    log_likelihood: float


def condition(mean: np.ndarray, cov: np.ndarray, obs_index: np.ndarray, G: np.ndarray, B: np.ndarray, sigma2: float,
              yy: float | None = None, n_obs: int | None = None,
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
        Compute the posterior covariance (``O(P^2 P_o)``); the mean alone is cheaper.

    Returns
    -------
    Posterior
        Posterior mean, covariance (``None`` without ``need_cov``) and marginal log-likelihood.

    Notes
    -----
    The observation is whitened by the prior of the observed parameters
    (``Sigma_oo = L L^T``), so that every matrix factorised is
    ``sigma^2 I + L^T J L`` with ``J = blockdiag(G)``: exact for any ``G``,
    including the singular ``G`` of the first frames of a movement.
    """
    from scipy.linalg import cho_factor, cho_solve, solve_triangular  # lazy: keeps `import interprim` light

    obs_index = np.asarray(obs_index)
    D_o, q = obs_index.shape
    flat = obs_index.reshape(-1)
    Po = flat.size
    G = 0.5 * (np.asarray(G, dtype=np.float64) + np.asarray(G, dtype=np.float64).T)
    # Whitened by the prior of the observed parameters, Sigma_oo = Lp Lp^T:
    # Sigma Omega~^T A^-1 = Sigma_{:,o} Lp^-T (sigma^2 I + Q)^-1 Lp^T H^T with Q = Lp^T J Lp, J = blockdiag(G).
    # Exact and stable for any G (singular early in a movement): nothing is divided by eigenvalues of G.
    Lp = np.linalg.cholesky(cov[np.ix_(flat, flat)])
    JL = np.einsum("ab,ibk->iak", G, Lp.reshape(D_o, q, Po)).reshape(Po, Po)
    Q = Lp.T @ JL
    Q = 0.5 * (Q + Q.T)
    A = Q.copy()
    A[np.diag_indices_from(A)] += sigma2
    cf = cho_factor(A, lower=True)
    mu_o = mean[obs_index]  # (D_o, q)
    c = (B.T - mu_o @ G).reshape(-1)  # Omega^T (F - Omega mu), stacked per DoF
    u = cho_solve(cf, Lp.T @ c)
    w = solve_triangular(Lp, u, lower=True, trans="T")
    shift = cov[:, flat] @ w
    post_mean = mean + shift
    post_cov = None
    if need_cov:
        R = solve_triangular(Lp, cov[flat, :], lower=True)  # Lp^-1 Sigma_{o,:}, (Po, P)
        K = R.T @ (cho_solve(cf, Q) @ R)
        post_cov = cov - 0.5 * (K + K.T)
    loglik = float("nan")
    if yy is not None and n_obs is not None:
        # |F - Omega mu|^2 = yy - 2 sum_i mu_i^T b_i + sum_i mu_i^T G mu_i ;  quadratic form by Woodbury
        resid_total = yy - 2.0 * np.sum(mu_o * B.T) + np.sum((mu_o @ G) * mu_o)
        quad = max(resid_total - float(c @ shift[flat]), 0.0) / sigma2
        logdet = (n_obs - Po) * np.log(sigma2) + 2.0 * float(np.sum(np.log(np.diag(cf[0]))))
        loglik = -0.5 * (n_obs * LOG2PI + logdet + quad)
    return Posterior(post_mean, post_cov, loglik)


def condition_literal(mean: np.ndarray, cov: np.ndarray, Omega: np.ndarray, F: np.ndarray, sigma2: float) -> Posterior:
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
    loglik = -0.5 * (F.shape[0] * LOG2PI + logdet + r @ Ainv @ r)
    return Posterior(post_mean, post_cov, float(loglik))


def sample(mean: ArrayLike, cov: ArrayLike, n: int,
           random_state: int | np.random.Generator | None = None) -> np.ndarray:
    """Draw ``n`` samples of ``N(mean, cov)``; robust to a positive semi-definite ``cov``.

    ``mean + z L^T`` with ``z`` standard normal and ``L`` the Cholesky factor of ``cov``.  The Cholesky factor
    is a continuous function of ``cov``, so two covariances equal to rounding (e.g. from the compiled and the
    numpy conditioning) give samples equal to rounding.  (An eigendecomposition is not: near-equal
    eigenvalues let the eigenvectors rotate freely, and samples drawn through them differed by 20-40 %.)
    A singular ``cov`` gets the smallest diagonal jitter, from ``1e-14`` of its mean diagonal upwards,
    that makes it factorisable.

    Returns an array of shape ``(n, P)``.
    """
    rng = np.random.default_rng(random_state)
    mean = np.asarray(mean, dtype=np.float64)
    C = 0.5 * (np.asarray(cov, dtype=np.float64) + np.asarray(cov, dtype=np.float64).T)
    scale = max(float(np.mean(np.abs(np.diag(C)))), np.finfo(float).tiny)
    jitter = 0.0
    for _ in range(40):
        try:
            L = np.linalg.cholesky(C + jitter * np.eye(C.shape[0]) if jitter else C)
            break
        except np.linalg.LinAlgError:
            jitter = 1e-14 * scale if jitter == 0.0 else 10.0 * jitter
    else:
        raise ValueError("sample: cov is not positive semi-definite (no Cholesky factor even with a jitter of "
                         f"{jitter:.1e} on the diagonal)")
    return mean + rng.standard_normal((n, mean.shape[0])) @ L.T


def lowrank_parts(prior: GaussianPrior, thetas: ArrayLike | None = None, ridge: float | None = None,
                  tol: float = 1e-10) -> tuple[np.ndarray, np.ndarray] | None:
    """``(d, U)`` with ``prior.cov == diag(d) + U U^T`` (checked to ``tol`` relative), or ``None``.

    Uses ``prior.diag``/``prior.factor`` when present (set by :func:`fit_prior`);
    otherwise (a model read from a file) rebuilds them from the demonstrations'
    parameters ``thetas`` with the arithmetic of :func:`fit_prior` (so a saved
    and reloaded model predicts bitwise identically) and checks the result
    against ``prior.cov``.
    """
    if prior.diag is not None and prior.factor is not None:
        return np.asarray(prior.diag, dtype=np.float64), np.ascontiguousarray(prior.factor, dtype=np.float64)
    if thetas is None:
        return None
    X = np.asarray(thetas, dtype=np.float64)
    S, P = X.shape
    if P != prior.mean.shape[0] or S < 2:
        return None
    Xc = X - X.mean(axis=0)
    emp = Xc.T @ Xc / S
    lam = float(prior.shrinkage) if prior.method == "shrinkage" else 0.0
    if ridge is not None:
        floor = _floor(emp, ridge)
    else:
        floor = float(np.median(np.diag(prior.cov) - np.diag(emp)))
    d, U = _lowrank(Xc, emp, lam, floor)
    cov = prior.cov
    scale = float(np.abs(cov).max()) if cov.size else 0.0
    if not np.all(d > 0) or scale == 0.0:
        return None
    rec = U @ U.T
    rec[np.diag_indices(P)] += d
    if float(np.abs(rec - cov).max()) > tol * scale:
        return None
    return d, U


class LowRankConditioner:
    """Eq. 16-18 for a prior ``Sigma = diag(d) + U U^T`` (shrinkage, ridge and empirical priors all have it).

    The observation is ``Omega~ = [blockdiag(X, ..., X), 0]`` (one ``X`` for
    every observed DoF, Sec. III-D), seen through its statistics ``G = X^T X``
    and ``B = X^T F``.  With ``S_i = diag(sqrt(d_i))``, ``Uh = S^{-1} U`` and
    ``T_i = sigma^2 I + S_i G S_i`` (one per observed DoF, ``q x q``) the
    posterior of Eq. 18 is, exactly,

    * mean: ``mu + [S (a + sigma^2 T^{-1} Uh gamma);  U_c gamma]`` with
      ``a = T^{-1} S (B - G mu_o)``, ``K = I + sum_i Uh_i^T (I - sigma^2 T_i^{-1}) Uh_i``
      (``r x r``) and ``gamma = K^{-1} Uh^T a``;
    * covariance: ``blockdiag(sigma^2 S_i T_i^{-1} S_i) (+) diag(d_c) + W K^{-1} W^T``
      with ``W = [-sigma^2 S T^{-1} Uh; -U_c]`` -- a sum of positive
      semi-definite terms, no subtraction;
    * ``log det A = n log sigma^2 + sum_i (log det T_i - q log sigma^2) + log det K``
      (matrix determinant lemma), so the marginal log-likelihood needs no ``(T D_o)^2`` matrix.

    Everything that depends only on the prior is computed here, once.  The
    cost of :meth:`mean` is ``O(D_o (q^3 + q^2 r + q r^2) + P r)``: independent of
    the number of observed frames, and far below the ``O((D_o q)^3)`` of the
    dense structured form (:func:`condition`) when ``r`` (<= number of
    demonstrations) is small.
    """

    def __init__(self, mean: np.ndarray, d: np.ndarray, U: np.ndarray, obs_index: np.ndarray) -> None:
        obs_index = np.asarray(obs_index, dtype=np.intp)
        self.obs_index = obs_index
        D_o, q = obs_index.shape
        P = mean.shape[0]
        self.P, self.D_o, self.q = P, D_o, q
        self.mean = np.ascontiguousarray(mean, dtype=np.float64)
        self.obs_flat = np.ascontiguousarray(obs_index.reshape(-1))
        mask = np.ones(P, dtype=bool)
        mask[self.obs_flat] = False
        self.other = np.flatnonzero(mask).astype(np.intp)
        self.d = np.asarray(d, dtype=np.float64)
        U = np.asarray(U, dtype=np.float64)
        self.r = U.shape[1]
        self.sq = np.ascontiguousarray(np.sqrt(self.d[obs_index]))  # (D_o, q)
        self.Uh = np.ascontiguousarray(U[obs_index] / self.sq[:, :, None])  # (D_o, q, r)
        self.mu_o = np.ascontiguousarray(self.mean[obs_index])
        self.Uc = np.ascontiguousarray(U[self.other])  # (P - D_o q, r)
        self.d_other = self.d[self.other]
        Uh2 = self.Uh.reshape(D_o * q, self.r)
        self.K0 = np.eye(self.r) + Uh2.T @ Uh2

    @classmethod
    def from_prior(cls, prior: GaussianPrior, obs_index: np.ndarray, thetas: ArrayLike | None = None,
                   ridge: float | None = None) -> LowRankConditioner | None:
        """A conditioner for ``prior``, or ``None`` if its covariance is not diagonal plus low rank."""
        parts = lowrank_parts(prior, thetas, ridge)
        if parts is None:
            return None
        return cls(prior.mean, parts[0], parts[1], obs_index)

    def _loglik(self, ld_T: float, ld_K: float, resid: float, sigma2: float, n_obs: int | None) -> float:
        if n_obs is None:
            return float("nan")
        D_o, q = self.D_o, self.q
        log_s2 = np.log(sigma2)
        logdet = n_obs * log_s2 + ld_T - D_o * q * log_s2 + ld_K
        return float(-0.5 * (n_obs * LOG2PI + logdet + max(resid, 0.0) / sigma2))

    def mean_and_evidence(self, G: np.ndarray, B: np.ndarray, sigma2: float, yy: float = 0.0,
                          n_obs: int | None = None) -> tuple[np.ndarray, float] | None:
        """Posterior mean and log-likelihood (the evidence of Eq. 16-17) of Eq. 18: the compiled kernel when the
        kernels are in use (:func:`interprim.core._compiled.registry.in_use`), else :meth:`mean_numpy` (the same
        numbers to rounding); ``None`` if a factorisation failed."""
        return self.mean_compiled(G, B, sigma2, yy, n_obs) if _kernels.in_use() else \
            self.mean_numpy(G, B, sigma2, yy, n_obs)

    def mean_compiled(self, G: np.ndarray, B: np.ndarray, sigma2: float, yy: float = 0.0, n_obs: int | None = None,
                      out: np.ndarray | None = None) -> tuple[np.ndarray, float] | None:
        """Posterior mean and log-likelihood with the compiled kernel; ``None`` if a factorisation failed."""
        lowrank_condition_mean = _kernels.compiled("conditioning.lowrank_condition_mean")
        if out is None:
            out = np.empty(self.P)
        ld_T, ld_K, resid = lowrank_condition_mean(G, B, float(sigma2), float(yy), self.sq, self.Uh, self.K0,
                                                   self.mean, self.mu_o, self.obs_flat, self.other, self.Uc, out)
        if not (math.isfinite(ld_T) and math.isfinite(ld_K)):
            return None
        return out, self._loglik(ld_T, ld_K, resid, sigma2, n_obs)

    def _factors(self, G: np.ndarray, sigma2: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        q = self.q
        T = self.sq[:, :, None] * G[None, :, :] * self.sq[:, None, :]
        T[:, np.arange(q), np.arange(q)] += sigma2
        TinvUh = np.linalg.solve(T, self.Uh)  # (D_o, q, r)
        r = self.r
        K = self.K0 - sigma2 * (self.Uh.reshape(-1, r).T @ TinvUh.reshape(-1, r))  # sum_i Uh_i^T T_i^-1 Uh_i
        return T, TinvUh, 0.5 * (K + K.T)

    def mean_numpy(self, G: ArrayLike, B: ArrayLike, sigma2: float, yy: float = 0.0,
                   n_obs: int | None = None) -> tuple[np.ndarray, float]:
        """Same as :meth:`mean_compiled` in plain numpy (no compilation; used before the kernels are ready)."""
        G = np.asarray(G, dtype=np.float64)
        B = np.asarray(B, dtype=np.float64)
        T, TinvUh, K = self._factors(G, sigma2)
        mu_o = self.mean[self.obs_index]  # (D_o, q)
        c = B.T - mu_o @ G  # (D_o, q)
        a = np.linalg.solve(T, (self.sq * c)[:, :, None])[:, :, 0]
        beta = np.einsum("iqr,iq->r", self.Uh, a)
        gamma = np.linalg.solve(K, beta)
        w = np.einsum("iqr,r->iq", TinvUh, gamma)
        delta = self.sq * (a + sigma2 * w)
        out = self.mean.copy()
        out[self.obs_flat] += delta.reshape(-1)
        out[self.other] += self.Uc @ gamma
        resid = yy - float(np.sum(mu_o * (B.T + c))) - float(np.sum(c * delta))
        ld_T = float(np.sum(np.linalg.slogdet(T)[1]))
        ld_K = float(np.linalg.slogdet(K)[1])
        return out, self._loglik(ld_T, ld_K, resid, sigma2, n_obs)

    def cov(self, G: np.ndarray, sigma2: float) -> np.ndarray:
        """Posterior covariance of Eq. 18 (``P x P``), as a sum of positive semi-definite terms."""
        from scipy.linalg import solve_triangular  # lazy: keeps `import interprim` light

        G = np.asarray(G, dtype=np.float64)
        T, TinvUh, K = self._factors(G, sigma2)
        P = self.P
        Tinv = np.linalg.inv(T)
        blocks = sigma2 * self.sq[:, :, None] * Tinv * self.sq[:, None, :]  # (D_o, q, q)
        Wt = np.empty((P, self.r))
        Wt[self.obs_flat] = (-sigma2 * self.sq[:, :, None] * TinvUh).reshape(-1, self.r)
        Wt[self.other] = -self.Uc
        Lk = np.linalg.cholesky(K)
        V = solve_triangular(Lk, Wt.T, lower=True, check_finite=False)  # (r, P)
        out = V.T @ V
        oi = self.obs_index
        out[oi[:, :, None], oi[:, None, :]] += blocks  # the D_o diagonal blocks (disjoint index sets)
        out[self.other, self.other] += self.d_other
        return out


def LowRankPrior(thetas: ArrayLike, method: str, ridge: float, lam: float | None) -> GaussianPrior:
    """:meth:`GaussianPrior.factored` (the name of the factored prior when it was a type of its own)."""
    return GaussianPrior.factored(thetas, method, ridge, lam)


def compress_observation(X: np.ndarray, Y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(L, z)`` of the compressed observation of :func:`lowrank_case`: ``X = Q L`` (thin QR), ``z = Q^T Y``, so
    ``L^T L = X^T X`` and ``L^T z = X^T Y``.  It depends on the observation only, so it can be computed once and
    passed to every prior it is conditioned on.

    No direction of the design is dropped.  A direction where ``X`` is nearly singular (the basis functions not yet
    reached at a small phase) can still carry a prior variance many times the noise (weights in forcing units).
    Dropping such directions by a tolerance on ``X^T X``'s eigenvalues (``1e-10`` of the largest, as this function
    once did) moved the marginal log-likelihood of a partial observation by 0.3-82 (57 frames at phases 0.2-1).
    """
    X = np.asarray(X, dtype=np.float64)
    Q, L = np.linalg.qr(X)
    return L, Q.T @ np.asarray(Y, dtype=np.float64)


def lowrank_case(pr: GaussianPrior, n_o: int, q: int, X: np.ndarray, Y: np.ndarray, s2: np.ndarray,
                 need_mean: bool = True, need_ll: bool = False,
                 compressed: tuple[np.ndarray, np.ndarray] | None = None,
                 ) -> tuple[np.ndarray | None, np.ndarray | None]:
    """Posterior means ``(len(s2), P)`` and/or marginal log-likelihoods ``(len(s2),)`` for one observation.

    The observation ``Y = X theta_i + noise`` (one column per observed DoF ``i``, Eq. 16) is seen through
    its compression ``z_i = L theta_i + noise`` (module notes).  Per observed DoF the block
    ``L diag(d_i) L^T = V_i diag(e_i) V_i^T`` is eigendecomposed; in those bases
    ``A = sigma^2 I + L Sigma_oo L^T = diag(e + sigma^2) + Ut Ut^T`` (``Ut`` stacks ``V_i^T L W_i^T``), so every
    ``sigma^2`` candidate costs one ``n x n`` solve (Woodbury, ``n`` = rank of ``W``) and Eq. 18 follows:
    ``mu + Sigma_{:,o} L^T A^-1 r`` with ``r = z - L mu_o``.

    Parameters
    ----------
    pr : GaussianPrior
        With its low-rank form (``diag``/``factor``; e.g. :meth:`GaussianPrior.factored`).
    n_o, q : int
        Observed DoFs (the first ``n_o q`` parameters) and parameters per DoF.
    X, Y : ndarray, shape (M, q), (M, n_o)
        Design and targets (ignored when ``compressed`` is given, except ``Y`` for the log-likelihood).
    s2 : ndarray, shape (S2,)
        Observation noise candidates.
    need_mean, need_ll : bool
        Compute the posterior means / the marginal log-likelihoods.
    compressed : tuple, optional
        :func:`compress_observation` of ``(X, Y)``, reused across priors.
    """
    L, zc = compress_observation(X, Y) if compressed is None else compressed
    k = L.shape[0]
    no_q = n_o * q
    mu_o = pr.mean[:no_q].reshape(n_o, q)
    d_o = pr.d[:no_q].reshape(n_o, q)
    Wt_o = pr.W[:, :no_q].T.reshape(n_o, q, -1)  # (n_o, q, n): W_i^T
    # block i of L Sigma_oo L^T's diagonal part, L diag(d_i) L^T, eigendecomposed per observed DoF
    E, V = np.linalg.eigh((L[None, :, :] * d_o[:, None, :]) @ L.T)  # (n_o, k), (n_o, k, k)
    E = np.clip(E, 0.0, None)
    Vt = V.transpose(0, 2, 1)
    VL = Vt @ L  # (n_o, k, q): V_i^T L
    Ut = (VL @ Wt_o).reshape(n_o * k, -1)  # V_i^T L W_i^T, stacked (n_o k, n)
    r = (zc - L @ mu_o.T).T  # (n_o, k)
    rt = (Vt @ r[:, :, None]).reshape(-1)  # (n_o k,)
    e = E.reshape(-1)
    s2 = np.asarray(s2, dtype=np.float64)
    ns = s2.shape[0]
    g = 1.0 / (e[None, :] + s2[:, None])  # (S2, n_o k)
    nW = Ut.shape[1]
    C = (Ut.T[None, :, :] * g[:, None, :]) @ Ut  # I + Ut^T diag(g) Ut (after the next line), (S2, n, n)
    C[:, np.arange(nW), np.arange(nW)] += 1.0
    gr = g * rt[None, :]
    sol = np.linalg.solve(C, (gr @ Ut)[:, :, None])[:, :, 0]  # (S2, n)
    at = gr - g * (sol @ Ut.T)  # A^-1 r in the eigenbases, (S2, n_o k)
    means = ll = None
    if need_mean:
        # v_i = L^T V_i at_i (back to the parameters); v @ W_o^T = at @ Ut
        v = (VL.transpose(0, 2, 1) @ at.reshape(ns, n_o, k).transpose(1, 2, 0))  # (n_o, q, S2)
        v = v.transpose(2, 0, 1).reshape(ns, no_q)
        means = pr.mean[None, :] + (at @ Ut) @ pr.W
        means[:, :no_q] += v * pr.d[None, :no_q]
    if need_ll:
        resid_total = float(np.sum((Y - X @ mu_o.T) ** 2))
        resid_perp = max(resid_total - float(r.reshape(-1) @ r.reshape(-1)), 0.0)
        n_obs, dk = Y.size, n_o * k
        logdet = np.sum(np.log(e[None, :] + s2[:, None]), axis=1) + np.linalg.slogdet(C)[1]
        ll = -0.5 * (n_obs * LOG2PI + (n_obs - dk) * np.log(s2) + logdet + resid_perp / s2 + at @ rt)
    return means, ll


def lowrank_cases(pr: GaussianPrior, n_o: int, q: int, compressed: list[tuple[np.ndarray, np.ndarray]],
                  s2: np.ndarray, need_mean: bool = True, need_ll: bool = False,
                  observations: list[tuple[np.ndarray, np.ndarray]] | None = None,
                  ) -> tuple[np.ndarray | None, np.ndarray | None]:
    """:func:`lowrank_case` of several observations conditioned on one prior, at once: ``(B, len(s2), P)`` means
    and/or ``(B, len(s2))`` log-likelihoods of the ``B`` compressed observations ``compressed``
    (:func:`compress_observation`; each with the same number of rows ``k``).

    The same operations as :func:`lowrank_case` on arrays with a leading case axis: the matrix products,
    eigendecompositions, solves and log-determinants of stacked arrays apply the same routine to each case's
    matrices, so every case's numbers are those of its own :func:`lowrank_case` call, bit for bit (tested); only
    the per-call overhead is shared.  ``observations``: the cases' ``(X, Y)``, needed for the log-likelihood.
    """
    L = np.stack([c[0] for c in compressed])  # (B, k, q)
    zc = np.stack([c[1] for c in compressed])  # (B, k, n_o)
    B, k = L.shape[0], L.shape[1]
    no_q = n_o * q
    mu_o = pr.mean[:no_q].reshape(n_o, q)
    d_o = pr.d[:no_q].reshape(n_o, q)
    Wt_o = pr.W[:, :no_q].T.reshape(n_o, q, -1)  # (n_o, q, n): W_i^T
    Lt = L.transpose(0, 2, 1)[:, None]  # (B, 1, q, k): each case's L.T
    E, V = np.linalg.eigh((L[:, None, :, :] * d_o[None, :, None, :]) @ Lt)  # (B, n_o, k), (B, n_o, k, k)
    E = np.clip(E, 0.0, None)
    Vt = V.transpose(0, 1, 3, 2)
    VL = Vt @ L[:, None]  # (B, n_o, k, q)
    Ut = (VL @ Wt_o).reshape(B, n_o * k, -1)  # (B, n_o k, n)
    r = (zc - L @ mu_o.T).transpose(0, 2, 1)  # (B, n_o, k)
    rt = (Vt @ r[:, :, :, None]).reshape(B, -1)  # (B, n_o k)
    e = E.reshape(B, -1)
    s2 = np.asarray(s2, dtype=np.float64)
    ns = s2.shape[0]
    g = 1.0 / (e[:, None, :] + s2[None, :, None])  # (B, S2, n_o k)
    nW = Ut.shape[2]
    UtT = Ut.transpose(0, 2, 1)  # (B, n, n_o k)
    C = (UtT[:, None, :, :] * g[:, :, None, :]) @ Ut[:, None]  # (B, S2, n, n)
    C[:, :, np.arange(nW), np.arange(nW)] += 1.0
    gr = g * rt[:, None, :]
    sol = np.linalg.solve(C, (gr @ Ut)[:, :, :, None])[:, :, :, 0]  # (B, S2, n)
    at = gr - g * (sol @ UtT)  # (B, S2, n_o k)
    means = ll = None
    if need_mean:
        v = (VL.transpose(0, 1, 3, 2) @ at.reshape(B, ns, n_o, k).transpose(0, 2, 3, 1))  # (B, n_o, q, S2)
        v = v.transpose(0, 3, 1, 2).reshape(B, ns, no_q)
        means = pr.mean[None, None, :] + (at @ Ut) @ pr.W
        means[:, :, :no_q] += v * pr.d[None, None, :no_q]
    if need_ll:
        if observations is None:
            raise ValueError("lowrank_cases needs the observations (X, Y) for the log-likelihood")
        ll = np.empty((B, ns))
        logdet_C = np.linalg.slogdet(C)[1]  # (B, S2)
        for b, (X, Y) in enumerate(observations):
            resid_total = float(np.sum((Y - X @ mu_o.T) ** 2))
            rb = r[b].reshape(-1)
            resid_perp = max(resid_total - float(rb @ rb), 0.0)
            n_obs, dk = Y.size, n_o * k
            logdet = np.sum(np.log(e[b][None, :] + s2[:, None]), axis=1) + logdet_C[b]
            ll[b] = -0.5 * (n_obs * LOG2PI + (n_obs - dk) * np.log(s2) + logdet + resid_perp / s2 + at[b] @ rt[b])
    return means, ll

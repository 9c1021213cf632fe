"""The fast conditioning of the hyper-parameter selection (:func:`interprim.core.gaussian.lowrank_case`: matrix
products, and a compressed observation reused across priors) against Eq. 17-18 as printed, with the ``N x N`` matrix
``A = sigma^2 I + Omega Sigma Omega^T`` built and factorised (by Cholesky: the explicit inverse of
:func:`~interprim.core.gaussian.condition_literal` is less accurate than what it would check).

Error analysis (for the tolerances).  In whitened coordinates the posterior mean's shift is
``delta = Sigma^{1/2} u`` with ``u = (K + sigma^2 I)^-1 Sigma^{1/2} Omega^T r``,
``K = Sigma^{1/2} Omega^T Omega Sigma^{1/2}``, a symmetric positive definite solve of condition number
``kappa = 1 + lambda_max(K) / sigma^2`` (``lambda_max(K) = lambda_max(Omega Sigma Omega^T)``).  Backward-stable
factorisations give ``u`` to a relative ``c N eps kappa`` (``N`` scalar observations, ``eps`` the machine epsilon,
``c`` of order 1), hence ``|d delta| <= c N eps kappa sqrt(lambda_max(Sigma)) |u|``, plus ``eps`` times the mean
itself for the final addition; this holds for either implementation, so twice that for their difference.  The
log-likelihood ``-(N log 2 pi + log det A + r^T A^-1 r) / 2`` of a backward-stable evaluation is that of
``A + dA`` with ``|dA| <= c N eps |A|``: ``log det A`` moves by ``tr(A^-1 dA) <= c N eps |A| tr(A^-1)`` and
``r^T A^-1 r`` by ``x^T dA x <= c N eps |A| |x|^2`` (``x = A^-1 r``); the fast form also splits the residual
``|r|^2`` into its parts in and out of the range of the design through the eigenvectors of ``X^T X`` (each
accurate to ``eps kappa(X^T X)``) and by subtracting two sums of at most ``N`` squares, which costs
``eps (kappa(X^T X) + N) |r|^2 / sigma^2``.  The bounds used are these with ``c = 1``, doubled.  The smallest
noise candidate makes ``kappa ~ 1e5`` (bounds 1e-9 to 2e-7 relative for the mean, 4e-11 to 4e-9 for the
log-likelihood); at the largest (``kappa ~ 1``) they are a few ``eps``.  The differences seen are at most
3e-12 relative, an eighth of the bounds (median a few thousandths of them).
"""

import numpy as np
import pytest

from interprim.core.gaussian import LowRankPrior, compress_observation, lowrank_case, lowrank_cases

EPS = np.finfo(float).eps


def _case(seed, n_o, n_c, q, M, S, method, lam):
    rng = np.random.default_rng(seed)
    P = (n_o + n_c) * q
    th = rng.standard_normal((S, P)) @ rng.standard_normal((P, P)) / np.sqrt(P)
    pr = LowRankPrior(th, method, 1e-3, lam)
    X = rng.standard_normal((M, q))
    Y = rng.standard_normal((M, n_o)) + X @ pr.mean[: n_o * q].reshape(n_o, q).T
    return pr, X, Y


def _reference(mean, cov, Omega, F, sigma2):
    """Eq. 17-18 as printed, ``A = sigma^2 I + Omega Sigma Omega^T`` factorised by Cholesky (backward stable; the
    explicit inverse of :func:`condition_literal` would add ``N eps kappa(A) |r|^2 / sigma^2`` to the quadratic
    term)."""
    from scipy.linalg import cho_factor, cho_solve, solve_triangular

    A = sigma2 * np.eye(Omega.shape[0]) + Omega @ cov @ Omega.T
    cf = cho_factor(A, lower=True)
    r = F - Omega @ mean
    post_mean = mean + cov @ Omega.T @ cho_solve(cf, r)
    w = solve_triangular(cf[0], r, lower=True)
    logdet = 2.0 * float(np.sum(np.log(np.diag(cf[0]))))
    return post_mean, -0.5 * (F.size * np.log(2.0 * np.pi) + logdet + float(w @ w))


def _dense(pr, n_o, q, X):
    P = pr.mean.size
    cov = pr.W.T @ pr.W + np.diag(pr.d)
    M = X.shape[0]
    Omega = np.zeros((M * n_o, P))  # Omega~ = [blockdiag(X, ..., X), 0] (Sec. III-D)
    for i in range(n_o):
        Omega[i * M:(i + 1) * M, i * q:(i + 1) * q] = X
    return cov, Omega


CASES = [  # (seed, n_o, n_c, q, M, S, method, lam)
    (0, 3, 2, 6, 9, 12, "shrinkage", 0.3),
    (1, 2, 1, 5, 20, 8, "shrinkage", 0.02),
    (2, 3, 0, 6, 4, 10, "shrinkage", 0.6),  # M < q: rank-deficient design (the first frames of a movement)
    (3, 2, 2, 4, 7, 30, "ridge", None),  # more demonstrations than observed parameters
    (4, 4, 1, 7, 12, 6, "empirical", None),
    (5, 1, 3, 8, 15, 9, "shrinkage", 0.95),
]


@pytest.mark.parametrize("case", CASES)
def test_lowrank_cases_equal_each_case_bit_for_bit(case):
    # several observations of one prior at once: each case's means and log-likelihoods are those of its own
    # lowrank_case call exactly (the same routines per matrix), for designs of every case's own length
    seed, n_o, n_c, q, M, S, method, lam = case
    pr, _, _ = _case(seed, n_o, n_c, q, M, S, method, lam)
    rng = np.random.default_rng(seed + 100)
    obs = []
    M = max(M, q)  # full-rank designs: one compressed size
    for m in (M, M + 3, M + 3, 2 * M):
        X = rng.standard_normal((m, q))
        obs.append((X, rng.standard_normal((m, n_o)) + X @ pr.mean[: n_o * q].reshape(n_o, q).T))
    comps = [compress_observation(X, Y) for X, Y in obs]
    assert len({c[0].shape[0] for c in comps}) == 1  # one compressed size (lowrank_cases' contract)
    s2 = np.array([1e-4, 1e-2, 1.0, 1e2])
    means, ll = lowrank_cases(pr, n_o, q, comps, s2, need_ll=True, observations=obs)
    assert means.shape == (len(obs), s2.size, pr.mean.size) and ll.shape == (len(obs), s2.size)
    for b, ((X, Y), comp) in enumerate(zip(obs, comps)):
        m1, l1 = lowrank_case(pr, n_o, q, X, Y, s2, need_ll=True, compressed=comp)
        assert np.array_equal(means[b], m1) and np.array_equal(ll[b], l1)
    only_ll = lowrank_cases(pr, n_o, q, comps, s2, need_mean=False, need_ll=True, observations=obs)
    assert only_ll[0] is None and np.array_equal(only_ll[1], ll)
    with pytest.raises(ValueError, match="observations"):
        lowrank_cases(pr, n_o, q, comps, s2, need_ll=True)


@pytest.mark.parametrize("case", CASES)
def test_lowrank_case_equals_literal_eq18(case):
    seed, n_o, n_c, q, M, S, method, lam = case
    pr, X, Y = _case(seed, n_o, n_c, q, M, S, method, lam)
    cov, Omega = _dense(pr, n_o, q, X)
    F = Y.T.reshape(-1)  # [f_1; ...; f_N]
    OSO = Omega @ cov @ Omega.T
    top = float(np.linalg.eigvalsh(OSO)[-1])
    s2 = top * np.array([1e-5, 1e-3, 1e-1, 10.0])  # kappa(A) from ~1e5 down to ~1
    means, ll = lowrank_case(pr, n_o, q, X, Y, s2, need_ll=True)
    assert means.shape == (s2.size, pr.mean.size) and ll.shape == (s2.size,)
    N = F.size
    lmax_S = float(np.linalg.eigvalsh(cov)[-1])
    sv = np.linalg.svd(X, compute_uv=False)
    kappa_G = float(sv[0] / sv[-1]) ** 2  # X^T X on the range of the design (the compressed observation)
    for i, v in enumerate(s2):
        ref_mean, ref_ll = _reference(pr.mean, cov, Omega, F, float(v))
        kappa = 1.0 + top / v
        delta = ref_mean - pr.mean
        u_norm = np.sqrt(float(delta @ np.linalg.solve(cov, delta)))  # |Sigma^-1/2 delta|
        tol_mean = 2.0 * EPS * (N * kappa * np.sqrt(lmax_S) * u_norm + np.abs(ref_mean).max())
        err_mean = np.abs(means[i] - ref_mean).max()
        assert err_mean <= tol_mean, (i, kappa, err_mean, tol_mean)
        r = F - Omega @ pr.mean
        A = v * np.eye(N) + OSO
        Ainv = np.linalg.inv(A)
        x = Ainv @ r
        # first order in a backward error |dA| <= N eps |A|: log det moves by tr(A^-1 dA), r^T A^-1 r by x^T dA x
        tol_ll = 2.0 * EPS * (N * np.linalg.norm(A, 2) * (np.trace(Ainv) + float(x @ x))
                              + (kappa_G + N) * float(r @ r) / v + abs(ref_ll))
        assert abs(ll[i] - ref_ll) <= tol_ll, (i, abs(ll[i] - ref_ll), tol_ll)
    # the bounds are tests, not formalities: at the largest noise (kappa ~ 1) they are a few eps
    assert tol_mean / np.abs(ref_mean).max() < 1e-12 and tol_ll / abs(ref_ll) < 1e-12 and kappa < 2.0


@pytest.mark.parametrize("case", CASES[:3])
def test_lowrank_case_paths_agree(case):
    """The compressed observation passed in (as the selection reuses it for every shrinkage) and the mean-only /
    likelihood-only requests give exactly what one full call gives."""
    seed, n_o, n_c, q, M, S, method, lam = case
    pr, X, Y = _case(seed, n_o, n_c, q, M, S, method, lam)
    s2 = np.array([1e-3, 0.5, 40.0])
    means, ll = lowrank_case(pr, n_o, q, X, Y, s2, need_ll=True)
    comp = compress_observation(X, Y)
    m2, l2 = lowrank_case(pr, n_o, q, X, Y, s2, need_ll=True, compressed=comp)
    np.testing.assert_array_equal(m2, means)
    np.testing.assert_array_equal(l2, ll)
    m3, l3 = lowrank_case(pr, n_o, q, X, Y, s2)
    assert l3 is None
    np.testing.assert_array_equal(m3, means)
    m4, l4 = lowrank_case(pr, n_o, q, X, Y, s2, need_mean=False, need_ll=True)
    assert m4 is None
    np.testing.assert_array_equal(l4, ll)
    # one candidate at a time gives the same numbers as the whole grid (to rounding: batched products)
    for i, v in enumerate(s2):
        mi, li = lowrank_case(pr, n_o, q, X, Y, np.array([v]), need_ll=True)
        np.testing.assert_allclose(mi[0], means[i], rtol=1e-12, atol=1e-12 * np.abs(means).max())
        assert li[0] == pytest.approx(ll[i], rel=1e-12)


@pytest.mark.parametrize("n_o, n_lat", [(2, 5), (3, 3)])  # with and without a controlled agent
def test_cv_scores_equal_direct_form(n_o, n_lat):
    """The selection's held-out errors (several cases at once, the cross-agent factor expanded in (1 - gamma))
    against the direct form per case and per gamma, evaluated in extended precision.

    Every float64 operation of either form sums or multiplies terms bounded by the same expression with absolute
    values, ``m = sum_d w_d mean_t (|base| + |H| |theta| + |truth|)^2 / D`` (``mean_t (rc + (1 - gamma) dc)^2`` and its
    expansion alike), along chains of at most ``n_out + q + 10`` operations, so the error is below
    ``(n_out + q + 10) eps m`` (the classical running bound); doubled for a reference that is only float64 where
    ``longdouble`` is.
    """
    from interprim.models.primitive.selection import _score

    rng = np.random.default_rng(7)
    B, ns, n_out, q = 3, 4, 7, 4
    gam = np.array([0.0, 0.25, 0.9, 1.0] if n_lat > n_o else [0.0])
    w_d = rng.uniform(0.5, 2.0, n_lat)
    H = rng.standard_normal((n_out, q))
    mean = rng.standard_normal(n_lat * q)
    Th = mean + 0.1 * rng.standard_normal((B, ns, n_lat * q))
    base = rng.standard_normal((B, n_out, n_lat))
    truth = base + H @ mean.reshape(n_lat, q).T + 0.05 * rng.standard_normal((B, n_out, n_lat))
    pm_shift = H @ mean.reshape(n_lat, q).T
    e_o, e_c, p_o, p_c = _score(Th, base, truth, pm_shift, H, n_o, q, w_d, gam)
    assert e_o.shape == (B, ns) and e_c.shape == (B, ns, gam.size) and p_o.shape == p_c.shape == (B,)
    e_all, e_prior = (e_o[:, :, None] + e_c) / n_lat, (p_o + p_c) / n_lat  # both agents' sums, per DoF
    ld = np.longdouble
    Hl, wl = H.astype(ld), w_d.astype(ld)
    mag = np.abs(base)[:, None] + np.einsum("tq,bsdq->bstd", np.abs(H), np.abs(Th).reshape(B, ns, n_lat, q)) \
        + np.abs(truth)[:, None]
    m = np.sum(np.mean(mag ** 2, axis=2) * w_d, axis=2) / n_lat  # (B, S2)
    tol = 2.0 * (n_out + q + 10) * EPS * m
    for b in range(B):
        pm = base[b].astype(ld) + Hl @ mean.reshape(n_lat, q).T.astype(ld)
        ref_prior = np.mean((pm - truth[b]) ** 2 * wl)
        assert abs(e_prior[b] - float(ref_prior)) <= 2.0 * (n_out + q + 10) * EPS * float(np.max(m[b]))
        for s in range(ns):
            pred = base[b].astype(ld) + Hl @ Th[b, s].reshape(n_lat, q).T.astype(ld)
            e_o = np.sum(np.mean((pred[:, :n_o] - truth[b, :, :n_o]) ** 2, axis=0) * wl[:n_o])
            for c, g in enumerate(gam):
                mixed = pm[:, n_o:] + (1 - ld(g)) * (pred[:, n_o:] - pm[:, n_o:])
                e_c = np.sum(np.mean((mixed - truth[b, :, n_o:]) ** 2, axis=0) * wl[n_o:])
                ref = float((e_o + e_c) / n_lat)
                assert abs(e_all[b, s, c] - ref) <= tol[b, s], (b, s, c, e_all[b, s, c] - ref, tol[b, s])


@pytest.mark.parametrize("seed, n_o, n_c, q, M, S, gamma", [(0, 3, 2, 6, 9, 12, 0.0), (1, 2, 2, 5, 3, 8, 0.5),
                                                              (2, 4, 1, 4, 20, 30, 0.9)])
def test_lowrank_conditioner_cov_equals_dense(seed, n_o, n_c, q, M, S, gamma):
    """The posterior covariance of :class:`LowRankConditioner` (as the calibration uses it, cross-agent block
    shrunk) against ``Sigma - Sigma Omega^T A^-1 Omega Sigma`` with ``A`` built and factorised by Cholesky.

    Both are a backward-stable evaluation of ``sigma^2 Sigma^{1/2} (K + sigma^2 I)^-1 Sigma^{1/2}`` (notation of
    the module docstring), whose relative sensitivity is ``kappa``; each entry is then off by at most
    ``c (N + P) eps kappa lambda_max(Sigma)`` (``c = 1``, doubled for the two sides).
    """
    from scipy.linalg import cho_factor, cho_solve

    from interprim.core.gaussian import LowRankConditioner, fit_prior, shrink_cross

    rng = np.random.default_rng(seed)
    P = (n_o + n_c) * q
    th = rng.standard_normal((S, P)) @ rng.standard_normal((P, P)) / np.sqrt(P)
    prior = shrink_cross(fit_prior(th, "shrinkage", 1e-3), gamma, n_o * q)
    idx = np.arange(n_o * q).reshape(n_o, q)
    cond = LowRankConditioner(prior.mean, prior.diag, prior.factor, idx)
    X = rng.standard_normal((M, q))
    cov = prior.factor @ prior.factor.T + np.diag(prior.diag)
    Omega = np.zeros((M * n_o, P))
    for i in range(n_o):
        Omega[i * M:(i + 1) * M, i * q:(i + 1) * q] = X
    OSO = Omega @ cov @ Omega.T
    top = float(np.linalg.eigvalsh(OSO)[-1])
    lmax = float(np.linalg.eigvalsh(cov)[-1])
    for s2 in top * np.array([1e-4, 1e-2, 1.0]):
        A = s2 * np.eye(M * n_o) + OSO
        OS = Omega @ cov
        ref = cov - OS.T @ cho_solve(cho_factor(A, lower=True), OS)
        got = cond.cov(X.T @ X, float(s2))
        tol = 2.0 * (M * n_o + P) * EPS * (1.0 + top / s2) * lmax
        assert np.abs(got - ref).max() <= tol, (s2, np.abs(got - ref).max(), tol)


def test_learned_phase_loo_regressions_equal_explicit_refits():
    """The learned phase's closed-form leave-one-out predictions (batched matrix products) against refitting
    without each demonstration, at every time.

    Ridge: both sides solve with ``Zc^T Zc + alpha I`` (or its SVD), condition ``kappa = 1 + sigma_max^2 / alpha``,
    so they agree to ``c (n + p) eps kappa`` times the spread of the targets (``c = 1``, doubled); the centring
    with and without the left-out row is exact arithmetic on the same numbers up to ``n eps``.  Kernel
    (Nadaraya-Watson): the squared distances are formed as ``|z_i|^2 + |z_j|^2 - 2 z_i.z_j`` (fast) or
    ``|z_i - z_j|^2`` (reference), which differ by ``4 p eps max|z|^2 / p``; a weight ``exp(-d / 2h^2)`` then moves
    by that over ``2 h^2`` relative, and a weighted mean by twice that times the spread of the targets.
    """
    from interprim.phase._learned_features import kernel_loo, ridge_loo

    rng = np.random.default_rng(3)
    K, n, p = 4, 9, 3
    Z = rng.standard_normal((K, n, p))
    s = rng.uniform(0.0, 1.0, (K, n))
    alphas = np.array([0.1, 3.0, 1e3])
    got = ridge_loo(Z, s, alphas)
    spread = float(np.ptp(s))
    for a, lam in enumerate(alphas):
        for k in range(K):
            for i in range(n):
                keep = np.arange(n) != i
                Zk, sk = Z[k, keep], s[k, keep]
                zm, sm = Zk.mean(axis=0), sk.mean()
                Zc = Zk - zm
                beta = np.linalg.solve(Zc.T @ Zc + lam * np.eye(p), Zc.T @ (sk - sm))
                ref = sm + (Z[k, i] - zm) @ beta
                smax = np.linalg.svd(Zc, compute_uv=False)[0]
                tol = 2.0 * (n + p) * EPS * (1.0 + smax ** 2 / lam) * (spread + abs(ref))
                assert abs(got[a, k, i] - ref) <= tol, (a, k, i, got[a, k, i] - ref, tol)
    bws = np.array([0.3, 1.0, 5.0])
    got = kernel_loo(Z, s, bws)
    zmax2 = float(np.max(np.sum(Z * Z, axis=2)))
    for b, h in enumerate(bws):
        for k in range(K):
            D2 = np.sum((Z[k][:, None, :] - Z[k][None, :, :]) ** 2, axis=2) / p
            for i in range(n):
                keep = np.arange(n) != i
                d = D2[i, keep]
                w = np.exp(-(d - d.min()) / (2.0 * h * h))
                ref = float(w @ s[k, keep] / w.sum())
                tol = 2.0 * (4.0 * EPS * zmax2 / (2.0 * h * h)) * spread + 4.0 * n * EPS
                assert abs(got[b, k, i] - ref) <= tol, (b, k, i, got[b, k, i] - ref, tol)


def test_fading_design_under_a_wide_prior_is_not_truncated():
    """Early in a movement the design's last columns are nearly zero (basis functions not yet reached: here 1e-6 of
    the others) while the prior's variance of their weights is 1e10 times the others' (weights in forcing units):
    those columns still move the observation by about the noise.  A compression that dropped the directions of
    ``X^T X`` below 1e-10 of its largest eigenvalue missed them (the likelihood phase's cases: 0.3-82 in
    log-likelihood).  Here the reference's ``A`` stays well conditioned (``kappa`` about 1e4)."""
    rng = np.random.default_rng(11)
    n_o, n_c, q, M, S = 2, 1, 8, 30, 40
    U = np.linalg.qr(rng.standard_normal((M, q)))[0]
    sv = np.array([1.0, 0.8, 0.6, 0.5, 0.4, 1e-6, 1e-6, 1e-6])
    X = U * sv  # the last three columns fade
    scale = np.tile(np.where(sv < 1e-3, 1e5, 1.0), n_o + n_c)
    P = (n_o + n_c) * q
    pr = LowRankPrior(rng.standard_normal((S, P)) * scale, "shrinkage", 1e-3, 0.3)
    theta = pr.mean + pr.W.T @ rng.standard_normal(pr.W.shape[0])
    Y = X @ theta[: n_o * q].reshape(n_o, q).T + 0.1 * rng.standard_normal((M, n_o))
    cov, Omega = _dense(pr, n_o, q, X)
    s2 = np.array([1e-2, 1.0])
    means, ll = lowrank_case(pr, n_o, q, X, Y, s2, need_ll=True)
    for i, v in enumerate(s2):
        ref_mean, ref_ll = _reference(pr.mean, cov, Omega, Y.T.reshape(-1), float(v))
        # 2.2e-9 relative apart on an AVX-512 machine (the dense reference's sums ordered by another BLAS kernel),
        # within 1e-9 on the machines CI has run on: 1e-8 is still 1e-7 of the smallest error the truncation made (0.3)
        assert ll[i] == pytest.approx(ref_ll, rel=1e-8, abs=1e-9)
        np.testing.assert_allclose(means[i], ref_mean, rtol=1e-7, atol=1e-7 * np.abs(ref_mean).max())

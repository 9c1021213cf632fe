"""Distribution over theta (Eq. 10) and conditioning (Eq. 16-18, Sec. III-D)."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from interprim.core.gaussian import condition, condition_literal, fit_prior, sample, shrinkage_intensity


def _problem(seed, q, D_o, D_c, T, S):
    rng = np.random.default_rng(seed)
    P = q * (D_o + D_c)
    prior = fit_prior(rng.normal(size=(S, P)) @ rng.normal(size=(P, P)) * 0.3)
    X = rng.normal(size=(T, q))
    F = rng.normal(size=(T, D_o))
    Omega = np.zeros((T * D_o, P))  # Omega~ = [Omega, 0] (Sec. III-D)
    for i in range(D_o):
        Omega[i * T:(i + 1) * T, i * q:(i + 1) * q] = X
    return prior, X, F, Omega


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 10**6), st.integers(2, 6), st.integers(1, 3), st.integers(0, 2), st.integers(1, 12),
       st.integers(2, 9), st.floats(1e-3, 10.0))
def test_structured_equals_literal_eq18(seed, q, D_o, D_c, T, S, sigma2):
    prior, X, F, Omega = _problem(seed, q, D_o, D_c, T, S)
    idx = np.arange(D_o * q).reshape(D_o, q)
    a = condition(prior.mean, prior.cov, idx, X.T @ X, X.T @ F, sigma2, yy=float(np.sum(F**2)), n_obs=F.size)
    b = condition_literal(prior.mean, prior.cov, Omega, F.T.reshape(-1), sigma2)
    scale = np.abs(prior.cov).max()
    np.testing.assert_allclose(a.mean, b.mean, atol=1e-7 * (1 + np.abs(b.mean).max()))
    np.testing.assert_allclose(a.cov, b.cov, atol=1e-7 * scale)
    assert a.log_likelihood == pytest.approx(b.log_likelihood, rel=1e-7, abs=1e-6)
    # mean-only path gives the same mean
    c = condition(prior.mean, prior.cov, idx, X.T @ X, X.T @ F, sigma2, need_cov=False)
    np.testing.assert_allclose(c.mean, a.mean, rtol=1e-12, atol=1e-12)
    assert c.cov is None


def test_infinite_noise_returns_prior():
    prior, X, F, _ = _problem(1, 4, 2, 1, 10, 6)
    idx = np.arange(8).reshape(2, 4)
    post = condition(prior.mean, prior.cov, idx, X.T @ X, X.T @ F, 1e14)
    np.testing.assert_allclose(post.mean, prior.mean, atol=1e-9)
    np.testing.assert_allclose(post.cov, prior.cov, atol=1e-9 * np.abs(prior.cov).max())


def test_exact_full_observation_recovers_theta():
    """theta drawn from the prior, observed exactly through a full-rank design: posterior mean = theta."""
    rng = np.random.default_rng(3)
    q, D = 5, 3
    prior = fit_prior(rng.normal(size=(12, q * D)))
    theta = sample(prior.mean, prior.cov, 1, random_state=4)[0]
    X = rng.normal(size=(30, q))
    F = X @ theta.reshape(D, q).T
    post = condition(prior.mean, prior.cov, np.arange(q * D).reshape(D, q), X.T @ X, X.T @ F, 1e-10)
    np.testing.assert_allclose(post.mean, theta, atol=1e-6)
    assert np.abs(post.cov).max() < 1e-6


def test_conditioning_on_observed_dofs_moves_controlled_dofs():
    """Sec. III-D: with correlated agents, observing one agent informs the other."""
    rng = np.random.default_rng(0)
    z = rng.normal(size=(40, 1))
    thetas = np.hstack([z, 2 * z]) + 0.01 * rng.normal(size=(40, 2))  # q = 1, observed DoF 0, controlled DoF 1
    prior = fit_prior(thetas, method="empirical")
    post = condition(prior.mean, prior.cov, np.array([[0]]), np.array([[1.0]]), np.array([[1.5]]), 1e-8)
    assert post.mean[1] == pytest.approx(2 * 1.5, abs=0.05)
    assert post.cov[1, 1] < 0.01 * prior.cov[1, 1]


def test_prior_regularisation():
    rng = np.random.default_rng(0)
    X = rng.normal(size=(10, 40))  # fewer demos than parameters
    emp = fit_prior(X, "empirical", ridge=0.0)
    Xc = X - X.mean(0)
    np.testing.assert_allclose(emp.cov, Xc.T @ Xc / 10, atol=1e-9)  # Eq. 10 (divisor S)
    assert np.linalg.matrix_rank(emp.cov, tol=1e-8 * np.abs(emp.cov).max()) <= 9  # singular: S - 1 = 9 < P = 40
    shr = fit_prior(X, "shrinkage")
    assert 0.0 < shr.shrinkage <= 1.0
    assert np.linalg.eigvalsh(shr.cov).min() > 0  # positive definite although S < P
    np.testing.assert_allclose(np.diag(shr.cov), np.diag(Xc.T @ Xc / 10), rtol=1e-3)  # variances kept
    # strongly correlated data -> little shrinkage; independent noise -> a lot
    z = rng.normal(size=(200, 1))
    corr = np.hstack([z, z + 0.01 * rng.normal(size=(200, 1))] * 3)
    assert shrinkage_intensity(corr) < 0.05
    assert shrinkage_intensity(rng.normal(size=(15, 30))) > 0.5
    with pytest.raises(ValueError, match="covariance method"):
        fit_prior(X, "nope")


def test_sample_is_reproducible_and_has_right_moments():
    rng = np.random.default_rng(0)
    A = rng.normal(size=(3, 3))
    cov = A @ A.T
    s1 = sample(np.ones(3), cov, 20000, random_state=7)
    s2 = sample(np.ones(3), cov, 20000, random_state=7)
    np.testing.assert_array_equal(s1, s2)
    np.testing.assert_allclose(np.cov(s1.T), cov, atol=0.1 * np.abs(cov).max())


def test_sample_is_continuous_in_cov_and_handles_singular_cov():
    """Covariances equal to rounding give samples equal to rounding (the compiled and the numpy conditioning
    differ by ~1e-12 relative; eigenvector-based sampling turned that into 20-40 % differences when two
    eigenvalues were nearly equal), and a rank-deficient covariance still samples, within its range."""
    rng = np.random.default_rng(1)
    U = rng.normal(size=(12, 3))
    cov = np.eye(12) * 0.5 + U @ U.T
    cov[:, :] = 0.5 * (cov + cov.T)
    cov2 = cov.copy()
    cov2[0, 0] += 1e-12  # two exactly equal eigenvalues (0.5, nine times) split by rounding-size noise
    s1 = sample(np.zeros(12), cov, 50, random_state=3)
    s2 = sample(np.zeros(12), cov2, 50, random_state=3)
    assert np.abs(s1 - s2).max() <= 1e-10 * np.abs(s1).max()
    singular = U @ U.T  # rank 3
    s = sample(np.ones(12), singular, 4000, random_state=0)
    resid = (s - 1.0) - (s - 1.0) @ U @ np.linalg.pinv(U)  # the part outside range(U)
    assert np.abs(resid).max() < 1e-5 * np.abs(s - 1.0).max()
    np.testing.assert_allclose(np.cov(s.T), singular, atol=0.15 * np.abs(singular).max())


@pytest.mark.parametrize("method", ["shrinkage", "ridge", "empirical"])
@pytest.mark.parametrize("S", [5, 40])  # fewer and more demonstrations than parameters
def test_one_prior_type_every_form_equals_literal_eq18(method, S):
    """``GaussianPrior`` is the one prior: its factored form (``factored``, what cross-validation uses) has the
    covariance of ``fit_prior``; its conditioner, its dense ``condition``, ``posterior_means`` and ``evidence``
    (one or many sigma^2 at once, factored or dense) all equal Eq. 17-18 as printed (``condition_literal``)."""
    from interprim.core.gaussian import GaussianPrior, LowRankPrior

    rng = np.random.default_rng(S)
    q, D_o, D_c, T = 4, 2, 2, 9
    P = q * (D_o + D_c)
    thetas = rng.normal(size=(S, P)) @ rng.normal(size=(P, P)) * 0.3
    dense = fit_prior(thetas, method, 1e-3)
    lam = dense.shrinkage
    fact = GaussianPrior.factored(thetas, method, 1e-3, lam)
    assert type(fact) is type(dense) is type(LowRankPrior(thetas, method, 1e-3, lam))  # one type; the old name
    assert "cov" not in vars(fact)  # the dense covariance is built only when asked for
    np.testing.assert_allclose(fact.cov, dense.cov, rtol=1e-10, atol=1e-12 * np.abs(dense.cov).max())
    X = rng.normal(size=(T, q))
    F = rng.normal(size=(T, D_o))
    Omega = np.zeros((T * D_o, P))
    for i in range(D_o):
        Omega[i * T:(i + 1) * T, i * q:(i + 1) * q] = X
    idx = np.arange(D_o * q).reshape(D_o, q)
    s2 = np.array([0.05, 0.7, 3.0])
    lit = [condition_literal(dense.mean, dense.cov, Omega, F.T.reshape(-1), v) for v in s2]
    tol = dict(rtol=1e-8, atol=1e-9)
    np.testing.assert_allclose(fact.evidence(D_o, q, X, F, s2), [p.log_likelihood for p in lit], **tol)
    np.testing.assert_allclose(dense.evidence(D_o, q, X, F, s2), [p.log_likelihood for p in lit], **tol)
    np.testing.assert_allclose(fact.posterior_means(D_o, q, X, F, s2), [p.mean for p in lit], **tol)
    assert isinstance(fact.evidence(D_o, q, X, F, 0.7), float)
    assert fact.evidence(D_o, q, X, F, 0.7) == pytest.approx(lit[1].log_likelihood, rel=1e-8)
    G, B, yy, n = X.T @ X, X.T @ F, float(np.sum(F * F)), F.size
    post = dense.condition(idx, G, B, 0.7, yy=yy, n_obs=n)
    np.testing.assert_allclose(post.mean, lit[1].mean, **tol)
    np.testing.assert_allclose(post.cov, lit[1].cov, rtol=1e-8, atol=1e-9 * np.abs(dense.cov).max())
    cond = dense.conditioner(idx)
    mean, ll = cond.mean_and_evidence(G, B, 0.7, yy, n)  # compiled or numpy, chosen inside
    np.testing.assert_allclose(mean, lit[1].mean, **tol)
    assert ll == pytest.approx(lit[1].log_likelihood, rel=1e-8)
    ref = cond.mean_numpy(G, B, 0.7, yy, n)
    np.testing.assert_allclose(mean, ref[0], rtol=1e-12, atol=1e-12)
    # the observed block: the marginal of the first D_o q parameters, in the forms the prior has
    m = fact.marginal(D_o * q)
    np.testing.assert_allclose(m.cov, dense.cov[:D_o * q, :D_o * q], rtol=1e-10, atol=1e-12 * np.abs(dense.cov).max())
    np.testing.assert_array_equal(m.mean, dense.mean[:D_o * q])

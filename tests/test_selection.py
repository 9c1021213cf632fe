"""Choosing sigma2 and the covariance shrinkage from the data (interprim.selection)."""

import numpy as np
import pytest

import interprim as ip
from interprim.preprocessing import time_normalise
from interprim.synthetic import two_agent_demos


def _ctrl_mse(model, demos, frac=0.6):
    e = []
    for d in demos:
        T = d.shape[0]
        M = int(frac * T)
        Y = model.predict(d[:M, :2]).trajectory(50)
        e.append(np.mean((Y[:, 2:] - time_normalise(d, 50)[:, 2:]) ** 2))
    return float(np.mean(e))


@pytest.fixture(scope="module")
def small():
    return two_agent_demos(16, seed=0, frames=100)


@pytest.mark.parametrize("observation,phase_method",
                         [("forcing", "likelihood"), ("position", "likelihood"), ("position", "dtw")])
def test_cv_reports_its_choice_and_beats_the_prior_in_cv(small, observation, phase_method):
    train = small
    m = ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=12, observation=observation, sigma2="cv",
                                phase_method=phase_method).fit(train, dt=0.01)
    sel = m.selection_
    for key in ("sigma2", "shrinkage", "phase_sigma2", "cv_error", "cv_error_prior", "sigma2_grid"):
        assert key in sel
    assert m.sigma2_ == pytest.approx(sel["sigma2"])
    assert any(np.isclose(m.sigma2_, g) for g in sel["sigma2_grid"])
    assert m.prior_.shrinkage in sel["shrinkage_grid"]
    assert sel["cv_error"] < 0.5 * sel["cv_error_prior"]  # correlated agents: conditioning helps a lot


def test_cv_scores_the_dtw_phase_errors(small):
    """With the paper's DTW phase the held-out cases are conditioned at the DTW estimate, not the true phase:
    on demos that differ in goal, DTW's phase errors make forcing-value conditioning useless here, and the
    selection falls back to the prior (largest cross-agent shrinkage) instead of trusting a tiny sigma2."""
    m = ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=12, observation="forcing", sigma2="cv",
                                phase_method="dtw").fit(small, dt=0.01)
    sel = m.selection_
    assert sel["cv_error"] <= sel["cv_error_prior"] + 1e-12
    assert sel["cross_shrinkage"] == 1.0
    m_lik = ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=12, observation="forcing", sigma2="cv",
                                    phase_method="likelihood").fit(small, dt=0.01)
    assert m_lik.selection_["cross_shrinkage"] < 0.5 and m_lik.sigma2_ < 1e-3 * m.sigma2_


def test_cv_falls_back_towards_the_prior_when_agents_are_independent():
    rng = np.random.default_rng(3)
    demos = []
    for d in two_agent_demos(20, seed=7, frames=100):
        # controlled agent unrelated to the observed one: its own random amplitude
        s = np.linspace(0, 1, d.shape[0])
        a = rng.uniform(0.5, 1.5, 3)
        d = d.copy()
        d[:, 2:] = np.outer(10 * s**3 - 15 * s**4 + 6 * s**5, a)
        demos.append(d)
    train, test = demos[:14], demos[14:]
    m = ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=12, sigma2="cv").fit(train, dt=0.01)
    prior = np.mean([time_normalise(d, 50) for d in train], axis=0)
    e_prior = float(np.mean([np.mean((prior[:, 2:] - time_normalise(d, 50)[:, 2:]) ** 2) for d in test]))
    # never much worse than replaying the mean demonstration
    assert _ctrl_mse(m, test) < 1.25 * e_prior
    assert m.selection_["cv_error"] <= m.selection_["cv_error_prior"] + 1e-12
    # the cross-agent covariance is shrunk (gamma = 1: the controlled agent keeps its prior mean)
    assert m.selection_["cross_shrinkage"] >= 0.5
    po = 2 * m._q
    if m.selection_["cross_shrinkage"] == 1.0:
        assert np.all(m.prior_.cov[:po, po:] == 0.0)
    factor = getattr(m.prior_, "factor", None)
    if factor is not None:  # the diagonal + low-rank form stays exact
        rec = factor @ factor.T
        rec[np.diag_indices_from(rec)] += m.prior_.diag
        np.testing.assert_allclose(rec, m.prior_.cov, atol=1e-10 * np.abs(m.prior_.cov).max())


def test_lowrank_cv_equals_dense_conditioning():
    from interprim.gaussian import condition, fit_prior
    from interprim.gaussian import LowRankPrior, lowrank_case

    rng = np.random.default_rng(0)
    n_o, q, n_c = 3, 6, 2
    P = (n_o + n_c) * q
    th = rng.standard_normal((12, P)) @ rng.standard_normal((P, P))
    X = rng.standard_normal((9, q))
    Y = rng.standard_normal((9, n_o))
    idx = np.arange(n_o * q).reshape(n_o, q)
    for method, lam in (("shrinkage", 0.3), ("ridge", None), ("empirical", None)):
        pr = LowRankPrior(th, method, 1e-3, lam)
        fp = fit_prior(th, method, 1e-3, shrinkage=lam)
        means, ll = lowrank_case(pr, n_o, q, X, Y, np.array([0.1, 2.0]), need_ll=True)
        for i, s2 in enumerate((0.1, 2.0)):
            post = condition(fp.mean, fp.cov, idx, X.T @ X, X.T @ Y, s2, yy=float(np.sum(Y * Y)), n_obs=Y.size)
            np.testing.assert_allclose(means[i], post.mean, rtol=1e-8, atol=1e-8)
            assert ll[i] == pytest.approx(post.log_likelihood, rel=1e-9)


def test_cv_with_fixed_covariance_method_only_selects_sigma2(small):
    train = small
    m = ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=10, sigma2="cv", covariance="ridge").fit(
        train, dt=0.01)
    assert m.selection_["shrinkage_grid"] == [None]
    assert m.prior_.method == "ridge"


def test_bad_sigma2_string_rejected(small):
    train = small
    with pytest.raises((ValueError, TypeError), match="sigma2"):
        ip.InteractionPrimitive(observed_dofs=[0, 1], sigma2="loo").fit(train, dt=0.01)

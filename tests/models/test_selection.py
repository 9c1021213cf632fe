"""Choosing sigma2 and the covariance shrinkage from the data (interprim.models.primitive.selection)."""

import numpy as np
import pytest

import interprim as ip
from interprim.core.preprocessing import time_normalise
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


@pytest.mark.slow  # a full CV
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
    po = 2 * m.params_per_dof_
    if m.selection_["cross_shrinkage"] == 1.0:
        assert np.all(m.prior_.cov[:po, po:] == 0.0)
        # the robot keeps its mean whatever the noise: the observed agent's completion chose sigma2 and the shrinkage
        eo = np.asarray(m.selection_["cv_errors_observed"])
        assert m.selection_["cv_error_observed"] == eo[np.asarray(m.selection_["cv_observed_within_se"])].min()
    factor = getattr(m.prior_, "factor", None)
    if factor is not None:  # the diagonal + low-rank form stays exact
        rec = factor @ factor.T
        rec[np.diag_indices_from(rec)] += m.prior_.diag
        np.testing.assert_allclose(rec, m.prior_.cov, atol=1e-10 * np.abs(m.prior_.cov).max())


def test_lowrank_cv_equals_dense_conditioning():
    from interprim.core.gaussian import LowRankPrior, condition, fit_prior, lowrank_case

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


def test_cv_keeps_the_observed_agent_within_its_noise_then_scores_the_controlled_agent(small):
    """(lambda, sigma2) are first limited to those within one standard error of the observed agent's best held-out
    completion; among them the controlled agent's held-out error decides (and gamma by the one-SE rule)."""
    m = ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=12).fit(small, dt=0.01)
    sel = m.selection_
    assert sel["cv_target"] == "controlled agent"
    errs, errs_o = np.asarray(sel["cv_errors"]), np.asarray(sel["cv_errors_observed"])  # (lambda, sigma2)
    human_ok, within = np.asarray(sel["cv_observed_within_se"]), np.asarray(sel["cv_within_se"])
    a = sel["shrinkage_grid"].index(m.prior_.shrinkage)
    b = int(np.argmin(np.abs(np.asarray(sel["sigma2_grid"]) - m.sigma2_)))
    assert human_ok[np.unravel_index(np.argmin(errs_o), errs_o.shape)]  # the observed agent's best is always in
    assert not human_ok.all()  # a real restriction: far too small or large noises spoil the completion
    assert within[a, b] and human_ok[a, b] and not np.any(within & ~human_ok)
    assert sel["cv_error"] == errs[a, b] == pytest.approx(errs[within].min(), rel=1e-12)
    assert sel["cv_error_observed"] == errs_o[a, b]
    assert sel["cv_error"] < 0.5 * sel["cv_error_prior"]  # correlated agents: conditioning helps the robot a lot
    assert sel["cv_error_observed"] < 0.5 * sel["cv_error_observed_prior"]


def test_best_candidate_ties_broken_by_the_observed_agent():
    from interprim.models.primitive.selection import _best_at

    err_c = np.array([[1.0, 1.0], [1.0, 2.0]])
    err_o = np.array([[5.0, 3.0], [1.0, 0.0]])  # (1, 1) has the best observed error but not the best controlled
    assert tuple(int(i) for i in _best_at(err_c, err_o)) == (1, 0)
    err_c[1, 0] += 1e-6  # no longer tied: the controlled agent decides alone
    assert tuple(int(i) for i in _best_at(err_c, err_o)) == (0, 1)
    err_c[0, 1] = np.inf  # excluded candidates never win
    assert tuple(int(i) for i in _best_at(err_c, err_o)) == (0, 0)


def test_selection_criteria_per_agent():
    """``_criteria`` averages each agent's summed errors over its own DoFs; without a controlled agent the
    criterion is the observed agent's error."""
    from interprim.models.primitive.selection import _criteria

    rng = np.random.default_rng(1)
    n_lam, S2, G, n_cases = 2, 3, 4, 5
    per_case = {i: [(rng.random(S2), rng.random((S2, G)), rng.random(), rng.random()) for _ in range(n_cases)]
                for i in range(n_lam)}
    E, Eo, p_c, p_o = _criteria(per_case, n_lam, n_o=3, n_lat=5)
    assert E.shape == (n_cases, n_lam, S2, G) and Eo.shape == (n_cases, n_lam, S2)
    assert E[2, 1, 0, 3] == per_case[1][2][1][0, 3] / 2 and Eo[4, 0, 2] == per_case[0][4][0][2] / 3
    assert p_c == pytest.approx(np.mean([c[3] for c in per_case[0]]) / 2)
    assert p_o == pytest.approx(np.mean([c[2] for c in per_case[0]]) / 3)
    E1, Eo1, p1, po1 = _criteria(per_case, n_lam, n_o=5, n_lat=5)
    assert E1.shape == (n_cases, n_lam, S2, 1) and np.array_equal(E1[..., 0], Eo1) and p1 == po1


def test_a_fit_whose_records_nobody_reads_leaves_out_only_the_log_likelihood_record(small, monkeypatch):
    """Inside interprim.core.cache.records_unused (the default's inner cross-validation, which scores its fits'
    means and discards them) the selection skips the held-out marginal log-likelihood, a record when the phase noise
    is chosen by phase accuracy (the default): that record is None and says so; every other record, the choices
    and the predictions (mean, std, phase) are the plain fit's, bit for bit."""
    from interprim.core.cache import records_skipped, records_unused
    from interprim.model_selection import stacking

    plain = ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=12).fit(small, dt=0.01)
    with records_unused():
        assert records_skipped()
        quiet = ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=12).fit(small, dt=0.01)
    assert not records_skipped()
    a, b = plain.selection_, quiet.selection_
    assert b["phase_log_likelihood"] is None and len(a["phase_log_likelihood"]) == len(a["phase_sigma2_grid"])
    assert {k: v for k, v in a.items() if k != "phase_log_likelihood"} == \
        {k: v for k, v in b.items() if k != "phase_log_likelihood"}
    x = two_agent_demos(1, seed=9, frames=100)[0][:55, :2]
    p, q = plain.predict(x), quiet.predict(x)
    np.testing.assert_array_equal(p.trajectory(40), q.trajectory(40))
    np.testing.assert_array_equal(p.std(40), q.std(40))
    assert p.phase == q.phase
    # the default's inner cross-validation runs inside records_unused; its final models outside
    seen = []
    real = stacking.CrossValidation

    def spy(*args, **kwargs):
        seen.append(records_skipped())
        return real(*args, **kwargs)

    monkeypatch.setattr(stacking, "CrossValidation", spy)
    auto = ip.AutoInteraction([0, 1], candidates=("ip", "prior"), n_basis=12).fit(small[:10], dt=0.01)
    assert seen == [True] and not records_skipped()
    member = auto.model_.members_["ip"] if hasattr(auto.model_, "members_") else auto.model_
    assert member.selection_["phase_log_likelihood"] is not None

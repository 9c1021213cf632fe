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


@pytest.mark.parametrize("observation", ["forcing", "position"])
def test_cv_reports_its_choice_and_beats_the_prior_in_cv(synthetic, observation):
    train, _ = synthetic
    m = ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=12, observation=observation, sigma2="cv").fit(
        train, dt=0.01)
    sel = m.selection_
    for key in ("sigma2", "shrinkage", "phase_sigma2", "cv_error", "cv_error_prior", "sigma2_grid"):
        assert key in sel
    assert m.sigma2_ == pytest.approx(sel["sigma2"])
    assert any(np.isclose(m.sigma2_, g) for g in sel["sigma2_grid"])
    assert m.prior_.shrinkage in sel["shrinkage_grid"]
    assert sel["cv_error"] < 0.5 * sel["cv_error_prior"]  # correlated agents: conditioning helps a lot


def test_cv_falls_back_towards_the_prior_when_agents_are_independent():
    rng = np.random.default_rng(3)
    demos = []
    for d in two_agent_demos(24, seed=7, frames=120):
        # controlled agent unrelated to the observed one: its own random amplitude
        s = np.linspace(0, 1, d.shape[0])
        a = rng.uniform(0.5, 1.5, 3)
        d = d.copy()
        d[:, 2:] = np.outer(10 * s**3 - 15 * s**4 + 6 * s**5, a)
        demos.append(d)
    train, test = demos[:18], demos[18:]
    m = ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=12, sigma2="cv").fit(train, dt=0.01)
    prior = np.mean([time_normalise(d, 50) for d in train], axis=0)
    e_prior = float(np.mean([np.mean((prior[:, 2:] - time_normalise(d, 50)[:, 2:]) ** 2) for d in test]))
    # never much worse than replaying the mean demonstration
    assert _ctrl_mse(m, test) < 1.25 * e_prior
    assert m.selection_["cv_error"] <= m.selection_["cv_error_prior"] + 1e-12


def test_cv_with_fixed_covariance_method_only_selects_sigma2(synthetic):
    train, _ = synthetic
    m = ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=10, sigma2="cv", covariance="ridge").fit(
        train, dt=0.01)
    assert m.selection_["shrinkage_grid"] == [None]
    assert m.prior_.method == "ridge"


def test_bad_sigma2_string_rejected(synthetic):
    train, _ = synthetic
    with pytest.raises((ValueError, TypeError), match="sigma2"):
        ip.InteractionPrimitive(observed_dofs=[0, 1], sigma2="loo").fit(train, dt=0.01)

"""Peer methods on small data (interprim.models.demonstrations)."""

import numpy as np
import pytest

from interprim.core.preprocessing import time_normalise
from interprim.models.demonstrations import NearestNeighbour, PriorMean
from interprim.models.promp import InteractionProMP
from interprim.synthetic import two_agent_demos


@pytest.fixture(scope="module")
def data():
    return two_agent_demos(20, seed=0, frames=120), two_agent_demos(5, seed=9, frames=120)


def test_prior_mean_is_the_mean_demo(data):
    train, _ = data
    p = PriorMean([0, 1]).fit(train).predict(train[0][:10, :2])
    expected = np.mean([time_normalise(d, 100) for d in train], axis=0)
    np.testing.assert_allclose(p.trajectory(100), expected, atol=1e-3)
    assert p.std(100).shape == (100, 5) and np.all(p.std(100) >= 0)


def test_nearest_neighbour_finds_the_demo_a_prefix_came_from(data):
    train, _ = data
    nn = NearestNeighbour([0, 1]).fit(train)
    for j in (0, 7, 13):
        d = train[j]
        p = nn.predict(d[: int(0.6 * d.shape[0]), :2])
        assert p.neighbour == j
        np.testing.assert_allclose(p.trajectory(50), time_normalise(d, 50), atol=1e-2)
        assert p.phase == pytest.approx(0.6, abs=0.02)


def test_interaction_promp_conditions_and_beats_prior(data):
    train, test = data
    pm = PriorMean([0, 1]).fit(train)
    ipm = InteractionProMP([0, 1], n_weights=12).fit(train)
    e, e0 = [], []
    for d in test:
        T = d.shape[0]
        tr = time_normalise(d, 100)
        p = ipm.predict(d[: int(0.6 * T), :2])
        assert 0.3 < p.phase < 0.9  # maximum-likelihood time scaling near the truth (0.6)
        e.append(np.mean((p.trajectory(100)[:, 2:] - tr[:, 2:]) ** 2))
        e0.append(np.mean((pm.predict(None).trajectory(100)[:, 2:] - tr[:, 2:]) ** 2))
        # uncertainty shrinks on the observed part
        s = p.std(100)
        assert s.shape == (100, 5) and s[:40, :2].mean() < ipm.predict(d[:3, :2]).std(100)[:40, :2].mean()
    assert np.mean(e) < 0.3 * np.mean(e0)


def test_interaction_promp_known_phase_reproduces_observation(data):
    train, _ = data
    ipm = InteractionProMP([0, 1], n_weights=12).fit(train)
    d = train[3]
    p = ipm.predict(d[:, :2], phase=1.0)
    np.testing.assert_allclose(p.trajectory(50)[:, :2], time_normalise(d, 50)[:, :2], atol=0.02)


def test_baselines_validate_demos():
    with pytest.raises(ValueError, match="at least 2"):
        PriorMean([0]).fit([np.zeros((5, 2))])
    with pytest.raises(ValueError, match="demos\\[1\\]"):
        NearestNeighbour([0]).fit([np.zeros((5, 2)), np.zeros((5, 3))])

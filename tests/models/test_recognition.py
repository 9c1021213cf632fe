"""Recognising the interaction from a partial observation (interprim.models.recognition)."""

import numpy as np
import pytest

import interprim as ip
from interprim.models.recognition import Recogniser
from interprim.synthetic import two_agent_demos


def _other_interaction(n, seed):
    # the observed agent moves the other way and the controlled agent follows
    return [np.hstack([-d[:, :1], d[:, 1:2], -d[:, 2:]]) for d in two_agent_demos(n, seed=seed)]


@pytest.fixture(scope="module")
def recogniser():
    kw = dict(observed_dofs=[0, 1], n_basis=10, phase_method="likelihood")
    a = ip.InteractionPrimitive(**kw).fit(two_agent_demos(16, seed=1), dt=0.01)
    b = ip.InteractionPrimitive(**kw).fit(_other_interaction(16, seed=2), dt=0.01)
    return Recogniser({"reach": a, "mirror": b})


@pytest.mark.parametrize("frac", [0.3, 0.6, 1.0])
def test_recognises_held_out_demos(recogniser, frac):
    tests = {"reach": two_agent_demos(4, seed=11), "mirror": _other_interaction(4, seed=12)}
    for label, demos in tests.items():
        for d in demos:
            M = int(frac * d.shape[0])
            r = recogniser.recognise(d[:M, :2])
            assert r.label == label
            assert sum(r.probabilities.values()) == pytest.approx(1.0)
            assert r.probabilities[label] > 0.9
            assert set(r.phases) == {"reach", "mirror"}


def test_respond_returns_the_winners_prediction(recogniser):
    d = _other_interaction(1, seed=21)[0]
    r = recogniser.recognise(d[:100, :2], respond=True)
    assert r.label == "mirror"
    assert r.prediction.trajectory(20).shape == (20, 5)


def test_prior_shifts_the_posterior(recogniser):
    d = two_agent_demos(1, seed=31)[0][:40, :2]
    r0 = recogniser.recognise(d)
    biased = Recogniser(recogniser.models, prior={"reach": 1e-6, "mirror": 1 - 1e-6})
    r1 = biased.recognise(d)
    assert r1.probabilities["mirror"] > r0.probabilities["mirror"]


def test_rejects_incompatible_models(recogniser):
    other = ip.InteractionPrimitive(observed_dofs=[0], n_basis=5).fit(two_agent_demos(5, seed=1), dt=0.01)
    with pytest.raises(ValueError, match="observes columns"):
        Recogniser({"a": recogniser.models["reach"], "b": other})
    with pytest.raises(ValueError, match="not fitted"):
        Recogniser({"a": ip.InteractionPrimitive(observed_dofs=[0, 1])})
    with pytest.raises(ValueError, match="prior"):
        Recogniser(recogniser.models, prior={"reach": 1.0})

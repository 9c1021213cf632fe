"""A blend's Interaction Primitive (learned phase) and LearnedInteraction members share one learned phase model, whose
estimate of a prefix is computed once a frame; the numbers are those of separate models."""

import numpy as np
import pytest

import interprim as ip
from interprim.models.blend import Blend, share_phase_models
from interprim.phase.learned import LearnedPhase
from interprim.synthetic import two_agent_demos


@pytest.fixture(scope="module")
def parts():
    demos = two_agent_demos(8, seed=4, frames=70, noise=0.01)
    dt = 0.05
    prim = ip.InteractionPrimitive([0, 1], phase_method="learned").fit(demos, dt=dt)
    learned = ip.LearnedInteraction([0, 1]).fit(demos, dt=dt)
    return demos, dt, prim, learned


def _blend(demos, dt, prim, learned):
    members = {"ip": prim, "learned": learned}
    return Blend.from_fitted([0, 1], members, {"ip": [0.4, 0.6], "learned": [0.6, 0.4]}, None, demos, dt,
                             horizon=0.25, bands=[0.25, 2.0])


def test_equal_phase_models_are_shared_and_the_blend_gives_the_same_numbers(parts):
    demos, dt, prim, learned = parts
    alone_ip, alone_learned = prim.fitted_.phase_model_, learned.phase_
    assert alone_ip is not alone_learned  # two fits, equal numbers
    x = demos[3][:30, [0, 1]]
    before = {m: est.predict(x).trajectory(60) for m, est in (("ip", prim), ("learned", learned))}
    blend = _blend(demos, dt, prim, learned)
    assert blend.members_["learned"].phase_ is prim.fitted_.phase_model_
    for m, est in blend.members_.items():
        assert np.array_equal(est.predict(x).trajectory(60), before[m])
    st = blend.stream()
    for f in x:
        got = st.update(f)
    want = blend.predict(x)
    assert np.array_equal(got.trajectory(100), want.trajectory(100))
    assert share_phase_models(blend.members_) == 0  # already shared


def test_unequal_phase_models_are_not_shared(parts):
    demos, dt, prim, _ = parts
    other = ip.LearnedInteraction([0, 1], phase_kwargs={"history": 2}).fit(demos, dt=dt)
    own = other.phase_
    assert share_phase_models({"ip": prim, "learned": other}) == 0
    assert other.phase_ is own


def test_the_kept_estimate_is_the_estimate_and_is_not_saved(parts):
    demos, _, _, learned = parts
    lp = LearnedPhase.from_state(*learned.phase_.to_state())
    fresh = LearnedPhase.from_state(*lp.to_state())
    assert fresh.estimate_checked(np.ascontiguousarray(demos[1][:9, [0, 1]])) is not \
        fresh.estimate_checked(np.ascontiguousarray(demos[1][:9, [0, 1]]))  # nothing kept unless asked
    lp.keep_last_estimate()
    x = np.ascontiguousarray(demos[1][:, [0, 1]])
    for k in (2, 5, 17, 40, len(x)):
        a, b = lp.estimate_checked(x[:k]), lp.estimate_checked(x[:k].copy())
        assert b is a  # the same frames read: the kept estimate
        assert a == LearnedPhase.from_state(*fresh.to_state()).estimate_checked(x[:k])
    y = x.copy()
    y[-1] += 0.5  # another last frame: estimated anew
    assert lp.estimate_checked(y) == fresh.estimate_checked(y)
    assert lp.estimate_checked(y) != lp.estimate_checked(x)
    arrays, meta = lp.to_state()
    assert "_kept" not in meta and "_kept" not in arrays
    lp.fit([d[:, [0, 1]] for d in demos], dt=0.05)  # a new fit drops what was kept
    assert "_kept" not in vars(lp)

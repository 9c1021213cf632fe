"""The public contract checker, run over every registered model family and the default model (issue 28)."""

import numpy as np
import pytest

import interprim as ip
from interprim.models import registry
from interprim.testing import check_predictor, jittered_demonstrations

FAST = [n for n, f in registry.FAMILIES.items() if not f.needs]


@pytest.mark.parametrize("name", FAST)
def test_every_registered_family_honours_the_contract(name):
    make = registry.factories([name], registry.Settings((0, 1)))[name]
    out = check_predictor(make)
    got, want = out["jittered_duration"]
    assert got == pytest.approx(want, rel=0.05)


def test_the_default_model_honours_the_contract():
    out = check_predictor(lambda: ip.AutoInteraction([0, 1], candidates=("ip", "kernel", "prior"), folds=2))
    assert out["stream_vs_predict"] <= 1e-6


def test_the_checker_catches_a_model_that_changes_itself_in_predict():
    from interprim.models.demonstrations import PriorMean

    class Forgetful(PriorMean):
        def predict(self, partial, **kw):
            if hasattr(self, "mean_duration_"):
                self.mean_duration_ = self.mean_duration_ * 1.01  # state written by predict
            return super().predict(partial, **kw)

    with pytest.raises(AssertionError, match="predict changed"):
        check_predictor(lambda: Forgetful([0, 1]))


def test_jittered_stamps_have_no_common_interval():
    ds, durations = jittered_demonstrations(4, seed=0)
    assert ds.dt is None
    steps = np.concatenate([np.diff(t) for t in ds.times])
    assert steps.min() < 0.008 and steps.max() > 0.012
    assert durations == [float(t[-1]) for t in ds.times]


def test_the_checker_catches_an_attribute_written_by_predict_outside_the_saved_state():
    """The nearest demonstration used to keep its last answer on the model (``neighbour_``), which the saved state
    does not hold: the whole object is compared, as scikit-learn's ``check_dict_unchanged`` does."""
    from interprim.models.demonstrations import NearestNeighbour

    class Chatty(NearestNeighbour):
        def predict(self, partial):
            pred = super().predict(partial)
            self.neighbour_ = pred.neighbour
            return pred

    with pytest.raises(AssertionError, match=r"predict changed the model: model\.neighbour_ \(added\)"):
        check_predictor(lambda: Chatty([0, 1]))


def test_the_snapshot_follows_nested_objects_and_arrays_by_value():
    from interprim.core.cache import DerivedCache
    from interprim.testing import object_snapshot

    class Inner:
        def __init__(self):
            self.a = np.zeros(3)
            self.items = [1, {"k": np.ones(2)}]

    class Outer:
        def __init__(self):
            self.inner = Inner()
            self.cache = DerivedCache()

    o = Outer()
    before = object_snapshot(o)
    o.cache.get_or_build("x", (o.inner.a,), lambda: 42.0)  # a declared cache of derived values may fill
    assert object_snapshot(o) == before
    o.inner.items[1]["k"][0] = 2.0  # a write two containers deep, in place
    assert object_snapshot(o) != before
    o.inner.items[1]["k"][0] = 1.0
    assert object_snapshot(o) == before
    o.inner.a = np.zeros(3, dtype=np.float32)  # same values, another dtype
    assert object_snapshot(o) != before


def test_predict_and_stream_leave_a_shared_model_unchanged():
    """The server shares one model between sessions: the nearest and the kernel-weighted demonstrations return
    their choice on the prediction instead of writing it on the model."""
    from interprim.models.demonstrations import NearestNeighbour
    from interprim.models.kernel import KernelDemonstrations
    from interprim.synthetic import two_agent_demos
    from interprim.testing import object_snapshot

    demos = two_agent_demos(6, seed=2)
    for model in (NearestNeighbour([0, 1]).fit(demos[:-1]), KernelDemonstrations([0, 1]).fit(demos[:-1])):
        before = object_snapshot(model)
        a = model.predict(demos[-1][:30, :2])
        b = model.predict(demos[0][:30, :2])
        stream = model.stream()
        for f in demos[-1][:5, :2]:
            stream.update(f)
        assert object_snapshot(model) == before
        if isinstance(model, NearestNeighbour):
            assert b.neighbour == 0 and a.neighbour in range(5)
        else:
            assert sum(a.weights.values()) == pytest.approx(1.0) and max(b.weights, key=b.weights.get) == 0

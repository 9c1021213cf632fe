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

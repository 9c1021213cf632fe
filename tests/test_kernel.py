"""Kernel-weighted demonstrations (interprim.evaluation.kernel)."""

import numpy as np
import pytest

from interprim.errors import NotFittedError
from interprim.evaluation.baselines import NearestNeighbour
from interprim.evaluation.kernel import BANDWIDTHS, KernelDemonstrations
from interprim.synthetic import benchmark_tasks


@pytest.fixture(scope="module")
def reach():
    return benchmark_tasks(12, seed=0, names=("reach",))["reach"], benchmark_tasks(4, seed=1, names=("reach",))["reach"]


def test_bandwidth_is_chosen_by_leave_one_out(reach):
    dev, _ = reach
    m = KernelDemonstrations([0, 1]).fit(dev.demos, dt=dev.dt)
    assert m.bandwidth_ in BANDWIDTHS and set(m.cv_errors_) == set(BANDWIDTHS)
    assert m.cv_errors_[m.bandwidth_] == min(m.cv_errors_.values())


def test_prediction_shapes_timing_and_weights(reach):
    dev, hold = reach
    m = KernelDemonstrations([0, 1], bandwidth=0.3).fit(dev.demos, dt=dev.dt)
    test = hold.demos[0]
    k = len(test) // 2
    p = m.predict(test[:k, :2])
    assert p.trajectory(50).shape == (50, 4) and p.std(50).shape == (50, 4)
    assert np.all(p.std(50) >= 0)
    assert p.duration == pytest.approx((k - 1) * dev.dt / p.phase)
    assert 0.2 < p.phase < 0.8
    assert sum(p.weights.values()) == pytest.approx(1.0)


def test_small_bandwidth_is_the_nearest_demonstration_and_large_the_uniform_mix(reach):
    dev, hold = reach
    test = hold.demos[1]
    k = len(test) // 2
    tiny = KernelDemonstrations([0, 1], bandwidth=1e-6).fit(dev.demos, dt=dev.dt).predict(test[:k, :2])
    nn = NearestNeighbour([0, 1])
    nn.fit(dev.demos)
    nn.predict(test[:k, :2])
    w = tiny.weights
    assert max(w, key=w.get) == nn.neighbour_ and w[nn.neighbour_] > 0.999
    wide = KernelDemonstrations([0, 1], bandwidth=1e9).fit(dev.demos, dt=dev.dt).predict(test[:k, :2])
    np.testing.assert_allclose(list(wide.weights.values()), 1 / len(dev.demos), rtol=1e-6)


def test_errors_name_the_problem(reach):
    dev, _ = reach
    with pytest.raises(NotFittedError):
        KernelDemonstrations([0, 1]).predict(np.zeros((3, 2)))
    with pytest.raises(ValueError, match="bandwidth"):
        KernelDemonstrations([0, 1], bandwidth=-1).fit(dev.demos, dt=dev.dt)
    m = KernelDemonstrations([0, 1], bandwidth=1.0).fit(dev.demos, dt=dev.dt)
    with pytest.raises(ValueError, match=r"shape \(M, 2\)"):
        m.predict(np.zeros((3, 3)))
    with pytest.raises(ValueError, match="finite"):
        m.predict(np.full((3, 2), np.nan))
    with pytest.raises(ValueError, match="at least 3"):
        KernelDemonstrations([0, 1]).fit(dev.demos[:2], dt=dev.dt)

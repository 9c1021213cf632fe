"""AutoInteraction: the family chosen by cross-validation on the training demonstrations."""

import numpy as np
import pytest

import interprim as ip
from interprim.evaluation.realtime import RealTimeConfig, choose_method, default_methods
from interprim.synthetic import benchmark_tasks


@pytest.fixture(scope="module")
def task():
    return benchmark_tasks(10, seed=0, names=("handover",))["handover"], \
        benchmark_tasks(3, seed=1, names=("handover",))["handover"]


@pytest.fixture(scope="module")
def auto(task):
    dev, _ = task
    return ip.AutoInteraction([0, 1], candidates=("kernel", "nn", "prior")).fit(dev.demos, dt=dev.dt)


def test_chooses_the_family_with_the_smallest_held_out_error(auto, task):
    dev, _ = task
    make = {m: f for m, f in default_methods([0, 1]).items() if m in ("kernel", "nn", "prior")}
    chosen, errors = choose_method(make, dev.demos, [0, 1], dev.dt, RealTimeConfig(stride=3), k=3)
    assert auto.chosen_ == chosen == min(errors, key=errors.get)
    s = auto.selection_
    assert s["cv_errors"] == pytest.approx(errors) and s["margin"] >= 1.0
    assert s["vs_prior"] == pytest.approx(errors[chosen] / errors["prior"])
    assert type(auto.model_).__name__ in ("KernelDemonstrations", "NearestNeighbour", "PriorMean")
    assert repr(auto).startswith(f"AutoInteraction(chose {chosen!r}")


def test_predicts_streams_and_saves_as_the_chosen_model(auto, task, tmp_path):
    _, hold = task
    x = hold.demos[0][:40, :2]
    p = auto.predict(x)
    np.testing.assert_array_equal(p.trajectory(30), auto.model_.predict(x).trajectory(30))
    st = auto.stream()
    for f in x:
        q = st.update(f)
    np.testing.assert_allclose(q.trajectory(30), p.trajectory(30), rtol=0, atol=1e-10)
    auto.save(tmp_path / "auto.npz")
    back = ip.AutoInteraction.load(tmp_path / "auto.npz")
    assert back.chosen_ == auto.chosen_ and back.selection_ == auto.selection_
    np.testing.assert_array_equal(back.predict(x).trajectory(30), p.trajectory(30))


def test_bad_arguments_are_named(task):
    dev, _ = task
    with pytest.raises(ValueError, match="candidates"):
        ip.AutoInteraction([0, 1], candidates=("dance",)).fit(dev.demos, dt=dev.dt)
    with pytest.raises(ValueError, match="folds"):
        ip.AutoInteraction([0, 1], folds=1).fit(dev.demos, dt=dev.dt)
    with pytest.raises(ValueError, match="at least 3"):
        ip.AutoInteraction([0, 1]).fit(dev.demos[:2], dt=dev.dt)
    with pytest.raises(ip.NotFittedError):
        ip.AutoInteraction([0, 1]).predict(np.zeros((3, 2)))

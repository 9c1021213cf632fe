"""The prediction contract (interprim.models.base): every model fits, predicts, streams, saves and clones alike."""

import numpy as np
import pytest

import interprim as ip
from interprim.models import registry
from interprim.models.base import BasePrediction, BaseStream, Predictor
from interprim.models.demonstrations import NearestNeighbour, PriorMean
from interprim.models.kernel import KernelDemonstrations
from interprim.models.learned import LearnedInteraction
from interprim.models.promp import InteractionProMP
from interprim.synthetic import two_agent_demos

OBS = [0, 1]


def _ip():
    return ip.InteractionPrimitive(OBS, n_basis=8, sigma2=1e-3, covariance="ridge", phase_method="dtw",
                                   calibrate=False)


def _learned():
    return LearnedInteraction(OBS, coupling_kwargs=dict(methods=("ridge",), n_folds=4, fractions=(0.3, 0.6, 1.0),
                                                        n_jitter=3, blend_weights=()))


def _promp():
    pytest.importorskip("movement_primitives")
    pytest.importorskip("gmr")
    return InteractionProMP(OBS, n_weights=6, n_phases=8)


def _ip_phase(method):
    return lambda: ip.InteractionPrimitive(OBS, n_basis=8, sigma2=1e-3, phase_method=method, calibrate=False)


def _family(name):
    """The registry's family ``name`` with its defaults (the peers' packages skipped when absent)."""
    def make():
        for module in registry.family(name).needs:
            pytest.importorskip(module)
        return registry.factories([name], registry.Settings(tuple(OBS), n_basis=8))[name]()
    return make


#: every family of the registry with its defaults, faster variants of two, and the default model
MODELS = {**{name: _family(name) for name in registry.FAMILIES},
          "ip-dtw-fixed": _ip, "ip-likelihood": _ip_phase("likelihood"), "ip-learned": _ip_phase("learned"),
          "learned-ridge": _learned, "prior-mean-60": lambda: PriorMean(OBS, n=60),
          "nearest-neighbour-60": lambda: NearestNeighbour(OBS, n=60), "promp-small": _promp,
          "kernel-60": lambda: KernelDemonstrations(OBS, n=60),
          "auto": lambda: ip.AutoInteraction(OBS, candidates=("kernel", "prior"))}


@pytest.fixture(scope="module")
def demos():
    return two_agent_demos(10, seed=7, frames=120)


@pytest.fixture(scope="module")
def fitted(demos):
    cache = {}

    def get(name):
        if name not in cache:
            cache[name] = MODELS[name]().fit(demos[:-1], dt=0.01)
        return cache[name]

    return get


@pytest.mark.parametrize("name", sorted(MODELS))
def test_not_fitted_errors(name, demos, tmp_path):
    model = MODELS[name]()
    assert isinstance(model, Predictor)
    for call in (lambda: model.predict(demos[0][:10, :2]), model.stream, lambda: model.save(tmp_path / "m.npz")):
        with pytest.raises(ip.NotFittedError, match="not fitted"):
            call()


@pytest.mark.parametrize("name", sorted(MODELS))
def test_one_prediction_type_with_the_same_shapes(name, fitted, demos):
    model = fitted(name)
    test = demos[-1]
    M, n, D = 70, 25, test.shape[1]
    pred = model.predict(test[:M, :2])
    assert isinstance(pred, BasePrediction)
    assert pred.trajectory(n).shape == (n, D)
    sd = pred.std(n)
    assert (sd is None and type(model) is NearestNeighbour) or (sd.shape == (n, D) and np.all(sd >= 0))
    smp = pred.samples(4, n, random_state=0)
    assert smp.shape == (4, n, D)
    np.testing.assert_array_equal(smp, pred.samples(4, n, random_state=0))
    t, y = pred.response(n)
    assert t.shape == (n,) and y.shape == (n, D - 2) and t[0] == 0.0 and np.all(np.diff(t) >= 0)
    s, yc = pred.completion(n)
    assert s.shape == (n,) and yc.shape == (n, 2) and s[-1] == pytest.approx(1.0)
    assert np.asarray(pred.goal).shape == (D,)
    assert pred.n_observed == M and isinstance(pred.conditioned, bool)
    for attr in ("phase", "normalised_time", "duration", "speed", "log_likelihood", "input_distance"):
        assert isinstance(getattr(pred, attr), float), attr
    if type(model) is not PriorMean:  # the prior mean estimates no timing
        assert 0.0 < pred.normalised_time <= 1.0 and pred.duration > 0 and pred.speed > 0


@pytest.mark.parametrize("name", sorted(MODELS))
def test_stream_equals_batch(name, fitted, demos):
    model = fitted(name)
    test = demos[-1]
    st = model.stream()
    for k, frame in enumerate(test[:60, :2]):
        p = st.update(frame)
        if k + 1 in (20, 45, 60):
            ref = model.predict(test[: k + 1, :2])
            scale = float(np.abs(ref.trajectory(30)).max())
            # measured: 0.0 (bitwise) for every model but ip-likelihood (trajectory 2.9e-9, phase 7.7e-10: the
            # stream's lattice search and the batch search end with the same parabolic step, ~1e-8 apart at most)
            np.testing.assert_allclose(p.trajectory(30), ref.trajectory(30), rtol=0, atol=1e-6 * scale)
            assert p.normalised_time == pytest.approx(ref.normalised_time, abs=1e-6, nan_ok=True)
    assert st.n_frames == 60
    st.reset()
    assert st.n_frames == 0


@pytest.mark.parametrize("name", sorted(MODELS))
def test_extend_equals_update_frame_by_frame(name, fitted, demos):
    """Every model's stream is a BaseStream, and extend (several frames at once, as a server that fell behind feeds
    them) answers what update answers for the last of them: exactly, however the frames are grouped."""
    model = fitted(name)
    frames = demos[-1][:50, :2]
    a, b = model.stream(), model.stream()
    assert isinstance(a, BaseStream)
    i = 0
    for size in (1, 2, 5, 1, 9, 3, 17, 12):
        for f in frames[i:i + size]:
            pa = a.update(f)
        pb = b.extend(frames[i:i + size])
        i += size
        assert b.n_frames == a.n_frames == i
        np.testing.assert_array_equal(pb.trajectory(30), pa.trajectory(30))
        assert pb.conditioned == pa.conditioned
        assert pb.normalised_time == pa.normalised_time or (np.isnan(pb.normalised_time)
                                                            and np.isnan(pa.normalised_time))
    assert i == 50
    for bad in (np.zeros((0, 2)), np.zeros((3, 3)), np.array([[0.0, np.nan]])):  # nothing enters on bad input
        with pytest.raises(ValueError, match="frame"):
            b.extend(bad)
        assert b.n_frames == 50


@pytest.mark.parametrize("name", sorted(MODELS))
def test_mean_rollout_is_the_trajectory_columns(name, fitted, demos):
    """``pred.mean_rollout(n, cols)`` (what the server encodes at every frame) gives ``trajectory(n)[:, cols]`` for
    the prediction it was made from and for later predictions of the same model (an IP's MeanRollout builds the
    grid's design once: the same maths in another order, so to 1e-12 of the trajectory's scale)."""
    model = fitted(name)
    test = demos[-1]
    first = model.predict(test[:30, :2])
    for cols in (slice(2, 5), [0, 3], None):
        fn = first.mean_rollout(40, cols)
        for M in (30, 55, 90):
            pred = model.predict(test[:M, :2])
            ref = pred.trajectory(40)[:, slice(None) if cols is None else cols]
            got = fn(pred)
            assert got.shape == ref.shape
            np.testing.assert_allclose(got, ref, rtol=0, atol=1e-12 * float(np.abs(ref).max()))


@pytest.mark.parametrize("name", sorted(MODELS))
def test_save_load_round_trip(name, fitted, demos, tmp_path):
    model = fitted(name)
    path = tmp_path / f"{name}.npz"
    model.save(path)
    loaded = type(model).load(path)
    assert loaded.json_params() == model.json_params()
    part = demos[-1][:55, :2]
    a, b = model.predict(part), loaded.predict(part)
    np.testing.assert_array_equal(a.trajectory(40), b.trajectory(40))
    if a.std(40) is not None:
        np.testing.assert_array_equal(a.std(40), b.std(40))
    assert a.normalised_time == b.normalised_time or (np.isnan(a.normalised_time) and np.isnan(b.normalised_time))
    with open(path, "rb") as fh:
        assert b"pickle" not in fh.read().lower()


@pytest.mark.parametrize("name", sorted(MODELS))
def test_a_model_file_of_another_kind_is_refused(name, fitted, tmp_path):
    model = fitted(name)
    path = tmp_path / "m.npz"
    model.save(path)
    other = PriorMean if type(model) is not PriorMean else ip.InteractionPrimitive
    with pytest.raises(ip.ModelFileError, match=f"holds a {type(model).__name__} model"):
        other.load(path)


@pytest.mark.parametrize("name", sorted(MODELS))
def test_clone_and_params(name, fitted, demos):
    base = pytest.importorskip("sklearn.base")
    model = fitted(name)
    twin = base.clone(model)
    assert type(twin) is type(model) and twin.get_params(deep=False).keys() == model.get_params(deep=False).keys()
    with pytest.raises(ip.NotFittedError):
        twin.predict(demos[-1][:30, :2])
    assert twin.set_params(observed_dofs=[0, 1]) is twin
    with pytest.raises(ValueError, match="has no parameter"):
        twin.set_params(not_a_parameter=1)
    twin.fit(demos[:-1], dt=0.01)
    part = demos[-1][:50, :2]
    np.testing.assert_array_equal(twin.predict(part).trajectory(20), model.predict(part).trajectory(20))


def test_every_registered_family_is_in_the_contract_test():
    assert set(registry.FAMILIES) <= set(MODELS)

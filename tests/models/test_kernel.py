"""Kernel-weighted demonstrations (interprim.models.kernel)."""

import numpy as np
import pytest

from interprim.core.errors import NotFittedError
from interprim.models.demonstrations import NearestNeighbour
from interprim.models.kernel import BANDWIDTHS, KernelDemonstrations
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
    km = KernelDemonstrations([0, 1], bandwidth=1e-6).fit(dev.demos, dt=dev.dt)
    w = km.predict(test[:k, :2]).weights
    nn = NearestNeighbour([0, 1])
    nn.fit(dev.demos)
    best = nn.predict(test[:k, :2]).neighbour
    assert max(w, key=w.get) == best and w[best] > 0.999
    wide = KernelDemonstrations([0, 1], bandwidth=1e9).fit(dev.demos, dt=dev.dt)
    np.testing.assert_allclose(list(wide.predict(test[:k, :2]).weights.values()), 1 / len(dev.demos), rtol=1e-6)


def test_errors_name_the_problem(reach):
    dev, _ = reach
    with pytest.raises(NotFittedError):
        KernelDemonstrations([0, 1]).predict(np.zeros((3, 2)))
    with pytest.raises(ValueError, match="bandwidth"):
        KernelDemonstrations([0, 1], bandwidth=-1).fit(dev.demos, dt=dev.dt)
    m = KernelDemonstrations([0, 1], bandwidth=1.0).fit(dev.demos, dt=dev.dt)
    with pytest.raises(ValueError, match="partial"):
        m.predict(np.zeros((3, 3)))
    with pytest.raises(ValueError, match="partial"):
        m.predict(np.full((3, 2), np.nan))
    with pytest.raises(ValueError, match="at least 3"):
        KernelDemonstrations([0, 1]).fit(dev.demos[:2], dt=dev.dt)


def test_save_load_and_stream_follow_the_contract(reach, tmp_path):
    dev, hold = reach
    m = KernelDemonstrations([0, 1]).fit(dev.demos, dt=dev.dt)
    m.save(tmp_path / "k.npz")
    back = KernelDemonstrations.load(tmp_path / "k.npz")
    x = hold.demos[2][:30, :2]
    np.testing.assert_array_equal(back.predict(x).trajectory(40), m.predict(x).trajectory(40))
    assert back.bandwidth_ == m.bandwidth_
    st = m.stream()
    for f in x:
        p = st.update(f)
    np.testing.assert_allclose(p.trajectory(40), m.predict(x).trajectory(40), rtol=0, atol=1e-12)


def test_calibrated_spread_covers_new_demonstrations():
    """The weighted spread alone is far too narrow (one demonstration's weight near 1 gives no spread); calibrated
    on the leave-one-out errors it covers about 90 % of new demonstrations over the next 0.25 s."""
    from interprim.evaluation.realtime import RealTimeConfig, realtime_fold

    dev = benchmark_tasks(20, seed=0, names=("handover",))["handover"]
    new = benchmark_tasks(6, seed=1, names=("handover",))["handover"]
    m = KernelDemonstrations([0, 1]).fit(dev.demos, dt=dev.dt)
    assert np.all(m.std_scale_ >= 0) and np.all(m.std_floor_ >= 0)
    cov = {"cov_ctrl": [], "cov_obs": []}
    for d in new.demos:
        for r in realtime_fold(m, dev.demos, d, [0, 1], dev.dt, RealTimeConfig(stride=3), fitted=True):
            if r["method"] == "method":
                for key in cov:
                    cov[key].append(r[key])
    for key, v in cov.items():
        assert 0.8 <= np.mean(v) <= 0.98, (key, np.mean(v))


def _same_prediction(a, b):
    """Bitwise-equal predictions of the kernel or the nearest demonstration (mean, std, timing)."""
    np.testing.assert_array_equal(a.mean, b.mean)
    if a.std_values is None:
        assert b.std_values is None
    else:
        np.testing.assert_array_equal(a.std_values, b.std_values)
    for attr in ("phase", "duration", "n_observed", "method"):
        x, y = getattr(a, attr), getattr(b, attr)
        assert x == y or (x != x and y != y), attr


@pytest.mark.parametrize("path", ["numpy", "compiled"])
@pytest.mark.parametrize("cls", [KernelDemonstrations, NearestNeighbour])
def test_aligned_stream_equals_predict_on_every_frame(reach, cls, path):
    """The stream advances one incremental open-end DTW per demonstration instead of re-aligning the prefix, and
    gives exactly (bitwise) what predict gives on every prefix, on either path of the DTW kernels; extend in
    uneven blocks gives the same; reset starts again."""
    from interprim.core._compiled import loader, registry
    from interprim.models.demonstrations import AlignedStream

    if path == "compiled" and not loader.warmup():
        pytest.skip("numba kernels unavailable")
    dev, hold = reach
    m = cls([0, 1]).fit(dev.demos, dt=dev.dt)
    x = hold.demos[3][:, :2]
    with registry.forced(path):
        st = m.stream()
        assert isinstance(st, AlignedStream)
        for k in range(1, len(x) + 1):
            p = st.update(x[k - 1])
            q = m.predict(x[:k])
            _same_prediction(p, q)
            assert (p.weights, p.neighbour) == (q.weights, q.neighbour)
        assert st.n_frames == len(x)
        st.reset()
        assert st.n_frames == 0
        i = 0
        for size in (1, 4, 2, 11, 7):
            p = st.extend(x[i:i + size])
            i += size
            _same_prediction(p, m.predict(x[:i]))
    with pytest.raises(ValueError, match="frame"):
        st.update(np.array([0.0, np.nan]))
    with pytest.raises(ValueError, match="frame"):
        st.update(np.zeros(3))
    assert st.n_frames == i  # nothing entered
    with pytest.raises(ValueError, match="robot_state"):
        m.stream(robot_state=np.zeros(2))


def test_realtime_protocol_through_the_stream_equals_predicting_every_prefix(reach):
    """The real-time protocol feeds an exact stream frame by frame (cheaper); its records equal those of predicting
    every prefix anew (the same model with the stream shortcut switched off)."""
    from interprim.evaluation.realtime import RealTimeConfig, realtime_fold

    dev, hold = reach
    for cls in (KernelDemonstrations, NearestNeighbour):
        fast = cls([0, 1]).fit(dev.demos, dt=dev.dt)
        slow = cls([0, 1]).fit(dev.demos, dt=dev.dt)
        slow.exact_stream = False
        for d in hold.demos[:2]:
            a = realtime_fold(fast, dev.demos, d, [0, 1], dev.dt, RealTimeConfig(stride=2), fitted=True, trace=True)
            b = realtime_fold(slow, dev.demos, d, [0, 1], dev.dt, RealTimeConfig(stride=2), fitted=True, trace=True)
            assert len(a) == len(b) > 10
            for ra, rb in zip(a, b):
                assert ra.keys() == rb.keys()
                for key, va in ra.items():
                    if isinstance(va, np.ndarray):
                        np.testing.assert_array_equal(va, rb[key])
                    elif va is None or isinstance(va, str):
                        assert va == rb[key]
                    else:
                        assert va == rb[key] or (va != va and rb[key] != rb[key]), key


def test_protocol_predicts_anew_when_the_prefixes_are_not_nested(reach):
    """A causal prefix of an interpolated recording need not be the start of a later one: the protocol then
    predicts every prefix anew instead of streaming."""
    from interprim.evaluation.realtime import RealTimeConfig, realtime_fold

    dev, hold = reach
    m = KernelDemonstrations([0, 1]).fit(dev.demos, dt=dev.dt)
    d = hold.demos[0]

    def shifted(k):  # every prefix differs from the start of the next
        return d[:k, :2] + 1e-3 * k

    recs = realtime_fold(m, dev.demos, d, [0, 1], dev.dt, RealTimeConfig(stride=4), fitted=True, trace=True,
                         prefix=shifted, references=False)
    for r in recs:
        k = r["k"]
        p = m.predict(shifted(k))
        assert r["phase"] == p.normalised_time


def test_frames_of_all_demonstrations_at_once_equal_one_interpolation_each(reach):
    """The continuations of every demonstration are read at fractional frames all at once (padded frames,
    numpy.interp's own operations on the frame grid): the numbers of one interp_columns per demonstration, on
    samples, between them and at the last frame (bitwise on x86-64, whose numpy has no fused multiply-add in
    interp; elsewhere to rounding)."""
    import platform

    from interprim.core.preprocessing import interp_columns

    dev, _ = reach
    m = KernelDemonstrations([0, 1], bandwidth=0.3).fit(dev.demos, dt=dev.dt)
    rng = np.random.default_rng(0)
    idx = [3, 0, 7, 7, 11]
    T = np.array([len(m.demos_[j]) for j in idx])[:, None]
    f = rng.uniform(0.0, 1.0, size=(len(idx), 40)) * (T - 1)
    f[:, :5] = np.array([0, 1, 2, T.min() - 2, T.min() - 1])  # samples
    f[:, 5] = (T - 1)[:, 0]  # each one's last frame
    f[:, 6] = (T - 1)[:, 0] - 0.25
    for cols in (slice(None), [2, 3], [1]):
        got = m._frames_at(idx, f, cols)
        ref = np.stack([interp_columns(f[i], np.arange(len(m.demos_[j])), m.demos_[j][:, cols])
                        for i, j in enumerate(idx)])
        assert got.shape == ref.shape
        if platform.machine().lower() in ("x86_64", "amd64"):
            np.testing.assert_array_equal(got, ref)
        else:
            np.testing.assert_allclose(got, ref, rtol=0, atol=1e-14 * np.abs(ref).max())

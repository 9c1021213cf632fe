"""Stream.extend: several frames at once give what update gives frame by frame, and what predict gives."""

import warnings

import numpy as np
import pytest

import interprim as ip
from interprim.core.errors import OutOfRangeWarning
from interprim.synthetic import two_agent_demos

# chunk sizes of the extends: single frames, the first frames (M < 3: no conditioning; M = 2: the
# tracker's first estimate), long gaps (> the tracker's rank-1 window) and everything in between
CHUNKS = [1, 2, 1, 5, 3, 13, 1, 8, 21, 2, 40]


@pytest.fixture(scope="module")
def data():
    demos = two_agent_demos(18, seed=3)
    return demos[:14], demos[14:]


_CONFIGS = {
    "likelihood-position": dict(phase_method="likelihood"),  # the library's default phase and observation
    "likelihood-forcing": dict(phase_method="likelihood", observation="forcing"),
    "dtw-forcing": dict(phase_method="dtw", observation="forcing"),  # the paper's configuration
    "learned": dict(phase_method="learned"),
    "likelihood-pca": dict(phase_method="likelihood", pca_components=1),
}


@pytest.fixture(scope="module", params=sorted(_CONFIGS))
def model(request, data):
    train, _ = data
    kw = _CONFIGS[request.param]
    return ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=12, sigma2=1e-3, **kw).fit(train, dt=0.01)


def _chunks(n):
    out, i, k = [], 0, 0
    while i < n:
        c = min(CHUNKS[k % len(CHUNKS)], n - i)
        out.append((i, i + c))
        i += c
        k += 1
    return out


def _same(p, q, rtol=0.0, atol=0.0):
    """Largest differences between two predictions: phase, and trajectory/std relative to the trajectory's scale."""
    ds = abs(p.normalised_time - q.normalised_time)
    y, yq = p.trajectory(40), q.trajectory(40)
    scale = float(np.max(np.abs(yq)))
    dy = float(np.max(np.abs(y - yq))) / scale
    return ds, dy


def test_extend_equals_update_frame_by_frame(model, data):
    """Every chunk's answer is update's answer for its last frame, exactly (the same numbers), whatever the phase:
    the DTW and learned phases are functions of the frames, and the likelihood tracker walks its lattice frame by
    frame in extend as in update, so its state does not depend on how the frames were grouped."""
    _, test = data
    frames = test[0][:, :2]
    a, b = model.stream(), model.stream()
    tol = 0.0
    worst_s = worst_y = 0.0
    for i, j in _chunks(len(frames)):
        for f in frames[i:j]:
            pa = a.update(f)
        pb = b.extend(frames[i:j])
        assert b.n_frames == a.n_frames == j
        assert pb.n_star == pytest.approx(pa.n_star, rel=tol, abs=tol * model.reference_.shape[0])
        assert pb.conditioned == pa.conditioned
        ds, dy = _same(pb, pa)
        worst_s, worst_y = max(worst_s, ds), max(worst_y, dy)
        if np.isfinite(pa.log_likelihood):  # (likelihood phase: its slope in the phase is ~500; measured 1.5e-6)
            assert pb.log_likelihood == pytest.approx(pa.log_likelihood, rel=10 * tol, abs=10 * tol)
        assert pb.input_distance == pa.input_distance
        np.testing.assert_allclose(pb.goal, pa.goal, rtol=tol, atol=tol)
    assert worst_s <= tol and worst_y <= tol, (worst_s, worst_y)


def test_extend_equals_predict_on_the_prefix(model, data):
    """Stream = batch holds for extend as it does for update: each chunk's answer against ``predict`` on all the
    frames so far.  The DTW and learned phases: exactly (asserted 1e-12, measured 0); the likelihood phase ends
    at the same maximum of the log posterior by the same last step from other starting candidates (measured:
    phase within 7e-8, trajectory within 4e-7 relative, as close as update's own answers are; asserted 1e-6)."""
    _, test = data
    frames = test[1][:, :2]
    st = model.stream()
    tol = 1e-6 if model.phase_method_used() == "likelihood" else 1e-12
    worst_s = worst_y = 0.0
    for i, j in _chunks(len(frames)):
        p = st.extend(frames[i:j])
        if j < 3:
            continue
        q = model.predict(frames[:j])
        ds, dy = _same(p, q)
        worst_s, worst_y = max(worst_s, ds), max(worst_y, dy)
    assert worst_s <= tol and worst_y <= tol, (worst_s, worst_y)


def test_extend_then_update_and_reset(data):
    train, test = data
    m = ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=12, sigma2=1e-3, phase_method="likelihood").fit(
        train, dt=0.01)
    frames = test[2][:, :2]
    a, b = m.stream(), m.stream()
    for f in frames[:30]:
        a.update(f)
    b.extend(frames[:30])
    for f in frames[30:40]:  # update after extend goes on from the same state, exactly
        pa, pb = a.update(f), b.update(f)
        np.testing.assert_array_equal(pb.trajectory(20), pa.trajectory(20))
    b.reset()
    a2, b2 = m.stream(), m.stream()
    pa = b2.extend(frames[:25])
    pb = b.extend(frames[:25])  # after reset: a new interaction, exactly as a fresh stream
    np.testing.assert_array_equal(pb.trajectory(20), pa.trajectory(20))
    for f in frames[:25]:
        pa = a2.update(f)
    np.testing.assert_array_equal(pb.trajectory(20), pa.trajectory(20))
    # the covariance, now or on demand
    pc = b.extend(frames[25:27], need_cov=True)
    for f in frames[25:27]:
        pa = a2.update(f, need_cov=True)
    np.testing.assert_array_equal(pc.std(20), pa.std(20))
    assert pc.posterior_cov is not None


def test_extend_validates_its_input_before_taking_any_frame(data):
    train, test = data
    m = ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=12, sigma2=1e-3).fit(train, dt=0.01)
    frames = test[0][:, :2]
    st = m.stream()
    st.extend(frames[:10])
    bad = frames[10:15].copy()
    bad[3, 1] = np.nan
    with pytest.raises(ValueError, match=r"frames contains 1 non-finite value.*frame 3, column 1"):
        st.extend(bad)
    bad[3, 1] = np.inf
    with pytest.raises(ValueError, match="non-finite"):
        st.extend(bad)
    with pytest.raises(ValueError, match=r"frames has 3 columns, expected 2"):
        st.extend(np.zeros((4, 3)))
    with pytest.raises(ValueError, match=r"frames must be 2-D"):
        st.extend(frames[10])  # one frame: shape (2,), not (1, 2)
    with pytest.raises(ValueError, match=r"frames has 0 frames, at least 1"):
        st.extend(np.zeros((0, 2)))
    with pytest.raises(TypeError, match="frames must be a numeric array"):
        st.extend([["a", "b"]])
    assert st.n_frames == 10  # nothing of the bad calls entered the stream
    ref = m.stream()
    ref.extend(frames[:10])
    pr = ref.extend(frames[10:15])
    np.testing.assert_array_equal(st.extend(frames[10:15]).trajectory(20), pr.trajectory(20))
    # lists are accepted like arrays
    st2 = m.stream()
    st2.extend(frames[:10].tolist())
    np.testing.assert_array_equal(st2.extend(frames[10:15].tolist()).trajectory(20), pr.trajectory(20))


def test_extend_flags_out_of_range_frames_once(data):
    train, test = data
    m = ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=12, sigma2=1e-3).fit(train, dt=0.01)
    frames = test[0][:20, :2].copy()
    frames[7] *= 1000.0  # one frame in the wrong units, in the middle of a chunk
    st = m.stream()
    with pytest.warns(OutOfRangeWarning):
        p = st.extend(frames[:12])
    assert p.out_of_range and p.input_distance > m.input_limit_
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the warning is given once per interaction
        p2 = st.extend(frames[12:])
    assert p2.out_of_range and p2.input_distance == p.input_distance
    ref = m.stream()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", OutOfRangeWarning)
        for f in frames:
            pr = ref.update(f)
    assert pr.input_distance == p2.input_distance

"""Open-end DTW (Eq. 5-8) and the phase (Eq. 9)."""

import numpy as np
import pytest
from _dtw_reference import brute_force_dtw
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from interprim.phase.dtw import IncrementalDTW, accumulated_cost, open_end_dtw, phase_from_index

small = arrays(np.float64, st.tuples(st.integers(1, 12), st.integers(1, 3)),
               elements=st.floats(-5, 5, allow_nan=False, width=32))


@settings(max_examples=60, deadline=None)
@given(small, st.data())
def test_dtw_matches_brute_force(u, data):
    M = data.draw(st.integers(1, 10))
    v = data.draw(arrays(np.float64, (M, u.shape[1]), elements=st.floats(-5, 5, allow_nan=False, width=32)))
    Dbf, n_star = brute_force_dtw(u, v)
    n_star += 1  # the paper's 1-based n*
    np.testing.assert_allclose(accumulated_cost(u, v), Dbf, rtol=1e-12, atol=1e-9)
    r = open_end_dtw(u, v)
    assert r.cost == pytest.approx(Dbf[n_star - 1, -1], rel=1e-12, abs=1e-9)
    assert Dbf[r.n_star, -1] == pytest.approx(Dbf[:, -1].min(), rel=1e-12, abs=1e-9)
    # the path is a valid alignment from (0,0) to (n*, M-1) whose cost is D(n*, M)
    p = r.path
    assert tuple(p[0]) == (0, 0) and tuple(p[-1]) == (r.n_star, M - 1)
    steps = np.diff(p, axis=0)
    assert np.all((steps >= 0) & (steps <= 1)) and np.all(steps.sum(axis=1) >= 1)
    path_cost = sum(float(np.sum((u[i] - v[j]) ** 2)) for i, j in p)
    assert path_cost == pytest.approx(r.cost, rel=1e-9, abs=1e-9)


@settings(max_examples=30, deadline=None)
@given(small, st.integers(1, 15), st.integers(0, 2**31 - 1))
def test_incremental_equals_batch_frame_by_frame(u, M, seed):
    v = np.random.default_rng(seed).normal(size=(M, u.shape[1]))
    inc = IncrementalDTW(u)
    for m in range(M):
        n, c = inc.update(v[m])
        r = open_end_dtw(u, v[: m + 1], return_path=False)
        assert n == r.n_star and c == r.cost  # exactly equal, not approximately
        np.testing.assert_array_equal(inc.column, accumulated_cost(u, v[: m + 1])[:, -1])
    inc.reset()
    assert inc.n_frames == 0 and inc.update(v[0])[0] == open_end_dtw(u, v[:1]).n_star


def test_phase_eq9():
    assert phase_from_index(49, 100, alpha_x=3.0) == pytest.approx(np.exp(-1.5))
    assert open_end_dtw(np.arange(10.0)[:, None], np.arange(5.0)[:, None]).fraction == pytest.approx(0.5)


@pytest.mark.parametrize("stretch", [0.7, 0.85, 1.0, 1.2, 1.5])
@pytest.mark.parametrize("frac", [0.2, 0.5, 0.8])
def test_time_stretched_prefix_gets_true_phase(stretch, frac):
    """A prefix of a demonstration played 0.7x-1.5x as fast gets its true phase back."""
    import interprim as ip
    from interprim.synthetic import two_agent_demos

    train = two_agent_demos(20, seed=3)
    model = ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=15, phase_method="dtw").fit(train, dt=0.01)
    # a movement of the same shape as the reference, stretched in time
    ref = model.reference_
    T = int(round((len(ref) - 1) * stretch)) + 1
    moving = ip.core.preprocessing.time_normalise(ref, T)
    M = int(round(frac * (T - 1))) + 1
    pred = model.predict(moving[:M])
    true_phase = (M - 1) / (T - 1)
    assert abs(pred.phase - true_phase) < 0.03
    assert pred.speed == pytest.approx(1.0 / stretch, rel=0.12)


def test_bad_inputs():
    with pytest.raises(ValueError, match="columns"):
        open_end_dtw(np.zeros((5, 2)), np.zeros((3, 3)))
    with pytest.raises(ValueError, match="NaN"):
        open_end_dtw(np.zeros((5, 2)), np.full((3, 2), np.nan))
    inc = IncrementalDTW(np.zeros((5, 2)))
    with pytest.raises(ValueError, match="shape"):
        inc.update([1.0, 2.0, 3.0])


@pytest.mark.parametrize("path", ["numpy", "compiled"])
def test_incremental_dtw_takes_a_block_as_frame_by_frame(path):
    """``IncrementalDTW.extend`` of blocks of any size leaves the alignment exactly where ``update`` of each frame
    leaves it, which is the batch open-end DTW of the frames seen, on either path of the kernels."""
    from interprim.core._compiled import registry

    rng = np.random.default_rng(5)
    u = np.cumsum(rng.normal(size=(60, 3)), axis=0)
    v = np.ascontiguousarray(u[::2][:25] + 0.1 * rng.normal(size=(25, 3)))
    with registry.forced(path):
        one, blocks = IncrementalDTW(u), IncrementalDTW(u)
        for sizes in ([1, 3], [4, 1, 2], [7, 7]):
            one.reset()
            blocks.reset()
            start = 0
            for k in sizes:
                for f in v[start:start + k]:
                    want = one.update(f)
                assert blocks.extend(v[start:start + k]) == want
                start += k
                ref = open_end_dtw(u, v[:start], return_path=False)
                assert (blocks.n_star, blocks.cost) == (ref.n_star, ref.cost) and blocks.n_frames == start

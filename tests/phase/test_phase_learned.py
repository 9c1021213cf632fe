"""Tests of the learned phase estimator (interprim.phase.learned)."""

from __future__ import annotations

import numpy as np
import pytest

from interprim.core.errors import NotFittedError
from interprim.phase.learned import FEATURE_GROUPS, LearnedPhase
from interprim.phase.learned import prefix_features as _prefix_features

DT = 0.05


def _ramps(durations, n_dofs=2, seed=0):
    """Demos whose first DoF is the normalised time itself (phase = a linear function of the position)."""
    rng = np.random.default_rng(seed)
    out = []
    for T in durations:
        n = int(round(T / DT)) + 1
        s = np.linspace(0.0, 1.0, n)
        cols = [s] + [np.sin(np.pi * s) * rng.uniform(0.5, 1.5) for _ in range(n_dofs - 1)]
        out.append(np.stack(cols, axis=1))
    return out


def _noise_demos(n_demos=20, n_dofs=3, seed=0):
    """Durations unrelated to anything the features see: white noise positions."""
    rng = np.random.default_rng(seed)
    return [rng.standard_normal((int(rng.integers(30, 50)), n_dofs)) for _ in range(n_demos)]


def test_exact_recovery_when_phase_is_a_linear_function_of_the_features():
    durs = np.linspace(1.5, 3.0, 16)
    lp = LearnedPhase(features=("position",), model="ridge", alphas=(1e-9,)).fit(_ramps(durs), dt=DT)
    assert lp.method_ == "ridge" and not lp.fallback_
    assert lp.cv_error_ < 1e-3 * lp.cv_error_clock_  # only extrapolation past the longest demo is not exact
    test = _ramps([2.1], seed=1)[0]  # a duration between the training ones
    for M in (10, 20, 30, 42):
        est = lp.estimate(test[:M])
        assert est.phase == pytest.approx((M - 1) / (test.shape[0] - 1), abs=1e-6)
        assert est.duration == pytest.approx(2.1, rel=1e-5)
        assert est.speed == pytest.approx(lp.mean_duration_ / 2.1, rel=1e-5)
        assert est.elapsed == pytest.approx((M - 1) * DT)


def test_auto_choice_beats_the_clock_on_informative_features():
    durs = np.linspace(1.5, 3.0, 16)
    lp = LearnedPhase().fit(_ramps(durs), dt=DT)
    assert not lp.fallback_ and lp.method_ in ("kernel", "ridge")
    assert lp.cv_error_ < 0.2 * lp.cv_error_clock_
    test = _ramps([1.8], seed=2)[0]
    clock = min(20 * DT / lp.mean_duration_, 1.0)
    truth = 20 / (test.shape[0] - 1)
    assert abs(lp.estimate(test[:21]).phase - truth) < 0.3 * abs(clock - truth)


def test_falls_back_to_the_clock_when_features_carry_no_information():
    demos = _noise_demos()
    lp = LearnedPhase().fit(demos, dt=DT)
    assert lp.fallback_ and lp.method_ == "clock" and lp.features_ == ()
    assert lp.cv_error_ == lp.cv_error_clock_
    q = np.random.default_rng(5).standard_normal((25, 3))
    est = lp.estimate(q)
    assert est.phase == pytest.approx(min(24 * DT / lp.mean_duration_, 1.0))
    assert est.duration == pytest.approx(lp.mean_duration_)
    assert est.speed == pytest.approx(1.0)
    assert 0 < est.std < 1


def test_phase_is_clipped_and_monotone_in_elapsed_time_for_the_clock():
    lp = LearnedPhase().fit(_noise_demos(), dt=DT)
    q = np.zeros((400, 3))
    assert lp.estimate(q).phase == 1.0
    assert lp.estimate(q[:1]).phase == 0.0


@pytest.mark.parametrize("model", ["kernel", "ridge"])
@pytest.mark.parametrize("target", ["phase", "log_duration"])
@pytest.mark.parametrize("features", [None, FEATURE_GROUPS])
def test_tracker_equals_batch_estimate(model, target, features):
    demos = _ramps(np.linspace(1.5, 3.0, 10), n_dofs=3)
    kw = {} if features is None else {"features": features}
    lp = LearnedPhase(model=model, target=target, fallback_se=0.0, **kw).fit(demos, dt=DT)
    assert lp.method_ == model
    test = _ramps([2.4], n_dofs=3, seed=3)[0] + 0.01 * np.random.default_rng(0).standard_normal((49, 3))
    tr = lp.tracker()
    for M in range(1, test.shape[0] + 1):
        on = tr.update(test[M - 1])
        off = lp.estimate(test[:M])
        assert on.phase == pytest.approx(off.phase, abs=1e-10)
        assert on.duration == pytest.approx(off.duration, rel=1e-10)
        assert on.std == off.std
    tr.reset()
    assert tr.update(test[0]).phase == 0.0


@pytest.mark.parametrize("model", ["kernel", "ridge"])
@pytest.mark.parametrize("features", [None, FEATURE_GROUPS])
def test_estimate_checked_equals_estimate_and_reads_the_scaled_frames(model, features):
    """``estimate_checked`` (what LearnedInteraction's stream calls) gives ``estimate``'s numbers bit for bit, and
    the features scale only the frames they read: the same bits as the features of the whole scaled prefix."""
    demos = _ramps(np.linspace(1.5, 3.0, 10), n_dofs=3)
    kw = {} if features is None else {"features": features}
    lp = LearnedPhase(model=model, fallback_se=0.0, **kw).fit(demos, dt=DT)
    test = _ramps([2.4], n_dofs=3, seed=3)[0] + 0.01 * np.random.default_rng(0).standard_normal((49, 3))
    for M in range(1, test.shape[0] + 1):
        Y = np.ascontiguousarray(test[:M])
        a, b = lp.estimate(Y), lp.estimate_checked(Y)
        assert (a.phase, a.duration, a.speed, a.std) == (b.phase, b.duration, b.speed, b.std)
        if M < 2:
            continue
        Ys = Y / lp.scale_  # the whole prefix scaled, then read as the features read it
        k, h = M - 1, lp.history
        back = max(k - lp.window_, 0)
        x = np.arange(1, h + 1) / (h + 1) * k
        lo = x.astype(np.int64)
        f = (x - lo)[:, None]
        ref = {"position": Ys[k], "displacement": Ys[k] - Ys[0], "velocity": (Ys[k] - Ys[back]) / ((k - back) * DT),
               "history": ((1.0 - f) * Ys[lo] + f * Ys[np.minimum(lo + 1, k)] - Ys[0]).ravel()}
        got = lp._raw_features(Y, lp.scale_)
        if features is None:
            assert np.array_equal(got, np.concatenate([ref[g] for g in lp.features_]))
        else:  # path and peak speed: the batch features of the scaled prefix
            want = _prefix_features(Ys, DT, lp.window_, lp.features_, h)[-1]
            assert np.array_equal(got, want)


def test_incremental_features_equal_batch_features():
    rng = np.random.default_rng(1)
    Y = np.cumsum(rng.standard_normal((30, 4)), axis=0)
    F = _prefix_features(Y, DT, 3, FEATURE_GROUPS)
    for k in range(1, 30):
        Fk = _prefix_features(Y[: k + 1], DT, 3, FEATURE_GROUPS)
        np.testing.assert_allclose(Fk[-1], F[k], rtol=0, atol=1e-12)
    assert F.shape == (30, 3 * 4 + 2 + 3 * 4)  # position, displacement, velocity; path, peak; history


def test_times_equal_dt_for_uniform_sampling_and_irregular_times_work():
    demos = _ramps(np.linspace(1.5, 3.0, 10))
    a = LearnedPhase().fit(demos, dt=DT)
    b = LearnedPhase().fit(demos, times=[np.arange(d.shape[0]) * DT + 7.0 for d in demos])
    assert a.dt_ == pytest.approx(b.dt_)
    q = _ramps([2.0], seed=4)[0][:25]
    assert a.estimate(q).phase == pytest.approx(b.estimate(q).phase, abs=1e-9)
    # the same prefix sampled twice as slowly, given by its time stamps
    t = np.arange(0, 25, 2) * DT
    est = a.estimate(q[::2], times=t + 3.0)
    assert est.elapsed == pytest.approx(t[-1])
    assert est.phase == pytest.approx(a.estimate(q).phase, abs=0.02)
    assert a.estimate(q[::2], dt=2 * DT).phase == pytest.approx(est.phase, abs=1e-12)


def test_deterministic():
    demos = _ramps(np.linspace(1.5, 3.0, 12), n_dofs=3)
    demos = [d + 0.02 * np.random.default_rng(i).standard_normal(d.shape) for i, d in enumerate(demos)]
    a = LearnedPhase(model="auto", target="auto").fit(demos, dt=DT)
    b = LearnedPhase(model="auto", target="auto").fit(demos, dt=DT)
    assert (a.method_, a.target_, a.bandwidth_, a.alpha_, a.cv_error_) == \
        (b.method_, b.target_, b.bandwidth_, b.alpha_, b.cv_error_)
    q = demos[3][:20]
    assert a.estimate(q) == b.estimate(q)


def test_any_number_of_dofs_and_one_dof():
    for D in (1, 9):
        demos = _ramps(np.linspace(1.5, 3.0, 8), n_dofs=D)
        lp = LearnedPhase().fit(demos, dt=DT)
        assert lp.n_dofs_ == D
        est = lp.estimate(demos[0][:15])
        assert 0.0 <= est.phase <= 1.0 and est.duration > 0 and est.std >= 0


def test_errors_have_clear_messages():
    demos = _ramps(np.linspace(1.5, 3.0, 6))
    with pytest.raises(ValueError, match="at least 3 demonstrations"):
        LearnedPhase().fit(demos[:2], dt=DT)
    with pytest.raises(ValueError, match=r"demos\[2\] has 3 columns"):
        LearnedPhase().fit(demos[:2] + [np.zeros((20, 3))] + demos[3:], dt=DT)
    bad = [d.copy() for d in demos]
    bad[1][4, 0] = np.nan
    with pytest.raises(ValueError, match=r"demos\[1\].*non-finite.*frame 4"):
        LearnedPhase().fit(bad, dt=DT)
    with pytest.raises(ValueError, match="exactly one of dt"):
        LearnedPhase().fit(demos)
    with pytest.raises(ValueError, match="exactly one of dt"):
        LearnedPhase().fit(demos, dt=DT, times=[np.arange(d.shape[0]) for d in demos])
    with pytest.raises(ValueError, match="dt must be a positive"):
        LearnedPhase().fit(demos, dt=-1.0)
    with pytest.raises(ValueError, match="features: unknown group"):
        LearnedPhase(features=("position", "acceleration")).fit(demos, dt=DT)
    with pytest.raises(ValueError, match="model must be"):
        LearnedPhase(model="forest").fit(demos, dt=DT)
    with pytest.raises(TypeError, match="list of"):
        LearnedPhase().fit(np.zeros((5, 3)), dt=DT)
    with pytest.raises(NotFittedError, match="not fitted"):
        LearnedPhase().estimate(demos[0])
    lp = LearnedPhase().fit(demos, dt=DT)
    with pytest.raises(ValueError, match="partial has 3 columns, expected 2"):
        lp.estimate(np.zeros((5, 3)))
    with pytest.raises(ValueError, match="partial.*non-finite"):
        lp.estimate(np.full((5, 2), np.nan))
    with pytest.raises(ValueError, match=r"frame must have shape \(2,\)"):
        lp.tracker().update(np.zeros(3))


def test_a_tracking_glitch_is_not_extrapolated():
    """Query features are clipped to the demonstrations' range at the same elapsed time."""
    durs = np.linspace(1.5, 3.0, 16)
    demos = [d + 0.01 * np.random.default_rng(i).standard_normal(d.shape)
             for i, d in enumerate(_ramps(durs, n_dofs=4))]
    for model in ("ridge", "kernel"):
        lp = LearnedPhase(model=model, fallback_se=0.0).fit(demos, dt=DT)
        q = _ramps([2.2], n_dofs=4, seed=7)[0][:25].copy()
        clean = lp.estimate(q).phase
        q[-1, 3] += 50.0  # one DoF jumps by 50 standard deviations in the last frame
        glitch = lp.estimate(q).phase
        assert 0.0 <= glitch <= 1.0
        assert abs(glitch - clean) < 0.15


def test_shared_fits_learn_the_same_timing_once():
    """Inside ``shared_fits`` (the default model's fit) a second LearnedPhase with equal settings on bit-equal
    demonstrations (other arrays, e.g. the IP's latent copy of the observed columns) takes the first fit's state
    instead of fitting again; its estimates are those of a separate fit; other data or settings fit anew."""
    from interprim.core.cache import shared_fits

    demos = [d + 0.02 * np.random.default_rng(i).standard_normal(d.shape)
             for i, d in enumerate(_ramps(np.linspace(1.5, 3.0, 10), n_dofs=3))]
    alone = LearnedPhase().fit(demos, dt=DT)
    learned = []
    orig = LearnedPhase._learn

    def spy(self, *args, **kwargs):
        learned.append(self)
        return orig(self, *args, **kwargs)

    LearnedPhase._learn = spy
    try:
        with shared_fits():
            a = LearnedPhase().fit(demos, dt=DT)
            b = LearnedPhase().fit([np.array(d[:, :], order="F") for d in demos], dt=DT)  # equal values, new arrays
            c = LearnedPhase().fit(demos[1:], dt=DT)  # other data
            d = LearnedPhase(history=2).fit(demos, dt=DT)  # other settings
            e = LearnedPhase().fit(demos, dt=2 * DT)  # another sampling interval
        f = LearnedPhase().fit(demos, dt=DT)  # outside: fitted again
    finally:
        LearnedPhase._learn = orig
    assert learned == [a, c, d, e, f]
    assert b.std_grid_ is a.std_grid_ and b.history == 3
    for model in (a, b, f):
        np.testing.assert_array_equal(model.std_grid_, alone.std_grid_)
        for q in (demos[2][:15], demos[5][:30]):
            assert model.estimate(q) == alone.estimate(q)
    assert d.history == 2 and not np.array_equal(c.durations_, a.durations_)

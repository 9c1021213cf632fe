"""Blend(remaining=lam): beyond the real-time band every member runs to one shared end; inside it nothing changes."""

import numpy as np
import pytest

from interprim.model_selection.realtime import place_in_time
from interprim.models.blend import Blend
from interprim.models.demonstrations import NearestNeighbour, PriorMean
from interprim.synthetic import two_agent_demos


@pytest.fixture(scope="module")
def parts():
    demos = two_agent_demos(8, seed=2, frames=80, noise=0.01)
    dt = 0.05
    members = {"nn": NearestNeighbour([0, 1]).fit(demos, dt=dt), "prior": PriorMean([0, 1]).fit(demos, dt=dt)}
    weights = {"nn": [0.7, 0.2, 0.1], "prior": [0.3, 0.8, 0.9]}
    own = Blend.from_fitted([0, 1], members, weights, None, demos, dt, horizon=0.25, bands=[0.25, 0.5, 4.0])
    shared = Blend.from_fitted([0, 1], members, weights, None, demos, dt, horizon=0.25, bands=[0.25, 0.5, 4.0],
                               remaining=0.0)
    return demos, dt, members, own, shared


def test_the_shared_end_is_the_clocks_remaining_duration_and_holds_the_members_ends(parts):
    demos, dt, members, own, shared = parts
    test = demos[3]
    k = 30
    pred = shared.predict(test[:k, [0, 1]])
    R = shared.mean_duration_ - (k - 1) * dt  # lam = 0: the clock's remaining duration
    assert (1.0 - pred.normalised_time) * pred.duration == pytest.approx(R, rel=1e-9)
    w_end = shared.weights_at(R)[0]
    ends = np.array([members[m].predict(test[:k, [0, 1]]).trajectory(201)[-1] for m in shared._names])
    assert pred.trajectory(201)[-1] == pytest.approx(w_end @ ends, abs=1e-9)


def test_the_real_time_band_is_the_same_as_with_the_members_own_timing(parts):
    demos, dt, members, own, shared = parts
    test = demos[5]
    for k in (20, 40):
        a, b = own.predict(test[:k, [0, 1]]), shared.predict(test[:k, [0, 1]])
        t = np.arange(1, 6) * dt  # the next 0.25 s
        ya, yb = [], []
        for p, out in ((a, ya), (b, yb)):
            s, D = place_in_time(p, k, dt, own.mean_duration_)
            Y = p.trajectory(2001)
            g = np.linspace(0.0, 1.0, 2001)
            out.append(np.stack([np.interp(s + t / D, g, Y[:, j]) for j in range(Y.shape[1])], axis=1))
        assert np.max(np.abs(ya[0] - yb[0])) < 2e-3 * np.max(np.abs(test))


def test_the_shared_timing_is_saved_and_restored(parts, tmp_path):
    import interprim as ip

    demos, dt, members, own, shared = parts
    path = tmp_path / "blend.npz"
    shared.save(path)
    back = ip.load_any(path)
    assert back.remaining == 0.0
    x = demos[2][:25, [0, 1]]
    assert back.predict(x).trajectory(50) == pytest.approx(shared.predict(x).trajectory(50))


@pytest.mark.parametrize("lam", [None, 0.0, 0.5, 1.0, "nn"])
def test_the_blend_places_its_members_by_the_long_range_formulas(parts, lam):
    """Blend.combine repeats, on scalars, what long_range.remaining_duration and member_units compute for the
    inner cross-validation's cases: the two must place every member alike (the selection scores what is run)."""
    from interprim.core.preprocessing import interp_columns
    from interprim.model_selection.long_range import member_units, pace_remaining, remaining_duration

    demos, dt, members, own, _ = parts
    weights = {"nn": [0.7, 0.2, 0.1], "prior": [0.3, 0.8, 0.9]}
    blend = Blend.from_fitted([0, 1], members, weights, None, demos, dt, horizon=0.25, bands=[0.25, 0.5, 4.0],
                              remaining=lam)
    test = demos[4]
    for k in (6, 25, 50, 70):
        preds = {m: members[m].predict(test[:k, [0, 1]]) for m in blend._names}
        got = blend.combine(preds, k)
        _, Y, W, ahead = got._parts
        timing = np.array([place_in_time(preds[m], k, dt, blend.mean_duration_) for m in blend._names])
        w0 = blend._w_now
        s, D = float(w0 @ timing[:, 0]), float(w0 @ timing[:, 1])
        R = None
        if isinstance(lam, str):  # the named member's own remaining duration
            R = max(float(pace_remaining(*timing[blend._names.index(lam)])), 0.25)
            D = R / (1.0 - s) if s < 1.0 - 1e-9 else D
        elif lam is not None:
            R = max(float(remaining_duration(timing[:, :1], timing[:, 1:], (k - 1) * dt, blend.mean_duration_, w0,
                                             lam)[0]), 0.25)
            D = R / (1.0 - s) if s < 1.0 - 1e-9 else D
        u = np.linspace(0.0, 1.0, Y.shape[1])
        np.testing.assert_allclose(ahead, np.clip((u - s) * D, 0.0, None), rtol=0, atol=1e-12)
        for j, m in enumerate(blend._names):
            sm, Dm = timing[j]
            future = member_units([sm], [Dm], ahead, None if R is None else [R], 0.25)[0]
            um = np.clip(np.where(u >= s, future, u * (sm / s if s > 0 else 1.0)), 0.0, 1.0)
            want = interp_columns(um, u, preds[m].trajectory(len(u)))
            np.testing.assert_allclose(Y[j], want, rtol=0, atol=1e-12)


def test_a_member_of_weight_0_can_time_the_blend_with_its_own_remaining_duration(parts, tmp_path):
    """Blend(remaining="nn"): the shared end is the nearest demonstration's own remaining duration while the mean
    carries every band; streamed frame by frame it equals predict, and it is saved and restored."""
    import interprim as ip
    from interprim.model_selection.long_range import pace_remaining

    demos, dt, members, own, _ = parts
    weights = {"nn": [0.0, 0.0, 0.0], "prior": [1.0, 1.0, 1.0]}
    blend = Blend.from_fitted([0, 1], members, weights, None, demos, dt, horizon=0.25, bands=[0.25, 0.5, 4.0],
                              remaining="nn")
    alone = Blend.from_fitted([0, 1], {"prior": members["prior"]}, {"prior": [1.0, 1.0, 1.0]}, None, demos, dt,
                              horizon=0.25, bands=[0.25, 0.5, 4.0], remaining=0.0)
    test = demos[6]
    k = 30
    x = test[:k, [0, 1]]
    pred = blend.predict(x)
    s_nn, D_nn = place_in_time(members["nn"].predict(x), k, dt, blend.mean_duration_)
    R = float(pace_remaining(s_nn, D_nn))
    assert R > 0.25 and abs(R - (blend.mean_duration_ - (k - 1) * dt)) > 0.05  # not the clock's end here
    assert (1.0 - pred.normalised_time) * pred.duration == pytest.approx(R, rel=1e-9)
    # the mean played to that end: its own normalised time now, then linearly to 1 at R seconds from now
    s = pred.normalised_time
    u = np.linspace(0.0, 1.0, 201)
    ahead = np.clip((u - s) * pred.duration, 0.0, None)
    from interprim.model_selection.long_range import member_units

    um = np.where(u >= s, member_units([s], [blend.mean_duration_], ahead, [R], 0.25)[0], u)
    want = members["prior"].predict(x)
    from interprim.core.preprocessing import interp_columns

    np.testing.assert_allclose(pred.mean, interp_columns(um, u, want.trajectory(201)), rtol=0, atol=1e-12)
    assert not np.allclose(pred.mean, alone.predict(x).mean, atol=1e-6)  # the clock's end places it elsewhere
    # streamed == predicted, every frame
    st = blend.stream()
    for i in range(k):
        got = st.update(x[i])
    np.testing.assert_allclose(got.mean, pred.mean, rtol=0, atol=1e-12)
    assert got.duration == pytest.approx(pred.duration, rel=1e-12)
    # saved and restored
    path = tmp_path / "paced.npz"
    blend.save(path)
    back = ip.load_any(path)
    assert back.remaining == "nn" and back.past is None and Blend.STATE_VERSION == 4
    np.testing.assert_allclose(back.predict(x).mean, pred.mean, rtol=0, atol=1e-12)


def test_a_shared_end_named_after_no_member_is_refused(parts):
    demos, dt, members, own, _ = parts
    with pytest.raises(ValueError, match="names no member"):
        Blend.from_fitted([0, 1], {"prior": members["prior"]}, {"prior": 1.0}, None, demos, dt, remaining="nn")

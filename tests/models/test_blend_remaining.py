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

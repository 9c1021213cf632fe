"""The robot's past (before now, in normalised time) by its own weights: long_range.past_choice on the inner
folds, Blend(past=...) when predicting and streaming, saved and restored."""

import numpy as np
import pytest

from interprim.model_selection.long_range import _past_errors, _past_fit, past_cases, past_choice
from interprim.model_selection.stacking import CrossValidation, case_rms_loss

G = 101


def _cv(trajs: dict, truth_shape=None, n_demo=12, per=3, seed=0):
    """A cross-validation whose members' predictions on normalised time are ``trajs`` ``{name: (G, 2)}`` (plus a
    little noise of their own per case), every member at the true phase, the held-out demonstrations
    ``truth_shape`` plus a per-recording offset of the controlled column."""
    rng = np.random.default_rng(seed)
    truth_shape = SHAPE if truth_shape is None else truth_shape
    n_case = n_demo * per
    cv = object.__new__(CrossValidation)
    cv.names = list(trajs)
    cv.observed, cv.controlled, cv.point_dim = [0], [1], 1
    cv.demo = np.repeat(np.arange(n_demo), per)
    phase = np.tile([0.4, 0.6, 0.8], n_demo)
    cv.phase = np.stack([phase] * len(cv.names))
    cv.duration = np.ones((len(cv.names), n_case))
    cv.traj = np.stack([np.broadcast_to(trajs[m], (n_case, G, 2)) + rng.normal(0.0, 0.01, (n_case, G, 2))
                        for m in cv.names])
    offsets = rng.normal(0.0, 0.02, n_demo)
    cv.unit_truth = {j: truth_shape + np.array([0.0, offsets[j]]) for j in range(n_demo)}
    return cv


_u = np.linspace(0.0, 1.0, G)
SHAPE = np.stack([_u, np.sin(np.pi * _u)], axis=1)
OFF = SHAPE + np.array([0.0, 0.5]) * (_u < 0.7)[:, None]  # wrong in the past, right in the future


def test_the_past_is_read_where_the_blend_places_it():
    """past_cases reads member m at u s_m / s before the blend's phase s (Blend's rule), the controlled agent."""
    cv = _cv({"a": SHAPE, "b": OFF})
    cv.phase[1] *= 0.5  # member b says half as far: read at half the normalised time
    w = np.array([0.5, 0.5])
    P, T, mask = past_cases(cv, w)
    s = w @ cv.phase
    c = 4
    assert np.array_equal(mask[c], _u < s[c])
    want = np.interp(_u * cv.phase[1, c] / s[c], _u, cv.traj[1, c, :, 1])
    np.testing.assert_allclose(P[1, c, :, 0], want, rtol=0, atol=1e-12)
    np.testing.assert_allclose(T[c, :, 0], cv.unit_truth[int(cv.demo[c])][:, 1], rtol=0, atol=0)


def test_the_fitted_past_weights_minimise_the_mean_rms_over_the_past():
    """case_rms_loss over the past equals the mean of the cases' RMS errors (and its gradient the finite
    differences'); _past_fit's weights are no worse than any vertex or random weights on the simplex."""
    rng = np.random.default_rng(1)
    M, C, K = 3, 2, 20
    P = rng.normal(size=(M, C * 10, K, 2))
    T = rng.normal(size=(C * 10, K, 2)) + 0.5 * P[0]
    mask = rng.random((C * 10, K)) < 0.6
    mask[:, 0] = True
    m = mask.astype(float)
    E = P - T[None]
    loss = case_rms_loss(np.einsum("cg,mcgk,ncgk->cmn", m, E, E), np.einsum("cg,mcgk,cgk->cm", m, E, T),
                         np.einsum("cg,cgk->c", m, T * T), m.sum(axis=1) * 2)
    w = rng.dirichlet(np.ones(M))
    assert loss(w)[0] == pytest.approx(float(np.mean(_past_errors(P, T, mask, w, 1))), abs=1e-10)
    eps = 1e-6
    fd = [(loss(w + eps * np.eye(M)[i])[0] - loss(w - eps * np.eye(M)[i])[0]) / (2 * eps) for i in range(M)]
    np.testing.assert_allclose(loss(w)[1], fd, rtol=1e-5, atol=1e-7)
    best = _past_fit(P, T, mask)
    assert best.sum() == pytest.approx(1.0) and np.all(best >= 0)
    floor = float(np.mean(_past_errors(P, T, mask, best, 1)))
    for v in list(np.eye(M)) + list(rng.dirichlet(np.ones(M), 20)):
        assert floor <= float(np.mean(_past_errors(P, T, mask, v, 1))) + 1e-9


def test_the_real_time_weights_are_kept_unless_another_past_is_better_by_more_than_its_noise():
    """Member "a" (all the real-time weight) reconstructs the past badly and "b" well: the fitted weights win by far
    more than their noise and put the weight on "b"; when "b" says what "a" says the real-time weights stay (None)."""
    cv = _cv({"a": OFF, "b": SHAPE, "prior": SHAPE + 0.2})
    w, name, table = past_choice(cv, [1.0, 0.0, 0.0])
    assert list(table) == ["real-time weights", "prior", "fitted"]
    assert name == "fitted" and w[1] > 0.9
    assert table["real-time weights"]["vs_best"] > 5 * table["real-time weights"]["se"]
    cv = _cv({"a": SHAPE, "b": SHAPE, "prior": SHAPE + 0.2})
    cv.traj[1] = cv.traj[0]  # "b" says what "a" says: no combination reconstructs the past better
    w, name, table = past_choice(cv, [1.0, 0.0, 0.0])
    assert w is None and name == "real-time weights"
    assert table["prior"]["vs_best"] > table["prior"]["se"]  # the mean is worse by more than its noise


def test_a_blend_reads_its_past_with_its_past_weights_and_its_future_as_before(blend_parts, tmp_path):
    """Blend(past={"prior": 1}) with all the band weight on "nn": before now the mean, read where the blend places
    it (u s_prior / s), after now what the blend without ``past`` gives; streamed = predicted; saved and restored."""
    import interprim as ip
    from interprim.core.preprocessing import interp_columns
    from interprim.model_selection.realtime import place_in_time
    from interprim.models.blend import Blend

    demos, dt, members = blend_parts
    weights = {"nn": [1.0, 1.0], "prior": [0.0, 0.0]}
    kw = dict(horizon=0.25, bands=[0.25, 4.0])
    plain = Blend.from_fitted([0, 1], members, weights, None, demos, dt, **kw)
    paced = Blend.from_fitted([0, 1], members, weights, None, demos, dt, past={"prior": 1.0}, **kw)
    x = demos[3][:35, [0, 1]]
    a, b = plain.predict(x), paced.predict(x)
    u = np.linspace(0.0, 1.0, Blend.N_GRID)
    s = b.normalised_time
    past = u < s
    assert 0.2 < s < 0.9 and a.normalised_time == s
    np.testing.assert_array_equal(b.mean[~past], a.mean[~past])
    sp, _ = place_in_time(members["prior"].predict(x), len(x), dt, paced.mean_duration_)
    want = interp_columns(u[past] * sp / s, u, members["prior"].predict(x).trajectory(Blend.N_GRID))
    np.testing.assert_allclose(b.mean[past], want, rtol=0, atol=1e-12)
    assert np.max(np.abs(b.mean[past] - a.mean[past])) > 1e-3  # the past did change
    st = paced.stream()
    for f in x:
        q = st.update(f)
    np.testing.assert_array_equal(q.mean, b.mean)
    path = tmp_path / "past.npz"
    paced.save(path)
    back = ip.load_any(path)
    assert back.past == {"prior": 1.0}
    np.testing.assert_array_equal(back.predict(x).mean, b.mean)


@pytest.mark.parametrize("past, match", [({"kernel": 1.0}, "not members"), ({"prior": -1.0}, "non-negative"),
                                         ({"prior": 0.0}, "not all zero"), ({}, "non-empty"),
                                         ({"prior": float("nan")}, "finite")])
def test_bad_past_weights_are_refused(blend_parts, past, match):
    from interprim.models.blend import Blend

    demos, dt, members = blend_parts
    with pytest.raises(ValueError, match=match):
        Blend.from_fitted([0, 1], members, {"nn": 1.0, "prior": 0.0}, None, demos, dt, past=past)

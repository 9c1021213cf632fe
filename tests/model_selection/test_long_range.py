"""The blend beyond the real-time band: the shared remaining duration and the weights chosen on the rest of the
movement with the one-standard-error rule (interprim.model_selection.long_range)."""

import numpy as np
import pytest

from interprim.model_selection.long_range import long_range_choice, member_units, remaining_duration, timing_choice
from interprim.model_selection.stacking import CrossValidation, look_ahead_bands, weights_at


def test_remaining_duration_shrinks_the_members_estimate_toward_the_clock():
    phase = np.array([[0.5], [0.25]])
    duration = np.array([[2.0], [4.0]])  # remaining 1 s and 3 s: 2 s with equal weights
    for lam, want in ((0.0, 1.5), (0.5, 1.75), (1.0, 2.0)):  # the clock: 2.5 s - 1 s elapsed
        assert remaining_duration(phase, duration, [1.0], 2.5, [0.5, 0.5], lam) == pytest.approx([want])
    assert remaining_duration(phase, duration, [3.0], 2.5, [0.5, 0.5], 0.0) == pytest.approx([0.0])  # past its end


def test_members_keep_their_own_speed_in_the_real_time_band_and_then_run_to_the_shared_end():
    t = np.array([0.1, 0.25, 1.0, 1.5, 2.0])
    u = member_units([0.5], [2.0], t, [1.5], horizon=0.25)[0]
    # own speed 1/2 per second up to 0.25 s (0.625), then the remaining 0.375 over the 1.25 s left
    assert u == pytest.approx([0.55, 0.625, 0.625 + 0.75 * 0.375 / 1.25, 1.0, 1.0])
    assert member_units([0.5], [2.0], t, None, horizon=0.25)[0] == pytest.approx([0.55, 0.625, 1.0, 1.0, 1.0])


def _cv(members: dict, truth, n_demo, dt=0.05, horizon=0.25):
    """A cross-validation of the given placed predictions ``{name: (cases, H, 2)}`` (column 0 observed)."""
    cv = object.__new__(CrossValidation)
    cv.names = list(members)
    cv.mean = np.stack([members[m] for m in cv.names])
    cv.truth = truth
    n_case, H, _ = truth.shape
    cv.valid = np.ones((n_case, H), dtype=bool)
    cv.observed, cv.controlled = [0], [1]
    cv.horizon, cv.dt, cv.point_dim = horizon, dt, 1
    cv.t_ahead = np.arange(1, H + 1) * dt
    cv.errors = {m: 0.0 for m in cv.names}
    cv.demo = np.repeat(np.arange(n_demo), n_case // n_demo)
    return cv


def _stacked(cv):
    edges = [float(e) for e in look_ahead_bands(cv.horizon, float(cv.t_ahead[-1]))]
    steps = cv.band_steps(edges)
    return np.array([cv.blend_weights(s) for s in steps]), [float(cv.t_ahead[s[-1]]) for s in steps]


def test_the_mean_is_kept_when_the_members_are_no_better_than_noise():
    rng = np.random.default_rng(3)
    n_demo, per, H = 12, 4, 40
    truth = np.broadcast_to(np.sin(np.linspace(0.0, 3.0, H))[None, :, None], (n_demo * per, H, 2)).copy()
    prior = truth + rng.normal(0.0, 1.0, truth.shape)
    # two members: the mean plus noise of their own (no information the mean lacks)
    members = {"prior": prior, "a": prior + rng.normal(0.0, 0.05, truth.shape),
               "b": prior + rng.normal(0.0, 0.05, truth.shape)}
    cv = _cv(members, truth, n_demo)
    W, edges = _stacked(cv)
    Wc, ec, name, table = long_range_choice(cv, W, edges, prefer="simple")
    assert name == "prior"
    assert np.allclose(Wc[2:], [1.0, 0.0, 0.0]) and np.allclose(Wc[0], W[0])
    # the real-time band keeps the per-band schedule's weights (to a step): the move to the mean starts after it
    assert ec[:2] == pytest.approx([edges[0], edges[0] + cv.dt]) and ec[2:] == edges[1:]
    rt_steps = cv.t_ahead <= cv.horizon - cv.dt + 1e-12
    got, want = weights_at(cv.t_ahead[rt_steps], ec, Wc), weights_at(cv.t_ahead[rt_steps], edges, W)
    assert np.max(np.abs(got - want)) <= np.max(np.abs(W[1] - W[0])) * cv.dt / (edges[1] - edges[0]) * 2 + 1e-12
    assert table["prior"]["vs_best"] <= table["prior"]["se"]
    # a member that knows the future better than the noise: chosen whichever end the rule starts from
    members["a"] = truth + rng.normal(0.0, 0.2, truth.shape)
    cv = _cv(members, truth, n_demo)
    W, edges = _stacked(cv)
    for prefer in ("simple", "fitted"):
        Wc, ec, name, _ = long_range_choice(cv, W, edges, prefer=prefer)
        assert name != "prior"
        per_step = weights_at(cv.t_ahead, ec, Wc)
        assert np.all(per_step[cv.t_ahead > 0.5, 1] > 0.9)  # "a" carries the long look-ahead


def test_timing_choice_keeps_the_members_own_timing_when_it_is_what_the_truth_does():
    """Members that are the truth placed at their own duration: re-placing them at the clock's remaining duration
    can only be worse, so the members' own timing is kept."""
    cv, _ = _own_timing_cv(5)
    H = len(cv.t_ahead)
    lam, table = timing_choice(cv, np.ones((H, 1)), prefer="simple")
    assert lam is not None or table["0"]["vs_best"] > table["0"]["se"]
    assert table["own"]["error"] == pytest.approx(0.0, abs=1e-3)
    assert table["1"]["error"] == pytest.approx(0.0, abs=1e-3)  # the members' own end is the truth's end
    assert table["0"]["error"] > 0.01  # the clock's end is not
    assert lam in (1.0, None)


def test_inner_yardsticks_have_the_known_answers_of_the_truth_and_of_the_clock():
    from interprim.model_selection.long_range import inner_yardsticks

    dt, H, G = 0.05, 60, 201
    grid = np.linspace(0.0, 1.0, G)
    rng = np.random.default_rng(6)
    n_demo, per = 8, 3
    n_case = n_demo * per
    frames = np.repeat(rng.integers(30, 50, n_demo), per)  # recordings of 30-49 frames
    durations = (frames - 1) * dt
    k = np.tile([10, 18, 24], n_demo)
    elapsed = (k - 1) * dt
    shape = np.stack([grid, np.sin(np.pi * grid)], axis=1)
    t = np.arange(1, H + 1) * dt
    u_true = (elapsed[:, None] + t[None, :]) / durations[:, None]
    truth = np.stack([np.stack([np.interp(np.clip(u, 0, 1), grid, shape[:, j]) for j in range(2)], axis=1)
                      for u in u_true])
    md = 2.0
    mean_traj = shape + np.array([0.0, 0.1])  # the mean: the shape moved by 0.1
    clock_u = np.clip((elapsed[:, None] + t[None, :]) / md, 0, 1)
    clock = np.stack([np.stack([np.interp(u, grid, mean_traj[:, j]) for j in range(2)], axis=1) for u in clock_u])
    cv = _cv({"m": truth, "prior": clock}, truth, n_demo, dt=dt)
    cv.traj = np.stack([np.broadcast_to(shape, (n_case, G, 2)), np.broadcast_to(mean_traj, (n_case, G, 2))])
    cv.phase = np.stack([elapsed / durations, np.minimum(elapsed / md, 1.0)])
    cv.duration = np.stack([durations, np.full(n_case, md)])
    cv.elapsed, cv.mean_duration = elapsed, np.full(n_case, md)
    cv.valid = np.arange(H)[None, :] < (frames - k)[:, None]
    cv.unit_truth = {j: shape for j in range(n_demo)}
    edges = [0.25, 0.5, 1.0, 3.0]
    truth_only = inner_yardsticks(cv, np.tile([1.0, 0.0], (4, 1)), edges, None)
    assert len(truth_only) == 5 and all(v[0] < 0.02 for v in truth_only.values())
    mean_only = inner_yardsticks(cv, np.tile([0.0, 1.0], (4, 1)), edges, None)
    assert mean_only["rest of the movement ÷ clock"][0] == pytest.approx(1.0)  # the mean, played by the clock
    assert mean_only["real time ÷ clock"][0] == pytest.approx(1.0)
    assert mean_only["whole movement at 60 % ÷ the mean demonstration"][0] == pytest.approx(1.0)


def _own_timing_cv(seed=5):
    """One member "m", the truth's shape placed at each recording's own duration (the case's true timing)."""
    dt, H, G = 0.05, 40, 201
    grid = np.linspace(0.0, 1.0, G)
    rng = np.random.default_rng(seed)
    n_demo, per = 10, 3
    n_case = n_demo * per
    durations = np.repeat(rng.uniform(1.5, 3.0, n_demo), per)
    elapsed = np.tile([0.3, 0.5, 0.7], n_demo) * durations
    shape = np.stack([grid, np.sin(np.pi * grid)], axis=1)
    t = np.arange(1, H + 1) * dt
    u_true = (elapsed[:, None] + t[None, :]) / durations[:, None]
    truth = np.stack([np.stack([np.interp(np.clip(u, 0, 1), grid, shape[:, j]) for j in range(2)], axis=1)
                      for u in u_true])
    cv = _cv({"m": truth}, truth, n_demo, dt=dt)
    cv.traj = np.broadcast_to(shape, (1, n_case, G, 2)).copy()
    cv.phase = (elapsed / durations)[None, :]
    cv.duration = durations[None, :]
    cv.elapsed = elapsed
    cv.mean_duration = np.full(n_case, 2.2)
    cv.valid = u_true <= 1.0
    cv.w0 = np.ones(1)
    return cv, durations - elapsed


def test_the_shared_end_of_a_named_member_is_its_own_remaining_duration():
    from interprim.model_selection.long_range import pace_remaining, shared_end

    assert pace_remaining([0.25, 0.5, 1.2], [2.0, 3.0, 2.0]) == pytest.approx([1.5, 1.5, 0.0])  # none past the end
    cv, R_true = _own_timing_cv()
    assert shared_end(cv, None) is None
    assert shared_end(cv, "m") == pytest.approx(R_true)  # the member's own timing is the truth's here
    assert shared_end(cv, 0.0) == pytest.approx(np.clip(2.2 - cv.elapsed, 0.0, None))  # the clock's
    with pytest.raises(ValueError, match="names no member"):
        shared_end(cv, "learned")


def test_timing_choice_takes_the_partners_pace_first_unless_it_is_worse_by_more_than_its_noise():
    cv, R_true = _own_timing_cv()
    per_step = np.ones((cv.truth.shape[1], 1))
    lam, table = timing_choice(cv, per_step, pace=("p", R_true))
    assert lam == "p"  # the pace's end is the truth's: tried first, and the best
    assert list(table)[0] == "p" and table["p"]["error"] == pytest.approx(0.0, abs=1e-3)
    # a pace 60 % too slow: worse than the members' own end by more than its noise, so not taken
    lam, table = timing_choice(cv, per_step, pace=("p", 1.6 * R_true))
    assert lam in (1.0, None)
    assert table["p"]["error"] > 0.05 and table["p"]["vs_best"] > table["p"]["se"]
    # without a pace the candidates are the former ones
    lam, table = timing_choice(cv, per_step)
    assert list(table) == ["0", "0.5", "1", "own"] and lam in (1.0, None)


def test_refine_keeps_the_pace_family_at_weight_0_when_it_times_the_blend_better_than_the_clock():
    """A member "a" of the right shape played by the clock, and "learned" of a wrong shape (no weight in any band)
    whose phase and duration are each recording's true ones: the blend keeps "a" alone for its shape and "learned"
    at weight 0 for its timing; with a budget that cannot afford both, the pace is not a candidate."""
    from interprim.model_selection.long_range import refine, replaced
    from interprim.model_selection.stacking import stack

    dt, H, G = 0.05, 60, 201
    grid = np.linspace(0.0, 1.0, G)
    rng = np.random.default_rng(7)
    n_demo, per = 12, 3
    n_case = n_demo * per
    durations = np.repeat(rng.uniform(1.5, 3.0, n_demo), per)
    elapsed = np.tile([0.3, 0.5, 0.7], n_demo) * durations
    t = np.arange(1, H + 1) * dt
    u_true = (elapsed[:, None] + t[None, :]) / durations[:, None]

    def placed(Y, u):
        return np.stack([np.stack([np.interp(np.clip(v, 0, 1), grid, Y[:, j]) for j in range(2)], axis=1)
                         for v in u])

    shape = np.stack([grid, np.sin(np.pi * grid)], axis=1)
    wrong = shape + np.array([0.0, 50.0])
    md = float(np.mean(durations))
    truth = placed(shape, u_true)
    cv = _cv({"a": placed(shape, (elapsed[:, None] + t[None, :]) / md), "learned": placed(wrong, u_true)}, truth,
             n_demo, dt=dt)
    cv.traj = np.stack([np.broadcast_to(shape, (n_case, G, 2)), np.broadcast_to(wrong, (n_case, G, 2))]).copy()
    cv.phase = np.stack([np.minimum(elapsed / md, 1.0), elapsed / durations])
    cv.duration = np.stack([np.full(n_case, md), durations])
    cv.elapsed, cv.mean_duration = elapsed, np.full(n_case, md)
    cv.valid = u_true <= 1.0
    cv.unit_truth = {j: shape for j in range(n_demo)}
    fitted = stack(cv, 0.25, scales=False)
    assert fitted.names == ["a"]  # the wrong shape carries no weight
    st, lam = refine(cv, fitted, 0.25)
    assert lam == "learned" and st.names == ["a", "learned"]
    assert np.all(st.W[:, 0] == 1.0) and np.all(st.W[:, 1] == 0.0)
    assert st.record["long_range"]["remaining"] == "learned"
    assert st.record["band_weights"]["learned"] == [0.0] * len(st.edges)
    table = st.record["long_range"]["remaining_table"]
    assert list(table)[0] == "learned" and table["learned"]["error"] < 0.5 * table["0"]["error"]
    # "a" placed with the pace's end (R = each recording's true remaining duration): at its shape's end from the
    # first step after the recording's end, not before it
    one = cv.subset(["a"])
    one.mean = replaced(one, "learned", durations - elapsed)
    after = cv.valid.sum(axis=1)  # the first step past the held-out movement
    rows = np.flatnonzero(after < H)
    assert len(rows) > n_case // 2
    assert one.mean[0, rows, after[rows]] == pytest.approx(np.tile(shape[-1], (len(rows), 1)), abs=1e-12)
    assert np.all(np.abs(one.mean[0, rows, after[rows] - 2, 0] - 1.0) > 1e-3)
    # a budget that affords "a" but not "a" with "learned": the clock's or the members' own timing, no pace
    st, lam = refine(cv, fitted, 0.25, cost=lambda names: float(len(names)), budget=1.5)
    assert not isinstance(lam, str) and st.names == ["a"]
    assert "learned" not in st.record["long_range"]["remaining_table"]
    st, lam = refine(cv, fitted, 0.25, pace=None)
    assert not isinstance(lam, str) and "learned" not in st.record["long_range"]["remaining_table"]

"""AutoInteraction: the family chosen by cross-validation on the training demonstrations."""

import dataclasses

import numpy as np
import pytest

import interprim as ip
from interprim.evaluation.realtime import RealTimeConfig, choose_method, default_methods
from interprim.model_selection import stacking
from interprim.synthetic import benchmark_tasks


@pytest.fixture(scope="module")
def task():
    return benchmark_tasks(10, seed=0, names=("handover",))["handover"], \
        benchmark_tasks(3, seed=1, names=("handover",))["handover"]


@pytest.fixture(scope="module")
def auto(task):
    dev, _ = task
    return ip.AutoInteraction([0, 1], candidates=("kernel", "nn", "prior"), combine="best").fit(dev.demos, dt=dev.dt)


@pytest.fixture(scope="module")
def blend(task):
    dev, _ = task
    return ip.AutoInteraction([0, 1], candidates=("kernel", "nn", "prior")).fit(dev.demos, dt=dev.dt)


def test_chooses_the_family_with_the_smallest_held_out_error(auto, task):
    dev, _ = task
    make = {m: f for m, f in default_methods([0, 1]).items() if m in ("kernel", "nn", "prior")}
    cfg = RealTimeConfig(stride=3, max_frames=auto.max_prefixes)  # the fit's protocol
    chosen, errors = choose_method(make, dev.demos, [0, 1], dev.dt, cfg, k=3)
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


def test_blend_weights_minimise_the_held_out_error_and_never_lose_to_the_best_family(blend, task):
    dev, _ = task
    s = blend.selection_
    w = blend.weights_
    assert s["combine"] == "blend" and set(w) <= {"kernel", "nn", "prior"}
    assert sum(w.values()) == pytest.approx(1.0) and all(0 <= x <= 1 for x in w.values())
    # the blend's in-sample CV error is at most the best family's (a vertex of the simplex is a candidate) ...
    assert s["blend_cv_error"] <= s["cv_errors"][blend.chosen_] + 1e-12
    assert s["blend_vs_best"] <= 1.0 + 1e-12
    # ... and no other point of the simplex does better in the real-time band, nor in any later look-ahead band
    from interprim.model_selection import stacking as ensemble

    cfg = ensemble.scoring_config(0.25, list(dev.demos), dev.dt, stride=3, max_frames=blend.max_prefixes)
    cv = ensemble.CrossValidation(blend.factories(), dev.demos, [0, 1], dev.dt, cfg, k=3, horizon=0.25)
    for m, e in s["cv_errors"].items():
        assert cv.errors[m] == pytest.approx(e)
    # the per-band weights stacked on the inner folds (before the long-range choice, tested below)
    stacked = ensemble.stack(cv, 0.25)
    sub = cv.subset(stacked.names)
    bands = stacked.edges
    assert 0.25 - dev.dt < bands[0] <= 0.25 and bands[-1] >= 0.5 * cv.t_ahead[-1]
    assert cv.t_ahead[-1] >= max(len(d) - 1 for d in dev.demos) * dev.dt - 1e-9  # scored to the end
    Wb = np.array([[stacked.band_weights[m][b] for m in sub.names] for b in range(len(bands))])
    rng = np.random.default_rng(0)
    for b, steps in enumerate(sub.band_steps(bands)):
        assert b == 0 or sub.valid[:, steps].any()  # every band has frames of held-out movements
        n_rt = round(0.25 / dev.dt)
        ok = sub.valid[:, steps] | (steps < n_rt)[None, :]  # the steps inside each held-out movement

        def band_error(wv, steps=steps, ok=ok):
            mix = np.tensordot(wv, sub.mean[:, :, steps], axes=1)
            e2 = ((mix - sub.truth[:, steps])[..., sub.controlled] ** 2).sum(axis=2) * ok
            rows = ok.any(axis=1)
            return float(np.mean(np.sqrt(e2[rows].sum(axis=1) / (ok[rows].sum(axis=1) * len(sub.controlled)))))
        best = band_error(Wb[b])
        for _ in range(20):
            assert band_error(rng.dirichlet(np.ones(len(sub.names)))) >= best - 1e-7
        for v in np.eye(len(sub.names)):  # never worse than one family alone in its band
            assert band_error(v) >= best - 1e-7
    # the blend's weights and timing: the long-range choice made on those stacked weights
    from interprim.model_selection.long_range import candidate_cases, refine, replaced

    fitted, lam = refine(cv, stacked, 0.25)
    cv = candidate_cases(cv, stacked)  # the families the choice could use, with the real-time weights
    assert s["long_range"]["remaining"] == ("own" if lam is None else lam)
    assert blend.model_.remaining == lam
    assert set(s["band_weights"]) == set(fitted.names)
    for m in fitted.names:
        assert s["band_weights"][m] == pytest.approx(fitted.band_weights[m])
    bands = fitted.edges
    if lam is not None:
        cv = cv.cases(np.arange(len(cv.demo)))
        cv.mean = replaced(cv, lam)
    sub = cv.subset(fitted.names)
    Wb = np.array([[fitted.band_weights[m][b] for m in sub.names] for b in range(len(bands))])
    per_step = ensemble.weights_at(sub.t_ahead, bands, Wb)
    assert sub.blend_error(per_step) == pytest.approx(s["blend_cv_error"], rel=1e-9)
    # the variance model's band covers its level's share of the held-out cases at every step ahead, for each agent,
    # the level (at least 90 %) chosen by cross-fitting and recorded
    W = per_step.T[:, None, :, None]
    mix = np.sum(W * sub.mean, axis=0)
    spread = np.sum(W * (sub.mean - mix) ** 2, axis=0)
    vm = sub.blend_scales(per_step)
    assert vm["level"] == s["band_level"]
    inside = np.abs(mix - sub.truth) <= 1.6448536269514722 * np.sqrt(vm["a"] * spread + vm["b"]) + 1e-12
    ok = sub.valid | (np.arange(sub.truth.shape[1]) < round(0.25 / dev.dt))[None, :]
    for agent, cols in (("controlled", sub.controlled), ("observed", sub.observed)):
        level = vm["level"][agent]
        assert level in stacking.BAND_LEVELS and level >= 0.9
        for h in range(0, inside.shape[1], 7):  # per step ahead, over the cases still inside their movement
            if ok[:, h].sum() >= 20:
                cover = inside[ok[:, h], h][:, cols].mean()
                n = ok[:, h].sum() * len(cols)
                assert level - 1e-9 <= cover <= level + 2.0 / n, (h, cover)


def test_band_level_is_the_smallest_that_covers_90_percent_of_unseen_demonstrations():
    """The band's quantile level is chosen by cross-fitting: the variance model fitted on two groups of held-out
    demonstrations covers at least 90 % of the third group's frames at the chosen level and less at the level below;
    checked by brute force over the levels, on errors whose scale drifts over the recordings (so that a model
    calibrated on the same cases is optimistic and the level must rise above 90 %)."""
    rng = np.random.default_rng(2)
    n_demo, per, H, D = 12, 10, 8, 2
    demo = np.repeat(np.arange(n_demo), per)
    scale = np.exp(0.3 * np.arange(n_demo) + rng.normal(0.0, 0.3, n_demo))[demo][:, None, None]
    truth = rng.normal(size=(len(demo), H, D)) * scale
    mean = np.stack([truth + rng.normal(size=truth.shape) * scale * s for s in (0.8, 1.2)])
    valid = np.ones((len(demo), H), dtype=bool)
    w = np.array([0.5, 0.5])[:, None, None, None]
    level = stacking.band_level(mean, truth, valid, w, [1], demo, floor=0.0)  # the mean's condition alone
    covers = {L: stacking.crossfit_coverage(mean, truth, valid, w, [1], demo, L) for L in stacking.BAND_LEVELS}
    assert covers[level] >= 0.9
    below = [L for L in stacking.BAND_LEVELS if L < level]
    assert all(covers[L] < 0.9 for L in below)
    assert level > 0.9  # optimistic in-sample: the level had to rise
    # one demonstration: nothing to cross-fit, the nominal level
    assert stacking.band_level(mean[:, :per], truth[:per], valid[:per], w, [1], demo[:per]) == 0.9


def test_band_level_also_covers_each_contiguous_third_of_the_recordings():
    """With the floor, the level is the smallest at which the cross-fitted band covers 90 % of all held-out frames
    *and* 85 % (``BAND_FLOOR``) of each contiguous third's, checked by brute force over the levels from each
    demonstration's own coverage; on errors that jump in the last recordings that third is the one short of it, so
    the level rises above the mean's alone."""
    from interprim.model_selection.yardsticks import case_groups

    rng = np.random.default_rng(7)
    n_demo, per, H, D = 12, 10, 8, 2
    demo = np.repeat(np.arange(n_demo), per)
    sc = np.exp(rng.normal(0.0, 0.1, n_demo))
    sc[8:] *= 3.0  # the last third's errors three times larger
    scale = sc[demo][:, None, None]
    truth = rng.normal(size=(len(demo), H, D)) * scale
    mean = np.stack([truth + rng.normal(size=truth.shape) * scale * s for s in (0.8, 1.2)])
    valid = np.ones((len(demo), H), dtype=bool)
    w = np.array([0.5, 0.5])[:, None, None, None]
    assert stacking.BAND_FLOOR == 0.85
    level = stacking.band_level(mean, truth, valid, w, [1], demo)
    alone = stacking.band_level(mean, truth, valid, w, [1], demo, floor=0.0)
    # each demonstration's cross-fitted coverage at every level, and the third it lies in
    (cover, grp), = stacking._crossfit_demos(mean, truth, valid, w, [[1]], demo)
    assert cover.shape == (n_demo, len(stacking.BAND_LEVELS))
    np.testing.assert_array_equal(grp, case_groups(demo)[::per])
    np.testing.assert_allclose(cover.mean(axis=0), stacking.crossfit_coverages(mean, truth, valid, w, [1], demo),
                               rtol=0, atol=1e-15)
    thirds = np.stack([cover[grp == g].mean(axis=0) for g in range(3)])  # (3, levels)
    ok = (cover.mean(axis=0) >= 0.9) & (thirds >= 0.85).all(axis=0)
    assert level == stacking.BAND_LEVELS[np.flatnonzero(ok)[0]]
    assert level > alone  # here the mean alone leaves a third short of 85 %
    short = thirds[:, stacking.BAND_LEVELS.index(alone)]
    assert short.min() < 0.85 and np.argmin(short) == 2  # the latest recordings


def test_weights_move_smoothly_from_real_time_to_the_whole_movement():
    from interprim.model_selection.stacking import weights_at

    W = np.array([[1.0, 0.0], [0.5, 0.5], [0.0, 1.0]])
    edges = [0.25, 0.5, 1.0]  # middles 0.125, 0.375, 0.75
    got = weights_at(np.array([0.0, 0.125, 0.25, 0.375, 0.75, 5.0]), edges, W)
    np.testing.assert_allclose(got[:, 0], [1.0, 1.0, 0.75, 0.5, 0.0, 0.0])
    np.testing.assert_allclose(got.sum(axis=1), 1.0)


def test_blend_mean_is_the_weighted_members_placed_in_time(blend, task):
    """Ahead of now, the blend at the instant t seconds ahead is the weighted mean of every member's prediction at
    that same instant (each member placed in time by its own phase and duration)."""
    from interprim.model_selection.realtime import place_in_time

    _, hold = task
    x = hold.demos[1][:35, :2]
    model = blend.model_
    preds = {m: est.predict(x) for m, est in model.members_.items()}
    p = model.combine(preds, len(x), n_grid=2001)  # a fine grid: the rule, not the grid's interpolation, is tested
    t = np.array([0.02, 0.1, 0.2])
    s_b, D_b = place_in_time(p, len(x), hold.dt, model.mean_duration_)
    got = np.stack([np.interp(s_b + t / D_b, p.times, p.mean[:, d]) for d in range(4)], axis=1)
    want = 0
    wt = model.weights_at(t)  # (instants, members): the weights fitted for each look-ahead
    for i, pm in enumerate(preds.values()):
        sm, Dm = place_in_time(pm, len(x), hold.dt, model.mean_duration_)
        Y = pm.trajectory(model.N_GRID)
        grid = np.linspace(0, 1, model.N_GRID)
        want = want + wt[:, i:i + 1] * np.stack([np.interp(np.clip(sm + t / Dm, 0, 1), grid, Y[:, d])
                                                 for d in range(4)], axis=1)
    np.testing.assert_allclose(got, want, rtol=0, atol=2e-3 * np.abs(want).max())


def test_blend_real_time_weights_are_computed_once(blend):
    """The weights at look-ahead 0 that place the blend in time after every frame are those of ``weights_at(0)``,
    kept from the fit (and from a load) instead of interpolated again per frame."""
    model = blend.model_
    assert np.array_equal(model._w_now, model.weights_at(0.0)[0])
    again = type(model)(**model.get_params(deep=False))
    again.load_state(*model.to_state())
    assert np.array_equal(again._w_now, model._w_now)


def test_blend_streams_saves_and_calibrates(blend, task, tmp_path):
    _, hold = task
    x = hold.demos[0][:40, :2]
    p = blend.predict(x)
    st = blend.stream()
    for f in x:
        q = st.update(f)
    np.testing.assert_array_equal(q.trajectory(50), p.trajectory(50))
    np.testing.assert_array_equal(q.std(50), p.std(50))
    assert st.n_frames == 40
    blend.save(tmp_path / "blend.npz")
    back = ip.load_any(tmp_path / "blend.npz")
    assert type(back) is ip.AutoInteraction and back.weights_ == blend.weights_
    np.testing.assert_array_equal(back.predict(x).trajectory(50), p.trajectory(50))
    np.testing.assert_array_equal(back.predict(x).std(50), p.std(50))
    vm = {k: np.asarray(v) for k, v in blend.selection_["variance_model"].items()}
    assert set(vm) == {"a", "b", "t"} and vm["a"].shape == vm["b"].shape == (len(vm["t"]), 4)
    assert vm["t"][0] == pytest.approx(hold.dt) and vm["t"][-1] > 1.0  # every look-ahead, to the end
    assert np.all(vm["a"] > 0) and np.all(vm["b"] >= 0)
    assert "blend of" in repr(blend) and "blend:" in blend.summary()


def test_the_server_serves_a_saved_blend_like_its_stream(blend, task, tmp_path):
    """A model file of the blend (what 'interprim fit' saves by default) is served: every reply equals the
    blend's own stream."""
    pytest.importorskip("websockets")
    from interprim.server.app import InterprimServer, ServerConfig, ServerThread
    from interprim.server.client import Client
    from interprim.server.models import load_models

    _, hold = task
    path = tmp_path / "handover.npz"
    blend.save(path)
    models = load_models([path])
    assert type(models["handover"].model) is ip.AutoInteraction
    direct = blend.stream()
    with ServerThread(InterprimServer(models, ServerConfig(port=0))) as st, Client(st.ws_url) as c:
        op = c.open("handover", points=20, std=True)
        assert op["n_observed"] == 2 and op["columns"] == [2, 3]
        for k, f in enumerate(hold.demos[2][:25, :2], start=1):
            p = c.frame(f)
            d = direct.update(f)
            np.testing.assert_allclose(p["mean"], d.trajectory(20)[:, 2:], rtol=1e-6, atol=1e-9)  # JSON: 7 digits
            np.testing.assert_allclose(p["std"], d.std(20)[:, 2:], rtol=1e-6, atol=1e-9)
            assert p["frames"] == k and p["out_of_range"] is False
        far = c.frame(hold.demos[2][25, :2] * 1000.0)  # millimetres to a model fitted in metres: flagged on the wire
        assert far["out_of_range"] is True


def test_fast_inner_cross_validation_equals_the_plain_protocol(task):
    """The inner cross-validation skips what it does not use (the families' std, the clock's records) and streams
    the kernel and nearest-demonstration predictions frame by frame; its errors, placed means and truth equal,
    bitwise, those of the plain protocol (every prefix predicted anew, every record computed), so the blend's
    weights and variance model are those the plain protocol gives."""
    from interprim.core.blas import single_thread
    from interprim.evaluation.realtime import realtime_sweep, summarise_realtime
    from interprim.model_selection.stacking import CrossValidation

    dev, _ = task
    fams = ("kernel", "nn", "prior")
    make = {m: f for m, f in default_methods([0, 1]).items() if m in fams}
    cfg = RealTimeConfig(stride=3, max_frames=ip.AutoInteraction([0, 1]).max_prefixes)  # the fit's protocol
    cv = CrossValidation(make, dev.demos, [0, 1], dev.dt, cfg, k=3)

    def plain(factory):  # the same family with the stream shortcut off
        def build():
            est = factory()
            est.exact_stream = False
            return est
        return build

    assert cv.names == list(fams)
    for i, m in enumerate(fams):
        recs = realtime_sweep({m: plain(make[m])}, dev.demos, [0, 1], dev.dt, cfg, k=3, trace=True)
        assert {r["method"] for r in recs} == {m, "clock", "oracle-duration"}
        assert cv.errors[m] == summarise_realtime(recs)[m]["rt_ctrl"]
        mine = sorted((r["demo"], r["k"]) for r in recs if r["method"] == m)
        by = {(r["demo"], r["k"]): r for r in recs if r["method"] == m}
        np.testing.assert_array_equal(cv.mean[i], np.array([by[c]["mean"] for c in mine]))
        np.testing.assert_array_equal(cv.truth, np.array([by[c]["truth"] for c in mine]))
    auto = ip.AutoInteraction([0, 1], candidates=fams, frame_budget=None).fit(dev.demos, dt=dev.dt)  # every family
    with single_thread():  # as fit computes them (a BLAS thread count changes the last bits of the weights)
        w = cv.blend_weights()
    # the real-time band's weights are those of the 0.25 s protocol (the fit scores further ahead too)
    np.testing.assert_allclose([auto.weights_.get(m, 0.0) for m in cv.names], w, atol=1e-6)


@pytest.mark.slow  # starts worker processes
def test_worker_processes_serve_a_default_model_file(blend, task, tmp_path):
    """``interprim serve --processes 2`` with the file ``interprim fit`` writes by default: the workers load it with
    ``load_any`` and every reply equals the blend's own stream, ``out_of_range`` included."""
    pytest.importorskip("websockets")
    from interprim.server.app import InterprimServer, ServerConfig, ServerThread
    from interprim.server.client import Client
    from interprim.server.models import load_models

    _, hold = task
    path = tmp_path / "handover.npz"
    blend.save(path)
    models = load_models([path])
    srv = InterprimServer(models, ServerConfig(port=0, processes=2, max_rate_hz=100000, rate_burst=100000))
    direct = blend.stream()
    with ServerThread(srv) as st, Client(st.ws_url) as c:
        assert len(st.server.compute.procs.workers) == 2
        c.open("handover", points=10, std=True)
        for f in hold.demos[2][:20, :2]:
            p, d = c.frame(f), direct.update(f)
            np.testing.assert_allclose(p["mean"], d.trajectory(10)[:, 2:], rtol=1e-6, atol=1e-9)
            assert p["out_of_range"] is False
        far = c.frame(hold.demos[2][20, :2] * 1000.0)
        assert far["out_of_range"] is True


def test_settings_flow_down_to_every_member(task):
    """``AutoInteraction(horizon=0.5, n_basis=8)``: the kernel member is tuned for 0.5 s and the IP member has 8
    basis functions (a setting is given once, at the top)."""
    dev, _ = task
    auto = ip.AutoInteraction([0, 1], candidates=("ip", "kernel"), horizon=0.5, n_basis=8, folds=2).fit(
        dev.demos, dt=dev.dt)
    members = auto.model_.members_ if hasattr(auto.model_, "members_") else {auto.chosen_: auto.model_}
    for name, est in members.items():
        if name == "kernel":
            assert est.horizon == 0.5
        if name == "ip":
            assert est.n_basis == 8
    made = auto.factories()
    assert made["kernel"]().horizon == 0.5 and made["ip"]().n_basis == 8
    assert 0.5 - dev.dt < auto.selection_.get("bands", [0.5])[0] <= 0.5


def test_fit_shows_its_progress_when_asked(task, capsys, monkeypatch):
    import builtins

    real_import = builtins.__import__

    def no_tqdm(name, *args, **kwargs):  # the [experiments] extra absent: one line per step on stderr
        if name == "tqdm":
            raise ImportError("no tqdm")
        return real_import(name, *args, **kwargs)

    dev, _ = task
    monkeypatch.setattr(builtins, "__import__", no_tqdm)
    ip.AutoInteraction([0, 1], candidates=("kernel", "prior"), folds=2, progress=True, frame_budget=None).fit(
        dev.demos, dt=dev.dt)
    err = capsys.readouterr().err.splitlines()
    assert err[0].startswith("fit: step 1/2 compared kernel") and "fitted" in err[-1]
    assert err[-1].split()[2].split("/")[0] == err[-1].split()[2].split("/")[1]  # the last step is the last
    # with a frame budget, the Interaction Primitive that sets it is fitted first, and the count still adds up
    ip.AutoInteraction([0, 1], candidates=("kernel", "prior"), folds=2, progress=True).fit(dev.demos, dt=dev.dt)
    err = capsys.readouterr().err.splitlines()
    assert "fitted ip (the frame budget's yardstick)" in err[0]
    assert err[-1].split()[2].split("/")[0] == err[-1].split()[2].split("/")[1]
    ip.AutoInteraction([0, 1], candidates=("kernel", "prior"), folds=2).fit(dev.demos, dt=dev.dt)
    assert capsys.readouterr().err == ""


def _user_family():
    """A user's own family in a few lines (the public contract only): the mean demonstration in normalised time,
    shifted so that its observed agent passes through the last observed frame at the clock's phase."""
    from interprim.core.preprocessing import time_normalise
    from interprim.models.base import Predictor
    from interprim.models.grid import GridPrediction

    class ShiftedMean(Predictor):
        _FITTED = "mean_"

        def __init__(self, observed_dofs, n: int = 101):
            self.observed_dofs = observed_dofs
            self.n = n

        def fit(self, demos, dt=None):
            self.dt_ = float(dt)
            self.observed_dofs_ = [int(i) for i in self.observed_dofs]
            self.mean_ = np.mean([time_normalise(np.asarray(d), self.n) for d in demos], axis=0)
            self.mean_duration_ = float(np.mean([len(d) - 1 for d in demos])) * self.dt_
            return self

        def predict(self, partial):
            x = np.asarray(partial, dtype=np.float64)
            s = min((len(x) - 1) * self.dt_ / self.mean_duration_, 1.0)
            u = np.linspace(0.0, 1.0, self.n)
            at = np.array([np.interp(s, u, self.mean_[:, c]) for c in self.observed_dofs])
            mean = self.mean_.copy()
            mean[:, self.observed_dofs] += x[-1] - at
            return GridPrediction(u, mean, None, phase=s, observed_dofs=list(self.observed_dofs),
                                  duration=self.mean_duration_, mean_duration=self.mean_duration_,
                                  n_observed=len(x))

    return ShiftedMean


def test_a_users_own_family_joins_the_blend(task, tmp_path):
    """``candidates`` takes ``(name, factory)`` pairs beside registry names (as scikit-learn's
    ``StackingRegressor(estimators=...)``): the user's family is compared on the same folds, weighted, fitted and
    streamed like the registry's; a model file names registered families only, so saving it is refused clearly."""
    dev, hold = task
    ShiftedMean = _user_family()
    auto = ip.AutoInteraction([0, 1], candidates=("nn", ("shifted", lambda: ShiftedMean([0, 1])), "prior"))
    auto.fit(dev.demos, dt=dev.dt)
    s = auto.selection_
    assert set(s["cv_errors"]) == {"nn", "shifted", "prior"} and np.isfinite(s["cv_errors"]["shifted"])
    assert auto.weights_.get("shifted", 0.0) > 0 and type(auto.model_.members_["shifted"]) is ShiftedMean
    x = hold.demos[0][:30, :2]
    st = auto.stream()
    for f in x:
        q = st.update(f)
    np.testing.assert_array_equal(q.trajectory(40), auto.predict(x).trajectory(40))
    assert auto.json_params()["candidates"] == ["nn", "shifted", "prior"]
    with pytest.raises(ValueError, match="'shifted' is a ShiftedMean, not a family of interprim's registry"):
        auto.save(tmp_path / "mine.npz")
    assert not (tmp_path / "mine.npz").exists()
    with pytest.raises(ValueError, match="pairs"):
        ip.AutoInteraction([0, 1], candidates=("nn", ("shifted",))).fit(dev.demos, dt=dev.dt)


def _tied(n=12, Do=3, Dc=3, T=80, seed=0, scale=None):
    """Sines of random amplitude, frequency and phase for the observed agent and a fixed quadratic map of them for
    the controlled one: data on which the families tie (issue 37's second benchmark set, smaller).  ``scale``: each
    demonstration's length as a multiple of ``T`` (default: 0.9-1.1 at random)."""
    rng = np.random.default_rng(seed)
    A, B = rng.normal(size=(Do, Dc)) / np.sqrt(Do), rng.normal(size=(Do, Dc)) / np.sqrt(Do)
    out = []
    for i in range(n):
        s = np.linspace(0, 1, int(round(T * (rng.uniform(0.9, 1.1) if scale is None else scale[i]))))[:, None]
        x = rng.uniform(0.7, 1.3, Do) * np.sin(2 * np.pi * rng.uniform(0.8, 1.2, Do) * s + rng.uniform(-.3, .3, Do))
        out.append(np.hstack([x, x @ A + (x ** 2) @ B]) + 0.01 * rng.standard_normal((len(s), Do + Dc)))
    return out


def _modelled_frame(auto, demos):
    """The modelled frame of ``auto``'s members, recomputed from the registry's cost model."""
    from interprim.models import registry
    from interprim.models.blend import Blend

    c = auto.selection_["cost"]
    z = registry.FrameSizes(len(demos), float(np.mean([len(d) for d in demos])), len(auto.observed_dofs),
                            demos[0].shape[1], auto.n_basis, phase=c["ip_phase"] or "likelihood",
                            coupling=c["learned_coupling"] or "ppca")
    members = list(auto.model_.members_) if hasattr(auto.model_, "members_") else [auto.chosen_]
    return sum(registry.frame_cost(m, z) for m in members) + Blend.frame_overhead(len(members), demos[0].shape[1])


@pytest.fixture(scope="module")
def tied():
    demos = _tied()
    # the budget purely relative (no floor), so that it binds on these small data
    return demos, ip.AutoInteraction([0, 1, 2], frame_budget_floor=0.0, predict_budget_floor=0.0).fit(demos, dt=0.02)


def test_a_fitted_default_keeps_no_member_without_weight_and_stays_within_its_budget(tied, blend):
    """Every member of a fitted default carries weight (at least MIN_WEIGHT of some look-ahead band or weight in the
    robot's past, ``Blend.past``) or is the one whose pace sets the blend's shared end (``Blend.remaining``), and
    on the tied data its modelled frame is within the budget: 3x the Interaction Primitive's, by the cost model."""
    from interprim.model_selection.stacking import MIN_WEIGHT

    demos, auto = tied
    for model in (auto, blend):
        s = model.selection_
        if s["combine"] == "blend":
            assert set(s["band_weights"]) == set(model.model_.members_)
            for m, w in s["band_weights"].items():
                assert max(w) >= MIN_WEIGHT or m == model.model_.remaining or m in (model.model_.past or {}), (
                    m, w, model.model_.remaining, model.model_.past)
    c = auto.selection_["cost"]
    assert c["budget"] == pytest.approx(3.0 * c["ip_frame"]) and c["frame"] <= c["budget"]
    assert c["predict_budget"] == pytest.approx(3.0 * c["ip_predict"]) and c["predict"] <= c["predict_budget"]
    assert c["frame"] == pytest.approx(_modelled_frame(auto, demos), rel=1e-12)
    for m in c["left_out"]:  # what was left out was left out for the budget, and is not run
        assert m not in getattr(auto.model_, "members_", {auto.chosen_: None})
    assert "streamed frame (modelled)" in auto.summary()
    x = _tied(1, seed=7)[0][:40, :3]
    st = auto.stream()
    for f in x:
        q = st.update(f)
    np.testing.assert_allclose(q.trajectory(60), auto.predict(x).trajectory(60), rtol=0, atol=1e-8)  # rounding


def test_budget_phase_reads_the_inner_folds_fits():
    """``budget_phase``: the learned phase when most inner-fold fits chose it, else the other phase most of them
    chose (the first fold's on a tie); None when the IP was not fitted on every fold."""
    from types import SimpleNamespace

    from interprim.models.auto import budget_phase

    def fits(*phases):
        return [SimpleNamespace(fitted_=object(), phase_method_used=lambda p=p: p) for p in phases]

    assert budget_phase(fits("learned", "likelihood", "learned"), 3) == "learned"
    assert budget_phase(fits("learned", "likelihood", "likelihood"), 3) == "likelihood"
    assert budget_phase(fits("learned", "dtw", "likelihood"), 3) == "dtw"  # no majority: the first fold's other
    assert budget_phase(fits("learned", "learned", "likelihood", "likelihood"), 4) == "likelihood"  # half: not most
    assert budget_phase(fits("learned", "learned"), 3) is None  # a fold without a fit
    assert budget_phase(fits("learned", "learned") + [SimpleNamespace(fitted_=None)], 3) is None  # not fitted


def test_budget_coupling_reads_the_inner_folds_fits():
    """``budget_coupling``: the reduced-rank coupling when most inner-fold fits of the learned interaction chose it,
    else the coupling most of the others chose (the first fold's on a tie); None when it was not fitted on every
    fold."""
    from types import SimpleNamespace

    from interprim.models.auto import budget_coupling

    def fits(*methods):
        return [SimpleNamespace(coupling_=SimpleNamespace(method_=m)) for m in methods]

    assert budget_coupling(fits("ppca", "ridge", "ppca"), 3) == "ppca"
    assert budget_coupling(fits("ppca", "ridge", "blend"), 3) == "ridge"  # no majority: the first fold's other
    assert budget_coupling(fits("kernel", "blend", "blend"), 3) == "blend"
    assert budget_coupling(fits("ppca", "ppca", "ridge", "ridge"), 4) == "ridge"  # half: not most
    assert budget_coupling(fits("ppca", "ppca"), 3) is None  # a fold without a fit
    assert budget_coupling(fits("ppca", "ppca") + [SimpleNamespace(coupling_=None)], 3) is None  # not fitted


def test_the_cost_model_tells_the_learned_couplings_apart():
    """The learned interaction's frame is costed by its coupling's class: the reduced-rank coupling, which factorises
    its joint PCA at every frame, 3-5x the linear smoothers at the benchmark's size (measured: 0.82 ms against
    0.17-0.26 ms at 30 demonstrations x (7 + 7) DoFs x 200 frames); every linear smoother costs the same."""
    from interprim.models import registry

    z = registry.FrameSizes(30, 200.0, 7, 14)
    ppca = registry.frame_cost("learned", dataclasses.replace(z, coupling="ppca"))
    smooth = {m: registry.frame_cost("learned", dataclasses.replace(z, coupling=m))
              for m in ("ridge", "kernel", "blend", "mean")}
    assert len(set(smooth.values())) == 1 and 3.0 <= ppca / smooth["ridge"] <= 5.0
    assert 0.6e-3 <= ppca <= 1.0e-3 and 0.15e-3 <= smooth["ridge"] <= 0.3e-3  # within 26 % of the measurements
    assert registry.frame_cost("learned", z) == ppca  # sizes that do not say: the dearer class
    assert registry.COUPLING_CLASSES == {"ppca": "learned-ppca"}


def test_the_budget_bounds_a_predict_call_as_well_as_a_frame():
    """``budget_model``: a blend within the budget (``cost <= budget``) has its modelled frame within the frame's
    budget and its modelled predict within the predict's (each the larger of 3x the IP's and the floor); a family
    whose predict alone exceeds the predict's budget (the aligned families redo a DTW of the whole prefix) is left
    out for it, and the summary says what it costs a frame and a predict."""
    import itertools

    from interprim.models import registry

    z = registry.FrameSizes(30, 200.0, 7, 14, phase="learned", coupling="blend")
    auto = ip.AutoInteraction(list(range(7)), frame_budget_floor=0.0, predict_budget_floor=0.0)
    bm = auto.budget_model(z, list(registry.CANDIDATES))
    assert bm.budget == pytest.approx(3.0 * bm.ip_frame) and bm.predict_budget == pytest.approx(3.0 * bm.ip_predict)
    for n in range(1, len(registry.CANDIDATES) + 1):
        for members in map(list, itertools.combinations(registry.CANDIDATES, n)):
            within = bm.cost(members) <= bm.budget
            assert within == (bm.frame_of(members) <= bm.budget and bm.predict_of(members) <= bm.predict_budget)
    assert registry.predict_cost("nn", z) > bm.predict_budget > registry.frame_cost("nn", z)  # cheap to stream
    assert bm.costs["nn"] > bm.budget  # left out for its predict alone
    longer = dataclasses.replace(z, n_frames=400.0)  # a DTW over twice the prefix and twice the frames: 4x the cells
    grow = registry.predict_cost("nn", longer) - registry._PREDICT_US["nn"][0] * 1e-6
    assert grow == pytest.approx(4.0 * (registry.predict_cost("nn", z) - registry._PREDICT_US["nn"][0] * 1e-6))
    demos = _tied()
    fitted = ip.AutoInteraction([0, 1, 2], frame_budget=1.0, frame_budget_floor=0.0, predict_budget_floor=0.0).fit(
        demos, dt=0.02)
    c = fitted.selection_["cost"]
    assert c["predict"] <= c["predict_budget"] and c["frame"] <= c["budget"]
    assert c["left_out"] and set(c["left_out_predict"]) == set(c["left_out"])  # at 1x the IP, something is
    text = fitted.summary()
    assert "predict from half the movement (modelled)" in text
    streams = ip.AutoInteraction(list(range(7)), frame_budget_floor=0.0, predict_budget_floor=None)
    only = streams.budget_model(z, list(registry.CANDIDATES))  # a predict not bounded: the frame alone decides
    assert only.predict_budget is None and all(only.cost([m]) == only.frame_of([m]) for m in registry.CANDIDATES)
    assert only.costs["nn"] <= only.budget  # cheap to stream, so it fits
    m = min(c["left_out"], key=lambda k: c["left_out"][k])
    assert f"{m} ({1e3 * c['left_out'][m]:.2f} ms a frame, {1e3 * c['left_out_predict'][m]:.2f} ms a predict)" in text


@pytest.mark.parametrize("floor", [0.0, 0.002])
def test_the_learned_budget_coupling_is_its_own_when_the_model_keeps_it(monkeypatch, floor):
    """The learned interaction's frame is costed by the coupling its inner-fold fits chose; when the model keeps it,
    it is fitted on all the demonstrations then (once: that fit is the member) and its own coupling times the
    budget.  Made to believe its inner folds chose the other class, the fit gives the same model whenever it keeps
    the learned interaction: the selection is made again with the coupling of the one it keeps."""
    from interprim.models import auto as auto_module
    from interprim.models.learned import LearnedInteraction

    demos = _tied()
    fits = []
    real = LearnedInteraction.fit
    monkeypatch.setattr(LearnedInteraction, "fit", lambda self, *a, **k: fits.append(len(a[0])) or real(self, *a, **k))
    first = ip.AutoInteraction([0, 1, 2], frame_budget_floor=floor).fit(demos, dt=0.02)
    c = first.selection_["cost"]
    kept = "learned" in getattr(first.model_, "members_", {first.chosen_: None})
    assert fits.count(len(demos)) == int(kept)  # fitted on all the demonstrations once, only when kept
    assert c["learned_coupling_from"] == ("fitted on all the demonstrations" if kept else "inner folds")
    if kept:
        own = first.model_.members_["learned"].coupling_.method_
        assert c["learned_coupling"] == own and f"learned interaction's {own} coupling" in first.summary()
    other = "ridge" if c["learned_coupling"] == "ppca" else "ppca"
    monkeypatch.setattr(auto_module, "budget_coupling", lambda fits, k: other)
    again = ip.AutoInteraction([0, 1, 2], frame_budget_floor=floor).fit(demos, dt=0.02)
    if "learned" in getattr(again.model_, "members_", {}):  # kept under the other class: the selection made again
        assert again.selection_["band_weights"] == first.selection_["band_weights"]
        assert again.selection_["cost"]["frame"] == pytest.approx(c["frame"], rel=1e-12)


@pytest.mark.parametrize("floor", [0.0, 0.002])
def test_the_ip_is_fitted_on_all_demonstrations_only_when_the_model_keeps_it(monkeypatch, floor):
    """The frame budget's yardstick, the Interaction Primitive's frame, is timed by the phase its inner-fold fits
    chose; the IP is fitted on all the demonstrations only when the model keeps it (and then times the budget
    itself).  Made to believe its inner folds chose the other phase, the fit gives the same model whenever it keeps
    the IP: the selection is made again with the phase of the IP it keeps."""
    from interprim.models import auto as auto_module
    from interprim.models import registry

    demos = _tied()
    calls = []
    real = registry.yardstick_ip
    monkeypatch.setattr(registry, "yardstick_ip", lambda *a, **k: calls.append(1) or real(*a, **k))
    first = ip.AutoInteraction([0, 1, 2], frame_budget_floor=floor).fit(demos, dt=0.02)
    c = first.selection_["cost"]
    kept = "ip" in first.model_.members_
    assert len(calls) == int(kept)
    assert c["ip_phase_from"] == ("fitted on all the demonstrations" if kept else "inner folds")
    assert ("fitted on all the demonstrations" if kept else "as most of its inner-fold fits chose") in first.summary()
    assert c["ip_phase"] == "likelihood" and c["ip_frame"] == pytest.approx(
        registry.frame_cost("ip", registry.FrameSizes(12, float(np.mean([len(d) for d in demos])), 3, 6, 20)))
    other = "learned" if c["ip_phase"] != "learned" else "likelihood"
    monkeypatch.setattr(auto_module, "budget_phase", lambda fits, k: other)
    calls.clear()
    again = ip.AutoInteraction([0, 1, 2], frame_budget_floor=floor).fit(demos, dt=0.02)
    if "ip" in again.model_.members_ or len(calls):  # the IP kept under the other phase: the selection made again
        assert again.selection_["band_weights"] == first.selection_["band_weights"]
        assert again.selection_["cost"] == dict(c, ip_phase_from="fitted on all the demonstrations")
    calls.clear()
    without = ip.AutoInteraction([0, 1, 2], candidates=("learned", "nn", "prior"), frame_budget_floor=floor)
    assert without.fit(demos, dt=0.02).selection_["cost"]["ip_phase_from"] == "fitted on all the demonstrations"
    assert len(calls) == 1  # the IP not compared: fitted on all the demonstrations for the budget alone


def test_the_budget_picks_the_best_set_of_families_within_it(task):
    """``stack`` with a frame budget: when the full blend costs more, the blend is made of the set of families within
    the budget with the smallest summed band loss (checked by brute force over every set), and says what it left
    out; without a budget (or within it) the blend is the unbudgeted one."""
    from itertools import combinations

    from interprim.model_selection import stacking

    dev, _ = task
    fams = ("kernel", "nn", "prior")
    make = {m: f for m, f in default_methods([0, 1]).items() if m in fams}
    cfg = stacking.scoring_config(0.25, list(dev.demos), dev.dt, stride=3)
    cv = stacking.CrossValidation(make, dev.demos, [0, 1], dev.dt, cfg, k=3, horizon=0.25)
    price = {"kernel": 5.0, "nn": 2.0, "prior": 1.0}

    def cost(names):
        return sum(price[m] for m in names) + (0.5 if len(names) > 1 else 0.0)

    free = stacking.stack(cv, 0.25)
    assert stacking.stack(cv, 0.25, cost=cost, budget=100.0).band_weights == free.band_weights
    budget = 4.0  # kernel alone is over; nn + prior fit (3.5)
    got = stacking.stack(cv, 0.25, cost=cost, budget=budget)
    assert cost(got.names) <= budget and "kernel" not in got.names
    assert got.record["cost"]["left_out"] == {"kernel": 5.0}
    edges = stacking.look_ahead_bands(0.25, float(cv.t_ahead[-1]))
    steps = [s for i, s in enumerate(cv.band_steps(edges)) if i == 0 or cv.valid[:, s].any()]
    options = [set(c) for n in (1, 2, 3) for c in combinations(fams, n) if cost(c) <= budget]
    best = min(options, key=lambda f: sum(cv.subset([m for m in fams if m in f]).band_loss(s) for s in steps))
    assert set(got.names) <= best


def test_the_blend_stream_is_the_weighted_combination_of_its_members_streamed_alone(blend, task):
    """After every frame, the blend's stream equals (to rounding) the combination of each member's own stream run
    alone on the same frames: the blend adds the weights, never another member computation."""
    _, hold = task
    model = blend.model_
    x = hold.demos[2][:30, :2]
    alone = {m: est.stream() for m, est in model.members_.items()}
    st = model.stream()
    for k, f in enumerate(x, start=1):
        got = st.update(f)
        want = model.combine({m: s.update(f) for m, s in alone.items()}, k)
        np.testing.assert_allclose(got.trajectory(50), want.trajectory(50), rtol=0, atol=1e-12)


def test_inner_fold_messages_name_the_users_demonstrations(task):
    """With 4 demonstrations a family that cannot be fitted on an inner training fold is reported with the user's
    count and why the fold is smaller, not with the fold's count alone."""
    dev, _ = task
    auto = ip.AutoInteraction([0, 1], candidates=("learned", "nn", "prior"), folds=3).fit(dev.demos[:4], dt=dev.dt)
    why = auto.selection_["not_compared"]["learned"]
    assert "of your 4 demonstrations" in why and "3-fold cross-validation" in why
    assert "of your 4 demonstrations" in auto.summary()


def test_the_inner_cross_validation_is_bounded_before_it_is_expanded(monkeypatch, tmp_path):
    """``held_out_size`` gives, before the cross-validation runs, the size of the held-out predictions it then holds
    (``CrossValidation.mean``, every family, case and step ahead); a fit that would need more than its share of the
    machine's memory (MEMORY_SHARE) at its peak stops first with an error naming the sizes and the remedies, and
    fits nothing."""
    from interprim.model_selection import memory, stacking

    demos = _tied(8, 2, 2, 60)
    cfg = stacking.scoring_config(0.25, demos, 0.02, stride=3, max_frames=16)
    make = {m: f for m, f in default_methods([0, 1]).items() if m in ("nn", "prior")}
    cv = stacking.CrossValidation(make, demos, [0, 1], 0.02, cfg, k=3, horizon=0.25)
    cases, steps, size = memory.held_out_size(len(make), [len(d) for d in demos], cfg, 0.02, 4)
    assert cv.mean.shape == (2, cases, steps, 4) and size == cv.mean.nbytes
    built = []
    monkeypatch.setattr(stacking, "CrossValidation", lambda *a, **k: built.append(1))
    monkeypatch.setattr(memory, "physical_memory", lambda: memory.PEAK_COPIES * size)  # too small for 5
    with pytest.raises(ValueError, match=r"GB at its peak.*5 families x \d+ scored prefixes.*max_prefixes"):
        ip.AutoInteraction([0, 1]).fit(demos, dt=0.02)
    assert not built
    monkeypatch.setattr(memory, "physical_memory", lambda: None)  # a system that does not say: no bound
    memory.check_memory(5, [10 ** 6], cfg, 0.02, 10 ** 3)


def test_the_memory_bound_reads_a_containers_limit(monkeypatch, tmp_path):
    """``physical_memory``: a container's cgroup limit when it is below the machine's memory; "max" (no limit) or
    no cgroup file leaves the machine's."""
    from interprim.model_selection import memory

    machine = memory.physical_memory()
    limit = tmp_path / "memory.max"
    monkeypatch.setattr(memory, "CGROUP_LIMITS", (str(limit), str(tmp_path / "v1")))
    assert memory.physical_memory() == machine  # neither file
    limit.write_text("max\n")
    assert memory.physical_memory() == machine
    limit.write_text("1073741824\n")
    assert memory.physical_memory() == min(machine or 2 ** 62, 2 ** 30)


def test_frame_budget_is_checked():
    with pytest.raises(ValueError, match="frame_budget"):
        ip.AutoInteraction([0, 1], frame_budget=0).fit(_tied(4, 1, 1, 30), dt=0.02)
    for bad in (-0.001, float("nan"), True, "2ms"):
        with pytest.raises(ValueError, match="frame_budget_floor"):
            ip.AutoInteraction([0, 1], frame_budget_floor=bad).fit(_tied(4, 1, 1, 30), dt=0.02)
        with pytest.raises(ValueError, match="predict_budget_floor"):
            ip.AutoInteraction([0, 1], predict_budget_floor=bad).fit(_tied(4, 1, 1, 30), dt=0.02)


def test_max_prefixes_bounds_the_inner_cross_validation(monkeypatch):
    """The fit scores at most ``max_prefixes`` prefixes of each held-out demonstration, however long: the inner
    cross-validation's protocol carries the cap, and the scored frames of a 300-frame demonstration are capped while
    a short one keeps every third frame."""
    from interprim.model_selection import realtime, stacking

    seen = []
    real = realtime.realtime_fold

    def spy(*a, **kw):
        recs = real(*a, **kw)
        seen.append((len(a[2]), sorted({r["k"] for r in recs})))
        return recs

    monkeypatch.setattr(realtime, "realtime_fold", spy)
    demos = _tied(6, 1, 1, 300) + _tied(3, 1, 1, 40, seed=1)
    ip.AutoInteraction([0], candidates=("nn", "prior"), max_prefixes=10).fit(demos, dt=0.02)
    assert seen and all(len(ks) <= 10 for _, ks in seen)
    short = [ks for T, ks in seen if T < 50]
    assert short and all(np.all(np.diff(ks) == 3) for ks in short)  # 0.7 x 40 frames / 3 < 10: the stride alone
    for bad in (0, -1, 2.5, True):
        with pytest.raises(ValueError, match="max_prefixes"):
            ip.AutoInteraction([0], max_prefixes=bad).fit(demos, dt=0.02)
    assert stacking.scoring_config(0.25, demos, 0.02, max_frames=10).max_frames == 10


def test_frame_budget_has_a_floor_in_milliseconds(tied):
    """The budget is the larger of 3x the Interaction Primitive's modelled frame and the floor (1 ms by default):
    on small data, where the IP's frame is a fraction of a millisecond, the families that carry the accuracy are
    not left out for a saving no control loop needs; the floor changes nothing else."""
    from interprim.models.auto import DEFAULT_FRAME_BUDGET_FLOOR, DEFAULT_PREDICT_BUDGET_FLOOR

    demos, relative = tied
    auto = ip.AutoInteraction([0, 1, 2]).fit(demos, dt=0.02)
    c, r = auto.selection_["cost"], relative.selection_["cost"]
    assert c["ip_frame"] == r["ip_frame"]
    assert c["budget"] == pytest.approx(max(3.0 * c["ip_frame"], DEFAULT_FRAME_BUDGET_FLOOR))
    assert c["frame"] <= c["budget"] and set(c["left_out"]) <= set(r["left_out"])
    assert "the larger of 3x and 1.00 ms" in auto.summary()
    assert c["predict_budget"] == pytest.approx(max(3.0 * c["ip_predict"], DEFAULT_PREDICT_BUDGET_FLOOR))
    assert c["budget"] >= r["budget"] and c["budget"] == pytest.approx(DEFAULT_FRAME_BUDGET_FLOOR)  # tiny IP here
    # the blend within the floor may be dearer than within 3x the IP, never beyond the floor
    assert r["frame"] <= r["budget"] < c["budget"]


def _paced(n=15, faster=0.3, seed=3):
    """``n`` demonstrations of the tied data whose durations fall by ``faster`` (a fraction) from the first to the
    last, with a little jitter: a partner speeding up over a session."""
    jitter = np.random.default_rng(seed + 100).uniform(0.97, 1.03, n)
    return _tied(n, T=60, seed=seed, scale=(1.0 - faster * np.arange(n) / (n - 1)) * jitter)


def test_pace_trend_measures_a_drift_in_duration_with_the_order():
    """``pace_trend``: Spearman's rank correlation of duration with position, the first and last thirds' means and
    whether the trend is significant (p < PACE_P and a change of at least PACE_CHANGE); nothing to measure for fewer
    than 6 demonstrations or equal durations."""
    from scipy.stats import spearmanr

    from interprim.models.training import PACE_CHANGE, PACE_P, pace_trend

    d = [2.6, 2.55, 2.5, 2.52, 2.4, 2.35, 2.3, 2.25, 2.2]
    t = pace_trend(d)
    assert t["n"] == 9 and t["rho"] == pytest.approx(spearmanr(range(9), d)[0]) and t["rho"] < -0.9
    assert t["first"] == pytest.approx(np.mean(d[:3])) and t["last"] == pytest.approx(np.mean(d[-3:]))
    assert t["change"] == pytest.approx(np.mean(d[-3:]) / np.mean(d[:3]) - 1.0)
    assert t["significant"] and t["p"] < PACE_P and abs(t["change"]) >= PACE_CHANGE
    small = pace_trend([2.0 + 0.001 * i for i in range(9)])  # a monotone trend, but a 0.3 % change
    assert small["p"] < PACE_P and not small["significant"]
    mixed = pace_trend(np.random.default_rng(0).permutation(d))
    assert not mixed["significant"]
    assert pace_trend(d[:5]) is None and pace_trend([2.0] * 8) is None


def test_a_default_fitted_on_demonstrations_that_speed_up_warns_once_and_says_so():
    """Demonstrations that get shorter with their order: the fit raises one ``PaceWarning`` naming the trend,
    records it in ``selection_["pace"]`` and ``summary()`` says it; the same demonstrations shuffled give no warning
    and no line."""
    import warnings

    demos = _paced()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        auto = ip.AutoInteraction([0, 1, 2], candidates=("nn", "prior")).fit(demos, dt=0.02)
    paced = [w for w in caught if issubclass(w.category, ip.PaceWarning)]
    assert len(paced) == 1 and "shorter than the first" in str(paced[0].message)
    assert paced[0].filename == __file__  # said of the caller's line
    p = auto.selection_["pace"]
    assert p["significant"] and p["change"] < -0.2 and p["n"] == 15
    assert "durations change with their order" in auto.summary()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ip.PaceWarning)
        alone = ip.AutoInteraction([0, 1, 2], candidates=("nn",)).fit(demos, dt=0.02)
    assert "durations change with their order" in alone.summary()  # one family alone says it too
    order = np.random.default_rng(1).permutation(len(demos))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        mixed = ip.AutoInteraction([0, 1, 2], candidates=("nn", "prior")).fit([demos[i] for i in order], dt=0.02)
    assert not [w for w in caught if issubclass(w.category, ip.PaceWarning)]
    assert not mixed.selection_["pace"]["significant"] and "durations change" not in mixed.summary()


def test_the_default_warns_once_for_far_input_and_its_members_still_check_alone(blend, task):
    """The default marks its prediction and warns once per predict and once per stream; its members, whose checks
    it skips (``CHECKED_BY_CALLER``), still flag and warn when used alone."""
    import warnings

    from interprim.core.input_range import checked_by_caller
    from interprim.models.blend import Blend

    dev, _ = task
    assert isinstance(blend.model_, Blend)
    far = np.asarray(dev.demos[0])[:40, [0, 1]] * 1000.0  # millimetres to a model in metres
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        p = blend.predict(far)
        st = blend.stream()
        q = [st.update(f) for f in far]
    assert sum(issubclass(w.category, ip.OutOfRangeWarning) for w in caught) == 2
    assert not checked_by_caller()
    assert p.out_of_range and p.input_distance == blend.input_distance(far)
    assert q[-1].out_of_range and q[-1].input_distance == pytest.approx(blend.input_distance(far), rel=1e-12)
    checked = 0
    for member in blend.model_.members_.values():
        if member.input_range_ is not None or member._CHECKS_INPUT:
            with pytest.warns(ip.OutOfRangeWarning):
                assert member.predict(far).out_of_range
            checked += 1
    assert checked > 0


def test_a_blends_interaction_primitive_is_kept_without_calibration_and_the_band_is_the_same(task, tmp_path):
    """Inside a blend a member's own std is never read (the band is the blend's variance model over its members'
    means): the default keeps its Interaction Primitive member without a calibration and says so (``calibrate``
    False, ``calibration_`` None, nothing deferred to measure later, the same after a model file), and the blend's
    mean, band, phase and duration, predicted and streamed, equal those of the same blend with a calibrated member.
    The Interaction Primitive as the whole model keeps its calibration."""
    import copy

    from interprim.models import registry

    dev, hold = task
    x = hold.demos[0][:40, :2]
    auto = ip.AutoInteraction([0, 1], candidates=("ip", "nn", "prior")).fit(dev.demos, dt=dev.dt)
    assert auto.selection_["combine"] == "blend" and "ip" in auto.model_.members_
    member = auto.model_.members_["ip"]
    assert member.calibrate is False and member.calibration_ is None
    assert member.json_params()["calibrate"] is False and "_calibration_pending" not in member.fitted_.__dict__
    assert "not calibrated" in member.summary()
    calibrated = registry.family("ip").build(auto.settings()).fit(dev.demos, dt=dev.dt)  # an eager fit
    assert calibrated.calibration_ is not None
    np.testing.assert_array_equal(member.predict(x).trajectory(50), calibrated.predict(x).trajectory(50))
    twin = copy.copy(auto)
    twin.model_ = copy.copy(auto.model_)
    twin.model_.members_ = dict(auto.model_.members_, ip=calibrated)
    back_path = tmp_path / "default.npz"
    auto.save(back_path)
    back = ip.load_any(back_path)
    loaded = back.model_.members_["ip"]
    assert loaded.calibrate is False and loaded.calibration_ is None
    assert "_calibration_pending" not in loaded.fitted_.__dict__
    for model in (auto, back):
        p, q = model.predict(x), twin.predict(x)
        np.testing.assert_array_equal(p.trajectory(50), q.trajectory(50))
        np.testing.assert_array_equal(p.std(50), q.std(50))
        assert (p.phase, p.duration) == (q.phase, q.duration)
        s, t = model.stream(), twin.stream()
        for f in x[:12]:
            a, b = s.update(f), t.update(f)
        np.testing.assert_array_equal(a.trajectory(50), b.trajectory(50))
        np.testing.assert_array_equal(a.std(50), b.std(50))
    # fitted afresh (no frame budget, so no yardstick to reuse), the member is kept the same way
    free = ip.AutoInteraction([0, 1], candidates=("ip", "nn"), frame_budget=None).fit(dev.demos, dt=dev.dt)
    assert free.model_.members_["ip"].calibrate is False and free.model_.members_["ip"].calibration_ is None
    # the Interaction Primitive as the whole model: calibrated, as fitted alone
    for kw in (dict(candidates=("ip",)), dict(candidates=("ip", "nn", "prior"), combine="best")):
        alone = ip.AutoInteraction([0, 1], **kw).fit(dev.demos, dt=dev.dt)
        assert alone.chosen_ == "ip" and alone.model_.calibrate == "with-cv"
        for k, v in alone.model_.calibration_.to_arrays().items():
            np.testing.assert_array_equal(v, calibrated.calibration_.to_arrays()[k])

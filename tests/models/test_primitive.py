"""InteractionPrimitive: the public API of Sec. III (both agents, Omega~ = [Omega, 0])."""

import json
import zipfile

import numpy as np
import pytest

import interprim as ip
from interprim.core.preprocessing import time_normalise


def _ctrl_mse(model, demos, frac, oracle):
    errs = []
    for d in demos:
        M = max(int(round(frac * (len(d) - 1))) + 1, 3)
        phase = (M - 1) / (len(d) - 1) if oracle else None
        pred = model.predict(d[:M, :2], phase=phase)
        gt = time_normalise(d, 100)
        errs.append(np.mean((pred.trajectory(100)[:, 2:] - gt[:, 2:]) ** 2))
    return float(np.mean(errs))


def test_api_shapes(fitted, synthetic):
    _, test = synthetic
    d = test[0]
    pred = fitted.predict(d[:80, :2])
    assert 0.0 < pred.phase <= 1.0 and pred.x == pytest.approx(np.exp(-3.0 * pred.phase))
    assert pred.trajectory(100).shape == (100, 5)
    assert pred.std(100).shape == (100, 5) and np.all(pred.std(100) >= 0)
    smp = pred.samples(20, 100, random_state=0)
    assert smp.shape == (20, 100, 5)
    np.testing.assert_array_equal(smp, pred.samples(20, 100, random_state=0))
    assert pred.goal.shape == (5,)
    t, y = pred.response(50)
    assert y.shape == (50, 3) and t[0] == 0.0 and t[-1] == pytest.approx(pred.duration * (1 - pred.normalised_time))
    s, yc = pred.completion(30)
    assert yc.shape == (30, 2)
    np.testing.assert_allclose(yc[0], d[79, :2], atol=1e-9)  # pattern completion starts at the last frame
    assert np.isfinite(pred.log_likelihood)


@pytest.mark.parametrize("config", ["paper", "default"])
def test_controlled_error_falls_with_more_observed(fitted, fitted_paper, synthetic, config):
    model = fitted_paper if config == "paper" else fitted
    _, test = synthetic
    prior_only = _ctrl_mse(model, test, 0.0, oracle=False)  # 3 frames seen: practically the prior
    e = {p: _ctrl_mse(model, test, p, oracle=True) for p in (0.3, 0.6, 1.0)}
    assert e[1.0] < e[0.6] < e[0.3] < prior_only
    assert e[1.0] < 0.01 * prior_only
    if config == "paper":
        # with the DTW phase the controlled agent still beats the prior mean once 60 % is seen
        assert _ctrl_mse(model, test, 0.6, oracle=False) < prior_only


@pytest.mark.slow  # fits and scores two models
def test_likelihood_phase_beats_dtw_when_goals_vary(synthetic):
    """The demos differ in goal: DTW on positions confuses "further along" with "aiming further" (the core
    issue's warning); the likelihood phase does not, and the controlled agent's error falls accordingly."""
    train, test = synthetic
    m = ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=20, phase_method="likelihood").fit(train, dt=0.01)
    prior_only = _ctrl_mse(m, test, 0.0, oracle=False)
    e_lik = {p: _ctrl_mse(m, test, p, oracle=False) for p in (0.3, 0.6)}
    m.phase_method = "dtw"
    e_dtw = {p: _ctrl_mse(m, test, p, oracle=False) for p in (0.3, 0.6)}
    assert e_lik[0.6] < 0.2 * prior_only and e_lik[0.3] < 0.6 * prior_only
    assert e_lik[0.6] < 0.2 * e_dtw[0.6] and e_lik[0.3] < e_dtw[0.3]


def test_single_agent_recovers_its_own_demo():
    """observed_dofs = all columns: pattern completion of a training demo is nearly exact."""
    from interprim.synthetic import two_agent_demos

    demos = two_agent_demos(25, seed=1, stretch=(1.0, 1.0))
    m = ip.InteractionPrimitive(observed_dofs=[0, 1, 2, 3, 4], n_basis=20).fit(demos, dt=0.01)
    d = demos[3]
    pred = m.predict(d, phase=1.0)
    gt = time_normalise(d, 100)
    err = np.abs(pred.trajectory(100) - gt)
    assert np.max(err) < 0.03 * np.ptp(d) and np.mean(err) < 0.002
    # exact Eq. 18 (every eigen-direction of X^T X kept): the weakly identified goal of one DoF moves by ~3e-3
    np.testing.assert_allclose(pred.goal, d[-1], atol=5e-3)


def test_likelihood_stream_tracks_batch_phase(fitted, synthetic):
    """The default stream (likelihood phase, local search around its last estimate) stays close to the
    batch estimate, and given its phase it conditions exactly as the batch path does."""
    _, test = synthetic
    d = test[1]
    assert fitted.phase_method_used() == "likelihood"
    st = fitted.stream()
    T = d.shape[0]
    for m in range(1, T + 1):
        p = st.update(d[m - 1, :2])
        if m in (20, T // 2, T - 1):
            b = fitted.predict(d[:m, :2])
            true = (m - 1) / (T - 1)
            assert abs(p.phase - b.phase) < 0.05 and abs(p.phase - true) < 0.06
            same = fitted.predict(d[:m, :2], phase=p.normalised_time)
            np.testing.assert_allclose(p.trajectory(50), same.trajectory(50), rtol=1e-9, atol=1e-10)


def test_stream_equals_batch_predict(fitted_paper, synthetic):
    fitted = fitted_paper
    _, test = synthetic
    d = test[1]
    st = fitted.stream()
    for m in range(1, 60):
        p = st.update(d[m - 1, :2])
        if m in (1, 2, 10, 59):
            b = fitted.predict(d[:m, :2])
            assert p.n_star == b.n_star and p.phase == pytest.approx(b.phase)
            np.testing.assert_allclose(p.trajectory(50), b.trajectory(50), rtol=1e-10, atol=1e-12)
    assert st.n_frames == 59
    st.reset()
    assert st.n_frames == 0
    p_mean_only = st.update(d[0, :2], need_cov=False)
    assert p_mean_only.std(10).shape == (10, 5)  # covariance computed on demand


def test_robot_state_sets_controlled_start(fitted, synthetic):
    _, test = synthetic
    rs = np.array([0.3, -0.2, 0.1])
    pred = fitted.predict(test[0][:50, :2], robot_state=rs)
    np.testing.assert_allclose(pred.trajectory(10)[0, 2:], rs, atol=1e-9)
    t, y = pred.response(20, state=rs)
    np.testing.assert_allclose(y[0], rs, atol=1e-9)
    with pytest.raises(ValueError, match="robot_state"):
        fitted.predict(test[0][:50, :2], robot_state=[1.0])


def test_dt_and_times_of_partial(fitted, synthetic):
    _, test = synthetic
    d = test[2]
    base = fitted.predict(d[:100, :2])
    half = fitted.predict(d[:100:2, :2], dt=0.02)  # same movement at half the rate
    assert half.phase == pytest.approx(base.phase, abs=0.02)
    t = np.arange(100) * 0.01
    assert fitted.predict(d[:100, :2], times=t).phase == pytest.approx(base.phase)


def test_fit_with_times_resamples_irregular_demos(synthetic):
    train, _ = synthetic
    rng = np.random.default_rng(0)
    times, demos = [], []
    for d in train[:10]:
        t = np.cumsum(rng.uniform(0.005, 0.015, len(d)))
        times.append(t)
        demos.append(d)
    m = ip.InteractionPrimitive(observed_dofs=[0, 1]).fit(demos, times=times)
    assert 0.008 < m.dt_ < 0.012 and m.mean_duration_ > 1.0


@pytest.mark.slow  # fits PCA models with CV
def test_pca_model(synthetic):
    train, test = synthetic
    m = ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=15, pca_components=(1, 2)).fit(train, dt=0.01)
    assert m.n_latent_ == 3 and m.prior_.mean.shape == (3 * 16,)
    pred = m.predict(test[0][:120, :2], phase=119 / (len(test[0]) - 1))
    assert pred.trajectory(40).shape == (40, 5) and pred.std(40).shape == (40, 5)
    full = ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=15).fit(train, dt=0.01)
    gt = time_normalise(test[0], 40)
    e_pca = np.mean((pred.trajectory(40)[:, 2:] - gt[:, 2:]) ** 2)
    e_prior = np.mean((full.predict(test[0][:1, :2]).trajectory(40)[:, 2:] - gt[:, 2:]) ** 2)
    assert e_pca < e_prior


def test_pca_roundtrip():
    from interprim.core.preprocessing import PCA

    rng = np.random.default_rng(0)
    X = rng.normal(size=(200, 3)) @ rng.normal(size=(3, 8))  # rank 3 in 8-D
    p = PCA(3).fit(X)
    np.testing.assert_allclose(p.inverse_transform(p.transform(X)), X, atol=1e-9)
    assert p.explained_variance_ratio_.sum() == pytest.approx(1.0)


@pytest.mark.parametrize("observation", ["forcing", "position"])
def test_save_load_roundtrip_exact(tmp_path, synthetic, observation):
    train, test = synthetic
    m = ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=12, observation=observation,
                                pca_components=(2, 2)).fit(train, dt=0.01)
    path = tmp_path / "model.npz"
    m.save(path)
    m2 = ip.InteractionPrimitive.load(path)
    assert m2.json_params() == m.json_params()
    for a in ("thetas_", "reference_", "start_position_", "start_velocity_"):
        np.testing.assert_array_equal(getattr(m2, a), getattr(m, a))
    np.testing.assert_array_equal(m2.prior_.cov, m.prior_.cov)
    p1, p2 = m.predict(test[0][:70, :2]), m2.predict(test[0][:70, :2])
    np.testing.assert_array_equal(p1.trajectory(30), p2.trajectory(30))


def _corrupt_files(tmp_path, good):
    data = good.read_bytes()
    (tmp_path / "trunc.npz").write_bytes(data[: len(data) // 2])
    (tmp_path / "garbage.npz").write_bytes(b"\x00not a zip file at all" * 10)
    with np.load(good) as f:
        arrays = {k: f[k] for k in f.files}
    meta = json.loads(arrays["metadata"].tobytes())
    meta["format_version"] = 99
    np.savez(tmp_path / "version.npz", **{**arrays, "metadata": np.frombuffer(json.dumps(meta).encode(), np.uint8)})
    np.savez(tmp_path / "shape.npz", **{**arrays, "prior_mean": arrays["prior_mean"][:-1]})
    np.savez(tmp_path / "nan.npz", **{**arrays, "prior_cov": arrays["prior_cov"] * np.nan})
    np.savez(tmp_path / "nometa.npz", **{k: v for k, v in arrays.items() if k != "metadata"})
    np.savez(tmp_path / "badjson.npz", **{**arrays, "metadata": np.frombuffer(b"{not json", np.uint8)})
    np.savez(tmp_path / "objects.npz", metadata=np.array([{"a": 1}], dtype=object))


@pytest.mark.parametrize("name,match", [
    ("trunc.npz", "not a readable"), ("garbage.npz", "not a readable"), ("version.npz", "format_version 99"),
    ("shape.npz", "prior_mean"), ("nan.npz", "prior_cov"), ("nometa.npz", "metadata"), ("badjson.npz", "metadata"),
    ("objects.npz", "not a readable"), ("missing.npz", "no such"),
])
def test_bad_model_files(tmp_path, fitted, name, match):
    good = tmp_path / "good.npz"
    fitted.save(good)
    _corrupt_files(tmp_path, good)
    with pytest.raises(ip.ModelFileError, match=match):
        ip.InteractionPrimitive.load(tmp_path / name)


def test_save_is_atomic_and_pickle_free(tmp_path, fitted):
    p = tmp_path / "m.npz"
    fitted.save(p)
    assert not (tmp_path / "m.npz.tmp").exists()
    with zipfile.ZipFile(p) as z:
        for name in z.namelist():
            header = z.read(name)[:200]
            assert b"'descr': '|O'" not in header  # no object arrays


def test_bad_inputs(synthetic):
    train, test = synthetic
    M = ip.InteractionPrimitive
    with pytest.raises(ip.NotFittedError, match="fit"):
        M(observed_dofs=[0]).predict(np.zeros((3, 1)))
    with pytest.raises(ip.NotFittedError):
        M(observed_dofs=[0]).stream()
    with pytest.raises(ValueError, match="at least 2 demonstrations"):
        M(observed_dofs=[0]).fit(train[:1])
    with pytest.raises(ValueError, match=r"demos\[1\] has 4 columns"):
        M(observed_dofs=[0]).fit([train[0], train[1][:, :4]])
    bad = train[2].copy()
    bad[7, 1] = np.nan
    with pytest.raises(ValueError, match=r"demos\[1\] contains 1 non-finite.*frame 7, column 1"):
        M(observed_dofs=[0]).fit([train[0], bad])
    with pytest.raises(ValueError, match=r"demos\[1\] has 3 frames"):
        M(observed_dofs=[0]).fit([train[0], train[1][:3]])
    with pytest.raises(ValueError, match="out of range"):
        M(observed_dofs=[0, 7]).fit(train)
    with pytest.raises(TypeError, match="observed_dofs"):
        M(observed_dofs="0,1").fit(train)
    with pytest.raises(ValueError, match="times has 1 entries"):
        M(observed_dofs=[0]).fit(train[:2], times=[np.arange(len(train[0]))])
    with pytest.raises(ValueError, match="strictly increasing"):
        M(observed_dofs=[0]).fit(train[:2], times=[np.zeros(len(train[0])), np.arange(len(train[1]))])
    with pytest.raises(ValueError, match="sigma2"):
        M(observed_dofs=[0], sigma2=-1.0).fit(train)
    with pytest.raises(ValueError, match="observation"):
        M(observed_dofs=[0], observation="velocity").fit(train)
    with pytest.raises(TypeError, match="list"):
        M(observed_dofs=[0]).fit("demos.csv")
    m = M(observed_dofs=[0, 1], n_basis=8).fit(train, dt=0.01)
    with pytest.raises(ValueError, match="partial has 3 columns, expected 2"):
        m.predict(test[0][:10, :3])
    with pytest.raises(ValueError, match="partial contains"):
        m.predict(np.full((4, 2), np.inf))
    with pytest.raises(ValueError, match="partial must be 2-D"):
        m.predict(np.zeros((2, 3, 4)))
    with pytest.raises(ValueError, match="phase must be in"):
        m.predict(test[0][:10, :2], phase=1.5)
    st = m.stream()
    with pytest.raises(ValueError, match=r"frame must have shape \(2,\)"):
        st.update([1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match="NaN"):
        st.update([np.nan, 0.0])
    assert st.n_frames == 0  # a rejected frame does not corrupt the stream
    st.update([0.0, 0.0])
    assert st.n_frames == 1


@pytest.mark.slow  # fits and scores several models on noisy input (~20 s under load)
def test_input_noise_makes_clean_models_robust_to_noisy_input():
    """Models learned from clean (simulated) demonstrations choose a tiny sigma2 by CV; noisy online input then
    moves the predicted high-five point far.  ``input_noise`` adds the sensor's variance and fixes that."""
    from interprim.sim import highfive_split

    train, test = highfive_split(40, 4, seed=0, progress=False)
    rng = np.random.default_rng(0)
    cases = [(d[: int(0.6 * len(d)), :2] + 0.01 * rng.standard_normal((int(0.6 * len(d)), 2)), g)
             for d, g in zip(test.demos, test.goals)]
    ca = test.controlled_arm
    err = {}
    for noise in (None, 0.01):
        m = ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=15, input_noise=noise).fit(train.demos,
                                                                                             dt=train.dt)
        err[noise] = np.mean([np.linalg.norm(ca.hand(m.predict(z).goal[2:]) - g) for z, g in cases])
        if noise:
            assert m.get_params()["input_noise"] == 0.01 and "input_noise=0.01" in repr(m)
    assert err[0.01] < 0.5 * err[None] and err[0.01] < 0.08, err
    with pytest.raises(ValueError, match="input_noise"):
        ip.InteractionPrimitive(observed_dofs=[0, 1], input_noise=float("nan")).fit(train.demos, dt=train.dt)


def test_fit_takes_a_demonstrations_object_and_keeps_column_names(synthetic, tmp_path):
    from interprim.datasets import Demonstrations

    train, _ = synthetic
    cols = ["h_x", "h_y", "r_1", "r_2", "r_3"]
    ds = Demonstrations(demos=train[:8], times=[np.arange(len(d)) * 0.02 for d in train[:8]], columns=cols)
    m = ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=8, sigma2="residual").fit(ds)
    assert m.dt_ == pytest.approx(0.02) and m.columns_ == cols
    m.save(tmp_path / "m.npz")
    assert ip.InteractionPrimitive.load(tmp_path / "m.npz").columns_ == cols
    with pytest.raises(ValueError, match="columns has 2 names"):
        ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=8).fit(train[:4], columns=["a", "b"])


@pytest.mark.parametrize("phase_method", ["likelihood", "dtw"])
def test_prediction_does_not_depend_on_the_callers_array_afterwards(synthetic, phase_method):
    """A robot loop reuses its frame buffer: a Prediction must not keep views into it."""
    train, test = synthetic
    m = ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=10, sigma2="residual", phase_method=phase_method).fit(
        train[:12], dt=0.01)
    buf = np.ascontiguousarray(test[0][:60, :2], dtype=np.float64)
    p = m.predict(buf)
    ref = m.predict(buf.copy())
    buf[:] = 123.0  # the caller overwrites its buffer before reading the prediction
    np.testing.assert_array_equal(p.trajectory(30), ref.trajectory(30))
    for a, b in zip(p.completion(30), ref.completion(30)):
        np.testing.assert_array_equal(a, b)
    assert p.dtw_cost == ref.dtw_cost


def test_two_demonstrations_need_explicit_noise():
    """sigma2='cv' cannot cross-validate two demonstrations: a clear error that says what to do (was a KeyError
    deep in the selection); with sigma2 and covariance given, two demonstrations fit."""
    from interprim.synthetic import two_agent_demos

    d = two_agent_demos(2)
    with pytest.raises(ValueError, match="at least 3 demonstrations, got 2"):
        ip.InteractionPrimitive(observed_dofs=[0, 1]).fit(d, dt=0.01)
    m = ip.InteractionPrimitive(observed_dofs=[0, 1], sigma2=1e-3, covariance="ridge").fit(d, dt=0.01)
    assert 0.0 < m.predict(d[0][:50, :2]).normalised_time <= 1.0


@pytest.mark.parametrize("phase", [0.40013, 0.6, 0.77771])  # s * n_steps rounding down, exact, rounding up
def test_continuations_start_exactly_at_the_current_state(fitted, synthetic, phase):
    """The completion starts at the last observed frame and the response at the robot's state whatever the phase:
    output times are counted from the snapped start (no interpolation towards the next grid point at ``s0``)."""
    _, test = synthetic
    d = test[1]
    rs = np.array([0.2, 0.1, -0.3])
    pred = fitted.predict(d[:40, :2], phase=phase)
    s, yc = pred.completion(25)
    assert s[0] == pytest.approx(phase)
    np.testing.assert_allclose(yc[0], d[39, :2], atol=1e-12)
    t, y = pred.response(25, state=rs)
    np.testing.assert_allclose(y[0], rs, atol=1e-12)
    t_ref, y_ref = pred._response_reference(25, state=rs)  # the compiled kernel counts times the same way
    np.testing.assert_allclose(y, y_ref, rtol=1e-9, atol=1e-12)

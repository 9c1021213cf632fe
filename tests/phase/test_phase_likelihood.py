"""Phase estimation by the marginal likelihood of the observation (interprim.phase.likelihood,
interprim.phase.tracking)."""

import numpy as np
import pytest

import interprim as ip
from interprim.core._compiled import registry as kernels
from interprim.phase.dtw import open_end_dtw
from interprim.phase.likelihood import estimate_phase, phase_log_likelihood


@pytest.fixture(scope="module")
def lik_model(synthetic):
    train, _ = synthetic
    return ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=15, phase_method="likelihood").fit(train, dt=0.01)


def _cases(test, fractions=(0.3, 0.5, 0.7, 0.9)):
    for d in test:
        T = d.shape[0]
        for p in fractions:
            M = int(round(p * T))
            yield d[:M, :2], (M - 1) / (T - 1)


def test_likelihood_phase_beats_dtw_on_goal_varying_demos(synthetic, lik_model):
    _, test = synthetic
    N1 = lik_model.reference_.shape[0] - 1
    e_lik, e_dtw = [], []
    for z, s_true in _cases(test):
        e_dtw.append(abs(open_end_dtw(lik_model.reference_, z, return_path=False).n_star / N1 - s_true))
        e_lik.append(abs(lik_model.predict(z).normalised_time - s_true))
    assert np.mean(e_lik) < 0.05
    assert np.mean(e_lik) < 0.5 * np.mean(e_dtw)


def test_phase_noise_is_selected_and_reported(lik_model):
    assert lik_model.phase_sigma2_ > 0
    sel = lik_model.selection_
    assert sel["phase_sigma2"] == lik_model.phase_sigma2_
    assert len(sel["phase_error"]) == len(sel["phase_sigma2_grid"])


def test_estimate_phase_maximises_the_curve(synthetic, lik_model):
    _, test = synthetic
    z = test[0][:80, :2]
    est = estimate_phase(lik_model.fitted_, z, refine=True)
    assert 0.0 < est.s_end <= 1.0
    assert est.grid.shape == est.curve.shape
    assert est.log_posterior >= est.curve.max() - 1e-9
    # the likelihood at the estimate is higher than far away from it
    far = 1.0 if est.s_end < 0.5 else 0.1
    assert phase_log_likelihood(lik_model.fitted_, z, est.s_end) > phase_log_likelihood(lik_model.fitted_, z, far)


def test_known_phase_bypasses_estimation(synthetic, lik_model):
    _, test = synthetic
    p = lik_model.predict(test[0][:60, :2], phase=0.4)
    assert p.normalised_time == pytest.approx(0.4)


def test_stream_tracks_phase_with_local_search(synthetic, lik_model):
    _, test = synthetic
    d = test[1]
    T = d.shape[0]
    st = lik_model.stream()
    for k in range(int(0.7 * T)):
        pred = st.update(d[k, :2], need_cov=False)
    s_true = (int(0.7 * T) - 1) / (T - 1)
    assert abs(pred.normalised_time - s_true) < 0.08


def test_phase_method_validated_and_saved(tmp_path, synthetic, lik_model):
    train, test = synthetic
    with pytest.raises(ValueError, match="phase_method"):
        ip.InteractionPrimitive(observed_dofs=[0, 1], phase_method="magic").fit(train, dt=0.01)
    path = tmp_path / "m.npz"
    lik_model.save(path)
    m2 = ip.InteractionPrimitive.load(path)
    assert m2.phase_method == "likelihood"
    assert m2.phase_sigma2_ == lik_model.phase_sigma2_
    p = m2.predict(test[0][:100, :2])  # the same phase and prediction after the round trip
    p0 = lik_model.predict(test[0][:100, :2])
    assert p.normalised_time == pytest.approx(p0.normalised_time, abs=1e-12)
    np.testing.assert_allclose(p.trajectory(20), p0.trajectory(20), atol=1e-10)


# --- batched / compiled evaluation against the per-candidate reference -------------------------------------------

from interprim.phase import likelihood as PL  # noqa: E402
from interprim.phase import tracking as PT  # noqa: E402


def _demos(n, D=4, T=120, seed=0):
    r = np.random.default_rng(seed)
    t = np.linspace(0, 1, T)[:, None]
    out = []
    for _ in range(n):
        g = r.normal(size=D)
        obs = (1 - np.cos(np.pi * t)) / 2 * g + 0.05 * np.sin(3 * np.pi * t) * r.normal(size=D)
        ctrl = (1 - np.cos(np.pi * t)) / 2 * (0.5 * g[:2] + 0.1 * r.normal(size=2))
        out.append(np.hstack([obs, ctrl]))
    return out


_SMALL = {}


def _small_model(observation, pca, covariance):
    key = (observation, pca, covariance)
    if key not in _SMALL:
        _SMALL[key] = ip.InteractionPrimitive(
            observed_dofs=[0, 1, 2, 3], n_basis=8, observation=observation, pca_components=pca,
            covariance=covariance, sigma2=1e-2, phase_method="likelihood").fit(_demos(12), dt=0.01)
    return _SMALL[key]


def _latent(model, frames):
    return model.fitted_.observed_to_latent(frames[:, model.observed_dofs_])


def _both_paths(model, z, s, s2):
    fs = PL.fast_state(model.fitted_)
    assert fs is not None
    Rg = fs.mean_path(np.ascontiguousarray(z[0]))
    num = PL._loglik_batch_numpy(fs.Zh, Rg, np.ascontiguousarray(z), s, fs.sq, fs.Uh, fs.K0, s2)
    assert kernels.kernel("phase_likelihood.phase_loglik_batch") is not None
    comp = fs.loglik(z, s, s2)
    return num, comp


@pytest.mark.parametrize("observation", ["position", "forcing"])
@pytest.mark.parametrize("pca", [None, 2])
@pytest.mark.parametrize("covariance", ["shrinkage", "ridge"])
def test_batched_log_likelihoods_equal_reference(observation, pca, covariance):
    model = _small_model(observation, pca, covariance)
    test = _demos(1, seed=7)[0]
    s = np.exp(np.linspace(np.log(0.02), 0.0, 15))
    for M in (2, 3, 17, 60, 120):
        z = _latent(model, test[:M])
        s2 = PL.phase_noise(model.fitted_)
        ref = np.array([PL._phase_log_likelihood_reference(model.fitted_, z, x, s2) for x in s])
        num, comp = _both_paths(model, z, s, s2)
        np.testing.assert_allclose(num, ref, rtol=1e-8, atol=0)
        np.testing.assert_allclose(comp, ref, rtol=1e-8, atol=0)
        np.testing.assert_allclose(PL.phase_log_likelihoods(model.fitted_, z, s), ref, rtol=1e-8, atol=0)
        assert PL.phase_log_likelihood(model.fitted_, z, s[3]) == pytest.approx(ref[3], rel=1e-8)


def test_batched_log_likelihood_matches_extended_precision_where_reference_loses_digits():
    """At a small noise the reference (eigendecomposition of H^T H, subtraction of projected residuals) loses
    digits; the batched form agrees with a direct dense evaluation in extended precision."""
    model = _small_model("position", None, "shrinkage")
    z = _latent(model, _demos(1, seed=7)[0][:30])
    pr = PL._factored(model.fitted_)
    n_o, q = model.n_observed_latent_, model.params_per_dof_
    LD = np.longdouble
    for s2 in (1e-2, 1e-6):
        for s in (0.3, 0.8):
            X, Y = PL.observation_design(model.fitted_, z, s, "position")
            H = X.astype(LD)
            mu = pr.mean[: n_o * q].reshape(n_o, q).astype(LD)
            W = pr.W.astype(LD)
            Sig = W.T @ W
            Sig[np.diag_indices_from(Sig)] += pr.d.astype(LD)
            Xb = np.kron(np.eye(n_o, dtype=LD), H)
            r = (Y.astype(LD) - H @ mu.T).T.reshape(-1)
            C = Xb @ Sig @ Xb.T
            C[np.diag_indices_from(C)] += LD(s2)
            N = C.shape[0]
            L = np.zeros_like(C)
            for j in range(N):  # Cholesky in extended precision
                L[j, j] = np.sqrt(C[j, j] - L[j, :j] @ L[j, :j])
                L[j + 1:, j] = (C[j + 1:, j] - L[j + 1:, :j] @ L[j, :j]) / L[j, j]
            y = np.zeros(N, dtype=LD)
            for i in range(N):
                y[i] = (r[i] - L[i, :i] @ y[:i]) / L[i, i]
            truth = float(-0.5 * (N * np.log(2 * np.pi) + 2 * np.sum(np.log(np.diag(L))) + y @ y))
            num, comp = _both_paths(model, z, np.array([s]), s2)
            assert comp[0] == pytest.approx(truth, rel=1e-11)
            assert num[0] == pytest.approx(truth, rel=1e-11)


def test_dense_fallback_when_prior_is_not_low_rank():
    import copy

    model = _small_model("position", None, "shrinkage")
    n = model.n_observed_latent_ * model.params_per_dof_
    prior = copy.copy(model.prior_)
    cov = prior.cov.copy()
    cov[:n, :n] += 0.05 * np.mean(np.diag(cov[:n, :n])) * np.eye(n)  # no longer diag(d) + W^T W of thetas_
    prior.cov = cov
    model = model.with_fitted(prior_=prior)
    assert PL._factored(model.fitted_) is None and PL.fast_state(model.fitted_) is None
    z = _latent(model, _demos(1, seed=7)[0][:50])
    s = np.array([0.2, 0.45, 0.9])
    ref = [PL._phase_log_likelihood_reference(model.fitted_, z, x) for x in s]
    np.testing.assert_allclose(PL.phase_log_likelihoods(model.fitted_, z, s), ref, rtol=1e-12)
    est = estimate_phase(model.fitted_, z)
    assert 0.0 < est.s_end <= 1.0


def _paused(frames, pre=20, post=40):
    """Frames held still before and after the movement (the tracker's phase clips at S_MIN and at 1)."""
    return np.concatenate([np.repeat(frames[:1], pre, 0), frames, np.repeat(frames[-1:], post, 0)])


def _window_reference(model, z, ss):
    """Log posterior of each candidate phase, one reference evaluation each (no batching, no kernel)."""
    s2 = PL.phase_noise(model.fitted_)
    M = z.shape[0]
    fitted = model.fitted_
    return np.array([PL._phase_log_likelihood_reference(fitted, z, s, s2) + float(PL.log_speed_prior(fitted, M, s))
                     for s in ss])


@pytest.mark.parametrize("observation", ["position", "forcing"])
def test_stream_lattice_scores_equal_reference(observation, monkeypatch):
    """Every lattice window the stream scores (slots extended frame by frame, clipped candidates, re-centred
    windows) equals the per-candidate reference evaluation of the log posterior."""
    model = _small_model(observation, None, "shrinkage")
    assert kernels.kernel("phase_likelihood.phase_loglik_batch") is not None
    frames = _paused(_demos(1, seed=11)[0])[:, model.observed_dofs_]
    seen = []
    real = PT.finish

    def spy(scores, ss, lps, i, lo, hi):
        seen.append((scores.M, np.array(ss), np.array(lps), i))
        return real(scores, ss, lps, i, lo, hi)

    monkeypatch.setattr(PT, "finish", spy)
    st = model.stream()
    for f in frames:
        st.update(f)
    assert len(seen) > frames.shape[0] - 10
    assert any(ss[-1] == 1.0 for _, ss, _, _ in seen)  # the clipped candidate at s = 1 is scored too
    for M, ss, lps, i in seen[::3]:
        ref = _window_reference(model, st._buf[:M], ss)
        np.testing.assert_allclose(lps, ref, rtol=1e-9, atol=1e-9)
        assert i == int(np.argmax(ref))


@pytest.mark.parametrize("observation, paused", [("position", False), ("forcing", False), ("position", True)])
def test_stream_phase_and_prediction_equal_batch(observation, paused):
    """Issue 12: streaming a movement frame by frame ends where ``predict`` on the same frames is, at every
    frame.  Both phases are the same local maximum of the same log posterior reached by the same last step
    (``finish``), so they differ by ~1e-8 of the movement at most; measured (issue 20): phase 2.9e-12,
    trajectory 4e-12 (position) and 1.2e-9 (forcing) relative.  Asserted: phase 1e-8, trajectory 1e-7
    (tightened from issue 12's 1e-3)."""
    model = _small_model(observation, None, "shrinkage")
    assert kernels.kernel("phase_likelihood.phase_loglik_batch") is not None
    frames = _demos(1, seed=11)[0][:, model.observed_dofs_]
    if paused:  # held still before and after: phases clipped at s_min and at 1
        frames = _paused(frames)
    st = model.stream()
    worst_s = worst_y = 0.0
    for M in range(1, frames.shape[0] + 1):
        p = st.update(frames[M - 1])
        if M < 3:
            continue
        q = model.predict(frames[:M])
        worst_s = max(worst_s, abs(p.normalised_time - q.normalised_time))
        y, yq = p.trajectory(50), q.trajectory(50)
        worst_y = max(worst_y, float(np.max(np.abs(y - yq)) / np.max(np.abs(yq))))
    assert worst_s < 1e-8
    assert worst_y < 1e-7


def test_finish_finds_the_maximum_and_does_not_depend_on_the_starting_candidates():
    """``finish`` (a parabola through the best candidate and its neighbours, then one through ``u1 -+ h``):
    on smooth peaked functions it lands within ``c h^2 / (2 k)`` of the maximiser, and from two different
    sets of candidates (a coarse grid or a fine lattice) at the same point to ~1e-8, which is what makes the
    stream's phase the batch's; a maximum at a bound is returned as the bound."""
    rng = np.random.default_rng(5)

    def scorer(f):
        def sc(s):
            v = f(np.asarray(s))
            return v, v
        return sc

    for _ in range(40):
        c, k = rng.uniform(0.1, 0.95), rng.uniform(1e2, 1e5)
        def f(s, c=c, k=k):
            return -k * np.log(s / c) ** 2 - 0.3 * k * np.log(s / c) ** 3

        sc = scorer(f)
        fine = np.exp(np.linspace(np.log(c) - 0.4, min(np.log(c) + 0.4, 0.0), 400001))
        s_max = fine[np.argmax(f(fine))]
        ss1 = c * np.exp(np.linspace(-0.03, 0.03, 7) + rng.uniform(-0.005, 0.005))  # a lattice window
        ss1 = ss1[ss1 <= 1.0]
        ss2 = c * np.exp(np.array([-0.012, 0.0007, 0.009]))  # around a Brent estimate
        ss2 = ss2[ss2 <= 1.0]
        out = []
        for ss in (ss1, ss2):
            lps = f(ss)
            out.append(PL.finish(sc, ss, lps, int(np.argmax(lps)), 0.02, 1.0))
        bias = 0.3 * PL._H_FINAL ** 2  # c h^2 / (2 k) in log s, with c = 0.3 k (and the grid of the reference)
        assert abs(np.log(out[0] / s_max)) < bias + 2e-6
        assert abs(out[0] - out[1]) < 1e-7
    inc = scorer(lambda s: s)  # increasing: the maximum is the bound
    ss = np.array([0.9, 0.95, 1.0])
    assert PL.finish(inc, ss, ss, 2, 0.02, 1.0) == 1.0


def _slot_errors(tr, z):
    """Largest relative differences between the tracker's slots (extended frame by frame) and a recomputation
    from scratch at the same lattice speeds: statistics, log-likelihood (same rows), log-likelihood of the
    batch kernel at ``s = v (M - 1)``."""
    from interprim.core._compiled import phase_likelihood as PK

    M = z.shape[0]
    fs, b = tr._fs, tr._buf
    s2 = PL.phase_noise(tr.model)
    tmp = PK.track_buffers(fs.q, fs.n_o, fs.Uh.shape[2])
    q, n_o = fs.q, fs.n_o
    err = np.zeros(4)
    live = np.nonzero((b[0] != PT._SLOT_FREE) & (b[1] == M))[0]
    for k in live:
        v = tr.v0 * np.exp(tr.dlog * b[0][k])
        G = tmp[3][0]
        q4 = G.shape[0]
        rr = PK._stats_lattice(fs.Zh, tr.Rg, z, M, v * (fs.Zh.shape[0] - 1), q4, tmp[8], G, tmp[15][0], tmp[15][1])
        ld, J = PK._dense_full(G, rr, q4, fs.sq, fs.Uh, fs.K0, s2, tmp[5][0], tmp[6][0], tmp[18][0], tmp[19][0],
                               *tmp[9:14], tmp[15][2], tmp[15][3])
        ll_f = PK._eval_slot(J, ld, M, n_o, q, s2, tmp[6][0], tmp[19][0], tmp[14])
        ll_i = PK._eval_slot(b[20][k], b[7][k], M, n_o, q, s2, b[6][k], b[19][k], tmp[14])
        for a, f in ((b[20][k], J), (b[7][k], ld), (b[18][k], tmp[18][0]), (b[19][k], tmp[19][0]),
                     (np.tril(b[6][k]), np.tril(tmp[6][0])), (b[5][k], tmp[5][0])):
            err[3] = max(err[3], np.abs(a - f).max() / np.abs(f).max())
        batch = kernels.compiled("phase_likelihood.phase_loglik_batch")
        ll_b = batch(fs.Zh, tr.Rg, z, M, np.array([v * (M - 1)]), fs.sq, fs.Uh, fs.K0, s2, np.empty(1))[0]
        Gi, Gf = np.triu(b[3][k][:q, :q]), np.triu(G[:q, :q])
        Bi, Bf = b[3][k][:q, q4:q4 + n_o], G[:q, q4:q4 + n_o]
        err[0] = max(err[0], np.abs(Gi - Gf).max() / np.abs(Gf).max(), np.abs(Bi - Bf).max() / np.abs(Bf).max(),
                     abs(b[4][k] - rr) / rr)
        err[1] = max(err[1], abs(ll_i - ll_f) / abs(ll_f))
        err[2] = max(err[2], abs(ll_i - ll_b) / abs(ll_b))
    return err, live.size


@pytest.mark.parametrize("kw", [{}, {"pca_components": 2}, {"smoothing_window": 7},
                                {"pca_components": 2, "smoothing_window": 7, "observation": "forcing"}])
def test_stream_incremental_statistics_equal_recomputation(kw):
    """Each lattice point's statistics and factors, extended by one frame at a time (and caught up after
    leaving the candidate window), equal a recomputation from all frames."""
    model = ip.InteractionPrimitive(observed_dofs=[0, 1, 2, 3], n_basis=8, sigma2=1e-2, phase_method="likelihood",
                                    **kw).fit(_demos(12), dt=0.01)
    assert kernels.kernel("phase_likelihood.phase_loglik_batch") is not None
    frames = _paused(_demos(1, seed=11)[0], 10, 20)[:, model.observed_dofs_]
    st = model.stream()
    worst, n_checked = np.zeros(4), 0
    for k in range(frames.shape[0]):
        st.update(frames[k])
        if k >= 2:
            e, c = _slot_errors(st._tracker, st._buf[: k + 1])
            worst = np.maximum(worst, e)
            n_checked += c
    assert n_checked > 2 * frames.shape[0]  # 3 lattice candidates per frame, fewer where clipped ones merge
    assert worst[0] < 1e-12
    assert worst[1] < 1e-10
    assert worst[2] < 1e-10
    assert worst[3] < 1e-9


def _numpy_phase_kernels(mp):
    """The likelihood phase's kernels answer ``None`` (numpy), the other kernels stay compiled."""
    real = kernels.kernel
    mp.setattr(kernels, "kernel", lambda name: None if name.startswith("phase_likelihood.") else real(name))


def test_stream_tracker_numpy_fallback_and_reset(monkeypatch):
    model = _small_model("position", 2, "shrinkage")
    assert kernels.kernel("phase_likelihood.phase_loglik_batch") is not None
    frames = _paused(_demos(1, seed=11)[0])[:, model.observed_dofs_]
    st = model.stream()
    got = np.array([st.update(f).normalised_time for f in frames])
    st.reset()
    again = np.array([st.update(f).normalised_time for f in frames[:50]])
    np.testing.assert_array_equal(again, got[:50])
    with monkeypatch.context() as mp:  # no compiled kernel: the same candidates scored by numpy
        _numpy_phase_kernels(mp)
        st.reset()
        num = np.array([st.update(f).normalised_time for f in frames])
    # the refinement's parabola vertex divides score differences by (curvature x lattice spacing): the two
    # paths' scores agree to ~1e-12 relative (|log posterior| ~ 1e3 here), curvature x spacing is >= ~0.1, so
    # the phases agree to ~1e-8 (measured 8e-11)
    np.testing.assert_allclose(num, got, rtol=0, atol=1e-8)
    st2 = model.stream()  # kernel back mid-stream (numpy first): the slots start afresh
    for k, f in enumerate(frames):
        if k < 40:
            with monkeypatch.context() as mp:
                _numpy_phase_kernels(mp)
                p = st2.update(f)
        else:
            p = st2.update(f)
        assert p.normalised_time == pytest.approx(got[k], abs=1e-8)


@pytest.mark.parametrize("n_basis, n_obs, n_demos", [(7, 3, 12), (8, 1, 5), (10, 2, 9)])
def test_compiled_kernel_padding_shapes_equal_reference(n_basis, n_obs, n_demos):
    """The kernel pads q, n + 1 and n to multiples of 4 and pairs the observed DoFs: sizes on and off those
    multiples, an odd number of observed DoFs, and fewer demonstrations than basis functions."""
    model = ip.InteractionPrimitive(observed_dofs=list(range(n_obs)), n_basis=n_basis, sigma2=1e-2,
                                    phase_method="likelihood").fit(_demos(n_demos, D=4), dt=0.01)
    s2 = PL.phase_noise(model.fitted_)
    s = np.exp(np.linspace(np.log(0.05), 0.0, 9))
    for M in (2, 5, 64, 65, 120):
        z = _latent(model, _demos(1, D=4, seed=3)[0][:M])
        ref = np.array([PL._phase_log_likelihood_reference(model.fitted_, z, x, s2) for x in s])
        num, comp = _both_paths(model, z, s, s2)
        np.testing.assert_allclose(comp, ref, rtol=1e-8, atol=0)
        np.testing.assert_allclose(num, ref, rtol=1e-8, atol=0)


def test_brent_search_matches_scipy_bounded_minimiser():
    """The hand-written bounded Brent search (no scipy.optimize import on the online path) finds the
    minimiser that scipy.optimize.minimize_scalar(method='bounded') finds, to the requested tolerance."""
    from scipy.optimize import minimize_scalar

    from interprim.phase.likelihood import brent_min

    rng = np.random.default_rng(3)
    for _ in range(40):
        c, k = rng.uniform(0.1, 0.9), rng.uniform(0.5, 5.0)

        def f(s, c=c, k=k):
            return k * (s - c) ** 2 + 0.3 * (s - c) ** 3 + np.cos(3 * s) * 0.01

        a, b = max(0.0, c - rng.uniform(0.05, 0.3)), min(1.0, c + rng.uniform(0.05, 0.3))
        x0 = rng.uniform(a, b)
        tol = 1e-3 * b
        x, fx = brent_min(f, a, b, x0, f(x0), xatol=tol, maxiter=50)
        ref = minimize_scalar(f, bounds=(a, b), method="bounded", options={"xatol": tol})
        assert a <= x <= b and fx == pytest.approx(f(x))
        assert abs(x - ref.x) < 2 * tol
        assert fx <= ref.fun + 1e-6
    # a minimum at the bracket's end
    x, _ = brent_min(lambda s: s, 0.2, 0.6, 0.4, 0.4, xatol=1e-4, maxiter=60)
    assert x == pytest.approx(0.2, abs=3e-4)


def test_refined_phase_is_a_local_maximum(synthetic, lik_model):
    _, test = synthetic
    for frac in (0.2, 0.5, 0.8):
        z = test[1][: int(frac * test[1].shape[0]), :2]
        est = estimate_phase(lik_model.fitted_, z, refine=True)
        coarse = estimate_phase(lik_model.fitted_, z, refine=False)
        assert est.log_posterior >= coarse.log_posterior - 1e-12
        from interprim.phase.likelihood import make_scorer, phase_noise

        sc = make_scorer(lik_model.fitted_, z, phase_noise(lik_model.fitted_), True)
        h = 2e-3 * est.s_end
        nb = np.clip(np.array([est.s_end - h, est.s_end + h]), 1e-3, 1.0)
        nb = nb[np.abs(nb - est.s_end) > 1e-12]
        if nb.size:
            assert est.log_posterior >= sc(nb)[0].max() - 1e-6


def test_batch_predict_reports_the_dtw_cost_on_demand(synthetic, lik_model):
    """The likelihood-phase predict skips the DTW; ``dtw_cost`` is still D(n*, M) of Eq. 5-8 when asked."""
    _, test = synthetic
    obs = test[2][:70, :2]
    p = lik_model.predict(obs)
    z = lik_model.fitted_.observed_to_latent(obs)
    assert p.dtw_cost == pytest.approx(open_end_dtw(lik_model.reference_, z, return_path=False).cost, rel=1e-12)
    assert isinstance(p.dtw_cost, float)


@pytest.mark.parametrize("compiled", [True, False])
def test_scorer_prior_and_shared_parts_are_the_same_numbers(compiled, monkeypatch):
    """The scorer adds the speed prior element by element and the stream's tracker hands it the parts it already
    looked up for the frame: both give exactly (bit for bit) the log posterior ``log p(z | s) + log p(s)`` of
    :func:`~interprim.phase.likelihood.log_speed_prior`, on the compiled and the numpy path, also at a clipped
    candidate."""
    model = _small_model("position", None, "shrinkage").fitted_
    if not compiled:
        _numpy_phase_kernels(monkeypatch)
    z = _demos(1, seed=11)[0][:70, model.observed_dofs_]
    M = z.shape[0]
    s2 = PL.phase_noise(model)
    s = np.append(np.exp(np.linspace(np.log(PL.S_MIN), 0.0, 150)), [0.3107, 0.52])  # the bounds included
    sc = PL.make_scorer(model, z, s2)
    lp, ll = sc(s)
    np.testing.assert_array_equal(lp, ll + PL.log_speed_prior(model, M, s))
    parts = (PL.fast_state(model), PL.speed_prior_params(model, M))
    lp2, ll2 = PL.make_scorer(model, z, s2, _parts=parts)(s)
    np.testing.assert_array_equal(lp2, lp)
    np.testing.assert_array_equal(ll2, ll)
    lp3, ll3 = PL.make_scorer(model, z, s2, speed_prior=False)(s)  # no prior: the log-likelihood itself
    np.testing.assert_array_equal(lp3, ll)
    np.testing.assert_array_equal(ll3, ll)


@pytest.mark.parametrize("compiled", [True, False])
@pytest.mark.parametrize("speed_prior", [True, False])
def test_noise_curves_equal_one_scorer_per_noise(compiled, speed_prior, monkeypatch):
    """``make_scorer.noise_curves`` (the likelihood phase's noise selection: every noise on one grid of phases, each
    phase's statistics once) gives, column by column, exactly (bit for bit) what a scorer of that noise gives, on the
    compiled and the numpy path, over noises 12 decades apart (the selection's grid) and with or without the prior."""
    model = _small_model("position", None, "shrinkage").fitted_
    if not compiled:
        _numpy_phase_kernels(monkeypatch)
    z = _demos(1, seed=5)[0][:60, model.observed_dofs_]
    s2 = PL.phase_noise(model) * 10.0 ** np.arange(-6.0, 6.01, 1.5)
    s = np.exp(np.linspace(np.log(PL.S_MIN), 0.0, 24))
    curves = PL.make_scorer(model, z, 1.0, speed_prior=speed_prior).noise_curves(s, s2)
    assert curves.shape == (s.size, s2.size)
    one = np.stack([PL.make_scorer(model, z, float(v), speed_prior=speed_prior)(s)[0] for v in s2], axis=1)
    np.testing.assert_array_equal(curves, one)
    assert np.all(np.isfinite(curves))

"""The coupling model between the agents (interprim.models.coupling)."""

import numpy as np
import pytest

from interprim.core.errors import NotFittedError
from interprim.core.preprocessing import time_normalise
from interprim.models.coupling import CouplingModel
from interprim.models.grid import GridPrediction

T = 40
OBS = [0, 1]


def linear_demos(n, seed, coupled=True, noise=0.0):
    """Two-agent demos driven by a latent z ~ N(0, I_2).

    Observed agent: ``o_1 = z_1 sin(pi t) + 0.3 t``, ``o_2 = z_2 t^2``; controlled agent:
    ``c_1 = (z_1 + 0.5 z_2) sin(pi t) + noise``, ``c_2 = -z_2 t`` (or, with ``coupled=False``, the same
    shapes driven by an independent latent).
    """
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 1.0, T)
    out = []
    for _ in range(n):
        z = rng.standard_normal(2)
        zc = z if coupled else rng.standard_normal(2)
        o1 = z[0] * np.sin(np.pi * t) + 0.3 * t
        o2 = z[1] * t**2
        c1 = (zc[0] + 0.5 * zc[1]) * np.sin(np.pi * t)
        c2 = -zc[1] * t
        d = np.stack([o1, o2, c1, c2], axis=1)
        d[:, 2:] += noise * rng.standard_normal() * np.sin(np.pi * t)[:, None]  # whole-movement noise
        out.append(d)
    return out


@pytest.fixture(scope="module")
def coupled_model():
    return CouplingModel(OBS, phase_std=0.0, n_folds=5).fit(linear_demos(30, 0))


def test_known_linear_coupling_is_recovered(coupled_model):
    m = coupled_model
    assert not m.fallback_to_mean_ and m.method_ != "mean"
    test = linear_demos(20, 1)
    err, err0 = [], []
    for d in test:
        M = int(0.5 * T)
        p = m.predict(d[:M, OBS], (M - 1) / (T - 1), phase_std=0.0)
        truth = time_normalise(d, 50)
        err.append(np.mean((p.trajectory(50)[:, 2:] - truth[:, 2:]) ** 2))
        err0.append(np.mean((m.y_mean_[:, 2:] - truth[:, 2:]) ** 2))
    # the controlled agent is a linear function of what half the movement shows: far better than the mean
    assert np.mean(err) < 0.05 * np.mean(err0)


def test_no_information_falls_back_to_the_mean():
    demos = linear_demos(30, 2, coupled=False)
    m = CouplingModel(OBS, phase_std=0.0, n_folds=5).fit(demos)
    assert m.fallback_to_mean_ and m.method_ == "mean"
    assert "prior mean" in m.selection_["reason"]
    d = linear_demos(1, 3)[0]
    p = m.predict(d[:20, OBS], 0.5)
    np.testing.assert_allclose(p.trajectory(50), m.y_mean_, atol=1e-12)


@pytest.mark.slow  # coverage over many held-out draws
def test_calibration_on_gaussian_data_covers_about_90_percent():
    train = linear_demos(40, 4, noise=0.3)
    test = linear_demos(150, 5, noise=0.3)
    m = CouplingModel(OBS, phase_std=0.0, n_folds=8).fit(train)
    cov = []
    for d in test:
        for frac in (0.3, 0.6, 0.8):
            M = int(frac * T)
            p = m.predict(d[:M, OBS], (M - 1) / (T - 1), phase_std=0.0)
            e = np.abs(p.trajectory(50) - time_normalise(d, 50))[:, 2:]
            cov.append(np.mean(e <= 1.6448536 * p.std(50)[:, 2:]))
    assert 0.82 <= np.mean(cov) <= 0.97


def test_std_shrinks_as_more_is_observed(coupled_model):
    d = linear_demos(1, 6)[0]
    s = [coupled_model.predict(d[: int(f * T), OBS], (int(f * T) - 1) / (T - 1)).std(50)[:, 2:].mean()
         for f in (0.2, 0.5, 0.9)]
    assert s[0] >= s[1] >= s[2]
    # the residual variance is non-increasing in the phase by construction
    assert np.all(np.diff(coupled_model.residual_var_, axis=0) <= 0)


def test_std_computed_when_first_read_is_the_fitted_models():
    """The calibrated std is computed when first read, from the arrays of the fit that made the prediction: a refit
    of the same model in between does not change it (the numbers of a model fitted on the same data)."""
    d = linear_demos(1, 6)[0][: T // 2, OBS]
    m = CouplingModel(OBS, phase_std=0.0, n_folds=5).fit(linear_demos(12, 0))
    p = m.predict(d, 0.5)
    q = CouplingModel(OBS, phase_std=0.0, n_folds=5).fit(linear_demos(12, 0)).predict(d, 0.5)
    m.fit(linear_demos(12, 9, noise=0.3))
    assert not np.array_equal(m.residual_var_, CouplingModel(OBS, phase_std=0.0, n_folds=5).fit(
        linear_demos(12, 0)).residual_var_)
    np.testing.assert_array_equal(p.std_values, q.std_values)
    np.testing.assert_array_equal(p.mean, q.mean)


def test_phase_error_model_is_used_and_prediction_shapes():
    demos = linear_demos(12, 7)
    m = CouplingModel(OBS, phase_std="clock", n_folds=4, methods=("ridge",)).fit(demos)
    p = m.predict(demos[0][:15, OBS], 0.4)
    assert isinstance(p, GridPrediction)
    assert p.trajectory(30).shape == (30, 4) and p.std(30).shape == (30, 4) and np.all(p.std(30) > 0)
    t, y = p.response(30)  # the contract of interprim.models.base: (t, y) like the Interaction Primitive's
    assert t.shape == (30,) and t[0] == 0.0 and y.shape == (30, 2)
    np.testing.assert_allclose(y[-1], p.trajectory(30)[-1, m.controlled_dofs_])
    s, cm = p.completion(10)
    assert s[0] == pytest.approx(0.4) and cm.shape == (10, 2) and p.completion_std(10).shape == (10, 2)
    lo, hi = p.band(30)
    assert np.all(lo <= hi)
    # equal-length demos: the clock is exact, so its phase error model is zero
    assert m.clock_rel_std_ == pytest.approx(0.0)


def test_deterministic():
    demos = linear_demos(15, 8, noise=0.1)
    a = CouplingModel(OBS, n_folds=5).fit(demos)
    b = CouplingModel(OBS, n_folds=5).fit(demos)
    pa = a.predict(demos[3][:20, OBS], 0.5)
    pb = b.predict(demos[3][:20, OBS], 0.5)
    assert a.method_ == b.method_ and a.param_ == b.param_
    np.testing.assert_array_equal(pa.trajectory(50), pb.trajectory(50))
    np.testing.assert_array_equal(pa.std(50), pb.std(50))


@pytest.mark.parametrize("kwargs, match", [
    ({"observed_dofs": [0, 9]}, "observed_dofs"),
    ({"observed_dofs": [0, 1, 2, 3]}, "no controlled agent"),
    ({"observed_dofs": OBS, "methods": ("ridge", "gp")}, "unknown coupling"),
    ({"observed_dofs": OBS, "n_in": 1}, "n_in"),
    ({"observed_dofs": OBS, "coverage": 1.5}, "coverage"),
    ({"observed_dofs": OBS, "phase_std": -0.1}, "phase_std"),
    ({"observed_dofs": OBS, "fractions": (0.5, 0.2)}, "fractions"),
])
def test_bad_parameters_name_the_problem(kwargs, match):
    with pytest.raises(ValueError, match=match):
        CouplingModel(**kwargs).fit(linear_demos(6, 9))


def test_bad_inputs_name_the_problem():
    demos = linear_demos(6, 10)
    with pytest.raises(ValueError, match="at least 4"):
        CouplingModel(OBS).fit(demos[:3])
    with pytest.raises(ValueError, match=r"demos\[2\] has 3 columns"):
        CouplingModel(OBS).fit(demos[:2] + [demos[2][:, :3]] + demos[3:])
    bad = [d.copy() for d in demos]
    bad[1][5, 0] = np.nan
    with pytest.raises(ValueError, match=r"demos\[1\].*non-finite"):
        CouplingModel(OBS).fit(bad)
    with pytest.raises(NotFittedError, match="fit"):
        CouplingModel(OBS).predict(demos[0][:10, OBS], 0.3)
    m = CouplingModel(OBS, n_folds=3, methods=("ridge",)).fit(demos)
    with pytest.raises(ValueError, match="partial has 4 columns, expected 2"):
        m.predict(demos[0][:10], 0.3)
    with pytest.raises(ValueError, match="phase must be a number in"):
        m.predict(demos[0][:10, OBS], 1.5)
    with pytest.raises(ValueError, match="phase_std"):
        m.predict(demos[0][:10, OBS], 0.3, phase_std=-1.0)


def test_learned_interaction_std_adds_the_timing_uncertainty():
    """``LearnedInteraction``'s std = the coupling's std (+) |dy/du| u std(s)/s, the first-order effect of a
    relative phase error on a point placed in real time; without phase uncertainty it is the coupling's std.  Its
    prediction is the coupling's placed in time by the phase estimate (``CouplingModel.predict(timing=...)``)."""
    from interprim import LearnedInteraction
    from interprim.phase.estimate import PhaseEstimate
    from interprim.synthetic import two_agent_demos

    u = np.linspace(0.0, 1.0, 11)
    mean = np.stack([2.0 * u, np.sin(np.pi * u), np.ones_like(u)], axis=1)  # slopes 2, pi cos(pi u), 0

    def timed(est):  # a coupling's prediction placed in time by est, as CouplingModel.predict(timing=est) makes it
        return GridPrediction(u, mean, np.full_like(mean, 0.1), est.phase, est.std, [0], [1, 2], "ridge", 0.0,
                              duration=est.duration, timing=True)

    sd = np.full_like(mean, 0.1)
    p = timed(PhaseEstimate(0.5, 2.0, 1.0, 0.05, 1.0))
    got = p.std(11)
    e = 0.05 / 0.5
    slope = np.gradient(mean, u, axis=0)  # the mean's derivative on the grid (exact for the linear column)
    assert np.allclose(got, np.sqrt(0.01 + (slope * (u * e)[:, None]) ** 2), rtol=1e-12)
    assert np.allclose(got[:, 0], np.sqrt(0.01 + (2.0 * u * e) ** 2), rtol=1e-12)  # the linear column exactly
    assert np.allclose(got[:, 2], 0.1)  # a constant column gets no timing term
    assert np.all(got >= sd - 1e-15)
    assert np.allclose(p.std(11, timing=False), sd)
    still = timed(PhaseEstimate(0.5, 2.0, 1.0, 0.0, 1.0))  # a phase known exactly
    assert np.allclose(still.std(11), sd)

    demos = two_agent_demos(10, seed=2)
    m = LearnedInteraction([0, 1]).fit(demos, dt=0.01)
    x = demos[0][:40, :2]
    pred = m.predict(x)
    est = pred.phase_estimate
    alone = m.coupling_.predict(x, min(max(est.phase, 1e-3), 1.0), phase_std=est.std)
    np.testing.assert_array_equal(pred.mean, alone.mean)
    np.testing.assert_array_equal(pred.std(50, timing=False), alone.std(50, timing=False))
    assert (pred.phase, pred.duration, pred.speed) == (est.phase, est.duration, est.speed)


def test_training_rows_equal_one_resample_per_demonstration():
    """The training rows are built for all demonstrations at once (padded to a common length) and equal, bitwise,
    one ``_resample`` per demonstration of its own length; a refit on other demonstrations rebuilds them."""
    from interprim.models.coupling import _jitter_nodes, _resample

    rng = np.random.default_rng(3)
    demos = [np.cumsum(rng.normal(size=(int(L), 4)), axis=0) for L in rng.integers(12, 60, size=9)]
    m = CouplingModel(OBS, phase_std=0.05).fit(demos)

    def reference(model, idx, s_hat, sig):
        z = _jitter_nodes(int(model.n_jitter)) if sig > 0 else np.zeros(1)
        s_true = np.clip(s_hat + sig * z, 0.02, 1.0)
        X = [model._feat(_resample(model.obs_frames_[j], s_true * (model.obs_frames_[j].shape[0] - 1),
                                   int(model.n_in))) for j in idx]
        return np.concatenate(X), np.concatenate([np.full(s_true.size, j) for j in idx])

    for idx in (np.arange(9), np.array([0, 4, 8]), np.array([5])):
        for s_hat, sig in ((0.02, 0.0), (0.37, 0.05), (0.99, 0.2), (1.0, 0.0)):
            X, g = m._rows(idx, s_hat, sig)
            Xr, gr = reference(m, idx, s_hat, sig)
            np.testing.assert_array_equal(X, Xr)
            np.testing.assert_array_equal(g, gr)
    m.fit(demos[:5] + [d[::2] for d in demos[5:]])
    X, _ = m._rows(np.arange(9), 0.5, 0.05)
    np.testing.assert_array_equal(X, reference(m, np.arange(9), 0.5, 0.05)[0])

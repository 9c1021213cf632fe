"""DMP: basis (Eq. 2), forcing targets (Eq. 3), least squares (Eq. 4), integration (Eq. 1)."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from interprim.core.basis import Basis, canonical_phase
from interprim.core.dmp import LinearRollout, fit_weights, forcing_targets, forcing_values
from interprim.core.preprocessing import derivatives


def _demo(T=300):
    s = np.linspace(0, 1, T)
    return s, np.stack([np.sin(3 * s) + s**2, 0.5 * np.cos(2 * s), (10 * s**3 - 15 * s**4 + 6 * s**5)], 1)


def test_basis_rows_sum_to_phase():
    b = Basis(15, alpha_x=3.0)
    s = np.linspace(0, 1, 50)
    # normalised Gaussians times x: sum_i phi_i(x) = x  (Eq. 2)
    np.testing.assert_allclose(b.phi(s).sum(axis=1), canonical_phase(s, 3.0), rtol=1e-12)
    pt = b.phi_tilde(s, 25.0, 6.25)
    assert pt.shape == (50, 16) and np.all(pt[:, -1] == 25.0 * 6.25)


def test_fit_and_rollout_reproduces_demo():
    s, y = _demo()
    _, yd, ydd = derivatives(y, s[1])
    b = Basis(25, 3.0)
    theta, resid = fit_weights([y], [yd], [ydd], b, 25.0, 6.25)
    np.testing.assert_allclose(theta[0, :, -1], y[-1])  # g = y_T
    r = LinearRollout(b, 25.0, 6.25)
    yr = r.rollout(theta[0], y[0], yd[0], 0.0, s)
    assert np.max(np.abs(yr - y)) < 2e-3 * np.ptp(y)


def test_batched_fit_equals_per_demo_lstsq(rng):
    b = Basis(10, 3.0)
    demos = [rng.normal(size=(T, 2)).cumsum(0) for T in (40, 40, 55)]
    ders = [derivatives(d, 1 / (len(d) - 1)) for d in demos]
    theta, _ = fit_weights([d[0] for d in ders], [d[1] for d in ders], [d[2] for d in ders], b, 25.0, 6.25,
                           ridge=0.0)
    for j, (y, yd, ydd) in enumerate(ders):
        Phi = b.phi(np.linspace(0, 1, len(y)))
        F = forcing_targets(y, yd, ydd, y[-1], 25.0, 6.25)
        w = np.linalg.lstsq(Phi, F, rcond=None)[0]  # Eq. 4
        np.testing.assert_allclose(theta[j, :, :-1], w.T, rtol=1e-6, atol=1e-8 * np.abs(w).max())


def test_forcing_values_equal_phi_tilde_theta():
    """Eq. 12-15: f* of the movement equals [phi, alpha_y beta_y] [w; g] up to the fit residual."""
    s, y = _demo(400)
    y, yd, ydd = derivatives(y, s[1])
    b = Basis(30, 3.0)
    theta, resid = fit_weights([y], [yd], [ydd], b, 25.0, 6.25)
    fstar = forcing_values(y, yd, ydd, 25.0, 6.25)
    pred = b.phi_tilde(s, 25.0, 6.25) @ theta[0].T
    rms = np.sqrt(np.mean((fstar - pred) ** 2, axis=0))
    np.testing.assert_allclose(rms**2, resid[0], rtol=1e-6)


def test_linear_rollout_matches_ode_solver():
    """The precomputed linear map integrates Eq. 1 (checked against an adaptive ODE solver)."""
    b = Basis(8, 3.0)
    rng = np.random.default_rng(0)
    w, g = rng.normal(size=8) * 50, 0.7
    ay, by = 25.0, 6.25

    def rhs(s, z):
        f = b.phi(np.array([s]))[0] @ w
        return [z[1], ay * (by * (g - z[0]) - z[1]) + f]

    s_out = np.linspace(0.2, 1.0, 30)
    sol = solve_ivp(rhs, (0.2, 1.0), [0.1, -0.5], t_eval=s_out, rtol=1e-10, atol=1e-12)
    r = LinearRollout(b, ay, by, n_steps=4000)
    y = r.rollout(np.append(w, g)[None], np.array([0.1]), np.array([-0.5]), 0.2, s_out)[:, 0]
    np.testing.assert_allclose(y, sol.y[0], atol=2e-4)


def test_integrate_real_time_tau_and_goal():
    b = Basis(10, 3.0)
    r = LinearRollout(b, 25.0, 6.25)
    theta = np.zeros((1, 11))
    theta[0, -1] = 2.0  # goal only
    t1, y1 = r.integrate(theta, [0.0], tau=1.0, dt=0.01)
    t2, y2 = r.integrate(theta, [0.0], tau=2.0, dt=0.005)  # twice as fast: same path in half the time
    assert t1[-1] == pytest.approx(1.0) and t2[-1] == pytest.approx(0.5)
    np.testing.assert_allclose(y1, y2, atol=1e-9)
    assert y1[-1, 0] == pytest.approx(2.0, abs=0.01)  # converges to the goal
    # from mid-phase: start state respected
    t3, y3 = r.integrate(theta, [1.0], yd0=[0.0], tau=1.0, dt=0.01, x0=float(np.exp(-1.5)))
    assert y3[0, 0] == pytest.approx(1.0) and len(t3) == 51


def test_representation_report_and_warning_for_a_movement_the_dmps_cannot_hold():
    """A three-cycle wave with 10 basis functions: the DMPs lose most of what distinguishes the demonstrations
    (report > 0.5, warning with the numbers and what to do); with 40 they keep it; a smooth reach is fine."""
    import warnings

    import interprim as ip
    from interprim.synthetic import benchmark_tasks

    tasks = benchmark_tasks(12, seed=0, names=("reach", "wave"))
    kw = dict(sigma2=1e-3, covariance="ridge", phase_method="dtw", calibrate=False)
    wave = tasks["wave"]
    with pytest.warns(ip.RepresentationWarning, match=r"n_basis=10 cannot represent.*controlled agent: "
                                                      r"reconstruction \d\.\d\dx.*n_basis \(e\.g\. 20\)"):
        m = ip.InteractionPrimitive([0, 1], n_basis=10, **kw).fit(wave.demos, dt=wave.dt)
    assert m.representation_["controlled"]["reconstruction"] > 0.5
    with warnings.catch_warnings():
        warnings.simplefilter("error", ip.RepresentationWarning)
        m40 = ip.InteractionPrimitive([0, 1], n_basis=40, **kw).fit(wave.demos, dt=wave.dt)
        reach = ip.InteractionPrimitive([0, 1], n_basis=10, **kw).fit(tasks["reach"].demos, dt=0.02)
    assert m40.representation_["controlled"]["reconstruction"] < 0.25
    assert reach.representation_["observed"]["reconstruction"] < 0.1
    for r in reach.representation_.values():
        assert 0 <= r["mean_offset"] < r["reconstruction"] + 0.05 and r["spread"] > 0


def test_representation_report_is_zero_for_exact_dmp_movements():
    """Movements generated by the DMP itself are reconstructed exactly (up to the rollout's discretisation)."""
    from interprim.core.dmp import cached_rollout, representation_report

    rng = np.random.default_rng(0)
    ro = cached_rollout(8, 3.0, 25.0, 6.25, 2000)
    s = np.linspace(0.0, 1.0, 150)
    free, H = ro.design(0.0, s)
    theta = rng.normal(size=(5, 2, 9))
    starts = [(rng.normal(size=2), np.zeros(2)) for _ in range(5)]
    latent = [free @ np.stack(st) + H @ th.T for st, th in zip(starts, theta)]
    rep = representation_report(latent, starts, theta, ro)["all"]
    assert rep["reconstruction"] < 1e-3 and rep["spread"] > 0.1


def test_grid_design_is_the_design_on_the_uniform_grid_computed_once():
    """``grid_design(n)`` (cached per ``n``: every trajectory of a prediction asks for it) is, bit for bit,
    ``design(0, linspace(0, 1, n))``, and read-only so that no caller can change what the next one gets."""
    r = LinearRollout(Basis(8), 25.0, 6.25, n_steps=500)
    for n in (2, 37, 201):
        free, H = r.grid_design(n)
        want_free, want_H = r.design(0.0, np.linspace(0.0, 1.0, n))
        assert np.array_equal(free, want_free) and np.array_equal(H, want_H)
        assert r.grid_design(n)[1] is H
        assert not free.flags.writeable and not H.flags.writeable

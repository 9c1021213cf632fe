"""Every compiled kernel equals its numpy reference, in one process (interprim.core._compiled.registry).

Each test asks the registry for both implementations explicitly (``implementation(name, "compiled")`` /
``"numpy"``, or the ``forced`` path for the kernels whose reference is a whole numpy path) and compares them
on the same inputs, with tolerances set from the measured differences (``MEASURED``).

CI also runs this file with ``NUMBA_DISABLE_JIT=1`` (``scripts/test.sh``): numba's ``njit`` then returns the
Python function, so the "compiled" side is each kernel's body run as Python and the kernel bodies are covered.
"""

from __future__ import annotations

import importlib
import inspect
import os
import types

import numpy as np
import pytest

import interprim as ip
from interprim.core._compiled import registry
from interprim.core.gaussian import LowRankConditioner
from interprim.core.preprocessing import derivatives
from interprim.models.kernel import KernelDemonstrations
from interprim.phase import likelihood as PL
from interprim.phase.dtw import IncrementalDTW
from interprim.synthetic import two_agent_demos

JIT_DISABLED = os.environ.get("NUMBA_DISABLE_JIT", "0") not in ("", "0")

# Largest difference measured between the two implementations on this file's inputs (relative to the largest
# magnitude of the reference; 0 = bitwise), with the compiled kernels and with NUMBA_DISABLE_JIT=1 (the bodies as
# Python, no fastmath), and the tolerance asserted: about ten times the larger figure (summation order depends on
# the CPU's vector width under fastmath's reassociation, the references' LAPACK on the BLAS build), bitwise for
# the DTW kernels, which are written to perform the same operations in the same order.
#   name: (compiled, as Python, tolerance)
MEASURED = {
    "dtw.accumulate": (0.0, 0.0, 0.0),
    "dtw.open_end": (0.0, 0.0, 0.0),
    "dtw.backtrack": (0.0, 0.0, 0.0),
    "dtw.incremental_step": (0.0, 0.0, 0.0),
    "dtw.incremental_block": (0.0, 0.0, 0.0),
    "dtw.incremental_set": (0.0, 0.0, 0.0),
    "observation.forcing_values_into": (9.0e-15, 0.0, 1e-13),
    "observation.design_stats": (1.9e-16, 1.9e-16, 1e-14),
    "observation.position_stats": (3.7e-15, 4.8e-16, 1e-13),
    "observation.forcing_targets_batch": (1.4e-15, 0.0, 1e-13),
    "conditioning.lowrank_condition_mean": (2.6e-11, 3.1e-10, 3e-9),  # sigma2 = 1e-3: condition number ~1e6
    "rollout.response_positions": (2.3e-15, 8.6e-16, 1e-13),
    "phase_likelihood.phase_loglik_batch": (1.9e-13, 1.5e-13, 2e-12),
    # the noises 0.1-10x the model's (each row bit for bit phase_loglik_batch's at its noise, asserted there)
    "phase_likelihood.phase_loglik_noise_grid": (1.6e-12, 2.1e-12, 2e-11),
    # whole stream (phase + trajectory per frame); the phase ends with a parabolic step through the best three
    # scores, so a last-digit change in a score moves it by ~1e-8 at most (tests/compiled/test_fastpaths.py)
    "phase_likelihood.track_step": (3.2e-11, 3.8e-11, 1e-8),
    "resample.interp_columns": (0.0, 0.0, 0.0),  # numpy.interp's operations in its order, without fastmath
    "weighted.weighted_frames": (0.0, 0.0, 0.0),  # einsum's sums in their order, without fastmath
    "blend.place_members": (0.0, 0.0, 0.0),  # the reference's operations per point, einsum's sums in their order
    "blend.weights_on": (0.0, 0.0, 0.0),  # the reference's operations per point, numpy's sum in its order
    "blend.spread_std": (0.0, 0.0, 0.0),  # the reference's operations per point, einsum's sums in their order
    "prefix_rows.prefix_rows_into": (0.0, 0.0, 0.0),  # the reference's operations per element, without fastmath
    "prefix_rows.centre_rows_into": (0.0, 0.0, 0.0),  # numpy's reductions in their order (pairwise), no fastmath
    "prefix_rows.cv_loss_into": (0.0, 0.0, 0.0),  # the reference's operations per element, numpy's sums in order
}
TOL = {name: tol for name, (_, _, tol) in MEASURED.items()}


def rel(a, b) -> float:
    """Largest absolute difference relative to the largest magnitude of ``b`` (0 when both are 0)."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    assert a.shape == b.shape
    scale = float(np.abs(b).max()) if b.size else 0.0
    d = float(np.abs(a - b).max()) if b.size else 0.0
    return d / scale if scale > 0 else d


def on_both_paths(fn) -> dict:
    """``{"compiled": fn(), "numpy": fn()}``, each computed with the kernels' paths forced."""
    out = {}
    for which in ("compiled", "numpy"):
        with registry.forced(which):
            out[which] = fn()
    return out


def traj_std(p, n: int, grid: bool = False) -> tuple:
    """A prediction's ``(trajectory(n), std(n))`` (``grid``: its mean on its own grid instead of the trajectory)."""
    return p.mean if grid else p.trajectory(n), p.std(n)


def bitwise_gap(a, b) -> float:
    """0 when ``a`` and ``b`` are the same bits (signs of zeros included), else :func:`rel` (inf when that is 0)."""
    if np.array_equal(a, b) and np.array_equal(np.signbit(a), np.signbit(b)):
        return 0.0
    return rel(a, b) or np.inf


@pytest.fixture(scope="module")
def demos():
    return two_agent_demos(8, seed=0, frames=80), two_agent_demos(2, seed=5, frames=80)


@pytest.fixture(scope="module")
def models(demos):
    train, _ = demos
    common = dict(observed_dofs=[0, 1], n_basis=8, sigma2=1e-3)
    return {
        "position": ip.InteractionPrimitive(**common, phase_method="dtw").fit(train, dt=0.01),
        "smooth_pca": ip.InteractionPrimitive(**common, phase_method="dtw", smoothing_window=11,
                                              pca_components=(2, 2)).fit(train, dt=0.01),
        "forcing": ip.InteractionPrimitive(**common, observation="forcing", phase_method="dtw").fit(train, dt=0.01),
        "likelihood": ip.InteractionPrimitive(**common, phase_method="likelihood").fit(train, dt=0.01),
    }


def both(name):
    return registry.implementation(name, "compiled"), registry.implementation(name, "numpy")


# ----------------------------------------------------------------------------------------------- DTW (Eq. 5-8)

SHAPES = ((1, 1, 1), (7, 3, 2), (40, 13, 3), (33, 9, 10))


def check_dtw_accumulate():
    comp, ref = both("dtw.accumulate")
    rng = np.random.default_rng(5)
    worst = 0.0
    for N, M, D in SHAPES:
        u, v = rng.normal(size=(N, D)), rng.normal(size=(M, D))
        worst = max(worst, rel(comp(u, v), ref(u, v)))
    return worst


def check_dtw_open_end():
    comp, acc = both("dtw.open_end")
    rng = np.random.default_rng(6)
    worst = 0.0
    for N, M, D in SHAPES + ((25, 4, 2), (25, 5, 2), (25, 8, 2)):  # the 4-column sweeps and the remainder
        u, v = rng.normal(size=(N, D)), rng.normal(size=(M, D))
        n, c = comp(np.ascontiguousarray(u.T), v, np.empty(N), np.empty(N), np.empty((4, N)))
        last = acc(u, v)[-1]
        n_ref = int(np.argmin(last))  # the first minimum, as Eq. 8 is implemented
        assert int(n) == n_ref
        worst = max(worst, rel(c, last[n_ref]))
    return worst


def check_dtw_backtrack():
    comp, ref = both("dtw.backtrack")
    acc = registry.implementation("dtw.accumulate", "numpy")
    rng = np.random.default_rng(7)
    for N, M, D in SHAPES:
        Dm = acc(rng.normal(size=(N, D)), rng.normal(size=(M, D)))
        for n_end in {0, N // 2, N - 1}:
            np.testing.assert_array_equal(comp(Dm, n_end), ref(Dm, n_end))
    return 0.0


def check_dtw_incremental_block():
    """Blocks of query frames through the compiled loop against the numpy steps frame by frame, bit for bit: the last
    column and n* after every block (IncrementalDTW.extend on both paths), the first frame alone or inside a block; on
    the compiled path a NaN frame stops the block there and raises, the frames before it counted."""
    rng = np.random.default_rng(9)
    for N, M, D in SHAPES:
        u, v = rng.normal(size=(N, D)), rng.normal(size=(M, D))
        cuts = np.unique(np.concatenate([[0, M], rng.integers(1, max(M, 2), 4)]))
        for which in ("compiled", "numpy"):
            with registry.forced(which):
                inc = IncrementalDTW(u)
                out = []
                for a, b in zip(cuts[:-1], cuts[1:]):
                    n, c = inc.extend(np.ascontiguousarray(v[a:b]))
                    out.append((n, c, inc.column.copy(), inc.n_frames))
            if which == "compiled":
                got = out
        for (n1, c1, col1, k1), (n2, c2, col2, k2) in zip(got, out):
            assert (n1, k1) == (n2, k2) and c1 == c2 and np.array_equal(col1, col2)
        bad = rng.normal(size=(3, D))
        bad[2, 0] = np.nan
        with registry.forced("compiled"):  # (extend takes checked frames: the numpy steps do not look)
            inc = IncrementalDTW(u)
            with pytest.raises(ValueError, match="NaN or inf"):
                inc.extend(bad)
            assert inc.n_frames == 2  # the frames before the NaN entered
    comp = registry.compiled("dtw.incremental_block")
    u, v = rng.normal(size=(7, 2)), rng.normal(size=(4, 2))
    a, b, cost = np.empty(7), np.empty(7), np.empty(7)
    v[2, 1] = np.inf
    n, done, _ = comp(np.ascontiguousarray(u.T), v, a, b, cost, 0)
    assert (n, done) == (-1, 2)
    return 0.0


def check_dtw_incremental_set():
    """Several references of different lengths advanced together, in blocks, on the compiled path, on the numpy
    path and switching between them mid-query: after every block each reference's n* and D(n*, M) equal those of
    its own IncrementalDTW fed frame by frame, bit for bit; reset starts a new query."""
    from interprim.phase.dtw import IncrementalDTWSet

    rng = np.random.default_rng(10)
    for D in (1, 3):
        refs = [rng.normal(size=(N, D)) for N in (1, 9, 40, 23)]
        v = rng.normal(size=(30, D))
        cuts = [0, 1, 2, 9, 10, 25, 30]
        for paths in (["compiled"] * 6, ["numpy"] * 6, ["compiled", "numpy"] * 3):
            st = IncrementalDTWSet(refs)
            for _query in range(2):  # the second after reset()
                singles = [IncrementalDTW(r) for r in refs]
                for (a, b), which in zip(zip(cuts[:-1], cuts[1:]), paths):
                    with registry.forced(which):
                        n, c = st.extend(np.ascontiguousarray(v[a:b]))
                    with registry.forced("numpy"):
                        for f in v[a:b]:
                            for inc in singles:
                                inc.update(f)
                    assert np.array_equal(n, [inc.n_star for inc in singles])
                    assert np.array_equal(c, [inc.cost for inc in singles])
                    assert st.n_frames == b
                st.reset()
    return 0.0


def check_dtw_incremental_step():
    comp, step_np = both("dtw.incremental_step")
    rng = np.random.default_rng(8)
    worst = 0.0
    for N, M, D in SHAPES:
        u, v = rng.normal(size=(N, D)), rng.normal(size=(M, D))
        uT = np.ascontiguousarray(u.T)
        prev, col, cost = np.empty(N), np.empty(N), np.empty(N)
        inc = IncrementalDTW(u)  # the reference keeps its columns on the object
        for m in range(M):
            first = m == 0
            if not first:
                prev, col = col, prev
                inc._prev, inc._col = inc._col, inc._prev
            n = comp(uT, v[m], prev, col, cost, first)
            n_ref = step_np(inc, v[m], first)
            assert int(n) == int(n_ref)
            worst = max(worst, rel(col, inc._col))
        bad = v[0].copy()
        bad[-1] = np.nan
        keep = col.copy()
        assert comp(uT, bad, col, prev, cost, False) == -1  # a non-finite frame touches nothing
        np.testing.assert_array_equal(col, keep)
    return worst


# ----------------------------------------------------------------------------------- observation (Eq. 3, 13-15)

PREFIXES = ((3, 0.01), (4, 0.3), (40, 0.5), (70, 1.0))


def _prefix(demos, M):
    _, test = demos
    d = np.concatenate([test[0], test[1]])
    return np.ascontiguousarray(d[:M, :2])


def check_observation_forcing_values_into(models, demos):
    comp, obs = both("observation.forcing_values_into")
    m = models["forcing"]
    worst = 0.0
    for M, s_end in PREFIXES:
        z = _prefix(demos, M)
        YT = np.empty((2, M + 2))
        const = comp(z, M, s_end, float(m.alpha_y), float(m.beta_y_), np.empty((M + 1, 2)), np.empty((M + 1, 2)), YT)
        _, Y, _ = obs(m.fitted_, z, s_end)
        assert const == pytest.approx(m.alpha_y * m.beta_y_, rel=1e-15)
        worst = max(worst, rel(YT[:, :M].T, Y))
    return worst


def check_observation_design_stats(models, demos):
    comp, obs = both("observation.design_stats")
    m = models["forcing"]
    basis = m.basis_
    q = m.params_per_dof_
    worst = 0.0
    for M, s_end in PREFIXES:
        z = _prefix(demos, M)
        X, Y, _ = obs(m.fitted_, z, s_end)
        YT = np.ascontiguousarray(Y.T)
        G, B = np.empty((q, q)), np.empty((q, 2))
        yy = comp(YT, M, s_end, basis.centers, basis.widths, float(basis.alpha_x), float(m.alpha_y * m.beta_y_),
                  np.empty((q, M)), G, B, np.empty((4, M)), np.empty(M, dtype=np.int64))
        worst = max(worst, rel(G, X.T @ X), rel(B, X.T @ Y), rel(yy, np.sum(Y * Y)))
    return worst


def check_observation_position_stats(models, demos):
    comp, obs = both("observation.position_stats")
    worst = 0.0
    for key in ("position", "smooth_pca"):
        m = models[key]
        q, n_o = m.params_per_dof_, m.n_observed_latent_
        v0 = m.start_velocity_[:n_o]
        ro = m.rollout_
        for M, s_end in PREFIXES + ((65, 0.6), (130, 0.9)):  # one block of 64 frames, two, three
            z = np.ascontiguousarray(m.fitted_.observed_to_latent(_prefix(demos, M)) + 0.3)  # y0 matters
            X, Y, y0 = obs(m.fitted_, z, s_end)
            G, B = np.empty((q, q)), np.empty((q, n_o))
            yy = comp(z, M, s_end, y0, v0, ro.Z, ro.powers, G, B, np.empty((q, 64)), np.empty((n_o, 64)))
            worst = max(worst, rel(G, X.T @ X), rel(B, X.T @ Y), rel(yy, np.sum(Y * Y)))
    return worst


def check_observation_forcing_targets_batch():
    comp, ref = both("observation.forcing_targets_batch")
    rng = np.random.default_rng(2)
    worst = 0.0
    for n, T, D in ((1, 3, 1), (3, 50, 4)):
        Z = np.cumsum(rng.normal(size=(n, T, D)), axis=1)
        F, yd0 = np.empty_like(Z), np.empty((n, D))
        comp(Z, 1 / (T - 1), 25.0, 6.25, np.empty((T, D)), F, yd0)
        for k in range(n):
            y, yd, ydd = derivatives(Z[k], 1 / (T - 1))
            worst = max(worst, rel(F[k], ref(y, yd, ydd, y[-1], 25.0, 6.25)), rel(yd0[k], yd[0]))
    return worst


# ------------------------------------------------------------------------------------- Eq. 16-18 and the rollout

def check_conditioning_lowrank_condition_mean(models, demos):
    registry.implementation("conditioning.lowrank_condition_mean", "compiled")  # what mean_compiled runs
    obs = registry.reference("observation.position_stats")
    worst = 0.0
    for key in ("position", "smooth_pca", "forcing"):
        m = models[key]
        cond = LowRankConditioner.from_prior(m.prior_, m.obs_index_, m.thetas_, float(m.ridge))
        assert cond is not None
        for M, s_end in PREFIXES:
            X, Y, _ = obs(m.fitted_, np.ascontiguousarray(m.fitted_.observed_to_latent(_prefix(demos, M))), s_end)
            G, B, yy = X.T @ X, X.T @ Y, float(np.sum(Y * Y))
            for s2 in (1e-3, 0.7):
                (mc, llc), (mn, lln) = cond.mean_compiled(G, B, s2, yy, Y.size), cond.mean_numpy(G, B, s2, yy, Y.size)
                worst = max(worst, rel(mc, mn), rel(llc, lln))
    return worst


def check_rollout_response_positions(models, demos):
    worst = 0.0
    for key in ("position", "smooth_pca"):
        m = models[key]
        for M in (1, 30, 70):
            p = m.predict(_prefix(demos, M))
            for state in (None, np.array([0.1, -0.2, 0.3]), np.array([[0.1, -0.2, 0.3], [1.0, 0.5, -2.0]])):
                for n in (1, 2, 50):
                    with registry.forced("compiled"):
                        t1, y1 = p.response(n, state)
                    with registry.forced("numpy"):
                        t2, y2 = p.response(n, state)
                    worst = max(worst, rel(t1, t2), rel(y1, y2))
    return worst


# ------------------------------------------------------------------------------------------ resampling

def check_resample_interp_columns():
    """The kernel against numpy.interp per column (what the reference, interp_columns on numpy, computes), bit for
    bit: inside, outside and on the sample positions, NaN points, infinite values (numpy's fallbacks), read-only
    grids; and the reference under ``forced("numpy")`` against the one under ``forced("compiled")``."""
    rng = np.random.default_rng(7)
    comp = registry.compiled("resample.interp_columns")
    ref = registry.reference("resample.interp_columns")
    worst = 0.0
    for trial in range(300):
        n, D = int(rng.integers(2, 80)), int(rng.integers(1, 9))
        x = np.unique(rng.uniform(-1.0, 2.0, n)) if trial % 2 else np.linspace(0.0, 1.0, n)
        if x.size < 2:
            continue
        y = rng.normal(size=(x.size, D)) * 10.0 ** rng.integers(-5, 5)
        if trial % 7 == 0:
            y[rng.integers(x.size), 0] = np.inf
        x_new = rng.uniform(-1.5, 2.5, int(rng.integers(1, 150)))
        x_new[::3] = rng.choice(x, x_new[::3].size)
        if trial % 11 == 0:
            x_new[0] = np.nan
        if trial % 5 == 0:
            x.setflags(write=False)
        out = np.empty((x_new.size, D))
        assert comp(x_new, x, y, out)
        want = np.stack([np.interp(x_new, x, y[:, d]) for d in range(D)], axis=-1)
        with registry.forced("numpy"):
            got_numpy = ref(x_new, x, y)
        with registry.forced("compiled"):
            got_compiled = ref(x_new, x, y)
        for got in (out, got_numpy, got_compiled):
            if not (np.array_equal(got, want, equal_nan=True) and np.array_equal(np.signbit(got), np.signbit(want))):
                worst = max(worst, float(np.nanmax(np.abs(got - want))) or np.inf)
    assert not comp(np.zeros(2), np.array([0.0, 0.0, 1.0]), np.zeros((3, 2)), np.empty((2, 2)))  # numpy's case
    return worst


# ------------------------------------------------------------------------------------------ kernel-weighted demos

def check_weighted_weighted_frames():
    """The kernel against its reference (interpolated frames, then numpy's einsum), bit for bit: demonstrations of
    different lengths, on and between samples and at each one's last frame, every column or some, zero weights;
    and KernelDemonstrations' predictions (which use the kernel once the kernels are loaded) on both paths."""
    rng = np.random.default_rng(11)
    comp, ref = registry.compiled("weighted.weighted_frames"), registry.reference("weighted.weighted_frames")
    worst = 0.0
    for trial in range(200):
        nd, D, n = int(rng.integers(2, 25)), int(rng.integers(1, 12)), int(rng.integers(2, 120))
        L = rng.integers(3, 150, nd)
        padded = np.zeros((nd, int(L.max()) + 1, D))
        for j in range(nd):
            padded[j, :L[j]] = rng.normal(size=(L[j], D)) * 10.0 ** rng.integers(-3, 3)
        J = int(rng.integers(1, nd + 1))
        idx = rng.choice(nd, J, replace=False).astype(np.intp)
        f = rng.uniform(0.0, 1.0, (J, n)) * (L[idx] - 1)[:, None]
        f[:, ::4] = np.floor(f[:, ::4])  # on samples
        f[:, -1] = L[idx] - 1  # each one's last frame
        cols = (np.arange(D, dtype=np.intp) if trial % 2 else
                np.sort(rng.choice(D, max(1, D // 2), replace=False)).astype(np.intp))
        w = rng.random(J)
        w[0] = 0.0 if trial % 5 == 0 else w[0]
        w /= w.sum()
        got = [np.empty((n, cols.size)) for _ in range(4)]
        comp(padded, idx, f, cols, w, got[0], got[1])
        ref(padded, idx, f, cols, w, got[2], got[3])
        for a, b in ((got[0], got[2]), (got[1], got[3])):
            worst = max(worst, bitwise_gap(a, b))
    demos = two_agent_demos(6, seed=3, frames=60)
    m = KernelDemonstrations([0, 1], bandwidth=0.3).fit(demos, dt=0.01)
    for M in (5, 30, 59):
        out = on_both_paths(lambda: traj_std(m.predict(demos[0][:M, :2]), 50))  # noqa: B023 (called at once)
        worst = max(worst, *(rel(a, b) for a, b in zip(out["compiled"], out["numpy"])))
    return worst


# ------------------------------------------------------------------------------------------ a blend's members

def check_blend_place_members():
    """The kernel against its reference, bit for bit: one to five members at phases and durations anywhere (the
    blend's phase before, between or after theirs, zero), with and without a shared end (before, inside and beyond
    the real-time band), zero weights; and a fitted blend's combination of its members' streamed predictions (mean
    and std) on both paths."""
    rng = np.random.default_rng(12)
    comp, ref = registry.compiled("blend.place_members"), registry.reference("blend.place_members")
    worst = 0.0
    for trial in range(300):
        A, n, D = int(rng.integers(1, 6)), int(rng.integers(2, 202)), int(rng.integers(1, 15))
        u = np.linspace(0.0, 1.0, n)
        sv = rng.uniform(0.0, 1.1, A)
        dv = rng.uniform(0.2, 4.0, A)
        s = 0.0 if trial % 13 == 0 else float(rng.uniform(0.0, 1.0))
        ahead = np.maximum((u - s) * rng.uniform(0.5, 4.0), 0.0)
        h = 0.25
        R = np.nan if trial % 3 == 0 else float(rng.choice([0.1, 0.25, rng.uniform(0.0, 5.0)]))
        grids = rng.normal(size=(A, n, D)) * 10.0 ** rng.integers(-3, 3)
        W = rng.random((n, A))
        W[:, 0] = 0.0 if trial % 4 == 0 else W[:, 0]
        W /= np.maximum(W.sum(axis=1, keepdims=True), 1e-300)
        Y, mean = np.empty_like(grids), np.empty((n, D))
        assert comp(u, ahead, sv, dv, s, R, h, grids, W, Y, mean, np.empty(n))
        Y_ref, mean_ref = ref(u, ahead, sv, dv, s, R, h, grids, W)
        for a, b in ((Y, Y_ref), (mean, mean_ref)):
            worst = max(worst, bitwise_gap(a, b))
    demos = two_agent_demos(12, seed=5, frames=60)
    blend = ip.models.blend.Blend.from_fitted(
        [0, 1], {m: f.build(ip.models.registry.Settings((0, 1))).fit(demos, dt=0.01)
                 for m, f in ip.models.registry.FAMILIES.items() if m in ("ip", "learned", "nn")},
        {"ip": [0.5, 0.2], "learned": [0.3, 0.5], "nn": [0.2, 0.3]}, None, demos, 0.01, bands=[0.25, 1.0],
        remaining=0.5)
    st = blend.stream()
    for M, f in enumerate(demos[0][:59, :2], start=1):
        preds = {m: s.update(f) for m, s in st.streams.items()}  # the members once: their own kernels aside
        if M in (5, 30, 59):
            out = on_both_paths(lambda: traj_std(blend.combine(preds, M), 50, grid=True))  # noqa: B023
            for a, b in zip(out["compiled"], out["numpy"]):
                if not np.array_equal(a, b):
                    worst = max(worst, rel(a, b) or np.inf)
    return worst


def check_blend_weights_on():
    """The kernel against its reference, bit for bit: one to seven members (more: the kernel declines), one to six
    bands, weights with zeros (whole members and single bands), negative and NaN weights, the blend's phase before,
    inside and after the grid, zero durations; and the count of zero weights."""
    rng = np.random.default_rng(14)
    comp, ref = registry.compiled("blend.weights_on"), registry.reference("blend.weights_on")
    worst = 0.0
    for trial in range(400):
        M, B, n = int(rng.integers(1, 8)), int(rng.integers(2, 7)), int(rng.integers(2, 202))
        u = np.linspace(0.0, 1.0, n)
        s = float(rng.choice([0.0, 1.0, rng.uniform(-0.2, 1.2)]))
        D = 0.0 if trial % 17 == 0 else float(rng.uniform(0.1, 6.0))
        edges = np.cumsum(rng.uniform(0.05, 1.5, B))
        mids = 0.5 * (np.concatenate([[0.0], edges[:-1]]) + edges)
        table = rng.random((B, M)) * 10.0 ** rng.integers(-3, 3)
        if trial % 3 == 0:
            table[:, int(rng.integers(M))] = 0.0  # a member without weight
        if trial % 5 == 0:
            table[int(rng.integers(B))] = 0.0  # a band without weight: the sum's floor
        if trial % 7 == 0:
            table[int(rng.integers(B)), int(rng.integers(M))] = -0.3
        if trial % 23 == 0:
            table[int(rng.integers(B)), int(rng.integers(M))] = np.nan
        ahead, W = np.empty(n), np.empty((n, M))
        zeros = comp(u, s, D, mids, table, ahead, W)
        ahead_ref, W_ref, zeros_ref = ref(u, s, D, mids, table)
        if zeros != zeros_ref:
            worst = np.inf
        for a, b in ((ahead, ahead_ref), (W, W_ref)):
            if not (np.array_equal(a, b, equal_nan=True) and np.array_equal(np.signbit(a), np.signbit(b))):
                worst = max(worst, rel(np.nan_to_num(a), np.nan_to_num(b)) or np.inf)
    big = rng.random((3, 8))
    assert comp(np.linspace(0.0, 1.0, 5), 0.3, 1.0, np.array([0.1, 0.4, 0.9]), big, np.empty(5),
                np.empty((5, 8))) == -1  # eight members: numpy's pairwise sum, the reference's
    two = np.ascontiguousarray(big[:2, :2])
    assert comp(np.linspace(0.0, 1.0, 5), 0.3, 1.0, np.array([0.1, 0.1]), two, np.empty(5),
                np.empty((5, 2))) == -1  # middles not increasing
    return worst


def check_blend_spread_std():
    """The kernel against its reference, bit for bit: one to five members, weights with zeros, points where every
    member agrees (variance 0, and -0.0 from a negative scale), variance models with negative and NaN values and
    look-aheads before, inside and beyond their steps, with and without a variance model; and a fitted blend's std
    on both paths (its variance model read by the kernel)."""
    rng = np.random.default_rng(13)
    comp, ref = registry.compiled("blend.spread_std"), registry.reference("blend.spread_std")
    worst = 0.0
    for trial in range(300):
        A, n, D, H = int(rng.integers(1, 6)), int(rng.integers(2, 202)), int(rng.integers(1, 15)), \
            int(rng.integers(2, 40))
        Y = rng.normal(size=(A, n, D)) * 10.0 ** rng.integers(-3, 3)
        Y[:, : n // 5] = Y[0, : n // 5]  # every member agrees there: spread 0
        W = rng.random((n, A))
        W[:, 0] = 0.0 if trial % 4 == 0 else W[:, 0]
        W /= np.maximum(W.sum(axis=1, keepdims=True), 1e-300)
        mean = np.einsum("gm,mgd->gd", W, Y)
        ahead = np.maximum((np.linspace(0.0, 1.0, n) - rng.uniform(0.0, 1.0)) * rng.uniform(0.5, 4.0), 0.0)
        steps = np.cumsum(rng.uniform(0.01, 0.3, H))
        a = rng.normal(1.0, 0.5, (H, D))
        b = rng.normal(0.0, 1e-3, (H, D))
        if trial % 7 == 0:
            a[0], b[0] = -1.0, -0.0  # -0.0 variances where the members agree
        if trial % 11 == 0:
            b[H // 2, 0] = np.nan
        scaled = trial % 5 != 0
        std = np.empty((n, D))
        positive = comp(Y, mean, W, ahead, steps, a, b, scaled, std)
        std_ref, positive_ref = ref(Y, mean, W, ahead, steps, a, b, scaled)
        if positive != positive_ref:
            worst = np.inf
        if not (np.array_equal(std, std_ref, equal_nan=True) and np.array_equal(np.signbit(std),
                                                                                   np.signbit(std_ref))):
            worst = max(worst, rel(np.nan_to_num(std), np.nan_to_num(std_ref)) or np.inf)
    assert comp(Y, mean, W, ahead, np.array([0.0, 0.0]), a[:2], b[:2], True, std) == -1  # steps not increasing
    demos = two_agent_demos(12, seed=5, frames=60)
    members = {m: f.build(ip.models.registry.Settings((0, 1))).fit(demos, dt=0.01)
               for m, f in ip.models.registry.FAMILIES.items() if m in ("ip", "learned")}
    H, D = 6, demos[0].shape[1]
    scales = {"a": rng.uniform(0.5, 2.0, (H, D)), "b": rng.uniform(0.0, 1e-3, (H, D)),
              "t": np.linspace(0.05, 0.6, H)}
    blend = ip.models.blend.Blend.from_fitted([0, 1], members, {"ip": [0.6, 0.2], "learned": [0.4, 0.8]}, scales,
                                              demos, 0.01, bands=[0.25, 1.0])
    st = blend.stream()
    for M, f in enumerate(demos[0][:59, :2], start=1):
        preds = {m: s.update(f) for m, s in st.streams.items()}
        if M in (5, 30, 59):
            out = on_both_paths(lambda: blend.combine(preds, M).std(50))  # noqa: B023 (called at once)
            if not np.array_equal(out["compiled"], out["numpy"]):
                worst = max(worst, rel(out["compiled"], out["numpy"]) or np.inf)
    return worst


# ------------------------------------------------------------------------------------------ the likelihood phase

def check_phase_likelihood_phase_loglik_batch(models, demos):
    comp, ref = both("phase_likelihood.phase_loglik_batch")
    m = models["likelihood"]
    fs = PL.fast_state(m.fitted_)
    s2 = PL.phase_noise(m.fitted_)
    worst = 0.0
    for M in (2, 5, 40, 70):
        z = np.ascontiguousarray(m.fitted_.observed_to_latent(_prefix(demos, M)))
        Rg = fs.mean_path(z[0])
        s = np.linspace(0.05, 1.0, 7)
        a = comp(fs.Zh, Rg, z, M, s, fs.sq, fs.Uh, fs.K0, s2, np.empty(s.size))
        worst = max(worst, rel(a, ref(fs.Zh, Rg, z, s, fs.sq, fs.Uh, fs.K0, s2)))
    return worst


def check_phase_likelihood_phase_loglik_noise_grid(models, demos):
    """Every noise's row against the numpy reference, and against phase_loglik_batch at that noise (to rounding; bit
    for bit on the project's machine: the noise selection's numbers are those of one call per noise)."""
    comp, ref = both("phase_likelihood.phase_loglik_noise_grid")
    batch = registry.compiled("phase_likelihood.phase_loglik_batch")
    m = models["likelihood"]
    fs = PL.fast_state(m.fitted_)
    s2 = PL.phase_noise(m.fitted_) * np.array([1e-3, 0.1, 1.0, 10.0, 1e3])
    worst = 0.0
    for M in (2, 5, 40, 70):
        z = np.ascontiguousarray(m.fitted_.observed_to_latent(_prefix(demos, M)))
        Rg = fs.mean_path(z[0])
        s = np.linspace(0.05, 1.0, 7)
        a = comp(fs.Zh, Rg, z, M, s, fs.sq, fs.Uh, fs.K0, s2, np.empty((s2.size, s.size)))
        one = np.stack([batch(fs.Zh, Rg, z, M, s, fs.sq, fs.Uh, fs.K0, float(v), np.empty(s.size)) for v in s2])
        # bit for bit on this machine; a compiler may order the two kernels' sums differently elsewhere, and the
        # selection only needs them equal to rounding
        np.testing.assert_allclose(a, one, rtol=1e-13, atol=0,
                                   err_msg="phase_loglik_noise_grid differs from phase_loglik_batch noise by noise")
        # against numpy at the noises near the model's (at 1e-3 of it the problem's conditioning, not the kernel,
        # sets the difference, as for phase_loglik_batch)
        worst = max(worst, rel(a[1:4], ref(fs.Zh, Rg, z, s, fs.sq, fs.Uh, fs.K0, s2[1:4])))
    return worst


def check_phase_likelihood_track_step(models, demos):
    """The stream's lattice search, compiled (track_step) against numpy (the reference's scores of the same
    lattice), frame by frame: the phases and the predictions."""
    m = models["likelihood"]
    moving = _prefix(demos, 60)
    held = np.concatenate([np.repeat(moving[:1], 12, 0), moving[:30]])  # held still first: candidates below s_min
    out = {}
    for which in ("compiled", "numpy"):
        with registry.forced(which):
            st = m.stream()
            out[which] = [(p.phase, p.trajectory(20)) for p in (st.update(f) for f in moving)]
            st.reset()
            out[which] += [(p.phase, p.trajectory(20)) for p in (st.update(f) for f in held)]
    worst = 0.0
    for (pc, tc), (pn, tn) in zip(out["compiled"], out["numpy"]):
        worst = max(worst, abs(pc - pn), rel(tc, tn))
    return worst


# ------------------------------------------------------------------------------------------ the prefix coupling

def check_prefix_rows_prefix_rows_into():
    """The coupling's training rows, compiled against numpy, bit for bit: demonstrations of different lengths (one
    of a single frame), phases at the clip's ends and between, both feature kinds; and LearnedInteraction's
    predictions on both paths."""
    from interprim.models import registry as families
    from interprim.models.coupling import _jitter_nodes

    rng = np.random.default_rng(12)
    comp, ref = both("prefix_rows.prefix_rows_into")
    worst = 0.0
    for trial in range(100):
        n, Do, n_in = int(rng.integers(2, 20)), int(rng.integers(1, 8)), int(rng.integers(2, 16))
        L = rng.integers(1, 90, n).astype(np.intp)
        frames = np.zeros((n, int(L.max()), Do))
        for j in range(n):
            frames[j, :L[j]] = rng.normal(size=(L[j], Do)) * 10.0 ** rng.integers(-3, 3)
        idx = np.sort(rng.choice(n, int(rng.integers(1, n + 1)), replace=False)).astype(np.intp)
        s_true = np.minimum(np.maximum(rng.uniform(-0.2, 1.2) + 0.1 * _jitter_nodes(int(rng.integers(1, 6))), 0.02),
                            1.0)
        lin = np.linspace(0.0, 1.0, n_in)
        scale = rng.uniform(0.1, 3.0, Do)
        got = [np.full((idx.size * s_true.size, n_in * Do), np.nan) for _ in range(2)]
        comp(frames, L, idx, s_true, lin, scale, bool(trial % 2), got[0])
        ref(frames, L, idx, s_true, lin, scale, bool(trial % 2), got[1])
        if not (np.array_equal(got[0], got[1]) and np.array_equal(np.signbit(got[0]), np.signbit(got[1]))):
            worst = max(worst, rel(got[0], got[1]) or np.inf)
    demos = two_agent_demos(8, seed=4, frames=70)
    m = families.family("learned").build(families.Settings((0, 1))).fit(demos, dt=0.01)
    for M in (3, 30, 69):
        out = on_both_paths(lambda: traj_std(m.predict(demos[1][:M, :2]), 40))  # noqa: B023 (called at once)
        worst = max(worst, *(rel(a, b) for a, b in zip(out["compiled"], out["numpy"])))
    return worst


def check_prefix_rows_centre_rows_into():
    """The coupling's rows centred with their sums of squares, compiled against numpy, bit for bit (values and
    signs of zero): sizes below, inside and beyond numpy's pairwise blocks (8, 128 elements; rows of 1 to 300
    columns, up to 10^5 elements), columns of very different magnitudes and offsets, the norms skipped; and
    LearnedInteraction's predictions with each conditioning method on both paths."""
    from interprim.models import registry as families

    rng = np.random.default_rng(13)
    comp, ref = both("prefix_rows.centre_rows_into")
    worst = 0.0
    for trial in range(200):
        R, p, Q = int(rng.integers(1, 400)), int(rng.integers(1, 300)), int(rng.integers(1, 4))
        if trial < 3:
            R, p = ((150, 70), (1, 1), (500, 200))[trial]
        X = rng.normal(size=(R, p)) * 10.0 ** rng.integers(-4, 4, p) + rng.normal(size=p) * 100.0
        x = rng.normal(size=(Q, p))
        norms = trial % 5 != 0
        got = []
        for fn in (comp, ref):
            out = (np.full((R, p), np.nan), np.full((Q, p), np.nan), np.full(R if norms else 0, np.nan),
                   np.full(Q if norms else 0, np.nan))
            got.append(out + (np.array([fn(X, x, *out)]),))
        for a, b in zip(*got):
            worst = max(worst, bitwise_gap(a, b))
    demos = two_agent_demos(8, seed=4, frames=70)
    m = families.family("learned").build(families.Settings((0, 1))).fit(demos, dt=0.01)
    for method, param in (("ridge", 0.1), ("kernel", 0.5), ("ppca", 2), ("blend", (0.1, 0.5, 0.5)), ("mean", None)):
        m.coupling_.method_, m.coupling_.param_ = method, param  # each conditioner's use of the sums
        for M in (3, 30, 69):
            out = on_both_paths(lambda: traj_std(m.predict(demos[1][:M, :2]), 40))  # noqa: B023 (called at once)
            for a, b in zip(out["compiled"], out["numpy"]):
                if not np.array_equal(a, b):
                    worst = max(worst, rel(a, b) or np.inf)
    return worst


def check_prefix_rows_cv_loss_into():
    """The coupling's cross-validation losses of a batch of conditioners, compiled against numpy, bit for bit: one
    to thirty candidates, one to four held-out cases, one to nine jittered queries, 2 to 120 output points (sums of
    the jitter and output points below, inside and beyond numpy's pairwise blocks), 1 to 12 controlled columns
    anywhere among up to 20 (below and beyond 8), magnitudes far apart; and a CouplingModel's whole cross-validation
    (selection, scores, residual variance) on both paths."""
    from interprim.models.coupling import CouplingModel

    rng = np.random.default_rng(14)
    comp, ref = both("prefix_rows.cv_loss_into")
    worst = 0.0
    for _trial in range(200):
        C, nh, nj, n_out = (int(rng.integers(1, 31)), int(rng.integers(1, 5)), int(rng.integers(1, 10)),
                            int(rng.integers(2, 121)))
        D = int(rng.integers(2, 21))
        ctrl = np.sort(rng.choice(D, size=int(rng.integers(1, min(D, 12) + 1)), replace=False)).astype(np.intp)
        F = n_out * D
        scale = 10.0 ** rng.integers(-4, 4, F)
        GY = rng.normal(size=(C, nh * nj, F)) * scale
        ybar = rng.normal(size=F) * scale
        truth = ybar + rng.normal(size=(nh, F)) * scale
        w = 1.0 / rng.uniform(0.1, 10.0, ctrl.size) ** 2
        out_c = np.full((C, nh), np.nan)
        comp(GY, ybar, truth, ctrl, w, nj, D, float(nj * n_out), out_c)
        out_r = ref(GY, ybar, truth, ctrl, w, nj, D, float(nj * n_out), np.full((C, nh), np.nan))
        worst = max(worst, bitwise_gap(out_c, out_r))
    demos = two_agent_demos(10, seed=6, frames=60)
    fits = on_both_paths(lambda: CouplingModel([0], n_folds=5).fit(demos, dt=0.01))
    a, b = fits["compiled"], fits["numpy"]
    if repr(a.selection_) != repr(b.selection_) or not np.array_equal(a.residual_var_, b.residual_var_):
        worst = max(worst, rel(a.residual_var_, b.residual_var_) or np.inf)
    return worst


CHECKS = {
    "dtw.accumulate": check_dtw_accumulate,
    "dtw.open_end": check_dtw_open_end,
    "dtw.backtrack": check_dtw_backtrack,
    "dtw.incremental_step": check_dtw_incremental_step,
    "dtw.incremental_block": check_dtw_incremental_block,
    "dtw.incremental_set": check_dtw_incremental_set,
    "observation.forcing_values_into": check_observation_forcing_values_into,
    "observation.design_stats": check_observation_design_stats,
    "observation.position_stats": check_observation_position_stats,
    "observation.forcing_targets_batch": check_observation_forcing_targets_batch,
    "conditioning.lowrank_condition_mean": check_conditioning_lowrank_condition_mean,
    "rollout.response_positions": check_rollout_response_positions,
    "phase_likelihood.phase_loglik_batch": check_phase_likelihood_phase_loglik_batch,
    "phase_likelihood.phase_loglik_noise_grid": check_phase_likelihood_phase_loglik_noise_grid,
    "phase_likelihood.track_step": check_phase_likelihood_track_step,
    "resample.interp_columns": check_resample_interp_columns,
    "weighted.weighted_frames": check_weighted_weighted_frames,
    "blend.weights_on": check_blend_weights_on,
    "blend.place_members": check_blend_place_members,
    "blend.spread_std": check_blend_spread_std,
    "prefix_rows.prefix_rows_into": check_prefix_rows_prefix_rows_into,
    "prefix_rows.centre_rows_into": check_prefix_rows_centre_rows_into,
    "prefix_rows.cv_loss_into": check_prefix_rows_cv_loss_into,
}


def run_check(name, request):
    fn = CHECKS[name]
    kwargs = {arg: request.getfixturevalue(arg) for arg in inspect.signature(fn).parameters}
    return fn(**kwargs)


@pytest.mark.parametrize("name", registry.names())
def test_kernel_equals_numpy_reference(name, request):
    worst = run_check(name, request)
    print(f"measured {name}: {worst:.3g}")  # pytest -s shows the figures of MEASURED
    assert worst <= TOL[name], f"{name}: compiled and numpy differ by {worst:.3g} (tolerance {TOL[name]:.3g})"


def test_every_kernel_has_a_numpy_reference_and_an_equivalence_check():
    assert set(CHECKS) == set(registry.names()) == set(TOL)
    for name, spec in registry.KERNELS.items():
        ref = registry.reference(name)
        assert callable(ref), name
        mod = importlib.import_module(spec.reference.split(":")[0])
        src = inspect.getsource(mod)
        assert "import numba" not in src and "from numba" not in src, f"{name}: the reference must not need numba"
        comp = registry.compiled(name)
        if JIT_DISABLED:  # the kernel's body as Python: what this file then covers
            assert isinstance(comp, types.FunctionType), name
        else:
            assert hasattr(comp, "py_func"), name  # a numba dispatcher
        if spec.drop_in:
            assert inspect.signature(ref).parameters.keys() == inspect.signature(
                getattr(comp, "py_func", comp)).parameters.keys(), name


def test_the_registry_answers_by_name_and_path():
    with registry.forced("numpy"):
        assert registry.kernel("dtw.accumulate") is None and not registry.in_use()
        assert registry.implementation("dtw.accumulate") is registry.reference("dtw.accumulate")
    with registry.forced("compiled"):
        assert registry.kernel("dtw.accumulate") is registry.compiled("dtw.accumulate")
    with pytest.raises(KeyError, match="no compiled kernel named 'dtw.nope'"):
        registry.kernel("dtw.nope")
    with pytest.raises(ValueError, match="takes other arguments"):
        registry.implementation("dtw.incremental_step")
    with pytest.raises(ValueError, match="which must be"):
        registry.implementation("dtw.accumulate", "fast")

"""interprim benchmark suite: our hot paths against their peers, side by side in one process.

Run from the repository root::

    python -m benchmarks.run --quick     # CI: a few minutes
    python -m benchmarks.run             # full: more repeats and the full scaling sweep

Prints ONE table (operation, size, our median and p99, the peer on identical
input in the same run, the ratio peer/ours, and whether the results agree)
and writes ``benchmarks/RESULTS.md`` with that table, the scaling sweeps
(DoF 2-30, basis 10-50, demo length 100-2000) and the machine it ran on.

Fairness: BLAS is capped at one thread for everything (ours and peers) with
threadpoolctl -- on a 2-core machine OpenBLAS threads only add spinning and
jitter at these sizes -- and the compiled kernels are loaded before timing
(``interprim.core._compiled.loader.warmup``).  Peers: dtaidistance, dtw-python,
movement-primitives (``pip install -e .[bench]``); a peer that is missing is
reported as such, the rest still runs.
"""

from __future__ import annotations

import argparse
import gc
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
if str(ROOT / "src") not in sys.path:
    sys.path.insert(0, str(ROOT / "src"))

import interprim as ip  # noqa: E402
from benchmarks.data import make_demos  # noqa: E402
from interprim.core._compiled import loader  # noqa: E402
from interprim.core.gaussian import LowRankConditioner, condition, condition_literal  # noqa: E402
from interprim.phase.dtw import IncrementalDTW, open_end_dtw  # noqa: E402

ROWS: list[dict] = []


# ----------------------------------------------------------------------------- data
def fitted_model(Do=7, Dc=7, n_basis=25, S=30, T=500, seed=0, **kw):
    """The library's defaults (positions, sigma2 by CV) unless ``kw`` overrides them."""
    demos = make_demos(S, Do, Dc, T, seed=seed)
    m = ip.InteractionPrimitive(observed_dofs=list(range(Do)), n_basis=n_basis, **kw).fit(demos, dt=0.01)
    test = make_demos(1, Do, Dc, T, seed=seed + 1000, stretch=(1.0, 1.0))[0]
    return m, test


# ----------------------------------------------------------------------------- timing
def timed(fn, n=None, min_time=0.3, max_n=2000, warm=2, clock=time.perf_counter):
    """Per-call times (s) of ``fn()`` (wall clock unless ``clock=time.thread_time``); ``n`` calls or ``min_time`` s."""
    for _ in range(warm):
        fn()
    out = []
    t_end = time.perf_counter() + min_time
    while (n is not None and len(out) < n) or (n is None and (time.perf_counter() < t_end or len(out) < 5)):
        t0 = clock()
        fn()
        out.append(clock() - t0)
        if len(out) >= max_n:
            break
    return np.array(out)


def stats(ts):
    return float(np.median(ts)), float(np.percentile(ts, 99))


def fmt_t(t):
    if t is None or not np.isfinite(t):
        return "-"
    if t < 1e-3:
        return f"{t * 1e6:.1f} us"
    if t < 1:
        return f"{t * 1e3:.2f} ms"
    return f"{t:.2f} s"


def row(op, size, ours, peer_name=None, peer=None, agree=None, note=""):
    med, p99 = stats(ours)
    pmed = float(np.median(peer)) if peer is not None and len(peer) else None
    r = {"op": op, "size": size, "median": med, "p99": p99, "peer": peer_name or "-", "peer_median": pmed,
         "ratio": (pmed / med) if pmed else None, "agree": agree, "note": note}
    ROWS.append(r)
    ratio = f"{r['ratio']:.1f}x" if r["ratio"] else "-"
    print(f"  {op:<44} {fmt_t(med):>10} {fmt_t(p99):>10}  {r['peer']:<42} {fmt_t(pmed):>10} {ratio:>9}  {agree or '-'}",
          flush=True)
    return r


def rel(a, b):
    a = np.asarray(a, float)
    b = np.asarray(b, float)
    return float(np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300))


AGREE_TOL = 1e-7  # see the note under the table: exact formulations of Eq. 18 differ by ~1e-8 here


def agree_str(err, tol=AGREE_TOL):
    return f"{'yes' if err <= tol else 'NO'} ({err:.1e})"


# ----------------------------------------------------------------------------- reference (pre-optimisation) paths
def ref_online_step(model, z, n_star, cost):
    """The online step with the reference pieces: numpy statistics, dense structured Eq. 18, LinearRollout.design."""
    M = z.shape[0]
    s_end, duration = model.fitted_.phase_info(n_star, M)
    X, Y, y0 = model.fitted_.observation_design(z, s_end)
    G, B = X.T @ X, X.T @ Y
    post = condition(model.prior_.mean, model.prior_.cov, model.obs_index_, G, B, model.sigma2_,
                     yy=float(np.sum(Y * Y)), n_obs=Y.size, need_cov=False)
    pred = ip.Prediction(model.fitted_, post, (G, B, float(np.sum(Y * Y)), Y.size), s_end, duration, n_star, cost,
                         M, y0, model.fitted_.robot_start(None), z[-1])
    return pred._response_reference(100)


# ----------------------------------------------------------------------------- operations
def bench_online(quick, label="defaults: likelihood phase", **kw):
    print(f"online step ({label})")
    model, test = fitted_model(**kw)
    st = model.stream()
    n_runs = 1 if quick else 3
    walls, cpus = [], []
    for _ in range(n_runs + 1):
        st.reset()
        w, c = [], []
        for i in range(test.shape[0]):
            gc_was = gc.isenabled()
            t0 = time.perf_counter()
            c0 = time.thread_time()
            p = st.update(test[i, :7])
            p.response(100)
            c.append(time.thread_time() - c0)
            w.append(time.perf_counter() - t0)
            del gc_was
        walls.append(w)
        cpus.append(c)
    wall = np.concatenate(walls[1:])
    cpu = np.concatenate(cpus[1:])
    # reference on a subset of frames (it is slow), and agreement of the response at those frames
    ref_t, errs = [], []
    st.reset()
    N = model.reference_.shape[0]
    for i in range(test.shape[0]):
        p = st.update(test[i, :7])
        n, c = p.normalised_time * (N - 1), p.dtw_cost  # the stream's own phase (DTW or likelihood)
        if i >= 2 and (i % (50 if quick else 10) == 0 or i == test.shape[0] - 1):
            z = test[: i + 1, :7]
            t0 = time.perf_counter()
            _, yr = ref_online_step(model, z, n, c)
            ref_t.append(time.perf_counter() - t0)
            errs.append(rel(p.response(100)[1], yr))
    r = row(f"online step, {label}", "7+7 DoF, 25 basis, 500 frames, update + response(100)", wall,
            "reference path (dense Eq.18, numpy)", np.array(ref_t), agree_str(max(errs)),
            note=f"cpu-time median {fmt_t(np.median(cpu))}, p99 {fmt_t(np.percentile(cpu, 99))}; "
                 f"agreement = response(100) vs reference at {len(errs)} frames")
    r["cpu_median"], r["cpu_p99"] = float(np.median(cpu)), float(np.percentile(cpu, 99))
    r["per_frame_wall"] = wall[: test.shape[0]].tolist()
    return model, test


def bench_predict(model, test, quick, label="defaults: likelihood phase"):
    print(f"batch predict ({label})")
    partial = test[:250, :7]
    ours = timed(lambda: model.predict(partial), min_time=0.5 if quick else 2.0)
    ours_cpu = timed(lambda: model.predict(partial), min_time=0.5 if quick else 2.0, clock=time.thread_time)
    p = model.predict(partial)
    # literal Eq. 17-18 on the same input (same phase, same observation): Omega is (T D_o) x P
    s_end = p.normalised_time
    X, Y, _ = model.fitted_.observation_design(partial, s_end)
    D_o, q = model.obs_index_.shape
    Omega = np.zeros((X.shape[0] * D_o, model.prior_.mean.size))
    for i in range(D_o):
        Omega[i * X.shape[0]:(i + 1) * X.shape[0], model.obs_index_[i]] = X
    F = Y.T.reshape(-1)
    lit = condition_literal(model.prior_.mean, model.prior_.cov, Omega, F, model.sigma2_)
    t_lit = timed(lambda: condition_literal(model.prior_.mean, model.prior_.cov, Omega, F, model.sigma2_),
                  n=1 if quick else 3, warm=0)
    row(f"predict, {label}", "250 frames, 7+7 DoF", ours, "literal Eq.18, (T*D)^2 matrix A",
        t_lit, agree_str(rel(p.posterior_mean, lit.mean)),
        note=f"phase + Eq.18 mean + log-likelihood; cpu-time median {fmt_t(np.median(ours_cpu))}, "
             f"p99 {fmt_t(np.percentile(ours_cpu, 99))}")
    ours_cov = timed(lambda: model.predict(partial).posterior_cov, min_time=0.5 if quick else 2.0)
    e_cov = float(np.max(np.abs(p.posterior_cov - lit.cov)) / np.max(np.abs(model.prior_.cov)))
    ll_err = abs(p.log_likelihood - lit.log_likelihood) / abs(lit.log_likelihood)
    row(f"predict + posterior covariance, {label}", "250 frames, 7+7 DoF", ours_cov, "literal Eq.18, (T*D)^2 matrix A",
        t_lit, agree_str(e_cov), note=f"cov error relative to max|prior cov|; log-likelihood rel. diff {ll_err:.1e}")


def ref_likelihood_phase(model, z, s_init, n_grid=40):
    """The likelihood phase as before the batched kernel: one reference evaluation per grid candidate + refine."""
    from scipy.optimize import minimize_scalar

    from interprim.phase import likelihood as PL

    model = getattr(model, "fitted_", model)  # the phase reads the fitted state (an estimator's fitted_)
    M = z.shape[0]
    lo = max(PL.S_MIN, min(1.0, (M - 1) * model.dt_ / (4.0 * float(np.max(model.durations_)))))
    grid = np.unique(np.append(np.exp(np.linspace(np.log(lo), 0.0, n_grid)), np.clip(s_init, lo, 1.0)))
    s2 = PL.phase_noise(model)

    def score(s):
        return PL._phase_log_likelihood_reference(model, z, s, s2) + float(PL.log_speed_prior(model, M, s))

    curve = np.array([score(s) for s in grid])
    i = int(np.argmax(curve))
    a, b = float(grid[max(i - 1, 0)]), float(grid[min(i + 1, grid.size - 1)])
    res = minimize_scalar(lambda s: -score(s), bounds=(a, b), method="bounded",
                          options={"xatol": 1e-3 * max(b, 1e-3), "maxiter": 20})
    return float(res.x) if res.success and -res.fun > curve[i] else float(grid[i])


def bench_likelihood_phase(quick):
    """``phase_method="likelihood"``: batch predict and the online step (batched phase kernel)."""

    print("likelihood phase")
    model, test = fitted_model(phase_method="likelihood")
    loader.warmup()
    partial = test[:250, :7]
    ours = timed(lambda: model.predict(partial), min_time=0.5 if quick else 2.0)
    N1 = model.reference_.shape[0] - 1
    s_ours = model.predict(partial).normalised_time
    s_dtw = open_end_dtw(model.reference_, model.fitted_.observed_to_latent(partial), return_path=False).n_star / N1
    t_ref = timed(lambda: ref_likelihood_phase(model, partial, s_dtw), n=1 if quick else 3, warm=0)
    s_ref = ref_likelihood_phase(model, partial, s_dtw)
    row("predict, phase_method='likelihood'", "250 frames, 7+7 DoF", ours, "per-candidate reference phase only",
        t_ref, f"phase diff {abs(s_ours - s_ref):.1e}")


def bench_dtw(quick):
    print("open-end DTW")
    rng = np.random.default_rng(0)
    N, M, D = 500, 250, 10
    u = np.cumsum(rng.normal(size=(N, D)), 0)
    v = u[:M] + 0.3 * rng.normal(size=(M, D))
    ours = timed(lambda: open_end_dtw(u, v, return_path=False), min_time=0.5 if quick else 2.0)
    n_ours = open_end_dtw(u, v, return_path=False).n_star
    try:
        from dtaidistance import dtw_ndim

        def dtai():
            _, P = dtw_ndim.warping_paths_fast(u, v, psi=(0, N, 0, 0), psi_neg=False)
            return int(np.argmin(P[1:, -1]))

        t = timed(dtai, min_time=0.5 if quick else 2.0)
        row("open-end DTW, n* (batch)", f"N={N}, M={M}, D={D}", ours, "dtaidistance C warping_paths_fast+argmin",
            t, "yes (same n*)" if dtai() == n_ours else f"NO ({dtai()} vs {n_ours})")
        t = timed(lambda: dtw_ndim.distance_fast(u, v, psi=(0, N, 0, 0)), min_time=0.5 if quick else 2.0)
        c_ours = open_end_dtw(u, v, return_path=False).cost
        d = dtw_ndim.distance_fast(u, v, psi=(0, N, 0, 0))
        row("open-end DTW, cost only (batch)", f"N={N}, M={M}, D={D}", ours, "dtaidistance C distance_fast psi",
            t, agree_str(abs(d**2 - c_ours) / c_ours, 1e-10))
    except ImportError:
        row("open-end DTW, n* (batch)", f"N={N}, M={M}, D={D}", ours, "dtaidistance (not installed)")
    try:
        import dtw as dtwpy
        from dtw import StepPattern, symmetric1

        sp = StepPattern(symmetric1.mx, hint="N")

        def dp():
            return int(dtwpy.dtw(v, u, step_pattern=sp, open_end=True, distance_only=True,
                                 dist_method="sqeuclidean").jmin)

        t = timed(dp, min_time=0.5 if quick else 2.0, max_n=50)
        row("open-end DTW, n* (batch)", f"N={N}, M={M}, D={D}", ours, "dtw-python open_end, symmetric1",
            t, "yes (same n*)" if dp() == n_ours else f"NO ({dp()} vs {n_ours})")
    except ImportError:
        row("open-end DTW, n* (batch)", f"N={N}, M={M}, D={D}", ours, "dtw-python (not installed)")
    # incremental: one new column per frame
    inc = IncrementalDTW(u[:, :7])
    w = []
    for _ in range(1 if quick else 3):
        inc.reset()
        for m in range(N):
            t0 = time.perf_counter()
            inc.update(v[m % M, :7] if m < M else u[m, :7])
            w.append(time.perf_counter() - t0)
    vv = np.concatenate([v[:, :7], u[M:, :7]])
    ok = inc.n_star == open_end_dtw(u[:, :7], vv, return_path=False).n_star
    peer = None
    try:
        from dtaidistance import dtw_ndim

        vq = np.ascontiguousarray(v[:, :7])
        uq = np.ascontiguousarray(u[:, :7])
        peer = timed(lambda: dtw_ndim.distance_fast(uq, vq, psi=(0, N, 0, 0)), min_time=0.3)
    except ImportError:
        pass
    row("incremental DTW, one frame", f"N={N}, D=7", np.array(w), "dtaidistance recompute at M=250", peer,
        "yes (= batch n*)" if ok else "NO")


def bench_fit(quick):
    print("fit")
    S, D, T = 100, 14, 500
    demos = make_demos(S, 7, 7, T, seed=3, stretch=(1.0, 1.0))
    # the DMP fit itself (Eq. 3-4, Eq. 10): sigma2 from the fit residual, DTW phase: no cross-validation
    model = ip.InteractionPrimitive(observed_dofs=list(range(7)), n_basis=25, observation="forcing", sigma2="residual",
                                    phase_method="dtw")
    mpos = ip.InteractionPrimitive(observed_dofs=list(range(7)), n_basis=25, sigma2="residual", phase_method="dtw")
    t_pos = timed(lambda: mpos.fit(demos, dt=0.01), n=3 if quick else 10)
    row("fit, observation='position' (sigma2 from the fit residual)", f"{S} demos x {D} DoF x {T}", t_pos, None,
        note="as the paper configuration plus one rollout per demonstration for the position residual")
    ours = timed(lambda: model.fit(demos, dt=0.01), n=5 if quick else 15)
    d30 = demos[:30]
    mcv = ip.InteractionPrimitive(observed_dofs=list(range(7)), n_basis=25)  # library default: sigma2="cv"
    t_cv = timed(lambda: mcv.fit(d30, dt=0.01), n=1 if quick else 3, warm=0)
    row("fit, library defaults (5-fold CV)", f"30 demos x {D} DoF x {T}", t_cv, None,
        note="sigma2, shrinkage, cross-agent damping and the phase noise chosen by cross-validation; once per model")
    try:
        from movement_primitives.dmp import DMP
        from movement_primitives.dmp._dmp import determine_forces, ridge_regression  # noqa: F401
        from movement_primitives.dmp._forcing_term import ForcingTerm
    except ImportError as exc:
        print(f"  movement-primitives unavailable ({exc}); pip install -e '.[bench]'", file=sys.stderr)
        row("fit (DMP weights + prior + reference)", f"{S} demos x {D} DoF x {T}", ours, "movement-primitives n/a")
        return
    Tt = np.arange(T) * 0.01

    def imitate_all():
        out = []
        for d in demos:
            dmp = DMP(n_dims=D, execution_time=Tt[-1], dt=0.01, n_weights_per_dim=25)
            dmp.imitate(Tt, d)
            out.append(dmp.forcing_term.weights_.copy())
        return out

    peer = timed(imitate_all, n=2 if quick else 5, warm=1)
    # agreement on the least-squares step (Eq. 4) with identical basis and identical forcing targets:
    # movement-primitives' basis is ours with alpha_x = -ln(0.01), overlap 1/sqrt(2 ln(1/0.8)); its forcing
    # targets (np.gradient with edge_order=1 and zeroed final velocity/acceleration, real time) are given to
    # our solver (interprim.core.dmp.fit_weights_targets, no ridge) -> weights compared to DMP.imitate's.
    from interprim.core.basis import Basis
    from interprim.core.dmp import fit_weights_targets

    W_theirs = np.stack(imitate_all())  # (S, D, m)
    ft = ForcingTerm(D, 25, Tt[-1], 0.0, 0.8, -np.log(0.01))
    basis = Basis(25, alpha_x=float(-np.log(0.01)), overlap=float(1.0 / np.sqrt(2.0 * np.log(1.0 / 0.8))))
    assert np.allclose(basis.centers, ft.centers, rtol=1e-12) and np.allclose(basis.widths, ft.widths, rtol=1e-9)
    Fs = []
    for d in demos:
        F, *_ = determine_forces(Tt, d, np.full(D, 25.0), np.full(D, 6.25), -np.log(0.01), False, False)
        Fs.append(F)
    Fs = np.stack(Fs)
    t_ls = timed(lambda: fit_weights_targets(Fs, Fs[:, -1, :], basis, ridge=0.0), n=10 if quick else 30)
    th, _ = fit_weights_targets(Fs, Fs[:, -1, :], basis, ridge=0.0)
    err = rel(th[:, :, :25], W_theirs)
    row("fit, paper configuration (DMP weights + prior + DTW reference)", f"{S} demos x {D} DoF x {T}", ours,
        "movement-primitives DMP.imitate x100", peer, "see next row")
    row("DMP least squares only (Eq. 4)", f"{S} demos x {D} DoF x {T}", t_ls, "movement-primitives DMP.imitate x100",
        peer, agree_str(err), note="same basis, same forcing targets")


def bench_promp(model, test, quick):
    print("conditioning vs ProMP")
    try:
        from movement_primitives.promp import ProMP
    except ImportError:
        return
    M = 50 if quick else 250
    partial = test[:M, :7]
    s_end = 0.5
    X, Y, _ = model.fitted_.observation_design(partial, s_end)
    cond = LowRankConditioner.from_prior(model.prior_, model.obs_index_)
    s2 = model.sigma2_

    def ours_fn():
        G_, B_ = X.T @ X, X.T @ Y
        mean, ll = cond.mean_compiled(G_, B_, s2, 0.0, None)
        return mean, cond.cov(G_, s2)

    ours = timed(ours_fn, min_time=0.5 if quick else 2.0)
    mean, cov = ours_fn()
    # equivalent ProMP: n_dims = D_o, per dim 2q weights [theta_o,i, theta_c,i]; the activation of frame t is
    # [X_t, 0]; weights permuted from our layout; y_cov = sigma2 I; one condition_position per frame.
    D_o, q = model.obs_index_.shape
    P = model.prior_.mean.size
    perm = np.concatenate([np.concatenate([np.arange(i * q, (i + 1) * q), P // 2 + np.arange(i * q, (i + 1) * q)])
                           for i in range(D_o)])
    rows_tbl = np.hstack([X, np.zeros_like(X)])
    orig = ProMP._rbfs_1d_point
    try:
        ProMP._rbfs_1d_point = lambda self, t, t_max=1.0, overlap=0.7: rows_tbl[int(t)]

        def promp_fn():
            pm = ProMP(D_o, 2 * q)
            pm.from_weight_distribution(model.prior_.mean[perm], model.prior_.cov[np.ix_(perm, perm)])
            for t in range(M):
                pm = pm.condition_position(Y[t], y_cov=s2 * np.eye(D_o), t=t, t_max=1.0)
            return pm

        peer = timed(promp_fn, n=1, warm=0)
        pm = promp_fn()
    finally:
        ProMP._rbfs_1d_point = orig
    inv = np.argsort(perm)
    cs = np.max(np.abs(model.prior_.cov))
    e_mean = rel(pm.weight_mean[inv], mean)
    e_cov = float(np.max(np.abs(pm.weight_cov[np.ix_(inv, inv)] - cov)) / cs)
    # both against the literal Eq. 18 on the same input, to show where the last digits go
    Omega = np.zeros((M * D_o, P))
    for i in range(D_o):
        Omega[i * M:(i + 1) * M, model.obs_index_[i]] = X
    lit = condition_literal(model.prior_.mean, model.prior_.cov, Omega, Y.T.reshape(-1), s2)
    e_ol = max(rel(mean, lit.mean), float(np.max(np.abs(cov - lit.cov)) / cs))
    e_pl = max(rel(pm.weight_mean[inv], lit.mean),
               float(np.max(np.abs(pm.weight_cov[np.ix_(inv, inv)] - lit.cov)) / cs))
    row("conditioning, mean + covariance", f"{M} frames x 7 obs DoF, P=364", ours,
        "movement-primitives ProMP.condition_position/frame", peer, agree_str(max(e_mean, e_cov)),
        note=f"cov error relative to max|prior cov|; vs literal Eq.18: ours {e_ol:.1e}, ProMP {e_pl:.1e}")


def bench_cold_start(quick, tmp):
    print("cold start")
    model, test = fitted_model()
    path = Path(tmp) / "model.npz"
    model.save(path)
    np.save(Path(tmp) / "partial.npy", test[:250, :7])
    code = ("import time; t0 = time.perf_counter(); import numpy as np; import interprim as ip; "
            f"m = ip.InteractionPrimitive.load(r'{path}'); p = m.predict(np.load(r'{Path(tmp) / 'partial.npy'}')); "
            "p.response(100); print(time.perf_counter() - t0, flush=True); "
            "from interprim.core._compiled import loader; loader.warmup()")  # a background compilation ends in the run
    env = dict(os.environ)
    env.pop("INTERPRIM_JIT", None)
    res = {}
    for label, extra in (("numba cache warm", {}), ("no numba cache (fresh clone)", None)):
        walls = []
        for _ in range(2 if quick else 4):
            e = dict(env)
            if extra is None:
                e["NUMBA_CACHE_DIR"] = tempfile.mkdtemp(dir=tmp)
            out = subprocess.run([sys.executable, "-c", code], env=e, check=True, capture_output=True, text=True,
                                 cwd=str(ROOT))
            walls.append(float(out.stdout.split()[0]))  # import to response, as timed inside the process
        res[label] = walls
        row(f"cold start: import + load + predict ({label})", "fresh process, 250 frames", np.array(walls))
    return res


def bench_memory(tmp):
    print("memory")
    model, test = fitted_model()
    path = Path(tmp) / "m.npz"
    model.save(path)
    size = path.stat().st_size
    st = model.stream()
    for i in range(50):
        st.update(test[i, :7]).response(100)
    per_frame = {}
    tracemalloc.start()
    for i in range(50, 500):
        before = tracemalloc.get_traced_memory()[0]
        tracemalloc.reset_peak()
        p = st.update(test[i, :7])
        p.response(100)
        peak = tracemalloc.get_traced_memory()[1] - before
        if i in (100, 250, 499):
            per_frame[i + 1] = peak
        del p
    tracemalloc.stop()
    txt = ", ".join(f"M={k}: {v / 1024:.1f} KiB" for k, v in per_frame.items())
    ROWS.append({"op": "model file (reference size)", "size": "30 demos, P=364", "median": None, "p99": None,
                 "peer": "-", "peer_median": None, "ratio": None, "agree": None,
                 "note": f"{size / 1e6:.2f} MB on disk"})
    ROWS.append({"op": "online step: peak allocation per frame", "size": "tracemalloc", "median": None,
                 "p99": None, "peer": "-", "peer_median": None, "ratio": None, "agree": None, "note": txt})
    print(f"  model file {size / 1e6:.2f} MB; per-frame peak allocation {txt}")
    return size, per_frame


# ----------------------------------------------------------------------------- scaling
CPU = time.thread_time  # scaling sweeps: cpu time of this thread (BLAS is single-threaded), robust to other jobs


def online_median(model, test, frames=None):
    st = model.stream()
    w = []
    T = test.shape[0] if frames is None else frames
    for i in range(T):
        t0 = CPU()
        st.update(test[i, :len(model.observed_dofs_)]).response(100)
        w.append(CPU() - t0)
    w = np.array(w)
    return float(np.median(w)), float(np.median(w[-max(T // 10, 1):]))


def scaling(quick):
    print("scaling")
    out = {"dof": [], "basis": [], "length": []}
    dofs = [2, 8, 14, 30] if quick else [2, 4, 8, 14, 20, 30]
    for D in dofs:
        Do = max(D // 2, 1)
        m, test = fitted_model(Do, D - Do, 25, 30, 500, sigma2="residual")
        med, last = online_median(m, test)
        tp = float(np.median(timed(lambda: m.predict(test[:250, :Do]), min_time=0.3, clock=CPU)))
        demos = make_demos(100, Do, D - Do, 500, seed=3, stretch=(1, 1))
        mm = ip.InteractionPrimitive(observed_dofs=list(range(Do)), n_basis=25, sigma2="residual", phase_method="dtw")
        tf = float(np.median(timed(lambda: mm.fit(demos, dt=0.01), n=3, clock=CPU)))
        out["dof"].append((D, med, last, tp, tf))
        print(f"  D={D}: online median {fmt_t(med)} (last 10% {fmt_t(last)}), predict {fmt_t(tp)}, fit {fmt_t(tf)}")
    for nb in ([10, 25, 50] if quick else [10, 20, 25, 35, 50]):
        m, test = fitted_model(7, 7, nb, 30, 500, sigma2="residual")
        med, last = online_median(m, test)
        tp = float(np.median(timed(lambda: m.predict(test[:250, :7]), min_time=0.3, clock=CPU)))
        out["basis"].append((nb, med, last, tp))
        print(f"  basis={nb}: online median {fmt_t(med)} (last 10% {fmt_t(last)}), predict {fmt_t(tp)}")
    for T in ([100, 500, 2000] if quick else [100, 250, 500, 1000, 2000]):
        m, test = fitted_model(7, 7, 25, 30, T, sigma2="residual")
        med, last = online_median(m, test)
        tp = float(np.median(timed(lambda: m.predict(test[: T // 2, :7]), min_time=0.3, clock=CPU)))
        out["length"].append((T, med, last, tp))
        print(f"  length={T}: online median {fmt_t(med)} (last 10% {fmt_t(last)}), predict(T/2) {fmt_t(tp)}")
    return out


# ----------------------------------------------------------------------------- report
def machine_info():
    cpu = platform.processor() or ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    vers = {}
    for mod in ("numpy", "scipy", "numba", "dtaidistance", "dtw", "movement_primitives"):
        try:
            vers[mod] = __import__(mod).__version__
        except Exception:  # noqa: BLE001
            vers[mod] = "n/a"
    return {"cpu": cpu, "cores": os.cpu_count(), "python": platform.python_version(), "platform": platform.platform(),
            "versions": vers, "load_average": os.getloadavg() if hasattr(os, "getloadavg") else None}


def table_md(rows, all_sections=False):
    """Markdown table of ``rows`` (without the rows of a section of their own unless ``all_sections``)."""
    rows = [r for r in rows if all_sections or "section" not in r]
    lines = ["| operation | size | ours median | ours p99 | peer | peer median | peer / ours | agree | note |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        ratio = f"{r['ratio']:.1f}x" if r.get("ratio") else "-"
        lines.append(f"| {r['op']} | {r['size']} | {fmt_t(r['median'])} | {fmt_t(r['p99'])} | {r['peer']} | "
                     f"{fmt_t(r['peer_median'])} | {ratio} | {r['agree'] or '-'} | {r.get('note', '')} |")
    return "\n".join(lines)


def write_results(path, info, scal, quick, load_end, elapsed):
    md = [f"# interprim benchmark results ({'quick' if quick else 'full'} run)", "",
          f"Command: `python -m benchmarks.run{' --quick' if quick else ''}` (repository root), "
          f"{elapsed:.0f} s.  Times are wall-clock per call; p99 over all calls of the run.  "
          "BLAS capped at one thread for ours and the peers alike.", "",
          "## Machine", "",
          f"- CPU: {info['cpu']} ({info['cores']} logical cores), Python {info['python']}, {info['platform']}",
          f"- load average at start {tuple(round(x, 2) for x in info['load_average'] or ())}, at end "
          f"{tuple(round(x, 2) for x in load_end or ())} (other jobs share this machine; wall-clock p99 "
          "includes their preemptions -- the cpu-time columns do not)",
          "- versions: " + ", ".join(f"{k} {v}" for k, v in info["versions"].items()), "",
          "## Operations (reference size: observed 7 DoF + controlled 7 DoF, 25 basis functions, theta of 364, "
          "30 demonstrations of 500 frames)", "", table_md(ROWS), "",
          f"*agree*: largest relative difference of the outputs (n* must be identical); 'yes' below {AGREE_TOL:g}.  "
          "Three exact formulations of Eq. 18 (ours, the dense structured reference, the literal one with the "
          "(T D)^2 matrix A) differ pairwise by 2e-9 to 1e-8 on these problems: the posterior precision is "
          "ill-conditioned (prior variances of the forcing weights ~1e4, sigma^2 ~1e-3, near-null directions of "
          "X^T X early in the movement), so ~1e-8 is the floor of double precision here, not an approximation.", ""]
    from benchmarks.threads_cold import section_md
    md += section_md(ROWS, table_md)
    for online in (r for r in ROWS if r["op"].startswith("online step, ") and "cpu_median" in r):
        md += [f"{online['op']}: cpu time (this thread only, excludes waiting for the CPU) median "
               f"{fmt_t(online['cpu_median'])}, p99 {fmt_t(online['cpu_p99'])}.", ""]
    md += ["## Scaling", "",
           "Cpu time of the calling thread (so other jobs on the machine do not blur the growth; BLAS is "
           "single-threaded).  Online step = `stream.update(frame)` + `response(100)`; median over a whole "
           "interaction (frames 1..T) and over its last 10 % of frames (M close to T).", "",
           "Models of the scaling sweeps: library defaults (positions, likelihood phase) with sigma2='residual' "
           "(the CV does not change the per-frame cost).", "",
           "### With the number of DoF (half observed, half controlled; 25 basis, 500 frames, 30 demos; "
           "fit on 100 demos)", "",
           "| DoF | online median | online, last 10 % | predict (250 frames) | fit (100 demos) |",
           "|---|---|---|---|---|"]
    md += [f"| {D} | {fmt_t(a)} | {fmt_t(b)} | {fmt_t(c)} | {fmt_t(d)} |" for D, a, b, c, d in scal["dof"]]
    md += ["", "### With the number of basis functions (7 + 7 DoF, 500 frames)", "",
           "| basis | online median | online, last 10 % | predict (250 frames) |", "|---|---|---|---|"]
    md += [f"| {nb} | {fmt_t(a)} | {fmt_t(b)} | {fmt_t(c)} |" for nb, a, b, c in scal["basis"]]
    md += ["", "### With the demonstration length (7 + 7 DoF, 25 basis; the stream runs over the whole length)", "",
           "| frames T | online median | online, last 10 % | predict (T/2 frames) |", "|---|---|---|---|"]
    md += [f"| {T} | {fmt_t(a)} | {fmt_t(b)} | {fmt_t(c)} |" for T, a, b, c in scal["length"]]
    md += ["", "## How cost grows", "",
           "- **Phase** per online frame: the likelihood phase (default) scores 3 candidate speeds 1 % apart on "
           "a fixed log-lattice (more when the best one is at an edge of them); a lattice point seen at the "
           "previous frame keeps its statistics and dense factors "
           "and adds the new frame by rank-1 updates, O(D_o (q^2 + q r) + r^3) per candidate, independent of M "
           "(a point entering the window, or clipped at s = 1, is scored from scratch: O(M q (q + D_o)) for the "
           "statistics in 64-frame blocks plus O(D_o (q^3 + q^2 r + q r^2))); then the batch search's last step "
           "(a parabola through the best lattice points, then one through 3 points 0.2 % apart: about 3 "
           "evaluations from scratch per frame) so that the stream's phase is predict's; the paper's DTW phase is "
           "one DTW column O(N D_o).  Batch predict with the likelihood phase: ~35 candidates (12-point grid, "
           "3 more inside each interval next to its best three points, Brent on the two highest peaks, the last "
           "parabolas), each O(M q (q + D_o)) + O(D_o (q^3 + q^2 r + q r^2)): at the "
           "reference size ~40 us of dense factorisation + 0.08 us per observed frame per candidate.",
           "- **Online step**, per frame with M frames seen, N reference frames, D_o observed DoF, q = n_basis + 1, "
           "r <= number of demonstrations (rank of the prior's low-rank part), P parameters: DTW column O(N D_o); "
           "observation statistics O(M q (q + D_o)) -- every earlier frame moves to a new phase when n* changes, so "
           "X^T X and X^T F are recomputed (compiled, SIMD exponentials, no allocation); conditioning "
           "O(D_o (q^3 + q^2 r + q r^2) + P r), independent of M; response O(n q D_c). Only the statistics grow "
           "with M (linearly); nothing allocated per frame grows with M (tracemalloc row above).",
           "- **predict** = batch DTW O(N M D_o) + the same statistics and conditioning; the posterior covariance "
           "is computed lazily, O(P^2 r).",
           "- **fit** O(S T D (q + 1)) for the least squares plus O(S P (S + P)) for the prior (S demonstrations).",
           "- **Open-end DTW** O(N M D); four query columns per sweep break the min-plus dependency chain.", ""]
    md += _sections_of_other_commands(path)
    Path(path).write_text("\n".join(md))


def _sections_of_other_commands(path) -> list:
    """The sections of the existing file that another benchmark command wrote (a ``## `` title naming its
    ``python -m benchmarks.<name>`` command, e.g. the ROS 2 bridge's latency): kept, not lost to this run."""
    try:
        old = Path(path).read_text().split("\n")
    except OSError:
        return []
    out, keep = [], False
    for line in old:
        if line.startswith("## "):
            keep = "`python -m benchmarks." in line and "benchmarks.run" not in line
        if keep:
            out.append(line)
    return ([""] + out) if out else []


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="fewer repeats and sizes (CI, < 3 min)")
    ap.add_argument("--out", default=str(HERE / "RESULTS.md"))
    ap.add_argument("--no-scaling", action="store_true", help="skip the scaling sweeps")
    ap.add_argument("--json", default=None, help="also write the rows as JSON to this file")
    args = ap.parse_args(argv)
    try:
        import scipy.linalg  # noqa: F401 - its own OpenBLAS loaded first, so that the limit reaches it too
        from threadpoolctl import threadpool_limits

        threadpool_limits(1)
    except ImportError:  # still fair (same BLAS for all), only noisier
        print("threadpoolctl not installed: BLAS thread count left at its default", file=sys.stderr)
    t_start = time.perf_counter()
    info = machine_info()
    loader.warmup()
    print(f"{'operation':<46} {'median':>10} {'p99':>10}  {'peer':<42} {'peer med':>10} {'ratio':>9}  agree")
    with tempfile.TemporaryDirectory() as tmp:
        model, test = bench_online(args.quick)
        bench_predict(model, test, args.quick)
        m_dtw, _ = bench_online(args.quick, label="phase_method='dtw' (paper)", phase_method="dtw")
        bench_predict(m_dtw, test, args.quick, label="phase_method='dtw' (paper)")
        bench_likelihood_phase(args.quick)
        from benchmarks.learned import bench_learned
        bench_learned(args.quick, fitted_model, make_demos, timed, row)
        from benchmarks.auto import bench_auto
        bench_auto(args.quick, make_demos, timed, row)
        bench_dtw(args.quick)
        bench_fit(args.quick)
        bench_promp(model, test, args.quick)
        bench_cold_start(args.quick, tmp)
        from benchmarks.threads_cold import bench_first_run, bench_threads
        bench_first_run(args.quick, tmp, row, rel, ROOT)
        bench_threads(args.quick, fitted_model, make_demos, row, rel)
        bench_memory(tmp)
        from benchmarks.csv_columns import bench_csv_columns
        bench_csv_columns(args.quick, tmp, timed, row)
    scal = {"dof": [], "basis": [], "length": []} if args.no_scaling else scaling(args.quick)
    elapsed = time.perf_counter() - t_start
    load_end = os.getloadavg() if hasattr(os, "getloadavg") else None
    write_results(args.out, info, scal, args.quick, load_end, elapsed)
    print("\n" + table_md(ROWS, True))
    print(f"\nwrote {args.out} ({elapsed:.0f} s)")
    if args.json:
        Path(args.json).write_text(json.dumps({"rows": [{k: v for k, v in r.items() if k != "per_frame_wall"}
                                                        for r in ROWS], "machine": info}, indent=1, default=str))


if __name__ == "__main__":
    main()

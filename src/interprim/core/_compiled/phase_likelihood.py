"""Compiled kernels of the likelihood phase estimator (numba, cached on disk).

:func:`phase_loglik_batch` evaluates the marginal log-likelihood of the
observed positions (``interprim.phase.likelihood.phase_log_likelihood``) at
several candidate phases in one call.  Reference:
``interprim.phase.likelihood._phase_log_likelihood_reference`` (the
per-candidate design matrix and :func:`interprim.core.gaussian.lowrank_case`);
plain numpy equivalent: ``interprim.phase.likelihood._loglik_batch_numpy``
(``tests/phase/test_phase_likelihood.py`` checks all three agree).

Per candidate ``s`` the ``M`` observed frames sit at ``s_m = s m / (M - 1)``.
The position design of every observed DoF is the same ``H(s)`` (``M x q``,
rows interpolated linearly on the rollout grid), so the observation enters
only through ``G = H^T H`` (``q x q``), ``b_i = H^T r_i`` and ``|r|^2``, with
the residual ``r = z - (free(s) [z0; v0] + H(s) mu)`` taken from a
precomputed grid of the prior-mean path (no cancellation in ``|r|^2``).  The
prior of the observed block is ``diag(d) + W^T W`` (rank ``n`` = number of
demonstrations); with ``S_i = diag(sqrt(d_i))``, ``Uh_i = S_i^{-1} W_i^T`` and
``T_i = sigma^2 I + S_i G S_i`` (as in :class:`interprim.core.gaussian.LowRankConditioner`)::

    log det Cov = sum_i (log det T_i + (M - q) log sigma^2) + log det K,
    K = I + sum_i Uh_i^T (I - sigma^2 T_i^{-1}) Uh_i                  (n x n)
    r^T Cov^{-1} r = (|r|^2 - sum_i c_i^T T_i^{-1} c_i) / sigma^2 - t^T K^{-1} t,
    c_i = S_i b_i,  t = sum_i Uh_i^T T_i^{-1} c_i.

Both ``T_i^{-1}`` terms come from one forward substitution of ``[Uh_i | c_i]``
(``q x (n + 1)``) per DoF, ``V_i``; the ``(n + 1)^2`` products ``sum_i V_i^T V_i`` of all DoFs are then formed
at once as dot products of length ``D_o q`` (the ``V_i`` stored transposed side by side), and ``K`` with
``t`` is factorised as one bordered matrix (``log det K`` and ``t^T K^{-1} t`` from one Cholesky).  Sizes are
padded to multiples of 4 (zero columns, identity rows) so that every inner loop is a regular register block.
Cost per candidate ``O(M q (q + D_o))`` for the
statistics plus ``O(D_o (q^3 + q^2 n + q n^2) + n^3)``, no ``M``-sized
factorisation; no BLAS call (so no thread pool to limit).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from numba import njit

from . import FASTMATH as _FM
from . import LOG2PI as _LOG2PI
from .linalg import chol_inplace, chol_update_R, forward_rows, solve_R

BLOCK = 64  # frames per block of the statistics: fixed-size workspaces, whatever the number of frames


@njit(cache=True, fastmath=_FM)
def _chol_aug(A, p4, Wd):
    """Upper Cholesky factor R (rows) of A[:p4, :p4] (full symmetric storage; p4 a multiple of 4) with the
    columns p4..Wd replaced by R^{-T} A[:, p4:Wd]; right-looking, 4-pivot panels.  Returns log det or nan.
    Entries below the diagonal are left as finite garbage."""
    logdet = 0.0
    for p in range(0, p4, 4):
        for k in range(4):
            Rk = A[p + k]
            piv = Rk[p + k]
            if not piv > 0.0:
                return np.nan
            logdet += np.log(piv)
            inv = 1.0 / np.sqrt(piv)
            for j in range(p, Wd):
                Rk[j] *= inv
            for kk in range(k + 1, 4):
                Rkk = A[p + kk]
                lc = Rk[p + kk]
                for j in range(p, Wd):
                    Rkk[j] -= lc * Rk[j]
        R0, R1, R2, R3 = A[p], A[p + 1], A[p + 2], A[p + 3]
        for a in range(p + 4, p4, 2):
            T0, T1 = A[a], A[a + 1]
            l00, l01, l02, l03 = R0[a], R1[a], R2[a], R3[a]
            l10, l11, l12, l13 = R0[a + 1], R1[a + 1], R2[a + 1], R3[a + 1]
            js = a - (a % 4)
            for j in range(js, Wd):
                r0, r1, r2, r3 = R0[j], R1[j], R2[j], R3[j]
                T0[j] -= l00 * r0 + l01 * r1 + l02 * r2 + l03 * r3
                T1[j] -= l10 * r0 + l11 * r1 + l12 * r2 + l13 * r3
    return logdet

@njit(cache=True, fastmath=_FM)
def _syrk_T(VT, L, K):
    """K[c1, c2] = dot(VT[c1, :L], VT[c2, :L]) for c2 < c1 rounded up to 4 (rows of VT: a multiple of 4)."""
    r = VT.shape[0]
    for c1 in range(0, r, 4):
        A0, A1, A2, A3 = VT[c1], VT[c1 + 1], VT[c1 + 2], VT[c1 + 3]
        for c2 in range(0, c1 + 4, 2):
            B0, B1 = VT[c2], VT[c2 + 1]
            s00 = s01 = s10 = s11 = s20 = s21 = s30 = s31 = 0.0
            for m in range(L):
                b0, b1 = B0[m], B1[m]
                a0, a1, a2, a3 = A0[m], A1[m], A2[m], A3[m]
                s00 += a0 * b0
                s01 += a0 * b1
                s10 += a1 * b0
                s11 += a1 * b1
                s20 += a2 * b0
                s21 += a2 * b1
                s30 += a3 * b0
                s31 += a3 * b1
            K[c1, c2] = s00
            K[c1, c2 + 1] = s01
            K[c1 + 1, c2] = s10
            K[c1 + 1, c2 + 1] = s11
            K[c1 + 2, c2] = s20
            K[c1 + 2, c2 + 1] = s21
            K[c1 + 3, c2] = s30
            K[c1 + 3, c2 + 1] = s31

@njit(cache=True, fastmath=_FM)
def _gram_block(ET, nb, q4, P, G):
    """G[j, lc] += dot(ET[j, :nb], ET[lc, :nb]) for j < q4 (blocks of 4 rows), lc from the block start to P (pairs)."""
    for j in range(0, q4, 4):
        A0, A1, A2, A3 = ET[j], ET[j + 1], ET[j + 2], ET[j + 3]
        for lc in range(j, P, 2):
            B0, B1 = ET[lc], ET[lc + 1]
            s00 = s01 = s10 = s11 = s20 = s21 = s30 = s31 = 0.0
            for m in range(nb):
                b0, b1 = B0[m], B1[m]
                a0, a1, a2, a3 = A0[m], A1[m], A2[m], A3[m]
                s00 += a0 * b0
                s01 += a0 * b1
                s10 += a1 * b0
                s11 += a1 * b1
                s20 += a2 * b0
                s21 += a2 * b1
                s30 += a3 * b0
                s31 += a3 * b1
            G[j, lc] += s00
            G[j, lc + 1] += s01
            G[j + 1, lc] += s10
            G[j + 1, lc + 1] += s11
            G[j + 2, lc] += s20
            G[j + 2, lc + 1] += s21
            G[j + 3, lc] += s30
            G[j + 3, lc + 1] += s31

@njit(cache=True, fastmath=_FM, inline="always")
def _grid_cell(u, n_steps):
    """``(k, a)``: the cell ``[k, k + 1]`` of the rollout grid ``0 .. n_steps`` holding position ``u`` (clipped to the
    grid) and ``u``'s fraction ``a`` in it: the one linear interpolation of the tabulated rollout."""
    if u < 0.0:
        u = 0.0
    elif u > n_steps:
        u = float(n_steps)
    kf = int(np.floor(u))
    if kf > n_steps - 1:
        kf = n_steps - 1
    return kf, u - kf


@njit(cache=True, fastmath=_FM)
def _stats(Zh, Rg, z, M, s, q4, ET, G):
    """Statistics of the first ``M`` frames of ``z`` at phase ``s``; returns ``|r|^2``.

    The frames are taken in blocks of ``ET.shape[1]``: rows ``0..q-1`` of ``ET`` hold the rows of ``H``
    (rows ``q..q4-1`` stay zero), rows ``q4..q4+D_o-1`` the residuals.  ``G`` (``q4 x P``) receives the upper
    part of ``[H r]^T [H r]`` restricted to its first ``q4`` rows: ``G[:q, :q]`` (upper) ``= H^T H`` and
    ``G[:q, q4 + i] = H^T r_i``.  Memory does not grow with ``M``.
    """
    K1, q = Zh.shape
    n_steps = K1 - 1
    n_o = Rg.shape[1]
    W = ET.shape[1]
    P = ET.shape[0]
    step = s / (M - 1) if M > 1 else 0.0
    rr = 0.0
    for j in range(q4):
        for lc in range(P):
            G[j, lc] = 0.0
    for m0 in range(0, M, W):
        nb = min(W, M - m0)
        for k in range(nb):
            m = m0 + k
            sm = m * step
            if M > 1 and m == M - 1:
                sm = s
            kf, a = _grid_cell(sm * n_steps, n_steps)
            wa = 1.0 - a
            Z0 = Zh[kf]
            Z1 = Zh[kf + 1]
            for j in range(q):
                ET[j, k] = wa * Z0[j] + a * Z1[j]
            R0 = Rg[kf]
            R1 = Rg[kf + 1]
            zm = z[m]
            for i in range(n_o):
                rv = zm[i] - (wa * R0[i] + a * R1[i])
                ET[q4 + i, k] = rv
                rr += rv * rv
        _gram_block(ET, nb, q4, P, G)
    return rr

@njit(cache=True, fastmath=_FM, inline="always")
def _loglik_at(G, rr, M, sq, Uh, K0, s2, log_s2, T, Ub, V, VT, Kacc, F):
    """The marginal log-likelihood at one phase from its statistics ``G``, ``rr`` (:func:`_stats`) at the noise
    ``s2`` (``log_s2`` its log): the per-phase part shared by :func:`phase_loglik_batch` and
    :func:`phase_loglik_noise_grid` (``-inf`` where a factorisation failed; the rest are workspaces)."""
    q = T.shape[0]
    n_o = sq.shape[0]
    n = Uh.shape[2]
    r4 = Ub.shape[1]
    n4 = F.shape[0]
    ld_T = 0.0
    for i in range(n_o):
        si = sq[i]
        Ui = Uh[i]
        for a in range(q):
            sa = si[a]
            Ta = T[a]
            for c in range(a + 1):
                Ta[c] = sa * G[c, a] * si[c]
            Ta[a] += s2
        ld = chol_inplace(T, q)
        if not np.isfinite(ld):
            return -np.inf
        ld_T += ld
        for a in range(q):
            Ua = Ui[a]
            Uba = Ub[a]
            for c in range(n):
                Uba[c] = Ua[c]
            Uba[n] = si[a] * G[a, G.shape[0] + i]
        forward_rows(T, Ub, V)
        off = i * q
        for a in range(q):
            Va = V[a]
            for c in range(r4):
                VT[c, off + a] = Va[c]
    _syrk_T(VT, n_o * q, Kacc)
    for a in range(n):
        Fa = F[a]
        K0a = K0[a]
        for c in range(a + 1):
            Fa[c] = K0a[c] - s2 * Kacc[a, c]
        for c in range(a + 1, n):
            Fa[c] = K0a[c] - s2 * Kacc[c, a]
        for c in range(n, n4 + 4):
            Fa[c] = 0.0
        Fa[n4] = Kacc[n, a]
    for a in range(n, n4):
        Fa = F[a]
        for c in range(n4 + 4):
            Fa[c] = 0.0
        Fa[a] = 1.0
    cTc = Kacc[n, n]
    ld_K = _chol_aug(F, n4, n4 + 4)
    if not np.isfinite(ld_K):
        return -np.inf
    tKt = 0.0
    for a in range(n4):
        tKt += F[a, n4] * F[a, n4]
    N = M * n_o
    logdet = n_o * (M - q) * log_s2 + ld_T + ld_K
    quad = (rr - cTc) / s2 - tKt
    return -0.5 * (N * _LOG2PI + logdet + quad)


@njit(cache=True, fastmath=_FM)
def phase_loglik_batch(Zh, Rg, z, M, s_values, sq, Uh, K0, s2, out):
    """Marginal log-likelihood of ``z[:M]`` (positions of the observed DoFs) at every phase in ``s_values``.

    Parameters
    ----------
    Zh : (K + 1, q) position response of ``theta`` on the rollout grid (``H`` rows before interpolation).
    Rg : (K + 1, D_o) prior-mean path on the same grid (``free [z0; v0] + H mu``).
    z : (>= M, D_o) observed latent frames.
    s_values : (C,) candidate phases of the last frame.
    sq : (D_o, q) ``sqrt(d)``; Uh : (D_o, q, n) ``S^{-1} W^T``; K0 : (n, n) ``I + sum_i Uh_i^T Uh_i``.
    s2 : position noise variance.
    out : (C,) log-likelihoods (output); ``-inf`` where a factorisation failed.

    Workspaces (``O(BLOCK (q + D_o))`` for the statistics, ``O(D_o q n + n^2)`` otherwise) are allocated once
    per call, independent of ``M``.
    """
    q = Zh.shape[1]
    n_o = Rg.shape[1]
    n = Uh.shape[2]
    q4 = (q + 3) // 4 * 4
    r = n + 1
    r4 = (r + 3) // 4 * 4
    n4 = (n + 3) // 4 * 4
    P = q4 + (n_o + 1) // 2 * 2
    ET = np.zeros((P, BLOCK))
    G = np.zeros((q4, P))
    T = np.zeros((q, q))
    Ub = np.zeros((q, r4))
    V = np.zeros((q, r4))
    VT = np.zeros((r4, n_o * q))
    Kacc = np.zeros((r4, r4))
    F = np.zeros((n4, n4 + 4))
    log_s2 = np.log(s2)
    for ci in range(s_values.shape[0]):
        rr = _stats(Zh, Rg, z, M, s_values[ci], q4, ET, G)
        out[ci] = _loglik_at(G, rr, M, sq, Uh, K0, s2, log_s2, T, Ub, V, VT, Kacc, F)
    return out


@njit(cache=True, fastmath=_FM)
def phase_loglik_noise_grid(Zh, Rg, z, M, s_values, sq, Uh, K0, s2_values, out):
    """:func:`phase_loglik_batch` at every position noise of ``s2_values`` (``out`` ``(S2, C)``: row ``v`` is
    ``phase_loglik_batch(..., s2_values[v], ...)``, the same numbers bit for bit).

    The statistics of a candidate phase (``H^T H``, ``H^T r``, ``|r|^2``: :func:`_stats`) do not depend on the
    noise, so they are computed once per phase instead of once per (phase, noise); the rest is
    :func:`_loglik_at`, as in :func:`phase_loglik_batch`, run once per noise with that noise fixed.  The likelihood
    phase's noise selection (:mod:`interprim.models.primitive.selection`) scores every held-out case at every
    candidate noise on one grid of phases.  Workspaces ``O(C q4 (q4 + D_o))`` for the statistics of the ``C`` phases.
    """
    q = Zh.shape[1]
    n_o = Rg.shape[1]
    n = Uh.shape[2]
    q4 = (q + 3) // 4 * 4
    r = n + 1
    r4 = (r + 3) // 4 * 4
    n4 = (n + 3) // 4 * 4
    P = q4 + (n_o + 1) // 2 * 2
    ET = np.zeros((P, BLOCK))
    T = np.zeros((q, q))
    Ub = np.zeros((q, r4))
    V = np.zeros((q, r4))
    VT = np.zeros((r4, n_o * q))
    Kacc = np.zeros((r4, r4))
    F = np.zeros((n4, n4 + 4))
    C = s_values.shape[0]
    Gs = np.zeros((C, q4, P))
    rrs = np.zeros(C)
    for ci in range(C):
        rrs[ci] = _stats(Zh, Rg, z, M, s_values[ci], q4, ET, Gs[ci])
    for vi in range(s2_values.shape[0]):
        s2 = s2_values[vi]
        log_s2 = np.log(s2)
        for ci in range(C):
            out[vi, ci] = _loglik_at(Gs[ci], rrs[ci], M, sq, Uh, K0, s2, log_s2, T, Ub, V, VT, Kacc, F)
    return out


# ---------------------------------------------------------------------------------------------------------------
# online tracking on a lattice of speeds (interprim.phase.tracking.Tracker)
#
# A stream's candidates are speeds ``v_j = v0 exp(dlog j)`` (integer ``j``): frame ``m`` of candidate ``j`` sits
# at phase ``v_j m`` whatever the number of frames seen, so each lattice point keeps its statistics ``G``,
# ``H^T r``, ``|r|^2`` and its dense factors (upper Cholesky factors ``R_i`` of ``T_i`` and the ``n x n`` matrix
# ``K``, ``log det T``) in a slot, and a new frame changes them by one row ``h``: ``T_i += u_i u_i^T`` with
# ``u_i = S_i h`` (rank-1 Cholesky update, ``O(q^2)``), ``K += sigma^2 / gamma_i (Uh_i^T T_i^{-1} u_i)(...)^T``
# with ``gamma_i = 1 + u_i^T T_i^{-1} u_i`` (Sherman-Morrison; ``log det T_i += log gamma_i``).  Only ``t``,
# ``c^T T^{-1} c`` (the new ``H^T r`` changes every entry) and the Cholesky of ``[K | t]`` are formed per frame:
# ``O(D_o (q^2 + q n) + n^3)`` instead of ``O(M q (q + D_o) + D_o (q^3 + q^2 n + q n^2))``.

SLOT_FREE = -(1 << 62)


@njit(cache=True, fastmath=_FM)
def _row(Zh, Rg, z, m, vn, h, rv):
    """Row ``h`` of ``H`` and residual ``rv`` of frame ``m`` at grid position ``m * vn``; returns ``|rv|^2``."""
    K1, q = Zh.shape
    n_steps = K1 - 1
    n_o = Rg.shape[1]
    kf, a = _grid_cell(m * vn, n_steps)
    wa = 1.0 - a
    Z0 = Zh[kf]
    Z1 = Zh[kf + 1]
    for j in range(q):
        h[j] = wa * Z0[j] + a * Z1[j]
    R0 = Rg[kf]
    R1 = Rg[kf + 1]
    zm = z[m]
    rr = 0.0
    for i in range(n_o):
        x = zm[i] - (wa * R0[i] + a * R1[i])
        rv[i] = x
        rr += x * x
    return rr


@njit(cache=True, fastmath=_FM)
def _stats_lattice(Zh, Rg, z, M, vn, q4, ET, G, h, rv):
    """:func:`_stats` with frame ``m`` at grid position ``m * vn`` (rows from :func:`_row`); returns ``|r|^2``."""
    q = Zh.shape[1]
    n_o = Rg.shape[1]
    W = ET.shape[1]
    P = ET.shape[0]
    rr = 0.0
    for j in range(q4):
        for lc in range(P):
            G[j, lc] = 0.0
    for m0 in range(0, M, W):
        nb = min(W, M - m0)
        for k in range(nb):
            rr += _row(Zh, Rg, z, m0 + k, vn, h, rv)
            for j in range(q):
                ET[j, k] = h[j]
            for i in range(n_o):
                ET[q4 + i, k] = rv[i]
        _gram_block(ET, nb, q4, P, G)
    return rr


@njit(cache=True, fastmath=_FM)
def _dense_full(G, rr, q4, sq, Uh, K0, s2, Rs, Ks, Ys, ts, T, Ub, V, VT, Kacc, c, p):
    """Dense state of a slot from its statistics: ``Rs[i]`` (upper Cholesky factor of ``T_i``), ``Ks`` (lower
    part of ``K``), ``Ys[i] = T_i^{-1} c_i``, ``ts = sum_i Uh_i^T Ys[i]``; returns ``(log det T, J)`` with
    ``J = |r|^2 - sum_i c_i^T T_i^{-1} c_i`` (``log det T`` nan on failure)."""
    n_o, q = sq.shape
    n = Uh.shape[2]
    r4 = Ub.shape[1]
    ld_T = 0.0
    J = rr
    for a in range(n):
        ts[a] = 0.0
    for i in range(n_o):
        si = sq[i]
        Ui = Uh[i]
        for a in range(q):
            sa = si[a]
            Ta = T[a]
            for cc in range(a + 1):
                Ta[cc] = sa * G[cc, a] * si[cc]
            Ta[a] += s2
        ld = chol_inplace(T, q)
        if not np.isfinite(ld):
            return np.nan, 0.0
        ld_T += ld
        Ri = Rs[i]
        for a in range(q):
            for cc in range(a):
                Ri[a, cc] = 0.0
            for cc in range(a, q):
                Ri[a, cc] = T[cc, a]
        for a in range(q):
            Ua = Ui[a]
            Uba = Ub[a]
            for cc in range(n):
                Uba[cc] = Ua[cc]
            for cc in range(n, r4):
                Uba[cc] = 0.0
        forward_rows(T, Ub, V)
        off = i * q
        for a in range(q):
            Va = V[a]
            for cc in range(r4):
                VT[cc, off + a] = Va[cc]
        for a in range(q):
            c[a] = si[a] * G[a, q4 + i]
        y = Ys[i]
        J -= solve_R(Ri, c, p, y)
        for a in range(q):
            ya = y[a]
            Ua = Ui[a]
            for cc in range(n):
                ts[cc] += Ua[cc] * ya
    _syrk_T(VT, n_o * q, Kacc)
    for a in range(n):
        for cc in range(a + 1):
            Ks[a, cc] = K0[a, cc] - s2 * Kacc[a, cc]
    return ld_T, J


@njit(cache=True, fastmath=_FM)
def _add_frame(h, rv, q4, sq, Uh, s2, G, Rs, Ks, Ys, ts, u, p, x, w):
    """Add one frame (row ``h``, residual ``rv``) to a slot: statistics, ``R_i`` (rank-1 update with
    ``u_i = S_i h``), ``K`` (Sherman-Morrison), ``y_i``, ``t`` (recursive least squares: innovation
    ``e_i = r_i - u_i^T y_i``, ``y_i += T_i^{-1} u_i e_i / gamma_i``).  Returns the changes of ``log det T``
    (``sum log gamma_i``) and of ``J`` (``sum e_i^2 / gamma_i``, no cancellation)."""
    n_o, q = sq.shape
    n = Uh.shape[2]
    for j in range(q):
        hj = h[j]
        Gj = G[j]
        for lc in range(j, q):
            Gj[lc] += hj * h[lc]
        for i in range(n_o):
            Gj[q4 + i] += hj * rv[i]
    dld = 0.0
    dJ = 0.0
    for i in range(n_o):
        si = sq[i]
        R = Rs[i]
        y = Ys[i]
        e = rv[i]
        for j in range(q):
            uj = si[j] * h[j]
            u[j] = uj
            e -= uj * y[j]
        g = 1.0 + solve_R(R, u, p, x)  # x = T^{-1} u
        for a in range(n):
            w[a] = 0.0
        Ui = Uh[i]
        for j in range(q):
            xj = x[j]
            Uj = Ui[j]
            for a in range(n):
                w[a] += Uj[a] * xj
        f = s2 / g
        for a in range(n):
            fa = f * w[a]
            Ka = Ks[a]
            for c in range(a + 1):
                Ka[c] += fa * w[c]
        eg = e / g
        for j in range(q):
            y[j] += x[j] * eg
        for a in range(n):
            ts[a] += w[a] * eg
        dld += np.log(g)
        dJ += e * eg
        chol_update_R(R, u)  # R^T R + u u^T (u is consumed)
    return dld, dJ


@njit(cache=True, fastmath=_FM)
def _eval_slot(J, ld_T, M, n_o, q, s2, Ks, ts, F):
    """Log-likelihood of a slot's ``M`` frames from ``J``, ``log det T``, ``K`` and ``t`` (``-inf`` on
    failure): one bordered Cholesky of ``[K | t]``."""
    n = Ks.shape[0]
    n4 = F.shape[0]
    for a in range(n):
        Fa = F[a]
        Ka = Ks[a]
        for c in range(a + 1):
            Fa[c] = Ka[c]
        for c in range(a + 1, n):
            Fa[c] = Ks[c, a]
        for c in range(n, n4 + 4):
            Fa[c] = 0.0
        Fa[n4] = ts[a]
    for a in range(n, n4):
        Fa = F[a]
        for c in range(n4 + 4):
            Fa[c] = 0.0
        Fa[a] = 1.0
    ld_K = _chol_aug(F, n4, n4 + 4)
    if not np.isfinite(ld_K):
        return -np.inf
    tKt = 0.0
    for a in range(n4):
        tKt += F[a, n4] * F[a, n4]
    N = M * n_o
    logdet = n_o * (M - q) * np.log(s2) + ld_T + ld_K
    return -0.5 * (N * _LOG2PI + logdet + J / s2 - tKt)


@njit(cache=True, fastmath=_FM)
def _slot_loglik(Zh, Rg, z, M, j, v, kc, nh, max_gap, sq, Uh, K0, s2, keys, cnt, last, Gs, rrs, Rs, Ks, ldTs,
                 Ys, ts, Js, ET, T, Ub, V, VT, Kacc, F, vec):
    """Log-likelihood of lattice point ``j`` (speed ``v``) at ``M`` frames, from its slot (extended by the new
    frames) or from a fresh slot."""
    n_o, q = sq.shape
    q4 = Gs.shape[1]
    NS = keys.shape[0]
    vn = v * (Zh.shape[0] - 1)
    h, rv, u, p, x, w = vec[0], vec[1], vec[2], vec[3], vec[4], vec[5]
    slot = -1
    for k in range(NS):
        if keys[k] == j:
            slot = k
            break
    if slot >= 0 and (cnt[slot] > M or M - cnt[slot] > max_gap):
        keys[slot] = SLOT_FREE
        slot = -1
    if slot < 0:  # a free slot, else the least recently used one outside the candidate window
        best = -1
        for k in range(NS):
            kk = keys[k]
            if kk == SLOT_FREE:
                best = k
                break
            if kk >= kc - nh and kk <= kc + nh:
                continue
            if best < 0 or last[k] < last[best]:
                best = k
        slot = best
        G = Gs[slot]
        rr = _stats_lattice(Zh, Rg, z, M, vn, q4, ET, G, h, rv)
        rrs[slot] = rr
        ld, J = _dense_full(G, rr, q4, sq, Uh, K0, s2, Rs[slot], Ks[slot], Ys[slot], ts[slot], T, Ub, V, VT, Kacc,
                            u, p)
        if not np.isfinite(ld):
            keys[slot] = SLOT_FREE
            return -np.inf
        ldTs[slot] = ld
        Js[slot] = J
        keys[slot] = j
        cnt[slot] = M
    else:
        G = Gs[slot]
        for m in range(cnt[slot], M):
            rrs[slot] += _row(Zh, Rg, z, m, vn, h, rv)
            dld, dJ = _add_frame(h, rv, q4, sq, Uh, s2, G, Rs[slot], Ks[slot], Ys[slot], ts[slot], u, p, x, w)
            ldTs[slot] += dld
            Js[slot] += dJ
        cnt[slot] = M
    last[slot] = M
    ll = _eval_slot(Js[slot], ldTs[slot], M, n_o, q, s2, Ks[slot], ts[slot], F)
    if not np.isfinite(ll):
        keys[slot] = SLOT_FREE
    return ll


@njit(cache=True, fastmath=_FM)
def track_step(Zh, Rg, z, M, v0, kc, nh, dlog, s_min, sq, Uh, K0, s2, prior, logel, mu, sd, max_gap,
               keys, cnt, last, Gs, rrs, Rs, Ks, ldTs, ET, T, Ub, V, VT, Kacc, F, vec, s1, o1, Ys, ts, Js,
               s_out, lp_out):
    """One online phase update on the speed lattice; returns ``(j, s)``: the chosen lattice index and phase.

    Candidates: ``j = kc - nh .. kc + nh`` at ``s_j = v0 exp(dlog j) (M - 1)``; those above 1 are scored once at
    ``s = 1`` (represented by the smallest such ``j``), those below ``s_min`` once at ``s_min`` (largest such
    ``j``), both from scratch (:func:`phase_loglik_batch`); the others from their slots.  Score = log-likelihood
    plus, with ``prior``, the log-normal duration prior (``logel`` = log elapsed time).  Ties: the smallest ``s``.
    Every scored candidate's phase and score are written to ``s_out[j - kc + nh]``, ``lp_out[j - kc + nh]``
    (``-inf`` where a candidate was merged into a clipped one), for the refinement of
    :class:`interprim.phase.tracking.Tracker`.
    """
    for t in range(2 * nh + 1):
        s_out[t] = -1.0
        lp_out[t] = -np.inf
    best_j = kc
    best_s = -1.0
    best_lp = -np.inf
    lo_j = kc - nh - 1
    hi_done = False
    for j in range(kc - nh, kc + nh + 1):
        v = v0 * np.exp(dlog * j)
        if v * (M - 1) < s_min:
            lo_j = j
    if lo_j >= kc - nh:  # one candidate at s_min
        s1[0] = s_min
        phase_loglik_batch(Zh, Rg, z, M, s1, sq, Uh, K0, s2, o1)
        lp = o1[0]
        if prior:
            d = (logel - np.log(s_min) - mu) / sd
            lp += -0.5 * d * d - np.log(s_min)
        best_j, best_s, best_lp = lo_j, s_min, lp
        s_out[lo_j - kc + nh] = s_min
        lp_out[lo_j - kc + nh] = lp
    for j in range(lo_j + 1, kc + nh + 1):
        v = v0 * np.exp(dlog * j)
        s = v * (M - 1)
        if s > 1.0:
            if hi_done:
                break
            hi_done = True
            s = 1.0
            s1[0] = 1.0
            phase_loglik_batch(Zh, Rg, z, M, s1, sq, Uh, K0, s2, o1)
            ll = o1[0]
        else:
            ll = _slot_loglik(Zh, Rg, z, M, j, v, kc, nh, max_gap, sq, Uh, K0, s2, keys, cnt, last, Gs, rrs, Rs, Ks,
                              ldTs, Ys, ts, Js, ET, T, Ub, V, VT, Kacc, F, vec)
        lp = ll
        if prior:
            d = (logel - np.log(s) - mu) / sd
            lp += -0.5 * d * d - np.log(s)
        s_out[j - kc + nh] = s
        lp_out[j - kc + nh] = lp
        if best_s < 0.0 or lp > best_lp:
            best_j, best_s, best_lp = j, s, lp
    return best_j, best_s


# ---------------------------------------------------------------------------------------------------------------
# workspaces of track_step, and the warm-up calls of the loader (interprim.core._compiled.loader)

N_SLOTS = 12
MAX_CANDIDATES = 63  # candidates per track_step call (its s_out, lp_out)


def track_buffers(q: int, n_o: int, n: int, n_slots: int = N_SLOTS):
    """Slots and workspaces of :func:`track_step` (sizes independent of the frames)."""
    q4 = (q + 3) // 4 * 4
    P = q4 + (n_o + 1) // 2 * 2
    r4 = (n + 1 + 3) // 4 * 4
    n4 = (n + 3) // 4 * 4
    return (np.full(n_slots, SLOT_FREE, dtype=np.int64), np.zeros(n_slots, dtype=np.int64),
            np.zeros(n_slots, dtype=np.int64), np.zeros((n_slots, q4, P)), np.zeros(n_slots),
            np.zeros((n_slots, n_o, q, q)), np.zeros((n_slots, n, n)), np.zeros(n_slots),
            np.zeros((P, BLOCK)), np.zeros((q, q)), np.zeros((q, r4)), np.zeros((q, r4)), np.zeros((r4, n_o * q)),
            np.zeros((r4, r4)), np.zeros((n4, n4 + 4)), np.zeros((6, max(q, n, n_o))), np.zeros(1), np.zeros(1),
            np.zeros((n_slots, n_o, q)), np.zeros((n_slots, n)), np.zeros(n_slots), np.zeros(MAX_CANDIDATES),
            np.zeros(MAX_CANDIDATES))


def warm_batch(fn: Callable[..., Any]) -> None:
    """Compile (or load from numba's cache) :func:`phase_loglik_batch` with tiny inputs of the real types."""
    rng = np.random.default_rng(0)
    K, q, n_o, n, M = 8, 3, 2, 2, 4
    sq = np.ones((n_o, q))
    Uh = rng.normal(size=(n_o, q, n))
    K0 = np.eye(n) + np.einsum("iqa,iqb->ab", Uh, Uh)
    fn(rng.normal(size=(K + 1, q)), rng.normal(size=(K + 1, n_o)), rng.normal(size=(M, n_o)), M,
       np.array([0.5, 1.0]), sq, Uh, K0, 1.0, np.empty(2))


def warm_noise_grid(fn: Callable[..., Any]) -> None:
    """Compile (or load from numba's cache) :func:`phase_loglik_noise_grid` with tiny inputs of the real types."""
    rng = np.random.default_rng(0)
    K, q, n_o, n, M = 8, 3, 2, 2, 4
    sq = np.ones((n_o, q))
    Uh = rng.normal(size=(n_o, q, n))
    K0 = np.eye(n) + np.einsum("iqa,iqb->ab", Uh, Uh)
    fn(rng.normal(size=(K + 1, q)), rng.normal(size=(K + 1, n_o)), rng.normal(size=(M, n_o)), M,
       np.array([0.5, 1.0]), sq, Uh, K0, np.array([1.0, 2.0]), np.empty((2, 2)))


def warm_track(fn: Callable[..., Any], s_min: float = 0.02) -> None:
    """Compile (or load from numba's cache) :func:`track_step` with tiny inputs of the real types."""
    rng = np.random.default_rng(0)
    K, q, n_o, n, M = 8, 3, 2, 2, 6
    Uh = rng.normal(size=(n_o, q, n))
    K0 = np.eye(n) + np.einsum("iqa,iqb->ab", Uh, Uh)
    buf = track_buffers(q, n_o, n, 4)
    z = rng.normal(size=(M, n_o))
    for v0 in (0.05, 0.3):
        buf[0][:] = SLOT_FREE
        for m in (4, 5, 6):
            fn(rng.normal(size=(K + 1, q)), rng.normal(size=(K + 1, n_o)), z, m, v0, 0, 3, 0.05, s_min,
               np.ones((n_o, q)), Uh, K0, 1.0, True, 0.0, 0.0, 1.0, 8, *buf)

"""Compiled kernel of the likelihood phase estimator (numba, cached on disk).

:func:`phase_loglik_batch` evaluates the marginal log-likelihood of the
observed positions (``interprim.phase_likelihood.phase_log_likelihood``) at
several candidate phases in one call.  Reference:
``interprim.phase_likelihood._phase_log_likelihood_reference`` (the
per-candidate design matrix and :func:`interprim.selection._lowrank_case`);
plain numpy equivalent: ``interprim.phase_likelihood._loglik_batch_numpy``
(``tests/test_phase_likelihood.py`` checks all three agree).

Per candidate ``s`` the ``M`` observed frames sit at ``s_m = s m / (M - 1)``.
The position design of every observed DoF is the same ``H(s)`` (``M x q``,
rows interpolated linearly on the rollout grid), so the observation enters
only through ``G = H^T H`` (``q x q``), ``b_i = H^T r_i`` and ``|r|^2``, with
the residual ``r = z - (free(s) [z0; v0] + H(s) mu)`` taken from a
precomputed grid of the prior-mean path (no cancellation in ``|r|^2``).  The
prior of the observed block is ``diag(d) + W^T W`` (rank ``n`` = number of
demonstrations); with ``S_i = diag(sqrt(d_i))``, ``Uh_i = S_i^{-1} W_i^T`` and
``T_i = sigma^2 I + S_i G S_i`` (as in :class:`interprim.gaussian.LowRankConditioner`)::

    log det Cov = sum_i (log det T_i + (M - q) log sigma^2) + log det K,
    K = I + sum_i Uh_i^T (I - sigma^2 T_i^{-1}) Uh_i                  (n x n)
    r^T Cov^{-1} r = (|r|^2 - sum_i c_i^T T_i^{-1} c_i) / sigma^2 - t^T K^{-1} t,
    c_i = S_i b_i,  t = sum_i Uh_i^T T_i^{-1} c_i.

Both ``T_i^{-1}`` terms come from one forward substitution of ``[Uh_i | c_i]``
(``q x (n + 1)``) per DoF.  Cost per candidate ``O(M q (q + D_o))`` for the
statistics plus ``O(D_o (q^3 + q^2 n + q n^2) + n^3)``, no ``M``-sized
factorisation; no BLAS call (so no thread pool to limit).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ._kernels import _chol_inplace, _chol_solve_vec, _forward_rows

_FM = {"contract", "reassoc", "nsz", "arcp"}
_LOG2PI = float(np.log(2.0 * np.pi))


@njit(cache=True, fastmath=_FM)
def _syrk_sub_lower(V, s2, K):
    """``K -= s2 V^T V`` on the lower triangle of ``K`` (``V`` is ``(q, r)``), four rows of ``V`` per sweep."""
    q, r = V.shape
    a = 0
    while a + 4 <= q:
        V0 = V[a]
        V1 = V[a + 1]
        V2 = V[a + 2]
        V3 = V[a + 3]
        for c1 in range(r):
            w0 = s2 * V0[c1]
            w1 = s2 * V1[c1]
            w2 = s2 * V2[c1]
            w3 = s2 * V3[c1]
            Kc = K[c1]
            for c2 in range(c1 + 1):
                Kc[c2] -= w0 * V0[c2] + w1 * V1[c2] + w2 * V2[c2] + w3 * V3[c2]
        a += 4
    while a < q:
        Va = V[a]
        for c1 in range(r):
            w = s2 * Va[c1]
            Kc = K[c1]
            for c2 in range(c1 + 1):
                Kc[c2] -= w * Va[c2]
        a += 1


@njit(cache=True, fastmath=_FM)
def _dot(A, B, M):
    acc = 0.0
    for m in range(M):
        acc += A[m] * B[m]
    return acc


@njit(cache=True, fastmath=_FM)
def _grams(ET, RT, M, G, b):
    """Upper triangle of ``G = ET ET^T`` and ``b = ET RT^T`` over the first ``M`` columns (4 x 2 register blocks)."""
    q = ET.shape[0]
    n_o = RT.shape[0]
    for j in range(0, q, 4):
        if j + 4 > q:  # remainder rows
            for jj in range(j, q):
                for l in range(jj, q):
                    G[jj, l] = _dot(ET[jj], ET[l], M)
            break
        A0 = ET[j]
        A1 = ET[j + 1]
        A2 = ET[j + 2]
        A3 = ET[j + 3]
        # the 4 x 4 diagonal block
        for jj in range(j, j + 4):
            for l in range(jj, j + 4):
                G[jj, l] = _dot(ET[jj], ET[l], M)
        l = j + 4
        while l < q:
            if l + 2 <= q:
                B0 = ET[l]
                B1 = ET[l + 1]
                s00 = 0.0
                s01 = 0.0
                s10 = 0.0
                s11 = 0.0
                s20 = 0.0
                s21 = 0.0
                s30 = 0.0
                s31 = 0.0
                for m in range(M):
                    b0 = B0[m]
                    b1 = B1[m]
                    a0 = A0[m]
                    a1 = A1[m]
                    a2 = A2[m]
                    a3 = A3[m]
                    s00 += a0 * b0
                    s01 += a0 * b1
                    s10 += a1 * b0
                    s11 += a1 * b1
                    s20 += a2 * b0
                    s21 += a2 * b1
                    s30 += a3 * b0
                    s31 += a3 * b1
                G[j, l] = s00
                G[j, l + 1] = s01
                G[j + 1, l] = s10
                G[j + 1, l + 1] = s11
                G[j + 2, l] = s20
                G[j + 2, l + 1] = s21
                G[j + 3, l] = s30
                G[j + 3, l + 1] = s31
                l += 2
            else:
                for jj in range(j, j + 4):
                    G[jj, l] = _dot(ET[jj], ET[l], M)
                l += 1
    for j in range(0, q - 1, 2):
        A0 = ET[j]
        A1 = ET[j + 1]
        for i in range(n_o):
            Ri = RT[i]
            s0 = 0.0
            s1 = 0.0
            for m in range(M):
                rv = Ri[m]
                s0 += A0[m] * rv
                s1 += A1[m] * rv
            b[j, i] = s0
            b[j + 1, i] = s1
    if q % 2:
        for i in range(n_o):
            b[q - 1, i] = _dot(ET[q - 1], RT[i], M)


BLOCK = 64  # frames per block of the statistics: fixed-size workspaces, whatever the number of frames


@njit(cache=True, fastmath=_FM)
def _statistics(Zh, Rg, z, M, s, ET, RT, G, b, Gb, bb):
    """``G = H^T H`` (upper triangle), ``b = H^T r`` and ``|r|^2`` of the first ``M`` frames of ``z`` at phase ``s``.

    The frames are taken in blocks of ``ET.shape[1]`` (the rows of ``H`` and ``r`` of one block in ``ET``,
    ``RT``; the block's sums in ``Gb``, ``bb``), so the memory does not grow with ``M``.
    """
    K1, q = Zh.shape
    n_steps = K1 - 1
    n_o = Rg.shape[1]
    W = ET.shape[1]
    step = s / (M - 1) if M > 1 else 0.0
    rr = 0.0
    for j in range(q):
        for l in range(q):
            G[j, l] = 0.0
        for i in range(n_o):
            b[j, i] = 0.0
    for m0 in range(0, M, W):
        nb = min(W, M - m0)
        for k in range(nb):
            m = m0 + k
            sm = m * step
            if M > 1 and m == M - 1:
                sm = s  # numpy.linspace sets the end point exactly
            u = sm * n_steps
            if u < 0.0:
                u = 0.0
            elif u > n_steps:
                u = float(n_steps)
            kf = int(np.floor(u))
            if kf > n_steps - 1:
                kf = n_steps - 1
            a = u - kf
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
                RT[i, k] = rv
                rr += rv * rv
        _grams(ET, RT, nb, Gb, bb)
        for j in range(q):
            for l in range(j, q):
                G[j, l] += Gb[j, l]
            for i in range(n_o):
                b[j, i] += bb[j, i]
    return rr


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

    Workspaces (``O(BLOCK (q + D_o))`` for the statistics, ``O(q n + n^2)`` otherwise) are allocated once per
    call, independent of ``M``.
    """
    q = Zh.shape[1]
    n_o = Rg.shape[1]
    n = Uh.shape[2]
    r = n + 1
    Mw = BLOCK
    ET = np.empty((q, Mw))
    RT = np.empty((n_o, Mw))
    G = np.empty((q, q))
    b = np.empty((q, n_o))
    Gb = np.empty((q, q))
    bb = np.empty((q, n_o))
    T = np.empty((q, q))
    Ub = np.empty((q, r))
    V = np.empty((q, r))
    Ka = np.empty((r, r))
    t = np.empty(n)
    gam = np.empty(n)
    log_s2 = np.log(s2)
    for ci in range(s_values.shape[0]):
        rr = _statistics(Zh, Rg, z, M, s_values[ci], ET, RT, G, b, Gb, bb)
        for a in range(n):
            for c in range(a + 1):
                Ka[a, c] = K0[a, c]
        for c in range(r):
            Ka[n, c] = 0.0
        ld_T = 0.0
        ok = True
        for i in range(n_o):
            si = sq[i]
            for a in range(q):
                sa = si[a]
                Ta = T[a]
                for c in range(a + 1):
                    Ta[c] = sa * G[c, a] * si[c]  # G holds the upper triangle
                Ta[a] += s2
            ld = _chol_inplace(T, q)
            if not np.isfinite(ld):
                ok = False
                break
            ld_T += ld
            Ui = Uh[i]
            for a in range(q):
                Ua = Ui[a]
                Uba = Ub[a]
                for c in range(n):
                    Uba[c] = Ua[c]
                Uba[n] = si[a] * b[a, i]
            _forward_rows(T, Ub, V)
            _syrk_sub_lower(V, s2, Ka)
        if not ok:
            out[ci] = -np.inf
            continue
        # Ka[n, :n] = -s2 t,  Ka[n, n] = -s2 sum_i c_i^T T_i^{-1} c_i
        for c in range(n):
            t[c] = -Ka[n, c] / s2
        cTc = -Ka[n, n] / s2
        ld_K = _chol_inplace(Ka, n)
        if not np.isfinite(ld_K):
            out[ci] = -np.inf
            continue
        _chol_solve_vec(Ka, n, t, gam)
        tKt = 0.0
        for c in range(n):
            tKt += t[c] * gam[c]
        N = M * n_o
        logdet = n_o * (M - q) * log_s2 + ld_T + ld_K
        quad = (rr - cTc) / s2 - tKt
        out[ci] = -0.5 * (N * _LOG2PI + logdet + quad)
    return out

"""Compiled small dense linear algebra shared by the conditioning and phase-likelihood kernels.

Cholesky factorisation in place, triangular solves by rows, a rank-1 update of an
upper Cholesky factor and a symmetric rank-k subtraction, on preallocated
buffers (no BLAS call, so no thread pool to limit).  Tested through the kernels
that use them (``tests/compiled/test_fastpaths.py``, ``tests/phase/test_phase_likelihood.py``).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from . import FASTMATH as _FM


@njit(cache=True, fastmath=_FM)
def chol_inplace(A, n):
    """Lower Cholesky factor of the leading ``n x n`` block of ``A`` in place; returns log det, or NaN."""
    logdet = 0.0
    for j in range(n):
        s = A[j, j]
        for k in range(j):
            s -= A[j, k] * A[j, k]
        if not s > 0.0:
            return np.nan
        ljj = np.sqrt(s)
        A[j, j] = ljj
        logdet += 2.0 * np.log(ljj)
        inv = 1.0 / ljj
        for i in range(j + 1, n):
            s = A[i, j]
            for k in range(j):
                s -= A[i, k] * A[j, k]
            A[i, j] = s * inv
    return logdet


@njit(cache=True, fastmath=_FM)
def chol_solve_vec(L, n, b, out):
    """``out = (L L^T)^{-1} b`` for a lower Cholesky factor ``L``."""
    for i in range(n):
        s = b[i]
        for k in range(i):
            s -= L[i, k] * out[k]
        out[i] = s / L[i, i]
    for i in range(n - 1, -1, -1):
        s = out[i]
        for k in range(i + 1, n):
            s -= L[k, i] * out[k]
        out[i] = s / L[i, i]


@njit(cache=True, fastmath=_FM)
def solve_R(R, b, p, out):
    """``out = (R^T R)^{-1} b`` for an upper factor ``R`` (rows); ``p = R^{-T} b``; returns ``|p|^2``."""
    q = R.shape[0]
    for j in range(q):
        p[j] = b[j]
    pp = 0.0
    for k in range(q):  # forward, row-axpy form
        Rk = R[k]
        pk = p[k] / Rk[k]
        p[k] = pk
        pp += pk * pk
        for j in range(k + 1, q):
            p[j] -= pk * Rk[j]
    for k in range(q - 1, -1, -1):
        Rk = R[k]
        acc = p[k]
        for j in range(k + 1, q):
            acc -= Rk[j] * out[j]
        out[k] = acc / Rk[k]
    return pp


@njit(cache=True, fastmath=_FM)
def chol_update_R(R, u):
    """``R <- chol(R^T R + u u^T)`` for an upper Cholesky factor ``R`` (rows), ``O(q^2)``; ``u`` is consumed."""
    q = R.shape[0]
    for k in range(q):
        Rk = R[k]
        rkk = Rk[k]
        uk = u[k]
        rn = np.sqrt(rkk * rkk + uk * uk)
        c = rn / rkk
        sn = uk / rkk
        Rk[k] = rn
        ic = 1.0 / c
        for j in range(k + 1, q):
            rkj = (Rk[j] + sn * u[j]) * ic
            Rk[j] = rkj
            u[j] = c * u[j] - sn * rkj


@njit(cache=True, fastmath=_FM)
def forward_rows(L, U, W):
    """``W = L^{-1} U`` for lower-triangular ``L`` (q, q) and ``U`` (q, r); row updates vectorised over r."""
    q, r = U.shape
    for a in range(q):
        Wa = W[a]
        Ua = U[a]
        for c in range(r):
            Wa[c] = Ua[c]
        b = 0
        while b + 4 <= a:
            l0 = L[a, b]
            l1 = L[a, b + 1]
            l2 = L[a, b + 2]
            l3 = L[a, b + 3]
            W0 = W[b]
            W1 = W[b + 1]
            W2 = W[b + 2]
            W3 = W[b + 3]
            for c in range(r):
                Wa[c] -= l0 * W0[c] + l1 * W1[c] + l2 * W2[c] + l3 * W3[c]
            b += 4
        while b < a:
            lab = L[a, b]
            Wb = W[b]
            for c in range(r):
                Wa[c] -= lab * Wb[c]
            b += 1
        inv = 1.0 / L[a, a]
        for c in range(r):
            Wa[c] *= inv


@njit(cache=True, fastmath=_FM)
def syrk_sub(W, s2, K):
    """``K -= s2 W^T W`` on the lower triangle of ``K`` (all that :func:`chol_inplace` reads) for ``W`` (q, r),
    four rows of ``W`` per sweep over ``K``."""
    q, r = W.shape
    a = 0
    while a + 4 <= q:
        W0 = W[a]
        W1 = W[a + 1]
        W2 = W[a + 2]
        W3 = W[a + 3]
        for c1 in range(r):
            w0 = s2 * W0[c1]
            w1 = s2 * W1[c1]
            w2 = s2 * W2[c1]
            w3 = s2 * W3[c1]
            Kc = K[c1]
            for c2 in range(c1 + 1):
                Kc[c2] -= w0 * W0[c2] + w1 * W1[c2] + w2 * W2[c2] + w3 * W3[c2]
        a += 4
    while a < q:
        Wa = W[a]
        for c1 in range(r):
            w = s2 * Wa[c1]
            Kc = K[c1]
            for c2 in range(c1 + 1):
                Kc[c2] -= w * Wa[c2]
        a += 1

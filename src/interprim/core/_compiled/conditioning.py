"""Compiled Eq. 16-18 for a prior ``Sigma = diag(d) + U U^T`` (numba, cached on disk).

* :func:`lowrank_condition_mean` -- posterior mean and marginal
  log-likelihood of Eq. 16-18; reference: :meth:`interprim.core.gaussian.LowRankConditioner.mean_numpy`,
  :func:`interprim.core.gaussian.condition` / ``condition_literal``.

Nothing here allocates memory proportional to the number of observed frames:
callers pass preallocated buffers.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from . import FASTMATH as _FM
from .linalg import chol_inplace, chol_solve_vec, forward_rows, syrk_sub


@njit(cache=True, fastmath=_FM)
def lowrank_condition_mean(G, B, sigma2, yy, sq, Uh, K0, mean, mu_o, obs_flat, other, Uc, out):
    """Posterior mean of Eq. 18 for a prior ``Sigma = diag(d) + U U^T`` and ``Omega~ = [blockdiag(X), 0]``.

    Exact (no approximation): Woodbury's identity is applied twice, once to
    the block-diagonal part (one ``q x q`` Cholesky per observed DoF of
    ``T_i = sigma^2 I + S_i G S_i`` with ``S_i = diag(sqrt(d_i))``) and once to
    the rank-``r`` part (one ``r x r`` Cholesky of
    ``K = I + sum_i Uh_i^T (I - sigma^2 T_i^{-1}) Uh_i``, ``Uh = S^{-1} U``).
    Cost ``O(D_o (q^3 + q^2 r + q r^2) + P r)``, independent of the number of frames.

    Parameters
    ----------
    G, B : ``X^T X`` (q, q) and ``X^T F`` (q, D_o).
    sq : (D_o, q) ``sqrt(d)`` on the observed parameters.
    Uh : (D_o, q, r) whitened factor rows of the observed parameters.
    K0 : (r, r) ``I + Uh^T Uh``.
    mean : (P,) prior mean; mu_o : (D_o, q) its observed part.
    obs_flat : (D_o q,) int, other : (P - D_o q,) int.
    Uc : (P - D_o q, r) factor rows of the other parameters.
    out : (P,) posterior mean (output).

    Workspaces are allocated here (a few tens of kB, independent of the
    number of frames), so concurrent calls from several threads are safe.

    Returns
    -------
    (sum_i log det T_i, log det K, |F - Omega mu|^2 - c^T delta_o); NaN log-dets flag a failed factorisation.
    """
    Do, q, r = Uh.shape
    return _lowrank_mean(G, B, sigma2, yy, sq, Uh, K0, mean, mu_o, obs_flat, other, Uc, out,
                         np.empty((Do, q, q)), np.empty((r, r)), np.empty((0, 0)), np.empty((1, q, r)),
                         np.empty((3, Do, q)))


@njit(cache=True, fastmath=_FM)
def _lowrank_mean(G, B, sigma2, yy, sq, Uh, K0, mean, mu_o, obs_flat, other, Uc, out, T, K, Kpre, Ws, ca):
    """Body of :func:`lowrank_condition_mean`: ``T`` (D_o, q, q) receives the lower Cholesky factors of the
    ``T_i``, ``K`` (r, r) that of ``K``; when ``Kpre`` is ``(r, r)`` (not empty) it receives the lower
    triangle of ``K`` before factorisation.  Workspaces:
    ``Ws`` (1 or D_o, q, r), which keeps ``L_i^{-1} Uh_i`` when it has ``D_o`` entries, and ``ca``
    (3, D_o, q), which keeps ``c_i`` (``ca[0]``) and ``a_i = T_i^{-1} S_i c_i`` (``ca[1]``)."""
    Do, q, r = Uh.shape
    keepW = Ws.shape[0] == Do
    for i in range(r):
        for j in range(r):
            K[i, j] = K0[i, j]
    beta = np.zeros(r)
    tmp = np.empty(q)
    logdet_T = 0.0
    resid = yy
    for i in range(Do):
        Ti = T[i]
        si = sq[i]
        for a in range(q):
            for b in range(a + 1):
                Ti[a, b] = si[a] * G[a, b] * si[b]
            Ti[a, a] += sigma2
        ld = chol_inplace(Ti, q)
        logdet_T += ld
        Ui = Uh[i]
        W = Ws[i] if keepW else Ws[0]
        forward_rows(Ti, Ui, W)
        syrk_sub(W, sigma2, K)
        # c_i = b_i - G mu_i ;  residual |f_i - X mu_i|^2 = yy_i - mu.b - mu.c
        c = ca[0, i]
        mu = mu_o[i]
        for a in range(q):
            acc = 0.0
            Ga = G[a]
            for b in range(q):
                acc += Ga[b] * mu[b]
            cc = B[a, i] - acc
            c[a] = cc
            resid -= mu[a] * (B[a, i] + cc)
            tmp[a] = si[a] * cc
        # a_i = T_i^{-1} S c_i ;  beta += Uh_i^T a_i
        ai = ca[1, i]
        chol_solve_vec(Ti, q, tmp, ai)
        for a in range(q):
            aa = ai[a]
            Ua = Ui[a]
            for k in range(r):
                beta[k] += Ua[k] * aa
    if Kpre.shape[0] == r:
        for a in range(r):
            for b in range(a + 1):
                Kpre[a, b] = K[a, b]
    ld_K = chol_inplace(K, r)
    gamma = np.empty(r)
    chol_solve_vec(K, r, beta, gamma)
    for i in range(Do):
        Ui = Uh[i]
        si = sq[i]
        for a in range(q):
            Ua = Ui[a]
            acc = 0.0
            for k in range(r):
                acc += Ua[k] * gamma[k]
            tmp[a] = acc
        w = ca[2, i]
        chol_solve_vec(T[i], q, tmp, w)
        c = ca[0, i]
        ai = ca[1, i]
        for a in range(q):
            delta = si[a] * (ai[a] + sigma2 * w[a])
            idx = obs_flat[i * q + a]
            out[idx] = mean[idx] + delta
            resid -= c[a] * delta
    for p in range(other.shape[0]):
        acc = 0.0
        Up = Uc[p]
        for k in range(r):
            acc += Up[k] * gamma[k]
        idx = other[p]
        out[idx] = mean[idx] + acc
    return logdet_T, ld_K, resid

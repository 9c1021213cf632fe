"""Compiled Eq. 16-18 for a prior ``Sigma = diag(d) + U U^T`` (numba, cached on disk).

* :func:`lowrank_condition_mean` -- posterior mean and marginal
  log-likelihood of Eq. 16-18; reference: :meth:`interprim.gaussian.LowRankConditioner.mean_numpy`,
  :func:`interprim.gaussian.condition` / ``condition_literal``.
* :func:`lowrank_condition_seed` / :func:`lowrank_condition_step` -- the same
  posterior mean, kept up to date frame by frame while the observed frames keep
  their phases (a stream on the likelihood phase's lattice of speeds): rank-1
  updates of the statistics and of the factors (Cholesky update,
  Sherman-Morrison); reference: :func:`lowrank_condition_mean` on the same frames.

Nothing here allocates memory proportional to the number of observed frames:
callers pass preallocated buffers.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from . import FASTMATH as _FM

from .linalg import _backward_rows, _chol_inplace, _chol_solve_vec, _chol_update_R, _forward_rows, _solve_R, _syrk_sub


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
    triangle of ``K`` before factorisation (the state of :func:`lowrank_condition_step`).  Workspaces:
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
        ld = _chol_inplace(Ti, q)
        logdet_T += ld
        Ui = Uh[i]
        W = Ws[i] if keepW else Ws[0]
        _forward_rows(Ti, Ui, W)
        _syrk_sub(W, sigma2, K)
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
        _chol_solve_vec(Ti, q, tmp, ai)
        for a in range(q):
            aa = ai[a]
            Ua = Ui[a]
            for k in range(r):
                beta[k] += Ua[k] * aa
    if Kpre.shape[0] == r:
        for a in range(r):
            for b in range(a + 1):
                Kpre[a, b] = K[a, b]
    ld_K = _chol_inplace(K, r)
    gamma = np.empty(r)
    _chol_solve_vec(K, r, beta, gamma)
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
        _chol_solve_vec(T[i], q, tmp, w)
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


@njit(cache=True, fastmath=_FM)
def lowrank_condition_seed(G, B, sigma2, yy, sq, Uh, K0, mean, mu_o, obs_flat, other, Uc, out, Rs, Ks, Ms, As):
    """:func:`lowrank_condition_mean` (same arithmetic, same results) that also keeps the state of
    :func:`lowrank_condition_step`: ``Rs`` (D_o, q, q) the upper Cholesky factors ``R_i`` (``R_i^T R_i = T_i``,
    rows; zero below the diagonal), ``Ks`` (r, r) the lower triangle of
    ``K = I + sum_i Uh_i^T (I - sigma^2 T_i^{-1}) Uh_i`` (before its factorisation), ``Ms`` (D_o, q, r)
    ``T_i^{-1} Uh_i`` and ``As`` (D_o, q) ``a_i = T_i^{-1} S_i c_i``.  Returns the same
    ``(sum_i log det T_i, log det K, residual)``."""
    Do, q, r = Uh.shape
    T = np.empty((Do, q, q))
    Ws = np.empty((Do, q, r))
    ca = np.empty((3, Do, q))
    res = _lowrank_mean(G, B, sigma2, yy, sq, Uh, K0, mean, mu_o, obs_flat, other, Uc, out, T, np.empty((r, r)),
                        Ks, Ws, ca)
    for i in range(Do):
        Ti = T[i]
        Ri = Rs[i]
        for a in range(q):
            for b in range(a):
                Ri[a, b] = 0.0
            for b in range(a, q):
                Ri[a, b] = Ti[b, a]
        _backward_rows(Ri, Ws[i], Ms[i])  # T_i^{-1} Uh_i = R_i^{-1} (L_i^{-1} Uh_i)
        for a in range(q):
            As[i, a] = ca[1, i, a]
    return res


@njit(cache=True, fastmath=_FM)
def lowrank_condition_step(zm, s, y0, v0, Z, powers, sigma2, yy, sq, Uh, mean, mu_o, obs_flat, other, Uc,
                           G, B, Rs, Ks, Ms, As, Kf, vec, C, out):
    """One more observed frame for :func:`lowrank_condition_mean`: the posterior mean of Eq. 18 (Eq. 16-17 with
    ``Omega~ = [blockdiag(X), 0]``, low-rank + diagonal prior), updated instead of recomputed.

    When the ``M - 1`` frames already seen keep their phases (the likelihood phase on a lattice of speeds:
    frame ``m`` at ``v m`` while the chosen speed ``v`` and the start ``[y0; v0]`` stay the same), the new
    frame ``zm`` at phase ``s`` only appends one row to the observation: the position design row
    ``h = H(s)`` (:func:`position_stats`' row, ``LinearRollout.design(0, s)``) with residual
    ``y = zm - free(s) [y0; v0]``.  The statistics change by rank one, ``G += h h^T``, ``B += h y^T``,
    ``|Y|^2 += |y|^2``, and so does everything kept in the state (per observed DoF ``i``, with
    ``u_i = S_i h``, ``x_i = T_i^{-1} u_i`` from the factor before the update (:func:`_solve_R`),
    ``g_i = 1 + u_i^T x_i`` and ``w_i = Uh_i^T x_i``; Sherman-Morrison:
    ``T_i'^{-1} = T_i^{-1} - x_i x_i^T / g_i``):

    * ``T_i = sigma^2 I + S_i G S_i`` gains ``u_i u_i^T``: its upper Cholesky factor ``R_i`` (``Rs[i]``)
      gets a rank-1 update (:func:`_chol_update_R`, ``O(q^2)``) and ``log det T_i`` grows by ``log g_i``
      (matrix determinant lemma);
    * ``K = I + sum_i Uh_i^T (I - sigma^2 T_i^{-1}) Uh_i`` (lower triangle ``Ks``) gains
      ``sigma^2 w_i w_i^T / g_i``;
    * ``T_i^{-1} Uh_i`` (``Ms[i]``) loses ``x_i w_i^T / g_i``;
    * ``a_i = T_i^{-1} S_i c_i`` (``As[i]``, ``c_i = b_i - G mu_i`` gains ``h e_i`` with
      ``e_i = y_i - h^T mu_i``) becomes ``a_i + x_i (e_i - u_i^T a_i) / g_i`` (recursive least squares).

    The mean is then finished as in :func:`lowrank_condition_mean`: ``beta = sum_i Uh_i^T a_i``, one
    ``r x r`` Cholesky of ``K`` (into ``Kf``), ``gamma = K^{-1} beta``,
    ``delta_i = S_i (a_i + sigma^2 T_i^{-1} Uh_i gamma)`` on the observed parameters and ``U_c gamma`` on
    the others; ``c_i`` (for the residual) from ``G`` and ``B``.  Cost ``O(D_o (q^2 + q r) + r^3)`` instead of
    ``O(M q (q + D_o) + D_o (q^3 + q^2 r + q r^2))`` for the statistics and the factorisations from scratch.
    Exact up to rounding (the same posterior; tested against the from-scratch path).

    ``yy`` is ``|Y|^2`` before the frame; ``G``, ``B``, ``Rs``, ``Ks``, ``Ms``, ``As`` (seeded by
    :func:`lowrank_condition_seed`) are updated in place; ``vec`` is a ``(>= 6, >= max(q, r, D_o))``
    workspace, ``C`` a ``(D_o, q)`` one, ``Kf`` an ``(r, r)`` one; ``out`` (P,) receives the posterior mean.

    Returns
    -------
    (change of sum_i log det T_i, log det K, residual as in :func:`lowrank_condition_mean`, new ``|Y|^2``);
    a NaN ``log det K`` flags a failed factorisation (the state is then unusable).
    """
    Kn = Z.shape[0] - 1
    Do, q, r = Uh.shape
    h = vec[0]
    y = vec[1]
    u = vec[2]
    p = vec[3]
    x = vec[4]
    w = vec[5]
    # -- the new row (as position_stats' frame at s)
    uu = min(max(s * Kn, 0.0), float(Kn))
    kf = min(int(np.floor(uu)), Kn - 1)
    kf = max(kf, 0)
    a = uu - kf
    b = 1.0 - a
    kf1 = min(kf + 1, Kn)
    Za = Z[kf, 0]
    Zb = Z[kf1, 0]
    for j in range(q):
        h[j] = b * Za[j] + a * Zb[j]
    f0 = b * powers[kf, 0, 0] + a * powers[kf1, 0, 0]
    f1 = b * powers[kf, 0, 1] + a * powers[kf1, 0, 1]
    for d in range(Do):
        yd = zm[d] - (f0 * y0[d] + f1 * v0[d])
        y[d] = yd
        yy += yd * yd
    # -- statistics
    for j in range(q):
        hj = h[j]
        Gj = G[j]
        for l in range(q):
            Gj[l] += hj * h[l]
        Bj = B[j]
        for d in range(Do):
            Bj[d] += hj * y[d]
    # -- state: R_i (rank-1 Cholesky update), K, T_i^{-1} Uh_i, a_i (Sherman-Morrison), log det T_i
    dld = 0.0
    for i in range(Do):
        si = sq[i]
        R = Rs[i]
        ai = As[i]
        mu = mu_o[i]
        e = y[i]
        ua = 0.0
        for j in range(q):
            uj = si[j] * h[j]
            u[j] = uj
            e -= h[j] * mu[j]
            ua += uj * ai[j]
        g = 1.0 + _solve_R(R, u, p, x)  # x = T_i^{-1} u_i
        Ui = Uh[i]
        for k in range(r):
            w[k] = 0.0
        for j in range(q):
            xj = x[j]
            Uj = Ui[j]
            for k in range(r):
                w[k] += Uj[k] * xj
        ig = 1.0 / g
        f = sigma2 * ig
        for k in range(r):
            fk = f * w[k]
            Kk = Ks[k]
            for l in range(k + 1):
                Kk[l] += fk * w[l]
        Mi = Ms[i]
        for j in range(q):
            xj = x[j] * ig
            Mj = Mi[j]
            for k in range(r):
                Mj[k] -= xj * w[k]
        ea = (e - ua) * ig
        for j in range(q):
            ai[j] += x[j] * ea
        dld += np.log(g)
        _chol_update_R(R, u)
    # -- the mean (as lowrank_condition_mean)
    beta = vec[5]
    gamma = vec[4]
    for k in range(r):
        beta[k] = 0.0
    resid = yy
    for i in range(Do):
        c = C[i]
        mu = mu_o[i]
        for j in range(q):
            acc = 0.0
            Gj = G[j]
            for l in range(q):
                acc += Gj[l] * mu[l]
            cc = B[j, i] - acc
            c[j] = cc
            resid -= mu[j] * (B[j, i] + cc)
        ai = As[i]
        Ui = Uh[i]
        for j in range(q):
            aj = ai[j]
            Uj = Ui[j]
            for k in range(r):
                beta[k] += Uj[k] * aj
    for k in range(r):
        Kk = Ks[k]
        Kfk = Kf[k]
        for l in range(k + 1):
            Kfk[l] = Kk[l]
    ld_K = _chol_inplace(Kf, r)
    if not np.isfinite(ld_K):
        return dld, np.nan, resid, yy
    _chol_solve_vec(Kf, r, beta, gamma)
    for i in range(Do):
        Mi = Ms[i]
        si = sq[i]
        c = C[i]
        ai = As[i]
        for j in range(q):
            Mj = Mi[j]
            acc = 0.0
            for k in range(r):
                acc += Mj[k] * gamma[k]
            delta = si[j] * (ai[j] + sigma2 * acc)
            idx = obs_flat[i * q + j]
            out[idx] = mean[idx] + delta
            resid -= c[j] * delta
    for pp in range(other.shape[0]):
        acc = 0.0
        Up = Uc[pp]
        for k in range(r):
            acc += Up[k] * gamma[k]
        idx = other[pp]
        out[idx] = mean[idx] + acc
    return dld, ld_K, resid, yy

"""Compiled kernels of the online hot path (numba, cached on disk).

Each kernel has a plain numpy reference elsewhere in the package that it is
tested against (``tests/test_fastpaths.py``):

* :func:`forcing_stats` -- sufficient statistics ``G = X^T X``, ``B = X^T Y``
  and ``|Y|^2`` of the paper's forcing observation (Eq. 13-15) at ``M``
  observed frames spread uniformly over ``[0, s_end]``; reference:
  ``InteractionPrimitive._observation`` (``np.gradient`` derivatives,
  :meth:`interprim.basis.Basis.phi_tilde`, :func:`interprim.dmp.forcing_values`).
* :func:`position_stats` -- the same statistics for the position observation
  (``observation="position"``: ``Y = z - free [y0; v0]``, ``X = H``, the rows of
  :meth:`interprim.dmp.LinearRollout.design` from ``s0 = 0``), accumulated in
  fixed-size blocks of frames; reference: ``InteractionPrimitive._observation``.
* :func:`lowrank_condition_mean` -- posterior mean and marginal
  log-likelihood of Eq. 16-18 for a prior ``Sigma = diag(d) + U U^T``;
  reference: :func:`interprim.gaussian.condition` / ``condition_literal``.
* :func:`lowrank_condition_seed` / :func:`lowrank_condition_step` -- the same
  posterior mean, kept up to date frame by frame while the observed frames keep
  their phases (a stream on the likelihood phase's lattice of speeds): rank-1
  updates of the statistics and of the factors (Cholesky update,
  Sherman-Morrison); reference: :func:`lowrank_condition_mean` on the same frames.
* :func:`response_positions` -- the controlled agent's mean movement from the
  current phase (integrated Eq. 1); reference:
  :meth:`interprim.dmp.LinearRollout.design`.

Nothing here allocates memory proportional to the number of observed frames:
callers pass preallocated buffers.
"""

from __future__ import annotations

import numpy as np
from numba import njit

# reassociation lets LLVM vectorise reductions; no 'nnan'/'ninf' (inputs are checked finite upstream)
_FM = {"contract", "reassoc", "nsz", "arcp"}


@njit(cache=True, fastmath=_FM)
def _gradient_uniform(f, M, dx, out):
    """``np.gradient(f[:M], dx, axis=0, edge_order=2)`` into ``out[:M]`` (``M >= 3``)."""
    D = f.shape[1]
    two_dx = 2.0 * dx
    for j in range(1, M - 1):
        for d in range(D):
            out[j, d] = (f[j + 1, d] - f[j - 1, d]) / two_dx
    a = -1.5 / dx
    b = 2.0 / dx
    c = -0.5 / dx
    for d in range(D):
        out[0, d] = a * f[0, d] + b * f[1, d] + c * f[2, d]
    a = 0.5 / dx
    b = -2.0 / dx
    c = 1.5 / dx
    for d in range(D):
        out[M - 1, d] = a * f[M - 3, d] + b * f[M - 2, d] + c * f[M - 1, d]


@njit(cache=True, fastmath=_FM)
def forcing_values_into(z, M, s_end, alpha_y, beta_y, yd, ydd, YT):
    """Forcing values of Eq. 15 of the first ``M`` frames of ``z`` observed over ``[0, s_end]``.

    Derivatives are second-order central differences in normalised time
    (``np.gradient`` with ``edge_order=2``, i.e. ``smoothing_window=None``).
    ``yd``, ``ydd`` are ``(>= M, D)`` workspaces; the forcing values are
    written transposed into ``YT`` (``(D, >= M)``).  Returns ``alpha_y beta_y``.
    """
    D = z.shape[1]
    ds = s_end / (M - 1)
    _gradient_uniform(z, M, ds, yd)
    _gradient_uniform(yd, M, ds, ydd)
    for j in range(M):
        for d in range(D):
            YT[d, j] = ydd[j, d] + alpha_y * (beta_y * z[j, d] + yd[j, d])
    return alpha_y * beta_y


_LOG2E = 1.4426950408889634
_LN2_HI = 6.93147180369123816490e-01  # fdlibm split of log(2): k * _LN2_HI is exact
_LN2_LO = 1.90821492927058770002e-10
_ROUND = 6755399441055744.0  # 1.5 * 2**52: adding and subtracting it rounds to the nearest integer


@njit(cache=True, fastmath={"contract"})
def vexp_nonpos(t, n, out, ibuf):
    """``out[:n] = exp(t[:n])`` for ``t <= 0``, vectorised (SIMD) and accurate to about 1 ulp.

    Cody-Waite range reduction ``t = k log 2 + r`` (``|r| <= log(2) / 2``), a
    degree-13 Taylor polynomial of ``exp(r)`` (truncation error < 1e-17) and
    ``2^k`` built from its IEEE bits.  Results below ``exp(-708)`` (subnormal
    in IEEE arithmetic) are flushed to 0; where it is used they are multiplied
    by numbers of order one, so this is far below double precision.
    ``t`` and ``out`` must be different arrays (aliasing defeats vectorisation).
    ``ibuf`` is an int64 workspace.
    """
    fb = ibuf.view(np.float64)
    for i in range(n):
        x = t[i]
        x = x if x > -708.0 else -708.0
        k = (x * _LOG2E + _ROUND) - _ROUND
        r = (x - k * _LN2_HI) - k * _LN2_LO
        p = 1.0 / 6227020800.0
        p = p * r + 1.0 / 479001600.0
        p = p * r + 1.0 / 39916800.0
        p = p * r + 1.0 / 3628800.0
        p = p * r + 1.0 / 362880.0
        p = p * r + 1.0 / 40320.0
        p = p * r + 1.0 / 5040.0
        p = p * r + 1.0 / 720.0
        p = p * r + 1.0 / 120.0
        p = p * r + 1.0 / 24.0
        p = p * r + 1.0 / 6.0
        p = p * r + 0.5
        p = p * r + 1.0
        p = p * r + 1.0
        ibuf[i] = np.int64(np.int32(k) + 1023) << 52
        out[i] = p if t[i] > -708.0 else 0.0
    for i in range(n):
        out[i] = out[i] * fb[i]


@njit(cache=True, fastmath=_FM)
def design_stats(YT, M, s_end, centers, widths, alpha_x, const, XT, G, B, work, ibuf):
    """``G = X^T X``, ``B = X^T Y`` and ``|Y|^2`` of Eq. 13 rows at ``s_j = linspace(0, s_end, M)``.

    ``YT`` holds the targets transposed, ``(D, >= M)``.  Row ``j`` of ``X`` is ``[phi(x(s_j)), const]`` (Eq. 2 and 13, ``const = alpha_y beta_y``),
    computed as :meth:`interprim.basis.Basis.phi` (max-shifted exponentials) with the
    exponentials of :func:`vexp_nonpos`.  ``XT`` is a ``(q, >= M)`` workspace, ``work``
    a ``(4, >= M)`` one and ``ibuf`` an int64 ``(>= M)`` one; ``G`` ``(q, q)`` and ``B``
    ``(q, D)`` are outputs.  Loops run along the frames, so they vectorise.
    """
    m = centers.shape[0]
    q = m + 1
    D = YT.shape[0]
    step = s_end / (M - 1) if M > 1 else 0.0
    xs = work[0]
    mx = work[1]
    tot = work[2]
    tv = work[3]
    for j in range(M):
        tv[j] = -alpha_x * (j * step)
    tv[M - 1] = -alpha_x * s_end
    vexp_nonpos(tv, M, xs, ibuf)  # x = exp(-alpha_x s)  (Eq. 9)
    for j in range(M):
        mx[j] = -np.inf
        tot[j] = 0.0
    for i in range(m):
        Ei = XT[i]
        ci = centers[i]
        wi = widths[i]
        for j in range(M):
            dxc = xs[j] - ci
            e = -wi * dxc * dxc
            Ei[j] = e
            mx[j] = e if e > mx[j] else mx[j]
    for i in range(m):
        Ei = XT[i]
        for j in range(M):
            tv[j] = Ei[j] - mx[j]
        vexp_nonpos(tv, M, Ei, ibuf)
        for j in range(M):
            tot[j] += Ei[j]
    for j in range(M):
        tot[j] = xs[j] / tot[j]
    for i in range(m):
        Ei = XT[i]
        for j in range(M):
            Ei[j] *= tot[j]
    Xc = XT[m]
    for j in range(M):
        Xc[j] = const
    for a in range(q):
        Xa = XT[a]
        for b in range(a + 1):
            Xb = XT[b]
            acc = 0.0
            for j in range(M):
                acc += Xa[j] * Xb[j]
            G[a, b] = acc
            G[b, a] = acc
    yy = 0.0
    for d in range(D):
        Yd = YT[d]
        for a in range(q):
            Xa = XT[a]
            acc = 0.0
            for j in range(M):
                acc += Xa[j] * Yd[j]
            B[a, d] = acc
        acc = 0.0
        for j in range(M):
            acc += Yd[j] * Yd[j]
        yy += acc
    return yy


@njit(cache=True, fastmath=_FM)
def position_stats(z, M, s_end, y0, v0, Z, powers, G, B, HT, YT):
    """``G = H^T H``, ``B = H^T Y`` and ``|Y|^2`` of the position observation of ``z[:M]`` over ``[0, s_end]``.

    Frame ``j`` is at ``s_j = linspace(0, s_end, M)[j]``; its design row is the
    rollout map from rest at ``s = 0`` (``LinearRollout.design(0, s)``: grid
    ``K = n_steps``, ``u = clip(s K, 0, K)``, linear interpolation between grid
    points ``kf`` and ``kf + 1``)::

        h_j = (1 - a) Z[kf, 0] + a Z[kf + 1, 0]          (Z[0] = 0, so P Z[0] drops out)
        Y_j = z_j - ((1 - a) P[kf, 0] + a P[kf + 1, 0]) @ [y0; v0]

    with ``Z`` (K+1, 2, q) and ``powers`` (K+1, 2, 2) of :class:`interprim.dmp.LinearRollout`.
    Neither ``H`` nor ``Y`` is formed: frames are taken in blocks of
    ``C = HT.shape[1]`` into the fixed workspaces ``HT`` (q, C) and ``YT``
    (D, C), and each block is added to ``G`` (q, q) and ``B`` (q, D)
    (outputs) with dot products along the block (vectorised; the lower
    triangle of ``G`` is accumulated, entries above the diagonal of a 4-row
    sweep are overwritten by the final symmetrisation).  Memory is
    independent of ``M``; work is ``O(M q (q + D))``.  Returns ``|Y|^2``.
    """
    K = Z.shape[0] - 1
    q = Z.shape[2]
    D = z.shape[1]
    C = HT.shape[1]
    step = s_end / (M - 1) if M > 1 else 0.0
    for i in range(q):
        for k in range(q):
            G[i, k] = 0.0
        for d in range(D):
            B[i, d] = 0.0
    yy = 0.0
    for j0 in range(0, M, C):
        n = min(C, M - j0)
        for t in range(n):
            j = j0 + t
            s = j * step if j < M - 1 else s_end  # np.linspace(0, s_end, M)
            u = min(max(s * K, 0.0), float(K))
            kf = min(int(np.floor(u)), K - 1)
            kf = max(kf, 0)
            a = u - kf
            b = 1.0 - a
            kf1 = min(kf + 1, K)
            Za = Z[kf, 0]
            Zb = Z[kf1, 0]
            for i in range(q):
                HT[i, t] = b * Za[i] + a * Zb[i]
            f0 = b * powers[kf, 0, 0] + a * powers[kf1, 0, 0]
            f1 = b * powers[kf, 0, 1] + a * powers[kf1, 0, 1]
            for d in range(D):
                YT[d, t] = z[j, d] - (f0 * y0[d] + f1 * v0[d])
        i = 0
        while i + 4 <= q:  # four rows of H per sweep: each loaded column serves four dot products
            H0 = HT[i]
            H1 = HT[i + 1]
            H2 = HT[i + 2]
            H3 = HT[i + 3]
            for k in range(i + 4):
                Hk = HT[k]
                a0 = 0.0
                a1 = 0.0
                a2 = 0.0
                a3 = 0.0
                for t in range(n):
                    h = Hk[t]
                    a0 += H0[t] * h
                    a1 += H1[t] * h
                    a2 += H2[t] * h
                    a3 += H3[t] * h
                G[i, k] += a0
                G[i + 1, k] += a1
                G[i + 2, k] += a2
                G[i + 3, k] += a3
            for d in range(D):
                Yd = YT[d]
                a0 = 0.0
                a1 = 0.0
                a2 = 0.0
                a3 = 0.0
                for t in range(n):
                    h = Yd[t]
                    a0 += H0[t] * h
                    a1 += H1[t] * h
                    a2 += H2[t] * h
                    a3 += H3[t] * h
                B[i, d] += a0
                B[i + 1, d] += a1
                B[i + 2, d] += a2
                B[i + 3, d] += a3
            i += 4
        while i < q:
            Hi = HT[i]
            for k in range(i + 1):
                Hk = HT[k]
                acc = 0.0
                for t in range(n):
                    acc += Hi[t] * Hk[t]
                G[i, k] += acc
            for d in range(D):
                Yd = YT[d]
                acc = 0.0
                for t in range(n):
                    acc += Hi[t] * Yd[t]
                B[i, d] += acc
            i += 1
        for d in range(D):
            Yd = YT[d]
            acc = 0.0
            for t in range(n):
                acc += Yd[t] * Yd[t]
            yy += acc
    for i in range(q):
        for k in range(i):
            G[k, i] = G[i, k]
    return yy


@njit(cache=True, fastmath=_FM)
def _chol_inplace(A, n):
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
def _chol_solve_vec(L, n, b, out):
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
def _solve_R(R, b, p, out):
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
def _chol_update_R(R, u):
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
def _forward_rows(L, U, W):
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
def _syrk_sub(W, s2, K):
    """``K -= s2 W^T W`` on the lower triangle of ``K`` (all that :func:`_chol_inplace` reads) for ``W`` (q, r),
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
def _backward_rows(R, W, M):
    """``M = R^{-1} W`` for an upper factor ``R`` (q, q, rows) and ``W`` (q, r); row updates vectorised over r."""
    q, r = W.shape
    for a in range(q - 1, -1, -1):
        Ma = M[a]
        Wa = W[a]
        Ra = R[a]
        for c in range(r):
            Ma[c] = Wa[c]
        for b in range(a + 1, q):
            rab = Ra[b]
            Mb = M[b]
            for c in range(r):
                Ma[c] -= rab * Mb[c]
        inv = 1.0 / Ra[a]
        for c in range(r):
            Ma[c] *= inv


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


@njit(cache=True, fastmath=_FM)
def response_positions(Z, powers, s0, n, th, z0, at_s0, out, duration, t_out):
    """Mean positions of DoFs with parameters ``th`` (d, q) at ``linspace(s0, 1, n)``, from their state at ``s0``.

    The state at ``s0`` is that of the movement started at ``s = 0`` in ``z0``
    (2, d) (positions, velocities), or ``z0`` itself when ``at_s0``; the continuation uses the exact
    discretisation of :class:`interprim.dmp.LinearRollout` (same snapping and
    interpolation as :meth:`~interprim.dmp.LinearRollout.design`).
    ``out`` has shape (n, d); ``t_out`` (n,) receives ``(s - s0) * duration``.
    """
    Kn = Z.shape[0] - 1
    q = Z.shape[2]
    d = th.shape[0]
    h = np.empty(q)
    # -- state at s0 of the movement from rest at s = 0 (design(0, [s0]) rows 0 and 1)
    y0 = np.empty(d)
    v0 = np.empty(d)
    u = min(max(s0 * Kn, 0.0), float(Kn))
    kf = min(int(np.floor(u)), Kn - 1)
    kf = max(kf, 0)
    a = u - kf
    kf1 = min(kf + 1, Kn)
    for row in range(2):
        if at_s0:
            for dd in range(d):
                if row == 0:
                    y0[dd] = z0[0, dd]
                else:
                    v0[dd] = z0[1, dd]
            continue
        f0 = (1.0 - a) * powers[kf, row, 0] + a * powers[kf1, row, 0]
        f1 = (1.0 - a) * powers[kf, row, 1] + a * powers[kf1, row, 1]
        for j in range(q):
            # k0 = 0: P @ Z[0] = 0 because Z[0] = 0
            h[j] = (1.0 - a) * (Z[kf, row, j] - (powers[kf, row, 0] * Z[0, 0, j] + powers[kf, row, 1] * Z[0, 1, j])) \
                + a * (Z[kf1, row, j] - (powers[kf1, row, 0] * Z[0, 0, j] + powers[kf1, row, 1] * Z[0, 1, j]))
        for dd in range(d):
            acc = f0 * z0[0, dd] + f1 * z0[1, dd]
            for j in range(q):
                acc += h[j] * th[dd, j]
            if row == 0:
                y0[dd] = acc
            else:
                v0[dd] = acc
    # -- continuation from s0 (design(s0, linspace(s0, 1, n)))
    k0 = int(np.rint(s0 * Kn))
    k0 = min(max(k0, 0), Kn)
    pz = np.empty((2, q))  # rows of P @ Z[k0] for the two grid points, recomputed per output
    step = (1.0 - s0) / (n - 1) if n > 1 else 0.0
    for t in range(n):
        s = t * step + s0 if t < n - 1 else 1.0
        if n == 1:
            s = s0
        t_out[t] = (s - s0) * duration
        u = min(max(s * Kn, float(k0)), float(Kn))
        kf = min(int(np.floor(u)), Kn - 1)
        kf = max(kf, k0)
        a = u - kf
        kf1 = min(kf + 1, Kn)
        pa0 = powers[kf - k0, 0, 0]
        pa1 = powers[kf - k0, 0, 1]
        pb0 = powers[kf1 - k0, 0, 0]
        pb1 = powers[kf1 - k0, 0, 1]
        f0 = (1.0 - a) * pa0 + a * pb0
        f1 = (1.0 - a) * pa1 + a * pb1
        for j in range(q):
            pz[0, j] = pa0 * Z[k0, 0, j] + pa1 * Z[k0, 1, j]
            pz[1, j] = pb0 * Z[k0, 0, j] + pb1 * Z[k0, 1, j]
            h[j] = (1.0 - a) * (Z[kf, 0, j] - pz[0, j]) + a * (Z[kf1, 0, j] - pz[1, j])
        for dd in range(d):
            acc = f0 * y0[dd] + f1 * v0[dd]
            for j in range(q):
                acc += h[j] * th[dd, j]
            out[t, dd] = acc
    return out


@njit(cache=True, fastmath=_FM)
def forcing_targets_batch(Z, ds, alpha_y, beta_y, yd_work, F, yd0):
    """Forcing targets of Eq. 3 for ``n`` demonstrations of one length, ``Z`` ``(n, T, D)``, in one pass.

    ``F[k] = ydd - alpha_y (beta_y (g - y) - yd)`` with ``g = y[T-1]`` and
    second-order central differences in normalised time (``np.gradient``
    twice with ``edge_order=2``, as :func:`interprim.preprocessing.derivatives`
    without smoothing).  ``yd0[k]`` receives the start velocity.  ``yd_work``
    is a ``(T, D)`` workspace.  Reference: ``derivatives`` + :func:`interprim.dmp.forcing_targets`.
    """
    n, T, D = Z.shape
    two_ds = 2.0 * ds
    a0 = -1.5 / ds
    b0 = 2.0 / ds
    c0 = -0.5 / ds
    a1 = 0.5 / ds
    b1 = -2.0 / ds
    c1 = 1.5 / ds
    for k in range(n):
        y = Z[k]
        _gradient_uniform(y, T, ds, yd_work)
        Fk = F[k]
        g = y[T - 1]
        for d in range(D):
            yd0[k, d] = yd_work[0, d]
        for j in range(T):
            for d in range(D):
                if j == 0:
                    ydd = a0 * yd_work[0, d] + b0 * yd_work[1, d] + c0 * yd_work[2, d]
                elif j == T - 1:
                    ydd = a1 * yd_work[T - 3, d] + b1 * yd_work[T - 2, d] + c1 * yd_work[T - 1, d]
                else:
                    ydd = (yd_work[j + 1, d] - yd_work[j - 1, d]) / two_ds
                Fk[j, d] = ydd - alpha_y * (beta_y * (g[d] - y[j, d]) - yd_work[j, d])

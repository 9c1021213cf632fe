"""Compiled observation statistics (paper Eq. 3, 13-15): forcing values and ``X^T X``, ``X^T Y``, ``|Y|^2``.

Each kernel has a plain numpy reference elsewhere in the package that it is
tested against (``tests/compiled/test_fastpaths.py``):

* :func:`forcing_values_into` / :func:`design_stats` -- sufficient statistics ``G = X^T X``, ``B = X^T Y``
  and ``|Y|^2`` of the paper's forcing observation (Eq. 13-15) at ``M``
  observed frames spread uniformly over ``[0, s_end]``; reference:
  ``FittedPrimitive.observation_design`` (``np.gradient`` derivatives,
  :meth:`interprim.core.basis.Basis.phi_tilde`, :func:`interprim.core.dmp.forcing_values`).
* :func:`position_stats` -- the same statistics for the position observation
  (``observation="position"``: ``Y = z - free [y0; v0]``, ``X = H``, the rows of
  :meth:`interprim.core.dmp.LinearRollout.design` from ``s0 = 0``), accumulated in
  fixed-size blocks of frames; reference: ``FittedPrimitive.observation_design``.
* :func:`forcing_targets_batch` -- the forcing targets of Eq. 3 of a batch of equally long
  demonstrations (the fit); reference: :func:`interprim.core.dmp.forcing_targets`.

:class:`StatsWorkspace` holds the preallocated buffers the statistics kernels write into.
Nothing here allocates memory proportional to the number of observed frames.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from . import FASTMATH as _FM


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

    ``YT`` holds the targets transposed, ``(D, >= M)``.  Row ``j`` of ``X`` is ``[phi(x(s_j)), const]`` (Eq. 2 and 13,
    ``const = alpha_y beta_y``), computed as :meth:`interprim.core.basis.Basis.phi` (max-shifted exponentials) with the
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

    with ``Z`` (K+1, 2, q) and ``powers`` (K+1, 2, 2) of :class:`interprim.core.dmp.LinearRollout`.
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
def forcing_targets_batch(Z, ds, alpha_y, beta_y, yd_work, F, yd0):
    """Forcing targets of Eq. 3 for ``n`` demonstrations of one length, ``Z`` ``(n, T, D)``, in one pass.

    ``F[k] = ydd - alpha_y (beta_y (g - y) - yd)`` with ``g = y[T-1]`` and
    second-order central differences in normalised time (``np.gradient``
    twice with ``edge_order=2``, as :func:`interprim.core.preprocessing.derivatives`
    without smoothing).  ``yd0[k]`` receives the start velocity.  ``yd_work``
    is a ``(T, D)`` workspace.  Reference: ``derivatives`` + :func:`interprim.core.dmp.forcing_targets`.
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


# ---------------------------------------------------------------------------------------------------------------
# buffers of the statistics kernels

class StatsWorkspace:
    """Preallocated buffers for the observation statistics of up to ``cap`` frames (grown by doubling).

    ``observation="position"`` needs only fixed-size blocks (:func:`position_stats`);
    the per-frame buffers of the forcing observation are then allocated on first use.
    """

    BLOCK = 64  # frames per block of the position statistics

    def __init__(self, cap: int, n_obs: int, q: int, observation: str = "forcing"):
        self.n_obs = int(n_obs)
        self.q = int(q)
        self.G = np.empty((self.q, self.q))
        self.B = np.empty((self.q, self.n_obs))
        self.HT = np.empty((self.q, self.BLOCK))
        self.YTb = np.empty((self.n_obs, self.BLOCK))
        self.cap = 0
        if observation == "forcing":
            self._alloc(max(int(cap), 3))

    def _alloc(self, cap):
        self.cap = cap
        self.yd = np.empty((cap, self.n_obs))
        self.ydd = np.empty((cap, self.n_obs))
        self.YT = np.empty((self.n_obs, cap))
        self.XT = np.empty((self.q, cap))
        self.work = np.empty((4, cap))
        self.ibuf = np.empty(cap, dtype=np.int64)

    def forcing_stats(self, z, M, s_end, model):
        """``(G, B, |Y|^2)`` of the forcing observation (Eq. 13-15) of ``z[:M]`` over ``[0, s_end]``.

        ``G`` and ``B`` are this workspace's buffers (overwritten by the next call).
        """
        if M > self.cap:
            self._alloc(max(M, 2 * self.cap))
        basis = model.basis_
        const = forcing_values_into(z, M, float(s_end), float(model.alpha_y), float(model.beta_y_),
                                    self.yd, self.ydd, self.YT)
        yy = design_stats(self.YT, M, float(s_end), basis.centers, basis.widths, float(basis.alpha_x), const,
                          self.XT, self.G, self.B, self.work, self.ibuf)
        return self.G, self.B, float(yy)

    def position_stats(self, z, M, s_end, y0, v0, rollout):
        """``(G, B, |Y|^2)`` of the position observation of ``z[:M]`` over ``[0, s_end]`` from start ``[y0; v0]``.

        Reference: ``FittedPrimitive.observation_design`` (``LinearRollout.design(0, s)``).
        ``G`` and ``B`` are this workspace's buffers (overwritten by the next call).
        """
        yy = position_stats(z, M, float(s_end), y0, v0, rollout.Z, rollout.powers, self.G, self.B,
                            self.HT, self.YTb)
        return self.G, self.B, float(yy)

"""Compiled training rows of the prefix coupling (:meth:`interprim.models.coupling.CouplingModel._rows`).

:func:`prefix_rows_into` reads every demonstration at ``n_in`` equally spaced fractional frames of its first
``s (T_j - 1)`` frames, for each phase ``s`` of a set, and scales the points as the coupling's features: the rows
of Eq. 17-18's observation with the prefix resampled on ``[0, s]``.  Its reference,
:func:`interprim.models.coupling.prefix_rows_np`, does the same with numpy's broadcasting; the kernel performs the
same scalar operations in the same order, compiled without fastmath (no fused multiply-add), so the two agree bit
for bit.  It allocates nothing: a coupling stream rebuilds these rows for every frame.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, types

_F1 = types.Array(types.float64, 1, "C", readonly=True)
_I1 = types.Array(types.intp, 1, "C", readonly=True)
#: one signature for every call (writable inputs convert to the read-only types, so that a cached, read-only grid
#: compiles nothing new)
_SIGNATURE = types.void(types.Array(types.float64, 3, "C", readonly=True), _I1, _I1, _F1, _F1, _F1, types.boolean,
                        types.Array(types.float64, 2, "C"))


@njit(_SIGNATURE, cache=True, fastmath=False)
def prefix_rows_into(frames, lengths, idx, s_true, lin, scale, displacement, out):
    """``out[(j, r), (k, d)]``: demonstration ``idx[j]`` (zero-padded ``frames`` ``(n, T_max, Do)``, true lengths
    ``lengths``) at fractional frame ``min(max(s_true[r] (T - 1) lin[k], 0), T - 1)``, linearly interpolated,
    divided by ``scale[d]`` (minus its first point's with ``displacement``); ``out`` ``(len(idx) len(s_true),
    len(lin) Do)``, rows ordered by demonstration, then phase."""
    Do = frames.shape[2]
    n_in = lin.shape[0]
    R = s_true.shape[0]
    for jj in range(idx.shape[0]):
        j = idx[jj]
        T = lengths[j]
        stop_hi = T - 2 if T > 1 else 0
        for r in range(R):
            stop = s_true[r] * (T - 1)
            row = jj * R + r
            for k in range(n_in):
                pos = min(max(stop * lin[k], 0.0), T - 1.0)
                i0 = min(int(math.floor(pos)), stop_hi)
                w = pos - i0
                i1 = min(i0 + 1, T - 1)
                for d in range(Do):
                    v = (frames[j, i0, d] * (1.0 - w) + frames[j, i1, d] * w) / scale[d]
                    out[row, k * Do + d] = v
            if displacement:
                for k in range(n_in - 1, -1, -1):
                    for d in range(Do):
                        out[row, k * Do + d] = out[row, k * Do + d] - out[row, d]


# ------------------------------------------------------------------------------------------ centring the rows

@njit(cache=True, fastmath=False, inline="always")
def _term(v, square):
    """``v * v`` (``square``) or ``v``: one term of the sums below."""
    return v * v if square else v


@njit(cache=True, fastmath=False)
def _block_sq(a, lo, n, square):
    """``numpy.add.reduce(a[lo:lo + n] ** 2)`` (``square``; else of ``a[lo:lo + n]`` itself) for ``n <= 128`` in
    numpy's order (the leaves of :func:`_pairwise_sq`): sequential below 8 elements, else eight interleaved partial
    sums combined pairwise, then the remainder."""
    if n < 8:
        res = 0.0
        for i in range(n):
            res += _term(a[lo + i], square)
        return res
    r0, r1, r2, r3 = (_term(a[lo], square), _term(a[lo + 1], square), _term(a[lo + 2], square),
                      _term(a[lo + 3], square))
    r4, r5, r6, r7 = (_term(a[lo + 4], square), _term(a[lo + 5], square), _term(a[lo + 6], square),
                      _term(a[lo + 7], square))
    m = n - n % 8
    i = 8
    while i < m:
        b = lo + i
        r0 += _term(a[b], square)
        r1 += _term(a[b + 1], square)
        r2 += _term(a[b + 2], square)
        r3 += _term(a[b + 3], square)
        r4 += _term(a[b + 4], square)
        r5 += _term(a[b + 5], square)
        r6 += _term(a[b + 6], square)
        r7 += _term(a[b + 7], square)
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += _term(a[lo + i], square)
        i += 1
    return res


@njit(cache=True, fastmath=False)
def _pairwise_sq(a, lo, n, square=True):
    """``numpy.add.reduce(a[lo:lo + n] ** 2)`` (``square``; else of ``a[lo:lo + n]``) of a contiguous float64
    ``a`` in numpy's own order: its pairwise summation (``pairwise_sum`` of numpy's ``loops_utils.h``: blocks of
    at most 128 elements summed by :func:`_block_sq`, a larger range split in two at a multiple of eight below its
    half and the halves' sums added).  The recursion is unrolled on a stack of tasks (numba's cache cannot load a
    recursive function): a range is replaced by the addition of its halves, evaluated after them."""
    if n <= 128:
        return _block_sq(a, lo, n, square)
    task_lo = np.empty(256, dtype=np.int64)  # a range's start, or -1 for "add the last two values"
    task_n = np.empty(256, dtype=np.int64)
    vals = np.empty(128)
    nt = 1
    task_lo[0] = lo
    task_n[0] = n
    nv = 0
    while nt > 0:
        nt -= 1
        t_lo, t_n = task_lo[nt], task_n[nt]
        if t_lo < 0:  # left + right (the right half's sum is on top)
            vals[nv - 2] = vals[nv - 2] + vals[nv - 1]
            nv -= 1
        elif t_n <= 128:
            vals[nv] = _block_sq(a, t_lo, t_n, square)
            nv += 1
        else:
            n2 = t_n // 2
            n2 -= n2 % 8
            task_lo[nt], task_n[nt] = -1, 0  # after both halves
            task_lo[nt + 1], task_n[nt + 1] = t_lo + n2, t_n - n2  # the right half, evaluated second
            task_lo[nt + 2], task_n[nt + 2] = t_lo, n2  # the left half, first
            nt += 3
    return vals[0]


_F2 = types.Array(types.float64, 2, "C", readonly=True)
_O2 = types.Array(types.float64, 2, "C")
_O1 = types.Array(types.float64, 1, "C")


@njit(types.float64(_F2, _F2, _O2, _O2, _O1, _O1), cache=True, fastmath=False)
def centre_rows_into(X, x, Xc, xc, nrm, qnrm):
    """The rows ``X`` (R, p) and queries ``x`` (Q, p) centred by the rows' mean into ``Xc`` and ``xc``, with the
    squared norms a conditioner reads: each centred row's into ``nrm`` (R,) and each query's into ``qnrm`` (Q,)
    (skipped when they are empty); returns ``sum(Xc ** 2)``.  The numbers of
    :func:`interprim.models.conditioners.centre_rows_np` bit for bit: the column sums run over the rows in
    order (numpy's axis-0 reduction; of one column, its pairwise sum), then divided by ``R`` (``numpy.mean``);
    the sums of squares are numpy's pairwise sums (:func:`_pairwise_sq`); no fastmath (no fused multiply-add).
    Called once per streamed frame of :class:`~interprim.models.learned.LearnedInteraction` (Eq. 18's smoother
    on rows that move with the phase)."""
    R, p = X.shape
    Q = x.shape[0]
    mu = np.zeros(p)
    if p == 1:  # numpy's axis-0 reduction of one contiguous column: its pairwise sum
        mu[0] = 0.0 + _pairwise_sq(X.reshape(R), 0, R, False)
    else:  # of several columns: each summed over the rows in order
        for i in range(R):
            for j in range(p):
                mu[j] += X[i, j]
    for j in range(p):
        mu[j] = mu[j] / R
    for i in range(R):
        for j in range(p):
            Xc[i, j] = X[i, j] - mu[j]
    for i in range(Q):
        for j in range(p):
            xc[i, j] = x[i, j] - mu[j]
    flat = Xc.reshape(R * p)
    if nrm.shape[0] == R:
        for i in range(R):
            nrm[i] = 0.0 + _pairwise_sq(flat, i * p, p)
    if qnrm.shape[0] == Q:
        qflat = xc.reshape(Q * p)
        for i in range(Q):
            qnrm[i] = 0.0 + _pairwise_sq(qflat, i * p, p)
    return 0.0 + _pairwise_sq(flat, 0, R * p)



_F3 = types.Array(types.float64, 3, "C", readonly=True)
_F1 = types.Array(types.float64, 1, "C", readonly=True)
_I1 = types.Array(types.intp, 1, "C", readonly=True)


@njit(types.void(_F3, _F1, _F2, _I1, _F1, types.intp, types.intp, types.float64, _O2), cache=True, fastmath=False)
def cv_loss_into(GY, ybar, truth, ctrl, w, nj, D, n_mean, out):
    """The held-out losses of a batch of conditioners on one fold and phase of the coupling's cross-validation into
    ``out`` (C, nh): candidate ``c``'s mean is ``ybar + GY[c]`` (``GY[c]`` (nh nj, n_out D): its row weights summed
    per demonstration times the demonstrations' centred targets, Eq. 18 as a linear smoother), held-out case ``i``'s
    loss the weighted squared error of its controlled columns ``ctrl`` (weights ``w``) against ``truth[i]``, summed
    over the columns and averaged over its ``nj`` jittered queries and the ``n_out`` output points (``n_mean`` of
    them).  The numbers of :func:`interprim.models.coupling.cv_loss_np` bit for bit: each error ``(ybar + GY) -
    truth`` squared then weighted, the sums numpy's over the columns (pairwise, :func:`_pairwise_sq`, for consecutive
    columns; in turn otherwise), then over the jitter and the output points (pairwise); no fastmath (no fused
    multiply-add)."""
    C, Q, F = GY.shape
    nh = truth.shape[0]
    n_out = F // D
    nc = ctrl.shape[0]
    terms = np.empty(nc)
    rows = np.empty(nj * n_out)
    # numpy's sum over the columns: pairwise over a run of consecutive columns (the reference's slice, a view whose
    # difference with the truth is laid out with the columns innermost), in turn over other columns (a list: numpy's
    # indexed copy has the columns outermost, and its reduction adds them one after the other); the same below 8
    run = True
    for k in range(1, nc):
        run = run and ctrl[k] == ctrl[k - 1] + 1
    for c in range(C):
        for i in range(nh):
            for j in range(nj):
                g = GY[c, i * nj + j]
                for t in range(n_out):
                    b = t * D
                    acc = 0.0
                    for k in range(nc):
                        f = b + ctrl[k]
                        e = (ybar[f] + g[f]) - truth[i, f]
                        terms[k] = e * e * w[k]
                        acc += terms[k]
                    rows[j * n_out + t] = 0.0 + _pairwise_sq(terms, 0, nc, False) if run else acc
            out[c, i] = (0.0 + _pairwise_sq(rows, 0, nj * n_out, False)) / n_mean


def warm_up() -> None:
    """Compile (or load from the cache) :func:`centre_rows_into` and :func:`cv_loss_into` with tiny inputs of the
    real types."""
    X = np.arange(6.0).reshape(3, 2)
    centre_rows_into(X, X[:1].copy(), np.empty((3, 2)), np.empty((1, 2)), np.empty(3), np.empty(1))
    cv_loss_into(np.zeros((1, 2, 4)), np.zeros(4), np.zeros((1, 4)), np.array([1], dtype=np.intp), np.ones(1), 2, 2,
                 4.0, np.empty((1, 1)))

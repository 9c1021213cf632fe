"""Compiled kernels of the open-end DTW (paper Eq. 5-8); see :mod:`interprim.phase.dtw` for the maths.

Kept apart from :mod:`interprim.phase.dtw` so that importing the package and the
first prediction do not need numba (see :mod:`interprim.core._compiled.loader`).
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, fastmath=False)
def _local_cost_column(u, vm, out):
    N, D = u.shape
    for n in range(N):
        acc = 0.0
        for d in range(D):
            diff = u[n, d] - vm[d]
            acc += diff * diff
        out[n] = acc


@njit(cache=True, fastmath=False)
def _first_column(u, v0, col):
    """Eq. 6: D(n, 1) = sum_{k<=n} c(u_k, v_1)."""
    _local_cost_column(u, v0, col)
    for n in range(1, col.shape[0]):
        col[n] += col[n - 1]


@njit(cache=True, fastmath=False)
def _next_column(u, vm, prev, col):
    """One column of Eq. 5 and 7 from the previous column (in place into ``col``)."""
    N, D = u.shape
    # row n = 0: Eq. 5, D(1, m) = D(1, m-1) + c(u_1, v_m)
    acc = 0.0
    for d in range(D):
        diff = u[0, d] - vm[d]
        acc += diff * diff
    col[0] = prev[0] + acc
    for n in range(1, N):
        acc = 0.0
        for d in range(D):
            diff = u[n, d] - vm[d]
            acc += diff * diff
        best = prev[n - 1]
        if prev[n] < best:
            best = prev[n]
        if col[n - 1] < best:
            best = col[n - 1]
        col[n] = best + acc


@njit(cache=True, fastmath=False)
def _accumulate(u, v):
    N = u.shape[0]
    M = v.shape[0]
    Dm = np.empty((M, N))  # stored column-major in the query index for cache-friendly columns
    _first_column(u, v[0], Dm[0])
    for m in range(1, M):
        _next_column(u, v[m], Dm[m - 1], Dm[m])
    return Dm


@njit(cache=True, fastmath=False)
def _argmin_first(col):
    best = 0
    for n in range(1, col.shape[0]):
        if col[n] < col[best]:
            best = n
    return best


@njit(cache=True, fastmath=False)
def _cost_column_t(uT, vm, out):
    """``out[n] = c(u_n, v_m)`` from the transposed reference ``uT`` (D, N).

    Same summation order over ``d`` as :func:`_local_cost_column` (bitwise equal),
    but the loop over ``n`` is innermost and contiguous, so it vectorises.
    """
    D, N = uT.shape
    for n in range(N):
        out[n] = 0.0
    for d in range(D):
        vd = vm[d]
        for n in range(N):
            diff = uT[d, n] - vd
            out[n] += diff * diff


@njit(cache=True, fastmath=False)
def _open_end_strips(uT, v, a, b, cb):
    """n* and D(n*, M) (Eq. 5-8) with two columns of memory, four query frames per sweep.

    Four consecutive columns of Eq. 7 are advanced together: at row ``n`` the
    cells ``(n, m), (n, m+1), (n, m+2), (n, m+3)`` are computed from the
    previous row of each.  The four dependency chains overlap in the CPU, so
    the sweep is bounded by throughput, not by the latency of the ``min + add``
    chain.  Every cell is computed with exactly the operations of Eq. 7, so the
    result is bitwise equal to the column-by-column recursion.
    """
    D, N = uT.shape
    M = v.shape[0]
    _cost_column_t(uT, v[0], a)
    for n in range(1, N):  # Eq. 6
        a[n] += a[n - 1]
    m = 1
    while m + 4 <= M:
        for k in range(4):
            _cost_column_t(uT, v[m + k], cb[k])
        c0 = cb[0]
        c1 = cb[1]
        c2 = cb[2]
        c3 = cb[3]
        # row 0: Eq. 5
        A = a[0] + c0[0]
        B = A + c1[0]
        C = B + c2[0]
        E = C + c3[0]
        b[0] = E
        for n in range(1, N):
            pa0 = a[n - 1]
            pa1 = a[n]
            x = pa0 if pa0 <= pa1 else pa1
            x = x if x <= A else A
            An = x + c0[n]
            x = A if A <= An else An
            x = x if x <= B else B
            Bn = x + c1[n]
            x = B if B <= Bn else Bn
            x = x if x <= C else C
            Cn = x + c2[n]
            x = C if C <= Cn else Cn
            x = x if x <= E else E
            En = x + c3[n]
            b[n] = En
            A = An
            B = Bn
            C = Cn
            E = En
        a, b = b, a
        m += 4
    while m < M:
        _next_column_cost(a, cb[0], b, uT, v[m])
        a, b = b, a
        m += 1
    n = _argmin_first(a)
    return n, a[n]


@njit(cache=True, fastmath=False)
def _next_column_cost(prev, cost, col, uT, vm):
    """One column of Eq. 5 and 7 (same result as :func:`_next_column`) via a vectorised cost column."""
    _cost_column_t(uT, vm, cost)
    N = prev.shape[0]
    col[0] = prev[0] + cost[0]
    for n in range(1, N):
        best = prev[n - 1]
        if prev[n] < best:
            best = prev[n]
        if col[n - 1] < best:
            best = col[n - 1]
        col[n] = best + cost[n]


@njit(cache=True, fastmath=False)
def _incremental_step(uT, vm, prev, col, cost, first):
    """Add one query frame: new last column into ``col`` (``prev`` is the old one); returns n*.

    Returns -1 without touching any buffer if the frame has a NaN or inf.
    """
    for d in range(vm.shape[0]):
        if not np.isfinite(vm[d]):
            return -1
    N = col.shape[0]
    if first:
        _cost_column_t(uT, vm, col)
        for n in range(1, N):
            col[n] += col[n - 1]
    else:
        _next_column_cost(prev, cost, col, uT, vm)
    return _argmin_first(col)


@njit(cache=True, fastmath=False)
def _incremental_block(uT, block, a, b, cost, n_frames):
    """Add the query frames ``block`` ``(k, D)`` one after the other, each by :func:`_incremental_step` (the same
    numbers): the two column buffers ``a`` (the last column after the frames seen so far, ``n_frames`` of them)
    and ``b`` swap roles at every frame after the first, as the per-frame calls of
    :meth:`interprim.phase.dtw.IncrementalDTW.extend` swap them.  Returns ``(n*, frames added, swapped)``:
    ``swapped`` says whether the roles are now swapped (the last column in ``b``, ``a`` the previous one); a frame
    with a NaN or inf stops the block at it, untouched (``n*`` -1, the roles as the per-frame calls leave them)."""
    prev, col = b, a
    swapped = False
    n = -1
    for i in range(block.shape[0]):
        first = n_frames + i == 0
        if not first:
            prev, col = col, prev
            swapped = not swapped
        n = _incremental_step(uT, block[i], prev, col, cost, first)
        if n < 0:
            return -1, i, swapped
    return n, block.shape[0], swapped


@njit(cache=True, fastmath=False)
def _incremental_set(uT, starts, lengths, block, A, B, cost, swapped, n_frames, n_star, last_cost):
    """:func:`_incremental_block` of the query frames ``block`` ``(k, D)`` against every reference ``j`` of a set
    (:class:`interprim.phase.dtw.IncrementalDTWSet`), in one call.  The set is stored flat: reference ``j`` (``N_j =
    lengths[j]`` frames) is ``uT[D s_j : D (s_j + N_j)]`` read as its transposed ``(D, N_j)`` array, its two
    column buffers ``A[s_j : s_j + N_j]`` and ``B[...]`` (the last column in ``B`` when ``swapped[j]``, updated
    here) and its workspace ``cost[...]``, with ``s_j = starts[j]``; ``n_frames`` frames were seen before.  Each
    reference's columns are those of its own :func:`_incremental_step` calls on contiguous arrays (the same
    operations on the same numbers); writes ``n_star[j]`` and ``last_cost[j] = D(n*, M)``.  Returns 0, or -1 at a
    frame with a NaN or inf (the caller passes checked frames)."""
    D = block.shape[1]
    for j in range(lengths.shape[0]):
        N = lengths[j]
        s = starts[j]
        u = uT[D * s: D * (s + N)].reshape((D, N))
        a = A[s: s + N]
        b = B[s: s + N]
        c = cost[s: s + N]
        if swapped[j]:
            prev, col = a, b
        else:
            prev, col = b, a
        n = -1
        for i in range(block.shape[0]):
            if n_frames + i > 0:
                prev, col = col, prev
                swapped[j] = not swapped[j]
            n = _incremental_step(u, block[i], prev, col, c, n_frames + i == 0)
            if n < 0:
                return -1
        n_star[j] = n
        last_cost[j] = col[n]
    return 0


@njit(cache=True, fastmath=False)
def _backtrack(Dm, n_end):
    M = Dm.shape[0]
    path = np.empty((M + n_end + 1, 2), dtype=np.int64)
    n, m, k = n_end, M - 1, 0
    path[0, 0] = n
    path[0, 1] = m
    while n > 0 or m > 0:
        if n == 0:
            m -= 1
        elif m == 0:
            n -= 1
        else:
            diag = Dm[m - 1, n - 1]
            left = Dm[m - 1, n]  # D(n, m-1)
            up = Dm[m, n - 1]  # D(n-1, m)
            if diag <= left and diag <= up:
                n -= 1
                m -= 1
            elif left <= up:
                m -= 1
            else:
                n -= 1
        k += 1
        path[k, 0] = n
        path[k, 1] = m
    return path[: k + 1][::-1].copy()


def warm_up(u, v) -> None:
    """Compile (or load from the cache) every kernel of this module with tiny inputs ``u (N, D)``, ``v (M, D)``
    of the real types (called by :func:`interprim.core._compiled.loader.warmup`)."""
    uT = np.ascontiguousarray(u.T)
    N = u.shape[0]
    _open_end_strips(uT, v, np.empty(N), np.empty(N), np.empty((4, N)))
    _incremental_step(uT, v[0], np.zeros(N), np.empty(N), np.empty(N), True)
    _incremental_block(uT, v, np.zeros(N), np.empty(N), np.empty(N), 0)
    _incremental_set(uT.ravel(), np.zeros(1, dtype=np.int64), np.array([N], dtype=np.int64), v, np.zeros(N),
                     np.zeros(N), np.empty(N), np.zeros(1, dtype=np.bool_), 0, np.empty(1, dtype=np.int64), np.empty(1))
    _backtrack(_accumulate(u, v), 2)

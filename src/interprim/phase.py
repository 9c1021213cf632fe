"""Phase estimation by open-end dynamic time warping (paper Sec. III-B, Eq. 5-9).

The reference ``u`` (``N`` frames) is the observed agent's movement in the
demonstrations; the query ``v`` (``M`` frames) is the partial movement seen so
far.  With the local cost ``c(u_n, v_m) = ||u_n - v_m||^2`` the accumulated
cost is (1-based indices as in the paper)::

    D(1, m) = sum_{k<=m} c(u_1, v_k)                                   (Eq. 5)
    D(n, 1) = sum_{k<=n} c(u_k, v_1)                                   (Eq. 6)
    D(n, m) = min{D(n-1, m-1), D(n, m-1), D(n-1, m)} + c(u_n, v_m)     (Eq. 7)

and the open end is ``n* = argmin_n D(n, M)`` (Eq. 8): the reference frame
that best matches the last observed frame.  ``n*/N`` is the fraction of the
movement seen and ``x = exp(-alpha_x (n*/N) tau)`` the phase (Eq. 9).

Code uses 0-based indices: ``n_star`` in ``0..N-1``; the paper's fraction
``n*/N`` is ``(n_star + 1) / N``.  Ties in Eq. 8 go to the smallest ``n``.

The recursion is compiled with numba (cached on disk).  :class:`IncrementalDTW`
adds one query frame at a time in ``O(N D)`` by computing one new column of
``D`` and gives exactly the batch result.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from ._validation import as_2d_finite, as_frame

__all__ = ["DTWResult", "open_end_dtw", "accumulated_cost", "IncrementalDTW", "phase_from_index"]


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
    """Add one query frame: new last column into ``col`` (``prev`` is the old one); returns n*."""
    N = col.shape[0]
    if first:
        _cost_column_t(uT, vm, col)
        for n in range(1, N):
            col[n] += col[n - 1]
    else:
        _next_column_cost(prev, cost, col, uT, vm)
    return _argmin_first(col)


def _open_end(u, v):
    """n* and D(n*, M) without storing the matrix (two columns of memory)."""
    N = u.shape[0]
    uT = np.ascontiguousarray(u.T)
    a = np.empty(N)
    b = np.empty(N)
    cb = np.empty((4, N))
    n, c = _open_end_strips(uT, v, a, b, cb)
    return int(n), float(c)


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


@dataclass(frozen=True)
class DTWResult:
    """Result of :func:`open_end_dtw`.

    Attributes
    ----------
    n_star : int
        0-based index of the reference frame matched by the last query frame (Eq. 8).
    cost : float
        ``D(n*, M)``, the accumulated squared-distance cost of the best alignment.
    fraction : float
        The paper's ``n*/N`` (1-based ``n*``): fraction of the reference covered, in (0, 1].
    path : ndarray of shape (L, 2) or None
        The alignment ``pi`` as (reference index, query index) pairs from (0, 0) to (n*, M-1).
    """

    n_star: int
    cost: float
    fraction: float
    path: np.ndarray | None = None


def _check_pair(reference, query):
    u = as_2d_finite(reference, "reference", min_rows=1)
    v = as_2d_finite(query, "query", n_cols=u.shape[1], min_rows=1)
    return u, v


def accumulated_cost(reference, query) -> np.ndarray:
    """The full accumulated cost matrix ``D`` of Eq. 5-7, shape ``(N, M)``."""
    u, v = _check_pair(reference, query)
    return _accumulate(u, v).T.copy()


def open_end_dtw(reference, query, return_path: bool = True) -> DTWResult:
    """Open-end DTW of a partial ``query`` against a ``reference`` (Eq. 5-8).

    Parameters
    ----------
    reference : array_like, shape (N, D)
        Reference movement of the observed agent.
    query : array_like, shape (M, D)
        The partial observation.
    return_path : bool
        Also backtrack the alignment (needs the full ``N x M`` matrix);
        otherwise only two columns of memory are used.
    """
    u, v = _check_pair(reference, query)
    if return_path:
        Dm = _accumulate(u, v)
        n = int(_argmin_first(Dm[-1]))
        return DTWResult(n, float(Dm[-1, n]), (n + 1) / u.shape[0], _backtrack(Dm, n))
    n, c = _open_end(u, v)
    return DTWResult(int(n), float(c), (int(n) + 1) / u.shape[0], None)


def phase_from_index(n_star: int, N: int, alpha_x: float, tau: float = 1.0) -> float:
    """Eq. 9: ``x = exp(-alpha_x (n*/N) tau)`` with the paper's 1-based ``n*`` (``n_star + 1``)."""
    return float(np.exp(-alpha_x * ((n_star + 1) / N) * tau))


class IncrementalDTW:
    """Open-end DTW that takes one query frame at a time (``O(N D)`` per frame).

    After ``update`` has seen frames ``v_1..v_M`` its ``n_star`` and ``cost``
    equal those of ``open_end_dtw(reference, v[:M])`` exactly.  Memory is two
    columns of length ``N``; nothing grows with the number of frames.

    Parameters
    ----------
    reference : array_like, shape (N, D)
    """

    def __init__(self, reference):
        self.reference = as_2d_finite(reference, "reference", min_rows=1)
        N = self.reference.shape[0]
        self._uT = np.ascontiguousarray(self.reference.T)
        self._col = np.empty(N)
        self._prev = np.empty(N)
        self._cost = np.empty(N)
        self.n_frames = 0
        self.n_star = -1
        self.cost = np.inf

    def reset(self):
        self.n_frames = 0
        self.n_star = -1
        self.cost = np.inf

    def update(self, frame, check: bool = True):
        """Add one query frame; returns ``(n_star, cost)``."""
        v = as_frame(frame, "frame", self.reference.shape[1]) if check else frame
        first = self.n_frames == 0
        if not first:
            self._prev, self._col = self._col, self._prev
        n = _incremental_step(self._uT, v, self._prev, self._col, self._cost, first)
        self.n_frames += 1
        self.n_star = n
        self.cost = float(self._col[n])
        return n, self.cost

    @property
    def column(self) -> np.ndarray:
        """The current last column ``D(., M)`` (read-only view)."""
        c = self._col.view()
        c.flags.writeable = False
        return c

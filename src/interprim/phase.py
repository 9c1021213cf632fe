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
def _open_end(u, v):
    """n* and D(n*, M) without storing the matrix (two columns of memory)."""
    N = u.shape[0]
    a = np.empty(N)
    b = np.empty(N)
    _first_column(u, v[0], a)
    for m in range(1, v.shape[0]):
        _next_column(u, v[m], a, b)
        a, b = b, a
    n = _argmin_first(a)
    return n, a[n]


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
        self._col = np.empty(N)
        self._prev = np.empty(N)
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
        if self.n_frames == 0:
            _first_column(self.reference, v, self._col)
        else:
            self._prev, self._col = self._col, self._prev
            _next_column(self.reference, v, self._prev, self._col)
        self.n_frames += 1
        n = int(_argmin_first(self._col))
        self.n_star = n
        self.cost = float(self._col[n])
        return n, self.cost

    @property
    def column(self) -> np.ndarray:
        """The current last column ``D(., M)`` (read-only view)."""
        c = self._col.view()
        c.flags.writeable = False
        return c

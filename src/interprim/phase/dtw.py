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

The recursion is compiled with numba (cached on disk; :mod:`interprim.core._compiled.dtw`),
with bitwise-equal numpy equivalents used until the kernels are loaded.  :class:`IncrementalDTW`
adds one query frame at a time in ``O(N D)`` by computing one new column of
``D`` and gives exactly the batch result.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core._compiled import registry as kernels
from ..core.validation import as_2d_finite, as_frame

__all__ = ["DTWResult", "open_end_dtw", "accumulated_cost", "IncrementalDTW", "IncrementalDTWSet",
           "phase_from_index"]


# ----------------------------------------------------------------------------- numpy equivalents
# Used until the compiled kernels (interprim.core._compiled.dtw) are loaded (see interprim.core._compiled.loader), e.g.
# for the first prediction of a fresh process.  They perform exactly the operations of the compiled recursion
# (the same cost summation order, min, then one addition per cell), so results are bitwise equal.


def _cost_matrix_np(u, v):
    """``C[n, m] = sum_d (u[n, d] - v[m, d])^2`` summed over ``d`` in order, shape (N, M)."""
    C = np.zeros((u.shape[0], v.shape[0]))
    for d in range(u.shape[1]):
        diff = u[:, d, None] - v[None, :, d]
        C += diff * diff
    return C


def accumulate_np(u, v):
    """Eq. 5-7 by anti-diagonals (cells of one anti-diagonal are independent); returns (M, N) like the kernel."""
    C = _cost_matrix_np(u, v)
    N, M = C.shape
    Dm = np.empty((N, M))
    Dm[:, 0] = np.cumsum(C[:, 0]) if N else Dm[:, 0]
    # Eq. 6 by sequential additions (np.cumsum adds in order)
    Dm[0, :] = np.cumsum(C[0, :])
    for k in range(2, N + M - 1):
        n_lo = max(1, k - (M - 1))
        n_hi = min(N - 1, k - 1)
        if n_lo > n_hi:
            continue
        n = np.arange(n_lo, n_hi + 1)
        m = k - n
        best = np.minimum(np.minimum(Dm[n - 1, m - 1], Dm[n, m - 1]), Dm[n - 1, m])
        Dm[n, m] = best + C[n, m]
    return np.ascontiguousarray(Dm.T)


def _argmin_first_np(col):
    return int(np.argmin(col))  # numpy's argmin returns the first minimum


def _backtrack_np(Dm, n_end):
    M = Dm.shape[0]
    path = [(n_end, M - 1)]
    n, m = n_end, M - 1
    while n > 0 or m > 0:
        if n == 0:
            m -= 1
        elif m == 0:
            n -= 1
        else:
            diag = Dm[m - 1, n - 1]
            left = Dm[m - 1, n]
            up = Dm[m, n - 1]
            if diag <= left and diag <= up:
                n -= 1
                m -= 1
            elif left <= up:
                m -= 1
            else:
                n -= 1
        path.append((n, m))
    return np.array(path[::-1], dtype=np.int64)


def _accumulate(u, v):
    return kernels.implementation("dtw.accumulate")(u, v)


def _open_end(u, v):
    """n* and D(n*, M) without storing the matrix (two columns of memory when compiled)."""
    k = kernels.kernel("dtw.open_end")
    if k is not None:
        N = u.shape[0]
        uT = np.ascontiguousarray(u.T)
        n, c = k(uT, v, np.empty(N), np.empty(N), np.empty((4, N)))
        return int(n), float(c)
    Dm = accumulate_np(u, v)
    n = _argmin_first_np(Dm[-1])
    return n, float(Dm[-1, n])


def _argmin_first(col):
    return _argmin_first_np(col)


def _backtrack(Dm, n_end):
    return kernels.implementation("dtw.backtrack")(Dm, n_end)


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
        """Forget all query frames (start a new query against the same reference)."""
        self.n_frames = 0
        self.n_star = -1
        self.cost = np.inf

    def update(self, frame, check: bool = True):
        """Add one query frame; returns ``(n_star, cost)``."""
        D = self.reference.shape[1]
        step = kernels.kernel("dtw.incremental_step")
        fast_in = (step is not None and type(frame) is np.ndarray and frame.dtype == np.float64
                   and frame.shape == (D,))
        v = frame if (fast_in or not check) else as_frame(frame, "frame", D)
        first = self.n_frames == 0
        if step is not None:
            prev, col = (self._prev, self._col) if first else (self._col, self._prev)
            n = step(self._uT, v, prev, col, self._cost, first)
            if n < 0:  # non-finite frame: the kernel touched nothing; raise the usual message
                as_frame(frame, "frame", D)
                raise ValueError("frame contains NaN or inf")
            self._prev, self._col = prev, col
        else:
            if not first:
                self._prev, self._col = self._col, self._prev
            n = self._step_np(v, first)
        self.n_frames += 1
        self.n_star = n
        self.cost = float(self._col[n])
        return n, self.cost

    def extend(self, block) -> tuple[int, float]:
        """Add the checked, finite query frames ``block`` ``(k, D)`` (float64, C order) one after the other, as
        ``update(frame, check=False)`` of each would, with one look-up of the compiled kernel for the block;
        returns ``(n_star, cost)`` after the last."""
        steps = kernels.kernel("dtw.incremental_block")
        if steps is None:
            for f in block:
                self.update(f, check=False)
            return self.n_star, self.cost
        if block.shape[0] == 0:
            return self.n_star, self.cost
        # every frame by the per-frame kernel's step, inside one compiled loop (no Python call per frame)
        n, done, swapped = steps(self._uT, block, self._col, self._prev, self._cost, self.n_frames)
        if swapped:
            self._prev, self._col = self._col, self._prev
        self.n_frames += int(done)
        if n < 0:  # non-finite frame: the kernel stopped before it; raise the usual message
            raise ValueError("frame contains NaN or inf")
        self.n_star = int(n)
        self.cost = float(self._col[n])
        return self.n_star, self.cost

    def _step_np(self, v, first):
        return _step_np(self.reference, v, self._prev, self._col, first)

    @property
    def column(self) -> np.ndarray:
        """The current last column ``D(., M)`` (read-only view)."""
        c = self._col.view()
        c.flags.writeable = False
        return c


def _step_np(u, v, prev, col, first):
    """One query frame ``v`` against the reference ``u`` ``(N, D)`` in numpy: the new last column into ``col``
    (``prev`` the old one; the operations of the compiled step, bitwise equal); returns n*."""
    c = np.zeros(u.shape[0])
    for d in range(u.shape[1]):
        diff = u[:, d] - v[d]
        c += diff * diff
    if first:
        np.cumsum(c, out=col)
    else:
        col[0] = prev[0] + c[0]
        tmp = np.minimum(prev[:-1], prev[1:]).tolist()
        cl = c.tolist()
        x = col[0]
        out = [x]
        for n in range(1, len(cl)):
            t = tmp[n - 1]
            x = (t if t < x else x) + cl[n]
            out.append(x)
        col[:] = out
    return _argmin_first_np(col)


class IncrementalDTWSet:
    """Open-end DTW of one query against several references, frames taken in blocks: after ``M`` frames its
    ``n_star[j]`` and ``cost[j]`` equal those of ``IncrementalDTW(references[j])`` fed the same frames (and so
    of ``open_end_dtw(references[j], v[:M])``), bit for bit.

    One compiled call per block advances every reference (:func:`interprim.core._compiled.dtw._incremental_set`,
    each reference's columns by the per-frame step), instead of one Python call per reference; the numpy steps
    (before the kernels are loaded) work on the same buffers.  Memory: two columns per reference.

    Parameters
    ----------
    references : sequence of array_like, shape (N_j, D)
    """

    def __init__(self, references):
        refs = [as_2d_finite(r, "reference", min_rows=1) for r in references]
        if not refs:
            raise ValueError("IncrementalDTWSet needs at least one reference")
        D = refs[0].shape[1]
        if any(r.shape[1] != D for r in refs):
            raise ValueError(f"every reference must have {D} columns, got {[r.shape[1] for r in refs]}")
        self.references = refs
        J = len(refs)
        self._lengths = np.array([r.shape[0] for r in refs], dtype=np.int64)
        self._starts = np.concatenate([[0], np.cumsum(self._lengths)[:-1]]).astype(np.int64)
        total = int(self._lengths.sum())
        # flat storage: each reference transposed, (D, N_j) in C order, one after the other; its columns likewise
        self._uT = np.concatenate([np.ascontiguousarray(r.T).ravel() for r in refs])
        self._A, self._B, self._work = np.zeros(total), np.zeros(total), np.zeros(total)
        self._swapped = np.zeros(J, dtype=np.bool_)  # the last column of reference j in B
        self.n_frames = 0
        self.n_star = np.full(J, -1, dtype=np.int64)
        self.cost = np.full(J, np.inf)

    def reset(self):
        """Forget all query frames."""
        self.n_frames = 0
        self.n_star[:] = -1
        self.cost[:] = np.inf

    def extend(self, block) -> tuple[np.ndarray, np.ndarray]:
        """Add the checked, finite query frames ``block`` ``(k, D)`` (float64, C order, ``k >= 1``); returns
        ``(n_star, cost)`` after the last, arrays over the references (``D(n*, M)``, as
        :attr:`IncrementalDTW.cost`)."""
        steps = kernels.kernel("dtw.incremental_set")
        if steps is not None:
            if steps(self._uT, self._starts, self._lengths, block, self._A, self._B, self._work, self._swapped,
                     self.n_frames, self.n_star, self.cost) < 0:
                raise ValueError("frame contains NaN or inf")
        else:
            for j, u in enumerate(self.references):
                s, N = int(self._starts[j]), u.shape[0]
                a, b = self._A[s:s + N], self._B[s:s + N]
                for i, f in enumerate(block):
                    first = self.n_frames + i == 0
                    if not first:
                        self._swapped[j] = not self._swapped[j]
                    prev, col = (a, b) if self._swapped[j] else (b, a)
                    n = _step_np(u, f, prev, col, first)
                self.n_star[j] = n
                self.cost[j] = col[n]
        self.n_frames += block.shape[0]
        return self.n_star, self.cost

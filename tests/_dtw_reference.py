"""The one brute-force open-end DTW of the tests: Eq. 5-8 of the paper written literally."""

from __future__ import annotations

import numpy as np


def brute_force_dtw(u, v):
    """Accumulated cost ``D`` (Eq. 5-7) of reference ``u (N, d)`` against observation ``v (M, d)`` and ``n*`` (Eq. 8).

    ``D[n, m]`` (0-based) is the paper's ``D(n+1, m+1)``: the cost of the best alignment of ``u[:n+1]`` with
    ``v[:m+1]``, ``c = ||u_n - v_m||^2``; ``n_star`` (0-based) minimises the last column ``D[:, M-1]`` (the first
    minimum).  Returns ``(D, n_star)``.
    """
    u, v = np.asarray(u, dtype=np.float64), np.asarray(v, dtype=np.float64)
    N, M = len(u), len(v)

    def c(n, m):
        return float(np.sum((u[n] - v[m]) ** 2))

    D = np.empty((N, M))
    for m in range(M):
        D[0, m] = sum(c(0, k) for k in range(m + 1))  # Eq. 5
    for n in range(N):
        D[n, 0] = sum(c(k, 0) for k in range(n + 1))  # Eq. 6
    for n in range(1, N):
        for m in range(1, M):
            D[n, m] = min(D[n - 1, m - 1], D[n, m - 1], D[n - 1, m]) + c(n, m)  # Eq. 7
    return D, int(np.argmin(D[:, M - 1]))  # Eq. 8

"""Compiled weighted mean and spread of demonstrations read at fractional frames (the prediction of
:class:`interprim.models.kernel.KernelDemonstrations`).

:func:`weighted_frames` performs the operations of its numpy reference
(:func:`interprim.models.kernel.weighted_frames_np`: the linear interpolation of ``KernelDemonstrations._frames_at``,
then ``einsum("j,jkd->kd", w, Y)`` and ``einsum("j,jkd->kd", w, (Y - mean) ** 2)``) in the same order: each
product added to a zero start, demonstration after demonstration.  It is compiled without fastmath (no fused
multiply-add, no reassociation), so its results equal the reference's bit for bit; it never holds the ``(J, n,
C)`` array of the interpolated frames, which it reads twice instead.
"""

from __future__ import annotations

import numpy as np
from numba import njit, types

_IN3 = types.Array(types.float64, 3, "C", readonly=True)
_IDX = types.Array(types.intp, 1, "C", readonly=True)
_IN2 = types.Array(types.float64, 2, "C", readonly=True)
_IN1 = types.Array(types.float64, 1, "C", readonly=True)
_OUT2 = types.Array(types.float64, 2, "C")
_SIGNATURE = types.void(_IN3, _IDX, _IN2, _IDX, _IN1, _OUT2, _OUT2)


@njit(cache=True, fastmath=False, inline="always")
def _value(padded, j, k, frac, col):
    """Column ``col`` of demonstration ``j`` at the fractional frame ``k + frac``: the sample itself when ``frac`` is
    0 (the last sample's successor is padding), else ``(y[k+1] - y[k]) frac + y[k]`` (numpy.interp's operations)."""
    lo = padded[j, k, col]
    if frac == 0.0:
        return lo
    return (padded[j, k + 1, col] - lo) * frac + lo


@njit(_SIGNATURE, cache=True, fastmath=False)
def weighted_frames(padded, idx, f, cols, w, mean, spread):
    """``mean[i, c] = sum_j w[j] Y[j, i, c]`` and ``spread[i, c] = sum_j w[j] (Y[j, i, c] - mean[i, c])^2`` with
    ``Y[j, i, c]`` demonstration ``idx[j]`` of the zero-padded ``padded`` (n_demos, T_max + 1, D) at the fractional
    frame ``f[j, i]`` (within ``[0, T_j - 1]``), column ``cols[c]``; the sums start at zero and add the
    demonstrations in order (two passes: the spread needs the whole mean)."""
    J = idx.shape[0]
    n = f.shape[1]
    C = cols.shape[0]
    for i in range(n):
        for c in range(C):
            mean[i, c] = 0.0
            spread[i, c] = 0.0
    for second in (False, True):
        for jj in range(J):
            j = idx[jj]
            wj = w[jj]
            for i in range(n):
                fk = f[jj, i]
                k = np.intp(np.floor(fk))
                frac = fk - k
                for c in range(C):
                    v = _value(padded, j, k, frac, cols[c])
                    if second:
                        t = v - mean[i, c]
                        spread[i, c] += wj * (t * t)
                    else:
                        mean[i, c] += wj * v


def warm_up() -> None:
    """Compile (or load) :func:`weighted_frames` with tiny inputs of the real types."""
    padded = np.zeros((2, 4, 2))
    weighted_frames(padded, np.arange(2, dtype=np.intp), np.array([[0.0, 1.5], [2.0, 0.25]]),
                    np.arange(2, dtype=np.intp), np.array([0.5, 0.5]), np.empty((2, 2)), np.empty((2, 2)))

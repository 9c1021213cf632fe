"""Compiled linear interpolation of many columns at the same points (the one resampling rule,
:func:`interprim.core.preprocessing.interp_columns`).

:func:`interp_columns_into` performs, for every column, the operations of :func:`numpy.interp`'s C routine in the
same order (the interval found once per point for all columns), so its results equal numpy's bit for bit.  It is
compiled without fastmath: contracting ``slope * dx + y`` into a fused multiply-add would change the last bit.
"""

from __future__ import annotations

import numpy as np
from numba import njit, types

_IN1 = types.Array(types.float64, 1, "C", readonly=True)
_IN2 = types.Array(types.float64, 2, "C", readonly=True)
#: one signature for every call (writable inputs convert to the read-only types; a read-only grid, e.g. a cached
#: ``linspace``, then compiles nothing new)
_SIGNATURE = types.boolean(_IN1, _IN1, _IN2, types.Array(types.float64, 2, "C"))


@njit(cache=True, fastmath=False, inline="always")
def interp_into(x_new, x, y, out):
    """The body of :func:`interp_columns_into`, for other kernels to call on their own arrays."""
    T = x.shape[0]
    D = y.shape[1]
    if T < 2:
        return False
    for k in range(T - 1):
        if not x[k] < x[k + 1]:
            return False
    j = 0
    for i in range(x_new.shape[0]):
        xv = x_new[i]
        if np.isnan(xv):
            for d in range(D):
                out[i, d] = xv
            continue
        if xv < x[0]:  # numpy's left value: the first sample
            for d in range(D):
                out[i, d] = y[0, d]
            continue
        if xv >= x[T - 1]:  # numpy's right value beyond the end, the last sample at it
            for d in range(D):
                out[i, d] = y[T - 1, d]
            continue
        # the interval x[j] <= xv < x[j + 1] (unique for strictly increasing x)
        if not (x[j] <= xv and xv < x[j + 1]):
            lo = 0
            hi = T
            while lo < hi:
                mid = lo + ((hi - lo) >> 1)
                if xv >= x[mid]:
                    lo = mid + 1
                else:
                    hi = mid
            j = lo - 1
        if x[j] == xv:
            for d in range(D):
                out[i, d] = y[j, d]
            continue
        dx = x[j + 1] - x[j]
        for d in range(D):
            slope = (y[j + 1, d] - y[j, d]) / dx
            r = slope * (xv - x[j]) + y[j, d]
            if np.isnan(r):  # numpy's fallbacks for infinite values
                r = slope * (xv - x[j + 1]) + y[j + 1, d]
                if np.isnan(r) and y[j, d] == y[j + 1, d]:
                    r = y[j, d]
            out[i, d] = r
    return True


@njit(_SIGNATURE, cache=True, fastmath=False)
def interp_columns_into(x_new, x, y, out):
    """``out[i, d] = numpy.interp(x_new[i], x, y[:, d])`` for C-contiguous float64 ``x_new`` (n,), ``x`` (T,),
    ``y`` (T, D) and ``out`` (n, D); returns False (``out`` undefined) when ``x`` is not strictly increasing or has
    fewer than two points, where numpy's search among equal positions is not reproduced (the caller then uses numpy)."""
    return interp_into(x_new, x, y, out)

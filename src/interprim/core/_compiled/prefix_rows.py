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

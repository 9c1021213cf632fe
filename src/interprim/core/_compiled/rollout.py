"""Compiled rollout of the DMPs (paper Eq. 1): the controlled agent's mean movement from the current phase.

:func:`response_positions` integrates the posterior mean of the controlled agent from
the current phase to the end on the rollout grid of :class:`interprim.core.dmp.LinearRollout`;
reference: :meth:`interprim.models.primitive.prediction.Prediction._response_reference`
(:meth:`interprim.core.dmp.LinearRollout.design`).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from . import FASTMATH as _FM


@njit(cache=True, fastmath=_FM)
def response_positions(Z, powers, s0, n, th, z0, at_s0, out, duration, t_out):
    """Mean positions of DoFs with parameters ``th`` (d, q) at ``linspace(s0, 1, n)``, from their state at ``s0``.

    The state at ``s0`` is that of the movement started at ``s = 0`` in ``z0``
    (2, d) (positions, velocities), or ``z0`` itself when ``at_s0``; the continuation uses the exact
    discretisation of :class:`interprim.core.dmp.LinearRollout` (same snapping and
    interpolation as :meth:`~interprim.core.dmp.LinearRollout.design`).
    ``out`` has shape (n, d); ``t_out`` (n,) receives ``(s - s0) * duration``.
    """
    Kn = Z.shape[0] - 1
    q = Z.shape[2]
    d = th.shape[0]
    h = np.empty(q)
    # -- state at s0 of the movement from rest at s = 0 (design(0, [s0]) rows 0 and 1)
    y0 = np.empty(d)
    v0 = np.empty(d)
    u = min(max(s0 * Kn, 0.0), float(Kn))
    kf = min(int(np.floor(u)), Kn - 1)
    kf = max(kf, 0)
    a = u - kf
    kf1 = min(kf + 1, Kn)
    for row in range(2):
        if at_s0:
            for dd in range(d):
                if row == 0:
                    y0[dd] = z0[0, dd]
                else:
                    v0[dd] = z0[1, dd]
            continue
        f0 = (1.0 - a) * powers[kf, row, 0] + a * powers[kf1, row, 0]
        f1 = (1.0 - a) * powers[kf, row, 1] + a * powers[kf1, row, 1]
        for j in range(q):
            # k0 = 0: P @ Z[0] = 0 because Z[0] = 0
            h[j] = (1.0 - a) * (Z[kf, row, j] - (powers[kf, row, 0] * Z[0, 0, j] + powers[kf, row, 1] * Z[0, 1, j])) \
                + a * (Z[kf1, row, j] - (powers[kf1, row, 0] * Z[0, 0, j] + powers[kf1, row, 1] * Z[0, 1, j]))
        for dd in range(d):
            acc = f0 * z0[0, dd] + f1 * z0[1, dd]
            for j in range(q):
                acc += h[j] * th[dd, j]
            if row == 0:
                y0[dd] = acc
            else:
                v0[dd] = acc
    # -- continuation from s0 (design(s0, linspace(s0, 1, n)))
    k0 = int(np.rint(s0 * Kn))
    k0 = min(max(k0, 0), Kn)
    pz = np.empty((2, q))  # rows of P @ Z[k0] for the two grid points, recomputed per output
    step = (1.0 - s0) / (n - 1) if n > 1 else 0.0
    for t in range(n):
        s = t * step + s0 if t < n - 1 else 1.0
        if n == 1:
            s = s0
        t_out[t] = (s - s0) * duration
        u = min(max(k0 + (s - s0) * Kn, float(k0)), float(Kn))  # times counted from s0 = grid point k0
        kf = min(int(np.floor(u)), Kn - 1)
        kf = max(kf, k0)
        a = u - kf
        kf1 = min(kf + 1, Kn)
        pa0 = powers[kf - k0, 0, 0]
        pa1 = powers[kf - k0, 0, 1]
        pb0 = powers[kf1 - k0, 0, 0]
        pb1 = powers[kf1 - k0, 0, 1]
        f0 = (1.0 - a) * pa0 + a * pb0
        f1 = (1.0 - a) * pa1 + a * pb1
        for j in range(q):
            pz[0, j] = pa0 * Z[k0, 0, j] + pa1 * Z[k0, 1, j]
            pz[1, j] = pb0 * Z[k0, 0, j] + pb1 * Z[k0, 1, j]
            h[j] = (1.0 - a) * (Z[kf, 0, j] - pz[0, j]) + a * (Z[kf1, 0, j] - pz[1, j])
        for dd in range(d):
            acc = f0 * y0[dd] + f1 * v0[dd]
            for j in range(q):
                acc += h[j] * th[dd, j]
            out[t, dd] = acc
    return out

"""Compiled placing in time of a blend's members (:meth:`interprim.models.blend.Blend.combine`).

:func:`place_members_into` performs the operations of its numpy reference
(:func:`interprim.models.blend.place_members_np`) in the same order: each member's normalised time at every point
of the common grid (its own speed up to the real-time band, then the shared end of
:func:`interprim.model_selection.long_range.member_units`, ``u s_m / s`` before now), its values read there by
:func:`numpy.interp`'s operations (:func:`interprim.core._compiled.resample.interp_into`), and the weighted sum of
the members added to a zero start, member after member (``einsum("gm,mgd->gd", W, Y)``'s order).  Compiled without
fastmath, so its results equal the reference's bit for bit.  It saves the per-member array operations of a streamed
frame (about 25 us a member).

:func:`weights_on_into` performs the operations of the weights over the look-ahead (the numpy reference
:func:`interprim.models.blend.weights_on_np`, what :meth:`interprim.models.blend.Blend.combine` reads after every
frame): each point's look-ahead, the bands' weights interpolated there, clipped at 0 and divided by their sum (numpy's
order: one member after another from 0, for up to :data:`MAX_MEMBERS` members), and the count of zero weights, in one
pass without the temporaries.

:func:`spread_std_into` performs the operations of the blend's std (the numpy reference
:func:`interprim.models.blend.spread_std_np`, what :attr:`interprim.models.blend.BlendPrediction.std_values` reads):
the members' weighted disagreement ``sum_m W[:, m] (Y_m - mean)^2`` (einsum's order, member after member from a zero
start), the variance model ``a(ahead) spread + b(ahead)`` with ``a`` and ``b`` read by :func:`numpy.interp`'s
operations, then ``sqrt(max(var, 0))``, in one pass without the temporaries (about 30 us of a prediction's std).
"""

from __future__ import annotations

import numpy as np
from numba import njit, types

from .resample import interp_into

_IN1 = types.Array(types.float64, 1, "C", readonly=True)
_IN2 = types.Array(types.float64, 2, "C", readonly=True)
_IN3 = types.Array(types.float64, 3, "C", readonly=True)
_OUT1 = types.Array(types.float64, 1, "C")
_OUT2 = types.Array(types.float64, 2, "C")
_OUT3 = types.Array(types.float64, 3, "C")
_STD_SIGNATURE = types.int64(_IN3, _IN2, _IN2, _IN1, _IN1, _IN2, _IN2, types.boolean, _OUT2)
_SIGNATURE = types.boolean(_IN1, _IN1, _IN1, _IN1, types.float64, types.float64, types.float64, _IN3, _IN2,
                           _OUT3, _OUT2, _OUT1)


#: the most members whose weights :func:`weights_on_into` normalises: numpy sums up to 7 terms one after another
#: from 0 (its pairwise summation unrolls 8 or more), the order the kernel follows
MAX_MEMBERS = 7
_W_SIGNATURE = types.int64(_IN1, types.float64, types.float64, _IN1, _IN2, _OUT1, _OUT2)


@njit(_W_SIGNATURE, cache=True, fastmath=False, error_model="numpy")
def weights_on_into(u, s, D, mids, table, ahead, W):
    """``ahead = max((u - s) D, 0)`` seconds after now at every point of the grid ``u`` (the blend's phase ``s``,
    duration ``D``) and the weights ``W`` (n, M) there: the bands' weights ``table`` (B, M) at the bands' middles
    ``mids`` (B,) read by :func:`numpy.interp`'s operations, clipped at 0 and divided by their sum (at least
    1e-300).  Returns the number of weights equal to 0, or -1 (outputs undefined) when ``mids`` is not strictly
    increasing or there are more than :data:`MAX_MEMBERS` members."""
    n = u.shape[0]
    M = table.shape[1]
    if M > MAX_MEMBERS:
        return -1
    for g in range(n):
        a = (u[g] - s) * D
        if not (a > 0.0 or np.isnan(a)):  # numpy.maximum(a, 0): NaN kept, -0.0 and below become 0.0
            a = 0.0
        ahead[g] = a
    if not interp_into(ahead, mids, table, W):
        return -1
    zeros = 0
    for g in range(n):
        total = 0.0
        for j in range(M):
            w = W[g, j]
            if not (w > 0.0 or np.isnan(w)):
                w = 0.0
            W[g, j] = w
            total += w
        if not (total > 1e-300 or np.isnan(total)):
            total = 1e-300
        for j in range(M):
            w = W[g, j] / total
            W[g, j] = w
            if w == 0.0:
                zeros += 1
    return zeros


@njit(_SIGNATURE, cache=True, fastmath=False, error_model="numpy")
def place_members_into(u, ahead, sv, dv, s, R, h, grids, W, Y, mean, um):
    """``Y[j]``: member ``j``'s values ``grids[j]`` (on the grid ``u``) read at its normalised time for every point
    of ``u`` (phase ``sv[j]``, duration ``dv[j]``; ``ahead`` seconds after now, the blend's phase ``s``; a shared
    end ``R`` seconds from now beyond the real-time band of ``h`` seconds, NaN for none); ``mean = sum_j W[:, j]
    Y[j]``.  ``um`` (n,) is a workspace.  Returns False (outputs undefined) when ``u`` is not strictly increasing."""
    n = u.shape[0]
    A = sv.shape[0]
    D = grids.shape[2]
    shared = not np.isnan(R)
    for j in range(A):
        sm = sv[j]
        Dm = dv[j]
        uh = 0.0
        Rm = 0.0
        if shared:
            Rm = max(R, h)
            uh = min(sm + h / Dm, 1.0)
        past_scale = sm / s if s > 0 else 1.0
        for g in range(n):
            a = ahead[g]
            v = a / Dm
            v += sm
            if shared and not a <= h + 1e-12:
                if Rm > h:
                    v = (a - h) * (1.0 - uh) / max(Rm - h, 1e-9) + uh
                else:
                    v = 1.0
            v = min(max(v, 0.0), 1.0)
            if u[g] < s:
                v = min(max(u[g] * past_scale, 0.0), 1.0)
            um[g] = v
        if not interp_into(um, u, grids[j], Y[j]):
            return False
    for g in range(n):
        for d in range(D):
            mean[g, d] = 0.0
    for j in range(A):
        for g in range(n):
            w = W[g, j]
            for d in range(D):
                mean[g, d] += w * Y[j, g, d]
    return True


@njit(_STD_SIGNATURE, cache=True, fastmath=False, error_model="numpy")
def spread_std_into(Y, mean, W, ahead, steps, a, b, scaled, std):
    """``std = sqrt(max(var, 0))`` with ``var = a(ahead) * spread + b(ahead)`` (``spread`` alone unless ``scaled``)
    and ``spread = sum_j W[:, j] (Y[j] - mean)^2``; ``a`` and ``b`` ``(H, D)`` are tabulated at ``steps`` ``(H,)``
    seconds ahead and read at ``ahead`` ``(n,)`` (held at the ends).  Returns -1 (``std`` undefined) when ``steps``
    is not strictly increasing or has fewer than two points, else the number of points with ``var > 0``."""
    n = mean.shape[0]
    D = mean.shape[1]
    A = Y.shape[0]
    for g in range(n):
        for d in range(D):
            std[g, d] = 0.0
    for j in range(A):
        for g in range(n):
            w = W[g, j]
            for d in range(D):
                e = Y[j, g, d] - mean[g, d]
                std[g, d] += w * (e * e)
    if scaled:
        ia = np.empty((n, D))
        ib = np.empty((n, D))
        if not interp_into(ahead, steps, a, ia) or not interp_into(ahead, steps, b, ib):
            return -1
        for g in range(n):
            for d in range(D):
                std[g, d] = ia[g, d] * std[g, d] + ib[g, d]
    positive = 0
    for g in range(n):
        for d in range(D):
            v = std[g, d]
            if v > 0.0:
                positive += 1
            if v <= 0.0:  # numpy.clip(var, 0, None): -0.0 becomes 0.0, NaN is kept
                v = 0.0
            std[g, d] = np.sqrt(v)
    return positive


def warm_up() -> None:
    """Compile (or load) :func:`weights_on_into`, :func:`place_members_into` and :func:`spread_std_into` with tiny
    inputs of the real types."""
    u = np.linspace(0.0, 1.0, 4)
    weights_on_into(u, 0.4, 1.5, np.array([0.1, 0.5]), np.array([[0.3, 0.7], [0.6, 0.4]]), np.empty(4),
                    np.empty((4, 2)))
    place_members_into(u, np.array([0.0, 0.0, 0.1, 0.3]), np.array([0.4, 0.5]), np.array([1.0, 1.2]), 0.45, 0.8,
                       0.25, np.zeros((2, 4, 2)), np.full((4, 2), 0.5), np.empty((2, 4, 2)), np.empty((4, 2)),
                       np.empty(4))
    spread_std_into(np.zeros((2, 4, 2)), np.zeros((4, 2)), np.full((4, 2), 0.5), np.array([0.0, 0.0, 0.1, 0.3]),
                    np.array([0.1, 0.2]), np.ones((2, 2)), np.zeros((2, 2)), True, np.empty((4, 2)))

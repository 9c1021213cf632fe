"""Features of an observed prefix and the closed-form leave-one-out regressions of
:class:`interprim.phase.learned.LearnedPhase` (kept apart so that each file reads in one sitting)."""

from __future__ import annotations

import numpy as np

_GROUP_SIZE = {"position": "D", "displacement": "D", "velocity": "D", "path": 1, "peak_speed": 1, "history": "DH"}


def group_dims(groups, D, H):
    size = {"D": D, "DH": D * H}
    return [size.get(_GROUP_SIZE[g], _GROUP_SIZE[g]) for g in groups]


def prefix_features(Y, dt, w, groups, history=3):
    """Features of every prefix ``Y[:k+1]`` of a uniformly sampled, scaled ``(T, D)`` movement: ``(T, p)``.

    The numpy reference of :class:`PhaseTracker`'s incremental update (equal to rounding).
    """
    T, D = Y.shape
    cols = []
    k = np.arange(T)
    back = np.maximum(k - w, 0)
    span = (k - back) * dt
    vel = np.zeros((T, D))
    ok = span > 0
    vel[ok] = (Y[ok] - Y[back[ok]]) / span[ok, None]
    for g in groups:
        if g == "position":
            cols.append(Y)
        elif g == "displacement":
            cols.append(Y - Y[0])
        elif g == "velocity":
            cols.append(vel)
        elif g == "path":
            step = np.zeros(T)
            step[1:] = np.sqrt(np.sum(np.diff(Y, axis=0) ** 2, axis=1))
            cols.append(np.cumsum(step)[:, None])
        elif g == "peak_speed":
            cols.append(np.maximum.accumulate(np.sqrt(np.sum(vel * vel, axis=1)))[:, None])
        elif g == "history":
            for q in np.arange(1, history + 1) / (history + 1):
                x = q * k
                lo = np.floor(x).astype(int)
                hi = np.minimum(lo + 1, T - 1)
                f = (x - lo)[:, None]
                cols.append((1.0 - f) * Y[lo] + f * Y[hi] - Y[0])
    return np.concatenate(cols, axis=1) if cols else np.zeros((T, 0))


def ridge_loo(Z, s, alphas):
    """Closed-form leave-one-out predictions of ridge regression with intercept, batched over times.

    ``Z`` (K, n, p) standardised features, ``s`` (K, n) targets; returns ``(len(alphas), K, n)``.
    """
    K, n, p = Z.shape
    Zc = Z - Z.mean(axis=1, keepdims=True)
    sm = s.mean(axis=1, keepdims=True)
    sc = s - sm
    U, S, _ = np.linalg.svd(Zc, full_matrices=False)  # (K, n, r), (K, r)
    out = np.empty((len(alphas), K, n))
    Ut_s = (sc[:, None, :] @ U)[:, 0, :]  # U^T s per time, (K, r)
    U2 = U * U
    for a, lam in enumerate(alphas):
        f = S * S / (S * S + lam)  # (K, r)
        fit = sm + (U @ (f * Ut_s)[:, :, None])[:, :, 0]
        h = 1.0 / n + (U2 @ f[:, :, None])[:, :, 0]  # leverages
        out[a] = s - (s - fit) / np.maximum(1.0 - h, 1e-9)
    return out


def kernel_loo(Z, s, bandwidths):
    """Leave-one-out Nadaraya-Watson predictions at each time: ``(len(bandwidths), K, n)``."""
    K, n, p = Z.shape
    sq = np.sum(Z * Z, axis=2)
    D2 = np.maximum(sq[:, :, None] + sq[:, None, :] - 2.0 * (Z @ Z.transpose(0, 2, 1)), 0.0) / max(p, 1)
    idx = np.arange(n)
    D2[:, idx, idx] = np.inf
    dmin = D2.min(axis=2, keepdims=True)
    out = np.empty((len(bandwidths), K, n))
    for b, h in enumerate(bandwidths):
        W = np.exp(-(D2 - dmin) / (2.0 * h * h))
        out[b] = (W @ s[:, :, None])[:, :, 0] / W.sum(axis=2)
    return out


def jsonable(v):
    """``v`` with numpy scalars as Python numbers and tuples as lists (JSON; inf/nan as JSON's Infinity/NaN)."""
    if isinstance(v, dict):
        return {str(k): jsonable(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [jsonable(x) for x in v]
    if isinstance(v, np.generic):
        return v.item()
    return v

"""The yardsticks a user reads, scored on held-out cases, and a choice that prefers the simpler answer.

A robot builder reads three figures of a model (docs/evaluation.md): the error over the next ``horizon`` seconds
after each frame (real time), over the **rest of the movement in seconds** (every remaining frame of the held-out
recording, placed in time by the model's own phase and duration), and the paper's Fig. 7 measure (the whole
movement in normalised time after 60 % seen).  Each is read against two references: the **clock** (the mean
demonstration played at the mean duration) and the **mean at the true duration** (the same mean stretched to the
held-out recording's real length: a floor that needs the future, known in a held-out fold).

This module computes these figures from the arrays of held-out cases that a cross-validation keeps (one case =
one evaluated frame of one held-out demonstration), their ratios with standard errors over the held-out
*demonstrations* (cases of one recording are not independent), and :func:`one_se_choice`: among candidates
ordered from the simplest, the first whose error is within one standard error of the best one's (the
one-standard-error rule of Breiman et al. 1984, *Classification and Regression Trees*, §3.4.3).  It names no model.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping

import numpy as np
from numpy.typing import ArrayLike

from ..core._compiled import registry as _kernels
from ..core.cv import paired_gain
from ..core.preprocessing import column_index, interp_columns

__all__ = ["case_rms", "case_groups", "demo_means", "ratio_se", "one_se_choice", "place_cases", "clock_units",
           "true_duration_units", "whole_movement_units"]


def case_rms(pred: ArrayLike, truth: ArrayLike, mask: ArrayLike, cols: Iterable[int], point_dim: int = 1) -> np.ndarray:
    """``(cases,)``: per case, the RMS of the point errors of columns ``cols`` over the steps where ``mask``.

    Parameters
    ----------
    pred, truth : ndarray, shape (cases, H, D)
        Predictions placed in time and the held-out frames at the same ``H`` steps.
    mask : ndarray of bool, shape (cases, H)
        The steps scored (e.g. the real-time band, or every step inside the held-out movement).
    cols : sequence of int
        Columns of the agent scored.
    point_dim : int
        Columns per point (3 for 3-D positions; as in
        :class:`~interprim.model_selection.realtime.RealTimeConfig`).
    """
    sel = column_index(cols)  # consecutive columns by a slice: views instead of two copies, the same differences
    e = np.asarray(pred, dtype=np.float64)[..., sel] - np.asarray(truth, dtype=np.float64)[..., sel]
    n_case, H, C = e.shape
    pd = point_dim if C % point_dim == 0 else 1
    sq = e ** 2
    # (cases, H) squared point errors; one column per point: the squares themselves (a sum of one term, 0 + x)
    p2 = (sq if pd == 1 else np.sum(sq.reshape(n_case, H, C // pd, pd), axis=3)).mean(axis=2)
    m = np.asarray(mask, dtype=np.float64)
    return np.sqrt(np.sum(p2 * m, axis=1) / np.maximum(m.sum(axis=1), 1.0))


def case_groups(demo: ArrayLike, k: int = 3) -> np.ndarray:
    """``(cases,)`` group labels ``0..k-1``: the held-out demonstrations ``demo`` split into ``k`` contiguous groups
    (every case of a demonstration in one group)."""
    demo = np.asarray(demo)
    u = np.unique(demo)
    k = max(1, min(int(k), len(u)))
    g = {d: i * k // len(u) for i, d in enumerate(u)}
    return np.array([g[d] for d in demo], dtype=np.int64)


def demo_means(values: ArrayLike, groups: ArrayLike) -> np.ndarray:
    """Means of ``values`` ``(cases, ...)`` per held-out demonstration (``groups``: ``(cases,)`` labels, in the
    order of ``np.unique``)."""
    values = np.asarray(values, dtype=np.float64)
    groups = np.asarray(groups)
    return np.array([values[groups == g].mean(axis=0) for g in np.unique(groups)])


def ratio_se(a: ArrayLike, b: ArrayLike, groups: ArrayLike | None = None) -> tuple[float, float]:
    """``(ratio of the means of a and b, its standard error)`` over demonstrations (paired, delta method).

    ``a``, ``b``: errors of two methods on the same cases; with ``groups`` (the cases' demonstrations) they are
    first averaged per demonstration, and the ratio is of the means of those (each recording counts once); the
    standard error is that of the mean of ``a_i - r b_i`` over the ``n`` demonstrations, divided by the mean of
    ``b`` (NaN with fewer than two).
    """
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    if groups is not None:
        a, b = demo_means(a, groups), demo_means(b, groups)
    mb = float(b.mean())
    r = float(a.mean()) / mb if mb > 0 else float("nan")
    if len(a) < 2 or not mb > 0:
        return r, float("nan")
    _, se = paired_gain(a, r * b)  # the standard error of the mean of a_i - r b_i
    return r, float(se) / mb


def one_se_choice(errors: Mapping[str, ArrayLike], groups: ArrayLike,
                  order: Iterable[str] | None = None) -> tuple[str, dict[str, dict[str, float]]]:
    """The simplest candidate whose error is within one standard error of the best one's.

    Parameters
    ----------
    errors : dict
        ``{candidate: (cases,) errors}`` on the same held-out cases (smaller is better).
    groups : array_like, shape (cases,)
        The held-out demonstration of each case: errors are averaged per demonstration, and the standard error
        of a difference is over demonstrations.
    order : sequence, optional
        The candidates from the simplest to the most complex (default: the order of ``errors``).

    Returns
    -------
    (str, dict)
        The choice and ``{candidate: {"error", "vs_best", "se"}}``: its mean error, the mean over demonstrations
        of (its error - the best one's) and that difference's standard error.  A candidate is within the noise
        when ``vs_best <= se``; the best is always within it, so a choice always exists.
    """
    order = list(errors if order is None else order)
    per = {m: demo_means(errors[m], groups) for m in order}
    best = min(order, key=lambda m: (float(per[m].mean()), order.index(m)))
    table: dict[str, dict[str, float]] = {}
    for m in order:
        vs_best, se = paired_gain(per[m], per[best])  # mean of (m - best) over demonstrations, its standard error
        table[m] = {"error": float(per[m].mean()), "vs_best": float(vs_best), "se": float(se)}
    chosen = next(m for m in order if table[m]["vs_best"] <= table[m]["se"] + 1e-12)
    return chosen, table


def place_cases(Y: ArrayLike, u: ArrayLike, out: np.ndarray | None = None) -> np.ndarray:
    """``(cases, H, D)``: each case's trajectory ``Y[c]`` (``(G, D)`` on a uniform normalised-time grid) read at its
    normalised times ``u[c]`` (``(H,)``, clipped to [0, 1]); written into ``out`` when given (a C-contiguous float
    array of that shape, e.g. one member's rows of the members' array: no copy of the placed cases)."""
    Y = np.asarray(Y, dtype=np.float64)
    u = np.clip(np.asarray(u, dtype=np.float64), 0.0, 1.0)
    grid = np.linspace(0.0, 1.0, Y.shape[1])
    if u.ndim == 2 and Y.ndim == 3 and Y.shape[0] and Y.shape[1] > 1 and Y.shape[2] > 1:
        # interp_columns' compiled kernel, case by case into one array, when the kernels are loaded (the numbers
        # of interp_columns, which calls it, without its per-call conversions and the copy of np.stack)
        kernel = _kernels.loaded_kernel("resample.interp_columns")
        if kernel is not None:
            u, Yc = np.ascontiguousarray(u), np.ascontiguousarray(Y)
            res = np.empty((Y.shape[0], u.shape[1], Y.shape[2])) if out is None else out
            if all(kernel(u[c], grid, Yc[c], res[c]) for c in range(Y.shape[0])):
                return res
    placed = np.stack([interp_columns(u[c], grid, Y[c]) for c in range(Y.shape[0])])
    if out is None:
        return placed
    out[...] = placed
    return out


def clock_units(k: ArrayLike, t_ahead: ArrayLike, dt: float, mean_duration: ArrayLike) -> np.ndarray:
    """``(cases, H)``: the clock's normalised time ``t_ahead`` seconds after the last of ``k`` frames seen (the
    mean played from the first frame at the mean duration, ``mean_duration`` seconds, one or one per case)."""
    elapsed = (np.asarray(k, dtype=np.float64) - 1.0) * float(dt)
    md = np.broadcast_to(np.asarray(mean_duration, dtype=np.float64), elapsed.shape)
    return (elapsed[:, None] + np.asarray(t_ahead, dtype=np.float64)[None, :]) / md[:, None]


def true_duration_units(k: ArrayLike, n_frames: ArrayLike, t_ahead: ArrayLike, dt: float) -> np.ndarray:
    """``(cases, H)``: normalised time of the mean stretched to the held-out recording's true duration
    (``n_frames`` frames), ``t_ahead`` seconds after the last of ``k`` frames seen."""
    k = np.asarray(k, dtype=np.float64)
    dur = (np.asarray(n_frames, dtype=np.float64) - 1.0) * float(dt)
    return ((k - 1.0) * float(dt))[:, None] / dur[:, None] + np.asarray(t_ahead)[None, :] / dur[:, None]


def whole_movement_units(u: ArrayLike, phase: float, member_phase: ArrayLike, duration: float,
                         member_duration: ArrayLike) -> np.ndarray:
    """``(members, G)``: where each member is read for the blend's normalised time ``u`` ``(G,)`` when the blend
    places "now" at ``phase`` with the duration ``duration`` and member ``m`` at ``member_phase[m]``,
    ``member_duration[m]`` (the rule of :class:`interprim.models.blend.Blend`: the same instant in seconds
    ahead of now for every member, and ``u * s_m / s`` before now)."""
    u = np.asarray(u, dtype=np.float64)[None, :]
    sm = np.asarray(member_phase, dtype=np.float64)[:, None]
    Dm = np.asarray(member_duration, dtype=np.float64)[:, None]
    ahead = np.clip((u - phase) * duration, 0.0, None)
    past = u * (sm / phase if phase > 0 else 1.0)
    return np.clip(np.where(u >= phase, sm + ahead / Dm, past), 0.0, 1.0)

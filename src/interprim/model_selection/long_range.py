"""The blend beyond the real-time band: its remaining duration and its weights, chosen on the rest of the movement.

The inner cross-validation of :class:`~interprim.models.auto.AutoInteraction` fits the blend's weights per look-ahead
band (:mod:`interprim.model_selection.stacking`).  Beyond the first quarter second, two things decide where the
robot's hand will be: *when* the movement ends (the remaining duration) and *which* members are trusted.  On
people the phase is still close to a clock, and weights fitted freely per band on 12-20 recordings overrate the
nearest and kernel-weighted demonstrations at long look-aheads.  This module chooses both on the yardstick a user
reads, the error over the rest of the movement in seconds (:mod:`interprim.model_selection.yardsticks`), with the
one-standard-error rule: the simpler answer unless the complex one is better by more than its noise over the
held-out demonstrations.

**Timing** (:func:`remaining_duration`).  Beyond the real-time ``horizon`` every member runs to the end of the
movement at one shared remaining duration

    R = R_c + lam (R_b - R_c),    R_c = max(D_mean - elapsed, 0),    R_b = sum_m w_m(0) (1 - s_m) D_m,

a shrinkage of the members' own estimate ``R_b`` (their phases ``s_m`` and durations ``D_m`` weighted with the
real-time weights) toward the clock's ``R_c``; ``lam`` in :data:`LAMBDAS` (0: the clock's remaining duration) or
``None`` (each member at its own duration, the blend before this module).  Up to ``horizon`` each member keeps its
own speed (the real-time band is unchanged); after it, member ``m`` moves from where it is then,
``u_h = s_m + horizon / D_m``, linearly to its end at ``R`` seconds from now (:func:`member_units`).

**The partner's pace** (:data:`PACE`).  One more candidate, tried first: the shared end read from one family alone,
``R = max(1 - s_p, 0) D_p`` (:func:`pace_remaining`), the family whose phase and duration are read from the
partner's own movement so far (``LearnedInteraction``: its phase extrapolates the partner's current speed), as a
member of the blend or, when the stacking gave it no weight, as a member of weight 0 that only times the others
(when the frame budget affords it).  People repeating an interaction change their pace over a session, so that the
last recordings are faster or slower than the mean of the earlier ones; inside the demonstrations the pace barely
drifts, so the inner folds cannot show the clock's error on a later session, and the one-standard-error rule keeps
the partner's pace unless a simpler timing is better by more than its noise (docs/evaluation-history.md, "A
remaining duration read from the partner's pace").

**Weights beyond the real-time band** (:func:`long_range_choice`).  Candidates, from the simplest: the mean
demonstration (``prior``) alone, (optionally each single family,) the real-time weights held at every look-ahead,
the weights fitted per band.  Every candidate keeps the real-time band's weights; the per-band weights are scored
cross-fitted (fitted on the other demonstrations' cases), the others need no fit.

**The robot's past** (:func:`past_choice`).  Before now (normalised time ``u < s``) the blend reconstructs what the
robot has done, which the paper's whole-movement measure (Fig. 7) reads and no look-ahead band scores.  Candidates:
the real-time weights (tried first), the mean, and weights fitted on the past's error; another set than the
real-time weights only when it is better by more than its noise.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from ..core.preprocessing import interp_columns
from .yardsticks import case_groups, case_rms, clock_units, one_se_choice, place_cases, ratio_se, true_duration_units

if TYPE_CHECKING:
    from .stacking import CrossValidation, Stacking

__all__ = ["LAMBDAS", "PACE", "remaining_duration", "pace_remaining", "shared_end", "member_units",
           "timing_choice", "long_range_choice", "case_groups", "schedule", "held", "replaced", "PREFER", "refine",
           "inner_yardsticks", "summary_lines", "keep_real_time", "candidate_cases", "past_cases", "past_choice"]

#: The shrinkage factors of the members' remaining duration toward the clock's, from the simplest.
LAMBDAS = (0.0, 0.5, 1.0)
#: The family whose own remaining duration is the first timing candidate (module docstring: the partner's pace).
#: On the replayed development folds (:mod:`interprim.experiments.selection_replay`, 9 tasks) it took the rest of
#: the movement from 0.725x the clock to 0.719x over the three outer folds and from 0.735x to 0.719x on the fold that
#: predicts the latest third of the recordings (NuiSI alone: 0.950 → 0.937 and 0.925 → 0.895).
PACE = "learned"
#: How :func:`one_se_choice` orders the candidates: from the simplest (the default) or from the fitted one.  On the
#: development recordings, in outer folds with the whole fit inside (6 NuiSI tasks, docs/evaluation.md), starting
#: from the simplest gave 0.95x the clock over the rest of the movement and 0.96x the mean on the whole movement,
#: from the fitted end 0.95x and 1.01x (the blend before this choice: 0.93x and 1.00x).
PREFER = ("simple", "fitted")


def remaining_duration(phase: ArrayLike, duration: ArrayLike, elapsed: ArrayLike, mean_duration: ArrayLike,
                       w0: ArrayLike, lam: float) -> np.ndarray:
    """``(cases,)`` seconds left of the movement, ``R_c + lam (R_b - R_c)`` (module docstring).

    Parameters
    ----------
    phase, duration : ndarray, shape (members, cases)
        Each member's normalised time of "now" ``s_m`` and duration ``D_m`` (s) (as placed by
        :func:`~interprim.model_selection.realtime.place_in_time`).
    elapsed : ndarray, shape (cases,)
        Seconds since the first frame.
    mean_duration : float or ndarray
        The demonstrations' mean duration (s).
    w0 : ndarray, shape (members,)
        The real-time weights.
    lam : float
        0: the clock's remaining duration; 1: the members' weighted estimate.
    """
    phase = np.atleast_2d(np.asarray(phase, dtype=np.float64))
    duration = np.atleast_2d(np.asarray(duration, dtype=np.float64))
    Rb = np.asarray(w0, dtype=np.float64) @ (np.clip(1.0 - phase, 0.0, None) * duration)
    Rc = np.clip(np.asarray(mean_duration, dtype=np.float64) - np.asarray(elapsed, dtype=np.float64), 0.0, None)
    return np.clip(Rc + float(lam) * (Rb - Rc), 0.0, None)


def pace_remaining(phase: ArrayLike, duration: ArrayLike) -> np.ndarray:
    """Seconds left of the movement by one member's own timing, ``max(1 - s_p, 0) D_p`` (``phase``, ``duration``:
    its ``s_p`` and ``D_p``, any shape): the shared end of the timing named by a member (:data:`PACE`), the
    ``R_b`` of :func:`remaining_duration` with all the weight on that member and ``lam = 1``."""
    phase = np.asarray(phase, dtype=np.float64)
    return np.clip(1.0 - phase, 0.0, None) * np.asarray(duration, dtype=np.float64)


def shared_end(cv: CrossValidation, lam: float | str | None) -> np.ndarray | None:
    """``(cases,)`` the shared remaining duration of the timing ``lam`` on the cases of ``cv``: ``None`` for
    ``None`` (each member at its own duration), :func:`remaining_duration` with the real-time weights ``cv.w0``
    for a number, :func:`pace_remaining` of the member of that name (one of ``cv.names``) for a string."""
    if lam is None:
        return None
    if isinstance(lam, str):
        if lam not in cv.names:
            raise ValueError(f"the timing {lam!r} names no member of the cross-validation ({cv.names})")
        i = cv.names.index(lam)
        return pace_remaining(cv.phase[i], cv.duration[i])
    return remaining_duration(cv.phase, cv.duration, cv.elapsed, cv.mean_duration, cv.w0, lam)


def member_units(phase: ArrayLike, duration: ArrayLike, t_ahead: ArrayLike, remaining: ArrayLike | None,
                 horizon: float) -> np.ndarray:
    """``(cases, H)``: a member's normalised time ``t_ahead`` seconds from now, at its own speed ``1 / D_m`` up to
    ``horizon`` and then linearly to its end (1) at ``remaining`` seconds from now, at least ``horizon``
    (``remaining`` None: its own speed throughout).  ``phase``, ``duration``: ``(cases,)`` of the member;
    ``remaining``: ``(cases,)``."""
    s = np.asarray(phase, dtype=np.float64)[:, None]
    D = np.asarray(duration, dtype=np.float64)[:, None]
    t = np.asarray(t_ahead, dtype=np.float64)[None, :]
    own = s + t / D
    if remaining is None:
        return np.clip(own, 0.0, 1.0)
    h = float(horizon)
    R = np.maximum(np.asarray(remaining, dtype=np.float64)[:, None], h)  # never ends inside the real-time band
    uh = np.minimum(s + h / D, 1.0)
    after = uh + (t - h) * (1.0 - uh) / np.maximum(R - h, 1e-9)
    after = np.where(R > h, after, 1.0)  # the shared end at the band's edge: the members hold their end after it
    return np.clip(np.where(t <= h + 1e-12, own, after), 0.0, 1.0)


def schedule(t_ahead: ArrayLike, edges: ArrayLike, W: ArrayLike) -> np.ndarray:
    """``(H, members)`` per-step weights of the per-band weights ``W`` (upper edges ``edges``), moved smoothly
    between the bands' middles as the blend moves them (:func:`~interprim.model_selection.stacking.weights_at`)."""
    from .stacking import weights_at

    return weights_at(t_ahead, edges, W)


def held(W: ArrayLike, w: ArrayLike, n_first: int = 1) -> np.ndarray:
    """``(bands, M)``: the first ``n_first`` bands' weights of ``W``, then ``w`` in every later band."""
    out = np.tile(np.asarray(w, dtype=np.float64), (np.shape(W)[0], 1))
    out[:n_first] = np.asarray(W, dtype=np.float64)[:n_first]
    return out


def keep_real_time(W: ArrayLike, edges: Iterable[float], dt: float) -> tuple[np.ndarray, list[float], int]:
    """``(W, edges, n_first)``: the per-band weights with a band ``dt`` long added after the real-time band,
    carrying the weights the per-band schedule has at the real-time band's edge; a candidate that changes the
    bands after the first ``n_first`` then moves the blend only after the real-time band, whose weights stay (to a
    step) those of the per-band schedule (:func:`schedule`: linear between the bands' middles)."""
    W = np.asarray(W, dtype=np.float64)
    edges = [float(e) for e in edges]
    if W.shape[0] < 2 or edges[1] - edges[0] <= 2.0 * dt:
        return W, edges, 1
    w_edge = schedule(np.array([edges[0]]), edges, W)
    return np.vstack([W[:1], w_edge, W[1:]]), [edges[0], edges[0] + float(dt)] + edges[1:], 2


def _blend(mean: np.ndarray, per_step: np.ndarray) -> np.ndarray:
    """``(cases, H, D)``: the blend of the members' placed predictions ``mean`` ``(M, cases, H, D)``."""
    return np.einsum("hm,mchd->chd", per_step, mean)


def _rest(cv: CrossValidation, pred: np.ndarray, idx: np.ndarray | slice | None = None) -> np.ndarray:
    """``(cases,)``: the rest-of-the-movement error of the controlled agent (every step inside the held-out
    movement) of ``pred`` ``(cases, H, D)`` on the cases ``idx`` of ``cv``."""
    idx = slice(None) if idx is None else idx
    return case_rms(pred, cv.truth[idx], cv.valid[idx], cv.controlled or cv.observed, cv.point_dim)


def replaced(cv: CrossValidation, lam: float | str | None, remaining: ArrayLike | None = None) -> np.ndarray:
    """``(M, cases, H, D)``: the members' predictions of ``cv`` placed with the shared remaining duration of
    ``lam`` (:func:`shared_end`; ``None``: their own timing, ``cv.mean`` itself), or with ``remaining``
    ``(cases,)`` when given (e.g. a pace read from a family that is not among ``cv``'s)."""
    if lam is None:
        return cv.mean
    R = shared_end(cv, lam) if remaining is None else np.asarray(remaining, dtype=np.float64)
    D = cv.family_array("traj", 0).shape[-1] if cv.names else 0
    out = np.empty((len(cv.names), len(cv.elapsed), len(cv.t_ahead), D))
    for i in range(len(cv.names)):  # each member placed into its rows (np.stack's values, without its copy)
        place_cases(cv.family_array("traj", i), member_units(cv.phase[i], cv.duration[i], cv.t_ahead, R,
                                                             cv.horizon), out=out[i])
    return out


def _blend_replaced(cv: CrossValidation, lam: float | str | None, per_step: np.ndarray,
                    remaining: ArrayLike | None = None) -> np.ndarray:
    """``_blend(replaced(cv, lam, remaining), per_step)`` member by member: each member's placed predictions weighted
    and added to the blend in turn, from zeros (the sums of :func:`_blend`'s einsum, in its order), without the
    ``(M, cases, H, D)`` array of all members."""
    if lam is None:
        return _blend(cv.mean, per_step)
    R = shared_end(cv, lam) if remaining is None else np.asarray(remaining, dtype=np.float64)
    out = placed = None
    for i in range(len(cv.names)):  # each member placed into one buffer in turn
        placed = place_cases(cv.family_array("traj", i),
                             member_units(cv.phase[i], cv.duration[i], cv.t_ahead, R, cv.horizon), out=placed)
        placed *= per_step[:, i][None, :, None]
        if out is None:
            out = np.zeros(placed.shape)
        out += placed
    return _blend(replaced(cv, lam, remaining), per_step) if out is None else out


def _order(names: Iterable[str], prefer: str) -> list[str]:
    """The candidates in the order :func:`one_se_choice` tries them: from the simplest (``prefer="simple"``) or
    from the fitted, most complex one (``prefer="fitted"``)."""
    if prefer not in PREFER:
        raise ValueError(f"prefer must be one of {PREFER}, got {prefer!r}")
    names = list(names)
    return names if prefer == "simple" else names[::-1]


def timing_choice(cv: CrossValidation, per_step: np.ndarray, lambdas: Iterable[float] = LAMBDAS,
                  prefer: str = PREFER[0], pace: tuple[str, ArrayLike] | None = None
                  ) -> tuple[float | str | None, dict[str, dict[str, float]]]:
    """``(lam, table)``: the blend's remaining duration beyond the real-time band, chosen on the rest of the movement.

    Candidates, from the simplest: with ``pace = (name, R)``, the partner's pace, the shared end ``R`` ``(cases,)``
    read from the family ``name`` alone (:func:`pace_remaining`; returned as ``lam = name``); the shared remaining
    duration of each ``lam`` of :data:`LAMBDAS` (:func:`remaining_duration`), then ``None`` (each member at its own
    duration).  The blend (per-step weights ``per_step`` ``(H, M)``) of each is scored on the rest of the movement
    in seconds over the held-out cases of ``cv``; :func:`one_se_choice` takes the first candidate within one
    standard error (over the held-out demonstrations) of the best, trying them from the simplest
    (``prefer="simple"``, the default: the partner's pace, else the clock's remaining duration, unless another is
    better by more than its noise) or from the members' own timing (``prefer="fitted"``)."""
    cands: dict[str, float | str | None] = {}
    errors: dict[str, np.ndarray] = {}
    if pace is not None:
        cands[pace[0]] = pace[0]
        errors[pace[0]] = _rest(cv, _blend_replaced(cv, pace[0], per_step, pace[1]))
    cands.update({f"{lam:g}": lam for lam in lambdas})
    cands["own"] = None
    errors.update({name: _rest(cv, _blend_replaced(cv, lam, per_step)) for name, lam in cands.items()
                   if name not in errors})
    name, table = one_se_choice(errors, cv.demo, _order(cands, prefer))
    return cands[name], table


def long_range_choice(cv: CrossValidation, W: ArrayLike, edges: Sequence[float], groups: int = 3,
                      prefer: str = PREFER[0], singles: bool = False
                      ) -> tuple[np.ndarray, list[float], str, dict[str, dict[str, float]]]:
    """``(W, edges, name, table)``: the blend's weights beyond the real-time band, chosen on the rest of the movement.

    Parameters
    ----------
    cv
        The inner cross-validation (:class:`~interprim.model_selection.stacking.CrossValidation`), its members'
        predictions placed as the blend will place them.
    W : ndarray, shape (bands, M)
        The weights fitted per band on all the cases (row 0: the real-time band, kept by every candidate).
    edges : sequence of float
        Upper edges (s) of the bands.
    groups : int
        The per-band weights are scored cross-fitted: fitted on the cases of the other ``groups - 1`` groups of
        held-out demonstrations (:func:`case_groups`), scored on this group's.
    singles : bool
        Also each family alone as a candidate (off by default: on the nested development folds a single family
        chosen on 12-20 recordings was the choice that went wrong, on three NuiSI interactions of six).
    prefer : {"simple", "fitted"}
        :func:`one_se_choice` takes the first candidate within one standard error of the best, trying them from
        the mean (``"simple"``, the default: a more complex candidate only when it is better by more than its
        noise) or from the per-band weights (``"fitted"``: a simpler candidate only when it is better by more than
        its noise).

    Returns
    -------
    W : ndarray, shape (bands, M)
        The chosen weights (row 0 unchanged; the other rows all equal for a candidate that holds one set).
    edges : list of float
        Their bands' upper edges: ``edges``, with a band after the real-time band for a candidate other than the
        per-band weights (:func:`keep_real_time`: the real-time band keeps the per-band schedule's weights).
    name : str
        ``"prior"``, a family, ``"real-time weights"`` or ``"per band"``.
    table : dict
        :func:`one_se_choice`'s table over the candidates.
    """
    W = np.asarray(W, dtype=np.float64)
    M = len(cv.names)
    t = cv.t_ahead
    W_rt, e_rt, n_first = keep_real_time(W, edges, cv.dt)  # the held candidates' bands
    cands = {"prior": held(W_rt, np.eye(M)[cv.names.index("prior")], n_first)} if "prior" in cv.names else {}
    if singles:
        cands.update({m: held(W_rt, np.eye(M)[i], n_first) for i, m in enumerate(cv.names) if m != "prior"})
    first = {m: _rest(cv, _blend(cv.mean, schedule(t, e_rt, Wm))) for m, Wm in cands.items()}
    order = (["prior"] if "prior" in cands else []) + sorted((m for m in cands if m != "prior"),
                                                             key=lambda m: first[m].mean())
    errors = {m: first[m] for m in order}
    cands["real-time weights"] = held(W_rt, W[0], n_first)
    errors["real-time weights"] = _rest(cv, _blend(cv.mean, schedule(t, e_rt, cands["real-time weights"])))
    if W.shape[0] > 1:
        g = case_groups(cv.demo, groups)
        crossed = np.zeros(len(g))
        for gi in np.unique(g):
            train, test = np.flatnonzero(g != gi), np.flatnonzero(g == gi)
            sub = cv.cases(train)
            steps = sub.band_steps(edges)
            Wg = np.array([W[0]] + [sub.blend_weights(s) if sub.valid[:, s].any() else W[i + 1]
                                    for i, s in enumerate(steps[1:])])
            crossed[test] = _rest(cv, _blend(cv.mean[:, test], schedule(t, edges, Wg)), test)
        errors["per band"] = crossed
    order = list(errors)  # from the simplest: the mean, the families (the best first), held, per band
    if _order(order, prefer) != order:  # from the fitted: per band, held, the families (the best first), the mean
        fitted = [m for m in ("per band", "real-time weights") if m in errors]
        order = fitted + [m for m in order if m not in fitted and m != "prior"] + [m for m in order if m == "prior"]
    name, table = one_se_choice(errors, cv.demo, order)
    if name == "per band":
        return W, list(edges), name, table
    return cands[name], e_rt, name, table


def past_cases(cv: CrossValidation, w_now: ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(P, T, mask)``: the robot's past as the blend reconstructs it on the cases of ``cv``.

    On the normalised-time grid ``u`` of the members' predictions (``cv.traj``), the blend's past is ``u < s``
    with ``s = w_now . s_m`` (its phase, the members' weighted with the real-time weights ``w_now``), where member
    ``m`` is read at ``u s_m / s`` (:class:`~interprim.models.blend.Blend`).  ``P`` (members, cases, G, C): each
    member there, the controlled agent's ``C`` columns; ``T`` (cases, G, C): the held-out demonstration on the
    grid (``cv.unit_truth``); ``mask`` (cases, G): the points before now."""
    w_now = np.asarray(w_now, dtype=np.float64)
    cols = cv.controlled or cv.observed
    G = cv.family_array("traj", 0).shape[1]
    u = np.linspace(0.0, 1.0, G)
    s = w_now @ cv.phase  # (cases,)
    mask = u[None, :] < s[:, None]
    scale = np.divide(cv.phase, s[None, :], out=np.ones_like(cv.phase), where=s[None, :] > 0)  # (M, cases)
    P = np.stack([place_cases(cv.family_array("traj", i)[..., cols], u[None, :] * scale[i][:, None])
                  for i in range(len(cv.names))])
    T = np.stack([cv.unit_truth[int(j)][:, cols] for j in cv.demo]) if len(cv.demo) else np.zeros((0, G, len(cols)))
    return P, T, mask


def _past_errors(P: np.ndarray, T: np.ndarray, mask: np.ndarray, w: np.ndarray, point_dim: int) -> np.ndarray:
    """``(cases,)``: the RMS point error over the past (``mask``) of the members ``P`` weighted with ``w``."""
    return case_rms(np.tensordot(w, P, axes=1), T, mask, range(T.shape[-1]), point_dim)


def _past_fit(P: np.ndarray, T: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Weights on the simplex minimising the mean over cases of the RMS error over the past
    (:func:`~interprim.model_selection.stacking.simplex_minimum` of
    :func:`~interprim.model_selection.stacking.case_rms_loss`, the stacking's loss on the past's points)."""
    from .stacking import case_rms_loss, simplex_minimum

    m = mask.astype(np.float64)
    E = P - T[None]  # (M, cases, G, C)
    K = np.einsum("cg,mcgk,ncgk->cmn", m, E, E)
    h = np.einsum("cg,mcgk,cgk->cm", m, E, T)
    t = np.einsum("cg,cgk->c", m, T * T)
    count = m.sum(axis=1) * T.shape[-1]
    keep = count > 0
    return simplex_minimum(case_rms_loss(K[keep], h[keep], t[keep], count[keep]), P.shape[0])[0]


def past_choice(cv: CrossValidation, w_now: ArrayLike, groups: int = 3
                ) -> tuple[np.ndarray | None, str, dict[str, dict[str, float]]]:
    """``(w, name, table)``: the blend's weights for the robot's past (before now, in normalised time).

    The paper's measure (Fig. 7) reads the robot's whole movement, most of which, from 60 % seen, is its past: what
    its partner's movement so far says it has done.  No look-ahead band scores it, and the real-time weights that
    place it otherwise may favour a member that follows the next quarter second well and reconstructs the past
    badly (the nearest demonstration on a periodic task).  Candidates: the real-time weights ``w_now`` (tried
    first: kept unless another candidate is better by more than its noise), the mean (``prior``, when among the
    members of ``cv``) and the weights fitted on the past (:func:`_past_fit`, scored cross-fitted: fitted on the
    cases of the other ``groups - 1`` groups of held-out demonstrations).  Each is scored by the RMS error over the
    past of every held-out case (:func:`past_cases`), and :func:`one_se_choice` takes the first within one
    standard error of the best, over the held-out demonstrations.

    Returns ``w`` None for the real-time weights (the blend as before), else ``(members,)`` on the simplex over
    ``cv.names``; ``name`` (``"real-time weights"``, ``"prior"`` or ``"fitted"``) and the choice's table.
    """
    w_now = np.asarray(w_now, dtype=np.float64)
    P, T, mask = past_cases(cv, w_now)
    rows = np.flatnonzero(mask.any(axis=1))
    name = "real-time weights"
    if len(cv.names) < 2 or len(np.unique(cv.demo[rows])) < 2:
        return None, name, {}
    P, T, mask, demo = P[:, rows], T[rows], mask[rows], cv.demo[rows]
    M = len(cv.names)
    cands: dict[str, np.ndarray] = {name: w_now}
    if "prior" in cv.names:
        cands["prior"] = np.eye(M)[cv.names.index("prior")]
    errors = {m: _past_errors(P, T, mask, w, cv.point_dim) for m, w in cands.items()}
    g = case_groups(demo, groups)
    crossed = np.zeros(len(g))
    for gi in np.unique(g):
        train, test = np.flatnonzero(g != gi), np.flatnonzero(g == gi)
        crossed[test] = _past_errors(P[:, test], T[test], mask[test], _past_fit(P[:, train], T[train], mask[train]),
                                     cv.point_dim)
    errors["fitted"] = crossed
    name, table = one_se_choice(errors, demo, list(errors))
    if name == "real-time weights":
        return None, name, table
    return (cands[name] if name in cands else _past_fit(P, T, mask)), name, table


def _full(st: Stacking, names: list[str]) -> np.ndarray:
    """``(bands, len(names))``: the weights of the stacking ``st`` over ``names`` (0 for the others)."""
    W = np.zeros((st.W.shape[0], len(names)))
    for i, m in enumerate(st.names):
        W[:, names.index(m)] = st.W[:, i]
    return W


def candidate_cases(cv: CrossValidation, fitted: Stacking, cost: Callable[[list[str]], float] | None = None,
                    budget: float | None = None) -> CrossValidation:
    """The cross-validation ``cv`` restricted to the families the long-range choice may use: the members the
    stacking ``fitted`` kept and the mean (``prior``, when compared and within the budget), with ``w0``, the
    real-time weights over them (what :func:`replaced` places the shared end with)."""
    allowed = list(fitted.names)
    if "prior" in cv.names and "prior" not in allowed and (
            cost is None or budget is None or cost(allowed + ["prior"]) <= budget):
        allowed.append("prior")
    out = cv.subset([m for m in cv.names if m in allowed])
    out.w0 = _full(fitted, list(out.names))[0]
    return out


def refine(cv: CrossValidation, fitted: Stacking, horizon: float, prefer: str = PREFER[0],
           cost: Callable[[list[str]], float] | None = None, budget: float | None = None,
           level: float | None = None, pace: str | None = PACE) -> tuple[Stacking, float | str | None]:
    """``(Stacking, remaining)``: the stacked blend ``fitted`` (:func:`~interprim.model_selection.stacking.stack` of
    ``cv``) with its remaining duration and its weights beyond the real-time band chosen on the rest of the
    movement (:func:`timing_choice`, then :func:`long_range_choice` on the predictions placed with that timing; the
    per-band weights are fitted again on them when the timing changed).

    ``remaining``: the chosen ``lam`` of :func:`remaining_duration` (``None``: each member at its own duration; a
    family's name: the shared end is that family's own remaining duration, the partner's pace of
    :func:`timing_choice`), for :class:`~interprim.models.blend.Blend`.  The returned
    :class:`~interprim.model_selection.stacking.Stacking` keeps the members carrying weight in some band (and the
    pace's family, of weight 0 in every band when it carries none, when it times the blend), its variance model
    fitted again with the chosen weights, and its ``record`` says what was chosen (``long_range``: ``remaining``,
    ``beyond``, ``past`` and the choices' tables; ``past_weights``: the weights of the robot's past,
    :func:`past_choice`, None for the real-time weights; a family weighted there alone joins at weight 0 in every
    band).

    ``pace``: the family whose own remaining duration is the first timing candidate (:data:`PACE`; None: no such
    candidate), offered when it was compared and, with a budget, when the blend's families and it fit in it.

    ``level``: the band's quantile level fixed
    (:meth:`~interprim.model_selection.stacking.CrossValidation.blend_scales`; default: chosen by cross-fitting).
    ``cost``, ``budget``: the frame budget of
    :func:`~interprim.model_selection.stacking.stack`.  The choice is
    made among the members ``fitted`` kept (within the budget) and the mean (``prior``, when compared and, with a
    budget, when it fits in it); a re-stacking keeps the budget; the record's ``cost`` is that of the members kept.
    """
    from .stacking import MIN_WEIGHT, Stacking, stack

    full_cv = cv
    cv = candidate_cases(cv, fitted, cost, budget)
    names = list(cv.names)

    def full(st: Stacking) -> np.ndarray:
        return _full(st, names)

    pace_R = None  # the partner's pace: the shared end read from the family ``pace`` alone (maybe not a candidate)
    if pace is not None and pace in full_cv.names and (
            cost is None or budget is None or cost(sorted(set(names) | {pace})) <= budget):
        i = full_cv.names.index(pace)
        pace_R = pace_remaining(full_cv.phase[i], full_cv.duration[i])  # the cases of ``cv``, in its order
    W = full(fitted)
    lam, t_table = timing_choice(cv, schedule(cv.t_ahead, fitted.edges, W), prefer=prefer,
                                 pace=None if pace_R is None else (str(pace), pace_R))
    R = pace_R if isinstance(lam, str) else None
    placed = cv
    if lam is not None:
        placed = cv.subset(names)  # every case and family: the cases' arrays shared, not copied
        placed.mean = replaced(cv, lam, R)
        fitted = stack(placed, horizon, cost=cost, budget=budget, scales=False)
        W = full(fitted)
    Wc, edges, beyond, b_table = long_range_choice(placed, W, list(fitted.edges), prefer=prefer)
    keep = [i for i in range(len(names)) if Wc[:, i].max() >= MIN_WEIGHT] or [int(np.argmax(Wc.max(axis=0)))]
    members = [names[i] for i in keep]
    Wk = Wc[:, keep]
    Wk = Wk / Wk.sum(axis=1, keepdims=True)
    sub = placed.subset(members)
    per_step = schedule(cv.t_ahead, edges, Wk)
    scales = sub.blend_scales(per_step, level=level)
    band_level = scales.pop("level")
    scales["t"] = cv.t_ahead
    blend_error = sub.blend_error(per_step)
    if isinstance(lam, str) and lam not in members:  # the pace's family times the blend at weight 0
        members.append(lam)
        Wk = np.hstack([Wk, np.zeros((Wk.shape[0], 1))])
    # the robot's past: the real-time weights unless another set is better by more than its noise (past_choice);
    # the mean may join at weight 0 in every band when it fits the budget
    offered = [m for m in names if m in members or (m == "prior" and (
        cost is None or budget is None or cost(members + ["prior"]) <= budget))]
    past_cv = placed.subset(offered)
    w_rt = np.array([Wk[0, members.index(m)] if m in members else 0.0 for m in past_cv.names])
    w_past, past_name, p_table = past_choice(past_cv, w_rt)
    past = None
    if w_past is not None:
        past = {m: float(w) for m, w in zip(past_cv.names, w_past) if w > 0.0}
        for m in past:
            if m not in members:  # a member for the past alone: weight 0 in every band
                members.append(m)
                Wk = np.hstack([Wk, np.zeros((Wk.shape[0], 1))])
    band_weights = {m: [float(x) for x in Wk[:, i]] for i, m in enumerate(members)}
    record = dict(fitted.record)
    record["inner_yardsticks"] = inner_yardsticks(
        placed, Wc, edges, lam, R, past=None if past is None else [past.get(m, 0.0) for m in names])
    record["past_weights"] = past
    record.update({"weights": {m: float(Wk[0, i]) for i, m in enumerate(members)}, "band_weights": band_weights,
                   "bands": edges, "blend_cv_error": blend_error, "band_level": band_level,
                   "variance_model": {k: np.asarray(v).tolist() for k, v in scales.items()},
                   "long_range": {"remaining": "own" if lam is None else lam if isinstance(lam, str)
                                  else float(lam), "beyond": beyond, "prefer": prefer,
                                  "remaining_table": t_table, "beyond_table": b_table,
                                  "past": past_name, "past_table": p_table}})
    if cost is not None and "cost" in record:
        record["cost"] = dict(record["cost"], frame=float(cost(members)))
    return Stacking(members, Wk, edges, scales, record), lam


def inner_yardsticks(cv: CrossValidation, W: ArrayLike, edges: ArrayLike, lam: float | str | None,
                     remaining: ArrayLike | None = None, past: ArrayLike | None = None) -> dict[str, list[float]]:
    """The blend's figures on the inner folds' held-out cases, as a user reads them on a hold-out.

    ``{label: [ratio, standard error]}`` over the held-out demonstrations (:func:`ratio_se`): real time (the
    next ``cv.horizon`` seconds) and the rest of the movement in seconds, each ÷ the clock and ÷ the mean at the
    true duration (known in a held-out fold), and the paper's Fig. 7 measure (the whole movement in normalised
    time from the case nearest 60 % seen of each held-out demonstration) ÷ the mean demonstration.  ``W``,
    ``edges``: the blend's weights per band; ``lam``: its remaining duration (:func:`refine`; ``remaining``: its
    shared end per case when given, else :func:`shared_end`); ``past``: its weights for the robot's past
    (:func:`past_choice`; None: the real-time weights); ``cv.mean``: the members placed with it.  Empty when
    the mean (``prior``) was not compared: its prediction is each inner fold's mean demonstration, the references'
    shape.
    """
    if "prior" not in cv.names or not len(cv.demo):
        return {}
    W = np.asarray(W, dtype=np.float64)
    t = cv.t_ahead
    per_step = schedule(t, edges, W)
    blend = _blend(cv.mean, per_step)
    mean = cv.family_array("traj", cv.names.index("prior"))
    k = np.rint(cv.elapsed / cv.dt).astype(np.int64) + 1
    n_frames = k + cv.valid.sum(axis=1)
    clock = place_cases(mean, clock_units(k, t, cv.dt, cv.mean_duration))
    true = place_cases(mean, true_duration_units(k, n_frames, t, cv.dt))
    cols = cv.controlled or cv.observed
    n_rt = max(1, int(round(cv.horizon / cv.dt)))
    rt = np.zeros_like(cv.valid)
    rt[:, :n_rt] = True
    out: dict[str, list[float]] = {}
    for label, mask in (("real time", rt), ("rest of the movement", cv.valid)):
        err = case_rms(blend, cv.truth, mask, cols, cv.point_dim)
        for ref, ref_pred in (("clock", clock), ("mean at the true duration", true)):
            out[f"{label} ÷ {ref}"] = list(ratio_se(err, case_rms(ref_pred, cv.truth, mask, cols, cv.point_dim),
                                                    cv.demo))
    # the paper's measure: per held-out demonstration, the case nearest 60 % seen, on normalised time
    frac = (k - 1) / np.maximum(n_frames - 1, 1)
    G = mean.shape[1]
    u = np.linspace(0.0, 1.0, G)
    w_now = W[0] / W[0].sum()
    R_all = None  # a shared end per case, when it is not the members' of the weights w_now (below)
    if remaining is not None:
        R_all = np.asarray(remaining, dtype=np.float64)
    elif isinstance(lam, str):
        R_all = shared_end(cv, lam)
    wm_blend: list[float]
    wm_mean: list[float]
    wm_blend, wm_mean = [], []
    for j in np.unique(cv.demo):
        c = np.flatnonzero(cv.demo == j)[np.argmin(np.abs(frac[cv.demo == j] - 0.6))]
        sm, Dm = cv.phase[:, c], cv.duration[:, c]
        s, D = float(w_now @ sm), float(w_now @ Dm)
        R = None
        if lam is not None:
            R = float(R_all[c]) if R_all is not None else float(remaining_duration(
                sm[:, None], Dm[:, None], [cv.elapsed[c]], cv.mean_duration[c], w_now, float(lam))[0])
            D = R / (1.0 - s) if s < 1.0 - 1e-9 else D
        ahead = np.clip((u - s) * D, 0.0, None)
        Wu = np.clip(interp_columns(ahead, t, per_step), 0.0, None)
        Wu = Wu / np.maximum(Wu.sum(axis=1, keepdims=True), 1e-300)
        if past is not None:
            Wu[u < s] = np.asarray(past, dtype=np.float64)
        Y = np.zeros((G, mean.shape[2]))
        for i in range(len(cv.names)):
            future = (np.clip(sm[i] + ahead / Dm[i], 0.0, 1.0) if R is None
                      else member_units([sm[i]], [Dm[i]], ahead, [R], cv.horizon)[0])
            um = np.where(u >= s, future, u * (sm[i] / s if s > 0 else 1.0))
            Y += Wu[:, i:i + 1] * place_cases(cv.family_array("traj", i)[c][None], um[None])[0]
        truth = cv.unit_truth[int(j)]
        wm_blend.append(case_rms(Y[None], truth[None], np.ones((1, G), bool), cols, cv.point_dim)[0])
        wm_mean.append(case_rms(mean[c][None], truth[None], np.ones((1, G), bool), cols, cv.point_dim)[0])
    out["whole movement at 60 % ÷ the mean demonstration"] = list(ratio_se(wm_blend, wm_mean))
    return out


def summary_lines(record: Mapping[str, Any]) -> list[str]:
    """Lines of :meth:`~interprim.models.auto.AutoInteraction.summary` about the long-range choice (``record``: its
    ``selection_``)."""
    lr = record.get("long_range")
    if not lr:
        return []
    rem = lr["remaining"]
    timing = ("each member at its own duration" if rem == "own" else
              f"one shared end, {rem}'s own remaining duration (the partner's pace)"
              if isinstance(rem, str) else
              f"one shared end, the members' remaining duration shrunk {1 - float(rem):.0%} toward the clock's")
    out = [f"beyond the real-time band: {lr['beyond']} (chosen on the rest of the movement, one-standard-error "
           f"rule from the {'fitted' if lr.get('prefer') == 'fitted' else 'simplest'} end); timing: {timing}"]
    if "past" in lr:
        pw = record.get("past_weights")
        out.append(f"the robot's past: {lr['past']}" + ("" if not pw else " (" + ", ".join(
            f"{m} {w:.2f}" for m, w in pw.items()) + ")") + " (chosen on the past's error, one-standard-error rule "
            "from the real-time weights)")
    ys = record.get("inner_yardsticks") or {}
    if ys:
        out.append("inner folds: " + "; ".join(f"{k} {v[0]:.2f} ± {v[1]:.2f}" for k, v in ys.items()))
    return out

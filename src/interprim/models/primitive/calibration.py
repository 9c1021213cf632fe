"""Calibrated predictive uncertainty: scale the posterior spread so that it matches held-out errors.

The posterior of Eq. 18 says how uncertain the parameters ``theta`` are *if* the model is right: a Gaussian
prior estimated from a few dozen demonstrations (regularised, Eq. 10), an observation noise ``sigma^2``
chosen for the mean's accuracy, and a phase taken as known.  On real recordings none of that holds exactly:
shrinkage of the covariance towards its diagonal breaks the strong negative correlations of neighbouring
DMP weights and widens the trajectory band many times (NuiSI: the predicted std was ~14x the actual error),
while phase errors make the real error larger than the posterior admits where timing matters.

:class:`Calibration` measures the actual errors on held-out folds of the *training* demonstrations
(:func:`held_out_sums`, :func:`fold_model`), with the phase the model itself estimates (so timing errors
count), the way a robot uses a prediction (:mod:`interprim.evaluation.realtime`): after the first ``p`` of a
held-out demonstration, the frame ``j`` steps after the last observed one is compared with the prediction at
normalised time ``s + h``, look-ahead ``h = j dt / D``, with the model's own phase ``s`` and duration ``D``;
the observed past (``j <= 0``) is compared the same way.  When the demonstrations carry their raw samples (an
irregular recording interpolated onto the grid, as NuiSI, whose partner is tracked at ~9 Hz on a 20 Hz grid), each
held-out case sees its causal prefix (:class:`~interprim.model_selection.prefixes.Prefixes`: only the samples
recorded by its last frame, the last one held), as a robot does; calibrated on the uncut interpolation instead,
which hands every prefix the partner's next sample, the partner's band over the next 0.25 s covered 65-88 % under
causal prefixes on NuiSI's development recordings, and 82-89 % calibrated on causal prefixes (three contiguous
folds; the means unchanged).

How far the posterior std is off depends on where one looks: the observed agent's next frames are pinned by
the frames just seen and its far future is not; a DoF that barely moves (a shoulder) is predicted relatively
better than a hand; and the balance changes with the fraction seen.  One scale per agent and fraction fitted
on the whole remaining movement (the calibration before format version 3) left the human's own 90 % band
over the next 0.25 s covering 70-77 % on NuiSI (RMS error / RMS std ~1.8).  So the calibrated std of column
``d`` at normalised time ``u`` of a prediction at estimated phase ``s`` is ``c_a(s, h) r_d(s, h) std`` with
``h = u - s`` (:meth:`Calibration.column_factors`; ``a`` the agent of ``d``), on nodes at the fractions
``p`` (0.1 ... 0.9) and the look-ahead bins (0, 0.02, 0.05, 0.1, 0.2, 0.4, 1 of normalised time, mirrored for
the past; a node sits at its bin's mean look-ahead), interpolated linearly, held at the ends.  Every scale is
a ratio of held-out sums ``c^2 = sum err^2 / sum std^2`` (columns divided by their spread over the
demonstrations, so that no DoF dominates an agent's), and every level is shrunk towards the one above by
empirical Bayes (:func:`_shrink`) with the leave-one-demonstration-out variance of its logarithm, so a
noisy cell (few demonstrations: 19-30 per NuiSI interaction) keeps only the part of its deviation that
exceeds its sampling noise, with no tuned constant:

1. ``c_a(p)``: the agent over all look-aheads at fraction ``p`` (the former calibration);
2. ``c_a(p, h)``: the agent per (fraction, look-ahead) cell, shrunk towards level 1;
3. ``c_a(p, h) r_d(p, h)``: every column per cell, shrunk towards ``c_a(p, h) exp(alpha_d)``, with the column's
   offset ``alpha_d`` over all cells (itself shrunk towards 0).

Held-out cases count at the fraction nodes by the phase the fold model *estimated* (linear weights), the value
the factor is looked up with.  ``clip`` bounds every scale (a guard against a degenerate fold).  Because the
held-out errors shrink as more is seen, the calibrated band shrinks with them, whether or not the posterior
does.

Measured (docs/evaluation.md, *Calibration per look-ahead and per column*): NuiSI v1, default model, 5-fold
real-time protocol, next 0.25 s, 20-90 % seen: the 90 % band covers 0.89-0.90 of the human's coordinates (was
0.70-0.77 with one scale per agent and fraction; 0.99 on handshake2) and 0.86-0.91 of the robot's (was
0.87-1.00); RMS error / RMS std per 10 % seen within 0.7-1.3 in 81 of 84 cells (worst: the robot's last 10 % of
rocket1, 1.47).  Synthetic set and simulated high five: 0.88-0.92 coverage (were 0.92-0.97, a band too wide).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...core.cv import folds, observed_frames
from ...core.preprocessing import interp_columns

__all__ = ["Calibration", "fit_calibration", "fold_model"]

DEFAULT_FRACTIONS = (0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9)


@dataclass
class Calibration:
    """Scale of the posterior std per column, as a function of the fraction seen and of the look-ahead.

    The calibrated std of column ``d`` at normalised time ``u``, for a prediction at estimated phase ``s``, is
    ``c_a(s, h) * r_d(s, h) * std`` with the look-ahead ``h = u - s``, ``a`` the agent of ``d`` and ``r_d`` the
    column's factor relative to its agent (both interpolated linearly in ``s`` and ``h``, held at the ends).

    Attributes
    ----------
    fractions : ndarray, shape (F,)
        Fractions of the movement seen at which the scales were measured (increasing).
    scale_observed, scale_controlled : ndarray, shape (F, H) or (F,)
        ``c_a(p, h)`` of the observed and of the controlled agent at the fractions and look-aheads; ``(F,)``
        (files written before look-ahead-aware calibration): the same at every look-ahead.
    n_cases : int
        Held-out (demonstration, fraction) cases the scales were measured on.
    lookaheads : ndarray, shape (H,), optional
        Look-aheads ``h = u - s`` in normalised time (negative: the observed past) of the scales' columns
        (increasing); ``None`` for one-dimensional scales.
    column_scale : ndarray, shape (F, H, D), optional
        ``r_d(p, h)``: the factor of every data column relative to its agent's; ``None``: all 1.
    """

    fractions: np.ndarray
    scale_observed: np.ndarray
    scale_controlled: np.ndarray
    n_cases: int = 0
    lookaheads: np.ndarray | None = None
    column_scale: np.ndarray | None = None

    def _profile(self, scale, phase: float, h):
        """``scale`` (``(F,)`` or ``(F, H, ...)``) at ``phase`` and look-aheads ``h``: shape ``h.shape + (...)``."""
        p = float(np.clip(phase, self.fractions[0], self.fractions[-1]))
        scale = np.asarray(scale, dtype=np.float64)
        i = int(np.clip(np.searchsorted(self.fractions, p, side="right") - 1, 0, max(self.fractions.size - 2, 0)))
        t = 0.0 if self.fractions.size == 1 else (p - self.fractions[i]) / (self.fractions[i + 1] - self.fractions[i])
        row = scale[i] if t == 0.0 else (1 - t) * scale[i] + t * scale[i + 1]
        if scale.ndim == 1 or self.lookaheads is None:
            return np.full(np.shape(h), float(row))
        h = np.asarray(h, dtype=np.float64)
        if row.ndim == 1:
            return np.interp(h, self.lookaheads, row)  # held at the ends
        return interp_columns(h, self.lookaheads, row)

    def factors(self, phase: float, lookahead=0.0):
        """``(c_observed, c_controlled)`` at an estimated phase and look-ahead(s) ``h`` (normalised time after
        the phase; an array gives arrays): linear interpolation in both, held at the ends.  Without the
        per-column ``column_scale``."""
        h = np.asarray(lookahead, dtype=np.float64)
        c_o, c_c = self._profile(self.scale_observed, phase, h), self._profile(self.scale_controlled, phase, h)
        return (float(c_o), float(c_c)) if h.ndim == 0 else (c_o, c_c)

    def column_factors(self, phase: float, u, observed_dofs, controlled_dofs) -> np.ndarray:
        """Factors ``(len(u), D)`` of the calibrated std at normalised times ``u`` of a prediction at ``phase``."""
        u = np.asarray(u, dtype=np.float64)
        c_o, c_c = self.factors(phase, u - float(phase))
        obs, ctrl = list(observed_dofs), list(controlled_dofs)
        f = np.empty((u.size, len(obs) + len(ctrl)))
        f[:, obs] = np.asarray(c_o).reshape(-1, 1)
        f[:, ctrl] = np.asarray(c_c).reshape(-1, 1)
        if self.column_scale is not None:
            f *= self._profile(self.column_scale, phase, u - float(phase)).reshape(u.size, -1)
        return f

    def to_arrays(self) -> dict:
        """The calibration as plain numeric arrays (for the model file; inverse of :meth:`from_arrays`)."""
        out = {"fractions": np.asarray(self.fractions, dtype=np.float64),
               "scale_observed": np.asarray(self.scale_observed, dtype=np.float64),
               "scale_controlled": np.asarray(self.scale_controlled, dtype=np.float64),
               "n_cases": np.asarray(self.n_cases, dtype=np.int64)}
        if self.lookaheads is not None:
            out["lookaheads"] = np.asarray(self.lookaheads, dtype=np.float64)
        if self.column_scale is not None:
            out["column_scale"] = np.asarray(self.column_scale, dtype=np.float64)
        return out

    @classmethod
    def from_arrays(cls, d) -> Calibration:
        """Rebuild a calibration from the arrays written by :meth:`to_arrays` (a mapping of the names;
        ``lookaheads`` and ``column_scale`` may be absent: a calibration written before they existed)."""
        opt = {k: (np.asarray(d[k], dtype=np.float64) if k in d else None) for k in ("lookaheads", "column_scale")}
        return cls(np.asarray(d["fractions"], dtype=np.float64), np.asarray(d["scale_observed"], dtype=np.float64),
                   np.asarray(d["scale_controlled"], dtype=np.float64), int(d["n_cases"]), **opt)

    def problem(self, n_dofs: int | None = None) -> str | None:
        """What is inconsistent in the arrays (shapes, order, non-positive scales), or ``None``."""
        F = self.fractions
        if F.ndim != 1 or F.size < 1 or not np.all(np.isfinite(F)) or not np.all(np.diff(F) > 0):
            return "fractions are not increasing finite numbers"
        shape = (F.size,) if self.lookaheads is None else (F.size, self.lookaheads.size)
        if self.lookaheads is not None and (self.lookaheads.ndim != 1 or not np.all(np.diff(self.lookaheads) > 0)):
            return "lookaheads are not increasing"
        for name in ("scale_observed", "scale_controlled"):
            c = getattr(self, name)
            if c.shape != shape:
                return f"{name} has shape {c.shape}, expected {shape}"
            if not (np.all(np.isfinite(c)) and np.all(c > 0)):
                return f"{name} holds non-positive or non-finite scales"
        if self.column_scale is not None:
            want = shape + ((n_dofs,) if n_dofs is not None else self.column_scale.shape[-1:])
            if self.lookaheads is None or self.column_scale.shape != want:
                return f"column_scale has shape {self.column_scale.shape}, expected {want} (with lookaheads)"
            if not (np.all(np.isfinite(self.column_scale)) and np.all(self.column_scale > 0)):
                return "column_scale holds non-positive or non-finite factors"
        return None


def _fill(x):
    """Replace NaNs by linear interpolation between measured neighbours (held at the ends); all NaN -> 1."""
    x = np.asarray(x, dtype=np.float64).copy()
    ok = np.isfinite(x)
    if not ok.any():
        return np.ones_like(x)
    idx = np.arange(x.size)
    x[~ok] = np.interp(idx[~ok], idx[ok], x[ok])
    return x


def _shrink(est, var, parent):
    """Empirical-Bayes shrinkage of noisy estimates ``est`` (sampling variances ``var``) towards ``parent``:
    the spread of the true deviations ``tau^2`` is the spread of the observed ones less the mean sampling
    variance (method of moments, at least 0); each estimate keeps the share ``tau^2 / (tau^2 + var)`` of its
    deviation.  NaN estimates stay NaN."""
    dev = est - parent
    ok = np.isfinite(dev) & np.isfinite(var)
    if not ok.any():
        return np.where(np.isfinite(est), parent, np.nan)
    tau2 = max(0.0, float(np.mean(dev[ok] ** 2) - np.mean(var[ok])))
    w = np.where(ok, tau2 / (tau2 + np.where(ok, var, 1.0) + 1e-300), 0.0)
    return np.where(np.isfinite(est), parent + w * np.where(ok, dev, 0.0), np.nan)


def _log_ratio(E, V, axis):
    """``0.5 log(sum E / sum V)``, the sums over demonstrations (the first axis) and ``axis``, and its
    leave-one-demonstration-out (jackknife) variance (``inf`` where fewer than two demonstrations count)."""
    e, v = E.sum(axis=axis), V.sum(axis=axis)  # (S, ...)
    te, tv = e.sum(0), v.sum(0)
    with np.errstate(invalid="ignore", divide="ignore"):
        est = 0.5 * np.log(te / tv)
        # a demonstration whose share of a sum is at rounding level (a std of 0 in one path, 1e-17 in another) or is
        # (almost) all of it is left out of the jackknife: either would make its variance depend on the last bits
        rest_e, rest_v = te - e, tv - v
        tol = 1e-9
        sane = (v > tol * tv) & (rest_v > tol * tv) & (rest_e > tol * te)
        loo = np.where(sane, 0.5 * np.log(rest_e / np.where(sane, rest_v, 1.0)), np.nan)  # (S, ...)
        ok = np.isfinite(loo)
        n = ok.sum(0)
        mu = np.where(ok, loo, 0.0).sum(0) / np.maximum(n, 1)
        var = (n - 1) / np.maximum(n, 1) * np.where(ok, (loo - mu) ** 2, 0.0).sum(0)
    est = np.where(np.isfinite(est), est, np.nan)
    var = np.where((n >= 2) & np.isfinite(var), var, np.inf)
    return est, var


def fold_model(model, keep, observed=None):
    """A copy of a fitted ``model`` whose prior (Eq. 10) is re-estimated from the demonstrations ``keep`` only,
    with the hyper-parameters ``model`` chose (shrinkage ``lambda``, cross-agent damping ``gamma``, ``sigma^2``,
    phase noise): the model a fold of cross-validation would have, without repeating the selection.

    The DMP basis, PCA, start state and DTW reference stay those of ``model`` (they use all demonstrations: a
    small optimism of the calibration, far smaller than the prior's share).  A learned phase model
    (``phase_model_``) is refitted on the kept demonstrations' observed columns ``observed`` (one array per
    demonstration, the model's latent space) when given: it is fitted on the very prefixes it is asked about,
    and kept as is it would make the held-out timing, and so the calibrated band, optimistic."""
    from ...core.gaussian import fit_prior, shrink_cross

    keep = np.asarray(keep, dtype=np.intp)
    thetas = model.thetas_[keep]
    durations = model.durations_[keep]
    lam = float(model.prior_.shrinkage) if model.covariance == "shrinkage" else None
    prior = fit_prior(thetas, model.covariance, model.ridge, shrinkage=lam)
    gamma = float((getattr(model, "selection_", None) or {}).get("cross_shrinkage", 0.0) or 0.0)
    shrink_cross(prior, gamma, model.n_observed_latent_ * model.params_per_dof_)
    phase_model = getattr(model, "phase_model_", None)
    if observed is not None and phase_model is not None:
        from ...phase.learned import LearnedPhase

        phase_model = LearnedPhase(**phase_model.get_params()).fit([observed[i] for i in keep], dt=model.dt_)
    return model.with_fitted(thetas_=thetas, durations_=durations, mean_duration_=float(durations.mean()),
                             n_demos_=int(keep.size), prior_=prior, calibration_=None, phase_model_=phase_model)


LOOKAHEAD_EDGES = (0.0, 0.02, 0.05, 0.1, 0.2, 0.4, 1.0)


def held_out_sums(model, demos, n_folds: int = 5, fractions=DEFAULT_FRACTIONS, edges=LOOKAHEAD_EDGES,
                  prefixes=None):
    """Held-out squared errors and predicted variances of a fitted ``model``, per demonstration, fraction seen,
    look-ahead bin and agent (the raw material of :func:`fit_calibration`).  Each held-out case sees the first
    frames of its demonstration's observed columns, or with ``prefixes`` (``prefixes(j, k)``: what a robot had of
    demonstration ``j`` at its ``k``-th frame, :class:`~interprim.model_selection.prefixes.Prefixes`) its causal
    prefix; the errors are always against the demonstration's own frames.

    Returns ``(sums, hsum, phases)``: ``sums`` of shape ``(S, F, B, D, 3)`` holds, for demonstration ``j`` held
    out, fraction ``i`` seen, look-ahead bin ``b`` (past bins ``-edges`` reversed, then future bins ``edges``)
    and data column ``d``, ``[sum err^2, sum std^2, count]`` over frames (each column divided by its spread over
    the demonstrations); ``hsum`` ``(B, 2)`` the sum of look-aheads and the count of frames per bin (their mean
    places the bin's node); ``phases`` ``(S, F)`` the phase the fold model estimated in each case."""
    demos = [np.asarray(d, dtype=np.float64) for d in demos]
    S = len(demos)
    dt = float(model.dt_)
    obs = [int(i) for i in model.observed_dofs_]
    observed = None
    if getattr(model, "phase_model_", None) is not None:  # refitted per fold (fold_model)
        n_o = model.n_observed_latent_
        observed = [np.asarray(model.observed_to_latent(d[:, obs]))[:, :n_o] for d in demos]
    D = demos[0].shape[1]
    spread = np.std(np.concatenate(demos, axis=0), axis=0)
    spread = np.where(spread > 0, spread, 1.0)
    e = np.asarray(edges, dtype=np.float64)
    allEdges = np.concatenate([-e[::-1], e[1:]])  # past bins then future bins; 0 closes the last past bin
    B = allEdges.size - 1
    fr = np.asarray(fractions, dtype=np.float64)
    sums = np.zeros((S, fr.size, B, D, 3))
    phases = np.zeros((S, fr.size))
    hsum = np.zeros((B, 2))
    n = 101
    grid = np.linspace(0.0, 1.0, n)
    # the fewest frames from which a robot had recorded the partner (1 without raw samples)
    first = [1 if prefixes is None else prefixes.first_frame(j) for j in range(S)]
    for held in folds(S, n_folds, "contiguous"):
        held_set = set(held.tolist())
        m = fold_model(model, [i for i in range(S) if i not in held_set], observed)
        for j in held:
            d = demos[j]
            T = d.shape[0]
            for i, p in enumerate(fr):
                M = observed_frames(T, p, keep=1)  # at least one frame left to score
                if M < first[j]:
                    continue  # nothing of the partner recorded yet: no prediction a robot could make
                pred = m.predict(d[:M, obs] if prefixes is None else prefixes(j, M))
                s = phases[j, i] = float(pred.normalised_time)
                h = (np.arange(T) - (M - 1)) * dt / float(pred.duration)
                # the past the grid can show; the first frame sits at s + h = 0 up to rounding (the phase is its elapsed
                # time over the duration), so a tolerance keeps it in or out whatever path computed s
                keep = (s + h >= -1e-9) & (h > allEdges[0]) & (h <= allEdges[-1])
                fut = np.arange(T)[keep]
                h = h[keep]
                u = np.clip(s + h, 0.0, 1.0)
                b = np.clip(np.searchsorted(allEdges, h, side="left") - 1, 0, B - 1)  # (lo, hi] bins
                Y = pred.trajectory(n)
                Sd = pred.std(n, calibrated=False)
                err = (interp_columns(u, grid, Y) - d[fut]) / spread
                sd = interp_columns(u, grid, Sd) / spread
                np.add.at(hsum[:, 0], b, h)
                np.add.at(hsum[:, 1], b, 1.0)
                np.add.at(sums[j, i, :, :, 0], b, err ** 2)
                np.add.at(sums[j, i, :, :, 1], b, sd ** 2)
                np.add.at(sums[j, i, :, :, 2], b, 1.0)
    return sums, hsum, phases


def _tent(x, nodes):
    """Linear-interpolation weights ``(..., K)`` of values ``x`` on increasing ``nodes`` (held at the ends)."""
    x = np.clip(np.asarray(x, dtype=np.float64), nodes[0], nodes[-1])
    if nodes.size == 1:
        return np.ones(x.shape + (1,))
    k = np.clip(np.searchsorted(nodes, x, side="right") - 1, 0, nodes.size - 2)
    t = (x - nodes[k]) / (nodes[k + 1] - nodes[k])
    w = np.zeros(x.shape + (nodes.size,))
    np.put_along_axis(w, k[..., None], (1 - t)[..., None], axis=-1)
    np.put_along_axis(w, (k + 1)[..., None], t[..., None], axis=-1)
    return w


def _estimate(sums, hsum, agents, clip):
    """Scales from :func:`held_out_sums` (summed at the fraction nodes): ``(c_observed, c_controlled)`` of shape
    ``(F, H)``, the look-ahead nodes ``(H,)`` and the relative column factors ``r (F, H, D)`` (module docstring).

    ``log c_a(p, h) = beta_a(p, h)`` and the column offsets ``alpha_d`` are fitted by alternating ratios of sums
    (``beta`` per agent from all its columns, ``alpha`` per column from all cells); ``alpha`` is shrunk towards
    0, ``beta(p, h)`` towards the agent's scale at ``p`` over all look-aheads and each column's own cell towards
    ``alpha_d + beta_a(p, h)``, all by :func:`_shrink` with jackknife variances over held-out demonstrations."""
    E, V = sums[..., 0], sums[..., 1]  # (S, F, B, D)
    D = E.shape[-1]
    alpha = np.zeros(D)
    beta = {}
    for it in range(3):
        w = np.exp(2 * alpha)
        for a, cols in enumerate(agents):
            if cols:
                beta[a] = _log_ratio(E[..., cols], V[..., cols] * w[cols], axis=3)[0]  # (F, B)
        if it == 2:
            break
        bfull = np.zeros(E.shape[1:])  # (F, B, D)
        for a, cols in enumerate(agents):
            if cols:
                bfull[..., cols] = np.nan_to_num(beta[a])[..., None]
        est, var = _log_ratio(E, V * np.exp(2 * bfull), axis=(1, 2))  # (D,)
        for cols in agents:
            if cols:
                e = est[cols] - np.nanmean(est[cols])
                alpha[cols] = np.nan_to_num(_shrink(e, var[cols], 0.0)) if it == 1 else np.nan_to_num(e)
                alpha[cols] -= np.mean(alpha[cols])
    w = np.exp(2 * alpha)
    keep = hsum[:, 1] > 0
    nodes = hsum[keep, 0] / hsum[keep, 1]
    F, B = E.shape[1], int(keep.sum())
    scales = []
    col = np.ones((F, B, D))
    with np.errstate(invalid="ignore", divide="ignore"):
        own, own_var = _log_ratio(E, V, axis=())  # (F, B, D): every column on its own
    for cols in agents:
        if not cols:
            scales.append(np.ones((F, B)))
            continue
        Ea, Va = E[..., cols].sum(-1), (V[..., cols] * w[cols]).sum(-1)  # (S, F, B)
        cell, var = _log_ratio(Ea[..., None], Va[..., None], axis=3)  # (F, B)
        parent = _log_ratio(Ea, Va, axis=2)[0]  # (F,): the whole remaining movement and the past, pooled
        parent = np.log(_fill(np.exp(parent)))
        b = _shrink(cell, var, parent[:, None])
        b = np.log(np.array([_fill(np.exp(r)) for r in b]))  # unmeasured look-aheads: interpolated
        c = np.clip(np.exp(b[:, keep]), *clip)
        scales.append(c)
        # each column's own deviation from alpha_d + beta(p, h), shrunk by the same rule (a DoF whose share of
        # the error changes with the fraction seen or the look-ahead)
        par = b[..., None] + alpha[cols]  # (F, B, n_a)
        lc = _shrink(own[..., cols], own_var[..., cols], par)
        lc = np.where(np.isfinite(lc), lc, par)[:, keep]
        col[..., cols] = np.clip(np.exp(lc), *clip) / c[..., None]
    return scales, nodes, col


def fit_calibration(model, demos, n_folds: int = 5, fractions=DEFAULT_FRACTIONS, min_demos: int = 6,
                    clip=(1e-3, 1e3), edges=LOOKAHEAD_EDGES, prefixes=None) -> Calibration | None:
    """Measure :class:`Calibration` of a fitted ``model`` by ``n_folds``-fold cross-validation on its own
    training demonstrations (:func:`fold_model`: the prior re-estimated without the held-out fold).

    Parameters
    ----------
    model : FittedPrimitive
        Fitted on ``demos``.
    demos : list of ndarray, shape (T_i, D)
        The training demonstrations in data columns, at ``model.dt_``.
    n_folds : int
        Folds (``"contiguous"`` runs of :func:`interprim.core.cv.folds`; at most one per demonstration).
    fractions : sequence of float
        Fractions of each held-out demonstration observed.
    min_demos : int
        With fewer demonstrations no calibration is fitted (``None``): the scales would be noise.
    clip : (float, float)
        Bounds of a scale (a guard against a degenerate fold).
    edges : sequence of float
        Look-ahead bins in normalised time (from 0, increasing; mirrored for the observed past).
    prefixes : Prefixes, optional
        The demonstrations' causal observed prefixes (:class:`~interprim.model_selection.prefixes.Prefixes` of
        demonstrations with their raw samples): a held-out case sees only the samples recorded by its last frame,
        as a robot does, so the band is calibrated on the stale last frame of a partner tracked slower than the
        grid.  Without it, the first frames of the demonstration.

    Returns
    -------
    Calibration or None
    """
    if len(demos) < min_demos:
        return None
    sums, hsum, phases = held_out_sums(model, demos, n_folds, fractions, edges, prefixes)
    fr = np.asarray(fractions, dtype=np.float64)
    sums = np.einsum("sik,si...->sk...", _tent(phases, fr), sums)  # re-binned by the phase the model estimated
    agents = ([int(i) for i in model.observed_dofs_], [int(i) for i in model.controlled_dofs_])
    (c_o, c_c), nodes, col = _estimate(sums, hsum, agents, clip)
    return Calibration(fr, c_o, c_c, int(sums.shape[0] * sums.shape[1]), lookaheads=nodes, column_scale=col)

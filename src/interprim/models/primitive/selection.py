"""Choosing the observation noise ``sigma^2`` and the covariance shrinkage from the data.

A plain Interaction Primitive has two numbers that decide whether conditioning
helps or hurts: the observation noise ``sigma^2`` of Eq. 16 and the
regularisation of the covariance of Eq. 10, which is estimated from fewer
demonstrations than it has entries.  A fixed ``sigma^2`` is right for one data
set at most, and an under-regularised covariance holds spurious correlations
that conditioning follows.  :func:`select_hyperparameters` picks both per
model by K-fold cross-validation on the training demonstrations:

1. split the demonstrations into ``n_folds`` folds; for every fold fit the
   prior (Eq. 10) on the others with each candidate shrinkage ``lambda``;
2. for every held-out demonstration observe the first 20/40/60/80 % of the
   observed agent (at the phase the model will estimate: the open-end DTW
   phase against the fold's own reference for ``phase_method="dtw"``, the
   true phase for the accurate likelihood phase), condition (Eq. 16-18) with every
   candidate ``sigma^2`` and predict the whole movement of *all* DoFs (both
   agents) by integrating the DMPs from the start;
3. score every candidate by the mean squared error of those predictions, per
   agent, each DoF divided by its variance over the demonstrations; keep the
   ``(lambda, sigma^2)`` whose observed-agent error is within one standard error
   of its best (the human's completion never pays for the robot's beyond its
   noise); among those, score the *controlled* agent (the robot's response is
   what conditioning is for: one score of all DoFs let the observed agent, with
   most of the DoFs, choose ``sigma^2`` and the shrinkage) and keep the most
   conservative ``gamma`` (the largest) within one standard error of its best,
   with its best ``(lambda, sigma^2)`` at that ``gamma`` (ties, as with
   ``gamma = 1``, broken by the observed agent's error) (Hastie et al.'s
   one-standard-error rule: a few dozen demonstrations make the CV noisy), the standard
   error being that of the paired per-case differences from the best candidate
   (:func:`interprim.core.cv.within_one_se`; every candidate is scored on the same held-out cases, so their own
   spread cancels: the unpaired standard error counted it and kept ``gamma = 1``, the prior mean, on NuiSI,
   where the coupling helps).  ``gamma`` in [0, 1] shrinks the *cross-agent* block of the
   covariance (observed x controlled) towards zero: the controlled agent's
   posterior mean moves from the prior mean by ``(1 - gamma)`` times the
   conditioned shift, so spurious correlations between the agents (few
   demonstrations, noisy data) are damped without giving up conditioning on
   the observed agent itself; ``gamma = 1`` predicts the controlled agent by
   its prior mean.  The largest ``sigma^2`` candidates (10^6 x the
   observation's scale) leave the prior practically unchanged, so the
   selection can always fall back to the prior mean when conditioning does
   not help on held-out data.

All ``sigma^2`` candidates cost one eigendecomposition per (fold, ``lambda``,
held-out demo, fraction): with ``A0 = L Sigma L^T`` (compressed observation,
see :mod:`interprim.core.gaussian`) ``= U diag(e) U^T`` the posterior mean for any
``sigma^2`` is ``mu + Sigma L^T U diag(1 / (e + sigma^2)) U^T r``.

The same loop gives the held-out marginal likelihood of the *positions* of the
observation for every ``sigma^2``; with ``phase_cases=0`` its maximiser is the position noise
``phase_sigma2_`` used by the likelihood phase estimator
(:mod:`interprim.phase.likelihood`).  By default that noise is the one under which the likelihood phase is most
accurate on held-out cases, and the log-likelihood is a record (``phase_log_likelihood``); a fit inside
:func:`interprim.core.cache.records_unused` (the default model's inner cross-validation, which discards its fits
after scoring their means) leaves it out (``None``): its log-determinants were about a tenth of the selection's cost.

The choice is reported in ``model.selection_``.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ...core.blas import single_thread
from ...core.cache import records_skipped
from ...core.cv import fold_labels, observed_frames, within_one_se
from ...core.cv import n_folds as _n_folds
from ...core.gaussian import (
    GaussianPrior,
    compress_observation,
    fit_prior,
    lowrank_case,
    lowrank_cases,
    shrink_cross,
    shrinkage_intensity,
)
from ...core.preprocessing import time_normalise
from ...phase.dtw import open_end_dtw
from ...phase.likelihood import observation_design

__all__ = ["select_hyperparameters", "Selection", "DEFAULT_FRACTIONS", "DEFAULT_SHRINKAGE_GRID",
           "DEFAULT_SIGMA2_FACTORS"]

DEFAULT_FRACTIONS = (0.2, 0.4, 0.6, 0.8)
DEFAULT_SHRINKAGE_GRID = (0.0, 0.02, 0.1, 0.3, 0.6, 0.95)
#: ``sigma^2`` candidates relative to the mean square of the observation targets
DEFAULT_SIGMA2_FACTORS = tuple(10.0 ** np.arange(-6.0, 6.01, 0.5))


class Selection(NamedTuple):
    """The choices of :func:`select_hyperparameters` (``fit`` assigns them to the model)."""

    #: observation noise of Eq. 16 chosen by cross-validation (``None``: not selected)
    sigma2: float | None
    #: the prior (Eq. 10) at the chosen shrinkage and cross-agent damping (``None``: not selected)
    prior: object
    #: position noise of the likelihood phase
    phase_sigma2: float
    #: what was chosen and measured (the model's ``selection_``)
    record: dict


def select_hyperparameters(model, latent, n_folds: int = 5, fractions=DEFAULT_FRACTIONS,
                           shrinkage_grid=DEFAULT_SHRINKAGE_GRID, sigma2_factors=DEFAULT_SIGMA2_FACTORS,
                           select_sigma2: bool = True, n_out: int = 50, phase_cases: int = 16):
    """Choose ``sigma^2`` (and the shrinkage) of a model being fitted by K-fold cross-validation.

    Called by :meth:`InteractionPrimitive.fit` (``sigma2="cv"``, or
    ``phase_method="likelihood"`` for the phase noise alone) after the DMP
    parameters ``model.thetas_`` are known; it returns its choices (a :class:`Selection`) and ``fit`` assigns
    them to ``prior_``, ``sigma2_`` (when ``select_sigma2``), ``phase_sigma2_`` and ``selection_``; the model
    itself is not changed.

    Parameters
    ----------
    model : FittedPrimitive
        Being fitted: needs ``thetas_``, ``basis_``, ``rollout_``, ``start_velocity_``,
        ``n_observed_latent_``, ``covariance``, ``ridge``, ``observation``.
    latent : list of ndarray, shape (T_j, D_latent)
        The training demonstrations in the model's latent space.
    n_folds : int
        Number of folds (at most the number of demonstrations).
    fractions : sequence of float
        Observed fractions of each held-out demonstration.
    shrinkage_grid : sequence of float
        Candidate shrinkage intensities (the analytic Schaefer-Strimmer value is
        always added); used only with ``covariance="shrinkage"``.
    sigma2_factors : sequence of float
        Candidate ``sigma^2`` relative to the mean square of the observation targets.
    select_sigma2 : bool
        Select ``sigma^2`` and the shrinkage (``False``: only ``phase_sigma2_``).
    n_out : int
        Points of the normalised-time grid on which predictions are scored.
    phase_cases : int
        Held-out cases (demonstration x fraction) on which ``phase_sigma2_`` is
        chosen as the position noise that gives the most accurate likelihood
        phase estimates (0: maximise the held-out marginal likelihood instead).

    Returns
    -------
    Selection
        ``sigma2`` and ``prior`` (``None`` unless ``select_sigma2``), ``phase_sigma2`` and ``record``, the dict
        ``fit`` keeps as ``selection_``: ``sigma2``, ``shrinkage``,
        ``phase_sigma2``, ``cv_error`` (normalised MSE of the choice),
        ``cv_error_prior`` (of the prior mean), ``cv_error_auto``-free grids and scores.
    """
    with single_thread():  # the model is only read: fit assigns the choices
        return _select(model, latent, n_folds, fractions, shrinkage_grid, sigma2_factors, select_sigma2, n_out,
                       phase_cases)


def _fold_references(model, latent, fold, K, n_o):
    """The DTW reference (mean of the time-normalised observed agent, as in ``fit``) of each fold's training part."""
    refs = {}
    for f in range(K):
        tr = [z for j, z in enumerate(latent) if fold[j] != f]
        if len(tr) < 1:
            continue
        n_ref = max(int(round(np.mean([z.shape[0] for z in tr]))), 2)
        refs[f] = np.mean([time_normalise(z[:, :n_o], n_ref) for z in tr], axis=0)
    return refs


def _select(model, latent, n_folds, fractions, shrinkage_grid, sigma2_factors, select_sigma2, n_out, phase_cases,
            cross_grid=(0.0, 0.25, 0.5, 0.75, 0.9, 1.0)):
    thetas = model.thetas_
    S, P = thetas.shape
    n_o = model.n_observed_latent_
    q = model.params_per_dof_
    n_lat = model.n_latent_
    K = _n_folds(n_folds, S)
    fold = fold_labels(S, K, "interleaved")
    method = model.covariance
    if method == "shrinkage" and select_sigma2:
        lam_grid = sorted(set([round(float(shrinkage_intensity(thetas)), 6)] + [float(x) for x in shrinkage_grid]))
    else:
        lam_grid = [None]
    kinds = ["position"] if model.observation == "position" else [model.observation, "position"]

    s_out = np.linspace(0.0, 1.0, n_out)
    free, H = model.rollout_.design(0.0, s_out)
    truths = [time_normalise(z, n_out) for z in latent]
    var_d = np.var(np.vstack(latent), axis=0)
    w_d = 1.0 / np.maximum(var_d, 1e-12 * max(float(var_d.max()), 1e-300))
    v0 = model.start_velocity_

    # observation targets of every held-out case (independent of the fold's prior).  The phase of a case is
    # the one the model will use at prediction time: with the paper's DTW phase, the open-end DTW estimate
    # against the reference of the demonstration's own fold (phase errors are then part of the held-out
    # error, so a small sigma2 that only pays off at the true phase is not chosen); with the likelihood
    # phase (accurate to a few % of the movement), the true phase.
    dtw_refs = _fold_references(model, latent, fold, K, n_o) if model.phase_method == "dtw" else None
    cases = []
    for j, z in enumerate(latent):
        T = z.shape[0]
        for p in fractions:
            M = observed_frames(T, p, max(3, model.min_observed))
            s_end = (M - 1) / (T - 1)
            if dtw_refs is not None:
                ref = dtw_refs[fold[j]]
                s_end = max(open_end_dtw(ref, z[:M, :n_o], return_path=False).n_star, 1) / (ref.shape[0] - 1)
            zo = z[:M, :n_o]
            designs = {kind: observation_design(model, zo, s_end, kind) for kind in kinds}
            y0 = np.concatenate([zo[0], model.start_position_[n_o:]])
            base = free @ np.vstack([y0, v0])  # (n_out, n_lat)
            # the compressed observation depends on the design only: computed once, used for every lambda
            comp = {kind: compress_observation(*designs[kind]) for kind in kinds}
            cases.append((j, designs, base, comp))
    scale = {kind: float(np.mean([np.mean(c[1][kind][1] ** 2) for c in cases])) for kind in kinds}
    s2_grid = {kind: max(scale[kind], 1e-300) * np.asarray(sigma2_factors, dtype=np.float64) for kind in kinds}

    kind0 = kinds[0]
    # the held-out marginal log-likelihood of the positions per (lambda, sigma2): the phase noise's criterion
    # without ``phase_cases``, else only a record (``phase_log_likelihood``), which a fit whose records nobody
    # reads leaves out (interprim.core.cache.records_unused: the default model's inner cross-validation); the
    # means, and so every choice, are the same either way
    skip_ll = kind0 == "position" and select_sigma2 and phase_cases > 0 and records_skipped()
    gam = np.asarray(cross_grid if n_lat > n_o else (0.0,), dtype=np.float64)
    ll = np.zeros((len(lam_grid), len(sigma2_factors)))
    per_case = {}  # lambda index -> per held-out case: the observed and controlled agents' errors, and the prior's
    for f in range(K):
        train = fold != f
        if train.sum() < 2:
            continue
        for a, lam in enumerate(lam_grid):
            prior = GaussianPrior.factored(thetas[train], method, model.ridge, lam)
            held = [c for c in cases if fold[c[0]] == f]
            if select_sigma2:
                pm_shift = H @ prior.mean.reshape(n_lat, q).T  # prior mean's positions minus the start's
                # every held-out case conditioned at once (lowrank_cases: each case's numbers as its own call's)
                outs = _conditioned(prior, n_o, q, [(c[3][kind0], c[1][kind0]) for c in held], s2_grid[kind0],
                                    need_ll=kind0 == "position" and not skip_ll)
                for c0 in range(0, len(held), _SCORE_CHUNK):  # several held-out cases scored at once
                    chunk = held[c0:c0 + _SCORE_CHUNK]
                    outs_c = outs[c0:c0 + _SCORE_CHUNK]
                    e_o, e_c, p_o, p_c = _score(np.stack([o[0] for o in outs_c]), np.stack([c[2] for c in chunk]),
                                                np.stack([truths[c[0]] for c in chunk]), pm_shift, H, n_o, q, w_d, gam)
                    for b in range(len(chunk)):
                        per_case.setdefault(a, []).append((e_o[b], e_c[b], p_o[b], p_c[b]))
                        if kind0 == "position" and not skip_ll:
                            ll[a] += outs_c[b][1]
            if (kind0 != "position" or not select_sigma2) and phase_cases <= 0:
                for _j, designs, _base, comp in held:
                    X, Y = designs["position"]
                    ll[a] += lowrank_case(prior, n_o, q, X, Y, s2_grid["position"], need_mean=False,
                                           need_ll=True, compressed=comp["position"])[1]
    if select_sigma2:
        E, Eo, crit_prior, crit_prior_o = _criteria(per_case, len(lam_grid), n_o, n_lat)
        err_all, err_o = E.mean(axis=0), Eo.mean(axis=0)  # (lam, s2, gamma), (lam, s2)
        # 1. the observed agent's completion: the (lambda, sigma2) within one standard error of its best
        # 2. among those, the controlled agent's: its best, then the most conservative cross-agent damping gamma
        #    within one standard error of that (Hastie et al.'s rule), then its best (lambda, sigma2) at that gamma
        human_ok = within_one_se(Eo)  # (lam, s2)
        E = np.where(human_ok[None, :, :, None], E, np.inf)
        ok = within_one_se(E)  # (lam, s2, gamma)
        c = int(np.flatnonzero(ok.any(axis=(0, 1))).max())
        err = np.where(ok, err_all, np.inf)
        a, b = _best_at(err[:, :, c], err_o)
        lam = lam_grid[a]
        gamma = float(gam[c])
        chosen_sigma2 = float(s2_grid[kind0][b])
        chosen_prior = shrink_cross(fit_prior(thetas, method, model.ridge, shrinkage=lam), gamma, n_o * q)
    else:
        a = 0
        lam = None
        chosen_sigma2, chosen_prior = None, None
    res = _phase_noise_by_accuracy(model, latent, fold, K, lam if select_sigma2 else None,
                                   s2_grid["position"], fractions, max_cases=phase_cases)
    phase_err, phase_err_refined = None, None
    if res is not None:
        phase_err, kept = res
        # the noise under which the likelihood phase estimate is most accurate on held-out demos
        # (the held-out marginal likelihood at the true phase favours too small a noise for this)
        bp = int(np.argmin(phase_err + 1e-9 * np.arange(len(phase_err))[::-1]))
        if model.phase_method == "cv":
            phase_err_refined = _refined_phase_error(model, kept, float(s2_grid["position"][bp]))
    else:
        bp = int(np.argmax(ll[a]))
    phase_sigma2 = float(s2_grid["position"][bp])
    sel = {
        "method": f"{K}-fold cross-validation" if select_sigma2 else "held-out marginal likelihood",
        "n_folds": K,
        "fractions": [float(p) for p in fractions],
        "sigma2": float(model.sigma2_ if chosen_sigma2 is None else chosen_sigma2),
        "shrinkage": float((model.prior_ if chosen_prior is None else chosen_prior).shrinkage),
        "phase_sigma2": phase_sigma2,
        "observation": kind0,
        "sigma2_grid": [float(x) for x in s2_grid[kind0]],
        "shrinkage_grid": [None if x is None else float(x) for x in lam_grid],
        "phase_sigma2_grid": [float(x) for x in s2_grid["position"]],
        "phase_log_likelihood": None if skip_ll else [float(x) for x in ll[a]],
        "phase_error": None if phase_err is None else [float(x) for x in phase_err],
        "phase_error_refined": phase_err_refined,
    }
    if select_sigma2:
        sel["cross_shrinkage"] = gamma
        sel["cross_shrinkage_grid"] = gam.tolist()
        sel["cv_target"] = "controlled agent" if n_lat > n_o else "observed agent"
        sel["cv_error"] = float(err_all[a, b, c])
        sel["cv_error_prior"] = float(crit_prior)
        sel["cv_error_observed"] = float(err_o[a, b])
        sel["cv_error_observed_prior"] = float(crit_prior_o)
        sel["cv_errors"] = err_all[:, :, c].tolist()
        sel["cv_errors_observed"] = err_o.tolist()
        sel["cv_observed_within_se"] = human_ok.tolist()
        sel["cv_within_se"] = ok[:, :, c].tolist()
    return Selection(chosen_sigma2, chosen_prior, phase_sigma2, sel)


_SCORE_CHUNK = 4  # held-out cases scored together (their (cases, sigma2, frames, DoF) arrays stay in cache)


def _conditioned(prior, n_o, q, cases, s2, need_mean=True, need_ll=False):
    """``[(means (S2, P) or None, log-likelihoods (S2,) or None)]``: :func:`~interprim.core.gaussian.lowrank_case` of
    each case ``(compressed observation, (X, Y))`` on ``prior``, the cases with the same compressed size conditioned
    together (:func:`~interprim.core.gaussian.lowrank_cases`: the same numbers, less overhead)."""
    out: list = [None] * len(cases)
    by_k: dict[int, list[int]] = {}
    for i, (comp, _) in enumerate(cases):
        by_k.setdefault(comp[0].shape[0], []).append(i)
    for group in by_k.values():
        for c0 in range(0, len(group), _CONDITION_CHUNK):  # bounded memory: (cases, S2, n, D_o k) arrays
            idx = group[c0:c0 + _CONDITION_CHUNK]
            means, lls = lowrank_cases(prior, n_o, q, [cases[i][0] for i in idx], s2, need_mean=need_mean,
                                       need_ll=need_ll, observations=[cases[i][1] for i in idx] if need_ll else None)
            for j, i in enumerate(idx):
                out[i] = (None if means is None else means[j], None if lls is None else lls[j])
    return out


#: cases conditioned in one lowrank_cases call: its largest array holds (cases, sigma2 candidates, rank, D_o q)
#: floats (8 cases of 100 demonstrations x 7 observed DoF x 26 parameters at 25 candidates: about 30 MB)
_CONDITION_CHUNK = 8


def _criteria(per_case, n_lam, n_o, n_lat):
    """Per-case selection criteria from the cases' errors: ``(E (cases, lam, s2, gamma), Eo (cases, lam, s2),
    prior's criterion, prior's observed error)``, each a mean over the DoFs of its agent.

    ``E`` is the *controlled* agent's error when there is one (the observed agent's otherwise); ``Eo`` limits the
    candidates first (see the module docstring, step 3).
    """
    cases = [list(zip(*per_case[i])) for i in range(n_lam)]  # per lambda: (e_o, e_c, p_o, p_c) over cases
    Eo = np.stack([np.stack(c[0]) for c in cases], axis=1) / n_o  # (cases, lam, s2)
    p_o = float(np.mean(cases[0][2])) / n_o
    if n_lat > n_o:
        E = np.stack([np.stack(c[1]) for c in cases], axis=1) / (n_lat - n_o)
        return E, Eo, float(np.mean(cases[0][3])) / (n_lat - n_o), p_o
    return Eo[..., None], Eo, p_o, p_o


def _best_at(err_c, err_o):
    """``(lambda, sigma^2)`` indices with the smallest controlled-agent error ``err_c`` (lam, s2; ``inf`` excluded);
    among candidates tied on it (to rounding; with ``gamma = 1`` the controlled agent keeps its prior mean whatever
    the noise, so all are tied) the one with the smallest observed-agent error ``err_o``."""
    m = float(err_c.min())
    tied = err_c <= m + 1e-12 * max(abs(m), 1e-300)
    return np.unravel_index(int(np.argmin(np.where(tied, err_o, np.inf))), err_c.shape)


def _score(Th, base, truth, pm_shift, H, n_o, q, w_d, gam):
    """CV errors of held-out cases, per agent: ``e_o`` (B, S2) of the observed agent per sigma2, ``e_c``
    (B, S2, G) of the controlled agent per (sigma2, gamma), and ``(B,)`` of the prior mean's, observed and
    controlled.

    ``Th`` (B, S2, P) posterior means, ``base`` (B, n_out, D) positions from the start state alone, ``truth``
    (B, n_out, D) the time-normalised demonstrations, ``pm_shift`` (n_out, D) the prior mean's part.  Mean squared
    error over the grid, each DoF weighted by ``w_d``, summed over the agent's DoFs.
    """
    B, ns, P = Th.shape
    n_lat = P // q
    # positions of every DoF for every sigma2 candidate, (B, S2, n_out, D): one matrix product
    pred = base[:, None] + (Th.reshape(B * ns * n_lat, q) @ H.T).reshape(B, ns, n_lat, -1).transpose(0, 1, 3, 2)
    pm = base + pm_shift[None]
    # observed agent: as conditioned; controlled agent: the conditioned shift scaled by (1 - gamma), which is
    # exactly the effect of scaling the cross-agent covariance
    e_o = np.sum(np.mean((pred[..., :n_o] - truth[:, None, :, :n_o]) ** 2, axis=2) * w_d[:n_o], axis=2)  # (B, S2)
    dc = pred[..., n_o:] - pm[:, None, :, n_o:]  # (B, S2, n_out, n_c)
    rc = pm[:, :, n_o:] - truth[:, :, n_o:]  # (B, n_out, n_c)
    # mean_t (rc + (1 - gamma) dc)^2 = mean rc^2 + 2 (1 - gamma) mean rc dc + (1 - gamma)^2 mean dc^2, per DoF
    wc = w_d[n_o:]
    R = np.mean(rc * rc, axis=1) @ wc  # (B,)
    X = np.mean(rc[:, None] * dc, axis=2) @ wc  # (B, S2)
    D = np.mean(dc * dc, axis=2) @ wc  # (B, S2)
    a = 1.0 - gam
    e_c = R[:, None, None] + (2.0 * a)[None, None, :] * X[:, :, None] + (a * a)[None, None, :] * D[:, :, None]
    ep = np.mean((pm - truth) ** 2, axis=1) * w_d  # (B, D)
    return e_o, e_c, ep[:, :n_o].sum(axis=1), ep[:, n_o:].sum(axis=1)


def _phase_noise_by_accuracy(model, latent, fold, K, lam, s2_grid, fractions, max_cases=24, n_phase=24):
    """Mean absolute phase error of the likelihood estimator on held-out cases, per noise candidate.

    Each case's log posterior is the one :func:`interprim.phase.likelihood.estimate_phase` maximises at prediction
    time, evaluated by the same code (:func:`_fold_scorer`) on the prior of the case's fold."""
    from ...phase.likelihood import search_bounds

    if max_cases <= 0:
        return None
    S = len(latent)
    all_cases = [(j, p) for p in fractions for j in range(S)]
    pick = np.unique(np.linspace(0, len(all_cases) - 1, min(max_cases, len(all_cases))).round().astype(int))
    cases = [all_cases[i] for i in pick]
    errs = np.zeros(len(s2_grid))
    states = {}
    kept = []
    for j, p in cases:
        f = fold[j]
        if f not in states:
            states[f] = _fold_state(model, model.thetas_[fold != f], lam)
        z = latent[j]
        T = z.shape[0]
        M = observed_frames(T, p, max(3, model.min_observed))
        s_true = (M - 1) / (T - 1)
        lo, hi = search_bounds(model, M)  # the phases estimate_phase searches
        grid = np.exp(np.linspace(np.log(lo), np.log(hi), n_phase))
        zo = z[:M, :model.n_observed_latent_]
        # (phases, noises): every noise's log posteriors on the grid, each phase's statistics computed once
        curves = _fold_scorer(model, states[f], zo, float(s2_grid[0])).noise_curves(grid, s2_grid)
        errs += np.abs(grid[np.argmax(curves, axis=0)] - s_true)
        kept.append((states[f], zo, M, s_true, grid, curves))
    return errs / len(cases), kept


def _fold_state(model, thetas, lam):
    """The likelihood phase's precomputed state (:func:`interprim.phase.likelihood.prior_state`) for the prior of a
    fold's training parameters ``thetas`` (its observed block, diagonal plus low rank)."""
    from ...phase.likelihood import prior_state

    pr = GaussianPrior.factored(thetas, model.covariance, model.ridge, lam)
    return prior_state(model, pr.marginal(model.n_observed_latent_ * model.params_per_dof_))


def _fold_scorer(model, state, zo, s2):
    """``s -> (log posterior, log likelihood)`` of the observed latent frames ``zo`` on a fold's prior (``state``):
    :class:`interprim.phase.likelihood.make_scorer` with that prior in place of the model's."""
    from ...phase.likelihood import make_scorer, speed_prior_params

    return make_scorer(model, zo, s2, True, _parts=(state, speed_prior_params(model, zo.shape[0])))


def _refined_phase_error(model, kept, s2) -> float:
    """Held-out mean absolute error of the likelihood phase at the chosen noise ``s2``, each case's phase found by
    the search :func:`interprim.phase.likelihood.estimate_phase` runs at prediction time
    (:func:`~interprim.phase.likelihood.maximise`: 12 phases evenly in ``log s``, the grid made finer around its
    best points, Brent's method on the two highest peaks) on its fold's prior: the figure ``phase_method="cv"``
    compares with the learned phase's cross-validated error."""
    from ...phase.likelihood import maximise

    errs = []
    for state, zo, _M, s_true, grid, _curves in kept:
        est = maximise(_fold_scorer(model, state, zo, s2), float(grid[0]), float(grid[-1]))
        errs.append(abs(est.phase - s_true))
    return float(np.mean(errs))

"""Calibrated predictive uncertainty: scale the posterior spread so that it matches held-out errors.

The posterior of Eq. 18 says how uncertain the parameters ``theta`` are *if* the model is right: a Gaussian
prior estimated from a few dozen demonstrations (regularised, Eq. 10), an observation noise ``sigma^2``
chosen for the mean's accuracy, and a phase taken as known.  On real recordings none of that holds exactly:
shrinkage of the covariance towards its diagonal breaks the strong negative correlations of neighbouring
DMP weights and widens the trajectory band many times (NuiSI: the predicted std was ~14x the actual error),
while phase errors make the real error larger than the posterior admits where timing matters.

:class:`Calibration` measures the actual errors on held-out folds of the *training* demonstrations, with the
phase the model itself estimates (so timing errors count), and fits one scale per agent and per fraction of
the movement seen: ``c_a(p)^2 = mean(err^2 / scale^2) / mean(std^2 / scale^2)`` over held-out demonstrations,
future frames and the agent's DoFs (each DoF divided by its spread over the demonstrations, so that no DoF
dominates).  A calibrated predictive std is ``c_a(p) * std``: 1 means the posterior was right; the factor is
interpolated linearly in the estimated phase ``p``.  Because the held-out errors shrink as more is seen, the
calibrated band shrinks with them, whether or not the posterior does.

Future frames are placed in time as a robot would use them (:mod:`interprim.evaluation.realtime`): the frame ``j``
steps after the last observed one is compared with the prediction at normalised time ``s + j dt / D``, with
the model's own phase ``s`` and duration ``D``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Calibration", "fit_calibration", "fold_model"]

DEFAULT_FRACTIONS = (0.1, 0.3, 0.5, 0.7, 0.9)


@dataclass
class Calibration:
    """Per-agent scale of the posterior std as a function of the fraction seen.

    Attributes
    ----------
    fractions : ndarray, shape (F,)
        Fractions of the movement seen at which the scale was measured.
    scale_observed, scale_controlled : ndarray, shape (F,)
        ``c(p)`` of the observed and of the controlled agent (NaN where nothing was measured).
    n_cases : int
        Held-out (demonstration, fraction) cases the scales were measured on.
    """

    fractions: np.ndarray
    scale_observed: np.ndarray
    scale_controlled: np.ndarray
    n_cases: int = 0

    def factors(self, phase: float):
        """``(c_observed, c_controlled)`` at an estimated phase (linear interpolation, held at the ends)."""
        p = float(np.clip(phase, self.fractions[0], self.fractions[-1]))
        return (float(np.interp(p, self.fractions, self.scale_observed)),
                float(np.interp(p, self.fractions, self.scale_controlled)))

    def to_arrays(self) -> dict:
        """The calibration as plain numeric arrays (for the model file; inverse of :meth:`from_arrays`)."""
        return {"fractions": np.asarray(self.fractions, dtype=np.float64),
                "scale_observed": np.asarray(self.scale_observed, dtype=np.float64),
                "scale_controlled": np.asarray(self.scale_controlled, dtype=np.float64),
                "n_cases": np.asarray(self.n_cases, dtype=np.int64)}

    @classmethod
    def from_arrays(cls, d) -> "Calibration":
        """Rebuild a calibration from the arrays written by :meth:`to_arrays` (a mapping of the four names)."""
        return cls(np.asarray(d["fractions"], dtype=np.float64), np.asarray(d["scale_observed"], dtype=np.float64),
                   np.asarray(d["scale_controlled"], dtype=np.float64), int(d["n_cases"]))


def _fill(x):
    """Replace NaNs by linear interpolation between measured neighbours (held at the ends); all NaN -> 1."""
    x = np.asarray(x, dtype=np.float64).copy()
    ok = np.isfinite(x)
    if not ok.any():
        return np.ones_like(x)
    idx = np.arange(x.size)
    x[~ok] = np.interp(idx[~ok], idx[ok], x[ok])
    return x


def fold_model(model, keep, observed=None):
    """A copy of a fitted ``model`` whose prior (Eq. 10) is re-estimated from the demonstrations ``keep`` only,
    with the hyper-parameters ``model`` chose (shrinkage ``lambda``, cross-agent damping ``gamma``, ``sigma^2``,
    phase noise): the model a fold of cross-validation would have, without repeating the selection.

    The DMP basis, PCA, start state and DTW reference stay those of ``model`` (they use all demonstrations: a
    small optimism of the calibration, far smaller than the prior's share).  A learned phase model
    (``phase_model_``) is refitted on the kept demonstrations' observed columns ``observed`` (one array per
    demonstration, the model's latent space) when given: it is fitted on the very prefixes it is asked about,
    and kept as is it would make the held-out timing, and so the calibrated band, optimistic."""
    import copy

    from .gaussian import fit_prior, shrink_cross

    keep = np.asarray(keep, dtype=np.intp)
    m = copy.copy(model)  # the model's caches are keyed by the identity of prior_ / durations_, replaced below
    m.thetas_ = model.thetas_[keep]
    m.durations_ = model.durations_[keep]
    m.mean_duration_ = float(m.durations_.mean())
    m.n_demos_ = int(keep.size)
    lam = float(model.prior_.shrinkage) if model.covariance == "shrinkage" else None
    m.prior_ = fit_prior(m.thetas_, model.covariance, model.ridge, shrinkage=lam)
    gamma = float((getattr(model, "selection_", None) or {}).get("cross_shrinkage", 0.0) or 0.0)
    shrink_cross(m.prior_, gamma, model.n_observed_latent_ * model._q)
    m.calibration_ = None
    if observed is not None and getattr(model, "phase_model_", None) is not None:
        from .phase.learned import LearnedPhase

        m.phase_model_ = LearnedPhase(**model.phase_model_.get_params()).fit([observed[i] for i in keep],
                                                                             dt=model.dt_)
    return m


def fit_calibration(model, demos, n_folds: int = 5, fractions=DEFAULT_FRACTIONS, min_demos: int = 6,
                    clip=(0.05, 20.0)) -> Calibration | None:
    """Measure :class:`Calibration` of a fitted ``model`` by ``n_folds``-fold cross-validation on its own
    training demonstrations (:func:`fold_model`: the prior re-estimated without the held-out fold).

    Parameters
    ----------
    model : InteractionPrimitive
        Fitted on ``demos``.
    demos : list of ndarray, shape (T_i, D)
        The training demonstrations in data columns, at ``model.dt_``.
    n_folds : int
        Folds (contiguous; at most one per demonstration).
    fractions : sequence of float
        Fractions of each held-out demonstration observed.
    min_demos : int
        With fewer demonstrations no calibration is fitted (``None``): the scales would be noise.
    clip : (float, float)
        Bounds of a scale (a guard against a degenerate fold).

    Returns
    -------
    Calibration or None
    """
    demos = [np.asarray(d, dtype=np.float64) for d in demos]
    S = len(demos)
    if S < min_demos:
        return None
    dt = float(model.dt_)
    obs = [int(i) for i in model.observed_dofs_]
    observed = None
    if getattr(model, "phase_model_", None) is not None:  # refitted per fold (fold_model)
        n_o = model.n_observed_latent_
        observed = [np.asarray(model._observed_to_latent(d[:, obs]))[:, :n_o] for d in demos]
    ctrl = [int(i) for i in model.controlled_dofs_]
    D = demos[0].shape[1]
    spread = np.std(np.concatenate(demos, axis=0), axis=0)
    spread = np.where(spread > 0, spread, 1.0)
    k = int(min(max(2, n_folds), S))
    edges = np.linspace(0, S, k + 1).round().astype(int)
    fr = np.asarray(fractions, dtype=np.float64)
    num = {a: np.zeros(fr.size) for a in ("o", "c")}
    den = {a: np.zeros(fr.size) for a in ("o", "c")}
    n_cases = 0
    n = 101
    grid = np.linspace(0.0, 1.0, n)
    for f in range(k):
        held = set(range(edges[f], edges[f + 1]))
        m = fold_model(model, [i for i in range(S) if i not in held], observed)
        for j in sorted(held):
            d = demos[j]
            T = d.shape[0]
            for i, p in enumerate(fr):
                M = int(min(T - 1, max(3, round(p * T))))
                fut = np.arange(M, T)
                pred = m.predict(d[:M, obs])
                s = float(pred.normalised_time)
                u = np.clip(s + (fut - (M - 1)) * dt / float(pred.duration), 0.0, 1.0)
                Y = pred.trajectory(n)
                Sd = pred.std(n, calibrated=False)
                e = (np.stack([np.interp(u, grid, Y[:, c]) for c in range(D)], axis=1) - d[fut]) / spread
                sd = np.stack([np.interp(u, grid, Sd[:, c]) for c in range(D)], axis=1) / spread
                for a, cols in (("o", obs), ("c", ctrl)):
                    if cols:
                        num[a][i] += float(np.sum(e[:, cols] ** 2))
                        den[a][i] += float(np.sum(sd[:, cols] ** 2))
                n_cases += 1
    scales = {}
    for a in ("o", "c"):
        with np.errstate(invalid="ignore", divide="ignore"):
            c = np.sqrt(num[a] / den[a])
        c[~np.isfinite(c)] = np.nan
        scales[a] = np.clip(_fill(c), *clip)
    return Calibration(fr, scales["o"], scales["c"], n_cases)

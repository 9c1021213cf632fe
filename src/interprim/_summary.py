"""What a fitted :class:`~interprim.models.primitive.estimator.InteractionPrimitive` chose, in a few lines of text.

Used by ``repr(model)`` (one line), :meth:`InteractionPrimitive.summary` and ``interprim fit``.  Reads only public
fitted attributes and ``selection_`` (keys documented in :data:`SELECTION_KEYS`); a key a model does not have
(``sigma2="residual"``, a model file of an older version) leaves its line out.
"""

from __future__ import annotations

import math

__all__ = ["SELECTION_KEYS", "one_line", "summary"]

#: the keys of ``InteractionPrimitive.selection_`` and what they hold (also in docs/equations.md)
SELECTION_KEYS = {
    "method": "how sigma2 was chosen: 'K-fold cross-validation' (sigma2='cv') or 'held-out marginal likelihood'",
    "n_folds": "K, the folds of the training demonstrations",
    "fractions": "fractions of the observed agent seen in the held-out cases (0.2, 0.4, 0.6, 0.8)",
    "observation": "the observation model the noise is chosen for ('position' or 'forcing')",
    "sigma2": "the chosen observation noise variance of Eq. 16 (also model.sigma2_)",
    "shrinkage": "the chosen shrinkage intensity of the covariance of Eq. 10 (0 = empirical, 1 = diagonal)",
    "cross_shrinkage": "the chosen cross-agent damping gamma in [0, 1]: the controlled agent moves from its prior "
                       "mean by (1 - gamma) times the conditioned shift (1 = the prior mean)",
    "phase_sigma2": "the position noise of the likelihood phase (model.phase_sigma2_)",
    "cv_target": "the agent whose held-out error chose the damping ('controlled agent'; 'observed agent' for a "
                 "single-agent model)",
    "cv_error": "held-out error of the controlled agent at the choice: mean squared error of the whole movement, "
                "each DoF divided by its variance over the demonstrations",
    "cv_error_prior": "the same error for the prior mean (no conditioning)",
    "cv_error_observed": "held-out error of the observed agent's completion at the choice (same units)",
    "cv_error_observed_prior": "the same for the observed agent's prior mean",
    "phase_error_refined": "held-out phase error of the likelihood phase, refined as predict refines it "
                           "(fraction of the movement; phase_method='cv' only)",
    "learned_phase_error": "held-out phase error of the learned phase (phase_method='cv' only)",
    "clock_phase_error": "held-out phase error of a clock: elapsed time over the mean duration (phase_method='cv')",
    "sigma2_grid": "the sigma2 candidates", "shrinkage_grid": "the shrinkage candidates",
    "cross_shrinkage_grid": "the gamma candidates", "phase_sigma2_grid": "the phase noise candidates",
    "phase_log_likelihood": "held-out marginal log-likelihood per phase noise candidate",
    "phase_error": "held-out phase error per phase noise candidate",
    "representation": "how well the DMPs represent the demonstrations, per agent: reconstruction and mean offset "
                      "relative to the spread between demonstrations (also model.representation_)",
    "cv_errors": "held-out error of the controlled agent per (shrinkage, sigma2) at the chosen gamma",
    "cv_errors_observed": "held-out error of the observed agent per (shrinkage, sigma2)",
    "cv_within_se": "per (shrinkage, sigma2): within one standard error of the controlled agent's best",
    "cv_observed_within_se": "per (shrinkage, sigma2): within one standard error of the observed agent's best",
}


LABEL_WIDTH = 15  # "held-out error:"


def _g(x, digits: int = 3) -> str:
    return "n/a" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{float(x):.{digits}g}"


def _choices(model) -> list:
    """``(label, text)`` pairs of the fitted choices, in the order they are printed."""
    sel = getattr(model, "selection_", None) or {}
    out = []
    phase = getattr(model, "phase_method_", model.phase_method)
    why = ""
    if model.phase_method == "cv" and "learned_phase_error" in sel:
        errs = {"likelihood": sel.get("phase_error_refined"), "learned": sel.get("learned_phase_error")}
        other = "learned" if phase == "likelihood" else "likelihood"
        why = (f" (chosen by 'cv': held-out phase error {_g(errs.get(phase), 2)}, {other} "
               f"{_g(errs[other], 2)}, a clock {_g(sel.get('clock_phase_error'), 2)})")
    elif model.phase_method == "cv":
        why = " (chosen by 'cv')"
    out.append(("phase", f"{phase}{why}"))
    noise = f"sigma2 {_g(getattr(model, 'sigma2_', None))}"
    if "method" in sel and model.sigma2 == "cv":
        noise += f" ({sel['method']})"
    elif not isinstance(model.sigma2, str):
        noise += " (given)"
    else:
        noise += f" (sigma2={model.sigma2!r})"
    if "shrinkage" in sel:
        noise += f", shrinkage {_g(sel['shrinkage'], 2)}"
    if "cross_shrinkage" in sel:
        noise += f", cross-agent damping {_g(sel['cross_shrinkage'], 2)}"
    out.append(("noise", f"{model.observation} observation, {noise}"))
    if "cv_error" in sel and "cv_error_prior" in sel:
        e, p = sel["cv_error"], sel["cv_error_prior"]
        text = (f"{sel.get('cv_target', 'controlled agent')} {_g(e)} vs {_g(p)} for the prior mean "
                f"({_g(e / p if p else float('nan'), 2)}x)")
        if "cv_error_observed" in sel and sel.get("cv_target") == "controlled agent":
            eo, po = sel["cv_error_observed"], sel.get("cv_error_observed_prior")
            text += f", observed agent {_g(eo)} vs {_g(po)}"
        out.append(("held-out error", text + " (MSE per DoF variance)"))
    cal = getattr(model, "calibration_", None)
    causal = " (causal prefixes of the recorded samples)" if sel.get("calibration_prefixes") == "causal" else ""
    out.append(("uncertainty", f"calibrated on held-out folds{causal}" if cal is not None
                else "the posterior (not calibrated)"))
    return out


def one_line(model) -> str:
    """What ``repr`` adds for a fitted model: demonstrations, phase, noise, shrinkage and damping."""
    sel = getattr(model, "selection_", None) or {}
    n = getattr(model, "n_demos_", None)
    parts = ([f"{int(n)} demonstrations"] if n is not None else []) + [
        f"phase {getattr(model, 'phase_method_', model.phase_method)!r}",
        f"sigma2 {_g(getattr(model, 'sigma2_', None))}"]
    if "shrinkage" in sel:
        parts.append(f"shrinkage {_g(sel['shrinkage'], 2)}")
    if "cross_shrinkage" in sel:
        parts.append(f"cross-agent damping {_g(sel['cross_shrinkage'], 2)}")
    return "fitted: " + ", ".join(parts)


def summary(model, fit_seconds: float | None = None) -> str:
    """A few lines: the data the model was fitted on and what it chose (see :data:`SELECTION_KEYS`)."""
    n_obs, n_ctrl = len(model.observed_dofs_), len(model.controlled_dofs_)
    n = getattr(model, "n_demos_", None)
    head = (f"{type(model).__name__} fitted on {'?' if n is None else int(n)} demonstrations: "
            f"{n_obs} observed + {n_ctrl} "
            f"controlled columns, dt {model.dt_:.4g} s, mean duration {model.mean_duration_:.3g} s, "
            f"{model.n_basis} basis functions per DoF")
    if fit_seconds is not None:
        head += f", fit in {fit_seconds:.1f} s"
    return "\n".join([head] + [f"  {k + ':':<{LABEL_WIDTH}} {v}" for k, v in _choices(model)])

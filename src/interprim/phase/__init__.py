"""Phase estimation (paper Sec. III-B): where in the movement a partial observation ends.

* :mod:`interprim.phase.dtw`: open-end DTW against a reference (Eq. 5-9), batch and incremental;
* :mod:`interprim.phase.likelihood`: the phase that makes the observation most probable under the
  learned distribution of movements (beyond the paper);
* :mod:`interprim.phase.tracking`: the likelihood phase online, by local search on a lattice of speeds.
* :mod:`interprim.phase.learned`: the phase regressed on features of the observed prefix, trained on the
  demonstrations' own prefixes (beyond the paper; the one that beats a clock on recordings of people).

:func:`estimate_phase` is the one dispatch on ``phase_method`` that both
:meth:`~interprim.models.primitive.estimator.InteractionPrimitive.predict` and
:meth:`~interprim.models.primitive.stream.Stream.update` use.
"""

from __future__ import annotations

import numpy as np

from .dtw import DTWResult, IncrementalDTW, accumulated_cost, open_end_dtw, phase_from_index

__all__ = ["estimate_phase", "movement_prefix", "fit_phase_model", "DTWResult", "IncrementalDTW", "accumulated_cost",
           "open_end_dtw", "phase_from_index"]


def estimate_phase(model, z, method: str = "dtw", *, dtw=None, tracker=None):
    """Phase of the last of the observed frames ``z`` as ``(n_star, cost)``.

    Parameters
    ----------
    model : FittedPrimitive
        A fitted model (its ``reference_`` has ``N`` frames).
    z : ndarray, shape (M, n_observed_latent)
        The frames seen so far, in the model's latent space, at the training ``dt``.
    method : {"dtw", "likelihood", "learned"}
        ``"dtw"``: open-end DTW against ``model.reference_`` (Eq. 5-8); ``"likelihood"``: the maximum of
        the observation's likelihood (:func:`interprim.phase.likelihood.estimate_phase`; with fewer than
        two frames the DTW phase).
    dtw : (int, float), optional
        ``(n_star, cost)`` of the open-end DTW of ``z``, when already known (an incremental DTW).
    tracker : interprim.phase.tracking.Tracker, optional
        Online likelihood phase (a stream's): one local search step on ``z`` instead of a full search.

    Returns
    -------
    n_star : float
        The matched reference frame, ``0 .. N - 1`` (fractional for the likelihood phase).
    cost : float or callable
        ``D(n*, M)`` of the open-end DTW; a callable that computes it on demand where the likelihood
        phase did not need it.
    """
    if method == "learned":  # regressed on the prefix (interprim.phase.learned): a pure function of z
        est = model.phase_model_.estimate(z)
        N1 = model.reference_.shape[0] - 1
        n_star = float(np.clip(est.phase, 0.5 / N1, 1.0)) * N1
        if dtw is not None:
            return n_star, dtw[1]
        ref, zc = model.reference_, z.copy()
        return n_star, lambda: open_end_dtw(ref, zc, return_path=False).cost
    if method == "likelihood" and tracker is not None:  # local search around the previous estimate
        n_star = tracker.step(z) * (model.reference_.shape[0] - 1)
        return n_star, dtw[1]
    if method == "likelihood" and z.shape[0] >= 2:
        from .likelihood import estimate_phase as likelihood_phase

        # no DTW seed: the search finds the maximum of the log posterior (checked against a brute-force search,
        # see likelihood.estimate_phase); D(n*, M) is computed only if asked for
        N1 = model.reference_.shape[0] - 1
        est = likelihood_phase(model, z)
        ref, zc = model.reference_, z.copy()  # a copy: z may be the caller's array, reused after the call
        return est.s_end * N1, lambda: open_end_dtw(ref, zc, return_path=False).cost
    if dtw is not None:
        return dtw
    res = open_end_dtw(model.reference_, z, return_path=False)
    return res.n_star, res.cost


def fit_phase_model(model, observed_latent, dt: float):
    """``(phase_model, method used, figures)`` for ``model.phase_method`` at the end of ``fit``.

    ``"learned"`` and ``"auto"`` fit a :class:`~interprim.phase.learned.LearnedPhase` on the observed (latent)
    columns of the demonstrations; ``"auto"`` keeps it only if its leave-one-demonstration-out phase error
    (``cv_error_``) is below the held-out error of the likelihood phase measured by the hyper-parameter selection
    at its chosen noise, each estimate refined like ``predict``'s (``selection_["phase_error_refined"]``): each on
    held-out training demonstrations, mean absolute error in fractions of the movement.  ``figures`` holds both
    errors of that choice (``learned_phase_error``, ``clock_phase_error``; empty otherwise): ``fit`` adds them to
    ``selection_``.
    """
    method = model.phase_method
    if method not in ("learned", "cv", "auto"):
        return None, method, {}
    from .learned import LearnedPhase

    if method == "learned":
        return LearnedPhase().fit(observed_latent, dt=dt), "learned", {}
    lik = (getattr(model, "selection_", None) or {}).get("phase_error_refined")
    if lik is None or len(observed_latent) < 3:  # no held-out measure to compare with: the likelihood phase
        return None, "likelihood", {}
    lp = LearnedPhase().fit(observed_latent, dt=dt)
    figures = {"learned_phase_error": float(lp.cv_error_), "clock_phase_error": float(lp.cv_error_clock_)}
    return (lp, "learned", figures) if float(lp.cv_error_) < float(lik) else (None, "likelihood", figures)


def movement_prefix(model, z, n_star):
    """The frames of ``z`` to condition on: all of them, or, when the learned phase says the movement has ended
    (phase 1 at the last frame), the shortest prefix at which it first said so.

    Past its end the learned phase stays at 1 and its duration grows with the elapsed time; conditioning on every
    frame would squeeze a partner who holds still onto ``[0, 1]`` and move the robot's goal with each still frame
    (NuiSI highfive1: up to 3.5 cm over 30 frames).  A pure function of ``z`` (binary search over prefix lengths
    for the first whose estimate is 1; ``O(M log M)``), so :meth:`~interprim.models.primitive.stream.Stream.update` and
    :meth:`~interprim.models.primitive.estimator.InteractionPrimitive.predict` agree.  Other phase methods: ``z``
    unchanged.
    """
    if model.phase_method_used() != "learned" or n_star < model.reference_.shape[0] - 1 or z.shape[0] < 3:
        return z
    est = model.phase_model_.estimate
    lo, hi = max(2, int(model.min_observed)), z.shape[0]  # the phase of z[:hi] is 1
    if lo >= hi:
        return z
    if est(z[:lo]).phase >= 1.0:
        return z[:lo]
    while hi - lo > 1:  # invariant: phase(z[:lo]) < 1 <= phase(z[:hi])
        mid = (lo + hi) // 2
        if est(z[:mid]).phase >= 1.0:
            hi = mid
        else:
            lo = mid
    return z[:hi]

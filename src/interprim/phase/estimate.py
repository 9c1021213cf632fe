"""The one phase-estimate type of :mod:`interprim.phase` (the learned phase's and the likelihood phase's)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

__all__ = ["PhaseEstimate"]


@dataclass(frozen=True)
class PhaseEstimate:
    """A phase estimate of a partial observation.

    Attributes
    ----------
    phase : float
        Normalised time of the last observed frame (fraction of the movement seen), in [0, 1]; also
        available as ``s_end``.
    duration : float
        Estimated duration of the whole movement in seconds (NaN when the estimator gives none).
    speed : float
        ``mean_duration / duration``: the partner's speed relative to the demonstrations' mean (1 = as fast;
        NaN when not estimated).
    std : float
        Uncertainty of ``phase`` (the learned phase: root mean square leave-one-demonstration-out error at this
        elapsed time; NaN when not estimated).
    elapsed : float
        Elapsed time of the last observed frame since the first, in seconds (NaN when not known).
    log_likelihood : float
        The likelihood phase: ``log p(observation | s_end)`` (positions, observed block of the prior).
    log_posterior : float
        The likelihood phase: ``log_likelihood + log p(s_end)`` (equal when there is no speed prior).
    grid, curve : ndarray
        The likelihood phase: the candidates evaluated and their log posteriors (for plots and diagnostics;
        not compared by ``==``).
    """

    phase: float
    duration: float = math.nan
    speed: float = math.nan
    std: float = math.nan
    elapsed: float = math.nan
    log_likelihood: float = math.nan
    log_posterior: float = math.nan
    grid: np.ndarray = field(default_factory=lambda: np.empty(0), compare=False)
    curve: np.ndarray = field(default_factory=lambda: np.empty(0), compare=False)

    @property
    def s_end(self) -> float:
        """``phase`` under the likelihood phase's name (normalised time of the last observed frame)."""
        return self.phase

"""Metrics of the evaluation protocols, defined once: point errors, the 90 % band, calibration ratios.

Used by the scorer (:mod:`interprim.model_selection.realtime`), the family comparison
(:mod:`interprim.model_selection.stacking`) and the reports (:mod:`interprim.evaluation`); names no model.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

__all__ = ["Z90", "point_rms", "coverage", "z_ratio"]

#: half-width of the two-sided 90 % band of a normal distribution, in standard deviations
Z90 = 1.6448536269514722


def point_rms(err: ArrayLike, point_dim: int = 1) -> float:
    """Root mean square of the point errors: ``err`` ``(n, C)`` with ``C = k * point_dim`` columns (Euclidean
    distances of ``point_dim``-D points; ``point_dim`` that does not divide ``C`` counts columns alone)."""
    err = np.asarray(err, dtype=np.float64)
    n, C = err.shape
    pd = point_dim if C % point_dim == 0 else 1
    return float(np.sqrt(np.mean(np.sum(err.reshape(n, C // pd, pd) ** 2, axis=2))))


def coverage(err: ArrayLike, std: ArrayLike) -> float:
    """Fraction of errors inside the pointwise 90 % band ``+- Z90 * std``."""
    return float(np.mean(np.abs(err) <= Z90 * np.asarray(std) + 1e-12))


def z_ratio(err: ArrayLike, std: ArrayLike) -> float:
    """RMS error / RMS predicted std (1 = calibrated, > 1 over-confident)."""
    return float(np.sqrt(np.mean(np.asarray(err) ** 2)) / max(np.sqrt(np.mean(np.asarray(std) ** 2)), 1e-300))

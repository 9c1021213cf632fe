"""Canonical system and normalised Gaussian basis functions (paper Sec. III-A, Eq. 2).

Time convention
---------------
interprim works in *normalised time* ``s`` in [0, 1] (``s = t * tau`` with
``tau = 1 / duration``; the paper's ``tau`` multiplies, so a larger ``tau`` is a
faster movement).  The canonical system ``dx/dt = -alpha_x * x * tau`` with
``x(0) = 1`` (paper, below Eq. 2) then has the closed form

    x(s) = exp(-alpha_x * s),

which is also Eq. 9 with ``s = n*/N``.  Everything that depends on time in the
forcing function depends on it only through ``x``.
"""

from __future__ import annotations

from typing import overload

import numpy as np
from numpy.typing import ArrayLike

__all__ = ["canonical_phase", "phase_to_time", "Basis"]


@overload
def canonical_phase(s: float, alpha_x: float) -> float: ...
@overload
def canonical_phase(s: np.ndarray, alpha_x: float) -> np.ndarray: ...
def canonical_phase(s: float | np.ndarray, alpha_x: float) -> float | np.ndarray:
    """Phase ``x = exp(-alpha_x * s)`` of the canonical system at normalised time ``s`` (Eq. 9)."""
    return np.exp(-alpha_x * np.asarray(s, dtype=np.float64))


@overload
def phase_to_time(x: float, alpha_x: float) -> float: ...
@overload
def phase_to_time(x: np.ndarray, alpha_x: float) -> np.ndarray: ...
def phase_to_time(x: float | np.ndarray, alpha_x: float) -> float | np.ndarray:
    """Inverse of :func:`canonical_phase`: normalised time ``s = -log(x) / alpha_x``."""
    return -np.log(np.asarray(x, dtype=np.float64)) / alpha_x


class Basis:
    """Normalised Gaussian basis of the forcing function, Eq. 2.

    ``phi_i(x) = psi_i(x) * x / sum_j psi_j(x)`` with
    ``psi_i(x) = exp(-h_i (x - c_i)^2)``.  The factor ``x`` is part of
    ``phi`` as in the paper, so ``f(x) = phi(x)^T w`` vanishes as ``x -> 0``.

    Centres ``c_i = exp(-alpha_x * s_i)`` are placed at equally spaced
    normalised times ``s_i = i / (m - 1)``, so the basis covers the movement
    evenly in time; widths ``h_i = 1 / (2 (overlap * dc_i)^2)`` follow the
    spacing ``dc_i`` of neighbouring centres in ``x``.

    Parameters
    ----------
    n_basis : int
        Number ``m`` of basis functions (>= 2).
    alpha_x : float
        Decay of the canonical system; ``x(1) = exp(-alpha_x)``.
    overlap : float
        Width of each Gaussian relative to the distance to its neighbour.
    """

    def __init__(self, n_basis: int, alpha_x: float = 3.0, overlap: float = 1.0):
        if int(n_basis) < 2:
            raise ValueError(f"n_basis must be >= 2, got {n_basis}")
        self.n_basis = int(n_basis)
        self.alpha_x = float(alpha_x)
        self.overlap = float(overlap)
        s_c = np.linspace(0.0, 1.0, self.n_basis)
        self.centers = np.exp(-self.alpha_x * s_c)
        dc = np.abs(np.diff(self.centers))
        dc = np.append(dc, dc[-1])
        self.widths = 1.0 / (2.0 * (self.overlap * dc) ** 2)

    def phi(self, s: ArrayLike) -> np.ndarray:
        """Basis ``phi(x(s))`` (Eq. 2) at normalised times ``s``; shape ``(len(s), n_basis)``."""
        x = canonical_phase(np.atleast_1d(s), self.alpha_x)
        # log-sum-exp style normalisation: stable far from every centre
        e = -self.widths[None, :] * (x[:, None] - self.centers[None, :]) ** 2
        e -= e.max(axis=1, keepdims=True)
        psi = np.exp(e)
        return np.asarray(psi * (x / psi.sum(axis=1))[:, None])

    def phi_tilde(self, s: ArrayLike, alpha_y: float, beta_y: float) -> np.ndarray:
        """Rows ``[phi_t^T, alpha_y * beta_y]`` of Eq. 13 (basis plus a constant for the goal ``g``).

        Shape ``(len(s), n_basis + 1)``.
        """
        p = self.phi(s)
        return np.hstack([p, np.full((p.shape[0], 1), alpha_y * beta_y)])

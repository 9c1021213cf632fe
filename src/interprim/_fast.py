"""Glue between the public objects and the compiled kernels of :mod:`interprim._kernels`.

``ready()`` says whether the compiled kernels are used.  They are unless the
environment variable ``INTERPRIM_JIT=0`` is set (then every hot path runs its
plain numpy equivalent, which gives the same numbers).
"""

from __future__ import annotations

import os

import numpy as np

_READY: bool | None = None


def ready() -> bool:
    """True when the numba kernels are to be used."""
    global _READY
    if _READY is None:
        _READY = os.environ.get("INTERPRIM_JIT", "1") != "0"
    return _READY


class StatsWorkspace:
    """Preallocated buffers for the observation statistics of up to ``cap`` frames (grown by doubling)."""

    def __init__(self, cap: int, n_obs: int, q: int):
        self.n_obs = int(n_obs)
        self.q = int(q)
        self.G = np.empty((self.q, self.q))
        self.B = np.empty((self.q, self.n_obs))
        self._alloc(max(int(cap), 3))

    def _alloc(self, cap):
        self.cap = cap
        self.yd = np.empty((cap, self.n_obs))
        self.ydd = np.empty((cap, self.n_obs))
        self.YT = np.empty((self.n_obs, cap))
        self.XT = np.empty((self.q, cap))
        self.work = np.empty((4, cap))
        self.ibuf = np.empty(cap, dtype=np.int64)

    def forcing_stats(self, z, M, s_end, model):
        """``(G, B, |Y|^2)`` of the forcing observation (Eq. 13-15) of ``z[:M]`` over ``[0, s_end]``.

        ``G`` and ``B`` are this workspace's buffers (overwritten by the next call).
        """
        from ._kernels import design_stats, forcing_values_into

        if M > self.cap:
            self._alloc(max(M, 2 * self.cap))
        basis = model.basis_
        const = forcing_values_into(z, M, float(s_end), float(model.alpha_y), float(model.beta_y_),
                                    self.yd, self.ydd, self.YT)
        yy = design_stats(self.YT, M, float(s_end), basis.centers, basis.widths, float(basis.alpha_x), const,
                          self.XT, self.G, self.B, self.work, self.ibuf)
        return self.G, self.B, float(yy)

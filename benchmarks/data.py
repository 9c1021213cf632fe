"""Synthetic two-agent demonstrations shared by the benchmarks (one generator, imported by each benchmark)."""

from __future__ import annotations

import numpy as np

__all__ = ["make_demos"]


def make_demos(S=30, Do=7, Dc=7, T=500, seed=0, stretch=(0.9, 1.1), noise=0.0):
    """Smooth two-agent demonstrations: both agents driven by shared latent factors (correlated goals/shapes)."""
    rng = np.random.default_rng(seed)
    D = Do + Dc
    K = 4
    mix = rng.normal(size=(K, D))
    f = np.arange(1, D + 1)[None, :]
    demos = []
    for _ in range(S):
        z = rng.normal(size=K)
        Tj = max(int(round(T * rng.uniform(*stretch))), 10)
        s = np.linspace(0, 1, Tj)[:, None]
        sm = 10 * s**3 - 15 * s**4 + 6 * s**5
        y = ((z @ mix)[None, :] * sm + 0.3 * np.sin(np.pi * f * s * 0.5 + z[0])
             + 0.1 * z[1] * np.sin(2 * np.pi * s * f / 3))
        if noise:
            y = y + noise * rng.standard_normal(y.shape)
        demos.append(y)
    return demos

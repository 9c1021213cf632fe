"""A small built-in synthetic two-agent data set (for examples, tests and the quick start).

Two agents whose movements are correlated through a shared goal: the
observed agent (2 DoF) reaches towards an amplitude ``a`` with a lateral
offset ``b``; the controlled agent (3 DoF) mirrors ``a`` and reacts to ``b``.
Durations vary by -20 %/+25 % so that phase estimation matters.  Smooth,
noise-free unless ``noise`` is given.
"""

from __future__ import annotations

import numpy as np

__all__ = ["two_agent_demos"]


def two_agent_demos(n: int, seed=0, frames: int = 200, noise: float = 0.0, stretch=(0.8, 1.25)):
    """Generate ``n`` demonstrations of shape ``(T_j, 5)``: columns ``[o1, o2, c1, c2, c3]``.

    Parameters
    ----------
    n : int
        Number of demonstrations.
    seed : int or numpy Generator
        Random seed (deterministic output).
    frames : int
        Nominal number of frames (sampled at ``dt = 0.01`` s).
    noise : float
        Standard deviation of additive Gaussian noise.
    stretch : (float, float)
        Range of the random duration factor.

    Returns
    -------
    list of ndarray
    """
    rng = np.random.default_rng(seed)
    demos = []
    for _ in range(n):
        a = rng.uniform(0.5, 1.5)
        b = rng.uniform(-0.5, 0.5)
        T = int(frames * rng.uniform(*stretch))
        s = np.linspace(0.0, 1.0, T)
        sm = 10 * s**3 - 15 * s**4 + 6 * s**5  # minimum-jerk profile
        cols = [a * sm, b * np.sin(np.pi * s) + 0.3 * sm,
                -a * sm + 0.2 * np.sin(2 * np.pi * s), (a + b) * sm, b * sm**2]
        y = np.stack(cols, axis=1)
        if noise:
            y = y + noise * rng.standard_normal(y.shape)
        demos.append(y)
    return demos

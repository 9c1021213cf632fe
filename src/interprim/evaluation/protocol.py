"""The evaluation protocol shared by every experiment: how much of a held-out demonstration is observed.

A held-out demonstration of ``T`` frames observed "``p`` % of the way" shows its first
:func:`observed_frames` frames: ``round(p T)``, at least 3 (the fewest frames that give a
phase, a speed and the derivatives of Eq. 15) and at most ``T``.
"""

from __future__ import annotations

__all__ = ["observed_frames", "MIN_OBSERVED_FRAMES"]

MIN_OBSERVED_FRAMES = 3


def observed_frames(T: int, fraction: float, min_frames: int = MIN_OBSERVED_FRAMES) -> int:
    """Number of frames of a ``T``-frame demonstration observed at ``fraction`` (in [0, 1]) of it."""
    return int(min(T, max(min_frames, round(fraction * T))))

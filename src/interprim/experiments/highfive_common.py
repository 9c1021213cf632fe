"""What the simulated high-five experiment (:mod:`interprim.experiments.highfive`) and its figures
(:mod:`interprim.experiments.highfive_figures`) share: the methods compared and two small measures."""

from __future__ import annotations

import numpy as np

from ..model_selection.prefixes import observed_frames

METHODS = ("ip", "ip_likelihood", "ip_known_phase", "ip_default", "prior", "nn", "promp")
METHOD_LABELS = {
    "ip": "IP, DTW phase (paper)",
    "ip_default": "IP, library defaults",
    "ip_likelihood": "IP, likelihood phase",
    "ip_known_phase": "IP, known phase",
    "prior": "prior mean",
    "nn": "nearest neighbour (DTW)",
    "promp": "Interaction ProMP (peer)",
}


def n_observed(T: int, p: float) -> int:
    """Frames observed at ``p`` % (:func:`interprim.model_selection.prefixes.observed_frames`)."""
    return observed_frames(T, p / 100.0)


def goal_spread(samples_ctrl, arm):
    """RMS distance (m) of the sampled end points (FK of the final joint angles) from their mean."""
    ends = arm.hand(samples_ctrl[:, -1, :])
    return float(np.sqrt(np.mean(np.sum((ends - ends.mean(axis=0)) ** 2, axis=1)))), ends


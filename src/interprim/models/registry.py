"""The one table of model families: name -> class, how it is built from the shared settings, CLI name.

Everything that names a family asks this module: the default model's candidates (:mod:`interprim.models.auto`),
the evaluation's methods (:mod:`interprim.evaluation`), ``interprim fit --model`` and the model files
(:func:`interprim.models.files.load_any`).  A family is built from one dictionary of settings given once at the
top (:class:`Settings`); each family takes the settings it uses and ignores the rest, so a setting such as the
look-ahead ``horizon`` reaches every member that has one.

To add a family: write its class in ``interprim/models/`` against :class:`interprim.models.base.Predictor`, add one
:class:`Family` row below, and run :func:`interprim.testing.check_predictor` on it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..core.cv import DEFAULT_HORIZON
from .base import Predictor
from .demonstrations import NearestNeighbour, PriorMean
from .kernel import KernelDemonstrations
from .learned import LearnedInteraction
from .primitive.estimator import InteractionPrimitive
from .promp import InteractionProMP

__all__ = ["Settings", "Family", "FAMILIES", "DEFAULT_HORIZON", "CANDIDATES", "family", "factories",
           "default_methods", "class_named", "FrameSizes", "frame_cost"]



@dataclass(frozen=True)
class Settings:
    """Settings shared by every family, given once and passed down.

    Parameters
    ----------
    observed_dofs : tuple of int
        The observed agent's columns.
    n_basis : int
        Basis functions per DoF of the DMP families (paper Eq. 2).
    smoothing_window : int or None
        Savitzky-Golay window of the DMP families (Sec. IV).
    horizon : float
        Seconds ahead the look-ahead-tuned families are tuned for.
    phase_method : str or None
        Phase of the Interaction Primitive (None: its default).
    """

    observed_dofs: tuple
    n_basis: int = 20
    smoothing_window: int | None = None
    horizon: float = DEFAULT_HORIZON
    phase_method: str | None = None

    def __post_init__(self):
        object.__setattr__(self, "observed_dofs", tuple(int(i) for i in self.observed_dofs))


@dataclass(frozen=True)
class FrameSizes:
    """The sizes a streamed frame's cost depends on: ``n_demos`` training demonstrations of ``n_frames`` frames
    (mean), ``n_observed`` observed columns of ``n_dofs``, ``n_basis`` basis functions per DoF, and the Interaction
    Primitive's phase (``"learned"`` or another; its own cross-validation chooses it, and it moves its frame by up
    to 2.5x)."""

    n_demos: int
    n_frames: float
    n_observed: int
    n_dofs: int
    n_basis: int = 20
    phase: str = "likelihood"


# The frame cost model: seconds of one streamed frame (``stream.update`` + ``trajectory(100)``) of each family, a
# linear formula in the sizes that drive it -- the Interaction Primitive's and the learned interaction's latent
# conditioning (demonstrations x DoFs) and rollout (DoFs x frames), the open-end DTW of the aligned families
# (demonstrations x frames x observed DoFs) and the kernel's weighted demonstrations (demonstrations x grid x DoFs).
# Deterministic: one input gives one cost whatever the machine's load (a choice made from timings taken during a fit
# would not be).  The constants are least-squares fits (non-negative) to the process time of 50-150 streamed frames
# at six sizes (10-40 demonstrations, 5-18 DoFs, 100-300 frames; one BLAS thread) on the project's 2-core machine
# while other jobs ran (load about 2; the absolute figures depend on it, the ratios are what the budget uses),
# measured by ``python -m benchmarks.auto --calibrate``; within 15-30 % of the measurement at most sizes.  The
# Interaction Primitive has one formula per phase (its own cross-validation chooses it; the learned phase's frame is
# 2-3x cheaper).
_COSTS_US = {
    "ip": (181.7, 1.1153, 0.0416),        # 1, n_dofs x n_demos, n_dofs x n_frames (likelihood or DTW phase)
    "ip-learned": (127.2, 0.2753, 0.0),   # the same with the learned phase
    "learned": (175.0, 2.2124, 0.0),      # 1, n_dofs x n_demos, n_dofs x n_frames
    "kernel": (216.6, 0.0019, 0.00583),   # 1, n_demos x n_frames x n_observed, n_demos x 201 x n_dofs
    "nn": (90.7, 0.00165),                # 1, n_demos x n_frames x n_observed
    "prior": (42.6, 0.5750),              # 1, n_dofs
}


def _cost_features(kind: str, z: FrameSizes) -> tuple:
    S, T, Do, D = float(z.n_demos), float(z.n_frames), float(z.n_observed), float(z.n_dofs)
    if kind in ("ip", "ip-learned", "learned"):
        return 1.0, D * S * z.n_basis / 20.0 if kind != "learned" else D * S, D * T
    if kind == "kernel":
        return 1.0, S * T * Do, S * 201.0 * D
    if kind == "nn":
        return 1.0, S * T * Do
    return 1.0, D


def frame_cost(name: str, sizes: FrameSizes) -> float | None:
    """Modelled seconds of one streamed frame of the family ``name`` on data of ``sizes`` (None: the family has no
    cost model, e.g. a user's own family or the peer)."""
    kind = getattr(FAMILIES.get(name), "cost_model", None)
    if kind is None:
        return None
    if kind == "ip" and sizes.phase == "learned":
        kind = "ip-learned"
    return float(np.dot(_COSTS_US[kind], _cost_features(kind, sizes))) * 1e-6


def _ip(s: Settings, **extra):
    kw: dict[str, Any] = dict(observed_dofs=list(s.observed_dofs), n_basis=s.n_basis,
                             smoothing_window=s.smoothing_window)
    if s.phase_method is not None:
        kw["phase_method"] = s.phase_method
    kw.update(extra)
    return InteractionPrimitive(**kw)


@dataclass(frozen=True)
class Family:
    """One model family: its registry (and CLI) name, its class and how to build it from :class:`Settings`."""

    name: str
    cls: type
    build: Callable[[Settings], Predictor]
    summary: str
    cli: bool = True
    candidate: bool = False
    needs: tuple = field(default_factory=tuple)
    #: the ``interprim fit`` options that fit this family alone (None: not available from the command line)
    fit_args: str | None = None
    #: what a user should know of that fit (printed after the command)
    fit_note: str = ""
    #: among the methods the real-time evaluation (``interprim evaluate --data FILE``, :func:`default_methods`) and
    #: the hold-out compare by default (False: a variant named on request, e.g. by the leave-one-out sweep)
    default_method: bool = True
    #: the frame cost model of the family (:func:`frame_cost`; None: none)
    cost_model: str | None = None


#: Every model family, by name.  ``candidate``: compared by the default model (``interprim fit``).
FAMILIES = {f.name: f for f in (
    Family("ip", InteractionPrimitive, _ip, "the Interaction Primitive with the library's defaults", candidate=True,
           fit_args="--model ip", cost_model="ip"),
    Family("learned", LearnedInteraction, lambda s: LearnedInteraction(list(s.observed_dofs)),
           "learned timing + phase-robust coupling", candidate=True, fit_args="--model learned",
           cost_model="learned"),
    Family("ip-paper", InteractionPrimitive,
           lambda s: _ip(s, observation="forcing", sigma2="residual", phase_method="dtw"),
           "the paper exactly: forcing observation (Eq. 15), open-end DTW phase (Eq. 5-9), sigma2 from the residual",
           cli=False, fit_args="--model ip --observation forcing --sigma2 residual --phase-method dtw",
           cost_model="ip"),
    Family("ip-forcing", InteractionPrimitive,
           lambda s: _ip(s, observation="forcing", sigma2="cv", phase_method=s.phase_method or "likelihood"),
           "the Interaction Primitive conditioned on forcing values (Eq. 15), sigma2 by cross-validation, the "
           "likelihood phase (a variant of the leave-one-out sweep; Settings.phase_method='dtw': the paper's phase)",
           cli=False, default_method=False, cost_model="ip",
           fit_args="--model ip --observation forcing --sigma2 cv --phase-method likelihood"),
    Family("ip-position", InteractionPrimitive,
           lambda s: _ip(s, observation="position", sigma2="cv", phase_method=s.phase_method or "likelihood"),
           "the Interaction Primitive conditioned on positions, sigma2 by cross-validation, the likelihood phase "
           "(a variant of the leave-one-out sweep)", cli=False, default_method=False, cost_model="ip",
           fit_args="--model ip --observation position --sigma2 cv --phase-method likelihood"),
    Family("kernel", KernelDemonstrations, lambda s: KernelDemonstrations(list(s.observed_dofs), horizon=s.horizon),
           "the demonstrations weighted by a kernel on the aligned prefix", candidate=True, fit_args="--model kernel",
           cost_model="kernel"),
    Family("nn", NearestNeighbour, lambda s: NearestNeighbour(list(s.observed_dofs)),
           "the nearest demonstration under open-end DTW (replays it)", candidate=True, fit_args="--model nn",
           fit_note="replays the nearest demonstration", cost_model="nn"),
    Family("prior", PriorMean, lambda s: PriorMean(list(s.observed_dofs)),
           "the mean demonstration at the mean speed (replays it)", candidate=True, fit_args="--model prior",
           fit_note="replays the mean demonstration", cost_model="prior"),
    Family("iprompt", InteractionProMP, lambda s: InteractionProMP(list(s.observed_dofs)),
           "Interaction ProMP (peer baseline, needs movement-primitives and gmr)", cli=False,
           needs=("movement_primitives", "gmr"), default_method=False),
)}

#: The families the default model compares, in order of preference on ties.
CANDIDATES = tuple(n for n, f in FAMILIES.items() if f.candidate)


def family(name: str) -> Family:
    """The :class:`Family` called ``name`` (a clear error naming the known ones otherwise)."""
    try:
        return FAMILIES[name]
    except KeyError:
        raise ValueError(f"unknown model family {name!r}; known: {', '.join(FAMILIES)}") from None


def factories(names, settings: Settings) -> dict:
    """``{name: zero-argument factory of an unfitted estimator}`` for the families ``names``."""
    out = {}
    for n in names:
        fam = family(n)
        out[n] = (lambda fam=fam: fam.build(settings))
    return out


def default_methods(observed_dofs, smoothing_window=None, n_basis: int = 20, phase_method: str | None = None,
                    horizon: float = DEFAULT_HORIZON) -> dict:
    """Factories of the families the real-time evaluation compares by default (:attr:`Family.default_method`: every
    family but the peer and the leave-one-out sweep's variants)."""
    s = Settings(tuple(observed_dofs), n_basis=n_basis, smoothing_window=smoothing_window, horizon=horizon,
                 phase_method=phase_method)
    return factories([n for n, f in FAMILIES.items() if f.default_method], s)


def class_named(name: str):
    """The family class whose ``__name__`` is ``name`` (model files name their class), or None."""
    for f in FAMILIES.values():
        if f.cls.__name__ == name:
            return f.cls
    return None

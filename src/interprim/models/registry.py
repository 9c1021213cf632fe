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

__all__ = ["Settings", "Family", "FAMILIES", "DEFAULT_HORIZON", "CANDIDATES", "COUPLING_CLASSES", "family", "factories",
           "default_methods", "class_named", "FrameSizes", "frame_cost", "predict_cost", "same_cost_class",
           "yardstick_ip"]



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
    #: the learned interaction's coupling (``CouplingModel.method_``, chosen by its own cross-validation):
    #: ``"ppca"`` costs 3-5x the linear smoothers (``"ridge"``, ``"kernel"``, their ``"blend"``, ``"mean"``): its
    #: joint PCA is factorised again at every frame (:data:`COUPLING_CLASSES`)
    coupling: str = "ppca"


# The frame cost model: seconds of one streamed frame (``stream.update`` + ``trajectory(100)``) of each family, a
# formula in the sizes that drive it -- the Interaction Primitive's and the learned interaction's latent
# conditioning (demonstrations x DoFs) and rollout (DoFs x frames), the open-end DTW of the aligned families
# (demonstrations x frames x observed DoFs) and the kernel's weighted demonstrations (demonstrations x grid x DoFs).
# Deterministic: one input gives one cost whatever the machine's load (a choice made from timings taken during a fit
# would not be).  The constants are least-squares fits (non-negative) to the process time of 75-150 streamed frames
# at seven sizes (10-40 demonstrations, 5-18 DoFs, 50-300 frames; one BLAS thread) on the project's 2-core machine,
# idle (so that the budget's floor, in seconds, is an idle machine's), measured by
# ``python -m benchmarks.auto --calibrate`` on 2026-12-07; within 30 % of the measurement at every size.  Two
# families have one formula per choice their own cross-validation makes: the Interaction Primitive per phase (the
# learned phase's frame is 2-4x cheaper) and the learned interaction per coupling class (COUPLING_CLASSES: the
# reduced-rank coupling's frame is 3-5x dearer; one formula for both classes was off by -45 % to +203 %).
_COSTS_US = {
    "ip": (143.73, 0.75536, 0.0),           # 1, n_dofs x n_demos, n_dofs x n_frames (likelihood or DTW phase)
    "ip-learned": (85.18, 0.20722, 0.0),    # the same with the learned phase
    "learned": (88.0, 0.26669, 0.0),        # 1, n_dofs x n_demos, n_dofs x n_frames (a linear smoother's coupling)
    "learned-ppca": (215.11, 0.62346, 0.45039),  # 1, n_dofs x n_demos, (order of its PCA)^3 / 1000
    "kernel": (97.87, 0.00057, 0.00248),    # 1, n_demos x n_frames x n_observed, n_demos x 201 x n_dofs
    "nn": (42.86, 0.00056),                 # 1, n_demos x n_frames x n_observed
    "prior": (34.65, 0.3872),               # 1, n_dofs
}


#: The learned interaction's cost classes by its coupling: the reduced-rank conditioning, whose joint PCA of the
#: training rows (``n_jitter`` = 5 per demonstration, ``n_in`` = 10 resampled points per observed DoF) and the
#: demonstrations' targets is an eigendecomposition of order ``min(5 n_demos, 10 n_observed + n_demos)`` at every
#: frame, and the linear smoothers (ridge, kernel, their blend, the mean), a few products of that order.
COUPLING_CLASSES = {"ppca": "learned-ppca"}


def _cost_features(kind: str, z: FrameSizes) -> tuple:
    S, T, Do, D = float(z.n_demos), float(z.n_frames), float(z.n_observed), float(z.n_dofs)
    if kind == "learned-ppca":
        m = min(5.0 * S, 10.0 * Do + S)  # the order of the joint PCA's eigendecomposition
        return 1.0, D * S, m ** 3 / 1e3
    if kind in ("ip", "ip-learned", "learned"):
        return 1.0, D * S * z.n_basis / 20.0 if kind != "learned" else D * S, D * T
    if kind == "kernel":
        return 1.0, S * T * Do, S * 201.0 * D
    if kind == "nn":
        return 1.0, S * T * Do
    return 1.0, D


# The predict cost model: seconds of one ``predict`` + ``trajectory(100)`` from a prefix of half the movement (a new
# prefix each call: nothing a model kept from an earlier call is reused), each family's own formula -- the aligned
# families' open-end DTW of the whole prefix against every demonstration (demonstrations x prefix x frames x observed
# DoFs), the IP's phase likelihood over the prefix (demonstrations x prefix x observed DoFs), the learned
# interaction's conditioning as in its frame.  Calibrated with the frame's constants, in the same run
# (``python -m benchmarks.auto --calibrate``); within 45 % of the measurement at every size but the smallest, where
# the aligned families' fixed cost dominates (then up to +92 %: an overestimate).
_PREDICT_US = {
    "ip": (536.65, 3.70552, 0.0),           # 1, n_dofs x n_demos, n_demos x prefix x n_observed / 1000
    "ip-learned": (117.24, 0.30973, 0.0),   # the same with the learned phase
    "learned": (116.42, 0.36999, 0.0),      # 1, n_dofs x n_demos, prefix x n_observed / 1000
    "learned-ppca": (278.88, 0.0, 0.90447),  # its frame's features
    "kernel": (503.77, 355.13),             # 1, n_demos x prefix x n_frames x n_observed / 1e6 (DTW cells)
    "nn": (326.33, 329.63),                 # the same
    "prior": (36.97, 0.90886),              # 1, n_dofs
}


def _predict_features(kind: str, z: FrameSizes) -> tuple:
    S, T, Do, D = float(z.n_demos), float(z.n_frames), float(z.n_observed), float(z.n_dofs)
    half = 0.5 * T  # the prefix: half the movement
    if kind in ("ip", "ip-learned"):
        return 1.0, D * S * z.n_basis / 20.0, S * half * Do / 1e3
    if kind == "learned":
        return 1.0, D * S, half * Do / 1e3
    if kind == "learned-ppca":
        return _cost_features(kind, z)
    if kind in ("kernel", "nn"):
        return 1.0, S * half * T * Do / 1e6
    return 1.0, D


def _cost_kind(name: str, sizes: FrameSizes) -> str | None:
    """The cost formula of the family ``name`` on data of ``sizes``: its cost class (the IP's phase, the learned
    interaction's coupling), None for a family without a cost model."""
    kind = getattr(FAMILIES.get(name), "cost_model", None)
    if kind == "ip" and sizes.phase == "learned":
        kind = "ip-learned"
    if kind == "learned":
        kind = COUPLING_CLASSES.get(sizes.coupling, kind)
    return kind


def same_cost_class(name: str, a: FrameSizes, b: FrameSizes) -> bool:
    """Whether the family ``name`` is costed by the same formulas on sizes ``a`` and ``b`` (e.g. an IP whose phase
    changed but stayed on the same side of the learned phase's formula)."""
    return _cost_kind(name, a) == _cost_kind(name, b)


def _modelled(name: str, sizes: FrameSizes, constants: dict, features) -> float | None:
    kind = _cost_kind(name, sizes)
    if kind is None:
        return None
    return float(np.dot(constants[kind], features(kind, sizes))) * 1e-6


def predict_cost(name: str, sizes: FrameSizes) -> float | None:
    """Modelled seconds of one ``predict`` of the family ``name`` from half of a movement of ``sizes`` (None: the
    family has no cost model)."""
    return _modelled(name, sizes, _PREDICT_US, _predict_features)


def frame_cost(name: str, sizes: FrameSizes) -> float | None:
    """Modelled seconds of one streamed frame of the family ``name`` on data of ``sizes`` (None: the family has no
    cost model, e.g. a user's own family or the peer)."""
    return _modelled(name, sizes, _COSTS_US, _cost_features)


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


def yardstick_ip(settings: Settings, demos, dt: float) -> InteractionPrimitive:
    """The registry's ``ip`` built with ``settings`` and fitted on ``demos``: the frame budget's yardstick (its
    phase, chosen by its own cross-validation, picks its frame's cost model: :class:`FrameSizes`)."""
    ip = family("ip").build(settings)
    assert isinstance(ip, InteractionPrimitive)  # the ip row builds an InteractionPrimitive
    return ip.fit(demos, dt=dt)


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

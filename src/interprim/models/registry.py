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

from dataclasses import dataclass, field
from typing import Callable

from ..core.cv import DEFAULT_HORIZON
from .demonstrations import NearestNeighbour, PriorMean
from .kernel import KernelDemonstrations
from .learned import LearnedInteraction
from .primitive.estimator import InteractionPrimitive
from .promp import InteractionProMP

__all__ = ["Settings", "Family", "FAMILIES", "DEFAULT_HORIZON", "CANDIDATES", "family", "factories",
           "default_methods", "class_named"]



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


def _ip(s: Settings, **extra):
    kw = dict(observed_dofs=list(s.observed_dofs), n_basis=s.n_basis, smoothing_window=s.smoothing_window)
    if s.phase_method is not None:
        kw["phase_method"] = s.phase_method
    kw.update(extra)
    return InteractionPrimitive(**kw)


@dataclass(frozen=True)
class Family:
    """One model family: its registry (and CLI) name, its class and how to build it from :class:`Settings`."""

    name: str
    cls: type
    build: Callable[[Settings], object]
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


#: Every model family, by name.  ``candidate``: compared by the default model (``interprim fit``).
FAMILIES = {f.name: f for f in (
    Family("ip", InteractionPrimitive, _ip, "the Interaction Primitive with the library's defaults", candidate=True,
           fit_args="--model ip"),
    Family("learned", LearnedInteraction, lambda s: LearnedInteraction(list(s.observed_dofs)),
           "learned timing + phase-robust coupling", candidate=True, fit_args="--model learned"),
    Family("ip-paper", InteractionPrimitive,
           lambda s: _ip(s, observation="forcing", sigma2="residual", phase_method="dtw"),
           "the paper exactly: forcing observation (Eq. 15), open-end DTW phase (Eq. 5-9), sigma2 from the residual",
           cli=False, fit_args="--model ip --observation forcing --sigma2 residual --phase-method dtw"),
    Family("ip-forcing", InteractionPrimitive,
           lambda s: _ip(s, observation="forcing", sigma2="cv", phase_method=s.phase_method or "likelihood"),
           "the Interaction Primitive conditioned on forcing values (Eq. 15), sigma2 by cross-validation, the "
           "likelihood phase (a variant of the leave-one-out sweep; Settings.phase_method='dtw': the paper's phase)",
           cli=False, default_method=False,
           fit_args="--model ip --observation forcing --sigma2 cv --phase-method likelihood"),
    Family("ip-position", InteractionPrimitive,
           lambda s: _ip(s, observation="position", sigma2="cv", phase_method=s.phase_method or "likelihood"),
           "the Interaction Primitive conditioned on positions, sigma2 by cross-validation, the likelihood phase "
           "(a variant of the leave-one-out sweep)", cli=False, default_method=False,
           fit_args="--model ip --observation position --sigma2 cv --phase-method likelihood"),
    Family("kernel", KernelDemonstrations, lambda s: KernelDemonstrations(list(s.observed_dofs), horizon=s.horizon),
           "the demonstrations weighted by a kernel on the aligned prefix", candidate=True, fit_args="--model kernel"),
    Family("nn", NearestNeighbour, lambda s: NearestNeighbour(list(s.observed_dofs)),
           "the nearest demonstration under open-end DTW (replays it)", candidate=True, fit_args="--model nn",
           fit_note="replays the nearest demonstration"),
    Family("prior", PriorMean, lambda s: PriorMean(list(s.observed_dofs)),
           "the mean demonstration at the mean speed (replays it)", candidate=True, fit_args="--model prior",
           fit_note="replays the mean demonstration"),
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

"""interprim: Interaction Primitives for human-robot cooperation.

Implements H. Ben Amor, G. Neumann, S. Kamthe, O. Kroemer, J. Peters,
"Interaction Primitives for Human-Robot Cooperation Tasks", ICRA 2014.
See ``docs/equations.md`` for the map from the paper's equations to the code.

The public names are loaded lazily (PEP 562), so ``import interprim`` is cheap
and sub-packages such as :mod:`interprim.sim` import without the numerical core.
"""

from __future__ import annotations

import importlib

from .core.errors import (
    DataFileError,
    InterprimError,
    ModelFileError,
    NotFittedError,
    OutOfRangeWarning,
    PaceWarning,
    RepresentationWarning,
)

__version__ = "0.1.0"

_LAZY = {
    "InteractionPrimitive": "interprim.models.primitive.estimator",
    "Prediction": "interprim.models.primitive.prediction",
    "Stream": "interprim.models.primitive.stream",
    "Recogniser": "interprim.models.recognition",
    "LearnedInteraction": "interprim.models.learned",
    "AutoInteraction": "interprim.models.auto",
    "load_any": "interprim.models.files",
    "LearnedPhase": "interprim.phase.learned",
    "CouplingModel": "interprim.models.coupling",
}

__all__ = [
    "InteractionPrimitive",
    "Prediction",
    "Stream",
    "Recogniser",
    "LearnedInteraction",
    "AutoInteraction",
    "load_any",
    "LearnedPhase",
    "CouplingModel",
    "InterprimError",
    "NotFittedError",
    "ModelFileError",
    "OutOfRangeWarning",
    "PaceWarning",
    "RepresentationWarning",
    "DataFileError",
    "__version__",
]


def __getattr__(name):
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'interprim' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(__all__))

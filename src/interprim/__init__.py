"""interprim: Interaction Primitives for human-robot cooperation.

Implements H. Ben Amor, G. Neumann, S. Kamthe, O. Kroemer, J. Peters,
"Interaction Primitives for Human-Robot Cooperation Tasks", ICRA 2014.
See ``docs/equations.md`` for the map from the paper's equations to the code.
"""

from .errors import DataFileError, InterprimError, ModelFileError, NotFittedError
from .primitive import InteractionPrimitive, Prediction, Stream

__version__ = "0.1.0"

__all__ = [
    "InteractionPrimitive",
    "Prediction",
    "Stream",
    "InterprimError",
    "NotFittedError",
    "ModelFileError",
    "DataFileError",
    "__version__",
]

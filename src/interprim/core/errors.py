"""Exception types raised by interprim.

Every error is a subclass of a built-in exception (``ValueError`` or
``TypeError``) so that callers who do not know this module can still catch
it, and every message names the offending argument, what it was and what was
expected.
"""

from __future__ import annotations


class InterprimError(Exception):
    """Base class of all errors raised on purpose by interprim."""


class NotFittedError(InterprimError, ValueError, AttributeError):
    """A model was used (``predict``, ``stream``, ``save``) before ``fit``."""


class ModelFileError(InterprimError, ValueError):
    """A model file is missing, truncated, corrupt or of an unknown format version."""


class DataFileError(InterprimError, ValueError):
    """A demonstration or observation file cannot be read or is malformed.

    Attributes
    ----------
    multiline : bool
        The message holds a table (e.g. the markers missing frames): the command line prints it as it is instead
        of joining its lines into one.  ``False`` unless set on the instance.
    """

    multiline: bool = False


class MissingExtraError(InterprimError, ImportError):
    """An optional dependency is not installed; the message names the extra to install
    (``pip install 'interprim[mocap]'``)."""


class DataFileWarning(UserWarning):
    """A demonstration file was read with a repair it needed (e.g. a truncated C3D file, of which the complete
    frames are kept); the message names the file and what was lost."""


class OutOfRangeWarning(UserWarning):
    """An observation lies far outside what the model was trained on (wrong units, a wrong column order, another
    frame of reference, a tracking failure): the prediction extrapolates and is not to be trusted.  The
    prediction carries ``input_distance`` and ``out_of_range``
    (:attr:`interprim.models.primitive.estimator.Prediction.out_of_range`)."""


class RepresentationWarning(UserWarning):
    """The DMPs cannot represent the demonstrations well enough (e.g. a periodic movement with too few basis
    functions): their reconstruction or their mean is far from the recorded movements, relative to the spread
    between demonstrations.  The numbers are in ``InteractionPrimitive.representation_``."""


class PaceWarning(UserWarning):
    """The demonstrations' durations change with their order (people change pace over a session): a
    cross-validation that mixes early and late demonstrations then measures a partner at the session's average pace,
    and its figures may be optimistic for a partner at a new pace.  The numbers are in
    ``AutoInteraction.selection_["pace"]`` (:func:`interprim.models.training.pace_trend`)."""


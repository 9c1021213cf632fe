"""Any model file, read as the class it names: :func:`load_any` (``interprim predict``, the server, its workers).

The container (pickle-free ``.npz`` + JSON metadata, bounded reads, checksums) is :mod:`interprim.io`; the classes
a file may name are the families of :mod:`interprim.models.registry` and the default model's two
(:class:`~interprim.models.auto.AutoInteraction`, :class:`~interprim.models.blend.Blend`).
"""

from __future__ import annotations

from pathlib import Path

from ..core.errors import ModelFileError
from ..io import model_kind
from . import registry
from .auto import AutoInteraction
from .blend import Blend

__all__ = ["load_any", "model_classes"]


def model_classes() -> dict:
    """``{class name: class}`` of every model a file may hold."""
    out = {f.cls.__name__: f.cls for f in registry.FAMILIES.values()}
    out.update({c.__name__: c for c in (AutoInteraction, Blend)})
    return out


def load_any(path):
    """Read any interprim model file as the class it names (``interprim fit``'s output, whatever model it chose).

    Raises :class:`~interprim.core.errors.ModelFileError` for a file that is not a readable interprim model, that
    holds a model class this version does not know, or whose values are inconsistent (every family checks what it
    reads, :mod:`interprim.core.state_checks`; a MemoryError, ArithmeticError, LinAlgError or ValueError raised
    while the model is built from them becomes "inconsistent values in the model file: ...").
    """
    kind = model_kind(path)
    classes = model_classes()
    if kind not in classes:
        raise ModelFileError(f"{Path(path)}: holds a {kind!r} model, which this interprim does not know (it reads "
                             f"{', '.join(classes)})")
    return classes[kind].load(path)  # each class's load names the file and turns what building raises into one

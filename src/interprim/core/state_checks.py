"""The values of a model file, checked before a model is built from them (every family's ``load_state``).

A model file's checksums cover its arrays only: its metadata (JSON) may have been edited by hand or written by a
buggy writer, and an array may hold what its writer computed wrongly.  Each family's ``load_state`` checks what it
reads with these helpers -- finiteness, signs, shapes against the model's own ``n_dofs_`` / ``observed_dofs_``,
lengths that sum to the stored row counts, and bounds on every size a load or a prediction expands (``n``,
``n_steps``, grid sizes) before anything is allocated -- and raises
:class:`~interprim.core.errors.ModelFileError` naming the field and the bad value.  :meth:`Predictor.load
<interprim.models.base.Predictor.load>` adds the file's path to the message, and turns what still goes wrong
while the model is built (:func:`building`) into a :class:`~interprim.core.errors.ModelFileError` too.
"""

from __future__ import annotations

import contextlib
import math
import numbers
from collections.abc import Iterator
from typing import Any

import numpy as np

from ..core.errors import ModelFileError

__all__ = ["MAX_GRID", "MAX_VALUES", "BUILD_ERRORS", "fail", "number", "integer", "array", "columns", "lengths",
           "size", "names", "building", "prefixed"]

#: the most points of any grid a model file may ask a load or a prediction to build (``n``, ``n_steps``, ...)
MAX_GRID = 1_000_000
#: the most values (float64: 256 MiB) of an array that a load or a prediction builds from a model file's sizes
MAX_VALUES = 1 << 25

#: what building a model from inconsistent values raises (numpy's LinAlgError is a ValueError)
BUILD_ERRORS = (MemoryError, ArithmeticError, np.linalg.LinAlgError, ValueError, IndexError)


def _show(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."


def fail(field: str, value: Any, what: str) -> None:
    """Raise ``ModelFileError("field 'field' = value: what")``."""
    raise ModelFileError(f"field {field!r} = {_show(value)}: {what}")


def number(field: str, value: Any, positive: bool = False, nonneg: bool = False) -> float:
    """``value`` as a finite float (``positive``: > 0; ``nonneg``: >= 0), or :func:`fail`."""
    if isinstance(value, bool) or not isinstance(value, (numbers.Real, np.floating, np.integer)):
        fail(field, value, "not a number")
    v = float(value)
    if not math.isfinite(v):
        fail(field, value, "not a finite number")
    if positive and not v > 0:
        fail(field, value, "must be positive")
    if nonneg and not v >= 0:
        fail(field, value, "must not be negative")
    return v


def integer(field: str, value: Any, lo: int = 0, hi: int | None = None) -> int:
    """``value`` as an int in ``[lo, hi]``, or :func:`fail`."""
    if isinstance(value, bool) or not isinstance(value, (numbers.Integral, np.integer)):
        fail(field, value, "not an integer")
    v = int(value)
    if v < lo or (hi is not None and v > hi):
        fail(field, value, f"must be an integer in [{lo}, {hi if hi is not None else 'inf'}]")
    return v


def size(field: str, n_values: int, limit: int = MAX_VALUES) -> None:
    """Refuse a file whose sizes would make an array of more than ``limit`` values."""
    if n_values > limit:
        raise ModelFileError(f"field {field!r}: would build an array of {n_values} values, over the limit of "
                             f"{limit} for a model file")


def array(field: str, arr: Any, shape: tuple[Any, ...] | None = None, positive: bool = False,
          nonneg: bool = False) -> np.ndarray:
    """``arr`` as a finite float64 array of ``shape`` (``None`` entries: any size; ``positive`` / ``nonneg``:
    every value), or raise :class:`ModelFileError` naming ``field``."""
    a = np.asarray(arr)
    if not (np.issubdtype(a.dtype, np.floating) or np.issubdtype(a.dtype, np.integer)) or a.dtype == bool:
        raise ModelFileError(f"array {field!r} has dtype {a.dtype}, expected numbers")
    if shape is not None and (a.ndim != len(shape)
                              or any(s is not None and int(s) != d for s, d in zip(shape, a.shape))):
        dims = ["N" if s is None else str(int(s)) for s in shape]
        want = "(" + ", ".join(dims) + ("," if len(dims) == 1 else "") + ")"
        raise ModelFileError(f"array {field!r} has shape {a.shape}, expected {want}")
    a = a.astype(np.float64, copy=False)
    bad = ~np.isfinite(a)
    if positive:
        bad |= ~(a > 0)
    elif nonneg:
        bad |= ~(a >= 0)
    if bad.any():
        at = tuple(int(i) for i in np.argwhere(bad)[0])
        what = "finite and positive" if positive else "finite and not negative" if nonneg else "finite"
        raise ModelFileError(f"array {field!r} holds {float(a[at])!r} at {at}: every value must be {what}")
    return a


def columns(field: str, dofs: Any, n_dofs: int, allow_empty: bool = False) -> list[int]:
    """``dofs`` as a list of distinct column indices in ``[0, n_dofs)``, or :func:`fail`."""
    if not isinstance(dofs, (list, tuple)) or (not dofs and not allow_empty):
        fail(field, dofs, "not a list of column indices")
    out = [integer(f"{field}[{j}]", i, 0, n_dofs - 1) for j, i in enumerate(dofs)]
    if len(set(out)) != len(out):
        fail(field, dofs, "repeats a column")
    return out


def lengths(field: str, arr: Any, total: int, n: int | None = None, min_len: int = 2) -> np.ndarray:
    """The per-demonstration ``lengths`` array: integers of at least ``min_len`` (``n`` of them when given)
    summing to ``total`` (the stored row count), or raise :class:`ModelFileError` naming ``field``."""
    a = np.asarray(arr)
    if a.ndim != 1 or a.size == 0 or (n is not None and a.size != n):
        raise ModelFileError(f"array {field!r} has shape {a.shape}, expected ({'N' if n is None else n},)")
    if not np.issubdtype(a.dtype, np.integer):
        raise ModelFileError(f"array {field!r} has dtype {a.dtype}, expected integers")
    if int(a.min()) < min_len:
        j = int(np.argmin(a))
        raise ModelFileError(f"array {field!r} gives demonstration {j} {int(a[j])} frames, at least {min_len} "
                             "are needed")
    if int(np.sum(a, dtype=np.int64)) != total or np.any(a > total):
        raise ModelFileError(f"array {field!r} sums to {int(np.sum(a, dtype=np.float64))} frames, but the file "
                             f"holds {total}")
    return a.astype(np.intp)


def names(field: str, cols: Any, n: int) -> list[str] | None:
    """Column names: None or a list of ``n`` of them, or :func:`fail`."""
    if cols is None:
        return None
    if not isinstance(cols, list) or len(cols) != n:
        fail(field, cols, f"not a list of the model's {n} column names")
    return [str(c) for c in cols]


def prefixed(prefix: str, exc: ModelFileError) -> ModelFileError:
    """``exc`` with ``prefix`` before its message (a member's error named in its owner's file; a member built from
    its state names no file of its own: ``"<state>: "`` is dropped)."""
    msg = str(exc)
    return ModelFileError(prefix + (msg[len("<state>: "):] if msg.startswith("<state>: ") else msg))


@contextlib.contextmanager
def building(source: Any) -> Iterator[None]:
    """Around the building of a model from a file's values: a :class:`ModelFileError` without the file's name gets
    it, and what inconsistent values make numpy or Python raise (:data:`BUILD_ERRORS`) becomes
    ``ModelFileError("{source}: inconsistent values in the model file: ...")``."""
    head = f"{source}: "
    try:
        yield
    except ModelFileError as exc:
        if str(exc).startswith(head):
            raise
        raise ModelFileError(f"{head}{exc}") from None
    except BUILD_ERRORS as exc:
        raise ModelFileError(f"{head}inconsistent values in the model file: {type(exc).__name__}: {exc}") from None

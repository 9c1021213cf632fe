"""A declared store of values derived from a fitted model, filled on first use.

A model's ``predict`` must not write to the model (a server shares one model between sessions); the one exception is
a :class:`DerivedCache`: values computed only from the fitted state (a factorisation, a padded copy of the
demonstrations), kept so that later predictions skip the work.  What it holds never changes an answer, so
:func:`interprim.testing.object_snapshot` compares a cache by identity, not by content.  Every fit (and every load)
starts a new, empty one.
"""

from __future__ import annotations

import contextvars
from collections.abc import Callable, Hashable, Iterator, Sequence
from contextlib import contextmanager
from typing import Any

import numpy as np

__all__ = ["DerivedCache", "std_unused", "std_deferred", "records_unused", "records_skipped", "shared_fits",
           "fitted_once"]

_STD_UNUSED: contextvars.ContextVar[bool] = contextvars.ContextVar("interprim_std_unused", default=False)
_RECORDS_UNUSED: contextvars.ContextVar[bool] = contextvars.ContextVar("interprim_records_unused", default=False)
#: the fits made within the innermost :func:`shared_fits` (None outside one)
_SHARED: contextvars.ContextVar[dict[Hashable, Any] | None] = contextvars.ContextVar("interprim_shared_fits",
                                                                                    default=None)


@contextmanager
def std_unused() -> Iterator[None]:
    """Within this block no model fitted in it will be asked for its predictive std (a cross-validation that scores
    the means alone): a fit may then defer the work only the std needs until the std is asked for, if ever.  The
    deferred work runs on the same fitted state, so every answer (the std included) is the one an eager fit gives."""
    token = _STD_UNUSED.set(True)
    try:
        yield
    finally:
        _STD_UNUSED.reset(token)


def std_deferred() -> bool:
    """Whether the caller is inside :func:`std_unused`."""
    return _STD_UNUSED.get()


@contextmanager
def records_unused() -> Iterator[None]:
    """Within this block the models fitted are scored on their predictions and discarded: nobody reads the records
    of how a fit made its choices (``selection_``).  A fit may then leave out a record that no choice of its uses,
    saying so (the entry is ``None``); every prediction, std and choice is the one a fit outside gives.  The default
    model's inner cross-validation fits its families in one (:class:`~interprim.models.auto.AutoInteraction`)."""
    token = _RECORDS_UNUSED.set(True)
    try:
        yield
    finally:
        _RECORDS_UNUSED.reset(token)


def records_skipped() -> bool:
    """Whether the caller is inside :func:`records_unused`."""
    return _RECORDS_UNUSED.get()


@contextmanager
def shared_fits() -> Iterator[None]:
    """Within this block a fit that :func:`fitted_once` guards is made once per settings and data: a second fit of
    the same kind with equal settings on the same arrays (bit for bit) takes the first one's result.  The default
    model's fit runs in one (:class:`~interprim.models.auto.AutoInteraction`): the Interaction Primitive and the
    learned interaction each learn the timing of the observed agent (a
    :class:`~interprim.phase.learned.LearnedPhase`) on the same inner training fold.  A fit being a deterministic
    function of its settings and data, every answer is the one separate fits give."""
    token = _SHARED.set({})
    try:
        yield
    finally:
        _SHARED.reset(token)


def _key(v: Any) -> Hashable:
    """A hashable key of a setting ``v`` that equals another's only for the same types and values (arrays by their
    bytes); TypeError for anything else."""
    if v is None or isinstance(v, (bool, int, float, str)):
        return type(v).__name__, v
    if isinstance(v, (tuple, list)):
        return type(v).__name__, tuple(_key(x) for x in v)
    if isinstance(v, dict):
        return "dict", tuple((str(k), _key(x)) for k, x in sorted(v.items(), key=lambda kv: str(kv[0])))
    if isinstance(v, np.ndarray):
        return "ndarray", v.dtype.str, v.shape, v.tobytes()
    raise TypeError(f"no key for a setting of type {type(v).__name__}")


def fitted_once(kind: str, settings: Any, arrays: Sequence[np.ndarray], fit: Callable[[], Any]) -> Any:
    """``fit()``, or inside :func:`shared_fits` the value an earlier call of the same ``kind`` returned for equal
    ``settings`` (numbers, strings, None, arrays, and sequences and dicts of them) and ``arrays`` equal bit for bit
    (shape, dtype and bytes); settings of another type are never shared.  The value is shared, not copied: what
    ``fit`` returns must not be changed by its users."""
    memo = _SHARED.get()
    if memo is None:
        return fit()
    try:
        key = (kind, _key(settings), tuple((a.dtype.str, a.shape, a.tobytes()) for a in arrays))
    except TypeError:
        return fit()
    if key not in memo:
        memo[key] = fit()
    return memo[key]


class DerivedCache(dict[Hashable, tuple[tuple[Any, ...], Any]]):
    """``{name: (key, value)}``: a value derived from the fitted state, kept while the objects in ``key`` stay the
    same (compared by identity)."""

    def get_or_build(self, name: Hashable, key: tuple[Any, ...], build: Callable[[], Any]) -> Any:
        """The value stored under ``name`` for ``key`` (the same objects, by identity), else ``build()``, stored."""
        hit = self.get(name)
        if hit is not None and len(hit[0]) == len(key):
            for a, b in zip(hit[0], key):  # per frame of a stream: a plain loop, no generator
                if a is not b:
                    break
            else:
                return hit[1]
        value = build()
        self[name] = (tuple(key), value)
        return value

"""A declared store of values derived from a fitted model, filled on first use.

A model's ``predict`` must not write to the model (a server shares one model between sessions); the one exception is
a :class:`DerivedCache`: values computed only from the fitted state (a factorisation, a padded copy of the
demonstrations), kept so that later predictions skip the work.  What it holds never changes an answer, so
:func:`interprim.testing.object_snapshot` compares a cache by identity, not by content.  Every fit (and every load)
starts a new, empty one.
"""

from __future__ import annotations

import contextvars
from collections.abc import Callable, Hashable, Iterator
from contextlib import contextmanager
from typing import Any

__all__ = ["DerivedCache", "std_unused", "std_deferred"]

_STD_UNUSED: contextvars.ContextVar[bool] = contextvars.ContextVar("interprim_std_unused", default=False)


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

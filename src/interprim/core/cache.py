"""A declared store of values derived from a fitted model, filled on first use.

A model's ``predict`` must not write to the model (a server shares one model between sessions); the one exception is
a :class:`DerivedCache`: values computed only from the fitted state (a factorisation, a padded copy of the
demonstrations), kept so that later predictions skip the work.  What it holds never changes an answer, so
:func:`interprim.testing.object_snapshot` compares a cache by identity, not by content.  Every fit (and every load)
starts a new, empty one.
"""

from __future__ import annotations

from collections.abc import Callable, Hashable
from typing import Any

__all__ = ["DerivedCache"]


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

"""What the sub-commands of the ``interprim`` command line share: their error type and argument checks."""

from __future__ import annotations

from ..errors import InterprimError

__all__ = ["CommandError"]


class CommandError(InterprimError, ValueError):
    """A command-line argument is invalid or a step of a command failed (reported in one line)."""


def _split_cols(values):
    out = []
    for v in values or []:
        out.extend(s.strip() for s in v.split(",") if s.strip())
    return out


def _positive(value, name):
    if value is not None and not value > 0:
        raise CommandError(f"{name} must be positive, got {value!r}")
    return value

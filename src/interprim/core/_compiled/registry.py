"""The one dispatch of the compiled kernels: each kernel registered with its numpy reference.

Every kernel called from Python is one row of :data:`KERNELS`: where the compiled kernel lives (a
module of :mod:`interprim.core._compiled`, which imports numba) and where its numpy reference lives (a
module that does not import numba, so that the reference runs with ``INTERPRIM_JIT=0``, without numba,
and while a cold cache compiles in the background).  Kernel and reference sit side by side in one row
(the kernels' modules cannot hold the references: importing them imports numba) and are tested against each other,
kernel by kernel, in one process (``tests/compiled/test_kernels_equivalence.py``, which also runs with
``NUMBA_DISABLE_JIT=1`` so that the kernel bodies run as Python).

Callers ask for a kernel by name; whether the compiled kernels are in use is decided once, by
:func:`interprim.core._compiled.loader.ready` (its environment switches and cold-start behaviour):

* :func:`kernel` -- the compiled kernel when the compiled kernels are in use, else ``None`` (the caller
  then runs the registered reference, or the numpy path of which it is a part);
* :func:`loaded_kernel` -- the compiled kernel if the kernels are in use already, else ``None``, without
  deciding (for kernels equal to their reference bit for bit, called outside the public numeric calls too);
* :func:`in_use` -- whether the compiled kernels are in use (for callers that allocate their workspaces);
* :func:`implementation` -- the compiled kernel or its numpy reference, for the kernels whose reference
  takes the same arguments (``drop_in``); tests name the implementation explicitly
  (``which="compiled"`` / ``"numpy"``).

Importing this module does not import numba.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

from . import loader
from .table import KERNELS, Kernel, compiled, names, reference, spec

__all__ = ["Kernel", "KERNELS", "kernel", "loaded_kernel", "implementation", "reference", "compiled", "names", "in_use",
           "forced"]


_FORCED: list[str | None] = [None]  # None: loader.ready() decides; "numpy" / "compiled": forced (tests, see forced)


def in_use() -> bool:
    """Whether the compiled kernels are in use now (:func:`interprim.core._compiled.loader.ready`), for callers that
    prepare the compiled path's workspaces (:class:`interprim.core._compiled.observation.StatsWorkspace`)."""
    forced_path = _FORCED[0]
    return loader.ready() if forced_path is None else forced_path == "compiled"


@contextmanager
def forced(which: str) -> Iterator[None]:
    """Run the block on one path, ``"numpy"`` or ``"compiled"``, whatever :func:`loader.ready` decided.

    For tests that compare the two paths in one process (``tests/compiled/test_kernels_equivalence.py``); not
    thread-safe (it applies to every thread while the block runs) and not for applications, whose path the
    loader's environment switches choose.
    """
    if which not in ("numpy", "compiled"):
        raise ValueError(f"which must be 'numpy' or 'compiled', got {which!r}")
    before = _FORCED[0]
    _FORCED[0] = which
    try:
        yield
    finally:
        _FORCED[0] = before


def kernel(name: str) -> Callable[..., Any] | None:
    """The compiled kernel ``name`` if the compiled kernels are in use now (:func:`loader.ready`), else ``None``."""
    forced_path = _FORCED[0]
    if loader.ready() if forced_path is None else forced_path == "compiled":
        return compiled(name)
    spec(name)
    return None


def loaded_kernel(name: str) -> Callable[..., Any] | None:
    """The compiled kernel ``name`` if the compiled kernels are in use already (:func:`loader.loaded`: this call
    never decides, loads or compiles), else ``None``; for kernels equal to their reference bit for bit."""
    forced_path = _FORCED[0]
    if loader.loaded() if forced_path is None else forced_path == "compiled":
        return compiled(name)
    return None


def implementation(name: str, which: str = "auto") -> Callable[..., Any]:
    """The implementation of kernel ``name``: ``"compiled"``, ``"numpy"`` (its reference) or ``"auto"`` (the
    compiled kernel when in use, else the reference; only for ``drop_in`` kernels)."""
    row = spec(name)
    if which == "compiled":
        return compiled(name)
    if which == "numpy":
        return reference(name)
    if which != "auto":
        raise ValueError(f"which must be 'auto', 'compiled' or 'numpy', got {which!r}")
    if not row.drop_in:
        raise ValueError(f"the numpy reference of {name!r} takes other arguments; use kernel({name!r})")
    return compiled(name) if in_use() else reference(name)

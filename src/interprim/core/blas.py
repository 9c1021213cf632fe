"""One BLAS thread for the library's numeric calls (many tiny factorisations).

numpy and scipy wheels each bundle an OpenBLAS thread pool; on a small,
loaded machine their threads oversubscribe the cores (``Prediction.std(50)``
of a 9 + 9 DoF model: 7.8 ms with the default two threads, 1.3 ms with one;
127 ms against 2.8 ms with other work on the machine), and the library's
matrices (a few hundred rows at most) gain nothing from threads anyway.

Every public numeric entry point (``fit``, ``predict``, ``Stream.update``, the
``Prediction`` accessors, ...) is wrapped by :func:`one_blas_thread`, and inner
code may use ``with single_thread():``.  Both share one process-wide limiter:

* the BLAS libraries are inspected once (``threadpoolctl.ThreadpoolController``
  reads every loaded shared library, ~5 ms per call, so ``threadpool_limits(1)``
  per call would cost more than the online step itself) and again only when new
  modules have been imported since (a BLAS loaded later, e.g. by ``scipy.linalg``);
* the outermost entry sets each pool to one thread and the last exit restores
  the previous counts; nested entries (a ``predict`` inside ``fit``) cost a
  counter increment.  The count is process-wide (BLAS pools are), so other
  threads' BLAS calls also run on one thread while a library call is running.

Results therefore do not depend on the caller's BLAS setting: the library's
calls always run on one thread (tested bit for bit: ``tests/core/test_blas.py``).

**Calls from other threads.**  OpenBLAS (0.3.2x, the numpy and scipy wheels'
build) honours ``openblas_set_num_threads`` only from the thread that set it
first while that thread lives: from any other thread (a server's event loop
after a warm-up in an executor, a ROS 2 executor's callback) the call is
silently ignored, the product runs on two threads and the second one spins
between calls, taking a whole core (measured: a server at 185 % CPU instead
of 100 %).  Every thread's outermost call therefore also sets OpenBLAS's
*thread-local* count, ``openblas_set_num_threads_local(1)``, which works
from any thread.  In the wheels' OpenBLAS that count is the process's (set from
one thread, every thread reads it), and the call returns the count it replaces:
the process's first library call keeps what it returned, and the last exit puts
it back, so a caller's own setting (``threadpool_limits(1)``) outlives the calls.
"""

from __future__ import annotations

import ctypes
import functools
import sys
import threading
from collections.abc import Callable, Iterable
from typing import Any, Literal, ParamSpec, TypeVar

__all__ = ["single_thread", "one_blas_thread"]

_A = ParamSpec("_A")
_R = TypeVar("_R")

_LOCK = threading.Lock()


class _State:
    """The process-wide limiter's state (under ``_LOCK``)."""

    depth = 0  # library calls running in the process (nested ones counted)
    saved: list[tuple[Any, int]] | None = None  # (pool, its thread count) to restore at the last exit
    ctrl: list[Any] | None = None  # threadpoolctl's controllers of the loaded libraries
    key = -1  # len(sys.modules) when they were inspected
    local: list[Any] | None = None  # OpenBLAS's thread-local setters (ctypes functions)
    saved_local: list[tuple[Any, int]] | None = None  # (setter, the count it replaced) at the process's first call


_STATE = _State()
_THREAD = threading.local()  # per thread: depth of library calls
# called at the entry of an outermost call (interprim.core._compiled.loader switches paths there)
_HOOK: list[Callable[[], object] | None] = [None]


def _controllers() -> list[Any]:
    """The BLAS/OpenMP pools of the loaded libraries, inspected again only after new imports."""
    if _STATE.ctrl is None:
        # scipy's own BLAS is loaded with scipy.linalg: loaded here, it is limited from the first call on (loaded
        # later, inside a call, it would run every scipy solve of that call on all cores -- 15 ms instead of
        # 0.03 ms for a small Cholesky solve on a loaded machine -- until the next outermost call re-inspects)
        try:
            import scipy.linalg  # noqa: F401
        except ImportError:  # pragma: no cover - scipy is a dependency
            pass
    key = len(sys.modules)
    if _STATE.ctrl is None or key != _STATE.key:
        from threadpoolctl import ThreadpoolController

        _STATE.ctrl = ctrl = list(ThreadpoolController().lib_controllers)
        _STATE.key = key
        _STATE.local = None
        return ctrl
    return _STATE.ctrl


def _local_setters() -> list[Any]:
    """``openblas_set_num_threads_local`` of every loaded OpenBLAS that has it (see the module docstring)."""
    if _STATE.local is None:
        fns = []
        for lc in _controllers():
            fn = getattr(getattr(lc, "dynlib", None), "openblas_set_num_threads_local", None)
            if fn is not None and getattr(lc, "internal_api", "") == "openblas":
                fn.argtypes, fn.restype = [ctypes.c_int], ctypes.c_int
                fns.append(fn)
        _STATE.local = fns
        return fns
    return _STATE.local


class _OneThread:
    """Re-entrant, process-wide 'one thread per pool' context (see the module docstring)."""

    __slots__ = ()

    def __enter__(self) -> _OneThread:
        t = _THREAD
        d = getattr(t, "depth", 0)
        with _LOCK:
            # this thread's outermost call: OpenBLAS's count through its thread-local setter, which works from any
            # thread; it returns the count it replaces (in the wheels' OpenBLAS the count is the process's, so
            # only the process's first call reads the caller's own, which the last exit puts back)
            prevs = [(fn, fn(1)) for fn in _local_setters()] if d == 0 else []
            if _STATE.depth == 0:
                hook = _HOOK[0]
                if hook is not None:
                    hook()
                saved = []
                for lc in _controllers():
                    n = lc.get_num_threads()
                    if n is not None and n != 1:
                        lc.set_num_threads(1)
                        saved.append((lc, n))
                _STATE.saved = saved
                _STATE.saved_local = prevs
            _STATE.depth += 1
        t.depth = d + 1
        return self

    def __exit__(self, *exc: object) -> Literal[False]:
        with _LOCK:
            _STATE.depth -= 1
            if _STATE.depth == 0:  # the last call in the process: the caller's counts again
                for lc, n in _STATE.saved or ():
                    lc.set_num_threads(n)
                for fn, prev in _STATE.saved_local or ():
                    fn(prev)  # (0 instead reset OpenBLAS to the machine's default: a caller's limit was undone)
                _STATE.saved = _STATE.saved_local = None
        _THREAD.depth -= 1
        return False


_ONE = _OneThread()


def single_thread() -> _OneThread:
    """Context limiting the BLAS (and OpenMP) thread pools to one thread, restoring them on exit.

    Re-entrant and cheap (the libraries are inspected once, see the module docstring); many tiny
    factorisations gain nothing from threads, which only add overhead: up to 100x on a loaded 2-core
    machine (SLSQP of the simulated arms up to 20x).
    """
    return _ONE


def one_blas_thread(fn: Callable[_A, _R]) -> Callable[_A, _R]:
    """Decorator: run ``fn`` inside :func:`single_thread` (the library's public numeric entry points)."""

    if getattr(fn, "__interprim_one_blas__", False):
        return fn  # already limited: once is enough

    @functools.wraps(fn)
    def wrapper(*args: _A.args, **kwargs: _A.kwargs) -> _R:
        with _ONE:
            return fn(*args, **kwargs)

    wrapper.__interprim_one_blas__ = True  # type: ignore[attr-defined]  # the mark that it is limited
    return wrapper


def limit_methods(cls: type, names: Iterable[str]) -> None:
    """Wrap the methods ``names`` that ``cls`` itself defines with :func:`one_blas_thread` (the model contract's
    numeric entry points: every family's ``fit``/``predict``, its stream's ``update``/``extend``, its prediction's
    accessors), so that no family can forget one.  Properties and inherited methods are left as they are."""
    for name in names:
        f = cls.__dict__.get(name)
        if callable(f) and not isinstance(f, (staticmethod, classmethod)):
            setattr(cls, name, one_blas_thread(f))


def depth() -> int:
    """Number of library calls running (nested ones counted) in this process."""
    return _STATE.depth


def on_outer_entry(fn: Callable[[], object] | None) -> None:
    """Call ``fn()`` at the start of every outermost library call (``None``: nothing); see
    :mod:`interprim.core._compiled.loader`: the kernels a call uses are chosen before it starts, never inside it."""
    _HOOK[0] = fn

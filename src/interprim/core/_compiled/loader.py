"""The one loader of the compiled kernels (:mod:`interprim.core._compiled`).

Every compiled kernel has a plain numpy equivalent that gives the same
numbers (bitwise for DTW, to ~1e-13 for the rest; both are listed side by side in
:mod:`interprim.core._compiled.registry`, which callers ask for a kernel, and are compared
in ``tests/compiled/test_kernels_equivalence.py``;
a whole fit + predict + stream agrees to ~2e-8 relative, the conditioning
floor of these problems; ``tests/compiled/test_cold_start.py``).  ``ready()`` says
which one runs:

* ``INTERPRIM_JIT=0``: numpy only;
* ``INTERPRIM_JIT=1``: the compiled kernels from the first call on, loaded from
  numba's on-disk cache in the calling thread (a fresh install waits once for a
  child process that compiles them into the cache, ~15 s on 2 cores: so every
  process runs the cached machine code, see :func:`_fill_cache`); one path for
  the whole process;
* default (``auto``): if numba's cache holds every kernel (checked from its
  index files, without compiling), the kernels are loaded on the first call that
  needs one (~0.3-1 s), as with ``1``.  If it does not (a fresh install, an
  upgraded numba), the kernels are compiled by a separate background process
  (``python -m interprim.core._compiled.loader``, which fills the cache for every later
  process too), the calling process computes with the numpy equivalents
  meanwhile, and switches to the compiled kernels once they are loaded -- only
  between two public calls (:func:`interprim.core.blas.one_blas_thread` marks them),
  never inside one, so each ``fit``, ``predict``, ``Stream.update``, ``std``...
  runs on one path.  A first run after an install then costs about what a warm
  one does instead of waiting for the compiler.  If numba is missing or fails
  to compile, numpy serves for the rest of the process.

``import interprim`` stays cheap: numba is imported on the first call that
needs a kernel (``fit``, ``predict``, ``stream``), not at import.  An
application that wants the compiled kernels before its first call calls
:func:`warmup` (waits) or :func:`prefetch` (starts loading, or the background
compilation, and returns at once).
"""

from __future__ import annotations

import os
import subprocess
import sys
import threading
from collections.abc import Callable

import numpy as np

_READY: bool | None = None  # None: undecided, or numpy while the kernels are being compiled (_PENDING)
_LOCK = threading.Lock()
_THREAD: threading.Thread | None = None
_ERROR: BaseException | None = None
_PENDING = False  # auto mode, cold cache: numpy now, the compiled kernels once _LOADED
_LOADED = threading.Event()  # the kernels are loaded in this process (set by _load on success or failure)

def _mode() -> str:
    return os.environ.get("INTERPRIM_JIT", "auto").strip().lower()


def _compile_all() -> None:
    """Import numba and compile (or load from the cache) every kernel once, with tiny inputs of the real types."""
    from . import blend as kb
    from . import conditioning as k
    from . import dtw as dk
    from . import observation as ko
    from . import phase_likelihood as kp
    from . import prefix_rows as kq
    from . import resample as ks
    from . import rollout as kr
    from . import weighted as kw

    rng = np.random.default_rng(0)
    u = rng.normal(size=(6, 2))
    v = rng.normal(size=(7, 2))
    dk.warm_up(u, v)
    q, Do, r, M = 4, 2, 3, 6
    z = np.cumsum(rng.normal(size=(M, Do)), axis=0)
    yd = np.empty((M, Do))
    ydd = np.empty((M, Do))
    YT = np.empty((Do, M))
    const = ko.forcing_values_into(z, M, 0.5, 25.0, 6.25, yd, ydd, YT)
    G = np.empty((q, q))
    B = np.empty((q, Do))
    ko.design_stats(YT, M, 0.5, np.linspace(1.0, 0.1, q - 1), np.full(q - 1, 10.0), 3.0, const, np.empty((q, M)),
                   G, B, np.empty((4, M)), np.empty(M, dtype=np.int64))
    Kr = 10
    ko.position_stats(z, M, 0.5, z[0], np.zeros(Do), rng.normal(size=(Kr + 1, 2, q)), rng.normal(size=(Kr + 1, 2, 2)),
                     G, B, np.empty((q, 4)), np.empty((Do, 4)))
    P = 2 * Do * q
    idx = np.arange(Do * q, dtype=np.intp)
    other = np.arange(Do * q, P, dtype=np.intp)
    k.lowrank_condition_mean(G, B, 1.0, 1.0, np.ones((Do, q)), rng.normal(size=(Do, q, r)), np.eye(r) * 5.0,
                             np.zeros(P), np.zeros((Do, q)), idx, other, np.zeros((P - Do * q, r)), np.empty(P))
    Kn = 8
    kr.response_positions(np.zeros((Kn + 1, 2, q)), np.zeros((Kn + 1, 2, 2)), 0.3, 3, np.zeros((Do, q)),
                         np.zeros((2, Do)), False, np.empty((3, Do)), 1.0, np.empty(3))
    Zs = np.cumsum(rng.normal(size=(2, M, Do)), axis=1)
    ko.forcing_targets_batch(Zs, 0.2, 25.0, 6.25, np.empty((M, Do)), np.empty_like(Zs), np.empty((2, Do)))
    ks.interp_columns_into(np.linspace(0.0, 1.0, 3), np.linspace(0.0, 1.0, 4), u[:4], np.empty((3, 2)))
    kp.warm_batch(kp.phase_loglik_batch)
    kp.warm_noise_grid(kp.phase_loglik_noise_grid)
    kp.warm_track(kp.track_step)
    kw.warm_up()
    kb.warm_up()
    kq.prefix_rows_into(np.zeros((2, 3, 2)), np.array([3, 2], dtype=np.intp), np.array([1], dtype=np.intp),
                        np.array([0.5]), np.linspace(0.0, 1.0, 3), np.ones(2), False, np.empty((1, 6)))
    kq.warm_up()


def _fill_cache() -> None:
    """With a cold cache, compile every kernel into numba's cache in a child process and wait for it.

    The kernels are then loaded from the cache in this process, as in every later one: numba's freshly
    compiled machine code and the code it writes to (and later loads from) its cache can differ in the last
    bits of floating-point results (measured: the conditioning and phase-likelihood kernels, 3e-16 relative
    per call, 1.8e-5 in the calibrated std after a fit's many phase searches).  So the first run after an
    install gives the answers of every later run.  Without a child process (or if it fails) the kernels are
    compiled here.
    """
    if cache_is_warm():
        return
    try:
        subprocess.run(_child_command(), stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                       stderr=subprocess.DEVNULL, check=False)
    except OSError:
        pass


def _load() -> None:
    global _READY, _ERROR
    try:
        if not _PENDING:  # (a background compilation has filled the cache already)
            _fill_cache()
        _compile_all()  # every kernel of the registry: one loader, one decision for all kernels
        ok = True
    except BaseException as exc:  # numba missing or broken: numpy for the whole process
        _ERROR = exc
        ok = False
    if _PENDING and ok:
        _LOADED.set()  # switched to at the next boundary between public calls (_switch)
        _arm_switch()
    else:
        _READY = ok
        _LOADED.set()


def _numpy_only() -> bool:
    return _mode() in ("0", "false", "no", "off")


def _strict() -> bool:
    return _mode() in ("1", "true", "yes", "on")


def cache_is_warm() -> bool:
    """Whether numba's on-disk cache holds a current entry for every kernel of the registry
    (:data:`interprim.core._compiled.registry.KERNELS`).

    Reads the cache index files (numba checks their source stamps), compiles nothing.  If numba's cache
    layout cannot be read, answers True (the kernels are then loaded, or compiled, in the calling thread).
    """
    try:
        from .table import KERNELS, compiled

        for name in KERNELS:
            disp = compiled(name)
            if not disp._cache._cache_file._load_index():  # type: ignore[attr-defined]  # numba's dispatcher
                return False
        return True
    except ImportError:
        raise
    except Exception:  # noqa: BLE001 -- another numba version's internals: fall back to loading in the caller
        return True


def _child_command() -> list[str]:
    """The command of the background compilation: this package, found where the parent found it."""
    pkg_root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
    code = (f"import sys; sys.path.insert(0, {pkg_root!r}); "
            "from interprim.core._compiled.loader import _compile_main; sys.exit(_compile_main())")
    return [sys.executable, "-c", code]


def _background() -> None:
    """Cold cache: compile in a child process (no GIL shared with the caller), then load from the cache here."""
    try:
        child = subprocess.Popen(_child_command(), stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                 stderr=subprocess.DEVNULL, start_new_session=True)
        child.wait()  # the child completes even if this process exits first (the next run is warm)
    except OSError:
        pass  # no child process possible: compile here instead (below)
    _load()


def _compile_main() -> int:
    """Entry point of the background compilation: compile every kernel into numba's cache."""
    try:
        _compile_all()
    except BaseException:  # noqa: BLE001 -- the parent finds out when it loads
        return 1
    return 0


def _start(target: Callable[[], None]) -> threading.Thread:
    global _THREAD
    with _LOCK:
        if _THREAD is None:
            _THREAD = threading.Thread(target=target, name="interprim-jit-warmup", daemon=True)
            _THREAD.start()
        return _THREAD


def _decide() -> bool:
    """First call needing a kernel: choose the path (see the module docstring)."""
    global _READY, _PENDING, _ERROR
    if _numpy_only():
        _READY = False
        return False
    if _PENDING:
        return _switch()
    if not _strict():
        try:
            warm = cache_is_warm()
        except BaseException as exc:  # numba not importable: numpy for the whole process
            _ERROR = exc
            _READY = False
            return False
        if not warm:
            with _LOCK:
                if _THREAD is None:
                    _PENDING = True
            if _PENDING:
                _start(_background)
                return _switch()
    return warmup()


def _switch() -> bool:
    """While pending: take the compiled kernels if they are loaded and no public call is running."""
    global _READY
    if _LOADED.is_set() and _outside_calls():
        _READY = _ERROR is None
        _disarm_switch()
    return bool(_READY)


def _outside_calls() -> bool:
    from .. import blas as _blas

    return _blas.depth() == 0


def _arm_switch() -> None:
    from .. import blas as _blas

    _blas.on_outer_entry(_switch)


def _disarm_switch() -> None:
    from .. import blas as _blas

    _blas.on_outer_entry(None)


def ready() -> bool:
    """True when the compiled kernels are to be used now (see the module docstring).

    The first call decides: with a warm numba cache (or ``INTERPRIM_JIT=1``) it waits for the kernels
    (loading them in the calling thread, or joining a :func:`prefetch` in progress); with a cold cache it
    answers False (numpy) until a background compilation has finished, and True from the next public call on.
    The answer never changes inside a public call.
    """
    if _READY is not None:
        return _READY
    return _decide()


def loaded() -> bool:
    """True when the compiled kernels are in use already; unlike :func:`ready`, never decides (nor loads, nor
    starts a compilation): for the kernels that give numpy's numbers bit for bit and serve callers outside the
    public numeric calls too (e.g. the resampling of a data file's rows), which then stay on numpy."""
    return _READY is True


def prefetch() -> None:
    """Start loading the compiled kernels (or, with a cold cache, their background compilation) and return.

    With a warm cache nothing runs on numpy meanwhile: the first call that needs a kernel waits for this load.
    A no-op with ``INTERPRIM_JIT=0`` or once loaded.
    """
    if _READY is not None or _numpy_only():
        return
    if not _strict() and not _PENDING:
        try:
            warm = cache_is_warm()
        except BaseException:  # noqa: BLE001 -- decided (numpy) on the first call
            return
        if not warm:
            _decide()
            return
    _start(_load)


def warmup() -> bool:
    """Load (or compile) the compiled kernels now and wait for them; returns whether they are in use.

    Call it outside any library call (it switches a process running on numpy during a background
    compilation to the compiled kernels once they are loaded).
    """
    global _READY
    if _READY is not None:
        return _READY
    if _numpy_only():
        _READY = False
        return False
    t = _start(_load)
    t.join()
    if _PENDING:
        _LOADED.wait()
        return _switch()
    return bool(_READY)


if __name__ == "__main__":  # the background compilation (see _child_command)
    sys.exit(_compile_main())

"""The one loader of the compiled kernels (:mod:`interprim._compiled`).

Every compiled kernel has a plain numpy equivalent that gives the same
numbers (bitwise for DTW, to ~1e-13 for the rest; ``tests/test_fastpaths.py``).
``ready()`` says which one runs, and the answer never changes within a process
(one input, one answer: no result may depend on when a compilation finished):

* ``INTERPRIM_JIT=0``: numpy only;
* ``INTERPRIM_JIT=1`` or default (``auto``): the compiled kernels, compiled or
  loaded from numba's on-disk cache on first use, in the calling thread (a
  fresh install without a cache waits for the compilation once).  If numba is
  missing or fails to compile, numpy serves for the rest of the process.

``import interprim`` stays cheap: numba is imported on the first call that
needs a kernel (``fit``, ``predict``, ``stream``), not at import.  An
application that wants the first prediction to be fast calls :func:`warmup`
(or :func:`prefetch`, which starts loading in a background thread while the
caller does something else; the first kernel call then waits for it).
"""

from __future__ import annotations

import os
import threading

import numpy as np

_READY: bool | None = None
_LOCK = threading.Lock()
_THREAD: threading.Thread | None = None
_ERROR: BaseException | None = None


def _mode() -> str:
    return os.environ.get("INTERPRIM_JIT", "auto").strip().lower()


def _compile_all():
    """Import numba and compile (or load from the cache) every kernel once, with tiny inputs of the real types."""
    from . import conditioning as k
    from . import dtw as dk
    from . import observation as ko
    from . import rollout as kr

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


def _load():
    global _READY, _ERROR
    try:
        _compile_all()
        _load_phase_kernels()  # the likelihood phase's kernels: one loader, one decision for all kernels
        _READY = True
    except BaseException as exc:  # numba missing or broken: numpy for the whole process
        _ERROR = exc
        _READY = False


def _numpy_only() -> bool:
    return _mode() in ("0", "false", "no", "off")


def ready() -> bool:
    """True when the compiled kernels are to be used (see the module docstring).

    The first call decides for the whole process: with ``INTERPRIM_JIT`` other than ``0`` it waits for the
    kernels (loading them in the calling thread, or joining a :func:`prefetch` in progress), so a result
    never depends on how far a background compilation has got.
    """
    if _READY is not None:
        return _READY
    return warmup()


def prefetch() -> None:
    """Start loading the compiled kernels in a background thread and return at once.

    Nothing runs on numpy meanwhile: the first call that needs a kernel waits for this load (so results are
    the same as without the prefetch).  A no-op with ``INTERPRIM_JIT=0`` or once loaded.
    """
    global _THREAD
    if _READY is not None or _numpy_only():
        return
    with _LOCK:
        if _THREAD is None:
            _THREAD = threading.Thread(target=_load, name="interprim-jit-warmup", daemon=True)
            _THREAD.start()


def warmup() -> bool:
    """Load (or compile) the compiled kernels now and wait for them; returns whether they are in use."""
    global _READY, _THREAD
    if _READY is not None:
        return _READY
    if _numpy_only():
        _READY = False
        return False
    with _LOCK:
        t = _THREAD
        if t is None:
            _THREAD = t = threading.Thread(target=_load, name="interprim-jit-warmup", daemon=True)
            t.start()
    t.join()
    return bool(_READY)


# ---------------------------------------------------------------------------------------------------------------
# the likelihood phase's kernels (interprim._compiled.phase_likelihood), loaded by _load with the others

_PHASE_KERNELS: list = []  # [phase_loglik_batch, track_step] once loaded


def _load_phase_kernels():
    """Compile (or load from numba's cache) the phase kernels; raises if they cannot be compiled."""
    if _PHASE_KERNELS:
        return
    from .phase_likelihood import phase_loglik_batch, track_step, warm_batch, warm_track

    warm_batch(phase_loglik_batch)
    warm_track(track_step)
    _PHASE_KERNELS.extend([phase_loglik_batch, track_step])


def phase_kernel():
    """The compiled batch kernel of the likelihood phase, or ``None`` on the numpy path (:func:`ready` decides,
    once per process; the first use waits for the kernels)."""
    return _PHASE_KERNELS[0] if ready() else None

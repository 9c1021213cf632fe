"""The one dispatch of the compiled kernels: each kernel registered with its numpy reference.

Every kernel called from Python is one row of :data:`KERNELS`: where the compiled kernel lives (a
module of :mod:`interprim._compiled`, which imports numba) and where its numpy reference lives (a
module that does not import numba, so that the reference runs with ``INTERPRIM_JIT=0``, without numba,
and while a cold cache compiles in the background).  Kernel and reference sit side by side in one row
(the kernels' modules cannot hold the references: importing them imports numba) and are tested against each other, kernel by kernel, in one process (``tests/test_kernels_equivalence.py``,
which also runs with ``NUMBA_DISABLE_JIT=1`` so that the kernel bodies run as Python).

Callers ask for a kernel by name; whether the compiled kernels are in use is decided once, by
:func:`interprim._compiled.loader.ready` (its environment switches and cold-start behaviour):

* :func:`kernel` -- the compiled kernel when the compiled kernels are in use, else ``None`` (the caller
  then runs the registered reference, or the numpy path of which it is a part);
* :func:`in_use` -- whether the compiled kernels are in use (for callers that allocate their workspaces);
* :func:`implementation` -- the compiled kernel or its numpy reference, for the kernels whose reference
  takes the same arguments (``drop_in``); tests name the implementation explicitly
  (``which="compiled"`` / ``"numpy"``).

Importing this module does not import numba.
"""

from __future__ import annotations

import importlib
from contextlib import contextmanager
from dataclasses import dataclass

from . import loader

__all__ = ["Kernel", "KERNELS", "kernel", "implementation", "reference", "compiled", "names", "in_use", "forced"]


@dataclass(frozen=True)
class Kernel:
    """One compiled kernel and its numpy reference.

    Attributes
    ----------
    name : str
        ``"<module>.<short name>"``, the key callers use.
    compiled : str
        ``"<module of interprim._compiled>:<function>"``.
    reference : str
        ``"<module>:<qualified name>"`` of the numpy reference (a module that does not import numba).
    drop_in : bool
        The reference takes the kernel's arguments and returns its result (:func:`implementation` may
        return either); otherwise it computes the same quantities at the level its callers use (e.g. the
        whole observation statistics instead of the kernel's workspaces), as stated in ``what``.
    what : str
        What is computed (with the paper's equations) and how the reference corresponds.
    """

    name: str
    compiled: str
    reference: str
    drop_in: bool
    what: str


KERNELS: dict[str, Kernel] = {k.name: k for k in (
    Kernel("dtw.accumulate", "dtw:_accumulate", "interprim.phase.dtw:_accumulate_np", True,
           "the accumulated cost matrix of Eq. 5-7, (M, N); bitwise equal"),
    Kernel("dtw.open_end", "dtw:_open_end_strips", "interprim.phase.dtw:_accumulate_np", False,
           "n* and D(n*, M) of Eq. 5-8 with two columns of memory; the reference's last column, first argmin; "
           "bitwise equal"),
    Kernel("dtw.backtrack", "dtw:_backtrack", "interprim.phase.dtw:_backtrack_np", True,
           "the alignment path from D (Eq. 5-8); equal"),
    Kernel("dtw.incremental_step", "dtw:_incremental_step", "interprim.phase.dtw:IncrementalDTW._step_np", False,
           "one query frame of the open-end DTW (the new last column and n*); bitwise equal"),
    Kernel("observation.forcing_values_into", "observation:forcing_values_into",
           "interprim.fitted:FittedPrimitive.observation_design", False,
           "forcing values of Eq. 15 (np.gradient derivatives); the reference's targets Y"),
    Kernel("observation.design_stats", "observation:design_stats",
           "interprim.fitted:FittedPrimitive.observation_design", False,
           "X^T X, X^T Y, |Y|^2 of the forcing observation (Eq. 13-15); the reference's X, Y"),
    Kernel("observation.position_stats", "observation:position_stats",
           "interprim.fitted:FittedPrimitive.observation_design", False,
           "X^T X, X^T Y, |Y|^2 of the position observation (rows of LinearRollout.design); the reference's X, Y"),
    Kernel("observation.forcing_targets_batch", "observation:forcing_targets_batch",
           "interprim.dmp:forcing_targets", False,
           "forcing targets of Eq. 3 of equally long demonstrations; reference: preprocessing.derivatives + "
           "dmp.forcing_targets"),
    Kernel("conditioning.lowrank_condition_mean", "conditioning:lowrank_condition_mean",
           "interprim.gaussian:LowRankConditioner.mean_numpy", False,
           "posterior mean and evidence of Eq. 16-18 for a diagonal + low-rank prior; the reference returns "
           "(mean, log-likelihood), the kernel (log-dets, residual) for LowRankConditioner.mean_compiled"),
    Kernel("rollout.response_positions", "rollout:response_positions",
           "interprim.prediction:Prediction._response_reference", False,
           "the controlled agent's mean movement from the current phase (Eq. 1, exact discretisation)"),
    Kernel("phase_likelihood.phase_loglik_batch", "phase_likelihood:phase_loglik_batch",
           "interprim.phase.likelihood:_loglik_batch_numpy", False,
           "log-likelihood of the observation at many candidate phases (the likelihood phase); the reference "
           "takes the same arrays without M and out"),
    Kernel("phase_likelihood.track_step", "phase_likelihood:track_step",
           "interprim.phase.likelihood:_loglik_batch_numpy", False,
           "one frame of the stream's lattice search: each lattice point's statistics extended by the frame; its "
           "log posteriors are the reference's log-likelihoods plus the speed prior"),
)}

_RESOLVED: dict[str, object] = {}
_FORCED: list = [None]  # None: loader.ready() decides; "numpy" / "compiled": forced (tests, see forced)


def names() -> list[str]:
    """Names of the registered kernels."""
    return list(KERNELS)


def _spec(name: str) -> Kernel:
    try:
        return KERNELS[name]
    except KeyError:
        raise KeyError(f"no compiled kernel named {name!r}; registered: {', '.join(KERNELS)}") from None


def compiled(name: str):
    """The compiled kernel ``name`` (imports numba; compiles it, or loads it from the cache, on its first call).

    With ``NUMBA_DISABLE_JIT=1`` this is the kernel's body as a plain Python function.
    """
    fn = _RESOLVED.get(name)
    if fn is None:
        mod, attr = _spec(name).compiled.split(":")
        fn = getattr(importlib.import_module(f"{__package__}.{mod}"), attr)
        _RESOLVED[name] = fn
    return fn


def reference(name: str):
    """The numpy reference of the kernel ``name`` (a function, or an unbound method)."""
    mod, qual = _spec(name).reference.split(":")
    obj = importlib.import_module(mod)
    for part in qual.split("."):
        obj = getattr(obj, part)
    return obj


def in_use() -> bool:
    """Whether the compiled kernels are in use now (:func:`interprim._compiled.loader.ready`), for callers that
    prepare the compiled path's workspaces (:class:`interprim._compiled.observation.StatsWorkspace`)."""
    forced_path = _FORCED[0]
    return loader.ready() if forced_path is None else forced_path == "compiled"


@contextmanager
def forced(which: str):
    """Run the block on one path, ``"numpy"`` or ``"compiled"``, whatever :func:`loader.ready` decided.

    For tests that compare the two paths in one process (``tests/test_kernels_equivalence.py``); not
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


def kernel(name: str):
    """The compiled kernel ``name`` if the compiled kernels are in use now (:func:`loader.ready`), else ``None``."""
    forced_path = _FORCED[0]
    if loader.ready() if forced_path is None else forced_path == "compiled":
        fn = _RESOLVED.get(name)
        return fn if fn is not None else compiled(name)
    _spec(name)
    return None


def implementation(name: str, which: str = "auto"):
    """The implementation of kernel ``name``: ``"compiled"``, ``"numpy"`` (its reference) or ``"auto"`` (the
    compiled kernel when in use, else the reference; only for ``drop_in`` kernels)."""
    spec = _spec(name)
    if which == "compiled":
        return compiled(name)
    if which == "numpy":
        return reference(name)
    if which != "auto":
        raise ValueError(f"which must be 'auto', 'compiled' or 'numpy', got {which!r}")
    if not spec.drop_in:
        raise ValueError(f"the numpy reference of {name!r} takes other arguments; use kernel({name!r})")
    return compiled(name) if in_use() else reference(name)

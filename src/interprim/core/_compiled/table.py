"""The table of the compiled kernels: each with its numpy reference (see :mod:`interprim.core._compiled.registry`).

Importing this module does not import numba; :func:`compiled` imports a kernel's module (and numba) on demand.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

__all__ = ["Kernel", "KERNELS", "names", "spec", "compiled", "reference"]


@dataclass(frozen=True)
class Kernel:
    """One compiled kernel and its numpy reference.

    Attributes
    ----------
    name : str
        ``"<module>.<short name>"``, the key callers use.
    compiled : str
        ``"<module of interprim.core._compiled>:<function>"``.
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
    Kernel("dtw.accumulate", "dtw:_accumulate", "interprim.phase.dtw:accumulate_np", True,
           "the accumulated cost matrix of Eq. 5-7, (M, N); bitwise equal"),
    Kernel("dtw.open_end", "dtw:_open_end_strips", "interprim.phase.dtw:accumulate_np", False,
           "n* and D(n*, M) of Eq. 5-8 with two columns of memory; the reference's last column, first argmin; "
           "bitwise equal"),
    Kernel("dtw.backtrack", "dtw:_backtrack", "interprim.phase.dtw:_backtrack_np", True,
           "the alignment path from D (Eq. 5-8); equal"),
    Kernel("dtw.incremental_step", "dtw:_incremental_step", "interprim.phase.dtw:IncrementalDTW._step_np", False,
           "one query frame of the open-end DTW (the new last column and n*); bitwise equal"),
    Kernel("dtw.incremental_block", "dtw:_incremental_block", "interprim.phase.dtw:IncrementalDTW._step_np", False,
           "several query frames of the open-end DTW, each by dtw.incremental_step in one compiled loop (the last "
           "column and n* after each); bitwise equal"),
    Kernel("dtw.incremental_set", "dtw:_incremental_set", "interprim.phase.dtw:_step_np", False,
           "query frames against several references in one call, each reference's columns by dtw.incremental_step "
           "(IncrementalDTWSet); the reference is one step of one reference; bitwise equal"),
    Kernel("observation.forcing_values_into", "observation:forcing_values_into",
           "interprim.models.primitive.fitted:FittedPrimitive.observation_design", False,
           "forcing values of Eq. 15 (np.gradient derivatives); the reference's targets Y"),
    Kernel("observation.design_stats", "observation:design_stats",
           "interprim.models.primitive.fitted:FittedPrimitive.observation_design", False,
           "X^T X, X^T Y, |Y|^2 of the forcing observation (Eq. 13-15); the reference's X, Y"),
    Kernel("observation.position_stats", "observation:position_stats",
           "interprim.models.primitive.fitted:FittedPrimitive.observation_design", False,
           "X^T X, X^T Y, |Y|^2 of the position observation (rows of LinearRollout.design); the reference's X, Y"),
    Kernel("observation.forcing_targets_batch", "observation:forcing_targets_batch",
           "interprim.core.dmp:forcing_targets", False,
           "forcing targets of Eq. 3 of equally long demonstrations; reference: preprocessing.derivatives + "
           "dmp.forcing_targets"),
    Kernel("conditioning.lowrank_condition_mean", "conditioning:lowrank_condition_mean",
           "interprim.core.gaussian:LowRankConditioner.mean_numpy", False,
           "posterior mean and evidence of Eq. 16-18 for a diagonal + low-rank prior; the reference returns "
           "(mean, log-likelihood), the kernel (log-dets, residual) for LowRankConditioner.mean_compiled"),
    Kernel("rollout.response_positions", "rollout:response_positions",
           "interprim.models.primitive.prediction:Prediction._response_reference", False,
           "the controlled agent's mean movement from the current phase (Eq. 1, exact discretisation)"),
    Kernel("phase_likelihood.phase_loglik_batch", "phase_likelihood:phase_loglik_batch",
           "interprim.phase.likelihood:_loglik_batch_numpy", False,
           "log-likelihood of the observation at many candidate phases (the likelihood phase); the reference "
           "takes the same arrays without M and out"),
    Kernel("phase_likelihood.phase_loglik_noise_grid", "phase_likelihood:phase_loglik_noise_grid",
           "interprim.phase.likelihood:_loglik_noise_grid_numpy", False,
           "phase_loglik_batch at several position noises, each phase's statistics once (the likelihood phase's "
           "noise selection); its rows equal phase_loglik_batch's bit for bit; the reference takes the same arrays "
           "without M and out"),
    Kernel("resample.interp_columns", "resample:interp_columns_into", "interprim.core.preprocessing:interp_columns",
           False, "numpy.interp of every column at the same points (the one resampling rule); the reference returns "
           "the array the kernel writes into out; bitwise equal"),
    Kernel("blend.weights_on", "blend:weights_on_into", "interprim.models.blend:weights_on_np", False,
           "a blend's look-ahead at every point of the common grid and its weights there (the bands' weights "
           "interpolated, clipped at 0, divided by their sum; up to 7 members, else the reference); the reference "
           "returns the arrays the kernel writes into ahead and W and the count it returns; bitwise equal"),
    Kernel("blend.place_members", "blend:place_members_into", "interprim.models.blend:place_members_np", False,
           "a blend's members read at their own normalised times on the common grid (each at its own speed, then "
           "to the shared end of long_range.member_units) and their weighted sum; the reference returns the arrays "
           "the kernel writes into Y and mean; bitwise equal"),
    Kernel("blend.spread_std", "blend:spread_std_into", "interprim.models.blend:spread_std_np", False,
           "a blend's std on the grid: the members' weighted disagreement through the variance model (a(ahead) "
           "spread + b(ahead)), clipped at 0 and square-rooted; the reference returns the array the kernel writes "
           "into std and the count of positive variances the kernel returns; bitwise equal"),
    Kernel("weighted.weighted_frames", "weighted:weighted_frames", "interprim.models.kernel:weighted_frames_np", True,
           "the weighted mean and spread of demonstrations read at fractional frames (KernelDemonstrations' "
           "prediction), without the (demonstrations, n, D) array of the frames; bitwise equal"),
    Kernel("prefix_rows.prefix_rows_into", "prefix_rows:prefix_rows_into",
           "interprim.models.coupling:prefix_rows_np", True,
           "the prefix coupling's training rows (each demonstration resampled on [0, s] at n_in points, Eq. 17-18's "
           "observation), written into out; bitwise equal"),
    Kernel("prefix_rows.centre_rows_into", "prefix_rows:centre_rows_into",
           "interprim.models.conditioners:centre_rows_np", True,
           "the prefix coupling's rows and query centred by the rows' mean, with the sums of squares its "
           "conditioners read (Eq. 18's smoother per streamed frame: the ridge's trace, the kernel's norms); "
           "numpy's reductions in their order, bitwise equal"),
    Kernel("prefix_rows.cv_loss_into", "prefix_rows:cv_loss_into", "interprim.models.coupling:cv_loss_np", True,
           "the coupling's cross-validation losses of a batch of conditioners on one fold and phase (Eq. 18's "
           "smoother: ybar plus each candidate's product, its controlled columns' weighted squared error over the "
           "held-out queries); numpy's reductions in their order, bitwise equal"),
    Kernel("phase_likelihood.track_step", "phase_likelihood:track_step",
           "interprim.phase.likelihood:_loglik_batch_numpy", False,
           "one frame of the stream's lattice search: each lattice point's statistics extended by the frame; its "
           "log posteriors are the reference's log-likelihoods plus the speed prior"),
)}

_RESOLVED: dict[str, Callable[..., Any]] = {}

def names() -> list[str]:
    """Names of the registered kernels."""
    return list(KERNELS)


def spec(name: str) -> Kernel:
    """The row of kernel ``name`` (``KeyError`` naming the registered ones if there is none)."""
    try:
        return KERNELS[name]
    except KeyError:
        raise KeyError(f"no compiled kernel named {name!r}; registered: {', '.join(KERNELS)}") from None


def compiled(name: str) -> Callable[..., Any]:
    """The compiled kernel ``name`` (imports numba; compiles it, or loads it from the cache, on its first call).

    With ``NUMBA_DISABLE_JIT=1`` this is the kernel's body as a plain Python function.
    """
    fn = _RESOLVED.get(name)
    if fn is None:
        mod, attr = spec(name).compiled.split(":")
        fn = getattr(importlib.import_module(f"{__package__}.{mod}"), attr)
        _RESOLVED[name] = fn
    return fn


def reference(name: str) -> Callable[..., Any]:
    """The numpy reference of the kernel ``name`` (a function, or an unbound method)."""
    mod, qual = spec(name).reference.split(":")
    obj = importlib.import_module(mod)
    for part in qual.split("."):
        obj = getattr(obj, part)
    return obj  # type: ignore[return-value]  # a function or an unbound method, found by name

"""The inner cross-validation's memory, bounded before it is expanded.

:class:`~interprim.model_selection.stacking.CrossValidation` holds the held-out predictions of every family, scored
prefix, step ahead (to the end of the longest demonstration) and column at once, and the default's fit holds a few
copies of them at its peak: 4.8 GB at 50 demonstrations x 48 columns x 600 frames.  :func:`held_out_size` gives
their size from the protocol's own rule before anything runs, and :func:`check_memory` stops a fit that could not
fit in the memory the process may use with an error that names the sizes and the remedies, rather than letting the
system kill it with the work lost.

Pure Python and numpy-free; reads the system's memory size and, on Linux, a container's cgroup limit.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

from .realtime import RealTimeConfig, scored_frames

__all__ = ["held_out_size", "check_memory", "physical_memory", "PEAK_COPIES", "MEMORY_SHARE", "CGROUP_LIMITS"]

#: The fit's peak memory in copies of the held-out predictions (:func:`held_out_size`): measured as the process's
#: peak resident memory of ``AutoInteraction().fit`` at 20-50 demonstrations x 12-48 columns x 600-1200 frames, 4.8-5.5
#: copies above the 0.3-0.5 GB the families and the libraries take (rounded up).
PEAK_COPIES = 6
#: The share of the machine's physical memory the inner cross-validation may take at its peak (the rest is the
#: system's and the caller's): a bound on what cannot fit, not a guarantee that what is below it will (other
#: processes' memory is not counted, so that one input gets one answer on one machine).
MEMORY_SHARE = 0.75


def held_out_size(n_families: int, lengths: Iterable[int], cfg: RealTimeConfig, dt: float,
                  n_dofs: int) -> tuple[int, int, int]:
    """``(cases, steps, bytes)`` of the inner cross-validation's held-out predictions, before it runs: the prefixes
    scored over the held-out demonstrations of ``lengths`` frames (each held out once,
    :func:`~interprim.model_selection.realtime.scored_frames`), the steps ahead each case is scored on
    (``cfg.horizon``), and the bytes of one family's placed means for all of them times ``n_families``
    (:attr:`CrossValidation.mean`'s size)."""
    cases = sum(len(scored_frames(int(T), cfg)) for T in lengths)
    steps = max(1, int(round(cfg.horizon / dt)))
    return cases, steps, 8 * int(n_families) * cases * steps * int(n_dofs)


#: Where Linux states a container's memory limit (cgroup v2, then v1): a process in a container is killed at it, however
#: much memory the machine has.
CGROUP_LIMITS = ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory/memory.limit_in_bytes")


def physical_memory() -> int | None:
    """Bytes of memory this process may use: the machine's physical memory, or the container's limit (cgroup) when
    that is lower (None where the system says neither)."""
    import os

    sizes = []
    try:
        sizes.append(int(os.sysconf("SC_PHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE")))
    except (AttributeError, ValueError, OSError):
        pass
    for path in CGROUP_LIMITS:
        try:
            with open(path, encoding="ascii") as fh:
                text = fh.read(64).strip()  # a number, or "max" (no limit)
        except OSError:
            continue
        if text.isdigit():
            sizes.append(int(text))
        break
    return min(sizes) if sizes else None


def check_memory(n_families: int, lengths: Sequence[int], cfg: RealTimeConfig, dt: float, n_dofs: int) -> None:
    """Raise a ``ValueError`` that names the sizes and the remedies when the inner cross-validation over demonstrations
    of ``lengths`` frames would need more than :data:`MEMORY_SHARE` of the machine's memory at its peak
    (:data:`PEAK_COPIES` copies of its held-out predictions, :func:`held_out_size`): before anything is expanded, not
    a process killed for its memory with the work lost."""
    total = physical_memory()
    cases, steps, one = held_out_size(n_families, lengths, cfg, dt, n_dofs)
    need = PEAK_COPIES * one
    if total is None or need <= MEMORY_SHARE * total:
        return
    mp = "every" if cfg.max_frames is None else str(cfg.max_frames)
    raise ValueError(
        f"the default's inner cross-validation would need about {need / 1e9:.1f} GB at its peak, more than "
        f"{MEMORY_SHARE:.0%} of the {total / 1e9:.1f} GB this process may use: {n_families} families x {cases} "
        f"scored prefixes ({mp} per held-out demonstration) x {steps} steps ahead (to the end of the longest "
        f"demonstration, dt = {dt:g} s) x {n_dofs} columns of held-out predictions, about {PEAK_COPIES} copies of "
        f"{one / 1e9:.2f} GB.  Score fewer prefixes (max_prefixes; interprim fit --max-prefixes N), compare fewer "
        f"families (candidates), or resample the demonstrations to a coarser interval (fewer steps ahead)")

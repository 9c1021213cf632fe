"""One BLAS thread for hot paths made of many tiny factorisations.

numpy and scipy wheels each bundle an OpenBLAS thread pool; on a small,
loaded machine their threads oversubscribe the cores (a 1.5 ms operation
measured 8 ms), and tiny matrices gain nothing from threads anyway.
"""

from __future__ import annotations

from threadpoolctl import threadpool_limits

__all__ = ["single_thread"]


def single_thread():
    """Context limiting the BLAS thread pools to one thread (many tiny factorisations: threads only add
    overhead, up to 100x on a loaded 2-core machine; SLSQP of the simulated arms up to 20x)."""
    return threadpool_limits(1)

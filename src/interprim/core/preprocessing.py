"""Pre-processing of recorded movements (paper Sec. IV): resampling, smoothing,
derivatives and PCA.

The forcing terms of Eq. 3 and Eq. 15 need accelerations of recorded data, and
recorded data is noisy: derivatives are taken with a Savitzky-Golay filter
(a local polynomial fit), whose window is a visible parameter everywhere it
is used.  ``window=None`` falls back to plain central differences
(``numpy.gradient``), which is exact on smooth synthetic data.
"""

from __future__ import annotations

from collections.abc import Iterable
from functools import lru_cache
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from ._compiled import registry as _registry
from .validation import as_2d_finite, check_times

__all__ = ["resample_uniform", "resample_step", "step_count", "step_grid", "interp_columns", "unit_grid",
           "start_position", "derivatives", "PCA", "time_normalise", "column_index"]


def column_index(cols: Iterable[int]) -> slice | list[int]:
    """``cols`` (column numbers) as a slice when they are consecutive and increasing, else as a list: indexing the
    last axis with it gives the same values, as a view instead of a copy when it is a slice."""
    cols = [int(i) for i in cols]
    if cols and cols == list(range(cols[0], cols[-1] + 1)):
        return slice(cols[0], cols[-1] + 1)
    return cols


def interp_columns(x_new: ArrayLike, x: ArrayLike, y: ArrayLike) -> np.ndarray:
    """Linear interpolation of every column of ``y`` (sampled at ``x``) at ``x_new``: the one resampling rule.

    Parameters
    ----------
    x_new : float or array_like, shape (n,)
        Where to evaluate (held at the end values outside ``x``, as :func:`numpy.interp`).
    x : array_like, shape (T,)
        Increasing sample positions (times, normalised times or frame indices).
    y : array_like, shape (T, D)
        Values.

    Returns
    -------
    ndarray, shape (n, D) (``(D,)`` for a scalar ``x_new``)
        Column ``d`` is ``numpy.interp(x_new, x, y[:, d])``.
    """
    y = np.asarray(y, dtype=np.float64)
    if y.shape[1] == 0:
        return np.empty(np.shape(x_new) + (0,))
    x_new = np.asarray(x_new, dtype=np.float64)
    x = np.ascontiguousarray(x, dtype=np.float64)
    if x_new.ndim == 1 and x.ndim == 1 and y.shape[0] == x.shape[0] and y.shape[1] > 1:
        # the compiled kernel when the kernels are loaded already (the same bits as numpy.interp; never loads them)
        kernel = _registry.loaded_kernel("resample.interp_columns")
        if kernel is not None:
            out = np.empty((x_new.shape[0], y.shape[1]))
            if kernel(np.ascontiguousarray(x_new), x, np.ascontiguousarray(y), out):
                return out
    # numpy.interp's own C routine, called once per column on arrays converted once (numpy.interp's Python
    # wrapper converts x_new and x again for every column and checks for complex values): the same numbers
    cols = np.ascontiguousarray(y.T)
    return np.stack([_interp_1d(x_new, x, c, None, None) for c in cols], axis=-1)


try:  # numpy >= 2 (numpy.interp's C routine; a private name, hence the fallbacks)
    from numpy._core.multiarray import interp as _interp_1d
except ImportError:
    try:  # numpy 1.x
        from numpy.core.multiarray import interp as _interp_1d  # type: ignore[no-redef]  # the same routine
    except ImportError:  # a numpy that moved it: numpy.interp itself (the same numbers, a little slower)

        def _interp_1d(x_new: Any, x: Any, y: Any, left: Any, right: Any) -> Any:  # type: ignore[no-redef]  # idem
            return np.interp(x_new, x, y, left, right)


def unit_grid(n: int) -> np.ndarray:
    """``linspace(0, 1, n)``, the normalised-time grid, computed once per ``n`` (read-only: shared by every caller)."""
    n = int(n)
    out = _UNIT_GRIDS.get(n)
    if out is None:
        out = np.linspace(0.0, 1.0, n)
        out.setflags(write=False)
        if len(_UNIT_GRIDS) >= 64:  # a few sizes in use at a time
            _UNIT_GRIDS.clear()
        _UNIT_GRIDS[n] = out
    return out


_UNIT_GRIDS: dict[int, np.ndarray] = {}


def step_count(duration: float, dt: float) -> int:
    """Frames of a grid ``0, dt, 2 dt, ...`` that fit in ``duration`` (a ``1e-9`` step of tolerance for rounding)."""
    return int(np.floor(duration / dt + 1e-9)) + 1


def step_grid(duration: float, dt: float) -> np.ndarray:
    """The grid ``0, dt, ..., (n - 1) dt`` of :func:`step_count` frames (it ends at or before ``duration``)."""
    return np.arange(step_count(duration, dt)) * dt


def resample_step(y: ArrayLike, times: ArrayLike, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Interpolate a ``(T, D)`` movement onto ``times[0] + k dt`` up to ``times[-1]`` (the step kept exactly).

    Unlike :func:`resample_uniform`, which stretches its step so that the grid ends at ``times[-1]``, the grid
    keeps the step ``dt`` and stops at or before the last time stamp (:func:`step_grid`).

    Parameters
    ----------
    y : array_like, shape (T, D)
    times : array_like, shape (T,)
        Increasing time stamps in seconds.
    dt : float
        Output sampling interval in seconds.

    Returns
    -------
    y_step : ndarray, shape (n, D)
    t_step : ndarray, shape (n,)
    """
    t = np.asarray(times, dtype=np.float64)
    t_new = t[0] + step_grid(t[-1] - t[0], dt)
    return interp_columns(t_new, t, y), t_new


def resample_uniform(y: ArrayLike, times: ArrayLike, n: int | None = None,
                     dt: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Linearly interpolate an irregularly sampled ``(T, D)`` movement onto a uniform grid.

    Parameters
    ----------
    y : array_like, shape (T, D)
    times : array_like, shape (T,)
        Strictly increasing time stamps in seconds.
    n : int, optional
        Number of output frames (covering ``times[0]`` to ``times[-1]``).
    dt : float, optional
        Output sampling interval in seconds (used when ``n`` is not given);
        defaults to the median interval of ``times``.

    Returns
    -------
    y_uniform : ndarray, shape (n, D)
    t_uniform : ndarray, shape (n,)
    """
    y = as_2d_finite(y, "y", min_rows=2)
    t = check_times(times, y.shape[0], "times")
    if n is None:
        if dt is None:
            dt = float(np.median(np.diff(t)))
        n = int(round((t[-1] - t[0]) / dt)) + 1
    n = max(int(n), 2)
    tu = np.linspace(t[0], t[-1], n)
    return interp_columns(tu, t, y), tu


def time_normalise(y: ArrayLike, n: int) -> np.ndarray:
    """Resample a uniformly sampled ``(T, D)`` movement to ``n`` frames over normalised time [0, 1]."""
    a = np.asarray(y, dtype=np.float64)
    if a.shape[0] == n:
        return np.array(a)  # a copy
    return interp_columns(np.linspace(0.0, 1.0, n), np.linspace(0.0, 1.0, a.shape[0]), a)


def savgol_window(T: int, window: int | None, polyorder: int = 3) -> tuple[int, int] | None:
    """The Savitzky-Golay ``(window, polyorder)`` used for ``T`` frames, or ``None`` for no smoothing.

    The window shrinks to the largest odd number not above ``T``; ``None`` when ``window`` is None or
    too short to smooth (fewer than 3 frames, or a polynomial order below 2).
    """
    if window is None:
        return None
    w = min(int(window), T if T % 2 == 1 else T - 1)
    if w % 2 == 0:
        w -= 1
    p = min(polyorder, w - 1)
    return (w, p) if w >= 3 and p >= 2 else None


@lru_cache(maxsize=64)
def _savgol_start_coeffs(w: int, p: int) -> np.ndarray:
    """Weights ``c`` (w,) with ``c @ y[:w]`` = the Savitzky-Golay (``mode="interp"``) smoothed first frame.

    That frame is the value at the first sample of the degree-``p`` least-squares
    polynomial through the first ``w`` samples, i.e. row 0 of the hat matrix
    ``Q Q^T`` (``Q`` an orthonormal basis of the polynomials on the window,
    from a QR of the Vandermonde matrix on ``[-1, 1]``: accurate to ~1e-16,
    where ``scipy.signal.savgol_coeffs(w, p, pos=0)`` loses ~1e-12 at ``w = 31``).
    """
    x = np.linspace(-1.0, 1.0, w)
    Q, _ = np.linalg.qr(np.vander(x, p + 1))
    c: np.ndarray = Q @ Q[0]
    c.setflags(write=False)
    return c


def start_position(z: np.ndarray, window: int | None, polyorder: int = 3) -> np.ndarray:
    """``derivatives(z, ds, window, polyorder)[0][0]`` (:func:`derivatives`) in ``O(window D)``.

    The first frame of the smoothed observation, with the same window rule
    (shrunk to the largest odd number not above ``len(z)``); the raw first
    frame when ``window`` is None or too short to smooth.  A new array.
    """
    wp = savgol_window(z.shape[0], window, polyorder)
    if wp is not None:
        out: np.ndarray = _savgol_start_coeffs(*wp) @ z[:wp[0]]
        return out
    first: np.ndarray = z[0].copy()
    return first


def derivatives(y: np.ndarray, ds: float, window: int | None = None,
                polyorder: int = 3) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Smoothed position, first and second derivative of a uniformly sampled movement.

    Parameters
    ----------
    y : ndarray, shape (T, D)
        Positions, time on axis 0.
    ds : float
        Sampling interval (in whatever time unit the derivatives should use;
        interprim uses normalised time, see :mod:`interprim.core.dmp`).
    window : int or None
        Savitzky-Golay window length in frames (odd; it is shrunk to the
        largest odd number not above ``T`` when the movement is short).
        ``None`` means no smoothing: second-order central differences.
    polyorder : int
        Polynomial order of the Savitzky-Golay filter (default 3).

    Returns
    -------
    y_s, yd, ydd : ndarray, shape (T, D) each
    """
    y = np.asarray(y, dtype=np.float64)
    T = y.shape[0]
    if T < 3:
        raise ValueError(f"derivatives need at least 3 frames, got {T}")
    wp = savgol_window(T, window, polyorder)
    if wp is not None:
        from scipy.signal import savgol_filter  # lazy: scipy.signal takes ~0.5 s to import

        w, p = wp
        y_s = savgol_filter(y, w, p, deriv=0, axis=0, mode="interp")
        yd = savgol_filter(y, w, p, deriv=1, delta=ds, axis=0, mode="interp")
        ydd = savgol_filter(y, w, p, deriv=2, delta=ds, axis=0, mode="interp")
        return y_s, yd, ydd
    yd = np.gradient(y, ds, axis=0, edge_order=2)
    ydd = np.gradient(yd, ds, axis=0, edge_order=2)
    return y.copy(), yd, ydd


class PCA:
    """Principal component analysis of the frames of one agent (paper Sec. IV).

    The paper projects high-dimensional motion capture onto a five-dimensional
    space before learning the IP.  ``fit`` takes all frames of all
    demonstrations; ``transform`` and ``inverse_transform`` map ``(T, D)`` to
    ``(T, k)`` and back.

    Parameters
    ----------
    n_components : int
        Number of principal components ``k`` kept.
    """

    def __init__(self, n_components: int) -> None:
        if int(n_components) < 1:
            raise ValueError(f"n_components must be >= 1, got {n_components}")
        self.n_components = int(n_components)

    def fit(self, frames: ArrayLike) -> PCA:
        """Fit the components to all frames.

        Parameters
        ----------
        frames : array_like, shape (n_frames, D)
            At least 2 finite frames (e.g. the frames of all demonstrations stacked), ``D >= n_components``.

        Returns
        -------
        PCA
            ``self``, with ``mean_`` (D,), ``components_`` (k, D; orthonormal rows, each with its largest
            loading positive so the result is deterministic) and ``explained_variance_ratio_`` (k,).
        """
        X = as_2d_finite(frames, "frames", min_rows=2)
        if self.n_components > X.shape[1]:
            raise ValueError(f"n_components={self.n_components} exceeds the {X.shape[1]} dimensions of the data")
        self.mean_ = X.mean(axis=0)
        _, s, vt = np.linalg.svd(X - self.mean_, full_matrices=False)
        # deterministic sign: largest |loading| of each component is positive
        signs = np.sign(vt[np.arange(vt.shape[0]), np.argmax(np.abs(vt), axis=1)])
        signs[signs == 0] = 1.0
        vt = vt * signs[:, None]
        self.components_ = vt[: self.n_components]
        var = s**2 / max(X.shape[0] - 1, 1)
        self.explained_variance_ratio_ = var[: self.n_components] / max(var.sum(), np.finfo(float).tiny)
        return self

    def transform(self, X: ArrayLike) -> np.ndarray:
        """Project frames ``(..., D)`` on the components: ``(X - mean_) @ components_.T``, shape ``(..., k)``."""
        out: np.ndarray = (np.asarray(X, dtype=np.float64) - self.mean_) @ self.components_.T
        return out

    def inverse_transform(self, Z: ArrayLike) -> np.ndarray:
        """Map component scores ``(..., k)`` back to frames ``(..., D)``: ``Z @ components_ + mean_``."""
        out: np.ndarray = np.asarray(Z, dtype=np.float64) @ self.components_ + self.mean_
        return out

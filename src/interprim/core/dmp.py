"""Dynamic movement primitives (paper Sec. III-A, Eq. 1-4, and Eq. 12-15).

The DMP of the paper, for one degree of freedom, in real time ``t``::

    ydd = (alpha_y (beta_y (g - y) - yd / tau) + f(x)) tau^2          (Eq. 1)

In normalised time ``s = t tau`` (``y' = yd / tau``, ``y'' = ydd / tau^2``) the
same system reads ``y'' = alpha_y (beta_y (g - y) - y') + f(x(s))``: ``tau``
only stretches time.  All functions here therefore work in normalised time
and convert to seconds at the edges.

Rearranged so that everything unknown is on the right (Eq. 12-13)::

    y'' + alpha_y y' + alpha_y beta_y y = phi(x)^T w + alpha_y beta_y g = [phi^T, alpha_y beta_y] [w; g]

The left-hand side is the *forcing value* of a recorded movement (Eq. 15,
:func:`forcing_values`); with ``g`` known it gives the forcing targets of
Eq. 3 (:func:`forcing_targets`).

Integration (:class:`LinearRollout`) is exact for the linear ODE with the
forcing held at its mid-step value on a fine grid of ``n_steps`` steps
(zero-order hold), and, because positions are linear in ``theta = [w, g]``
for a given start state, it is precomputed once as a linear map.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import lru_cache

import numpy as np
from numpy.typing import ArrayLike

from .basis import Basis

__all__ = ["forcing_targets", "forcing_values", "fit_weights", "fit_weights_stacked", "fit_weights_targets",
           "LinearRollout", "cached_rollout", "representation_report", "warn_representation"]


def forcing_targets(y: np.ndarray, yd: np.ndarray, ydd: np.ndarray, g: np.ndarray, alpha_y: float,
                    beta_y: float) -> np.ndarray:
    """Forcing targets ``F = y'' - alpha_y (beta_y (g - y) - y')`` (Eq. 3, normalised time).

    ``y, yd, ydd`` have shape ``(T, D)``, ``g`` shape ``(D,)``.
    """
    return ydd - alpha_y * (beta_y * (g - y) - yd)


def forcing_values(y: np.ndarray, yd: np.ndarray, ydd: np.ndarray, alpha_y: float, beta_y: float) -> np.ndarray:
    """Forcing values of an observation, Eq. 15: ``f* = y'' - alpha_y (-beta_y y - y')``.

    These equal ``Phi_tilde theta`` (Eq. 13-14) for the movement's parameters.
    """
    return ydd + alpha_y * (beta_y * y + yd)


def fit_weights(Y_list: Sequence[np.ndarray], Yd_list: Sequence[np.ndarray], Ydd_list: Sequence[np.ndarray],
                basis: Basis, alpha_y: float, beta_y: float,
                ridge: float = 1e-10) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares DMP parameters of many demonstrations at once (Eq. 3-4).

    The goal of each DoF is its last recorded position (``g = y_T``); the
    weights solve ``Phi w = F`` in the least-squares sense (Eq. 4) with a tiny
    ridge for numerical safety.  Demonstrations of the same length share one
    Cholesky factorisation of ``Phi^T Phi``; all their DoFs are solved in one
    call (:func:`fit_weights_stacked`).

    Parameters
    ----------
    Y_list, Yd_list, Ydd_list : list of ndarray, shape (T_j, D)
        Positions and first/second derivatives in normalised time.

    Returns
    -------
    theta : ndarray, shape (S, D, n_basis + 1)
        Per demonstration and DoF ``[w_1..w_m, g]``.
    residual_ms : ndarray, shape (S, D)
        Mean squared residual ``|F - Phi w|^2 / T`` of the fit.
    """
    S = len(Y_list)
    D = Y_list[0].shape[1]
    m = basis.n_basis
    theta = np.empty((S, D, m + 1))
    resid = np.empty((S, D))
    groups: dict[int, list[int]] = {}
    for j, Y in enumerate(Y_list):
        groups.setdefault(Y.shape[0], []).append(j)
    for idx in groups.values():
        th, r = fit_weights_stacked(np.stack([Y_list[j] for j in idx]), np.stack([Yd_list[j] for j in idx]),
                                    np.stack([Ydd_list[j] for j in idx]), basis, alpha_y, beta_y, ridge)
        theta[idx] = th
        resid[idx] = r
    return theta, resid


def fit_weights_stacked(Y: np.ndarray, Yd: np.ndarray, Ydd: np.ndarray, basis: Basis, alpha_y: float, beta_y: float,
                        ridge: float = 1e-10, resid_dofs: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """:func:`fit_weights` for ``n`` demonstrations of one length stacked as ``(n, T, D)`` arrays.

    One Cholesky factorisation of ``Phi^T Phi`` (Eq. 4) and one BLAS product
    for all demonstrations and DoFs; the forcing targets (Eq. 3) are formed in
    one preallocated buffer.  ``resid_dofs`` (a slice or index array) limits
    the residuals to those DoFs (the others are NaN), e.g. the observed agent's
    for ``sigma2="residual"``.

    Returns ``theta`` ``(n, D, n_basis + 1)`` and the mean squared residuals ``(n, D)``.
    """
    g = Y[:, -1, :]  # (n, D)
    # F = ydd - alpha_y (beta_y (g - y) - yd)   (Eq. 3), same operations as forcing_targets
    F = np.subtract(g[:, None, :], Y)
    F *= beta_y
    F -= Yd
    F *= alpha_y
    np.subtract(Ydd, F, out=F)
    return fit_weights_targets(F, g, basis, ridge, resid_dofs)


def fit_weights_targets(F: np.ndarray, g: np.ndarray, basis: Basis, ridge: float = 1e-10,
                        resid_dofs: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 4 for forcing targets ``F`` ``(n, T, D)`` (Eq. 3) and goals ``g`` ``(n, D)``; see
    :func:`fit_weights_stacked`."""
    n, T, D = F.shape
    m = basis.n_basis
    Phi = basis.phi(np.linspace(0.0, 1.0, T))  # (T, m)
    PtP = Phi.T @ Phi
    PtP[np.diag_indices_from(PtP)] += ridge * max(np.trace(PtP) / m, 1e-300)
    L = np.linalg.cholesky(PtP)
    # Phi^T F per demonstration (n small BLAS products, no transposed copy of F), then as (m, n D)
    rhs = np.ascontiguousarray(np.transpose(np.matmul(Phi.T, F), (1, 0, 2))).reshape(m, n * D)
    W = np.linalg.solve(L.T, np.linalg.solve(L, rhs)).reshape(m, n, D)
    theta = np.empty((n, D, m + 1))
    theta[:, :, :m] = np.transpose(W, (1, 2, 0))
    theta[:, :, m] = g
    resid = np.full((n, D), np.nan)
    sel = slice(None) if resid_dofs is None else resid_dofs
    Fs = F[:, :, sel]
    R = np.matmul(Phi, np.ascontiguousarray(np.transpose(W, (1, 0, 2))[:, :, sel]))  # (n, T, d)
    np.subtract(Fs, R, out=R)
    R *= R
    resid[:, sel] = R.mean(axis=1)
    return theta, resid


def _expm_small(A: np.ndarray) -> np.ndarray:
    """Matrix exponential of a small matrix by scaling and squaring with a Taylor series (to double precision)."""
    nrm = float(np.abs(A).sum(axis=1).max())
    k = max(0, int(np.ceil(np.log2(nrm / 0.25))) if nrm > 0.25 else 0)
    X = A / (2.0**k)
    E = np.eye(A.shape[0])
    term = np.eye(A.shape[0])
    for i in range(1, 20):
        term = term @ X / i
        E = E + term
    for _ in range(k):
        E = E @ E
    return E


def _scan_powers(Ad: np.ndarray, n: int) -> np.ndarray:
    """``Ad^k`` for ``k = 0..n`` by doubling (``log2 n`` batched products instead of ``n``)."""
    out = np.empty((n + 1,) + Ad.shape)
    out[0] = np.eye(Ad.shape[0])
    have = 1
    P = Ad.copy()  # Ad^have
    while have <= n:
        take = min(have, n + 1 - have)
        out[have:have + take] = P @ out[:take]
        have += take
        P = P @ P
    return out


#: the most values (float64: 512 MiB) of the arrays a :class:`LinearRollout` precomputes
MAX_ROLLOUT_VALUES = 1 << 26


def rollout_values(n_basis: int, n_steps: int) -> int:
    """Values of the arrays a :class:`LinearRollout` of ``n_basis`` basis functions over ``n_steps`` steps
    precomputes: the powers ``(n_steps + 1, 2, 2)`` and the forced response ``(n_steps + 1, 2, n_basis + 1)``."""
    return (int(n_steps) + 1) * (4 + 2 * (int(n_basis) + 1))


def check_rollout_size(n_basis: int, n_steps: int) -> None:
    """``ValueError`` naming ``n_steps`` unless it is a positive integer whose rollout (:func:`rollout_values`) stays
    within :data:`MAX_ROLLOUT_VALUES`: checked before anything is allocated."""
    if isinstance(n_steps, bool) or not isinstance(n_steps, (int, np.integer)) or n_steps < 1:
        raise ValueError(f"n_steps must be a positive integer, got {n_steps!r}")
    n = rollout_values(n_basis, n_steps)
    if n > MAX_ROLLOUT_VALUES:
        limit = MAX_ROLLOUT_VALUES // (4 + 2 * (int(n_basis) + 1)) - 1
        raise ValueError(f"n_steps={int(n_steps)} with n_basis={int(n_basis)} would precompute {n} values for the "
                         f"DMP rollout, over the limit of {MAX_ROLLOUT_VALUES}: n_steps must be at most {limit}")


@lru_cache(maxsize=16)
def _discretisation(alpha_y: float, beta_y: float, n_steps: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact zero-order-hold discretisation of the DMP's linear part over one step ``1 / n_steps``."""
    h = 1.0 / n_steps
    A = np.array([[0.0, 1.0], [-alpha_y * beta_y, -alpha_y]])
    M = np.zeros((3, 3))
    M[:2, :2] = A
    M[1, 2] = 1.0
    E = _expm_small(M * h)
    Ad, Bd = E[:2, :2], E[:2, 2]
    powers = _scan_powers(Ad, n_steps)
    return Ad, Bd, powers


class LinearRollout:
    """Integration of Eq. 1 as a precomputed linear map (normalised time).

    For a DoF with start state ``z0 = [y, y']`` at normalised time ``s0`` and
    parameters ``theta = [w, g]``, the position at ``s >= s0`` is::

        y(s) = e1^T Ad^(k-k0) z0 + (Z[k] - Ad^(k-k0) Z[k0])[0] @ theta

    where ``Z[k]`` is the state reached from rest at ``s = 0`` under unit forcing
    of each basis function (and of the goal term ``alpha_y beta_y``), computed
    once by the exact discretisation of the critically damped system on a grid
    of ``n_steps`` steps.  Times are snapped to that grid (error at most
    ``0.5 / n_steps`` in normalised time).

    Parameters
    ----------
    basis : Basis
    alpha_y, beta_y : float
    n_steps : int
        Number of integration steps over the whole movement (default 2000).
    """

    def __init__(self, basis: Basis, alpha_y: float, beta_y: float, n_steps: int = 2000):
        self.basis = basis
        self.alpha_y = float(alpha_y)
        self.beta_y = float(beta_y)
        check_rollout_size(basis.n_basis, n_steps)
        self.n_steps = int(n_steps)
        K = self.n_steps
        Ad, Bd, powers = _discretisation(self.alpha_y, self.beta_y, K)
        self.powers = self._powers = powers  # (K+1, 2, 2): powers of the one-step transition
        mid = (np.arange(K) + 0.5) / K
        U = basis.phi_tilde(mid, self.alpha_y, self.beta_y)  # (K, q)
        q = U.shape[1]
        # forced response from rest: Z[k+1] = Ad Z[k] + Bd u_k, i.e. Z[k] = sum_{l<k} Ad^(k-1-l) Bd u_l,
        # as an inclusive scan by doubling (log2 K vectorised steps; Hillis-Steele)
        Z = np.zeros((K + 1, 2, q))
        Z[1:] = Bd[None, :, None] * U[:, None, :]
        shift = 1
        while shift <= K:
            P = powers[shift]
            src = Z[1:K + 1 - shift].copy()
            dst = Z[shift + 1:]
            dst[:, 0] += P[0, 0] * src[:, 0] + P[0, 1] * src[:, 1]
            dst[:, 1] += P[1, 0] * src[:, 0] + P[1, 1] * src[:, 1]
            shift *= 2
        self.Z = self._Z = Z  # (K+1, 2, q): the forced response's rows on the grid

    @property
    def n_params(self) -> int:
        """Parameters ``q`` of one DoF (``[w, g]``: ``n_basis + 1``), the columns of the design per DoF."""
        return self._Z.shape[2]

    def index(self, s: ArrayLike) -> np.ndarray:
        """Grid index of normalised time(s) ``s`` (clipped to [0, 1])."""
        return np.clip(np.rint(np.asarray(s, dtype=np.float64) * self.n_steps), 0, self.n_steps).astype(np.intp)

    def design(self, s0: float, s_out: ArrayLike, derivative: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """Linear map from start state and ``theta`` to positions (or velocities) at ``s_out``.

        Returns
        -------
        free : ndarray, shape (n, 2)
            Map from the start state ``[y(s0), y'(s0)]``.
        H : ndarray, shape (n, n_basis + 1)
            Map from ``theta = [w, g]``.

        ``y(s_out) = free @ z0 + H @ theta``.  ``s0`` is snapped to the grid
        point ``k0`` and the output times are counted from it (``s0`` itself is
        ``k0``, so ``y(s0)`` is the start state exactly; the times are shifted by
        less than half a grid step); outputs are interpolated linearly between grid
        points, and outputs before ``s0`` are clipped to ``s0``.  ``derivative=1``
        gives ``y'`` (normalised time).
        """
        k0 = int(self.index(s0))
        # linear interpolation between the two grid points around each output time
        u = np.clip(k0 + (np.asarray(s_out, dtype=np.float64) - float(s0)) * self.n_steps, k0, self.n_steps)
        kf = np.minimum(np.floor(u).astype(np.intp), self.n_steps - 1)
        kf = np.maximum(kf, k0)
        a = (u - kf)[:, None]
        row = int(derivative)
        free = np.zeros((u.shape[0], 2))
        H = np.zeros((u.shape[0], self._Z.shape[2]))
        for k, wgt in ((kf, 1.0 - a), (np.minimum(kf + 1, self.n_steps), a)):
            P = self._powers[k - k0][:, row, :]  # (n, 2)
            free += wgt * P
            H += wgt * (self._Z[k, row, :] - P @ self._Z[k0])
        return free, H

    def grid_design(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`design` ``(0, linspace(0, 1, n))``, the map of every whole-movement trajectory on ``n`` points,
        computed once per ``n`` (read-only arrays: it depends on the rollout only, and a streamed frame asks for
        it again with every prediction's trajectory)."""
        n = int(n)
        cache = self.__dict__.setdefault("_grid_designs", {})
        out = cache.get(n)
        if out is None:
            out = self.design(0.0, np.linspace(0.0, 1.0, n))
            for a in out:
                a.setflags(write=False)
            if len(cache) >= 8:  # a few grid sizes in use at a time
                cache.clear()
            cache[n] = out
        return out

    def rollout(self, theta: np.ndarray, y0: ArrayLike, yd0: ArrayLike, s0: float = 0.0, s_out: ArrayLike | None = None,
                n: int = 100) -> np.ndarray:
        """Positions of several DoFs from a start state (Eq. 1 integrated).

        Parameters
        ----------
        theta : ndarray, shape (D, n_basis + 1)
            ``[w, g]`` per DoF.
        y0, yd0 : ndarray, shape (D,)
            Start position and velocity ``y' = dy/ds`` at ``s0``.
        s0 : float
            Normalised start time.
        s_out : ndarray, optional
            Normalised output times; default ``n`` points from ``s0`` to 1.

        Returns
        -------
        ndarray, shape (len(s_out), D)
        """
        theta = np.atleast_2d(np.asarray(theta, dtype=np.float64))
        if s_out is None:
            s_out = np.linspace(s0, 1.0, n)
        free, H = self.design(s0, s_out)
        z0 = np.stack([np.broadcast_to(y0, theta.shape[0]), np.broadcast_to(yd0, theta.shape[0])])  # (2, D)
        return free @ z0 + H @ theta.T

    def integrate(self, theta: np.ndarray, y0: ArrayLike, yd0: ArrayLike = 0.0, tau: float = 1.0, dt: float = 0.01,
                  x0: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
        """Integrate Eq. 1 in real time from phase ``x0`` until ``x = exp(-alpha_x)``.

        Parameters
        ----------
        theta : ndarray, shape (D, n_basis + 1)
            ``[w, g]`` per DoF; change ``g`` to move the goal.
        y0, yd0 : array_like, shape (D,)
            Start position and velocity (velocity in units per second).
        tau : float
            Time scaling (1 / duration in seconds); larger is faster.
        dt : float
            Output sampling interval in seconds.
        x0 : float
            Canonical phase at the start (1 = beginning of the movement).

        Returns
        -------
        t : ndarray, shape (n,)
            Time stamps in seconds from the start.
        y : ndarray, shape (n, D)
        """
        s0 = float(-np.log(x0) / self.basis.alpha_x)
        n = int(np.floor((1.0 - s0) / (tau * dt) + 1e-9)) + 1
        t = np.arange(n) * dt
        y = self.rollout(theta, np.asarray(y0, float), np.asarray(yd0, float) / tau, s0, s0 + t * tau)
        return t, y


@lru_cache(maxsize=8)
def cached_rollout(n_basis: int, alpha_x: float, alpha_y: float, beta_y: float, n_steps: int) -> LinearRollout:
    """A shared :class:`LinearRollout` per hyper-parameter set (it depends on nothing learned; treat it as
    read-only)."""
    return LinearRollout(Basis(int(n_basis), float(alpha_x)), float(alpha_y), float(beta_y), int(n_steps))


def representation_report(latent: Sequence[np.ndarray], starts: Sequence[tuple[np.ndarray, np.ndarray]],
                          theta: np.ndarray, rollout: LinearRollout, n: int = 101,
                          groups: dict[str, Sequence[int] | slice] | None = None) -> dict[str, dict[str, float]]:
    """How well the DMPs (Eq. 1-4) represent the demonstrations, relative to the spread between them.

    For every demonstration, its own parameters ``theta[j]`` are rolled out (Eq. 1) from its start state and
    compared with what was recorded; and the mean parameters are rolled out from the mean start and compared
    with the demonstrations' mean, all on a normalised-time grid of ``n`` points.  Both errors are divided by
    the spread between demonstrations (RMS distance of each from their mean): a ratio near 0 means the DMPs
    keep what distinguishes the demonstrations, a ratio near or above 1 means they lose it (e.g. a periodic
    movement with too few basis functions).

    Parameters
    ----------
    latent : list of ndarray, shape (T_j, d)
        The demonstrations in the space the DMPs model.
    starts : list of (ndarray (d,), ndarray (d,))
        Start position and velocity (normalised time) of each demonstration.
    theta : ndarray, shape (S, d, n_basis + 1)
        Each demonstration's DMP parameters.
    rollout : LinearRollout
        The rollout map.
    groups : dict, optional
        ``{name: slice or list of latent columns}`` to report separately (default: all as ``"all"``).

    Returns
    -------
    dict
        Per group: ``{"reconstruction": RMS reconstruction error / spread, "mean_offset": RMS distance of the
        DMP mean from the data mean / spread, "spread": RMS spread}``.
    """
    from .preprocessing import time_normalise

    s = np.linspace(0.0, 1.0, int(n))
    free, H = rollout.design(0.0, s)
    Y = np.stack([time_normalise(np.asarray(z, dtype=np.float64), n) for z in latent])  # (S, n, d)
    rec = np.stack([free @ np.stack([y0, v0]) + H @ th.T for (y0, v0), th in zip(starts, theta)])
    y0m = np.mean([st[0] for st in starts], axis=0)
    v0m = np.mean([st[1] for st in starts], axis=0)
    mean_roll = free @ np.stack([y0m, v0m]) + H @ np.mean(theta, axis=0).T
    data_mean = Y.mean(axis=0)
    out = {}
    for name, cols in (groups or {"all": slice(None)}).items():
        spread = float(np.sqrt(np.mean((Y[:, :, cols] - data_mean[None, :, cols]) ** 2)))
        if spread <= 0:
            out[name] = {"reconstruction": 0.0, "mean_offset": 0.0, "spread": 0.0}
            continue
        out[name] = {
            "reconstruction": float(np.sqrt(np.mean((rec[:, :, cols] - Y[:, :, cols]) ** 2)) / spread),
            "mean_offset": float(np.sqrt(np.mean((mean_roll[:, cols] - data_mean[:, cols]) ** 2)) / spread),
            "spread": spread,
        }
    return out


#: Above this ratio (error / spread between demonstrations) the DMPs lose most of what distinguishes the
#: demonstrations, and fit warns (:class:`~interprim.core.errors.RepresentationWarning`).
REPRESENTATION_LIMIT = 0.5


def warn_representation(report: dict[str, dict[str, float]], n_basis: int, stacklevel: int = 4) -> None:
    """One warning, with the numbers and what to do, when the DMPs cannot represent the demonstrations
    (``stacklevel``: of :func:`warnings.warn`, counted from here, so that it names the user's line)."""
    import warnings

    from .errors import RepresentationWarning

    bad = {a: r for a, r in report.items() if max(r["reconstruction"], r["mean_offset"]) > REPRESENTATION_LIMIT}
    if not bad:
        return
    what = "; ".join(f"{a} agent: reconstruction {r['reconstruction']:.2f}x and mean {r['mean_offset']:.2f}x the "
                     f"spread between demonstrations" for a, r in bad.items())
    warnings.warn(f"the DMPs with n_basis={n_basis} cannot represent these movements ({what}; above "
                  f"{REPRESENTATION_LIMIT}x they lose what distinguishes the demonstrations, as periodic or long "
                  f"movements do). Try a larger n_basis (e.g. {2 * n_basis}), and compare with "
                  f"LearnedInteraction and the kernel-weighted demonstrations on your data: "
                  f"interprim evaluate --data FILE", RepresentationWarning, stacklevel=stacklevel)

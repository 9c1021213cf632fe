"""The model's belief about the whole interaction after a partial observation (paper Sec. III-C/D, Eq. 1, 18).

A :class:`Prediction` holds the posterior ``p(theta | tau_o)`` (Eq. 18) of one
:meth:`~interprim.models.primitive.estimator.InteractionPrimitive.predict` or
:meth:`~interprim.models.primitive.stream.Stream.update` and integrates the DMPs (Eq. 1) from it:
the whole movement of both agents, its uncertainty and samples, the robot's
response from the current phase and the completion of the observed agent.
:class:`MeanRollout` is the mean trajectory of many predictions of one model on
one grid, with the grid's design built once (what the streaming server sends
per frame).
"""

from __future__ import annotations

import math

import numpy as np

from ...core._compiled import registry as kernels
from ...core.blas import one_blas_thread
from ...core.gaussian import Posterior, sample
from ..base import BasePrediction

__all__ = ["Prediction", "MeanRollout"]


#: :func:`_selected_columns` of an identity map
_SAME_COLUMNS = np.empty(0, dtype=np.intp)


def _selected_columns(M: np.ndarray, off: np.ndarray):
    """The latent column of each data column when the latent map ``M`` (D x D_latent) selects one latent DoF per
    data column (one 1 per row, 0 elsewhere) and the offset is +0 (:meth:`Prediction.grid_mean`);
    :data:`_SAME_COLUMNS` for the identity; None for another map."""
    if not (np.all((M == 0.0) | (M == 1.0)) and np.all(np.count_nonzero(M, axis=1) == 1)
            and not np.any(off) and not np.any(np.signbit(off))):
        return None
    cols = np.argmax(M, axis=1).astype(np.intp)
    return _SAME_COLUMNS if M.shape[0] == M.shape[1] and np.array_equal(cols, np.arange(M.shape[0])) else cols


class Prediction(BasePrediction):
    """The model's belief about the whole interaction after a partial observation.

    Attributes
    ----------
    phase : float
        Fraction of the movement already seen, in (0, 1] (DTW, Eq. 8).
    x : float
        Canonical-system phase ``exp(-alpha_x * phase)`` (Eq. 9).
    speed : float
        Partner's speed relative to the mean demonstration (1 = as fast).
    duration : float
        Estimated duration of the whole movement in seconds.
    tau : float
        Time scaling ``1 / duration`` of Eq. 1.
    n_star, dtw_cost : int, float
        Matched reference frame (0-based) and ``D(n*, M)``.
    n_observed : int
        Number of observed frames used (with the learned phase past the end of the movement, those up to where
        its phase first reached 1: :func:`interprim.phase.movement_prefix`).
    log_likelihood : float
        ``log p(observation | model)`` at the estimated phase (0 when
        nothing was conditioned on); compare across models for recognition.
    posterior_mean, posterior_cov : ndarray
        ``p(theta | tau_o)`` in the internal (latent) parameter layout.
    """

    def __init__(self, model, post: Posterior, stats, s_end, duration, n_star, cost, n_observed, y0_obs,
                 robot_start, last_obs):
        self._m = model
        self._post = post
        self._stats = stats
        self.normalised_time = float(s_end)
        N = model.reference_.shape[0]
        self.phase = float(max(s_end, 0.5 / (N - 1)))
        self.x = math.exp(-float(model.alpha_x) * self.phase)  # Eq. 9 (canonical_phase, scalar)
        self.duration = float(duration)
        self.tau = 1.0 / self.duration
        self.speed = float(model.mean_duration_ / self.duration)
        self.n_star = int(round(n_star))
        self._dtw_cost = cost if callable(cost) else float(cost)
        self.n_observed = int(n_observed)
        self.log_likelihood = float(post.log_likelihood)
        self._y0_obs = np.array(y0_obs, dtype=np.float64)  # a copy (see _last_obs)
        self._robot_start = robot_start
        self._last_obs = np.array(last_obs, dtype=np.float64)  # a copy: it may be a row of the caller's array
        #: largest standardised distance of an observed frame from the training frames (set by predict/stream)
        self.input_distance = float("nan")
        #: whether that distance passed the model's limit (wrong units, columns or frame of reference?)
        self.out_of_range = False

    @property
    def conditioned(self) -> bool:  # type: ignore[override]  # an attribute of GridPrediction, computed here
        """Whether the posterior is conditioned on the observed frames.  ``False`` while fewer than the
        model's ``min_observed`` frames (or only a phase of 0) were seen: the prediction is then the prior
        (the mean interaction from the first frame), ``log_likelihood`` is 0 and ``phase``/``speed``/``duration``
        come from too few frames to mean anything."""
        return self._stats is not None

    @property
    def dtw_cost(self) -> float:
        """``D(n*, M)`` of the open-end DTW of the observation against the reference (Eq. 5-8); with the
        likelihood phase of a batch ``predict`` it is computed on first access."""
        if callable(self._dtw_cost):
            self._dtw_cost = float(self._dtw_cost())
        return self._dtw_cost

    # -- parameters
    @property
    def posterior_mean(self) -> np.ndarray:
        """Mean of ``p(theta | tau_o)`` (Eq. 18), both agents, in the internal (latent) parameter layout."""
        return self._post.mean

    @property
    @one_blas_thread
    def posterior_cov(self) -> np.ndarray:
        """Covariance of ``p(theta | tau_o)`` (Eq. 18) in the layout of :attr:`posterior_mean`; computed on first
        access after a mean-only (streaming) update."""
        if self._post.cov is None:  # a mean-only update (streaming): compute the covariance on demand
            self._post = self._m.condition(self._stats, need_cov=True)
        assert self._post.cov is not None  # asked for above
        return self._post.cov

    @property
    def goal(self) -> np.ndarray:
        """Posterior mean goal attractor ``g`` of every DoF, in data columns, shape ``(D,)``."""
        m = self._m
        q = m.params_per_dof_
        g_lat = self._post.mean.reshape(m.n_latent_, q)[:, -1]
        M, off = m.latent_map()
        return M @ g_lat + off

    def start_states(self):
        """Start position and velocity ``(y0, v0)`` of every latent DoF (observed agent first) from which the
        prediction's movement is integrated (Eq. 1)."""
        m = self._m
        n_o = m.n_observed_latent_
        y0 = np.concatenate([self._y0_obs, self._robot_start[0]])
        v0 = np.concatenate([m.start_velocity_[:n_o], self._robot_start[1]])
        return y0, v0

    def _latent_traj(self, Th, s_out, y0, v0, s0=0.0, design=None):
        """Positions ``(..., n, d)`` of DoFs with parameters ``Th (..., d, q)`` from start state ``y0, v0``
        (``design``: ``rollout_.design(s0, s_out)`` when the caller has it)."""
        free, H = self._m.rollout_.design(s0, s_out) if design is None else design
        return free @ np.vstack([y0, v0]) + H @ np.swapaxes(Th, -1, -2)  # (n, q) x (..., q, d): one BLAS product

    def theta(self, flat=None):
        """Posterior mean DMP parameters (or the flat vectors ``flat``) as ``(..., n_latent, n_basis + 1)``."""
        m = self._m
        flat = self._post.mean if flat is None else flat
        return flat.reshape(*flat.shape[:-1], m.n_latent_, m.params_per_dof_)

    # -- trajectories
    @one_blas_thread
    def trajectory(self, n: int = 100) -> np.ndarray:
        """Posterior mean of all DoFs over the whole movement, shape ``(n, D)``.

        Uniform normalised-time grid from 0 to 1; the observed agent starts at
        its first observed frame, the controlled agent at ``robot_state``.
        """
        m = self._m
        y0, v0 = self.start_states()
        lat = self._latent_traj(self.theta(), None, y0, v0, design=m.rollout_.grid_design(n))
        M, off = m.latent_map()
        return lat @ M.T + off

    def grid_mean(self, n: int) -> np.ndarray:
        """:meth:`trajectory` ``(n)``'s values, the same numbers, for a caller inside the library's one-thread
        context that reads this prediction on a grid after every frame (:class:`~interprim.models.blend.Blend`).

        Without PCA the latent map is a 0/1 selection of the latent DoFs with offset 0: its product is each data
        column's latent column plus the products by 0, which add nothing to a finite value, so the column itself is
        read (then the offset added, as :meth:`trajectory` adds it); a trajectory with a non-finite value, or a
        model with PCA, takes the product."""
        m = self._m
        y0, v0 = self.start_states()
        lat = self._latent_traj(self.theta(), None, y0, v0, design=m.rollout_.grid_design(n))
        M, off = m.latent_map()
        cols = m.cached("latent_columns", (M, off), lambda: _selected_columns(M, off))
        if cols is None or not np.isfinite(lat).all():
            return lat @ M.T + off
        if cols is not _SAME_COLUMNS:
            lat = lat[:, cols]
        return np.add(lat, off, out=lat)

    def _calibration_scale(self, n: int):
        """Factors ``(n, D)`` of the calibrated predictive std on the grid ``linspace(0, 1, n)``
        (:mod:`interprim.models.primitive.calibration`: per column, at this prediction's phase and each point's
        look-ahead ``u - phase``), or ``None``."""
        m = self._m
        cal = getattr(m, "calibration_", None)
        if cal is None:
            return None
        return cal.column_factors(self.normalised_time, np.linspace(0.0, 1.0, int(n)), m.observed_dofs_,
                                  m.controlled_dofs_)

    @one_blas_thread
    def std(self, n: int = 100, calibrated: bool = True) -> np.ndarray:
        """Pointwise standard deviation of :meth:`trajectory`, shape ``(n, D)``.

        ``calibrated=True`` (default): the posterior std (Eq. 18) scaled by the model's
        :class:`~interprim.models.primitive.calibration.Calibration` (held-out errors on the training demonstrations),
        per column, at this prediction's phase and at each point's look-ahead ``u - phase`` (the observed past
        included), so that a 90 % band ``trajectory +- 1.645 std`` covers about 90 % of what happens;
        ``False``, or a model without calibration: the posterior std itself.
        """
        sd = self._posterior_std(n)
        f = self._calibration_scale(n) if calibrated else None
        return sd if f is None else sd * f

    def _posterior_std(self, n: int) -> np.ndarray:
        m = self._m
        s = np.linspace(0.0, 1.0, int(n))
        _, H = m.rollout_.design(0.0, s)
        C = self.posterior_cov.reshape(m.n_latent_, m.params_per_dof_, m.n_latent_, m.params_per_dof_)
        M, _ = m.latent_map()
        if M.shape[0] == M.shape[1] and np.array_equal(M, np.eye(M.shape[0])):  # no PCA: the diagonal blocks
            d = np.arange(m.n_latent_)
            var = np.sum(np.matmul(H[None], C[d, :, d, :]) * H[None], axis=2).T  # diag(H C_dd H^T) per DoF
        else:
            S_t = np.einsum("tq,dqer,tr->tde", H, C, H, optimize=True)  # latent covariance per time
            var = np.einsum("cd,tde,ce->tc", M, S_t, M, optimize=True)
        return np.sqrt(np.clip(var, 0.0, None))

    @one_blas_thread
    def samples(self, n_samples: int = 20, n: int = 100, random_state=None) -> np.ndarray:
        """Trajectories drawn from the posterior over ``theta``, shape ``(n_samples, n, D)``; with a calibrated
        model their spread about :meth:`trajectory` is scaled per point and column as in :meth:`std`."""
        m = self._m
        th = sample(self._post.mean, self.posterior_cov, int(n_samples), random_state)
        s = np.linspace(0.0, 1.0, int(n))
        y0, v0 = self.start_states()
        lat = self._latent_traj(self.theta(th), s, y0, v0)
        M, off = m.latent_map()
        out = lat @ M.T + off
        f = self._calibration_scale(n)
        if f is not None:  # spread about the mean scaled like std(): trajectories are affine in theta
            mean = self.trajectory(int(n))
            out = mean + (out - mean) * f
        return out

    @one_blas_thread
    def response(self, n: int = 100, state=None):
        """The controlled agent's mean movement from the current phase to the end.

        Parameters
        ----------
        n : int
            Number of points from the current phase to the end.
        state : array_like, optional
            Current robot position ``(n_c,)`` or position and velocity
            ``(2, n_c)`` (velocity per second); default: the mean prediction's
            state at the current phase.

        Returns
        -------
        t : ndarray, shape (n,)
            Seconds from now, at the partner's estimated speed.
        y : ndarray, shape (n, len(controlled_dofs))
        """
        kern = kernels.kernel("rollout.response_positions")
        if kern is None:
            return self._response_reference(n, state)
        m = self._m
        n = int(n)
        n_o = m.n_observed_latent_
        s0 = self.normalised_time
        th = self._post.mean.reshape(m.n_latent_, m.params_per_dof_)[n_o:]
        if state is None:
            rs = self._robot_start
            z0 = rs[2] if len(rs) > 2 else np.vstack(rs[:2])
            at_s0 = False
        else:
            y0, v0 = m.robot_start(state)
            z0 = np.vstack([y0, v0 / m.mean_duration_ * self.duration])
            at_s0 = True
        ro = m.rollout_
        t = np.empty(n)
        lat = kern(ro.Z, ro.powers, s0, n, th, z0, at_s0, np.empty((n, th.shape[0])), self.duration, t)
        Mc, offc = m.controlled_map()
        return t, (lat if Mc is None else lat @ Mc + offc)

    def _response_reference(self, n: int = 100, state=None):
        """:meth:`response` with :meth:`interprim.core.dmp.LinearRollout.design` (numpy; the fast path's reference)."""
        m = self._m
        n_o = m.n_observed_latent_
        s0 = self.normalised_time
        s = np.linspace(s0, 1.0, int(n))
        th = self.theta()[n_o:]
        if state is None:
            rs = self._robot_start
            free, H = m.rollout_.design(0.0, np.array([s0]))
            freed, Hd = m.rollout_.design(0.0, np.array([s0]), derivative=1)
            z0 = np.vstack([rs[0], rs[1]])
            y0 = (free @ z0 + H @ th.T)[0]
            v0 = (freed @ z0 + Hd @ th.T)[0]
        else:
            y0, v0 = m.robot_start(state)
            v0 = v0 / m.mean_duration_ * self.duration
        lat = self._latent_traj(th, s, y0, v0, s0=s0)
        M, off = m.latent_map()
        ctrl = m.controlled_dofs_
        y = lat @ M[ctrl, n_o:].T + off[ctrl]
        return (s - s0) * self.duration, y

    @one_blas_thread
    def completion(self, n: int = 100):
        """Pattern completion (paper Fig. 3): continue the observed agent from its last observed frame.

        Returns ``(s, y)``: normalised times from the current phase to 1 and
        positions ``(n, len(observed_dofs))``.
        """
        m = self._m
        n_o = m.n_observed_latent_
        s0 = self.normalised_time
        s = np.linspace(s0, 1.0, int(n))
        th = self.theta()[:n_o]
        # velocity at the current phase from the posterior mean movement
        freed, Hd = m.rollout_.design(0.0, np.array([s0]), derivative=1)
        z0 = np.vstack([self._y0_obs, m.start_velocity_[:n_o]])
        v0 = (freed @ z0 + Hd @ th.T)[0]
        lat = self._latent_traj(th, s, self._last_obs, v0, s0=s0)
        M, off = m.latent_map()
        obs = m.observed_dofs_
        return s, lat @ M[obs, :n_o].T + off[obs]

    def mean_rollout(self, n: int = 100, columns=None) -> MeanRollout:
        """A :class:`MeanRollout`: ``trajectory(n)[:, columns]`` for this and every later prediction of the same
        model, with the design of the grid built once."""
        return MeanRollout(self._m, n, columns)

    def __repr__(self):
        return (f"Prediction(phase={self.phase:.3f}, speed={self.speed:.3f}, n_observed={self.n_observed}, "
                f"log_likelihood={self.log_likelihood:.3g})")


class MeanRollout:
    """``pred.trajectory(n)[:, columns]`` for the predictions of one model, cheaper.

    :meth:`Prediction.trajectory` rebuilds the rollout's design matrices for the grid
    ``linspace(0, 1, n)`` at every call (about 0.1 ms, half the cost of a streamed frame); they depend
    only on the model and ``n``, so they are built once here, and only the requested columns are mapped
    back from the latent DoFs.  Made by :meth:`Prediction.mean_rollout`; call it with a prediction of the
    same model.

    Parameters
    ----------
    model : FittedPrimitive
        A fitted model.
    n : int
        Points of the uniform normalised-time grid from 0 to 1.
    columns : slice or list of int, optional
        Data columns to return (default: all).
    """

    __slots__ = ("free", "H", "MT", "off")

    def __init__(self, model, n: int, columns=None):
        sel = slice(None) if columns is None else columns
        free, H = model.rollout_.design(0.0, np.linspace(0.0, 1.0, int(n)))
        M, off = model.latent_map()
        self.free, self.H = np.ascontiguousarray(free), np.ascontiguousarray(H)
        self.MT, self.off = np.ascontiguousarray(M[sel].T), np.ascontiguousarray(off[sel])

    def __call__(self, pred: Prediction) -> np.ndarray:
        """The posterior mean of ``pred`` on the grid, shape ``(n, len(columns))``."""
        y0, v0 = pred.start_states()
        th = pred.theta()
        lat = self.free @ np.vstack((y0, v0)) + self.H @ th.T
        return lat @ self.MT + self.off

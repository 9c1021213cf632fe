"""Online use of a fitted Interaction Primitive: one observed frame at a time (paper Sec. III-B/C/D).

:class:`Stream` keeps the frames seen, the incremental open-end DTW (Eq. 5-8) or the
likelihood phase tracker, and the state of the incremental conditioning
(:class:`_IncrementalConditioning`: Eq. 16-18 updated by rank one while the frames seen keep
their phases), and returns a :class:`~interprim.prediction.Prediction` per frame.
"""

from __future__ import annotations

import numpy as np

from ._compiled import loader
from ._validation import as_frame
from .gaussian import Posterior
from .input_range import mark
from .phase import IncrementalDTW, estimate_phase
from .prediction import Prediction
from .preprocessing import savgol_window

__all__ = ["Stream"]


class _IncrementalConditioning:
    """What a :class:`Stream` keeps between frames to update Eq. 16-18 instead of recomputing it.

    The statistics ``G``, ``B``, ``|Y|^2`` of the frames seen (position observation), the upper
    Cholesky factors ``R`` of ``T_i = sigma^2 I + S_i G S_i``, ``TiU_i = T_i^{-1} Uh_i``,
    ``A_i = T_i^{-1} S_i c_i``, the lower triangle of the ``r x r`` matrix ``K`` and
    ``sum_i log det T_i`` of :class:`~interprim.gaussian.LowRankConditioner`, for
    ``M`` frames at phases ``v m`` (``m = 0 .. M - 1``) from the start ``[y0; v0]``.  Seeded by the
    from-scratch path (:func:`interprim._compiled.conditioning.lowrank_condition_seed`), extended by one frame by
    :func:`interprim._compiled.conditioning.lowrank_condition_step`.  Buffers are allocated once.
    """

    def __init__(self, model, cond):
        self.model = model
        self.cond = cond
        self.sigma2 = model.sigma2_
        self.rollout = model.rollout_
        self.start_velocity = model.start_velocity_
        Do, q, r = cond.D_o, cond.q, cond.r
        self.v0 = np.ascontiguousarray(model.start_velocity_[:Do], dtype=np.float64)
        self.G = np.zeros((q, q))
        self.B = np.zeros((q, Do))
        self.R = np.zeros((Do, q, q))
        self.K = np.zeros((r, r))
        self.TiU = np.zeros((Do, q, r))
        self.A = np.zeros((Do, q))
        self.Kf = np.zeros((r, r))
        self.vec = np.zeros((6, max(q, r, Do)))
        self.C = np.zeros((Do, q))
        self.invalidate()

    def invalidate(self):
        self.seeded = False
        self.M = -1
        self.v = 0.0
        self.yy = 0.0
        self.ld_T = 0.0
        self.y0 = None
        self.wp = None

    def matches(self, model, cond) -> bool:
        return (cond is self.cond and model.sigma2_ == self.sigma2 and model.rollout_ is self.rollout
                and model.start_velocity_ is self.start_velocity)


class Stream:
    """Online use of a fitted :class:`~interprim.primitive.InteractionPrimitive`: one observed frame at a time.

    Each :meth:`update` adds one column to the open-end DTW (Eq. 5-8, ``O(N D)``)
    and conditions on all frames seen so far at their new phases (Eq. 15-18).
    The frame buffer is preallocated and grows by doubling.

    With the likelihood phase (the default) the phase is chosen on a lattice of speeds, so
    while the chosen speed stays the same the frames already seen keep their phases and the new
    frame only adds one row to the observation: then Eq. 16-18 are updated by rank one
    (:func:`interprim._compiled.conditioning.lowrank_condition_step`, independent of the number of frames)
    instead of recomputed; the result is the same (to rounding).  Everything else (a new speed,
    a phase clipped at 1, a start position still being smoothed, ``need_cov=True``, PCA, the
    forcing observation, a dense prior, no compiled kernels) recomputes from scratch and re-seeds.
    ``incremental = False`` (class or instance attribute) always recomputes.
    """

    incremental = True

    def __init__(self, model, robot_state=None):
        self.model = model
        self.robot_state = robot_state
        self._robot_start = self._with_z0(model._robot_start(robot_state))
        self._dtw = IncrementalDTW(model.reference_)
        cap = max(2 * model.reference_.shape[0], 16)
        self._buf = np.empty((cap, model.n_observed_latent_))
        # streaming needs the compiled per-frame step: load the kernels now (see interprim._compiled.loader)
        self._ws = None
        if loader.warmup():
            from ._compiled.observation import StatsWorkspace

            self._ws = StatsWorkspace(cap, model.n_observed_latent_, model._q, model.observation)
        self._n = 0
        self._tracker = None  # likelihood phase: interprim.phase.tracking._Tracker (created on first use)
        self._s_prev = None
        self._inc = None  # _IncrementalConditioning (created on first use)
        self.n_incremental = 0  # frames conditioned by the rank-1 update (the rest from scratch)
        self._max_dist = 0.0  # largest standardised distance of a frame since reset (out-of-range check)
        self._warned = False

    @property
    def n_frames(self) -> int:
        """Number of frames received since the stream was created or last :meth:`reset`."""
        return self._n

    def reset(self, robot_state=None):
        """Forget all frames (start a new interaction)."""
        self._dtw.reset()
        self._n = 0
        self._s_prev = None
        self._max_dist = 0.0
        self._warned = False
        if self._tracker is not None:
            self._tracker.reset()
        if self._inc is not None:
            self._inc.invalidate()
        if robot_state is not None:
            self.robot_state = robot_state
            self._robot_start = self._with_z0(self.model._robot_start(robot_state))

    @staticmethod
    def _with_z0(rs):
        """``(y0, v0, [y0; v0])``: the stacked start state is reused by every :meth:`Prediction.response`."""
        return (rs[0], rs[1], np.vstack([rs[0], rs[1]]))

    def update(self, frame, need_cov: bool = False) -> Prediction:
        """Add one frame of the observed agent, shape ``(len(observed_dofs),)``; returns a :class:`Prediction`.

        See :meth:`_update` for the work per frame.  The prediction's ``input_distance`` is the largest
        standardised distance of any frame since the last :meth:`reset` from the training frames, and
        ``out_of_range`` says whether it passed the model's limit (a warning is issued the first time).
        """
        p = self._update(frame, need_cov)
        m = self.model
        mean = getattr(m, "input_mean_", None)
        if mean is not None:
            d = float(np.max(np.abs(np.asarray(frame, dtype=np.float64) - mean) / m.input_std_))
            self._max_dist = max(self._max_dist, d)
            p.input_distance = self._max_dist
            p.out_of_range = self._max_dist > m.input_limit_
            if p.out_of_range and not self._warned:
                self._warned = True
                mark(m, p, self._max_dist)
        return p

    def _update(self, frame, need_cov: bool = False) -> Prediction:
        """One frame (see :meth:`update`).

        The posterior mean is computed now; the covariance only when asked
        for (:attr:`Prediction.posterior_cov`, :meth:`Prediction.std`, ...) or
        with ``need_cov=True``.  Work per frame: one DTW column ``O(N D_o)``,
        the observation statistics ``O(M q (q + D_o))`` for the ``M`` frames
        seen (every frame moves to a new phase), and a conditioning step
        independent of ``M``; with the likelihood phase, while the estimated
        speed stays on the same lattice point, only the new frame's row:
        ``O(D_o (q^2 + q r) + r^3)`` for statistics and conditioning (see
        :class:`Stream`).  No buffer grows with ``M`` except the frame buffer
        itself (doubling).
        """
        m = self.model
        n_cols = len(m.observed_dofs_)
        if (m.pca_observed_ is None and type(frame) is np.ndarray and frame.dtype == np.float64
                and frame.shape == (n_cols,)):
            f = frame  # validated (finite) by the DTW step below, before anything is stored
            n_star, cost = self._dtw.update(f, check=True)
        else:
            f = as_frame(frame, "frame", n_cols)
            if m.pca_observed_ is not None:
                f = m.pca_observed_.transform(f[None])[0]
            n_star, cost = self._dtw.update(f, check=False)
        if self._n == self._buf.shape[0]:
            self._buf = np.concatenate([self._buf, np.empty_like(self._buf)])
        self._buf[self._n] = f
        self._n += 1
        tr = None
        if m._phase() == "likelihood":  # local search around the previous estimate, on a lattice of speeds
            tr = self._tracker
            if tr is None or tr.model is not m:
                from .phase.tracking import _Tracker

                self._tracker = tr = _Tracker(m)
        n_star, cost = estimate_phase(m, self._buf[: self._n], m._phase(), dtw=(n_star, cost), tracker=tr)
        if tr is not None:
            self._s_prev = n_star / (m.reference_.shape[0] - 1)
        z = self._buf[: self._n]
        inc = self._inc
        if inc is not None and inc.M == self._n - 1 and not need_cov:
            p = self._predict_incremental(z, n_star, cost)
            if p is not None:
                return p
        seed = self._seed()
        p = m._predict_latent(z, n_star, cost, None, need_cov=need_cov, robot_start=self._robot_start,
                              workspace=self._ws, seed=seed)
        if seed is not None and seed.seeded:
            G, B, yy, _ = p._stats
            np.copyto(seed.G, G)
            np.copyto(seed.B, B)
            seed.yy = float(yy)
            seed.y0 = np.ascontiguousarray(p._y0_obs, dtype=np.float64)
            seed.M = self._n
            seed.v = p.normalised_time / (self._n - 1)
            seed.wp = savgol_window(self._n, m.smoothing_window)
        return p

    def _seed(self):
        """The incremental state to (re)seed by this frame's from-scratch conditioning, or ``None``."""
        inc = self._inc
        if inc is not None:
            inc.invalidate()
        m = self.model
        if not (self.incremental and m._phase() == "likelihood" and m.observation == "position"
                and m.pca_observed_ is None and self._ws is not None and self._n >= 3 and loader.ready()):
            return None
        cond = m._conditioner()
        if cond is None:
            return None
        if inc is None or not inc.matches(m, cond):
            self._inc = inc = _IncrementalConditioning(m, cond)
        return inc

    def _predict_incremental(self, z, n_star, cost):
        """This frame's :class:`Prediction` by the rank-1 update of Eq. 16-18, or ``None`` when it does not apply
        (the frames seen moved to other phases, or the start changed; see :class:`Stream`)."""
        from ._compiled.conditioning import lowrank_condition_step

        m = self.model
        inc = self._inc
        M = self._n
        cond = m._conditioner()
        if not (self.incremental and inc.matches(m, cond) and M >= m.min_observed):
            return None
        s_end, duration = m._phase_info(n_star, M)
        v = s_end / (M - 1)
        # same speed: frame j of the from-scratch statistics sits at j s_end / (M - 1) = v j (to rounding)
        if not (s_end > 0 and abs(v - inc.v) <= 1e-12 * inc.v):
            return None
        if m.smoothing_window is not None and savgol_window(M, m.smoothing_window) != inc.wp:
            return None  # the smoothed start y0 still changes
        s2 = inc.sigma2
        ro = inc.rollout
        out = np.empty(cond.P)
        dld, ld_K, resid, yy = lowrank_condition_step(z[M - 1], s_end, inc.y0, inc.v0, ro._Z, ro._powers, s2, inc.yy,
                                                      cond.sq, cond.Uh, cond.mean, cond.mu_o, cond.obs_flat,
                                                      cond.other, cond.Uc, inc.G, inc.B, inc.R, inc.K, inc.TiU,
                                                      inc.A, inc.Kf, inc.vec, inc.C, out)
        if not np.isfinite(ld_K):
            inc.invalidate()
            return None
        inc.ld_T += dld
        inc.yy = yy
        inc.M = M  # inc.v stays the seeding frame's speed: no drift of the tolerance above
        n = M * cond.D_o
        post = Posterior(out, None, cond._loglik(inc.ld_T, ld_K, resid, s2, n))
        self.n_incremental += 1
        return Prediction(m, post, (inc.G.copy(), inc.B.copy(), yy, n), s_end, duration, n_star, cost, M, inc.y0,
                          self._robot_start, z[-1])

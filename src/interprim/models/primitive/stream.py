"""Online use of a fitted Interaction Primitive: one observed frame at a time (paper Sec. III-B/C/D).

:class:`Stream` keeps the frames seen and the incremental open-end DTW (Eq. 5-8) or the
likelihood phase tracker (:class:`interprim.phase.tracking.Tracker`, which ends where the batch
search ends on a single-peaked log posterior), conditions on all frames seen at the phase found (Eq. 15-18), and
returns a :class:`~interprim.models.primitive.prediction.Prediction` per frame: the one ``predict`` gives for the
same frames (at the same phase).
"""

from __future__ import annotations

import numpy as np

from ...core._compiled import registry as kernels
from ...core.blas import one_blas_thread
from ...core.input_range import checked_by_caller, mark, mark_duration
from ...core.validation import as_2d_finite, as_frame
from ...phase import IncrementalDTW, estimate_phase, movement_prefix
from ..base import BaseStream
from .prediction import Prediction

__all__ = ["Stream"]


class Stream(BaseStream):
    """Online use of a fitted :class:`~interprim.models.primitive.estimator.InteractionPrimitive`: one observed frame at
    a time.

    Each :meth:`update` adds one column to the open-end DTW (Eq. 5-8, ``O(N D)``)
    and conditions on all frames seen so far at their new phases (Eq. 15-18).
    :meth:`extend` adds several frames at once (a caller that fell behind) and conditions once, for
    the last of them.  The frame buffer is preallocated and grows by doubling.

    With the likelihood phase (what ``phase_method="cv"`` picks on most data) the phase is tracked on a lattice of
    speeds whose scores are extended frame by frame (:class:`interprim.phase.tracking.Tracker`) and then taken
    to the maximum of the log posterior by the batch search's own last step, so that the stream's
    phase, and hence its prediction, is :meth:`~interprim.models.primitive.estimator.InteractionPrimitive.predict`'s
    on the same frames (issue 12: within 1e-3, measured ~1e-6).  Eq. 16-18 are then evaluated at that
    phase for all frames seen.
    """

    def __init__(self, model, robot_state=None):
        self.model = model
        self.robot_state = robot_state
        self._robot_start = self._with_z0(model.robot_start(robot_state))
        self._dtw = IncrementalDTW(model.reference_)
        cap = max(2 * model.reference_.shape[0], 16)
        self._buf = np.empty((cap, model.n_observed_latent_))
        # the compiled per-frame step when the kernels are in use (see interprim.core._compiled.loader)
        self._ws = None
        if kernels.in_use():
            from ...core._compiled.observation import StatsWorkspace

            self._ws = StatsWorkspace(cap, model.n_observed_latent_, model.params_per_dof_, model.observation)
        self._n = 0
        self._tracker = None  # likelihood phase: interprim.phase.tracking.Tracker (created on first use)
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
        self._max_dist = 0.0
        self._warned = False
        if self._tracker is not None:
            self._tracker.reset()
        if robot_state is not None:
            self.robot_state = robot_state
            self._robot_start = self._with_z0(self.model.robot_start(robot_state))

    @staticmethod
    def _with_z0(rs):
        """``(y0, v0, [y0; v0])``: the stacked start state is reused by every :meth:`Prediction.response`."""
        return (rs[0], rs[1], np.vstack([rs[0], rs[1]]))

    @one_blas_thread
    def update(self, frame, need_cov: bool = False) -> Prediction:
        """Add one frame of the observed agent, shape ``(len(observed_dofs),)``; returns a :class:`Prediction`.

        See :meth:`_update` for the work per frame.  The prediction's ``input_distance`` is the largest
        standardised distance of any frame since the last :meth:`reset` from the training frames, and
        ``out_of_range`` says whether it passed the model's limit (a warning is issued the first time).
        """
        p = self._update(frame, need_cov)
        return self._check_range(p, frame)

    def _check_range(self, p, frames):
        """Mark ``p`` with the largest input distance of the frames seen so far (:mod:`interprim.core.input_range`),
        warning once when it leaves the training range; nothing inside
        :data:`~interprim.core.input_range.CHECKED_BY_CALLER` (a caller that marks the prediction itself: an
        :class:`~interprim.AutoInteraction` streaming its members)."""
        if checked_by_caller():
            return p
        m = self.model
        mean = getattr(m, "input_mean_", None)
        if mean is not None:
            d = float(np.max(np.abs(np.asarray(frames, dtype=np.float64) - mean) / m.input_std_))
            self._max_dist = max(self._max_dist, d)
            p.input_distance = self._max_dist
            p.out_of_range = self._max_dist > m.input_limit_
            if p.out_of_range and not self._warned:
                self._warned = True
                mark(m, p, self._max_dist)
        mark_duration(m, p)  # a predicted duration far outside the demonstrated ones
        return p

    def _update(self, frame, need_cov: bool = False) -> Prediction:
        """One frame (see :meth:`update`).

        The posterior mean is computed now; the covariance only when asked
        for (:attr:`Prediction.posterior_cov`, :meth:`Prediction.std`, ...) or
        with ``need_cov=True``.  Work per frame: one DTW column ``O(N D_o)``,
        the observation statistics ``O(M q (q + D_o))`` for the ``M`` frames
        seen (every frame moves to a new phase), and a conditioning step
        independent of ``M``; with the likelihood phase the lattice
        window's scores ``O(D_o (q^2 + q r) + r^3)`` per candidate and about
        three evaluations of the log posterior ``O(M q (q + D_o))`` each (see
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
        method = m.phase_method_used()
        if method == "likelihood":  # local search around the previous estimate on a speed lattice
            tr = self._tracker
            if tr is None or tr.model is not m:
                from ...phase.tracking import Tracker

                self._tracker = tr = Tracker(m)
        z_all = self._buf[: self._n]
        n_star, cost = estimate_phase(m, z_all, method, dtw=(n_star, cost), tracker=tr)
        z = movement_prefix(m, z_all, n_star)  # learned phase past the end: where it ended
        return m.predict_latent(z, n_star, cost, None, need_cov=need_cov, robot_start=self._robot_start,
                                 workspace=self._ws)

    def extend(self, frames, need_cov: bool = False) -> Prediction:
        """Add several frames of the observed agent at once, shape ``(k, len(observed_dofs))``; returns the
        :class:`Prediction` for the last of them.

        The answer is the one ``k`` calls of :meth:`update` give for their last frame, exactly (the same
        numbers), and so the one :meth:`~interprim.models.primitive.estimator.InteractionPrimitive.predict` gives for
        all the frames seen: the DTW and learned phases are functions of the frames, and with the likelihood phase
        the tracker walks its lattice frame by frame as :meth:`update` does, so that its state does not
        depend on how frames were grouped.  It costs less: for each of the ``k`` frames only
        what the stream keeps from a frame is done, namely the DTW column (Eq. 5-8, ``O(N D_o)``), the
        tracker's step (likelihood phase) and the frame's place in the buffer; the observation statistics
        at the phase, the conditioning (Eq. 15-18) and the :class:`Prediction` are computed once, for the
        last frame.  For a server or controller that received several frames while busy
        (:mod:`interprim.server` uses it for its coalesced replies).

        Parameters
        ----------
        frames : array_like, shape (k, len(observed_dofs))
            ``k >= 1`` frames, oldest first, in the observed columns' order, at the model's ``dt``.
        need_cov : bool
            As in :meth:`update`: compute the posterior covariance now (else on first use).

        Returns
        -------
        Prediction
            As :meth:`update` returns for the last frame; ``input_distance`` and ``out_of_range`` cover
            every frame since the last :meth:`reset` (the warning is issued once, as by :meth:`update`).

        Raises
        ------
        ValueError, TypeError
            ``frames`` is not a ``(k, len(observed_dofs))`` numeric array with ``k >= 1``, or contains NaN
            or inf (the message names the first such frame).  Nothing is added then: the frames are
            checked before any enters the stream.
        """
        m = self.model
        n_cols = len(m.observed_dofs_)
        raw = as_2d_finite(frames, "frames", n_cols=n_cols, min_rows=1)
        k = raw.shape[0]
        pca = m.pca_observed_
        # one row at a time through the projection, as update does (a batched product may round differently)
        zs = raw if pca is None else np.stack([pca.transform(raw[i:i + 1])[0] for i in range(k)])
        need = self._n + k
        if need > self._buf.shape[0]:
            cap = self._buf.shape[0]
            while cap < need:
                cap *= 2
            buf = np.empty((cap, self._buf.shape[1]))
            buf[: self._n] = self._buf[: self._n]
            self._buf = buf
        method = m.phase_method_used()
        tr = None
        if method == "likelihood":
            tr = self._tracker
            if tr is None or tr.model is not m:
                from ...phase.tracking import Tracker

                self._tracker = tr = Tracker(m)
        dtw, buf = self._dtw, self._buf
        n_star = cost = None
        for i in range(k):
            f = zs[i]
            n_star, cost = dtw.update(f, check=False)
            buf[self._n] = f
            self._n += 1
            if tr is not None and i < k - 1:
                # the likelihood tracker walks its lattice frame by frame, as update does: its state (and so the
                # phase) then does not depend on how the frames were grouped (a server's coalescing under load)
                estimate_phase(m, buf[: self._n], method, dtw=(n_star, cost), tracker=tr)
        z_all = buf[: self._n]
        n_star, cost = estimate_phase(m, z_all, method, dtw=(n_star, cost), tracker=tr)
        z = movement_prefix(m, z_all, n_star)
        p = m.predict_latent(z, n_star, cost, None, need_cov=need_cov, robot_start=self._robot_start,
                              workspace=self._ws)
        return self._check_range(p, raw)

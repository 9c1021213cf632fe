"""Families that answer with the demonstrations themselves: the mean, the nearest, (in ``kernel``) a weighted mix.

Every method follows the prediction contract of :mod:`interprim.models.base` (``fit``, ``predict``, ``stream``,
``save``/``load``, ``get_params``/``set_params``), used by :mod:`interprim.evaluation.sweep`::

    est = Method(observed_dofs, ...).fit(demos, dt=...)
    out = est.predict(partial)          # partial: (M, len(observed_dofs)) frames from the start
    out.trajectory(n), out.std(n)       # (n, D) over normalised time 0..1 (std may be None)

- :class:`PriorMean` - replay the mean of the time-normalised demonstrations
  (no conditioning): the bar every method must clear.
- :class:`NearestNeighbour` - the training demonstration whose observed agent
  is nearest to the observed prefix under open-end DTW (Eq. 5-8).
- :class:`InteractionProMP` (the peer) lives in :mod:`interprim.models.promp`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..core import state_checks as check
from ..core.preprocessing import time_normalise
from ..core.validation import as_2d_finite, as_frame, check_min_frames
from .base import BaseStream, InputMarks, Predictor
from .grid import GridPrediction
from .training import TrainingSet

__all__ = ["Baseline", "PriorMean", "NearestNeighbour", "AlignedStream", "AlignedBaseline"]




class Baseline(Predictor):
    """What the three methods share: the column layout, the sampling interval and the prediction's timing."""

    observed_dofs: Any  # a parameter of each subclass's __init__
    n: Any  # the prediction's grid size (a parameter of each subclass's __init__)

    def _fit_common(self, data: TrainingSet) -> list:
        """The demonstrations of the validated training set (at least 2), with ``observed_dofs_``, ``dt_``,
        ``mean_duration_`` and ``n_dofs_`` set."""
        if len(data) < 2:
            raise ValueError(f"at least 2 demonstrations are needed, got {len(data)}")
        arrays = list(data.arrays)
        check_min_frames(arrays, 2)  # every demonstration has a duration and a time-normalised movement
        dt = data.dt
        D = data.n_dofs
        obs = self.observed_dofs
        if obs is None or isinstance(obs, (str, bytes)) or np.ndim(obs) != 1 or len(obs) == 0:
            raise TypeError(f"observed_dofs must be a non-empty sequence of column indices, got {obs!r}")
        obs = [int(i) for i in obs]
        bad = [i for i in obs if not 0 <= i < D]
        if bad or len(set(obs)) != len(obs):
            raise ValueError(f"observed_dofs {list(self.observed_dofs)} must be distinct columns of the "
                             f"{D}-column demonstrations")
        self.dt_ = dt
        self.mean_duration_ = float(np.mean([(a.shape[0] - 1) * self.dt_ for a in arrays]))
        self.n_dofs_ = D
        self.observed_dofs_ = obs
        return arrays

    def _partial(self, partial):
        self._check_fitted("predict")
        return as_2d_finite(partial, "partial", n_cols=len(self.observed_dofs_), min_rows=1)

    def _prediction(self, times, mean, std, M, phase=float("nan"), log_likelihood=float("nan"), method=None,
                    conditioned=True):
        """A :class:`~interprim.models.grid.GridPrediction` with the duration ``elapsed / phase`` (the mean
        duration when the phase is unknown or 0)."""
        elapsed = (M - 1) * self.dt_
        duration = elapsed / phase if (np.isfinite(phase) and phase > 0 and M > 1) else self.mean_duration_
        return GridPrediction(times, mean, std, phase=phase, observed_dofs=self.observed_dofs_, method=method,
                              log_likelihood=log_likelihood, duration=duration, mean_duration=self.mean_duration_,
                              n_observed=M, conditioned=conditioned)

    def _common_state(self) -> dict:
        return {"observed_dofs_": self.observed_dofs_, "dt_": self.dt_, "mean_duration_": self.mean_duration_,
                "n_dofs_": self.n_dofs_}

    def _set_common(self, meta):
        """The column layout and timing of a model file's ``meta``, checked (:mod:`~interprim.core.state_checks`)."""
        n_dofs = check.integer("n_dofs_", meta["n_dofs_"], 1, check.MAX_GRID)
        obs = check.columns("observed_dofs_", meta["observed_dofs_"], n_dofs)
        params = getattr(self, "observed_dofs", None)
        if params is not None and check.columns("params.observed_dofs", params, n_dofs) != obs:
            check.fail("params.observed_dofs", params, f"not the fitted observed_dofs_ {obs}")
        self.dt_ = check.number("dt_", meta["dt_"], positive=True)
        self.mean_duration_ = check.number("mean_duration_", meta["mean_duration_"], positive=True)
        self.observed_dofs_ = obs
        self.n_dofs_ = n_dofs

    def _grid_size(self) -> int:
        """The parameter ``n`` (points of the prediction's grid), checked."""
        return check.integer("params.n", self.n, 2, check.MAX_GRID)


class AlignedStream(BaseStream):
    """Online prediction of a model that aligns the observed prefix to every training demonstration by open-end
    DTW (:class:`NearestNeighbour`, :class:`~interprim.models.kernel.KernelDemonstrations`).

    An :class:`~interprim.phase.dtw.IncrementalDTWSet` of the training demonstrations takes each frame in ``O(N)``
    per demonstration (one new column of Eq. 7) instead of re-aligning the whole prefix, and gives exactly the
    batch alignment;
    the model then predicts from the alignments (``model.predict_from_alignment``), so :meth:`update` returns exactly
    what ``model.predict`` returns for all frames seen, and :meth:`extend` advances the alignments by several
    frames and predicts once.  ``need_cov`` is accepted for the interface and has no effect.  Every prediction
    carries the largest ``input_distance`` of the frames seen (:mod:`interprim.core.input_range`), warned once.
    """

    marks_input = True

    def __init__(self, model):
        from ..phase.dtw import IncrementalDTWSet

        self.model = model
        self._n_cols = len(model.observed_dofs_)
        self._dtw = IncrementalDTWSet(model.observed_)  # every demonstration's alignment, advanced in one call
        self._n = 0
        self._marks = InputMarks(model)

    @property
    def n_frames(self) -> int:
        """Number of frames received since the stream was created or last :meth:`reset`."""
        return self._n

    def reset(self, robot_state=None):
        """Forget all frames (start a new interaction)."""
        self._dtw.reset()
        self._n = 0
        self._marks.reset()

    def _advance(self, block):
        n_star, cost = self._dtw.extend(block)  # the frames are checked: every alignment takes the block at once
        self._n += block.shape[0]
        n_star = n_star.copy()
        # the batch's normalisation D(n*, M) / (n* + 1 + M): the same float divisions, element by element
        cost = cost / (n_star + 1 + self._n)
        pred = self.model.predict_from_alignment(self._n, n_star, cost)
        if self.model.input_range_ is not None:
            self._marks.mark(pred, block)
        return pred

    def update(self, frame, need_cov: bool = False):
        """Add one frame of the observed agent, shape ``(len(observed_dofs),)``; returns its prediction."""
        f = np.ascontiguousarray(as_frame(frame, "frame", self._n_cols), dtype=np.float64)
        return self._advance(f[None])

    def extend(self, frames, need_cov: bool = False):
        """Add frames ``(k, len(observed_dofs))`` at once (checked before any enters); returns the prediction for
        all frames seen, as :meth:`update` does for the last of them."""
        block = np.ascontiguousarray(as_2d_finite(frames, "frames", n_cols=self._n_cols, min_rows=1),
                                     dtype=np.float64)
        return self._advance(block)


class AlignedBaseline(Baseline):
    """A baseline that predicts from the open-end DTW alignments of the observed prefix to every training
    demonstration (:class:`NearestNeighbour`, :class:`~interprim.models.kernel.KernelDemonstrations`): its
    :meth:`stream` advances the alignments one frame at a time (:class:`AlignedStream`) and gives exactly what
    ``predict`` gives."""

    #: ``stream()`` gives exactly what ``predict`` gives (see :func:`interprim.evaluation.realtime.realtime_fold`)
    exact_stream = True

    def _stream(self, robot_state=None) -> AlignedStream:
        """Online predictor (:class:`AlignedStream`: the alignments advance one frame at a time; every
        ``update`` equals :meth:`predict` of all frames seen)."""
        self._check_fitted("stream")
        if robot_state is not None:
            raise ValueError("robot_state: this model does not roll out from a robot state; pass None")
        return AlignedStream(self)

    def _alignments(self, v, exclude=None):
        """``(idx, n_star (J,), cost (J,))``: open-end DTW (Eq. 5-8) of the prefix ``v`` against the observed agent
        of every training demonstration ``idx`` (all but ``exclude``), the cost normalised by the alignment length,
        ``D(n*, M) / (n* + 1 + M)``; :class:`AlignedStream` gives the same numbers one frame at a time."""
        from ..phase.dtw import open_end_dtw

        idx = [j for j in range(len(self.observed_)) if j != exclude]
        n_star = np.empty(len(idx), dtype=np.int64)
        cost = np.empty(len(idx))
        for i, j in enumerate(idx):
            r = open_end_dtw(self.observed_[j], v, return_path=False)
            n_star[i] = r.n_star
            cost[i] = r.cost / (r.n_star + 1 + v.shape[0])
        return idx, n_star, cost

    def predict_from_alignment(self, M, n_star, cost) -> GridPrediction:  # pragma: no cover - interface
        """The prediction after ``M`` observed frames from the prefix's alignments to the demonstrations.

        Parameters
        ----------
        M : int
            Observed frames.
        n_star : ndarray of int, shape (J,)
            Each training demonstration's matched frame (Eq. 8, 0-based).
        cost : ndarray, shape (J,)
            Each one's normalised cost ``D(n*, M) / (n* + 1 + M)``.

        Returns
        -------
        GridPrediction
            What ``predict`` returns for a prefix with these alignments.
        """
        raise NotImplementedError


class PriorMean(Baseline):
    """Replay the mean demonstration (time-normalised), with the demonstrations' spread as ``std``.

    Parameters
    ----------
    observed_dofs : sequence of int
    n : int
        Points of the normalised-time grid the demonstrations are averaged on.
    """

    def __init__(self, observed_dofs, n: int = 200):
        self.observed_dofs = observed_dofs
        self.n = n

    def _fit(self, data: TrainingSet) -> None:
        """Average the time-normalised demonstrations (at least 2): ``mean_`` and ``std_`` (sample std,
        ``ddof=1``) of shape ``(n, D)``; ``dt`` is the unit of the predictions' ``duration``."""
        arrays = self._fit_common(data)
        Y = np.stack([time_normalise(a, self.n) for a in arrays])
        self.mean_ = Y.mean(axis=0)
        self.std_ = Y.std(axis=0, ddof=1)

    def _predict(self, partial) -> GridPrediction:  # type: ignore[override]  # only the options it names
        """The mean demonstration whatever ``partial`` holds (no conditioning, phase NaN; ``partial`` may be
        ``None``)."""
        self._check_fitted("predict")
        M = 0 if partial is None else self._partial(partial).shape[0]
        return self._prediction(np.linspace(0.0, 1.0, self.n), self.mean_, self.std_, M,
                                method="mean", conditioned=False)

    def to_state(self):
        """``(arrays, meta)`` of the fitted model (see :meth:`interprim.models.base.Predictor.to_state`)."""
        self._check_fitted("to_state")
        return {"mean": self.mean_, "std": self.std_}, self._common_state()

    def load_state(self, arrays, meta):
        """Restore the state written by :meth:`to_state`."""
        self._set_common(meta)
        shape = (self._grid_size(), self.n_dofs_)
        self.mean_ = check.array("mean", arrays["mean"], shape)
        self.std_ = check.array("std", arrays["std"], shape, nonneg=True)


class NearestNeighbour(AlignedBaseline):
    """The training demonstration nearest to the observed prefix under open-end DTW.

    The cost of demonstration ``j`` is ``D(n*, M) / (n* + M)`` of the open-end
    DTW (Eq. 5-8) of the observed prefix against demonstration ``j``'s observed
    agent (normalised by the alignment length, so that demonstrations of
    different lengths compare fairly); the prediction is that demonstration,
    time-normalised, and its matched fraction ``(n*+1)/N_j`` is the phase.
    """

    def __init__(self, observed_dofs, n: int = 200):
        self.observed_dofs = observed_dofs
        self.n = n

    def _fit(self, data: TrainingSet) -> None:
        """Keep the demonstrations (at least 2): their observed columns as DTW references, and each
        time-normalised."""
        arrays = self._fit_common(data)
        obs = self.observed_dofs_
        self.observed_ = [np.ascontiguousarray(a[:, obs]) for a in arrays]
        self.demos_ = [time_normalise(a, self.n) for a in arrays]

    def to_state(self):
        """``(arrays, meta)`` of the fitted model (see :meth:`interprim.models.base.Predictor.to_state`)."""
        self._check_fitted("to_state")
        arrays = {"observed": np.concatenate(self.observed_), "lengths": np.array([len(u) for u in self.observed_]),
                  "demos": np.stack(self.demos_)}
        return arrays, self._common_state()

    def load_state(self, arrays, meta):
        """Restore the state written by :meth:`to_state`."""
        self._set_common(meta)
        observed = check.array("observed", arrays["observed"], (None, len(self.observed_dofs_)))
        lengths = check.lengths("lengths", arrays["lengths"], observed.shape[0])
        demos = check.array("demos", arrays["demos"], (len(lengths), self._grid_size(), self.n_dofs_))
        ends = np.cumsum(lengths)
        self.observed_ = [np.ascontiguousarray(u) for u in np.split(observed, ends[:-1])]
        self.demos_ = list(demos)

    def _predict(self, partial) -> GridPrediction:  # type: ignore[override]  # only the options it names
        """The nearest demonstration to ``partial`` (``(M, len(observed_dofs))`` frames from the start).

        The prediction's ``neighbour`` is its index, its phase the matched fraction ``(n*+1)/N_j`` and its
        ``std`` is ``None`` (the model is left unchanged).
        """
        v = self._partial(partial)
        _, n_star, cost = self._alignments(v)
        return self.predict_from_alignment(v.shape[0], n_star, cost)

    def predict_from_alignment(self, M, n_star, cost) -> GridPrediction:
        """The nearest demonstration given the prefix's alignments (:meth:`AlignedBaseline.predict_from_alignment`;
        ties: the first demonstration)."""
        best, best_c, frac = 0, np.inf, float("nan")
        for j, u in enumerate(self.observed_):
            if cost[j] < best_c:
                best, best_c, frac = j, cost[j], (int(n_star[j]) + 1) / u.shape[0]
        pred = self._prediction(np.linspace(0.0, 1.0, self.n), self.demos_[best], None, M, phase=frac,
                                method=f"demonstration {best}")
        pred.neighbour = best
        return pred

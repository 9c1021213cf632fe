"""A learned-timing, learned-coupling predictor for real recordings: :class:`LearnedInteraction`.

It chains the two estimators that make the human matter on recordings of people (issue: timing better than a
clock, a response better than the mean):

1. **timing** -- :class:`~interprim.phase.learned.LearnedPhase` (extends Sec. III-B): the phase and the duration
   regressed on features of the observed prefix, trained on the demonstrations' own prefixes and chosen by
   leave-one-demonstration-out CV (the clock when nothing beats it);
2. **coupling** -- :class:`~interprim.models.coupling.CouplingModel` (Eq. 17-18 with the observed prefix resampled on
   ``[0, s]`` as the observation): conditioning trained on prefixes taken at phases jittered by the timing
   model's *own* held-out error, so that it is robust to the phase error it will see; the mean when nothing
   beats it; calibrated predictive std.

The phase error the coupling is trained with is the learned phase's cross-validated error at each elapsed
time (``LearnedPhase.std_grid_``, as a fraction of the movement), not a guess.  The model follows the prediction
contract of :mod:`interprim.models.base` (``fit``, ``predict``, ``stream``, ``save``/``load``, ``get_params``/
``set_params``); its prediction is a :class:`~interprim.models.grid.GridPrediction` whose ``std`` includes the
timing uncertainty.

It does not replace :class:`~interprim.models.primitive.estimator.InteractionPrimitive`: there is no DMP and no rollout
from a robot state.  Each :meth:`predict` is a pure function of the prefix that reads a few of its frames (the phase
features) and ``n_in`` resampled points (the coupling's observation); :meth:`LearnedInteraction.stream` returns a
:class:`LearnedStream` whose answer is, bitwise, ``predict`` of the frames seen.
"""

from __future__ import annotations

import math

import numpy as np

from ..core import state_checks as check
from ..core.blas import one_blas_thread
from ..core.validation import as_2d_finite, as_frame
from ..phase.learned import LearnedPhase
from .base import BasePrediction, BaseStream, InputMarks, Predictor
from .coupling import CouplingModel
from .grid import GridPrediction
from .training import TrainingSet

__all__ = ["LearnedInteraction", "LearnedStream"]


class LearnedInteraction(Predictor):
    """Learned timing + learned coupling (see the module docstring).

    Parameters
    ----------
    observed_dofs : sequence of int
        Columns of the observed agent.
    phase_kwargs, coupling_kwargs : dict, optional
        Extra arguments of :class:`~interprim.phase.learned.LearnedPhase` and
        :class:`~interprim.models.coupling.CouplingModel`.

    Attributes
    ----------
    phase_ : LearnedPhase
        The timing model, fitted on the observed columns.
    coupling_ : CouplingModel
        The coupling, trained with ``phase_``'s cross-validated error.
    observed_dofs_ : list of int
    dt_ : float
        Sampling interval of the demonstrations (s).
    """

    _FITTED = "coupling_"
    exact_stream = True  # LearnedStream gives, bitwise, predict's answer

    def __init__(self, observed_dofs, phase_kwargs=None, coupling_kwargs=None):
        self.observed_dofs = observed_dofs
        self.phase_kwargs = phase_kwargs
        self.coupling_kwargs = coupling_kwargs

    def _fit(self, data: TrainingSet) -> None:
        """Fit the timing model on the observed columns, then the coupling with the timing model's own error."""
        dt = data.dt
        for name in ("phase_kwargs", "coupling_kwargs"):
            v = getattr(self, name)
            if v is not None and not isinstance(v, dict):
                raise TypeError(f"{name} must be a dict or None, got {type(v).__name__}")
        obs = [int(i) for i in self.observed_dofs]
        phase = LearnedPhase(**(self.phase_kwargs or {})).fit([d[:, obs] for d in data.arrays], dt=dt)
        coupling = CouplingModel(obs, **self._coupling_kwargs(phase)).fit(data)
        self.phase_, self.coupling_, self.dt_, self.observed_dofs_ = phase, coupling, float(dt), obs

    @property
    def mean_duration_(self) -> float:
        """Mean duration of the training demonstrations in seconds (the timing model's)."""
        self._check_fitted("mean_duration_")
        return float(self.phase_.mean_duration_)

    def use_phase_model(self, phase: LearnedPhase) -> bool:
        """Take ``phase`` as the timing model when it is the same fit as ``phase_`` (:meth:`LearnedPhase.same_fit
        <interprim.phase.learned.LearnedPhase.same_fit>`: the same estimates of any frames), so that models fitted on
        the same frames can share one (:func:`interprim.models.blend.share_phase_models`); returns whether it did.
        The predictions are unchanged."""
        self._check_fitted("use_phase_model")
        if phase is self.phase_ or not self.phase_.same_fit(phase):
            return False
        self.phase_ = phase
        return True

    def _coupling_kwargs(self, phase: LearnedPhase) -> dict:
        grid_t = np.arange(len(phase.std_grid_)) * float(phase.dt_)
        std_grid = np.asarray(phase.std_grid_, dtype=np.float64)
        mean_dur = float(phase.mean_duration_)

        def phase_err(s, _t=grid_t, _g=std_grid, _d=mean_dur):  # CV error of the phase at normalised time s
            return np.interp(np.asarray(s, dtype=np.float64) * _d, _t, _g)

        kw = dict(phase_std=phase_err)
        kw.update(self.coupling_kwargs or {})
        return kw

    def _predict(self, partial) -> GridPrediction:  # type: ignore[override]  # only the options it names
        """Phase of the prefix (learned), then the whole movement of both agents given it (coupling)."""
        self._check_fitted("predict")
        return self.predict_checked(as_2d_finite(partial, "partial", n_cols=len(self.observed_dofs_), min_rows=1))

    @one_blas_thread
    def predict_checked(self, partial: np.ndarray) -> GridPrediction:
        """The prediction of frames already checked -- a finite float64 array ``(M, len(observed_dofs))``, not scanned
        again (:class:`LearnedStream` checks each frame once, as it enters) -- unmarked (``predict`` marks it)."""
        est = self.phase_.estimate_checked(partial)
        # the coupling conditions at the phase clipped to [1e-3, 1] (np.clip's number, NaN kept: the coupling's
        # checks raise on it) and the prediction is placed in time by the estimate itself
        s = float(est.phase)
        out = self.coupling_.predict(partial, s if math.isnan(s) else min(max(s, 1e-3), 1.0),
                                     phase_std=float(est.std), check=False, timing=est)
        out.speed = float(est.speed)
        out.phase_estimate = est  # an extra the learned model's predictions carry
        return out

    def _stream(self, robot_state=None) -> LearnedStream:
        """Online predictor fed one observed frame at a time (:class:`LearnedStream`): after the ``M``-th frame it
        returns, bitwise, :meth:`predict` of those ``M`` frames, without recomputing anything over the prefix."""
        self._check_fitted("stream")
        if robot_state is not None:
            raise ValueError("robot_state: this model does not roll out from a robot state; pass None")
        return LearnedStream(self)

    def to_state(self):
        """``(arrays, meta)`` of the fitted model (see :meth:`interprim.models.base.Predictor.to_state`)."""
        self._check_fitted("to_state")
        pa, pm = self.phase_.to_state()
        ca, cm = self.coupling_.to_state()
        arrays = {**{f"phase_{k}": v for k, v in pa.items()}, **{f"coupling_{k}": v for k, v in ca.items()}}
        return arrays, {"phase": pm, "coupling": cm, "dt_": self.dt_, "observed_dofs_": self.observed_dofs_}

    def load_state(self, arrays, meta):
        """Restore the state written by :meth:`to_state`."""
        self.phase_ = LearnedPhase.from_state({k[6:]: v for k, v in arrays.items() if k.startswith("phase_")},
                                              meta["phase"])
        ca = {k[9:]: v for k, v in arrays.items() if k.startswith("coupling_")}
        phase_std = self._coupling_kwargs(self.phase_)["phase_std"]
        self.coupling_ = CouplingModel.from_state(ca, meta["coupling"], phase_std=phase_std if callable(phase_std)
                                                  else None)
        self.dt_ = check.number("dt_", meta["dt_"], positive=True)
        obs = check.columns("observed_dofs_", meta["observed_dofs_"], self.coupling_.n_dofs_)
        if obs != self.coupling_.observed_dofs_ or len(obs) != self.phase_.n_dofs_:
            check.fail("observed_dofs_", meta["observed_dofs_"], f"not the coupling's observed columns "
                       f"{self.coupling_.observed_dofs_} nor {self.phase_.n_dofs_} columns of the phase model")
        self.observed_dofs_ = obs


class LearnedStream(BaseStream):
    """Online :class:`LearnedInteraction`: ``update(frame)`` returns ``predict`` of all frames seen, bitwise.

    What a prediction reads of the prefix is small and fixed: the learned phase's features
    (:meth:`~interprim.phase.learned.LearnedPhase.estimate`: the first and last frames, the frame one velocity
    window back and two frames per history point; the whole prefix only for the optional ``"path"`` and
    ``"peak_speed"`` groups) and the coupling's observation, the prefix resampled at ``n_in`` points over
    ``[0, s]`` (Eq. 17-18 with the prefix observation model of :mod:`interprim.models.coupling`).  There is therefore no
    statistic of the prefix worth accumulating: the stream keeps the frames in a growing buffer (amortised ``O(D)``
    per frame, no copy of the prefix) and predicts from a view of it with :meth:`LearnedInteraction.predict`
    itself, so that it gives the same bits.  What cannot be kept from one frame to the next is the conditioning:
    the coupling's training rows are the demonstrations' prefixes cut at the estimated phase (and its jitter), and
    the phase estimate changes with every frame, so the rows and their factorisation are rebuilt per frame, in the
    cheapest exact form (``CouplingModel._ppca_weights``: the ``(p + rank)``-square Gram matrix instead of the
    rows' own); what does not depend on the phase is computed once per model.  ``need_cov`` is accepted for the
    interface of :class:`~interprim.models.primitive.stream.Stream` and has no effect.

    Parameters
    ----------
    model : LearnedInteraction
        A fitted model.
    """

    marks_input = True  # its answer is LearnedInteraction.predict of every frame seen

    def __init__(self, model: LearnedInteraction):
        self.model = model
        self._n_cols = len(model.observed_dofs_)
        self._raw = np.empty((64, self._n_cols))
        self._n = 0
        self._marks = InputMarks(model)

    @property
    def n_frames(self) -> int:
        """Number of frames received since the stream was created or last :meth:`reset`."""
        return self._n

    def reset(self, robot_state=None):
        """Forget all frames (start a new interaction)."""
        if robot_state is not None:
            raise ValueError("robot_state: this model does not roll out from a robot state; pass None")
        self._n = 0
        self._marks.reset()

    def _append(self, block):
        need = self._n + block.shape[0]
        if need > self._raw.shape[0]:
            cap = self._raw.shape[0]
            while cap < need:
                cap *= 2
            buf = np.empty((cap, self._n_cols))
            buf[: self._n] = self._raw[: self._n]
            self._raw = buf
        self._raw[self._n:need] = block
        self._n = need

    def _predict(self, block) -> BasePrediction:
        """:meth:`LearnedInteraction.predict` of every frame seen, the new (checked) ``block`` appended, marked with
        the largest input distance so far (what ``predict`` finds over the prefix; warned once per stream)."""
        self._append(block)
        pred = self.model.predict_checked(self._raw[: self._n])
        if self.model.input_range_ is not None:  # marked as Predictor.predict marks it (this model does not check)
            self._marks.mark(pred, block)
        return pred

    def update(self, frame, need_cov: bool = False) -> BasePrediction:
        """Add one frame of the observed agent, shape ``(len(observed_dofs),)``; returns ``predict`` of all frames
        seen."""
        return self._predict(as_frame(frame, "frame", self._n_cols)[None, :])

    def extend(self, frames, need_cov: bool = False) -> BasePrediction:
        """Add frames ``(k, len(observed_dofs))`` at once (checked before any enters); returns what :meth:`update`
        returns for the last of them (one prediction, since it depends on the frames only)."""
        return self._predict(as_2d_finite(frames, "frames", n_cols=self._n_cols, min_rows=1))

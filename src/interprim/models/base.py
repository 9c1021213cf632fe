"""The prediction contract shared by every model of the package.

Every model -- :class:`~interprim.models.primitive.estimator.InteractionPrimitive`,
:class:`~interprim.models.learned.LearnedInteraction` and the peer methods of :mod:`interprim.models.demonstrations`
-- is a :class:`Predictor`:

* ``fit(demos, dt=None, times=None, columns=None)`` returns the model (``demos``: a list of arrays, a
  :class:`~interprim.datasets.Demonstrations` or a :class:`~interprim.models.training.TrainingSet`);
  ``predict(partial)`` and ``stream()`` raise
  :class:`~interprim.core.errors.NotFittedError` before it;
* ``predict(partial)`` takes the observed agent's frames from the start of the movement, shape
  ``(M, len(observed_dofs))``, and returns a :class:`BasePrediction`;
* ``stream()`` returns a :class:`BaseStream`, an online predictor whose ``update(frame, need_cov=False)``
  returns, after the ``M``-th frame, the prediction ``predict`` gives for those ``M`` frames, and whose
  ``extend(frames, need_cov=False)`` takes several frames at once and returns what ``update`` returns for the
  last of them (``reset()`` and ``n_frames`` as well);
* ``save(path)`` / ``load(path)`` write and read a pickle-free, checksummed, versioned model file
  (:mod:`interprim.io`);
* ``get_params(deep=True)`` / ``set_params(**params)`` follow scikit-learn, so ``sklearn.base.clone`` works.

Every prediction is a :class:`BasePrediction`: the same attributes (``phase``, ``normalised_time``,
``duration``, ``speed``, ``log_likelihood``, ``conditioned``, ``n_observed``, ``input_distance``,
``out_of_range``) and the same methods with the same return shapes on the normalised-time grid
``linspace(0, 1, n)``:

=================================  ===========================================================
``trajectory(n)``                  ``(n, D)`` mean of every data column
``std(n, calibrated=True)``        ``(n, D)`` pointwise standard deviation (``None``: the model
                                   gives no uncertainty)
``samples(n_samples, n, rs)``      ``(n_samples, n, D)`` trajectories drawn from the prediction
``response(n, state=None)``        ``(t, y)``: seconds from now and ``(n, n_controlled)`` positions
                                   of the controlled agent from the current phase to the end
``completion(n)``                  ``(s, y)``: normalised times from the current phase to 1 and
                                   ``(n, n_observed)`` positions of the observed agent
``goal``                           ``(D,)`` the predicted end point (the DMP goal for an IP)
=================================  ===========================================================

:class:`~interprim.models.grid.GridPrediction` is the prediction of the models that tabulate their mean and
standard deviation on a normalised-time grid (the coupling, the learned interaction and the baselines); the
Interaction Primitive's :class:`~interprim.models.primitive.prediction.Prediction` integrates its DMPs instead.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

import numpy as np
from numpy.typing import ArrayLike

from ..core.blas import limit_methods, one_blas_thread
from ..core.errors import NotFittedError
from ..core.input_range import CHECKED_BY_CALLER, checked_by_caller, duration_range, fit_input_range, mark
from ..core.params import Params
from ..core.validation import as_2d_finite, as_frame
from .training import DEFAULT_DT, TrainingSet, training_set, uniform_demonstrations

__all__ = ["BasePrediction", "BaseStream", "Predictor", "PrefixStream", "CheckedStream", "InputMarks",
           "TrajectoryColumns", "TrainingSet", "training_set", "uniform_demonstrations", "DEFAULT_DT"]


#: the prediction accessors run on one BLAS thread (:func:`interprim.core.blas.limit_methods`)
_PREDICTION_CALLS = ("trajectory", "std", "samples", "response", "completion", "completion_std", "band")

#: a :class:`Predictor` subclass (``fit`` and ``load`` return the class they are called on)
P = TypeVar("P", bound="Predictor")


class BasePrediction:
    """What every model's prediction offers (see the module docstring); subclasses implement the methods.

    Every accessor a subclass defines runs on one BLAS thread (:func:`interprim.core.blas.limit_methods`), as the
    predictors' ``fit``/``predict`` and the streams' ``update``/``extend`` do.
    """

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        limit_methods(cls, _PREDICTION_CALLS)

    #: fraction of the movement seen (NaN when the model does not estimate it)
    phase: float = float("nan")
    #: normalised time of the last observed frame, in [0, 1] (NaN when not estimated)
    normalised_time: float = float("nan")
    #: estimated duration of the whole movement in seconds (NaN when not estimated)
    duration: float = float("nan")
    #: partner's speed relative to the mean demonstration (NaN when not estimated)
    speed: float = float("nan")
    #: the DMP canonical-system value at ``phase`` (Eq. 2 and 9; NaN for a model without DMPs)
    x: float = float("nan")
    #: ``log p(observation | model)`` at the estimated phase (NaN when the model has none)
    log_likelihood: float = float("nan")
    #: whether the prediction depends on the observed frames (``False``: the prior / mean movement)
    conditioned: bool = True
    #: number of observed frames the prediction used
    n_observed: int = 0
    #: largest standardised distance of an observed frame from the training frames (NaN: not checked)
    input_distance: float = float("nan")
    #: whether that distance passed the model's limit
    out_of_range: bool = False
    #: whether the predicted duration is far outside the demonstrated ones
    #: (:data:`interprim.core.input_range.DURATION_FACTOR`)
    duration_out_of_range: bool = False

    def trajectory(self, n: int = 100) -> np.ndarray:  # pragma: no cover - interface
        """Mean of every data column on ``linspace(0, 1, n)`` (normalised time), shape ``(n, D)``."""
        raise NotImplementedError

    def std(self, n: int = 100, calibrated: bool = True) -> np.ndarray | None:  # pragma: no cover - interface
        """Pointwise standard deviation of :meth:`trajectory`, shape ``(n, D)`` (``None``: no uncertainty);
        ``calibrated=False``: the model's raw std (without calibration or timing terms)."""
        raise NotImplementedError

    def samples(self, n_samples: int = 20, n: int = 100,
                random_state: Any = None) -> np.ndarray:  # pragma: no cover - interface
        """Trajectories drawn from the prediction, shape ``(n_samples, n, D)``."""
        raise NotImplementedError

    def response(self, n: int = 100,
                 state: ArrayLike | None = None) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover
        """``(t, y)``: seconds from now and the controlled agent's positions ``(n, n_controlled)`` from the
        current phase to the end of the movement."""
        raise NotImplementedError

    def completion(self, n: int = 100) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover - interface
        """``(s, y)``: normalised times from the current phase to 1 and the observed agent's positions
        ``(n, n_observed)`` there."""
        raise NotImplementedError

    @property
    def goal(self) -> np.ndarray:  # pragma: no cover - interface
        """The predicted end point (goal) of every data column, shape ``(D,)``."""
        raise NotImplementedError

    def mean_rollout(self, n: int = 100, columns: Any = None) -> Callable[[Any], np.ndarray]:
        """A callable ``f`` with ``f(pred) == pred.trajectory(n)[:, columns]`` for this and every later prediction
        of the same model (a server or controller that needs the same columns on the same grid at every frame).

        This default calls :meth:`trajectory`; a model may return something cheaper that gives the same values
        (the Interaction Primitive's :class:`~interprim.models.primitive.prediction.MeanRollout` builds the grid's
        design once).
        """
        return TrajectoryColumns(n, columns)


class TrajectoryColumns:
    """``pred.trajectory(n)[:, columns]`` (all columns for ``columns=None``): :meth:`BasePrediction.mean_rollout`'s
    default."""

    __slots__ = ("n", "columns")

    def __init__(self, n: int, columns: Any = None) -> None:
        self.n = int(n)
        self.columns = slice(None) if columns is None else columns

    def __call__(self, pred: BasePrediction) -> np.ndarray:
        return np.asarray(pred.trajectory(self.n))[:, self.columns]


class BaseStream:
    """What every model's online predictor offers: :meth:`update`, :meth:`extend`, :meth:`reset` and ``n_frames``.

    Subclasses implement :meth:`update`, :meth:`reset` and ``n_frames``; :meth:`extend` defaults to :meth:`update`
    frame by frame, so a stream's answer never depends on how its frames were grouped (a server that fell behind
    feeds a session's pending frames with one ``extend``).  A subclass may override :meth:`extend` with a cheaper
    computation of the same answer.
    """

    #: whether the predictions already carry ``input_distance`` / ``out_of_range`` of every frame seen (a stream
    #: that answers with the model's own ``predict`` of the frames seen)
    marks_input = False

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        limit_methods(cls, ("update", "extend"))  # one BLAS thread (see BasePrediction)

    @property
    def n_frames(self) -> int:  # pragma: no cover - interface
        """Number of frames received since the stream was created or last :meth:`reset`."""
        raise NotImplementedError

    def reset(self, robot_state: ArrayLike | None = None) -> None:  # pragma: no cover - interface
        """Forget all frames (start a new interaction)."""
        raise NotImplementedError

    def update(self, frame: ArrayLike, need_cov: bool = False) -> BasePrediction:  # pragma: no cover - interface
        """Add one frame of the observed agent, shape ``(n_observed,)``; returns the prediction for all frames seen."""
        raise NotImplementedError

    def extend(self, frames: ArrayLike, need_cov: bool = False) -> BasePrediction:
        """Add several frames of the observed agent at once, shape ``(k, n_observed)`` with ``k >= 1``, oldest first;
        returns what ``k`` calls of :meth:`update` return for the last of them.

        Raises
        ------
        ValueError, TypeError
            ``frames`` is not a finite 2-D numeric array with at least one row; the message names it.  The
            frames are checked before any enters the stream (a wrong number of columns is found by the first
            frame's :meth:`update`).
        """
        block = as_2d_finite(frames, "frames", min_rows=1)
        pred = self.update(block[0], need_cov=need_cov)
        for f in block[1:]:
            pred = self.update(f, need_cov=need_cov)
        return pred


class PrefixStream(BaseStream):
    """Online use of a model whose prediction is a function of the observed prefix: one frame at a time.

    :meth:`update` appends a frame and returns ``model.predict`` of all frames seen (so a stream equals the
    batch predictions by construction); :meth:`extend` appends several and predicts once (the same answer as
    :meth:`update` for the last, since the prediction depends on the frames only).  ``need_cov`` is accepted for
    the interface of :class:`~interprim.models.primitive.stream.Stream` and has no effect.
    """

    marks_input = True  # its answer is the model's predict of every frame seen

    def __init__(self, model: Predictor) -> None:
        self.model = model
        self._n_cols = len(model.observed_dofs_)
        self._buf = np.empty((16, self._n_cols))
        self._n = 0

    @property
    def n_frames(self) -> int:
        """Number of frames received since the stream was created or last :meth:`reset`."""
        return self._n

    def reset(self, robot_state: ArrayLike | None = None) -> None:
        """Forget all frames (start a new interaction)."""
        self._n = 0

    def update(self, frame: ArrayLike, need_cov: bool = False) -> BasePrediction:
        """Add one frame of the observed agent, shape ``(len(observed_dofs),)``; returns its prediction."""
        f = as_frame(frame, "frame", self._n_cols)
        if self._n == self._buf.shape[0]:
            self._buf = np.concatenate([self._buf, np.empty_like(self._buf)])
        self._buf[self._n] = f
        self._n += 1
        return self.model.predict(self._buf[: self._n].copy())

    def extend(self, frames: ArrayLike, need_cov: bool = False) -> BasePrediction:
        """Add frames ``(k, len(observed_dofs))`` at once (checked before any enters); returns the prediction for
        all frames seen, as :meth:`update` does for the last of them."""
        block = as_2d_finite(frames, "frames", n_cols=self._n_cols, min_rows=1)
        need = self._n + block.shape[0]
        if need > self._buf.shape[0]:
            cap = self._buf.shape[0]
            while cap < need:
                cap *= 2
            buf = np.empty((cap, self._n_cols))
            buf[: self._n] = self._buf[: self._n]
            self._buf = buf
        self._buf[self._n:need] = block
        self._n = need
        return self.model.predict(self._buf[: self._n].copy())


class Predictor(Params):
    """Base of every model: the contract of the module docstring.

    A family implements the hooks and the base class writes the public methods around them once, here:

    * ``_fit(data)`` learns from a :class:`~interprim.models.training.TrainingSet`.  :meth:`fit` builds that set
      once (:func:`~interprim.models.training.training_set`, the one reader of demonstrations and time stamps),
      calls ``_fit`` and then keeps the range of the observed agent's training frames;
    * ``_predict(partial, **kwargs)`` returns the prediction; :meth:`predict` marks it with ``input_distance`` and
      ``out_of_range``;
    * ``_stream(robot_state)`` (default: :class:`PrefixStream`, ``predict`` of the frames seen) returns the online
      predictor; :meth:`stream` marks its predictions (:class:`CheckedStream`) unless it marks them itself;
    * :meth:`to_state` and :meth:`load_state`, and ``_FITTED`` names one fitted attribute; ``STATE_VERSION`` is
      the version of their model-file content.

    **The out-of-range check is part of the contract.**  After ``fit``, every model knows the range of its
    training frames of the observed agent (:func:`interprim.core.input_range.fit_input_range`, kept in
    ``input_range_`` and in its model file); every prediction carries ``input_distance`` and ``out_of_range``
    (:func:`interprim.core.input_range.mark`; a stream: the largest distance of the frames seen so far) and warns
    once.  A class that computes them itself sets ``_CHECKS_INPUT = True`` (the Interaction Primitive, whose
    fitted state marks its predictions, and :class:`~interprim.models.auto.AutoInteraction`).  A wrapper that marks
    the prediction it returns (:class:`~interprim.models.auto.AutoInteraction`, :class:`CheckedStream`) calls the
    models inside :data:`~interprim.core.input_range.CHECKED_BY_CALLER`, where they skip their own checks.

    :meth:`fit` and :meth:`predict` run on one BLAS thread (:func:`interprim.core.blas.one_blas_thread`); a subclass
    that overrides them instead of the hooks gets the same limit around its own.
    """

    #: whether the class computes ``input_distance`` / ``out_of_range`` itself
    _CHECKS_INPUT = False
    #: ``(mean, std, limit)`` of the observed training frames (None: unknown, e.g. a member inside a blend's file)
    input_range_ = None
    #: the observed agent's columns, once fitted (every family sets them in ``_fit`` or ``load_state``)
    observed_dofs_: list[int]

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        limit_methods(cls, [n for n in ("fit", "predict") if n in cls.__dict__
                            and not getattr(cls.__dict__[n], "__interprim_one_blas__", False)])

    @one_blas_thread
    def fit(self: P, demos: Any, dt: float | None = None, times: Any = None, columns: Any = None) -> P:
        """Learn the model from demonstrations of both agents; returns the model.

        Parameters
        ----------
        demos : list of array_like, shape (T_j, D), Demonstrations or TrainingSet
            One array per demonstration, time on axis 0, the columns of both agents (``observed_dofs`` for the
            observed one); lengths may differ.  An :class:`interprim.datasets.Demonstrations` (any loader's
            result) is taken with its ``dt`` (or time stamps) and column names unless given here.
        dt : float, optional
            Sampling interval in seconds of uniformly sampled arrays (default 0.01 when neither ``dt`` nor
            ``times`` is given).
        times : list of array_like, shape (T_j,), optional
            Time stamps in seconds per demonstration: irregular sampling is resampled onto a uniform grid at the
            median interval (:func:`~interprim.models.training.training_set`).
        columns : list of str, optional
            Names of the ``D`` columns.

        Returns
        -------
        self
        """
        data = training_set(demos, dt, times=times, columns=columns)
        self._fit(data)
        obs = getattr(self, "observed_dofs_", None)
        if not self._CHECKS_INPUT and obs is not None:
            self.set_input_range(fit_input_range(data.frames(obs)))
        return self

    def _fit(self, data: TrainingSet) -> None:  # pragma: no cover - interface
        """Learn from the validated training set (the family's part of :meth:`fit`)."""
        raise NotImplementedError

    @one_blas_thread
    def predict(self, partial: ArrayLike, **kwargs: Any) -> BasePrediction:
        """The prediction from the observed agent's frames ``partial`` ``(M, len(observed_dofs))`` since the start
        of the movement, marked with ``input_distance`` and ``out_of_range``; the model is left unchanged."""
        pred = self._predict(partial, **kwargs)
        if not self._CHECKS_INPUT and self.input_range_ is not None and not checked_by_caller() and not np.isfinite(
                getattr(pred, "input_distance", float("nan"))):
            mark(self, pred, self.input_distance(partial))
        return pred

    def _predict(self, partial: ArrayLike, **kwargs: Any) -> BasePrediction:  # pragma: no cover - interface
        """The family's prediction of :meth:`predict` (unmarked)."""
        raise NotImplementedError

    def stream(self, robot_state: ArrayLike | None = None) -> BaseStream:
        """Online predictor that takes one observed frame at a time; its answers equal :meth:`predict` of the
        frames seen, marked with the largest input distance so far."""
        inner = self._stream(robot_state)
        if self._CHECKS_INPUT or self.input_range_ is None or isinstance(inner, CheckedStream) or inner.marks_input:
            return inner
        return CheckedStream(self, inner)

    def _stream(self, robot_state: ArrayLike | None = None) -> BaseStream:
        """The family's online predictor of :meth:`stream` (default :class:`PrefixStream`)."""
        self._check_fitted("stream")
        if robot_state is not None:
            raise ValueError("robot_state: this model does not roll out from a robot state; pass None")
        return PrefixStream(self)

    def set_input_range(self, input_range: Any) -> None:
        """Set ``input_range_`` (``(mean, std, limit)`` or None), e.g. from a model file."""
        if input_range is None:
            self.input_range_ = self.input_limit_ = None
            return
        mean, std, limit = input_range
        mean, std = np.asarray(mean, dtype=np.float64).ravel(), np.asarray(std, dtype=np.float64).ravel()
        if std.shape != mean.shape or not np.all(std > 0) or not float(limit) > 0:
            raise ValueError("input_range: mean and std of one shape, std and limit positive")
        self.input_range_ = (mean, std, float(limit))
        #: the input distance above which a prediction is out of range
        self.input_limit_ = float(limit)

    def input_distance(self, frames: ArrayLike) -> float:
        """Largest standardised distance of observed frames ``(t, len(observed_dofs))`` from the training frames
        (:mod:`interprim.core.input_range`); NaN when the range is unknown."""
        if self.input_range_ is None:
            return float("nan")
        mean, std, _ = self.input_range_
        f = np.atleast_2d(np.asarray(frames, dtype=np.float64))
        return float(np.max(np.abs(f - mean) / std)) if f.size else 0.0


    _FITTED = "observed_dofs_"
    STATE_VERSION = 1
    #: whether :meth:`stream` gives, bitwise, what ``predict`` gives on the same frames and is cheaper than predicting
    #: every prefix anew (the real-time protocol then streams: :func:`interprim.evaluation.realtime.realtime_fold`)
    exact_stream = False

    def _check_fitted(self, what: str) -> None:
        if not hasattr(self, self._FITTED):
            raise NotFittedError(f"this {type(self).__name__} is not fitted yet; call fit(demos) before {what}")

    def json_params(self) -> dict[str, Any]:
        """:meth:`get_params` (not deep) as stored in a model file (tuples as lists)."""
        import json

        params: dict[str, Any] = json.loads(json.dumps(self.get_params(deep=False), default=_jsonable))
        return params

    def to_state(self) -> tuple[dict[str, np.ndarray], dict[str, Any]]:  # pragma: no cover - interface
        """``(arrays, meta)``: the fitted state, numeric arrays apart and the rest JSON-friendly."""
        raise NotImplementedError

    def load_state(self, arrays: dict[str, np.ndarray], meta: dict[str, Any]) -> None:  # pragma: no cover
        """Restore the fitted state written by :meth:`to_state` (used by :func:`interprim.io.load_estimator`)."""
        raise NotImplementedError

    def save(self, path: str | os.PathLike[str]) -> None:
        """Save to a safe ``.npz`` model file (arrays + JSON metadata, no pickle); see :mod:`interprim.io`."""
        self._check_fitted("save")
        from ..io import save_estimator

        save_estimator(self, path)

    @classmethod
    def load(cls: type[P], path: str | os.PathLike[str]) -> P:
        """Load a model saved by :meth:`save`; raises :class:`~interprim.ModelFileError` on bad files."""
        from ..core.state_checks import building
        from ..io import load_estimator

        with building(Path(path)):  # the file's name on every error; inconsistent values a ModelFileError
            return load_estimator(path, cls)


def _jsonable(v: Any) -> Any:
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, np.generic):
        return v.item()
    raise TypeError(f"parameter value {v!r} cannot be stored in a model file")


class InputMarks:
    """A stream's running input check: each prediction is marked with the largest ``input_distance`` of the frames
    seen so far and ``out_of_range`` (:func:`interprim.core.input_range.mark`), warned once per stream.

    Used by :class:`CheckedStream` and by the streams that mark their own predictions (``marks_input``)."""

    __slots__ = ("model", "largest", "warned", "span")

    def __init__(self, model: Predictor) -> None:
        self.model = model
        self.largest = 0.0
        self.warned = False
        #: the model's demonstrated durations (:func:`interprim.core.input_range.duration_range`), read once: the model
        #: does not change during a stream
        self.span = duration_range(model)

    def reset(self) -> None:
        """Forget the frames seen (a new interaction)."""
        self.largest = 0.0
        self.warned = False

    def mark(self, pred: BasePrediction, frames: ArrayLike) -> BasePrediction:
        """``pred`` marked after the new ``frames`` (one frame or ``(k, n_observed)``) entered the stream (left as it
        is inside :data:`~interprim.core.input_range.CHECKED_BY_CALLER`: the caller marks it)."""
        if checked_by_caller():
            return pred
        d = self.model.input_distance(np.atleast_2d(np.asarray(frames, dtype=np.float64)))
        self.largest = max(self.largest, d) if np.isfinite(d) else d
        mark(self.model, pred, self.largest, warn=not self.warned, span=self.span)
        self.warned = self.warned or pred.out_of_range
        return pred


class CheckedStream(BaseStream):
    """A model's stream whose predictions carry ``input_distance`` and ``out_of_range`` of every frame seen so far
    (the largest distance, :mod:`interprim.core.input_range`), warned once per stream."""

    def __init__(self, model: Predictor, inner: BaseStream) -> None:
        self.model, self.inner = model, inner
        self._marks = InputMarks(model)

    @property
    def n_frames(self) -> int:
        """Frames received since the stream was created or last reset."""
        return self.inner.n_frames

    def reset(self, robot_state: ArrayLike | None = None) -> None:
        """Forget all frames (start a new interaction)."""
        self.inner.reset(robot_state)
        self._marks.reset()

    def update(self, frame: ArrayLike, need_cov: bool = False) -> BasePrediction:
        """Add one observed frame; the inner stream's prediction, marked (the inner models' own checks skipped:
        :data:`~interprim.core.input_range.CHECKED_BY_CALLER`)."""
        with CHECKED_BY_CALLER:
            pred = self.inner.update(frame, need_cov=need_cov)
        return self._marks.mark(pred, frame)

    def extend(self, frames: ArrayLike, need_cov: bool = False) -> BasePrediction:
        """Add several frames; the inner stream's prediction for the last, marked."""
        with CHECKED_BY_CALLER:
            pred = self.inner.extend(frames, need_cov=need_cov)
        return self._marks.mark(pred, frames)


if TYPE_CHECKING:
    from ..model_selection.realtime import EstimatorLike, PredictionLike, StreamLike

    def _conforms(p: Predictor, b: BasePrediction, s: BaseStream) -> tuple[EstimatorLike, PredictionLike, StreamLike]:
        """The contract's classes are what the real-time protocol reads (its structural types; checked by mypy)."""
        return p, b, s

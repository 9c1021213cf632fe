"""The prediction contract shared by every model of the package.

Every model -- :class:`~interprim.models.primitive.estimator.InteractionPrimitive`, :class:`~interprim.models.learned.LearnedInteraction`
and the peer methods of :mod:`interprim.models.demonstrations` -- is a :class:`Predictor`:

* ``fit(demos, dt=None)`` returns the model; ``predict(partial)`` and ``stream()`` raise
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

:class:`GridPrediction` is the prediction of the models that tabulate their mean and standard deviation on a
normalised-time grid (the coupling, the learned interaction and the baselines); the Interaction Primitive's
:class:`~interprim.models.primitive.prediction.Prediction` integrates its DMPs instead.
"""

from __future__ import annotations

import functools
import math
import warnings

import numpy as np

from ..core.blas import limit_methods, one_blas_thread
from ..core.params import Params
from ..core.validation import as_2d_finite, as_frame
from ..core.preprocessing import interp_columns
from ..core.errors import NotFittedError, OutOfRangeWarning
from ..core.input_range import fit_input_range, mark

__all__ = ["BasePrediction", "BaseStream", "GridPrediction", "Predictor", "PrefixStream",
           "uniform_demonstrations", "DEFAULT_DT", "CheckedStream"]

#: Sampling interval (s) assumed for plain arrays given without ``dt``.
DEFAULT_DT = 0.01


def uniform_demonstrations(demos, dt=None):
    """The one rule by which every family reads demonstrations and their time stamps.

    Returns ``(arrays, dt, columns)``: ``(T_i, D)`` float arrays on a uniform grid, the sampling interval in
    seconds and the column names (``None`` without).  A :class:`~interprim.datasets.Demonstrations` with a common
    interval (``demos.dt``) is used as it is; one whose time stamps are irregular (jitter beyond 1 %, dropped
    frames: ``demos.dt is None``) is resampled linearly onto a grid at the median interval of all its stamps, so
    its durations are the recorded ones.  Plain arrays take ``dt`` (default :data:`DEFAULT_DT`).
    """
    from ..core.preprocessing import resample_uniform
    from ..core.validation import check_positive, check_times

    columns = None
    if hasattr(demos, "demos") and hasattr(demos, "times"):  # interprim.datasets.Demonstrations
        columns = getattr(demos, "columns", None)
        arrays = [as_2d_finite(d, f"demos[{j}]") for j, d in enumerate(demos.demos)]
        if dt is None and getattr(demos, "dt", None) is None:
            ts = [check_times(t, a.shape[0], f"times[{j}]") for j, (t, a) in enumerate(zip(demos.times, arrays))]
            dt = float(np.median(np.concatenate([np.diff(t) for t in ts])))
            arrays = [resample_uniform(a, t, dt=dt)[0] for a, t in zip(arrays, ts)]
        elif dt is None:
            dt = demos.dt
    else:
        if isinstance(demos, np.ndarray) and demos.ndim == 3:
            demos = list(demos)
        if not isinstance(demos, (list, tuple)):
            raise TypeError(f"demos must be a list of (T, D) arrays, got {type(demos).__name__}")
        arrays = [as_2d_finite(d, f"demos[{j}]") for j, d in enumerate(demos)]
    if not arrays:
        raise ValueError("demos is empty: at least one demonstration is needed")
    D = arrays[0].shape[1]
    for j, a in enumerate(arrays):
        if a.shape[1] != D:
            raise ValueError(f"demos[{j}] has {a.shape[1]} columns but demos[0] has {D}")
    dt = DEFAULT_DT if dt is None else check_positive(dt, "dt")
    return arrays, float(dt), None if columns is None else [str(c) for c in columns]


#: the prediction accessors run on one BLAS thread (:func:`interprim.core.blas.limit_methods`)
_PREDICTION_CALLS = ("trajectory", "std", "samples", "response", "completion", "completion_std", "band")


class BasePrediction:
    """What every model's prediction offers (see the module docstring); subclasses implement the methods.

    Every accessor a subclass defines runs on one BLAS thread (:func:`interprim.core.blas.limit_methods`), as the
    predictors' ``fit``/``predict`` and the streams' ``update``/``extend`` do.
    """

    def __init_subclass__(cls, **kwargs):
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

    def trajectory(self, n: int = 100) -> np.ndarray:  # pragma: no cover - interface
        """Mean of every data column on ``linspace(0, 1, n)`` (normalised time), shape ``(n, D)``."""
        raise NotImplementedError

    def std(self, n: int = 100, calibrated: bool = True):  # pragma: no cover - interface
        """Pointwise standard deviation of :meth:`trajectory`, shape ``(n, D)`` (``None``: no uncertainty);
        ``calibrated=False``: the model's raw std (without calibration or timing terms)."""
        raise NotImplementedError

    def samples(self, n_samples: int = 20, n: int = 100, random_state=None) -> np.ndarray:  # pragma: no cover
        """Trajectories drawn from the prediction, shape ``(n_samples, n, D)``."""
        raise NotImplementedError

    def response(self, n: int = 100, state=None):  # pragma: no cover - interface
        """``(t, y)``: seconds from now and the controlled agent's positions ``(n, n_controlled)`` from the
        current phase to the end of the movement."""
        raise NotImplementedError

    def completion(self, n: int = 100):  # pragma: no cover - interface
        """``(s, y)``: normalised times from the current phase to 1 and the observed agent's positions
        ``(n, n_observed)`` there."""
        raise NotImplementedError

    @property
    def goal(self) -> np.ndarray:  # pragma: no cover - interface
        """The predicted end point (goal) of every data column, shape ``(D,)``."""
        raise NotImplementedError

    def mean_rollout(self, n: int = 100, columns=None):
        """A callable ``f`` with ``f(pred) == pred.trajectory(n)[:, columns]`` for this and every later prediction
        of the same model (a server or controller that needs the same columns on the same grid at every frame).

        This default calls :meth:`trajectory`; a model may return something cheaper that gives the same values
        (the Interaction Primitive's :class:`~interprim.models.primitive.prediction.MeanRollout` builds the grid's design once).
        """
        return TrajectoryColumns(n, columns)


class TrajectoryColumns:
    """``pred.trajectory(n)[:, columns]`` (all columns for ``columns=None``): :meth:`BasePrediction.mean_rollout`'s
    default."""

    __slots__ = ("n", "columns")

    def __init__(self, n: int, columns=None):
        self.n = int(n)
        self.columns = slice(None) if columns is None else columns

    def __call__(self, pred) -> np.ndarray:
        return np.asarray(pred.trajectory(self.n))[:, self.columns]


class GridPrediction(BasePrediction):
    """A prediction of the whole movement of all DoFs tabulated on normalised time ``0 .. 1``.

    Made by :class:`~interprim.models.coupling.CouplingModel`, :class:`~interprim.models.learned.LearnedInteraction` and
    the demonstration families.

    Parameters
    ----------
    times : ndarray, shape (K,)
        Normalised times of ``mean`` (and ``std``), increasing from 0 to 1.
    mean : ndarray, shape (K, D)
        Predictive mean, columns in the demonstrations' order.
    std : ndarray, shape (K, D), optional
        Predictive standard deviation (kept as ``std_values``); ``None`` when the model gives no uncertainty.
    phase : float
        The phase estimate (fraction of the movement seen) the prediction was made with (NaN: none).
    phase_std : float
        Its standard deviation (0: known or not modelled).
    observed_dofs, controlled_dofs : list of int, optional
        Columns of the two agents (default: none observed, all controlled).
    method : str, optional
        What made it (e.g. the coupling chosen, ``"mean"`` for the prior mean).
    leverage : float
        ``h`` of :mod:`interprim.models.coupling` (parameter variance / residual variance; NaN when not defined).
    log_likelihood : float
    duration : float
        Estimated duration of the whole movement in seconds (NaN when not estimated).
    mean_duration : float
        Mean duration of the demonstrations in seconds (the unit of ``speed``; NaN when unknown).
    n_observed : int
        Observed frames the prediction used.
    timing : bool
        Whether :meth:`std` adds the uncertainty of the timing (``phase_std``) to ``std``.
    conditioned : bool
        Whether the prediction depends on the observed frames.
    """

    def __init__(self, times, mean, std=None, phase=float("nan"), phase_std=0.0, observed_dofs=None,
                 controlled_dofs=None, method=None, leverage=float("nan"), log_likelihood=float("nan"),
                 duration=float("nan"), mean_duration=float("nan"), n_observed: int = 0, timing: bool = False,
                 conditioned: bool = True):
        self.times = np.asarray(times, dtype=np.float64)
        self.mean = np.asarray(mean, dtype=np.float64)
        self.std_values = None if std is None else np.asarray(std, dtype=np.float64)
        D = self.mean.shape[1]
        self.phase = float(phase)
        self.normalised_time = self.phase
        self.phase_std = float(phase_std)
        self.observed_dofs = [] if observed_dofs is None else [int(i) for i in observed_dofs]
        self.controlled_dofs = ([i for i in range(D) if i not in set(self.observed_dofs)]
                                if controlled_dofs is None else [int(i) for i in controlled_dofs])
        self.method = method
        self.leverage = float(leverage)
        self.log_likelihood = float(log_likelihood)
        self.duration = float(duration)
        self.speed = float(mean_duration) / self.duration if self.duration > 0 else float("nan")
        self.n_observed = int(n_observed)
        self.timing = bool(timing)
        self.conditioned = bool(conditioned)
        self.input_distance = float("nan")
        self.out_of_range = False

    def _at(self, Y, s, cols=None):
        return interp_columns(s, self.times, Y if cols is None else Y[:, list(cols)])

    def trajectory(self, n: int = 100) -> np.ndarray:
        """Predictive mean of all DoFs, shape ``(n, D)`` on ``linspace(0, 1, n)`` (linear interpolation)."""
        return self._at(self.mean, np.linspace(0.0, 1.0, int(n)))

    @one_blas_thread
    def std(self, n: int = 100, calibrated: bool = True, timing: bool | None = None):
        """Predictive standard deviation of all DoFs, shape ``(n, D)``; ``None`` when the model gives none.

        With ``timing`` (default: the prediction's own ``timing`` flag, and only when ``calibrated``) the
        uncertainty of the timing is added: a point at normalised time ``u`` is placed in real time by the phase
        ``s`` and the duration ``elapsed / s``; a relative error ``e = phase_std / s`` of the phase moves it by
        ``u e`` to first order, and the position there by ``|dy/du| u e``, added in quadrature (``e`` capped
        at 1).  ``calibrated=False``: the tabulated std alone.
        """
        if self.std_values is None:
            return None
        sd = self._at(self.std_values, np.linspace(0.0, 1.0, int(n)))
        use_timing = (self.timing and calibrated) if timing is None else bool(timing)
        if not use_timing or not self.phase > 0.0 or self.phase_std <= 0.0:
            return sd
        u = np.linspace(0.0, 1.0, int(n))
        slope = np.gradient(self.trajectory(n), u, axis=0)
        e = min(self.phase_std / self.phase, 1.0)
        return np.sqrt(sd * sd + (slope * (u * e)[:, None]) ** 2)

    @one_blas_thread
    def samples(self, n_samples: int = 20, n: int = 100, random_state=None) -> np.ndarray:
        """Trajectories ``trajectory(n) + z * std(n)``, shape ``(n_samples, n, D)``, with one standard normal ``z``
        per sample and column (the tabulated std is pointwise: each sample is a whole-movement offset with the
        right pointwise spread); copies of the mean when the model gives no std."""
        rng = np.random.default_rng(random_state)
        mean = self.trajectory(n)
        sd = self.std(n)
        z = rng.standard_normal((int(n_samples), 1, mean.shape[1]))
        if sd is None:
            return np.repeat(mean[None], int(n_samples), axis=0)
        return mean[None] + z * sd[None]

    def _now(self) -> float:
        s = self.phase
        return float(min(max(s, 0.0), 1.0)) if math.isfinite(s) else 0.0

    def response(self, n: int = 100, state=None):
        """The controlled agent's mean movement from the current phase to the end.

        Returns ``(t, y)``: seconds from now (at the estimated ``duration``; normalised time when the model
        estimates none) and positions ``(n, len(controlled_dofs))``.  ``state`` (a robot state) is not used by a
        tabulated prediction and must be ``None``.
        """
        if state is not None:
            raise ValueError("state: this model's prediction does not roll out from a robot state; pass None")
        s0 = self._now()
        s = np.linspace(s0, 1.0, int(n))
        scale = self.duration if math.isfinite(self.duration) and self.duration > 0 else 1.0
        return (s - s0) * scale, self._at(self.mean, s, self.controlled_dofs)

    def completion(self, n: int = 100):
        """The observed agent's remaining movement: ``(s, y)``, normalised times from the current phase to 1 and
        the mean ``(n, len(observed_dofs))`` there (its std: :meth:`completion_std`)."""
        s = np.linspace(self._now(), 1.0, int(n))
        return s, self._at(self.mean, s, self.observed_dofs)

    def completion_std(self, n: int = 100):
        """The std of :meth:`completion`'s positions, ``(n, len(observed_dofs))`` (``None`` without a std)."""
        if self.std_values is None:
            return None
        return self._at(self.std_values, np.linspace(self._now(), 1.0, int(n)), self.observed_dofs)

    @property
    def goal(self) -> np.ndarray:
        """The predicted end point of every DoF, shape ``(D,)``."""
        return self.mean[-1].copy()

    def band(self, n: int = 100, coverage: float = 0.9):
        """Lower and upper edge of the pointwise ``coverage`` band, each ``(n, D)``."""
        from statistics import NormalDist

        z = NormalDist().inv_cdf(0.5 + coverage / 2.0)
        m, s = self.trajectory(n), self.std(n)
        return m - z * s, m + z * s

    def __repr__(self):
        return (f"GridPrediction(phase={self.phase:.3f}, duration={self.duration:.3f}, method={self.method!r}, "
                f"n_observed={self.n_observed})")


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

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        limit_methods(cls, ("update", "extend"))  # one BLAS thread (see BasePrediction)

    @property
    def n_frames(self) -> int:  # pragma: no cover - interface
        """Number of frames received since the stream was created or last :meth:`reset`."""
        raise NotImplementedError

    def reset(self, robot_state=None):  # pragma: no cover - interface
        """Forget all frames (start a new interaction)."""
        raise NotImplementedError

    def update(self, frame, need_cov: bool = False) -> BasePrediction:  # pragma: no cover - interface
        """Add one frame of the observed agent, shape ``(n_observed,)``; returns the prediction for all frames seen."""
        raise NotImplementedError

    def extend(self, frames, need_cov: bool = False) -> BasePrediction:
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
        pred = None
        for f in block:
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

    def __init__(self, model):
        self.model = model
        self._n_cols = len(model.observed_dofs_)
        self._buf = np.empty((16, self._n_cols))
        self._n = 0

    @property
    def n_frames(self) -> int:
        """Number of frames received since the stream was created or last :meth:`reset`."""
        return self._n

    def reset(self, robot_state=None):
        """Forget all frames (start a new interaction)."""
        self._n = 0

    def update(self, frame, need_cov: bool = False):
        """Add one frame of the observed agent, shape ``(len(observed_dofs),)``; returns its prediction."""
        f = as_frame(frame, "frame", self._n_cols)
        if self._n == self._buf.shape[0]:
            self._buf = np.concatenate([self._buf, np.empty_like(self._buf)])
        self._buf[self._n] = f
        self._n += 1
        return self.model.predict(self._buf[: self._n].copy())

    def extend(self, frames, need_cov: bool = False):
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


def _fit_then_range(fit):
    @functools.wraps(fit)
    def wrapper(self, demos, *args, **kwargs):
        out = fit(self, demos, *args, **kwargs)
        obs = getattr(self, "observed_dofs_", None)
        if obs is not None:
            arrays, _, _ = uniform_demonstrations(demos, kwargs.get("dt", args[0] if args else None))
            self.set_input_range(fit_input_range(np.concatenate([a[:, list(obs)] for a in arrays])))
        return out

    return wrapper


def _predict_then_mark(predict):
    @functools.wraps(predict)
    def wrapper(self, partial, *args, **kwargs):
        pred = predict(self, partial, *args, **kwargs)
        if getattr(self, "input_range_", None) is not None and not np.isfinite(
                getattr(pred, "input_distance", float("nan"))):
            mark(self, pred, self.input_distance(partial))
        return pred

    return wrapper


def _checked_stream(stream):
    @functools.wraps(stream)
    def wrapper(self, *args, **kwargs):
        inner = stream(self, *args, **kwargs)
        if getattr(self, "input_range_", None) is None or isinstance(inner, CheckedStream) or inner.marks_input:
            return inner
        return CheckedStream(self, inner)

    return wrapper


class Predictor(Params):
    """Base of every model: the contract of the module docstring.

    Subclasses implement ``fit``, ``predict``, :meth:`to_state` and :meth:`load_state`, and name one fitted
    attribute in ``_FITTED``; ``STATE_VERSION`` is the version of their model-file content.

    **The out-of-range check is part of the contract.**  After ``fit``, every model knows the range of its
    training frames of the observed agent (:func:`interprim.core.input_range.fit_input_range`, kept in
    ``input_range_`` and in its model file); every prediction carries ``input_distance`` and ``out_of_range``
    (:func:`interprim.core.input_range.mark`; a stream: the largest distance of the frames seen so far) and warns
    once.  The base class adds this around a subclass's ``fit``, ``predict`` and ``stream``, unless the class does it
    itself (``_CHECKS_INPUT = True``: the Interaction Primitive, :class:`~interprim.models.auto.AutoInteraction`).
    """

    #: whether the class computes ``input_distance`` / ``out_of_range`` itself
    _CHECKS_INPUT = False
    #: ``(mean, std, limit)`` of the observed training frames (None: unknown, e.g. a member inside a blend's file)
    input_range_ = None

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        if not cls.__dict__.get("_CHECKS_INPUT", False):
            for name, wrap in (("fit", _fit_then_range), ("predict", _predict_then_mark),
                               ("stream", _checked_stream)):
                if name in cls.__dict__ and not getattr(cls.__dict__[name], "__interprim_checked__", False):
                    f = wrap(cls.__dict__[name])
                    f.__interprim_checked__ = True
                    setattr(cls, name, f)
        limit_methods(cls, ("fit", "predict"))  # one BLAS thread, the range check included (see BasePrediction)

    def set_input_range(self, input_range):
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

    def input_distance(self, frames) -> float:
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

    def _check_fitted(self, what: str):
        if not hasattr(self, self._FITTED):
            raise NotFittedError(f"this {type(self).__name__} is not fitted yet; call fit(demos) before {what}")

    def stream(self, robot_state=None) -> BaseStream:
        """Online predictor that takes one observed frame at a time (:class:`PrefixStream`)."""
        self._check_fitted("stream")
        if robot_state is not None:
            raise ValueError("robot_state: this model does not roll out from a robot state; pass None")
        return PrefixStream(self)

    def json_params(self) -> dict:
        """:meth:`get_params` (not deep) as stored in a model file (tuples as lists)."""
        import json

        return json.loads(json.dumps(self.get_params(deep=False), default=_jsonable))

    def to_state(self):  # pragma: no cover - interface
        """``(arrays, meta)``: the fitted state, numeric arrays apart and the rest JSON-friendly."""
        raise NotImplementedError

    def load_state(self, arrays: dict, meta: dict):  # pragma: no cover - interface
        """Restore the fitted state written by :meth:`to_state` (used by :func:`interprim.io.load_estimator`)."""
        raise NotImplementedError

    def save(self, path):
        """Save to a safe ``.npz`` model file (arrays + JSON metadata, no pickle); see :mod:`interprim.io`."""
        self._check_fitted("save")
        from ..io import save_estimator

        save_estimator(self, path)

    @classmethod
    def load(cls, path):
        """Load a model saved by :meth:`save`; raises :class:`~interprim.ModelFileError` on bad files."""
        from ..io import load_estimator

        return load_estimator(path, cls)


Predictor.stream = _checked_stream(Predictor.stream)  # PrefixStream of every model that has no stream of its own


def _jsonable(v):
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, np.generic):
        return v.item()
    raise TypeError(f"parameter value {v!r} cannot be stored in a model file")


class CheckedStream(BaseStream):
    """A model's stream whose predictions carry ``input_distance`` and ``out_of_range`` of every frame seen so far
    (the largest distance, :mod:`interprim.core.input_range`), warned once per stream."""

    def __init__(self, model, inner):
        self.model, self.inner = model, inner
        self._max = 0.0
        self._warned = False

    @property
    def n_frames(self) -> int:
        """Frames received since the stream was created or last reset."""
        return self.inner.n_frames

    def reset(self, robot_state=None):
        """Forget all frames (start a new interaction)."""
        self.inner.reset(robot_state)
        self._max = 0.0
        self._warned = False

    def _mark(self, pred, frames):
        d = self.model.input_distance(np.atleast_2d(np.asarray(frames, dtype=np.float64)))
        self._max = max(self._max, d) if np.isfinite(d) else d
        mark(self.model, pred, self._max, warn=not self._warned)
        self._warned = self._warned or pred.out_of_range
        return pred

    def update(self, frame, need_cov: bool = False):
        """Add one observed frame; the inner stream's prediction, marked."""
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", OutOfRangeWarning)
            pred = self.inner.update(frame, need_cov=need_cov)
        return self._mark(pred, frame)

    def extend(self, frames, need_cov: bool = False):
        """Add several frames; the inner stream's prediction for the last, marked."""
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", OutOfRangeWarning)
            pred = self.inner.extend(frames, need_cov=need_cov)
        return self._mark(pred, frames)



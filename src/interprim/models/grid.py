"""The prediction of the models that tabulate their mean and standard deviation on a normalised-time grid.

:class:`GridPrediction` is what :class:`~interprim.models.coupling.CouplingModel`,
:class:`~interprim.models.learned.LearnedInteraction` and the demonstration families return: the contract of
:class:`~interprim.models.base.BasePrediction` on a tabulated mean (and std), with the timing uncertainty of a phase
estimate added to the std on request.
"""

from __future__ import annotations

import math

import numpy as np

from ..core.blas import one_blas_thread
from ..core.preprocessing import interp_columns, unit_grid
from .base import BasePrediction

__all__ = ["GridPrediction"]


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
    std : ndarray, shape (K, D), or callable, optional
        Predictive standard deviation (kept as ``std_values``); ``None`` when the model gives no uncertainty; a
        callable returning it when computed on first read (a model fitted for its means only, e.g. in a
        cross-validation: :func:`interprim.core.cache.std_unused`).
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

    Attributes
    ----------
    neighbour : int or None
        The training demonstration the prediction replays (:class:`~interprim.models.demonstrations.NearestNeighbour`;
        ``None`` for the other models).
    weights : dict or None
        ``{training demonstration: weight}`` of a weighted mix of demonstrations
        (:class:`~interprim.models.kernel.KernelDemonstrations`; ``None`` for the other models).
    """

    neighbour: int | None = None
    weights: dict | None = None

    def __init__(self, times, mean, std=None, phase=float("nan"), phase_std=0.0, observed_dofs=None,
                 controlled_dofs=None, method=None, leverage=float("nan"), log_likelihood=float("nan"),
                 duration=float("nan"), mean_duration=float("nan"), n_observed: int = 0, timing: bool = False,
                 conditioned: bool = True):
        self.times = np.asarray(times, dtype=np.float64)
        self.mean = np.asarray(mean, dtype=np.float64)
        self.std_values = std if std is None or callable(std) else np.asarray(std, dtype=np.float64)
        D = self.mean.shape[1]
        self.phase = float(phase)
        self.normalised_time = self.phase
        self.phase_std = float(phase_std)
        self.observed_dofs = [] if observed_dofs is None else [int(i) for i in observed_dofs]
        if controlled_dofs is None:
            seen = set(self.observed_dofs)
            self.controlled_dofs = [i for i in range(D) if i not in seen]
        else:
            self.controlled_dofs = [int(i) for i in controlled_dofs]
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

    @property
    def std_values(self):
        """The predictive std on the grid, ``(K, D)`` (``None``: no uncertainty), computed on first read when the
        model gave it as a callable."""
        v = self.__dict__.get("_std_values")
        if callable(v):
            v = self.__dict__["_std_values"] = np.asarray(v(), dtype=np.float64)
        return v

    @std_values.setter
    def std_values(self, value):
        self.__dict__["_std_values"] = value

    def std_source(self):
        """What :attr:`std_values` reads: the array, ``None`` or the callable not yet called (a prediction made
        from this one passes it on without computing it)."""
        return self.__dict__["_std_values"] if "_std_values" in self.__dict__ else self.std_values

    def _at(self, Y, s, cols=None):
        return interp_columns(s, self.times, Y if cols is None else Y[:, list(cols)])

    def trajectory(self, n: int = 100) -> np.ndarray:
        """Predictive mean of all DoFs, shape ``(n, D)`` on ``linspace(0, 1, n)`` (linear interpolation)."""
        return self._at(self.mean, unit_grid(n))

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
        sd = self._at(self.std_values, unit_grid(n))
        use_timing = (self.timing and calibrated) if timing is None else bool(timing)
        if not use_timing or not self.phase > 0.0 or self.phase_std <= 0.0:
            return sd
        u = unit_grid(n)
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

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
``set_params``); its prediction is a :class:`~interprim.models.base.GridPrediction` whose ``std`` includes the
timing uncertainty.

It does not replace :class:`~interprim.models.primitive.estimator.InteractionPrimitive`: there is no DMP, no rollout from a
robot state and no streaming state here (each :meth:`predict` is a pure function of the prefix, so a stream
of predictions equals the batch ones by construction).
"""

from __future__ import annotations

import numpy as np

from ..core.blas import one_blas_thread
from ..core.validation import as_2d_finite
from .base import GridPrediction, Predictor, uniform_demonstrations
from .coupling import CouplingModel
from ..phase.learned import LearnedPhase

__all__ = ["LearnedInteraction"]


def _Prediction(cp: GridPrediction, est) -> GridPrediction:
    """``cp`` (the coupling's prediction) placed in time by the phase estimate ``est``, with the timing
    uncertainty added to its std (:meth:`~interprim.models.base.GridPrediction.std`)."""
    out = GridPrediction(cp.times, cp.mean, cp.std_values, est.phase, est.std, cp.observed_dofs, cp.controlled_dofs,
                         cp.method, cp.leverage, duration=est.duration, n_observed=cp.n_observed, timing=True,
                         conditioned=cp.conditioned)
    out.speed = float(est.speed)
    out.phase_estimate = est
    return out


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

    def __init__(self, observed_dofs, phase_kwargs=None, coupling_kwargs=None):
        self.observed_dofs = observed_dofs
        self.phase_kwargs = phase_kwargs
        self.coupling_kwargs = coupling_kwargs

    @one_blas_thread
    def fit(self, demos, dt: float | None = None):
        """Fit the timing model on the observed columns, then the coupling with the timing model's own error."""
        demos, dt, _ = uniform_demonstrations(demos, dt)
        for name in ("phase_kwargs", "coupling_kwargs"):
            v = getattr(self, name)
            if v is not None and not isinstance(v, dict):
                raise TypeError(f"{name} must be a dict or None, got {type(v).__name__}")
        obs = [int(i) for i in self.observed_dofs]
        phase = LearnedPhase(**(self.phase_kwargs or {})).fit([d[:, obs] for d in demos], dt=dt)
        coupling = CouplingModel(obs, **self._coupling_kwargs(phase)).fit(demos, dt=dt)
        self.phase_, self.coupling_, self.dt_, self.observed_dofs_ = phase, coupling, float(dt), obs
        return self

    @property
    def mean_duration_(self) -> float:
        """Mean duration of the training demonstrations in seconds (the timing model's)."""
        self._check_fitted("mean_duration_")
        return float(self.phase_.mean_duration_)

    def _coupling_kwargs(self, phase: LearnedPhase) -> dict:
        grid_t = np.arange(len(phase.std_grid_)) * float(phase.dt_)
        std_grid = np.asarray(phase.std_grid_, dtype=np.float64)
        mean_dur = float(phase.mean_duration_)

        def phase_err(s, _t=grid_t, _g=std_grid, _d=mean_dur):  # CV error of the phase at normalised time s
            return np.interp(np.asarray(s, dtype=np.float64) * _d, _t, _g)

        kw = dict(phase_std=phase_err)
        kw.update(self.coupling_kwargs or {})
        return kw

    @one_blas_thread
    def predict(self, partial) -> GridPrediction:
        """Phase of the prefix (learned), then the whole movement of both agents given it (coupling)."""
        self._check_fitted("predict")
        partial = as_2d_finite(partial, "partial", n_cols=len(self.observed_dofs_), min_rows=1)
        est = self.phase_.estimate(partial)
        s = float(np.clip(est.phase, 1e-3, 1.0))
        cp = self.coupling_.predict(partial, s, phase_std=float(est.std))
        return _Prediction(cp, est)

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
        self.dt_ = float(meta["dt_"])
        self.observed_dofs_ = [int(i) for i in meta["observed_dofs_"]]

"""A learned-timing, learned-coupling predictor for real recordings: :class:`LearnedInteraction`.

It chains the two estimators that make the human matter on recordings of people (issue: timing better than a
clock, a response better than the mean):

1. **timing** -- :class:`~interprim.phase.learned.LearnedPhase` (extends Sec. III-B): the phase and the duration
   regressed on features of the observed prefix, trained on the demonstrations' own prefixes and chosen by
   leave-one-demonstration-out CV (the clock when nothing beats it);
2. **coupling** -- :class:`~interprim.coupling.CouplingModel` (Eq. 17-18 with the observed prefix resampled on
   ``[0, s]`` as the observation): conditioning trained on prefixes taken at phases jittered by the timing
   model's *own* held-out error, so that it is robust to the phase error it will see; the mean when nothing
   beats it; calibrated predictive std.

The phase error the coupling is trained with is the learned phase's cross-validated error at each elapsed
time (``LearnedPhase.std_grid_``, as a fraction of the movement), not a guess.  The prediction has the small
interface every method of :mod:`interprim.evaluation.realtime` and :mod:`interprim.evaluation.baselines` shares: ``trajectory(n)``,
``std(n)`` on normalised time, and ``normalised_time``, ``duration``, ``phase`` for placing it in seconds.

It does not replace :class:`~interprim.primitive.InteractionPrimitive`: there is no DMP, no rollout from a
robot state and no streaming state here (each :meth:`predict` is a pure function of the prefix, so a stream
of predictions equals the batch ones by construction).
"""

from __future__ import annotations

import numpy as np

from ._blas import one_blas_thread
from .coupling import CouplingModel
from .phase.learned import LearnedPhase

__all__ = ["LearnedInteraction"]


class _Prediction:
    """A :class:`~interprim.coupling.CouplingPrediction` with the timing that placed it."""

    def __init__(self, cp, est):
        self._cp = cp
        self.phase_estimate = est
        self.normalised_time = float(est.phase)
        self.phase = float(est.phase)
        self.duration = float(est.duration)
        self.speed = float(est.speed)
        self.phase_std = float(est.std)

    def trajectory(self, n: int = 100) -> np.ndarray:
        """Mean of all DoFs on the normalised-time grid ``linspace(0, 1, n)``, shape ``(n, D)``."""
        return self._cp.trajectory(n)

    @one_blas_thread
    def std(self, n: int = 100, timing: bool = True) -> np.ndarray:
        """Predictive standard deviation of :meth:`trajectory`, shape ``(n, D)``.

        The coupling's calibrated std (:class:`~interprim.coupling.CouplingPrediction`, errors measured in
        normalised time, where timing errors do not show) combined with the timing uncertainty
        (``timing=True``): a point at normalised time ``u`` is placed in real time by the phase ``s`` and the
        duration ``D = elapsed / s``; a relative error ``e = std(s) / s`` of the phase moves it by ``u e`` to
        first order, and the position there by ``|dy/du| u e``, added in quadrature (``e`` capped at 1).
        """
        sd = self._cp.std(n)
        if not timing or self.phase <= 0.0 or self.phase_std <= 0.0:
            return sd
        u = np.linspace(0.0, 1.0, int(n))
        slope = np.gradient(self._cp.trajectory(n), u, axis=0)
        e = min(self.phase_std / self.phase, 1.0)
        return np.sqrt(sd * sd + (slope * (u * e)[:, None]) ** 2)

    def response(self, n: int = 100):
        return self._cp.response(n)

    def __repr__(self):
        return (f"LearnedInteraction prediction(phase={self.phase:.3f}, duration={self.duration:.3f} s, "
                f"coupling={self._cp.method})")


class LearnedInteraction:
    """Learned timing + learned coupling (see the module docstring).

    Parameters
    ----------
    observed_dofs : sequence of int
        Columns of the observed agent.
    phase_kwargs, coupling_kwargs : dict, optional
        Extra arguments of :class:`~interprim.phase.learned.LearnedPhase` and
        :class:`~interprim.coupling.CouplingModel`.
    """

    def __init__(self, observed_dofs, phase_kwargs=None, coupling_kwargs=None):
        self.observed_dofs = observed_dofs
        self.phase_kwargs = phase_kwargs
        self.coupling_kwargs = coupling_kwargs

    @one_blas_thread
    def fit(self, demos, dt: float | None = None):
        """Fit the timing model on the observed columns, then the coupling with the timing model's own error."""
        if hasattr(demos, "demos") and hasattr(demos, "times"):
            dt = demos.dt if dt is None else dt
            demos = list(demos.demos)
        demos = [np.asarray(d, dtype=np.float64) for d in demos]
        if dt is None:
            raise ValueError("dt (the demonstrations' sampling interval in seconds) is required")
        obs = [int(i) for i in self.observed_dofs]
        self.phase_ = LearnedPhase(**(self.phase_kwargs or {})).fit([d[:, obs] for d in demos], dt=dt)
        grid_t = np.arange(len(self.phase_.std_grid_)) * float(self.phase_.dt_)
        std_grid = np.asarray(self.phase_.std_grid_, dtype=np.float64)
        mean_dur = float(self.phase_.mean_duration_)

        def phase_err(s, _t=grid_t, _g=std_grid, _d=mean_dur):  # CV error of the phase at normalised time s
            return np.interp(np.asarray(s, dtype=np.float64) * _d, _t, _g)

        kw = dict(phase_std=phase_err)
        kw.update(self.coupling_kwargs or {})
        self.coupling_ = CouplingModel(obs, **kw).fit(demos, dt=dt)
        self.dt_ = float(dt)
        return self

    @one_blas_thread
    def predict(self, partial) -> _Prediction:
        """Phase of the prefix (learned), then the whole movement of both agents given it (coupling)."""
        est = self.phase_.estimate(partial)
        s = float(np.clip(est.phase, 1e-3, 1.0))
        cp = self.coupling_.predict(partial, s, phase_std=float(est.std))
        return _Prediction(cp, est)

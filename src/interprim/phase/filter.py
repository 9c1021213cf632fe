"""A filter over phase and phase velocity (after Bayesian Interaction Primitives), observing the likelihood of
each new frame under the demonstrations' distribution.

The state is the normalised time ``u`` in [0, 1] of the last frame and the partner's speed ``r`` relative to
the demonstrations' mean (``du/dt = r / mean_duration``), on a grid (``G`` phases x ``R`` speeds).  Each new frame

1. *predicts*: every speed column moves its phases forward by ``r dt / mean_duration``; the phase diffuses by
   ``q_phase`` (a fraction of the grid step per frame), and the speed moves to a neighbouring grid speed with
   probability ``q_speed`` (the partner may speed up or slow down within a movement);
2. *observes*: the frame's likelihood ``N(y; mu(u), kappa sigma^2(u))`` under the time-normalised demonstrations'
   mean and variance at each phase (observed agent's columns, independent), ``kappa`` inflating the variance.

The prior over the speed is the demonstrations' log-normal duration distribution; the first frame is at
``u = 0``.  ``q_phase``, ``q_speed`` and ``kappa`` are chosen by cross-validation on the demonstrations' own
prefixes (phase error), unless given.  The estimate is the posterior mean of the phase, its standard deviation,
and the duration implied by the posterior mean speed.  Batch and online are the same recursion: ``estimate`` on
a prefix equals the stream's state after its frames.
"""

from __future__ import annotations

import itertools
import math

import numpy as np

from .estimate import PhaseEstimate

__all__ = ["PhaseFilter"]

GRID = 101
SPEEDS = np.geomspace(0.6, 1.0 / 0.6, 13)
NOISE_GRID = {"q_phase": (0.0, 0.5), "q_speed": (0.0, 0.05, 0.2), "kappa": (1.0, 4.0, 16.0)}


class PhaseFilter:
    """Phase and speed of a partial movement by forward filtering on a phase x speed grid.

    Parameters
    ----------
    q_phase, q_speed, kappa : float or "cv"
        Process noise of the phase (grid steps per frame), probability per frame of a change of speed to a
        neighbouring grid speed, observation-variance inflation; ``"cv"`` chooses each among ``NOISE_GRID`` by
        cross-validation (3 folds) on the demonstrations.

    Attributes
    ----------
    mean_duration_ : float
    noise_ : dict
        The ``q_phase``, ``q_speed`` and ``kappa`` in use; ``cv_errors_`` the cross-validated phase errors.
    """

    def __init__(self, q_phase="cv", q_speed="cv", kappa="cv"):
        self.q_phase = q_phase
        self.q_speed = q_speed
        self.kappa = kappa

    # -- fitting ---------------------------------------------------------------------------------
    def fit(self, demos, dt: float):
        """Learn the phase-wise mean and variance of the observed agent from ``demos`` (``(T_j, d)`` each)."""
        arrays = [np.asarray(d, dtype=np.float64) for d in demos]
        if len(arrays) < 3:
            raise ValueError(f"PhaseFilter needs at least 3 demonstrations, got {len(arrays)}")
        if not (isinstance(dt, (int, float)) and dt > 0):
            raise ValueError(f"dt must be a positive number of seconds, got {dt!r}")
        self.dt_ = float(dt)
        self._set_model(arrays)
        fixed = {k: getattr(self, k) for k in NOISE_GRID if getattr(self, k) != "cv"}
        self.cv_errors_ = {}
        if len(fixed) == 3:
            self.noise_ = {k: float(v) for k, v in fixed.items()}
            return self
        folds = [list(range(i, len(arrays), 3)) for i in range(3)]
        combos = [dict(zip(NOISE_GRID, c)) for c in itertools.product(*NOISE_GRID.values())]
        combos = [c for c in combos if all(c[k] == v for k, v in fixed.items())]
        errs = {i: [] for i in range(len(combos))}
        for held in folds:
            train = [a for i, a in enumerate(arrays) if i not in held]
            inner = PhaseFilter(0.0, 0.0, 1.0)
            inner.dt_ = self.dt_
            inner._set_model(train)
            for i, c in enumerate(combos):
                inner.noise_ = c
                for j in held:
                    a = arrays[j]
                    T = len(a)
                    est = inner.track(a)
                    truth = np.arange(T) / (T - 1)
                    errs[i].append(np.abs(est[1:] - truth[1:]))
        scores = {i: float(np.mean(np.concatenate(e))) for i, e in errs.items()}
        best = min(scores, key=scores.get)
        self.noise_ = {k: float(v) for k, v in combos[best].items()}
        self.cv_errors_ = {tuple(c.values()): scores[i] for i, c in enumerate(combos)}
        self._set_model(arrays)
        return self

    def _set_model(self, arrays):
        from ..preprocessing import time_normalise

        Y = np.stack([time_normalise(a, GRID) for a in arrays])
        self.mu_ = Y.mean(axis=0)
        var = Y.var(axis=0)
        self.var_ = var + 1e-3 * float(np.mean(var)) + 1e-12
        dur = np.array([(len(a) - 1) * self.dt_ for a in arrays])
        self.mean_duration_ = float(dur.mean())
        logd = np.log(dur / self.mean_duration_)
        sd = max(float(np.std(logd)), 0.05)
        lp = -0.5 * ((np.log(1.0 / SPEEDS) - float(np.mean(logd))) / sd) ** 2
        self.speed_prior_ = np.exp(lp - lp.max())
        self.speed_prior_ /= self.speed_prior_.sum()

    # -- filtering -------------------------------------------------------------------------------
    def _loglik(self, y):
        return -0.5 * np.sum((y - self.mu_) ** 2 / (self.noise_["kappa"] * self.var_)
                             + np.log(self.noise_["kappa"] * self.var_), axis=1)

    def _start(self, y0):
        alpha = np.zeros((GRID, SPEEDS.size))
        alpha[0] = self.speed_prior_
        return alpha

    def _step(self, alpha, y):
        step = SPEEDS * self.dt_ / self.mean_duration_ * (GRID - 1)  # grid steps per frame, per speed
        g = np.arange(GRID, dtype=np.float64)
        new = np.empty_like(alpha)
        for r in range(SPEEDS.size):  # move each speed column forward (linear split between two cells)
            src = g - step[r]
            lo = np.floor(src).astype(int)
            w = src - lo
            col = alpha[:, r]
            a = np.where((lo >= 0) & (lo < GRID), col[np.clip(lo, 0, GRID - 1)], 0.0)
            b = np.where((lo + 1 >= 0) & (lo + 1 < GRID), col[np.clip(lo + 1, 0, GRID - 1)], 0.0)
            new[:, r] = (1 - w) * a + w * b
        # mass conservation: whatever left the grid at the end is put on the last phase
        lost = alpha.sum(axis=0) - new.sum(axis=0)
        new[-1] += np.maximum(lost, 0.0)
        q = self.noise_["q_phase"]
        if q > 0:
            qq = min(q, 0.5) / 2
            new = (1 - 2 * qq) * new + qq * np.vstack([new[1:], new[-1:]]) + qq * np.vstack([new[:1], new[:-1]])
        qs = self.noise_["q_speed"]
        if qs > 0:
            new = (1 - qs) * new + 0.5 * qs * (np.hstack([new[:, 1:], new[:, -1:]]) + np.hstack([new[:, :1], new[:, :-1]]))
        ll = self._loglik(y)
        new *= np.exp(ll - ll.max())[:, None]
        s = new.sum()
        return new / s if s > 0 else alpha

    def track(self, frames) -> np.ndarray:
        """Posterior mean phase after each frame of ``frames`` (``(T, d)``), shape ``(T,)``."""
        frames = np.asarray(frames, dtype=np.float64)
        alpha = self._start(frames[0])
        u = np.linspace(0.0, 1.0, GRID)
        out = np.empty(len(frames))
        out[0] = 0.0
        for t in range(1, len(frames)):
            alpha = self._step(alpha, frames[t])
            out[t] = float(u @ alpha.sum(axis=1))
        return out

    def estimate(self, prefix) -> PhaseEstimate:
        """Phase, speed, duration and phase std after the frames of ``prefix`` (``(M, d)``, from the start)."""
        if not hasattr(self, "noise_"):
            from ..errors import NotFittedError

            raise NotFittedError("this PhaseFilter is not fitted yet; call fit(demos, dt) first")
        v = np.asarray(prefix, dtype=np.float64)
        if v.ndim != 2 or v.shape[1] != self.mu_.shape[1] or not np.all(np.isfinite(v)) or len(v) < 1:
            raise ValueError(f"prefix must be a finite (M, {self.mu_.shape[1]}) array with M >= 1, got {v.shape}")
        alpha = self._start(v[0])
        for t in range(1, len(v)):
            alpha = self._step(alpha, v[t])
        u = np.linspace(0.0, 1.0, GRID)
        pu = alpha.sum(axis=1)
        s = float(u @ pu)
        sd = math.sqrt(max(float((u - s) ** 2 @ pu), 0.0))
        r = float(SPEEDS @ alpha.sum(axis=0))
        dur = self.mean_duration_ / r
        return PhaseEstimate(phase=s, duration=dur, speed=r, std=sd, elapsed=(len(v) - 1) * self.dt_)

"""Kernel-weighted demonstrations: every training demonstration aligned at its own matched moment.

A model-free predictor that the evaluation compares with the Interaction Primitive, and that a user's
recordings may well prefer (waving, gait, few demonstrations): for an observed prefix of ``M`` frames,

1. each training demonstration ``j`` is aligned to the prefix by open-end DTW (paper Eq. 5-8) against its
   observed agent: matched frame ``n*_j`` and length-normalised cost ``c_j = D(n*_j, M) / (n*_j + 1 + M)``;
2. weights ``w_j ∝ exp(-(c_j - min c) / (h · c_scale))``, with ``c_scale`` the median cost between training
   demonstrations and the bandwidth ``h`` chosen by leave-one-out on the training demonstrations (the
   real-time error of the controlled agent over ``horizon`` seconds) unless given;
3. each demonstration continues from its own matched frame at its own timing: the remaining movement
   ``n*_j .. T_j - 1`` of all its columns, on a common normalised remainder, averaged with the weights; the
   remaining duration is the weighted mean of the demonstrations' remaining durations.  The weighted spread,
   scaled per agent to the leave-one-out errors over the horizon, is the predictive standard deviation.

The gain over the mean demonstration comes from lining each demonstration up at its own matched moment; a
small ``h`` gives the nearest demonstration, a large one the aligned mean.
"""

from __future__ import annotations

import numpy as np

from ..core import state_checks as check
from ..core._compiled import registry as _registry
from ..core.cache import DerivedCache
from ..core.cv import DEFAULT_HORIZON
from ..core.preprocessing import unit_grid
from ..model_selection.prefixes import observed_frames
from .demonstrations import AlignedBaseline
from .grid import GridPrediction
from .training import TrainingSet

__all__ = ["KernelDemonstrations", "frames_from_padded", "weighted_frames_np"]


def frames_from_padded(padded, idx, f, cols):
    """``(len(idx), n, C)``: columns ``cols`` of the demonstrations ``idx`` of the zero-padded ``padded``
    ``(n_demos, T_max + 1, D)`` at fractional frames ``f`` ``(len(idx), n)`` within ``[0, T_j - 1]``, i.e.
    ``interp_columns(f[i], arange(T_j), demo_j[:, cols])``.

    All demonstrations at once, with :func:`numpy.interp`'s own operations on a unit grid (``y[k]`` at an integer
    ``f = k``, else ``(y[k+1] - y[k]) * (f - k) + y[k]``), so the numbers are those of one ``interp_columns`` per
    demonstration.
    """
    idx = np.asarray(idx, dtype=np.intp)
    k = np.floor(f).astype(np.intp)
    frac = f - k
    # gathered by flat row index from the padded frames (no copy of the selected demonstrations): the values of
    # padded[idx][J, k] and [J, k + 1]
    rows = padded.reshape(-1, padded.shape[2])
    flat = k + (idx * padded.shape[1])[:, None]
    lo = np.take(rows, flat, axis=0)
    hi = np.take(rows, flat + 1, axis=0)
    if not (isinstance(cols, slice) and cols == slice(None)):
        lo, hi = lo[..., cols], hi[..., cols]
    hi -= lo
    hi *= frac[..., None]
    hi += lo  # (y[k+1] - y[k]) * (f - k) + y[k]
    exact = frac == 0.0  # on a sample (also the last one, whose successor is padding)
    hi[exact] = lo[exact]
    return hi


def weighted_frames_np(padded, idx, f, cols, w, mean, spread) -> None:
    """The numpy reference of the compiled ``weighted.weighted_frames``: ``mean`` ``(n, C)`` = the ``w``-weighted
    sum over ``j`` of :func:`frames_from_padded` of ``(padded, idx, f, cols)`` (``cols`` an index array), ``spread``
    = the weighted sum of the squared differences from it (the weighted spread, not square-rooted).  On the frames'
    C-contiguous array :func:`numpy.einsum` adds the demonstrations in turn to a zero start, as the kernel does
    (with ``n C > 1``: for a single point of a single column it sums over the demonstrations in its own order)."""
    D = padded.shape[2]
    Y = frames_from_padded(padded, idx, f, slice(None))  # (J, n, D), C-contiguous
    if not (len(cols) == D and np.array_equal(cols, np.arange(D))):
        Y = np.ascontiguousarray(Y[..., cols])
    mean[...] = np.einsum("j,jkd->kd", w, Y)
    spread[...] = np.einsum("j,jkd->kd", w, (Y - mean) ** 2)

BANDWIDTHS = (0.03, 0.1, 0.3, 1.0, 3.0, 1e6)


class KernelDemonstrations(AlignedBaseline):
    """Kernel-weighted, DTW-aligned training demonstrations continued at their own timing.

    Parameters
    ----------
    observed_dofs : sequence of int
        The observed agent's columns.
    bandwidth : float or "cv", default "cv"
        ``h`` of the weights (relative to the median DTW cost between demonstrations); ``"cv"`` chooses it
        among ``BANDWIDTHS`` by leave-one-out on the training demonstrations.
    horizon : float, default 0.25
        Seconds ahead scored by the bandwidth's cross-validation.
    n : int, default 201
        Points of the normalised-time grid of a prediction.

    Attributes
    ----------
    bandwidth_ : float
        The bandwidth used.
    cv_errors_ : dict
        ``{h: mean held-out error}`` of the cross-validation (empty when ``bandwidth`` is given).
    std_scale_, std_floor_ : ndarray, shape (D,)
        Calibration of the weighted spread: ``std = sqrt((std_scale_ spread)^2 + std_floor_^2)``, per agent fitted
        to the leave-one-out errors over ``horizon`` (``bandwidth="cv"``; the raw spread otherwise).
    """

    _FITTED = "demos_"

    def __init__(self, observed_dofs, bandwidth="cv", horizon: float = DEFAULT_HORIZON, n: int = 201):
        self.observed_dofs = observed_dofs
        self.bandwidth = bandwidth
        self.horizon = horizon
        self.n = n

    # -- fitting ---------------------------------------------------------------------------------
    def _fit(self, data: TrainingSet) -> None:
        """Keep the demonstrations (at least 2; 3 for ``bandwidth="cv"``) and choose the bandwidth."""
        if not (self.bandwidth == "cv" or (isinstance(self.bandwidth, (int, float)) and self.bandwidth > 0)):
            raise ValueError(f"bandwidth must be a positive number or 'cv', got {self.bandwidth!r}")
        if not (isinstance(self.horizon, (int, float)) and self.horizon > 0):
            raise ValueError(f"horizon must be a positive number of seconds, got {self.horizon!r}")
        arrays = self._fit_common(data)
        obs = self.observed_dofs_
        D = arrays[0].shape[1]
        self.obs_ = obs
        self.ctrl_ = [i for i in range(D) if i not in set(obs)] or obs
        self.demos_ = arrays
        self._derived = DerivedCache()  # the demonstrations zero-padded (_frames_at), filled on first use
        self.observed_ = [np.ascontiguousarray(a[:, obs]) for a in arrays]
        self.cv_errors_: dict[float, float] = {}
        D = arrays[0].shape[1]
        self.std_scale_, self.std_floor_ = np.ones(D), np.zeros(D)  # the raw spread unless calibrated by "cv"
        if self.bandwidth != "cv":
            self.cost_scale_ = self._cost_scale()
            self.bandwidth_ = float(self.bandwidth)
            return
        if len(arrays) < 3:
            raise ValueError(f"bandwidth='cv' needs at least 3 demonstrations, got {len(arrays)}")
        self.cost_scale_ = self._cost_scale()
        self.bandwidth_ = self._choose_bandwidth()

    def _padded(self):
        """``(padded (n_demos, T_max + 1, D), lengths)``: the demonstrations zero-padded (one row more than the
        longest: the successor of a last sample), built once per fit or load."""
        def build():
            lengths = np.array([len(a) for a in self.demos_], dtype=np.intp)
            padded = np.zeros((len(lengths), int(lengths.max()) + 1, self.demos_[0].shape[1]))
            for j, a in enumerate(self.demos_):
                padded[j, : len(a)] = a
            return padded, lengths

        return self._derived.get_or_build("padded", (self.demos_,), build)

    def _frames_at(self, idx, f, cols):
        """``(len(idx), n, C)``: columns ``cols`` of the demonstrations ``idx`` at fractional frames ``f``
        ``(len(idx), n)`` within ``[0, T_j - 1]``, i.e. ``interp_columns(f[i], arange(T_j), demos_[j][:, cols])``
        (:func:`frames_from_padded`)."""
        return frames_from_padded(self._padded()[0], idx, f, cols)

    def _weighted(self, f, w):
        """``(mean (n, D), spread (n, D))``: the ``w``-weighted mean of every demonstration's frames at ``f``
        ``(n_demos, n)`` (:meth:`_frames_at`) and the weighted spread around it (not square-rooted):
        :func:`weighted_frames_np`, or its compiled kernel (the same numbers bit for bit) when the kernels are
        loaded."""
        padded = self._padded()[0]
        J, n, D = len(self.demos_), f.shape[1], padded.shape[2]
        idx, cols = np.arange(J, dtype=np.intp), np.arange(D, dtype=np.intp)
        mean, spread = np.empty((n, D)), np.empty((n, D))
        # (one point of one column: numpy's einsum then sums over the demonstrations in its own order)
        kernel = _registry.loaded_kernel("weighted.weighted_frames") if n * D > 1 else None
        (weighted_frames_np if kernel is None else kernel)(padded, idx, np.ascontiguousarray(f, dtype=np.float64),
                                                           cols, np.ascontiguousarray(w, dtype=np.float64), mean,
                                                           spread)
        return mean, spread

    def _cost_scale(self):
        """The median DTW cost between halves of different training demonstrations (the weights' unit)."""
        costs = []
        for i, o in enumerate(self.observed_):
            k = max(3, len(o) // 2)
            costs.extend(self._alignments(o[:k], exclude=i)[2])
        c = float(np.median(costs)) if costs else 1.0
        return c if c > 0 else 1.0

    def _weights(self, cost, h):
        z = (cost - cost.min()) / (h * self.cost_scale_)
        w = np.exp(-z)
        return w / w.sum()

    def _ahead(self, idx, n_star, w, t_ahead, cols, spread=False):
        """The weighted continuation ``t_ahead`` seconds after the matched frames, own timing, ``(H, len(cols))``
        (and, with ``spread``, the weighted spread there)."""
        rem = np.array([len(self.demos_[j]) - 1 - n for j, n in zip(idx, n_star)], dtype=np.float64)
        R = float(w @ rem) * self.dt_
        n = np.asarray(n_star)[:, None]
        T = np.array([len(self.demos_[j]) for j in idx])[:, None]
        f = n + ((t_ahead / R)[None, :] * rem[:, None] if R > 0 else (0 * t_ahead)[None, :])
        Y = self._frames_at(idx, np.minimum(f, T - 1), cols)
        mean = np.einsum("j,jhc->hc", w, Y)
        if not spread:
            return mean
        return mean, np.sqrt(np.maximum(np.einsum("j,jhc->hc", w, (Y - mean) ** 2), 0.0))

    def _calibrate(self, cases, t_ahead):
        """Calibration of the weighted spread per agent from the leave-one-out cases over the horizon:
        ``std^2 = a spread^2 + b`` with ``a, b >= 0`` fitted (non-negative least squares) to the squared errors,
        so that a prediction whose weights sit on one demonstration (no spread) keeps an honest width."""
        from scipy.optimize import nnls

        D = self.demos_[0].shape[1]
        cols = list(range(D))
        agents = [a for a in (self.obs_, [i for i in cols if i not in set(self.obs_)]) if a]
        rows = {k: ([], []) for k in range(len(agents))}
        for idx, ns, c, tr_all in cases:
            m, sd = self._ahead(idx, ns, self._weights(c, self.bandwidth_), t_ahead, cols, spread=True)
            for k, agent in enumerate(agents):
                rows[k][0].append(float(np.mean((m[:, agent] - tr_all[:, agent]) ** 2)))
                rows[k][1].append(float(np.mean(sd[:, agent] ** 2)))
        scale, floor = np.ones(D), np.zeros(D)
        for k, agent in enumerate(agents):
            e2, s2 = np.array(rows[k][0]), np.array(rows[k][1])
            (a, b), _ = nnls(np.stack([s2, np.ones_like(s2)], axis=1), e2)
            scale[agent], floor[agent] = np.sqrt(a), np.sqrt(b)
        self.std_scale_, self.std_floor_ = scale, floor

    def _choose_bandwidth(self):
        H = max(1, int(round(self.horizon / self.dt_)))
        t_ahead = np.arange(1, H + 1) * self.dt_
        cases = []
        for i, a in enumerate(self.demos_):
            T = len(a)
            for f in (0.3, 0.5, 0.7):
                k = observed_frames(T, f)
                if k >= T:
                    continue
                idx, n_star, cost = self._alignments(self.observed_[i][:k], exclude=i)
                truth = a[np.minimum(np.arange(k, k + H), T - 1)]
                cases.append((idx, n_star, cost, truth))
        for h in BANDWIDTHS:
            errs = [np.sqrt(np.mean((self._ahead(idx, ns, self._weights(c, h), t_ahead, self.ctrl_)
                                     - tr[:, self.ctrl_]) ** 2)) for idx, ns, c, tr in cases]
            self.cv_errors_[h] = float(np.mean(errs))
        self.bandwidth_ = min(self.cv_errors_, key=self.cv_errors_.get)
        self._calibrate(cases, t_ahead)
        return self.bandwidth_

    # -- prediction ------------------------------------------------------------------------------
    def to_state(self):
        """``(arrays, meta)`` of the fitted model (see :meth:`interprim.models.base.Predictor.to_state`)."""
        self._check_fitted("to_state")
        arrays = {"demos": np.concatenate(self.demos_), "lengths": np.array([len(a) for a in self.demos_]),
                  "std_scale": self.std_scale_, "std_floor": self.std_floor_}
        meta = self._common_state()
        meta.update(bandwidth_=self.bandwidth_, cost_scale_=self.cost_scale_,
                    cv_errors_=[[float(h), float(e)] for h, e in self.cv_errors_.items()])
        return arrays, meta

    def load_state(self, arrays, meta):
        """Restore the state written by :meth:`to_state`."""
        self._set_common(meta)
        D = self.n_dofs_
        demos = check.array("demos", arrays["demos"], (None, D))
        lengths = check.lengths("lengths", arrays["lengths"], demos.shape[0])
        n = check.integer("params.n", self.n, 2, check.MAX_GRID)
        # a prediction reads every demonstration at each of the n points of its grid (zero-padded to the longest)
        check.size("params.n", len(lengths) * n * D)
        check.size("lengths", len(lengths) * (int(lengths.max()) + 1) * D)
        std_scale = check.array("std_scale", arrays["std_scale"], (D,), nonneg=True)
        std_floor = check.array("std_floor", arrays["std_floor"], (D,), nonneg=True)
        bandwidth = check.number("bandwidth_", meta["bandwidth_"], positive=True)
        cost_scale = check.number("cost_scale_", meta["cost_scale_"], positive=True)
        cv = meta["cv_errors_"]
        if not isinstance(cv, list) or not all(isinstance(p, list) and len(p) == 2 for p in cv):
            check.fail("cv_errors_", cv, "not a list of [bandwidth, error] pairs")
        ends = np.cumsum(lengths)
        self.demos_ = [np.ascontiguousarray(a) for a in np.split(demos, ends[:-1])]
        self._derived = DerivedCache()
        self.obs_ = list(self.observed_dofs_)
        self.ctrl_ = [i for i in range(self.n_dofs_) if i not in set(self.obs_)] or self.obs_
        self.observed_ = [np.ascontiguousarray(a[:, self.obs_]) for a in self.demos_]
        self.std_scale_, self.std_floor_ = std_scale, std_floor
        self.bandwidth_ = bandwidth
        self.cost_scale_ = cost_scale
        self.cv_errors_ = {float(h): float(e) for h, e in cv}

    def _predict(self, partial) -> GridPrediction:  # type: ignore[override]  # only the options it names
        """Predict the whole movement of both agents from the observed prefix ``partial`` (``(M, n_obs)``).

        The prediction's ``phase`` is the fraction of the movement seen and ``duration`` the predicted total
        duration in seconds; ``trajectory(n)`` and ``std(n)`` are the weighted mean and spread of the aligned
        demonstrations on normalised time; its ``weights`` holds each training demonstration's weight (the model is
        left unchanged).
        """
        v = self._partial(partial)
        _, n_star, cost = self._alignments(v)
        return self.predict_from_alignment(v.shape[0], n_star, cost)

    def predict_from_alignment(self, M, n_star, cost) -> GridPrediction:
        """The weighted demonstrations given the prefix's alignments (steps 2 and 3 of the module docstring;
        :meth:`~interprim.models.demonstrations.AlignedBaseline.predict_from_alignment`; the prediction's
        ``weights``: ``{demonstration: weight}``)."""
        J = len(self.demos_)
        idx = range(J)
        w = self._weights(cost, self.bandwidth_)
        elapsed = (M - 1) * self.dt_
        T = self._derived.get_or_build("lengths", (self.demos_,),
                                       lambda: np.array([len(a) for a in self.demos_])[:, None])
        n = np.asarray(n_star)[:, None]
        rem = (T[:, 0] - 1 - n[:, 0]).astype(np.float64)
        R = float(w @ rem) * self.dt_
        dur = max(elapsed + R, self.dt_)
        s = elapsed / dur
        u = unit_grid(int(self.n))
        past = u <= s
        f = np.where(past, (u / max(s, 1e-12))[None, :] * n, n + ((u - s) / max(1 - s, 1e-12))[None, :] * (T - 1 - n))
        mean, spread = self._weighted(np.clip(f, 0, T - 1), w)
        spread = np.sqrt(np.maximum(spread, 0.0))
        std = np.sqrt((self.std_scale_ * spread) ** 2 + self.std_floor_ ** 2)
        pred = GridPrediction(u.copy(), mean, std, phase=s, observed_dofs=self.observed_dofs_, method="kernel",
                              duration=dur, mean_duration=self.mean_duration_, n_observed=M)
        pred.weights = dict(zip(idx, (float(x) for x in w)))
        return pred

"""Coupling between the agents learned where it is used: conditioning on a phase-uncertain prefix.

The Interaction Primitive (Ben Amor et al., ICRA 2014, Sec. III-C/D) couples the agents through one
joint Gaussian over the DMP parameters ``theta = [theta_o, theta_c]`` (Eq. 10) and conditions it on
the forcing values of the observed prefix (Eq. 15-18, with ``Omega~ = [Omega, 0]``).  On real
recordings two things break that chain: the prefix is placed in time by a phase estimate that is
often wrong by 5-10 % of the movement, and 8-30 demonstrations cannot estimate a covariance with
hundreds of rows.  Cross-validated conditioning then chooses to change nothing (issue 11).

:class:`CouplingModel` keeps the *form* of the paper's conditioning and changes its observation
model and its training distribution:

- **Observation model.**  Instead of ``F* = Omega theta`` (Eq. 14-16) the observation is the
  prefix itself, resampled at ``n_in`` points over ``[0, s]`` where ``s`` is the estimated fraction
  of the movement seen: ``x(s) = [o(0), o(s / (n_in - 1)), ..., o(s)]``.  The latent quantity is the
  whole trajectory of both agents on a normalised-time grid of ``n_out`` points, ``y`` (a ProMP
  with one basis function per grid point, the role ``theta`` plays in Eq. 10).
- **Joint Gaussian, Eq. 17 form.**  ``p(x, y) = N([mu_x; mu_y], [[S_xx, S_xy], [S_yx, S_yy]])``
  estimated from pairs ``(x_j(s'), y_j)`` of the training demonstrations, where the prefixes are
  cut at phases ``s' = s + sigma_s z_k`` jittered by the phase estimator's own error ``sigma_s``:
  the model is trained on prefixes that are misplaced in time exactly as the ones it will see.
  Conditioning on an observed prefix is Eq. 18 with ``Omega`` replaced by the selection of the
  ``x`` block and ``A = S_xx + sigma^2 I``:
  ``mu_y|x = mu_y + S_yx (S_xx + sigma^2 I)^-1 (x - mu_x)``.
  Three covariance models are offered (``methods``):

  * ``"ridge"`` - the sample covariance with the noise ``sigma^2 = lambda tr(S_xx) / p`` of Eq. 16
    acting as the regulariser (this is ridge regression from the prefix to the trajectories);
  * ``"ppca"`` - a probabilistic-PCA (reduced-rank) joint covariance ``W W^T + diag(s_x^2 I, s_y^2 I)``
    of rank ``r`` over both blocks (the paper's PCA step, Sec. IV, is the special case without
    the coupling term); conditioning reduces to a ``r x r`` solve;
  * ``"kernel"`` - a locally weighted conditioning: the demonstrations' trajectories averaged with
    Gaussian weights of the distance between their prefixes and the observed one (bandwidth
    ``b``; ``b -> inf`` is the mean, ``b -> 0`` the nearest neighbour).

  and ``"mean"``, the prior mean (no coupling), is always a candidate; ``"blend"`` averages the
  best ridge and the best kernel conditioning with a weight chosen by the same cross-validation
  (model averaging of two linear smoothers).
- **Selection.**  Method and hyper-parameter are chosen by demonstration-grouped K-fold
  cross-validation on the training data (as ``sigma2="cv"`` does for the IP): the held-out
  demonstrations' prefixes are cut at phases that differ from the phase the model is told by the
  phase error, and the error of the controlled agent's whole trajectory is scored.  The mean is
  kept unless the best candidate beats it by more than one paired standard error; then
  ``fallback_to_mean_`` is ``True`` and ``selection_["reason"]`` says so.
- **Predictive std.**  Every method predicts ``mu_y + sum_i alpha_i (y_i - mu_y)``, a linear smoother
  of the training trajectories; its parameter variance is ``h = sum_j (sum_{i in demo j}
  (alpha_i + 1/N))^2`` times the residual variance (leverage of a linear smoother, rows grouped
  by demonstration).  The residual variance ``v(s, t, d)`` is the cross-validated held-out squared
  error divided by ``1 + h`` at each CV phase (averaged over ``smooth_window`` neighbouring grid
  times, interpolated in ``s``, made non-increasing in ``s`` so that the std shrinks as more is
  observed); ``std^2 = c^2 v (1 + h)`` with a factor ``c`` per agent fitted on the held-out folds
  (jackknife: each case is standardised by a ``v`` that excludes its own demonstration; ``c`` is
  the ``coverage (1 + 1/n)`` quantile of the standardised errors, the split-conformal level for
  ``n`` exchangeable held-out demonstrations) so that the ``coverage`` band is calibrated.

Each conditioning method is one small type of :mod:`interprim.models.conditioners` (``Mean``, ``Ridge``,
``PPCA``, ``Kernel``, ``Blend``) with one interface, the row weights of a shared ``Context``; the cross-validation
scores a list of them and ``method_`` / ``param_`` name the one chosen.

Pure numpy.  References: H. Ben Amor, G. Neumann, S. Kamthe, O. Kroemer, J. Peters, "Interaction
Primitives for Human-Robot Cooperation Tasks", ICRA 2014 (Eq. 10, 16-18); M. E. Tipping and
C. M. Bishop, "Probabilistic principal component analysis", JRSS-B 1999; T. Hastie, R. Tibshirani,
J. Friedman, The Elements of Statistical Learning, Sec. 3.4.1 (ridge), 6.1 (kernel smoothers),
7.10 (cross-validation).
"""

from __future__ import annotations

import functools
import math
import numbers
from statistics import NormalDist

import numpy as np

from ..core._compiled import registry as kernels
from ..core.blas import one_blas_thread
from ..core.cache import DerivedCache, std_deferred
from ..core.cv import folds as cv_folds
from ..core.cv import n_folds as cv_n_folds
from ..core.cv import paired_gain
from ..core.errors import ModelFileError, NotFittedError
from ..core.preprocessing import column_index, unit_grid
from ..core.validation import as_2d_finite
from .conditioners import PPCA, Blend, Conditioner, Context, Kernel, Mean, Ridge, conditioner, target_block
from .grid import GridPrediction
from .training import training_set

__all__ = ["CouplingModel", "METHODS", "DEFAULT_RIDGE_GRID", "DEFAULT_RANK_GRID",
           "DEFAULT_BANDWIDTH_GRID"]

METHODS = ("mean", "ridge", "ppca", "kernel")
#: ``lambda`` candidates of ``"ridge"``: ``sigma^2 = lambda tr(S_xx) / p`` (Eq. 16's noise, relative)
DEFAULT_RIDGE_GRID = tuple(float(v) for v in 10.0 ** np.arange(-3.0, 3.01, 0.5))
#: ranks of ``"ppca"``
DEFAULT_RANK_GRID = (1, 2, 3, 4, 6, 8)
#: bandwidths of ``"kernel"``, relative to the root median squared distance of the query to the rows
DEFAULT_BANDWIDTH_GRID = (0.25, 0.35, 0.5, 0.7, 1.0, 1.5, 2.5)
#: the fractions of the movement at which the coupling is cross-validated (0.1, 0.2, ..., 1.0)
DEFAULT_FRACTIONS = tuple(float(f) for f in np.round(np.arange(0.1, 1.01, 0.1), 2))

_Z = {0.5: 0.6744897501960817, 0.8: 1.2815515655446004, 0.9: 1.6448536269514722, 0.95: 1.959963984540054}


def _normal_quantile(q: float) -> float:
    """Standard normal quantile."""
    return _Z[q] if q in _Z else NormalDist().inv_cdf(float(q))


def _jitter_nodes(k: int) -> np.ndarray:
    """``k`` equally weighted standard-normal nodes (quantiles at ``(i + 1/2) / k``), deterministic (read-only)."""
    k = int(k)
    out = _NODES.get(k)
    if out is None:
        out = np.array([NormalDist().inv_cdf((i + 0.5) / k) for i in range(k)]) if k > 1 else np.zeros(1)
        out.setflags(write=False)
        _NODES[k] = out
    return out


_NODES: dict = {}
_ZERO_IDX = np.zeros(1, dtype=np.intp)  # the one prefix of CouplingModel._query (read-only)
_ZERO_IDX.setflags(write=False)
_ONE_PHASE = np.ones(1)  # its stop: the whole prefix (read-only)
_ONE_PHASE.setflags(write=False)
_EMPTY = np.empty(0)  # an output a kernel skips


def _resample(frames, stop, n):
    """Values of ``frames`` (T, D) at ``n`` equally spaced fractional frame indices ``0 .. stop``.

    ``stop`` is a scalar or an array of shape (R,); the result is (n, D) or (R, n, D).
    """
    T = frames.shape[0]
    scalar = np.ndim(stop) == 0
    stops = np.atleast_1d(np.asarray(stop, dtype=np.float64))
    pos = np.clip(stops[:, None] * unit_grid(int(n))[None, :], 0.0, T - 1.0)  # (R, n)
    i0 = np.minimum(np.floor(pos).astype(np.intp), T - 2 if T > 1 else 0)
    w = (pos - i0)[..., None]
    i1 = np.minimum(i0 + 1, T - 1)
    out = frames[i0] * (1.0 - w) + frames[i1] * w
    return out[0] if scalar else out


def _resample_one(frames, stop, n):
    """:func:`_resample` at one scalar ``stop`` (n, D): the same operations without the batch's reshaping."""
    T = frames.shape[0]
    pos = np.minimum(np.maximum(float(stop) * unit_grid(int(n)), 0.0), T - 1.0)  # np.clip's numbers
    i0 = np.minimum(np.floor(pos).astype(np.intp), T - 2 if T > 1 else 0)
    w = (pos - i0)[:, None]
    i1 = np.minimum(i0 + 1, T - 1)
    return frames[i0] * (1.0 - w) + frames[i1] * w


def prefix_rows_np(frames, lengths, idx, s_true, lin, scale, displacement, out):
    """``out[(j, r), (k, d)]``: demonstration ``idx[j]`` (zero-padded ``frames`` ``(n, T_max, Do)``, true lengths
    ``lengths``) resampled at the fractional frames ``s_true[r] (T - 1) lin[k]`` (as :func:`_resample`), divided
    by ``scale[d]`` (minus its first point's with ``displacement``): the coupling's training rows
    (:meth:`CouplingModel._rows`), ordered by demonstration, then phase.  The numpy reference of the compiled
    ``prefix_rows.prefix_rows_into`` (the same operations per element, so the same numbers)."""
    T = lengths[idx]
    stops = s_true[None, :] * (T - 1)[:, None]  # (J, R)
    pos = np.minimum(np.maximum(stops[:, :, None] * lin[None, None, :], 0.0), (T - 1.0)[:, None, None])
    i0 = np.minimum(np.floor(pos).astype(np.intp), np.where(T > 1, T - 2, 0)[:, None, None])
    w = (pos - i0)[..., None]
    i1 = np.minimum(i0 + 1, (T - 1)[:, None, None])
    # gathered from the padded frames directly (no copy of the selected demonstrations), by flat row index
    # (np.take on the (n T_max, Do) rows: the values of frames[J, i0], in a fraction of the time)
    flat = frames.reshape(-1, frames.shape[2])
    start = (idx * frames.shape[1])[:, None, None]
    pts = np.take(flat, start + i0, axis=0)
    pts *= 1.0 - w
    right = np.take(flat, start + i1, axis=0)
    right *= w
    pts += right  # frames[J, i0] (1 - w) + frames[J, i1] w, (J, R, n_in, Do)
    x = pts / scale
    if displacement:
        x = x - x[..., :1, :]
    out[...] = x.reshape(out.shape)


def _smooth_time(v, w):
    """Moving average of ``v`` (..., n_out, D) over ``w`` neighbouring time points (axis -2)."""
    if w <= 1:
        return v
    n = v.shape[-2]
    r = int(w) // 2
    c = np.cumsum(v, axis=-2)
    c = np.concatenate([np.zeros_like(c[..., :1, :]), c], axis=-2)  # c[k] = sum of v[:k]
    hi = np.minimum(np.arange(n) + r + 1, n)
    lo = np.maximum(np.arange(n) - r, 0)
    return (c[..., hi, :] - c[..., lo, :]) / (hi - lo)[:, None]




class CouplingModel:
    """Conditioning of both agents' trajectories on a phase-uncertain prefix of the observed agent.

    See the module docstring for the model (Eq. 17-18 form with a prefix observation model).

    Parameters
    ----------
    observed_dofs : sequence of int
        Columns of the demonstrations that belong to the observed agent (the human).
    n_in : int
        Points at which the observed prefix is resampled over ``[0, s]`` (the ``x`` block).
    n_out : int
        Points of the normalised-time grid of the predicted trajectories (the ``y`` block).
    methods : sequence of str
        Candidate couplings among :data:`METHODS` (``"mean"`` is always added).
    ridge_grid, rank_grid, bandwidth_grid : sequence
        Hyper-parameter candidates of ``"ridge"`` (relative noise ``lambda``), ``"ppca"`` (rank)
        and ``"kernel"`` (relative bandwidth).
    phase_std : "clock", float or callable
        Standard deviation of the phase estimate the model will be given, as a function of the
        estimated phase ``s``: ``"clock"`` (default) is the error of a clock that assumes the mean
        duration, ``s * std(mean_T / T_j)`` over the training durations; a float is a constant;
        a callable maps ``s`` (array) to the std.  It is used to jitter the training prefixes
        and, in the cross-validation, the held-out ones; ``predict`` may override it.
    n_jitter : int
        Phases per demonstration and estimated phase (normal quantile nodes of the jitter).
    fractions : sequence of float
        Estimated phases at which the cross-validation scores the candidates and estimates the
        residual variance (the predictive std is interpolated between them).
    n_folds : int
        Folds of the demonstration-grouped cross-validation (at most the number of demos).
    coverage : float
        Nominal coverage of the band the scale factor is calibrated for (0.9: ``mean +- 1.645 std``).
    features : {"position", "displacement"}
        ``"displacement"`` subtracts the prefix's first frame (translation-invariant prefixes).
    blend_weights : sequence of float
        Weights ``w`` of the ``"blend"`` candidates ``w ridge + (1 - w) kernel`` (empty: no blends;
        only when both ``"ridge"`` and ``"kernel"`` are among ``methods``).
    smooth_window : int
        Grid times over which the residual variance is averaged (1: none).
    score : {"normalised", "raw"}
        CV loss: the controlled agent's squared error with each DoF divided by its variance
        (default; DoFs in different units weigh alike) or in the data's own units (``"raw"``: the
        error a robot makes, when all controlled DoFs share a unit).

    Attributes
    ----------
    method_ : str
        The chosen coupling (``"mean"`` when nothing beat the prior mean on held-out demos).
    param_ : float or int or None
        Its hyper-parameter.
    fallback_to_mean_ : bool
        ``True`` when the cross-validation kept the prior mean.
    selection_ : dict
        CV errors of every candidate (``"scores"``, ``"scores_by_phase"``: mean squared error of the
        controlled agent, each DoF divided by its variance), the mean's error, the paired standard
        error and a plain-language ``"reason"``.
    scale_ : dict
        Calibration factor ``c`` per agent (``"observed"``, ``"controlled"``).
    residual_var_ : ndarray, shape (len(fractions), n_out, D)
        Residual variance ``v(s, t, d)`` (non-increasing in ``s``).
    """

    def __init__(self, observed_dofs, n_in: int = 10, n_out: int = 50, methods=("ridge", "ppca", "kernel"),
                 ridge_grid=DEFAULT_RIDGE_GRID, rank_grid=DEFAULT_RANK_GRID, bandwidth_grid=DEFAULT_BANDWIDTH_GRID,
                 phase_std="clock", n_jitter: int = 5, fractions=DEFAULT_FRACTIONS,
                 n_folds: int = 10, coverage: float = 0.9, features: str = "position",
                 blend_weights=(0.25, 0.5, 0.75), smooth_window: int = 5, score: str = "normalised"):
        self.observed_dofs = observed_dofs
        self.n_in = n_in
        self.n_out = n_out
        self.methods = methods
        self.ridge_grid = ridge_grid
        self.rank_grid = rank_grid
        self.bandwidth_grid = bandwidth_grid
        self.phase_std = phase_std
        self.n_jitter = n_jitter
        self.fractions = fractions
        self.n_folds = n_folds
        self.coverage = coverage
        self.features = features
        self.blend_weights = blend_weights
        self.smooth_window = smooth_window
        self.score = score
        self._derived = DerivedCache()  # values derived from the fitted state (renewed by every fit)

    # ------------------------------------------------------------------ checks
    def _check_params(self, D):
        obs = self.observed_dofs
        if obs is None or isinstance(obs, (str, bytes)) or not hasattr(obs, "__len__"):
            raise TypeError(f"observed_dofs must be a sequence of column indices, got {obs!r}")
        obs = [int(i) for i in obs]
        if not obs or len(set(obs)) != len(obs) or min(obs) < 0 or max(obs) >= D:
            raise ValueError(f"observed_dofs must be distinct column indices in [0, {D}), got {list(obs)}")
        if len(obs) == D:
            raise ValueError(f"observed_dofs {obs} covers all {D} columns: no controlled agent is left")
        for name in ("n_in", "n_out", "n_jitter", "n_folds"):
            v = getattr(self, name)
            lo = 2 if name in ("n_in", "n_out", "n_folds") else 1
            if not isinstance(v, numbers.Integral) or v < lo:
                raise ValueError(f"{name} must be an integer >= {lo}, got {v!r}")
        methods = [self.methods] if isinstance(self.methods, str) else list(self.methods)
        bad = [m for m in methods if m not in METHODS]
        if bad:
            raise ValueError(f"methods contains unknown coupling(s) {bad}; expected a subset of {METHODS}")
        if not (isinstance(self.coverage, numbers.Real) and 0.0 < self.coverage < 1.0):
            raise ValueError(f"coverage must be in (0, 1), got {self.coverage!r}")
        if self.score not in ("normalised", "raw"):
            raise ValueError(f"score must be 'normalised' or 'raw', got {self.score!r}")
        if self.features not in ("position", "displacement"):
            raise ValueError(f"features must be 'position' or 'displacement', got {self.features!r}")
        fr = np.asarray(self.fractions, dtype=np.float64)
        if fr.ndim != 1 or fr.size < 1 or np.any(~np.isfinite(fr)) or np.any(fr <= 0) or np.any(fr > 1) \
                or np.any(np.diff(fr) <= 0):
            raise ValueError(f"fractions must be increasing numbers in (0, 1], got {self.fractions!r}")
        ps = self.phase_std
        if not (ps == "clock" or callable(ps) or (isinstance(ps, numbers.Real) and ps >= 0 and math.isfinite(ps))):
            raise ValueError(f"phase_std must be 'clock', a non-negative number or a callable, got {ps!r}")
        return obs, ["mean"] + [m for m in methods if m != "mean"], fr

    # ------------------------------------------------------------------ fit
    @one_blas_thread
    def fit(self, demos, dt=None):
        """Learn the coupling and choose method, hyper-parameter and calibration by grouped CV.

        Parameters
        ----------
        demos : TrainingSet, list of array_like, shape (T_j, D), or Demonstrations
            Demonstrations of both agents (time on axis 0, from the start of the movement to its end; at
            least 4 of at least 3 frames); lengths may differ.  Read by
            :func:`~interprim.models.training.training_set` (a :class:`~interprim.models.training.TrainingSet`
            as it is).
        dt : float, optional
            Sampling interval (s, default 0.01); only used to report durations (``mean_duration_``).

        Returns
        -------
        self
        """
        data = training_set(demos, dt)
        if len(data) < 4:
            raise ValueError(f"demos has {len(data)} demonstrations; the coupling needs at least 4 "
                             "(its cross-validation holds some out)")
        short = [j for j, a in enumerate(data.arrays) if a.shape[0] < 3]
        if short:
            raise ValueError(f"demos[{short[0]}] has {data.arrays[short[0]].shape[0]} frames, at least 3 are needed")
        arrays = list(data.arrays)
        D = data.n_dofs
        obs, methods, fr = self._check_params(D)
        ctrl = [i for i in range(D) if i not in set(obs)]
        self.observed_dofs_, self.controlled_dofs_, self.n_dofs_ = obs, ctrl, D
        self._derived = DerivedCache()  # values derived from this fit, filled on first use
        self.methods_ = methods
        self.fractions_ = fr
        n = len(arrays)
        self.n_demos_ = n
        self.obs_frames_ = [np.ascontiguousarray(a[:, obs]) for a in arrays]
        lengths = np.array([a.shape[0] for a in arrays], dtype=np.float64)
        self.durations_ = (lengths - 1) * data.dt
        rel = lengths.mean() / lengths
        self.clock_rel_std_ = float(np.std(rel - 1.0)) if n > 1 else 0.0
        from ..core.preprocessing import time_normalise

        Y = np.stack([time_normalise(a, int(self.n_out)) for a in arrays])  # (n, n_out, D)
        self.Y_ = Y
        self.y_mean_ = Y.mean(axis=0)
        sd = Y.reshape(-1, D).std(axis=0)
        self.dof_scale_ = np.where(sd > 1e-12, sd, 1.0)
        oscale = np.concatenate([a for a in self.obs_frames_]).std(axis=0)
        self.feature_scale_ = np.where(oscale > 1e-12, oscale, 1.0)
        self.mean_duration_ = float(self.durations_.mean())
        self._cross_validate()
        return self

    # ------------------------------------------------------------------ phase error model
    def _phase_std(self, s):
        ps = self.phase_std
        s = np.asarray(s, dtype=np.float64)
        if ps == "clock":
            return np.maximum(s * self.clock_rel_std_, 0.0)
        if callable(ps):
            return np.broadcast_to(np.asarray(ps(s), dtype=np.float64), s.shape).copy()
        return np.full(s.shape, float(ps))

    # ------------------------------------------------------------------ features
    def _feat(self, pts):
        """Scaled features from resampled prefix points (..., n_in, Do)."""
        x = pts / self.feature_scale_
        if self.features == "displacement":
            x = x - x[..., :1, :]
        return x.reshape(*x.shape[:-2], -1)

    def _rows(self, idx, s_hat, sig):
        """Training rows of demonstrations ``idx`` for estimated phase ``s_hat`` with error ``sig``: each
        demonstration's prefix up to every jittered phase, resampled at ``n_in`` points and scaled as the features
        (:func:`prefix_rows_np`, or its compiled kernel once the kernels are loaded: the same numbers)."""
        z = _jitter_nodes(int(self.n_jitter)) if sig > 0 else np.zeros(1)
        s_true = np.minimum(np.maximum(s_hat + sig * z, 0.02), 1.0)  # np.clip's numbers, without its overhead
        idx = np.asarray(idx, dtype=np.intp)
        Do = len(self.observed_dofs_)
        if idx.size == 0:
            return np.empty((0, int(self.n_in) * Do)), np.empty(0, dtype=np.intp)
        frames, T = self._padded_obs()
        out = np.empty((idx.size * s_true.size, int(self.n_in) * Do))
        rows = kernels.loaded_kernel("prefix_rows.prefix_rows_into") or prefix_rows_np
        rows(frames, T, idx, s_true, unit_grid(int(self.n_in)), self.feature_scale_,
             self.features == "displacement", out)
        return out, np.repeat(idx, s_true.size)

    def _padded_obs(self):
        """``(frames (n, T_max, Do), lengths (n,))``: the observed frames of the demonstrations, zero-padded
        (rebuilt when ``obs_frames_`` is replaced, by a fit or a load)."""
        def build():
            T = np.array([f.shape[0] for f in self.obs_frames_], dtype=np.intp)
            frames = np.zeros((len(T), int(T.max()), self.obs_frames_[0].shape[1]))
            for j, f in enumerate(self.obs_frames_):
                frames[j, : f.shape[0]] = f
            return frames, T

        return self._derived.get_or_build("padded", (self.obs_frames_,), build)

    # ------------------------------------------------------------------ the smoothers
    @staticmethod
    def _context(X, groups, Ydemo, x) -> Context:
        """:meth:`Context.of <interprim.models.conditioners.Context.of>` (what every candidate of one training set
        and one batch of queries shares)."""
        return Context.of(X, groups, Ydemo, x)

    @staticmethod
    def _ppca_weights(rank, ctx):
        """The row weights of :class:`~interprim.models.conditioners.PPCA` of rank ``rank`` for ``ctx`` (a
        :class:`~interprim.models.conditioners.Context` or a mapping with its fields)."""
        return PPCA(rank).weights(Context.from_mapping(ctx))

    def _candidates(self) -> list[Conditioner]:
        """The prior mean, then every hyper-parameter of every method in ``methods_`` (the order of the grids)."""
        c: list[Conditioner] = [Mean()]
        for m in self.methods_:
            if m == "ridge":
                c += [Ridge(float(v)) for v in self.ridge_grid]
            elif m == "ppca":
                c += [PPCA(int(v)) for v in self.rank_grid if int(v) <= self.n_demos_ - 2]
            elif m == "kernel":
                c += [Kernel(float(v)) for v in self.bandwidth_grid]
        return c

    # ------------------------------------------------------------------ cross-validation
    def _cv_pass(self, cands, keep):
        """One pass of the grouped CV: per-demo losses of every candidate; residuals of candidate ``keep``."""
        n, D = self.n_demos_, self.n_dofs_
        K = cv_n_folds(self.n_folds, n)
        folds = cv_folds(n, K, "interleaved")  # deterministic, demonstrations interleaved
        fr = self.fractions_
        nj = int(self.n_jitter)
        ctrl = self.controlled_dofs_
        w_ctrl = (1.0 / self.dof_scale_[ctrl] ** 2 if self.score == "normalised"
                  else np.full(len(ctrl), 1.0 / float(np.mean(self.dof_scale_[ctrl] ** 2))))
        loss = np.zeros((len(cands), len(fr), n))
        resid = np.zeros((len(fr), n, nj, self.n_out, D)) if keep is not None else None
        lev = np.zeros((len(fr), n, nj)) if keep is not None else None
        Yflat = self.Y_.reshape(n, -1)
        n_mean = np.intp(nj * int(self.n_out))  # the count np.mean divides by (jitter x output points)
        ctrl_idx = np.asarray(ctrl, dtype=np.intp)
        score = kernels.loaded_kernel("prefix_rows.cv_loss_into") or cv_loss_np
        # what depends only on the fold and the phase (training rows, held-out queries and the smoothers' shared
        # context) is computed once per fit and reused by every pass (_cross_validate makes up to three)
        cache = getattr(self, "_cv_cache", None)
        cache = {} if cache is None else cache
        for hold in folds:
            in_train = np.ones(n, dtype=bool)
            in_train[hold] = False  # the fold's training demonstrations (np.isin(g, train) of every row by a lookup)
            for a, s in enumerate(fr):
                key = (tuple(int(j) for j in hold), a)
                if key not in cache:
                    sig = float(self._phase_std(s))
                    if ("rows", a) not in cache:  # every demonstration's training rows at this phase (_rows)
                        cache["rows", a] = self._rows(np.arange(n), s, sig)
                    X_all, g_all = cache["rows", a]
                    sel = in_train[g_all]
                    X, g = X_all[sel], g_all[sel]
                    # held-out prefixes: true phases spread around the estimate s by the phase error
                    z = _jitter_nodes(nj) if sig > 0 else np.zeros(nj)
                    s_true = np.clip(s - sig * z, 0.02, 1.0)
                    xq = np.concatenate([self._feat(_resample(self.obs_frames_[j],
                                                              s_true * (self.obs_frames_[j].shape[0] - 1),
                                                              int(self.n_in))) for j in hold])
                    ctx = self._context(X, g, Yflat, xq)
                    # PPCA's target block depends on the fold's rows' grouping and demonstrations only: one per fold
                    # (and number of rows), whatever the phase (the same numbers as the context's own)
                    yk = ("ylow", key[0], ctx.R)
                    if yk not in cache:
                        cache[yk] = target_block(ctx.P, ctx.Ydc, ctx.R)
                    ctx.ylow = cache[yk]
                    cache[key] = ctx
                ctx = cache[key]
                nh = len(hold)
                if keep is not None:
                    mean, h = cands[keep].predict(ctx)
                    e = (mean - np.repeat(Yflat[hold], nj, axis=0)).reshape(nh, nj, self.n_out, D)
                    resid[a, hold] = e
                    lev[a, hold] = h.reshape(nh, nj)
                    loss[keep, a, hold] = _sq_loss(e[..., ctrl], w_ctrl, n_mean)
                others = [c for c in range(len(cands)) if c != keep]
                if not others:
                    continue
                # every other candidate's losses at once: each candidate's Conditioner._mean (its row weights summed
                # per demonstration, times the demonstrations' centred targets: the same products, one per
                # candidate) into one buffer, then the losses of _sq_loss from ybar + the products in one call
                # (cv_loss_np, or its compiled kernel once the kernels are loaded: the same numbers)
                GY = np.empty((len(others), ctx.xc.shape[0], ctx.Ydc.shape[1]))
                for i, c in enumerate(others):
                    np.matmul(cands[c].weights(ctx) @ ctx.P, ctx.Ydc, out=GY[i])
                out = np.empty((len(others), nh))
                score(GY, ctx.ybar, Yflat[hold], ctrl_idx, w_ctrl, nj, D, float(n_mean), out)
                loss[np.asarray(others)[:, None], a, np.asarray(hold)[None, :]] = out
        return loss, resid, lev, K  # loss: (candidates, fractions, demos)

    def _cross_validate(self):
        self._cv_cache = {}
        try:
            self._cross_validate_cached()
        finally:
            del self._cv_cache

    def _cross_validate_cached(self):
        cands = self._candidates()
        loss, _, _, K = self._cv_pass(cands, None)
        if "ridge" in self.methods_ and "kernel" in self.methods_ and self.blend_weights:
            # model averaging of the best ridge and the best kernel conditioning (both linear smoothers)
            sc = loss.mean(axis=(1, 2))
            br = min((i for i, c in enumerate(cands) if isinstance(c, Ridge)), key=lambda i: sc[i])
            bk = min((i for i, c in enumerate(cands) if isinstance(c, Kernel)), key=lambda i: sc[i])
            blends: list[Conditioner] = [Blend((cands[br].param, cands[bk].param, float(w)))
                                         for w in self.blend_weights]
            loss = np.concatenate([loss, self._cv_pass(blends, None)[0]])
            cands = cands + blends
        by_phase = loss.mean(axis=2)  # (candidates, fractions)
        loss = loss.mean(axis=1)  # per candidate and held-out demonstration
        scores = loss.mean(axis=1)
        best = int(np.argmin(scores))
        # the one-standard-error rule, paired over the held-out demonstrations (interprim.core.cv)
        gain, se = (float(x) for x in paired_gain(loss[0], loss[best]))
        if best == 0 or gain <= se:
            choice = 0
            reason = ("the prior mean: no coupling beat it on held-out demonstrations by more than one "
                      f"paired standard error (best {cands[best].name} {cands[best].param}: "
                      f"{scores[best] / max(scores[0], 1e-300):.3f}x the mean's error, gain {gain:.3g} <= se {se:.3g})")
        else:
            choice = best
            reason = (f"{cands[best].name} ({cands[best].param}): {scores[best] / scores[0]:.3f}x the prior mean's "
                      f"held-out error (gain {gain:.3g} > paired se {se:.3g})")
        self.method_, self.param_ = cands[choice].key
        self.fallback_to_mean_ = choice == 0
        self.selection_ = {
            "method": self.method_, "param": self.param_, "reason": reason,
            "scores": {f"{c.name}:{c.param}": float(v) for c, v in zip(cands, scores)},
            "scores_by_phase": {f"{c.name}:{c.param}": [float(x) for x in v] for c, v in zip(cands, by_phase)},
            "error_mean": float(scores[0]), "error_best": float(scores[best]), "paired_se": se,
            "n_folds": K,
        }
        if std_deferred():  # a cross-validation that reads the means only: measured when the std is first read
            self._variance_pending = cands[choice]
            return
        self._measure_variance(cands[choice])

    def _measure_variance(self, cand: Conditioner) -> None:
        """The residual variance and calibration (:meth:`_fit_variance`) of the chosen candidate ``cand`` from its
        held-out residuals (one more pass of the cross-validation)."""
        _, resid, lev, _ = self._cv_pass([cand], 0)
        self._fit_variance(resid, lev)

    def __getattr__(self, name):
        # the residual variance of a fit inside std_unused (interprim.core.cache), measured when first read: the
        # same pass on the same folds as an eager fit makes, so the same numbers
        pending = self.__dict__.get("_variance_pending") if name in ("residual_var_", "scale_") else None
        if pending is None:
            raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")
        self._cv_cache = {}
        try:
            self._measure_variance(pending)
        finally:
            del self._cv_cache
        del self._variance_pending
        return self.__dict__[name]

    def _fit_variance(self, e, h):
        """Residual variance per (phase, t, dof) and the calibration factors (jackknife over demos)."""
        # e: (F, n, nj, n_out, D); h: (F, n, nj)
        n = e.shape[1]
        e2 = e**2 / (1.0 + h)[..., None, None]
        per_demo = _smooth_time(e2.mean(axis=2), int(self.smooth_window))  # (F, n, n_out, D)
        tot = per_demo.sum(axis=1)  # (F, n_out, D)
        floor = 1e-12 * self.dof_scale_**2
        v = np.maximum(tot / n, floor)
        v = np.minimum.accumulate(v, axis=0)  # the std never grows with the phase
        self.residual_var_ = v
        # jackknife: each demo's residual standardised by the variance of the other demos
        v_jk = np.maximum((tot[:, None] - per_demo) / max(n - 1, 1), floor)  # (F, n, n_out, D)
        v_jk = np.minimum.accumulate(v_jk, axis=0)
        zabs = np.abs(e) / np.sqrt(v_jk[:, :, None] * (1.0 + h)[..., None, None])
        zc = _normal_quantile(0.5 + self.coverage / 2.0)
        self.scale_ = {}
        for name, cols in (("observed", self.observed_dofs_), ("controlled", self.controlled_dofs_)):
            zz = zabs[..., cols]
            if name == "observed":
                # only the part still to come matters for the observed agent: t > phase
                t = np.linspace(0.0, 1.0, self.n_out)
                mask = t[None, :] > self.fractions_[:, None]  # (F, n_out)
                zz = zz[np.broadcast_to(mask[:, None, None, :, None], zz.shape)]
            # the held-out demonstrations are exchangeable units: split-conformal level (1 + 1/n) coverage
            level = min(1.0, self.coverage * (1.0 + 1.0 / n))
            q = float(np.quantile(zz.ravel(), level)) if zz.size else zc
            self.scale_[name] = max(q / zc, 1e-6)

    # ------------------------------------------------------------------ predict
    @one_blas_thread
    def predict(self, partial, phase, phase_std=None, check: bool = True, timing=None) -> GridPrediction:
        """Condition on the observed prefix at an estimated phase (Eq. 18 with the prefix observation).

        Parameters
        ----------
        partial : array_like, shape (M, len(observed_dofs))
            The observed agent's frames from the start of the movement (uniformly sampled).
        phase : float
            Estimated fraction of the movement seen, in (0, 1] (the prefix covers normalised time
            ``[0, phase]``).
        phase_std : float, optional
            Standard deviation of ``phase``; default the model's ``phase_std`` at ``phase``.
            ``0`` when the phase is known.
        check : bool
            ``False``: ``partial`` is already a finite float64 array of that shape, checked by the caller (a stream
            checks each frame once, as it enters), and is not scanned again; ``phase`` and ``phase_std`` still are.
        timing : PhaseEstimate, optional
            A phase estimate (``phase``, ``std``, ``duration``) that places the prediction in time: its phase, std
            and duration are the prediction's, with the timing uncertainty added to its std
            (:meth:`~interprim.models.grid.GridPrediction.std`; what
            :class:`~interprim.models.learned.LearnedInteraction` does), while the conditioning uses ``phase`` and
            ``phase_std``.

        Returns
        -------
        GridPrediction
            Both agents' mean and std on ``n_out`` normalised times.
        """
        if not hasattr(self, "method_"):
            raise NotFittedError("this CouplingModel is not fitted yet: call fit(demos) before predict")
        Do = len(self.observed_dofs_)
        v = as_2d_finite(partial, "partial", n_cols=Do, min_rows=1) if check else partial  # one frame: not moved
        if isinstance(phase, (bool, np.bool_)) or not isinstance(phase, numbers.Real) or not math.isfinite(phase) \
                or not 0.0 < float(phase) <= 1.0:
            raise ValueError(f"phase must be a number in (0, 1] (the fraction of the movement seen), got {phase!r}")
        s = float(phase)
        if phase_std is None:
            sig = float(self._phase_std(s))
        else:
            if isinstance(phase_std, bool) or not isinstance(phase_std, numbers.Real) or not math.isfinite(phase_std) \
                    or phase_std < 0:
                raise ValueError(f"phase_std must be a non-negative number, got {phase_std!r}")
            sig = float(phase_std)
        return self._predict_prefix(v, s, sig, timing)

    def _predict_prefix(self, v, s: float, sig: float, timing=None) -> GridPrediction:
        """:meth:`predict` of a checked prefix ``v`` (M, Do) at phase ``s`` with error ``sig`` (``timing``: that of
        :meth:`predict`)."""
        # the prefix enters only through its resampled points (_resample reads n_in of its frames)
        mean, h = self._condition(self._query(v), s, sig)
        return self._grid_prediction(mean, h, s, sig, v.shape[0], timing)

    def _query(self, v) -> np.ndarray:
        """The features (1, p) of a checked prefix ``v`` (M, Do): :func:`_resample_one` at ``n_in`` points over the
        whole prefix, scaled by :meth:`_feat`; by the compiled training-rows kernel (``prefix_rows.prefix_rows_into``
        of the one prefix at phase 1, whose stop ``1.0 (M - 1)`` is the same number) once the kernels are loaded and
        ``v`` is C-contiguous (the same operations on each element, so the same numbers)."""
        rows = kernels.loaded_kernel("prefix_rows.prefix_rows_into")
        M = v.shape[0]
        if rows is None or not v.flags.c_contiguous:
            return self._feat(_resample_one(v, M - 1, int(self.n_in)))[None, :]
        out = np.empty((1, int(self.n_in) * v.shape[1]))
        rows(v.reshape(1, M, v.shape[1]), np.array([M], dtype=np.intp), _ZERO_IDX, _ONE_PHASE,
             unit_grid(int(self.n_in)), self.feature_scale_, self.features == "displacement", out)
        return out

    def _condition(self, x, s: float, sig: float):
        """Eq. 18 for one query ``x`` (1, p) at phase ``s`` with error ``sig``: mean (n_out, D) and leverage ``h``.

        The training rows ``X(s, sig)`` (:meth:`_rows`) move with the phase, so their factorisation is redone for
        every ``s``; what does not depend on ``s`` (the group indicator, the demonstrations' centred targets and
        their Gram matrix's eigenpairs) is computed once per fitted model (:meth:`_static`).
        """
        n, D = self.n_demos_, self.n_dofs_
        X, g = self._rows(np.arange(n), s, sig)
        st = self._static(X.shape[0])
        cond = self._derived.get_or_build(("conditioner", self.method_, str(self.param_)), (),
                                          lambda: conditioner(self.method_, self.param_))
        ylow = st.ylow if isinstance(cond, PPCA) else None
        centre = kernels.loaded_kernel("prefix_rows.centre_rows_into")
        if centre is not None and x.flags.c_contiguous:  # X is: _rows' fresh array
            # the centring and the sums of squares the conditioner reads, in one compiled pass (centre_rows_np's
            # numbers: those of the lines below and of the context's own sums)
            Xc, xc = np.empty_like(X), np.empty_like(x)
            norms = isinstance(cond, (Kernel, Blend))
            nrm, qnrm = (np.empty(X.shape[0]), np.empty(x.shape[0])) if norms else (_EMPTY, _EMPTY)
            tr = centre(X, x, Xc, xc, nrm, qnrm)
            ctx = Context(Xc, xc, st.P, st.ybar, st.Ydc, ylow, (tr, nrm, qnrm) if norms else (tr, None, None))
        else:
            mu = X.mean(axis=0)  # what Context.of computes, with its query-free part cached
            ctx = Context(X - mu, x - mu, st.P, st.ybar, st.Ydc, ylow)
        mean, h = cond.predict(ctx)
        return mean[0].reshape(self.n_out, D), float(h[0])

    def _static(self, R: int) -> Context:
        """The query- and phase-free part of a :class:`~interprim.models.conditioners.Context` for the rows of all
        demonstrations (``R`` of them, grouped by demonstration: ``P``, ``ybar``, ``Ydc``) and the target block of
        :class:`~interprim.models.conditioners.PPCA`'s factorisation (``ylow``, :func:`target_block`);
        kept per ``R`` in the model's :class:`~interprim.core.cache.DerivedCache` (a new one per fit or load)."""
        def build():
            n = self.n_demos_
            ctx = Context.of(np.zeros((R, 1)), np.repeat(np.arange(n), R // n), self.Y_.reshape(n, -1),
                             np.zeros((1, 1)))
            return Context(ctx.Xc, ctx.xc, ctx.P, ctx.ybar, ctx.Ydc, target_block(ctx.P, ctx.Ydc, R))

        return self._derived.get_or_build(("static", R), (self.Y_,), build)

    def _grid_prediction(self, mean, h: float, s: float, sig: float, n_observed: int,
                         timing=None) -> GridPrediction:
        """The prediction of conditioned ``mean`` and leverage ``h`` at phase ``s`` (calibrated std, Eq. 18's
        variance replaced by the cross-validated residual variance times ``1 + h``; module docstring), placed in
        time by the phase estimate ``timing`` when given (:meth:`predict`)."""
        if timing is None:
            phase, phase_std, when = s, sig, {"mean_duration": self.mean_duration_}
        else:
            phase, phase_std, when = timing.phase, timing.std, {"duration": timing.duration, "timing": True}
        return GridPrediction(unit_grid(int(self.n_out)).copy(), mean, self._std_source(h, s), phase, phase_std,
                              self.observed_dofs_, self.controlled_dofs_, self.method_, h, n_observed=n_observed,
                              conditioned=not self.fallback_to_mean_, **when)

    def _std_source(self, h: float, s: float):
        """The calibrated std at phase ``s`` with leverage ``h`` as a callable computed when first read
        (:func:`_calibrated_std`; a :class:`~interprim.models.grid.GridPrediction` takes it as its std)."""
        if "_variance_pending" in self.__dict__:  # a fit inside std_unused: its variance is measured when first read
            def std():
                return _calibrated_std(self.fractions_, self.residual_var_, self.scale_, self.observed_dofs_,
                                       self.controlled_dofs_, self.n_dofs_, s, h)
        else:  # computed when first read (a stream's caller often reads the mean only), from this fit's arrays
            std = functools.partial(_calibrated_std, self.fractions_, self.residual_var_, self.scale_,
                                    self.observed_dofs_, self.controlled_dofs_, self.n_dofs_, s, h)
        return std

    # ------------------------------------------------------------------ persistence
    _ARRAYS = ("fractions_", "durations_", "Y_", "y_mean_", "dof_scale_", "feature_scale_", "residual_var_")
    _SCALARS = ("observed_dofs_", "controlled_dofs_", "n_dofs_", "methods_", "n_demos_", "clock_rel_std_",
                "mean_duration_", "method_", "param_", "fallback_to_mean_", "selection_", "scale_")

    def to_state(self):
        """``(arrays, meta)``: the fitted state, numeric arrays apart and the rest JSON-friendly (for the model
        files of :mod:`interprim.io`; no pickle); :meth:`from_state` restores it.  A callable ``phase_std`` is
        not stored: the owner passes it again to :meth:`from_state`."""
        if not hasattr(self, "method_"):
            raise NotFittedError("this CouplingModel is not fitted yet: call fit(demos) before to_state")
        arrays = {k: getattr(self, k) for k in self._ARRAYS}
        arrays["obs_frames"] = np.concatenate(self.obs_frames_)
        arrays["obs_lengths"] = np.array([len(f) for f in self.obs_frames_])
        params = {k: v for k, v in vars(self).items() if not k.endswith("_") and not k.startswith("_")}
        if callable(params.get("phase_std")):
            params["phase_std"] = None
        meta = {"params": _plain(params), "fitted": _plain({k: getattr(self, k) for k in self._SCALARS})}
        return arrays, meta

    @classmethod
    def from_state(cls, arrays, meta, phase_std=None) -> CouplingModel:
        """The model saved by :meth:`to_state` (``phase_std``: the callable it was fitted with, if any)."""
        params = dict(meta["params"])
        if phase_std is not None:
            params["phase_std"] = phase_std
        obj = cls(**params)
        for k in cls._ARRAYS:
            setattr(obj, k, np.asarray(arrays[k]))
        fitted = meta["fitted"]
        for k in cls._SCALARS:
            setattr(obj, k, fitted[k])
        obj.methods_ = list(obj.methods_)
        if isinstance(obj.param_, list):  # a blend: (ridge, bandwidth, weight)
            obj.param_ = tuple(obj.param_)
        cls._check_state(obj, arrays)
        ends = np.cumsum(arrays["obs_lengths"])
        obj.obs_frames_ = [np.ascontiguousarray(f) for f in np.split(np.asarray(arrays["obs_frames"]), ends[:-1])]
        return obj

    def _check_state(self, arrays) -> None:
        """The values :meth:`from_state` read, checked before a prediction divides by or allocates with them
        (:mod:`interprim.core.state_checks`: ModelFileError naming the field and its value)."""
        from ..core import state_checks as check

        D = check.integer("coupling.n_dofs_", self.n_dofs_, 1, check.MAX_GRID)
        obs = check.columns("coupling.observed_dofs_", self.observed_dofs_, D)
        ctrl = check.columns("coupling.controlled_dofs_", self.controlled_dofs_, D, allow_empty=True)
        if sorted(obs + ctrl) != list(range(D)):
            check.fail("coupling.controlled_dofs_", self.controlled_dofs_,
                       f"observed_dofs_ {obs} and controlled_dofs_ do not partition the {D} columns")
        self.observed_dofs_, self.controlled_dofs_ = obs, ctrl
        S = check.integer("coupling.n_demos_", self.n_demos_, 1, check.MAX_GRID)
        n_in = check.integer("coupling.params.n_in", self.n_in, 2, check.MAX_GRID)
        n_out = check.integer("coupling.params.n_out", self.n_out, 2, check.MAX_GRID)
        check.size("coupling.params.n_in", n_in * len(obs) * S)
        check.size("coupling.params.n_out", n_out * D * S)
        self.mean_duration_ = check.number("coupling.mean_duration_", self.mean_duration_, positive=True)
        self.clock_rel_std_ = check.number("coupling.clock_rel_std_", self.clock_rel_std_, nonneg=True)
        self.fractions_ = check.array("coupling.fractions_", self.fractions_, (None,), positive=True)
        F = self.fractions_.size
        if F == 0 or np.any(self.fractions_ > 1) or np.any(np.diff(self.fractions_) <= 0):
            raise ModelFileError(f"array 'coupling.fractions_' = {self.fractions_.tolist()}: not increasing "
                                 "phases in (0, 1]")
        self.durations_ = check.array("coupling.durations_", self.durations_, (S,), positive=True)
        self.Y_ = check.array("coupling.Y_", self.Y_, (S, n_out, D))
        self.y_mean_ = check.array("coupling.y_mean_", self.y_mean_, (n_out, D))
        self.dof_scale_ = check.array("coupling.dof_scale_", self.dof_scale_, (D,), positive=True)
        self.feature_scale_ = check.array("coupling.feature_scale_", self.feature_scale_, (len(obs),), positive=True)
        self.residual_var_ = check.array("coupling.residual_var_", self.residual_var_, (F, n_out, D), nonneg=True)
        frames = check.array("coupling.obs_frames", arrays["obs_frames"], (None, len(obs)))
        check.lengths("coupling.obs_lengths", arrays["obs_lengths"], frames.shape[0], n=S)
        sc = self.scale_
        if not isinstance(sc, dict) or set(sc) != {"observed", "controlled"}:
            check.fail("coupling.scale_", sc, "not the calibration factors {'observed': ..., 'controlled': ...}")
        self.scale_ = {k: check.number(f"coupling.scale_.{k}", v, nonneg=True) for k, v in sc.items()}
        if not isinstance(self.methods_, list) or any(m not in METHODS for m in self.methods_) \
                or self.method_ not in self.methods_:
            check.fail("coupling.method_", self.method_, f"not one of the fitted methods {self.methods_!r}")


def _sq_loss(ec: np.ndarray, w_ctrl: np.ndarray, n_mean) -> np.ndarray:
    """The weighted squared error of the held-out errors ``ec`` ``(..., n_jitter, n_out, n_ctrl)``, averaged over the
    jitter and the output points (``n_mean`` of them): ``np.mean(np.sum(ec ** 2 * w_ctrl, axis=-1), axis=(-2, -1))``
    by the reductions np.sum and np.mean call (the same sums, divided by the count), without their wrappers'
    overhead; the leading axes (held-out demonstrations, candidates) are independent rows of the same sums."""
    return np.true_divide(np.add.reduce(np.add.reduce(ec ** 2 * w_ctrl, axis=-1), axis=(-2, -1)), n_mean)


def cv_loss_np(GY, ybar, truth, ctrl, w, nj: int, D: int, n_mean: float, out):
    """The held-out losses ``out`` (C, nh) of a batch of conditioners on one fold and phase of the coupling's
    cross-validation (:meth:`CouplingModel._cv_pass`): candidate ``c``'s mean is ``ybar + GY[c]`` (``GY`` (C, nh nj,
    n_out D): Eq. 18's smoother, its row weights summed per demonstration times the demonstrations' centred
    targets), case ``i``'s loss :func:`_sq_loss` of its errors against ``truth[i]`` (n_out D) in the controlled
    columns ``ctrl`` (weights ``w``) over its ``nj`` jittered queries and the output points (``n_mean`` of them).
    The numpy reference of the compiled ``prefix_rows.cv_loss_into`` (the same numbers); returns ``out``."""
    C, F = GY.shape[0], GY.shape[2]
    nh = truth.shape[0]
    n_out = F // D
    cols = column_index([int(k) for k in ctrl])
    ec = (ybar + GY).reshape(C, nh, nj, n_out, D)[..., cols] - truth.reshape(nh, 1, n_out, D)[..., cols]
    out[...] = _sq_loss(ec, w, n_mean)
    return out


def _calibrated_std(fr, residual_var, scale, observed, controlled, D: int, s: float, h: float) -> np.ndarray:
    """The calibrated std (n_out, D) at phase ``s`` with leverage ``h``: ``c sqrt(v(s) (1 + h))`` with ``v`` the
    residual variance ``residual_var`` (F, n_out, D) interpolated linearly over the CV phases ``fr`` (constant
    outside) and ``c`` the calibration factor ``scale`` of each agent (module docstring)."""
    if s <= fr[0] or fr.size == 1:
        var = residual_var[0]
    elif s >= fr[-1]:
        var = residual_var[-1]
    else:
        k = int(np.searchsorted(fr, s)) - 1
        w = (s - fr[k]) / (fr[k + 1] - fr[k])
        var = (1.0 - w) * residual_var[k] + w * residual_var[k + 1]
    c = np.ones(D)
    c[observed] = scale["observed"]
    c[controlled] = scale["controlled"]
    return c[None, :] * np.sqrt(var * (1.0 + h))


def _plain(v):
    """``v`` with tuples, numpy scalars and arrays made JSON types (lists, floats, ints)."""
    if isinstance(v, dict):
        return {str(k): _plain(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, np.generic):
        return v.item()
    return v

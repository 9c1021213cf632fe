"""Peer methods evaluated on the same splits as Interaction Primitives.

Every method follows the prediction contract of :mod:`interprim.contract` (``fit``, ``predict``, ``stream``,
``save``/``load``, ``get_params``/``set_params``), used by :mod:`interprim.evaluation.sweep`::

    est = Method(observed_dofs, ...).fit(demos, dt=...)
    out = est.predict(partial)          # partial: (M, len(observed_dofs)) frames from the start
    out.trajectory(n), out.std(n)       # (n, D) over normalised time 0..1 (std may be None)

- :class:`PriorMean` - replay the mean of the time-normalised demonstrations
  (no conditioning): the bar every method must clear.
- :class:`NearestNeighbour` - the training demonstration whose observed agent
  is nearest to the observed prefix under open-end DTW (Eq. 5-8).
- :class:`InteractionProMP` - an Interaction ProMP (Maeda et al., "Probabilistic
  movement primitives for coordination of multiple human-robot collaborative
  tasks", Autonomous Robots 2017) built from the peer packages: ProMP weights
  of every DoF by ``movement_primitives.promp.ProMP``, a Gaussian over the
  stacked weights of both agents, and conditioning on the human's DoFs with
  ``gmr.MVN.condition``; the phase (time scaling) is chosen by maximum
  likelihood of the observation over a grid of candidates.  The peer
  packages are the ``bench`` extra (``pip install "interprim[bench]"``) and are
  imported lazily.
"""

from __future__ import annotations

import numpy as np

from .._validation import as_2d_finite, as_frame, check_positive
from ..contract import BaseStream, GridPrediction, Predictor
from ..preprocessing import time_normalise

__all__ = ["PriorMean", "NearestNeighbour", "InteractionProMP", "BaselinePrediction", "AlignedStream", "AlignedBaseline"]


#: the prediction type of every method here (:class:`interprim.contract.GridPrediction`; the old name is kept)
BaselinePrediction = GridPrediction


class _Baseline(Predictor):
    """What the three methods share: the column layout, the sampling interval and the prediction's timing."""

    def _fit_common(self, demos, dt):
        if hasattr(demos, "demos") and not isinstance(demos, (list, tuple, np.ndarray)):
            dt = getattr(demos, "dt", None) if dt is None else dt
            demos = list(demos.demos)
        arrays = _check_demos(demos)
        D = arrays[0].shape[1]
        obs = self.observed_dofs
        if obs is None or isinstance(obs, (str, bytes)) or np.ndim(obs) != 1 or len(obs) == 0:
            raise TypeError(f"observed_dofs must be a non-empty sequence of column indices, got {obs!r}")
        obs = [int(i) for i in obs]
        bad = [i for i in obs if not 0 <= i < D]
        if bad or len(set(obs)) != len(obs):
            raise ValueError(f"observed_dofs {list(self.observed_dofs)} must be distinct columns of the "
                             f"{D}-column demonstrations")
        self.dt_ = 0.01 if dt is None else check_positive(dt, "dt")
        self.mean_duration_ = float(np.mean([(a.shape[0] - 1) * self.dt_ for a in arrays]))
        self.n_dofs_ = D
        self.observed_dofs_ = obs
        return arrays

    def _partial(self, partial):
        self._check_fitted("predict")
        return as_2d_finite(partial, "partial", n_cols=len(self.observed_dofs_), min_rows=1)

    def _prediction(self, times, mean, std, M, phase=float("nan"), log_likelihood=float("nan"), method=None,
                    conditioned=True):
        """A :class:`~interprim.contract.GridPrediction` with the duration ``elapsed / phase`` (the mean
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
        self.observed_dofs_ = [int(i) for i in meta["observed_dofs_"]]
        self.dt_ = float(meta["dt_"])
        self.mean_duration_ = float(meta["mean_duration_"])
        self.n_dofs_ = int(meta["n_dofs_"])


class AlignedStream(BaseStream):
    """Online prediction of a model that aligns the observed prefix to every training demonstration by open-end
    DTW (:class:`NearestNeighbour`, :class:`~interprim.evaluation.kernel.KernelDemonstrations`).

    One :class:`~interprim.phase.dtw.IncrementalDTW` per training demonstration takes each frame in ``O(N)``
    (one new column of Eq. 7) instead of re-aligning the whole prefix, and gives exactly the batch alignment;
    the model then predicts from the alignments (``model.predict_from_alignment``), so :meth:`update` returns exactly
    what ``model.predict`` returns for all frames seen, and :meth:`extend` advances the alignments by several
    frames and predicts once.  ``need_cov`` is accepted for the interface and has no effect.
    """

    def __init__(self, model):
        from ..phase.dtw import IncrementalDTW

        self.model = model
        self._n_cols = len(model.observed_dofs_)
        self._dtw = [IncrementalDTW(o) for o in model.observed_]
        self._n = 0

    @property
    def n_frames(self) -> int:
        """Number of frames received since the stream was created or last :meth:`reset`."""
        return self._n

    def reset(self, robot_state=None):
        """Forget all frames (start a new interaction)."""
        for d in self._dtw:
            d.reset()
        self._n = 0

    def _advance(self, block):
        for f in block:
            for d in self._dtw:
                d.update(f, check=False)
        self._n += block.shape[0]
        n_star = np.array([d.n_star for d in self._dtw], dtype=np.int64)
        # the batch's normalisation D(n*, M) / (n* + 1 + M), with the same scalar operations
        cost = np.array([d.cost / (d.n_star + 1 + self._n) for d in self._dtw])
        return self.model.predict_from_alignment(self._n, n_star, cost)

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


def _check_demos(demos):
    arrays = [np.asarray(d, dtype=np.float64) for d in demos]
    if len(arrays) < 2:
        raise ValueError(f"at least 2 demonstrations are needed, got {len(arrays)}")
    D = arrays[0].shape[1]
    for j, a in enumerate(arrays):
        if a.ndim != 2 or a.shape[1] != D or not np.all(np.isfinite(a)):
            raise ValueError(f"demos[{j}] must be a finite (T, {D}) array, got shape {a.shape}")
    return arrays


class AlignedBaseline(_Baseline):
    """A baseline that predicts from the open-end DTW alignments of the observed prefix to every training
    demonstration (:class:`NearestNeighbour`, :class:`~interprim.evaluation.kernel.KernelDemonstrations`): its
    :meth:`stream` advances the alignments one frame at a time (:class:`AlignedStream`) and gives exactly what
    ``predict`` gives."""

    #: ``stream()`` gives exactly what ``predict`` gives (see :func:`interprim.evaluation.realtime.realtime_fold`)
    exact_stream = True

    def stream(self, robot_state=None) -> AlignedStream:
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


class PriorMean(_Baseline):
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

    def fit(self, demos, dt=None):
        """Average the time-normalised demonstrations.

        Parameters
        ----------
        demos : list of ndarray, shape (T_j, D)
            At least 2 finite demonstrations with the same columns.
        dt : float, optional
            Sampling interval in seconds (default 0.01): the unit of the predictions' ``duration``.

        Returns
        -------
        PriorMean
            ``self``, with ``mean_`` and ``std_`` (sample std, ``ddof=1``) of shape ``(n, D)``.
        """
        arrays = self._fit_common(demos, dt)
        Y = np.stack([time_normalise(a, self.n) for a in arrays])
        self.mean_ = Y.mean(axis=0)
        self.std_ = Y.std(axis=0, ddof=1)
        return self

    def predict(self, partial) -> GridPrediction:
        """The mean demonstration whatever ``partial`` holds (no conditioning, phase NaN; ``partial`` may be
        ``None``)."""
        self._check_fitted("predict")
        M = 0 if partial is None else self._partial(partial).shape[0]
        return self._prediction(np.linspace(0.0, 1.0, self.n), self.mean_, self.std_, M,
                                method="mean", conditioned=False)

    def to_state(self):
        """``(arrays, meta)`` of the fitted model (see :meth:`interprim.contract.Predictor.to_state`)."""
        self._check_fitted("to_state")
        return {"mean": self.mean_, "std": self.std_}, self._common_state()

    def load_state(self, arrays, meta):
        """Restore the state written by :meth:`to_state`."""
        self._set_common(meta)
        self.mean_, self.std_ = arrays["mean"], arrays["std"]


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

    def fit(self, demos, dt=None):
        """Keep the demonstrations: their observed columns as DTW references, and each time-normalised.

        Parameters
        ----------
        demos : list of ndarray, shape (T_j, D)
            At least 2 finite demonstrations with the same columns.
        dt : float, optional
            Sampling interval in seconds (default 0.01): the unit of the predictions' ``duration``.

        Returns
        -------
        NearestNeighbour
            ``self``.
        """
        arrays = self._fit_common(demos, dt)
        obs = self.observed_dofs_
        self.observed_ = [np.ascontiguousarray(a[:, obs]) for a in arrays]
        self.demos_ = [time_normalise(a, self.n) for a in arrays]
        return self

    def to_state(self):
        """``(arrays, meta)`` of the fitted model (see :meth:`interprim.contract.Predictor.to_state`)."""
        self._check_fitted("to_state")
        arrays = {"observed": np.concatenate(self.observed_), "lengths": np.array([len(u) for u in self.observed_]),
                  "demos": np.stack(self.demos_)}
        return arrays, self._common_state()

    def load_state(self, arrays, meta):
        """Restore the state written by :meth:`to_state`."""
        self._set_common(meta)
        ends = np.cumsum(arrays["lengths"])
        self.observed_ = [np.ascontiguousarray(u) for u in np.split(arrays["observed"], ends[:-1])]
        self.demos_ = list(arrays["demos"])

    def predict(self, partial) -> GridPrediction:
        """The nearest demonstration to ``partial`` (``(M, len(observed_dofs))`` frames from the start).

        Sets ``neighbour_`` to its index; the prediction's phase is its matched fraction ``(n*+1)/N_j``
        and its ``std`` is ``None``.
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
        self.neighbour_ = best
        return self._prediction(np.linspace(0.0, 1.0, self.n), self.demos_[best], None, M, phase=frac,
                                method=f"demonstration {best}")


class InteractionProMP(_Baseline):
    """Interaction ProMP (Maeda et al. 2017) from ``movement_primitives`` and ``gmr``.

    Parameters
    ----------
    observed_dofs : sequence of int
    n_weights : int
        ProMP basis functions per DoF.
    sigma2 : "auto" or float
        Observation noise; ``"auto"`` is the mean squared residual of the
        ProMP fits of the observed DoFs, floored at 1e-6 of their variance.
    ridge : float
        Relative diagonal loading of the weight covariance (the sample
        covariance is singular with fewer demonstrations than weights).
    n_phases : int
        Time-scaling candidates (fraction of the movement seen, log-spaced in
        [0.02, 1]) for the maximum-likelihood phase.
    """

    def __init__(self, observed_dofs, n_weights: int = 10, sigma2="auto", ridge: float = 1e-6,
                 n_phases: int = 40):
        self.observed_dofs = observed_dofs
        self.n_weights = n_weights
        self.sigma2 = sigma2
        self.ridge = ridge
        self.n_phases = n_phases

    def _basis(self, t):
        """ProMP activations (K, len(t)) at normalised times ``t`` in [0, 1] (movement_primitives' RBFs)."""
        T = np.append(np.asarray(t, dtype=np.float64), 1.0)
        return self.promp_._rbfs_1d_sequence(T.copy())[:, :-1]

    def fit(self, demos, dt=None):
        """Fit ProMP weights to every demonstration and a Gaussian over the stacked weights of both agents.

        Parameters
        ----------
        demos : list of ndarray, shape (T_j, D)
            At least 2 finite demonstrations with the same columns; each is put on normalised time [0, 1].
        dt : float, optional
            Sampling interval in seconds (default 0.01): the unit of the predictions' ``duration``.

        Returns
        -------
        InteractionProMP
            ``self``, with ``mean_``, ``cov_`` (observed DoFs' weights first) and ``sigma2_``.

        Raises
        ------
        ImportError
            Without the ``bench`` extra (``movement_primitives``).
        """
        from movement_primitives.promp import ProMP

        arrays = self._fit_common(demos, dt)
        D = arrays[0].shape[1]
        obs = self.observed_dofs_
        ctrl = [i for i in range(D) if i not in set(obs)]
        self.order_ = obs + ctrl  # observed DoFs first in the stacked weights
        self.n_dofs_ = D
        self.promp_ = ProMP(n_dims=D, n_weights_per_dim=int(self.n_weights))
        W, res = [], []
        for a in arrays:
            t = np.linspace(0.0, 1.0, a.shape[0])
            Y = a[:, self.order_]
            w = self.promp_.weights(t, Y)
            W.append(w)
            if self.sigma2 == "auto":
                res.append(np.mean((self.promp_.trajectory_from_weights(t, w)[:, : len(obs)] - Y[:, : len(obs)]) ** 2))
        W = np.asarray(W)
        self.weights_ = W
        self.mean_ = W.mean(axis=0)
        cov = np.cov(W, rowvar=False, bias=True)
        cov[np.diag_indices_from(cov)] += self.ridge * max(float(np.mean(np.diag(cov))), 1e-300)
        self.cov_ = cov
        var_o = float(np.mean([np.var(a[:, obs]) for a in arrays]))
        self.sigma2_ = (max(float(np.mean(res)), 1e-6 * var_o) if self.sigma2 == "auto" else float(self.sigma2))
        self.n_obs_ = len(obs)
        return self

    def to_state(self):
        """``(arrays, meta)`` of the fitted model (see :meth:`interprim.contract.Predictor.to_state`); the
        ProMP basis is rebuilt from the parameters on load."""
        self._check_fitted("to_state")
        meta = self._common_state()
        meta.update(order_=[int(i) for i in self.order_], sigma2_=float(self.sigma2_), n_obs_=int(self.n_obs_))
        return {"weights": self.weights_, "mean": self.mean_, "cov": self.cov_}, meta

    def load_state(self, arrays, meta):
        """Restore the state written by :meth:`to_state`."""
        from movement_primitives.promp import ProMP

        self._set_common(meta)
        self.order_ = [int(i) for i in meta["order_"]]
        self.sigma2_, self.n_obs_ = float(meta["sigma2_"]), int(meta["n_obs_"])
        self.weights_, self.mean_, self.cov_ = arrays["weights"], arrays["mean"], arrays["cov"]
        self.promp_ = ProMP(n_dims=self.n_dofs_, n_weights_per_dim=int(self.n_weights))

    def _stats(self, partial, s):
        M = partial.shape[0]
        Psi = self._basis(np.linspace(0.0, s, M)).T  # (M, K)
        return Psi.T @ Psi, Psi.T @ partial, float(np.sum(partial**2)), partial.size

    def phase_log_likelihood(self, partial, s) -> float:
        """``log p(partial | s)`` under the weight distribution (exact, structured evaluation)."""
        from ..gaussian import condition

        K = int(self.n_weights)
        G, B, yy, n = self._stats(partial, s)
        idx = np.arange(self.n_obs_ * K).reshape(self.n_obs_, K)
        return condition(self.mean_[: self.n_obs_ * K], self.cov_[: self.n_obs_ * K, : self.n_obs_ * K], idx,
                         G, B, self.sigma2_, yy=yy, n_obs=n, need_cov=False).log_likelihood

    def predict(self, partial, phase: float | None = None) -> GridPrediction:
        """Condition on the observed prefix (phase by maximum likelihood unless given)."""
        from gmr import MVN

        v = self._partial(partial)
        M = v.shape[0]
        K = int(self.n_weights)
        if phase is None:
            grid = np.exp(np.linspace(np.log(0.02), 0.0, int(self.n_phases)))
            ll = [self.phase_log_likelihood(v, s) for s in grid]
            i = int(np.argmax(ll))
            s, best_ll = float(grid[i]), float(ll[i])
        else:
            s, best_ll = float(phase), self.phase_log_likelihood(v, float(phase))
        # compressed observation z = L w_o + noise with L^T L = Psi^T Psi (exact; see interprim.gaussian)
        G, B, _, _ = self._stats(v, s)
        e, V = np.linalg.eigh(G)
        keep = e > 1e-10 * e[-1]
        e, V = e[keep], V[:, keep]
        L = np.sqrt(e)[:, None] * V.T  # (k, K)
        zc = (V.T @ B) / np.sqrt(e)[:, None]  # (k, D_o)
        k = L.shape[0]
        no = self.n_obs_
        Lb = np.kron(np.eye(no), L)  # (no k, no K)
        P = self.mean_.shape[0]
        Om = np.zeros((no * k, P))
        Om[:, : no * K] = Lb
        # joint Gaussian of [z, w] and gmr's conditioning on the z block (the human's observed dims)
        mean = np.concatenate([Om @ self.mean_, self.mean_])
        SOt = self.cov_ @ Om.T
        cov = np.block([[Om @ SOt + self.sigma2_ * np.eye(no * k), SOt.T], [SOt, self.cov_]])
        post = MVN(mean=mean, covariance=cov).condition(np.arange(no * k), zc.T.reshape(-1))
        t = np.linspace(0.0, 1.0, 200)
        Psi = self._basis(t)  # (K, n)
        Wm = post.mean.reshape(self.n_dofs_, K)
        Y = Wm @ Psi  # (D, n)
        C = post.covariance.reshape(self.n_dofs_, K, self.n_dofs_, K)
        var = np.einsum("kt,dkdl,lt->dt", Psi, C, Psi)
        inv = np.argsort(self.order_)
        mean_traj = Y.T[:, inv]
        std = np.sqrt(np.clip(var, 0.0, None)).T[:, inv]
        return self._prediction(t, mean_traj, std, M, phase=s, log_likelihood=best_ll, method="promp")

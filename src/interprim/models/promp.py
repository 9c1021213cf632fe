"""Interaction ProMP (Maeda et al.), the peer baseline, through ``movement-primitives`` and ``gmr``.

A probabilistic movement primitive over both agents, conditioned on the observed agent's prefix at a phase found by
a grid search; the peer the evaluation compares with (extra ``[bench]``).
"""

from __future__ import annotations

import numpy as np

from ..core import state_checks as check
from .demonstrations import Baseline
from .grid import GridPrediction
from .training import TrainingSet

__all__ = ["InteractionProMP"]


class InteractionProMP(Baseline):
    """Interaction ProMP (Maeda et al. 2017) from ``movement_primitives`` and ``gmr``.

    Parameters
    ----------
    observed_dofs : sequence of int
    n_weights : int
        ProMP basis functions per DoF.
    sigma2 : "residual" or float
        Observation noise; ``"residual"`` is the mean squared residual of the
        ProMP fits of the observed DoFs, floored at 1e-6 of their variance.
    ridge : float
        Relative diagonal loading of the weight covariance (the sample
        covariance is singular with fewer demonstrations than weights).
    n_phases : int
        Time-scaling candidates (fraction of the movement seen, log-spaced in
        [0.02, 1]) for the maximum-likelihood phase.
    """

    def __init__(self, observed_dofs, n_weights: int = 10, sigma2="residual", ridge: float = 1e-6,
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

    def _fit(self, data: TrainingSet) -> None:
        """Fit ProMP weights to every demonstration (at least 2, each put on normalised time [0, 1]) and a
        Gaussian over the stacked weights of both agents: ``mean_``, ``cov_`` (observed DoFs' weights first) and
        ``sigma2_``.

        Raises
        ------
        ImportError
            Without the ``bench`` extra (``movement_primitives``).
        """
        from movement_primitives.promp import ProMP

        arrays = self._fit_common(data)
        D = arrays[0].shape[1]
        obs = self.observed_dofs_
        ctrl = [i for i in range(D) if i not in set(obs)]
        self.order_ = obs + ctrl  # observed DoFs first in the stacked weights
        self.n_dofs_ = D
        self.promp_ = ProMP(n_dims=D, n_weights_per_dim=int(self.n_weights))
        rows, res = [], []
        for a in arrays:
            t = np.linspace(0.0, 1.0, a.shape[0])
            Y = a[:, self.order_]
            w = self.promp_.weights(t, Y)
            rows.append(w)
            if self.sigma2 == "residual":
                res.append(np.mean((self.promp_.trajectory_from_weights(t, w)[:, : len(obs)] - Y[:, : len(obs)]) ** 2))
        W = np.asarray(rows)
        self.weights_ = W
        self.mean_ = W.mean(axis=0)
        cov = np.cov(W, rowvar=False, bias=True)
        cov[np.diag_indices_from(cov)] += self.ridge * max(float(np.mean(np.diag(cov))), 1e-300)
        self.cov_ = cov
        var_o = float(np.mean([np.var(a[:, obs]) for a in arrays]))
        self.sigma2_ = (max(float(np.mean(res)), 1e-6 * var_o) if self.sigma2 == "residual" else float(self.sigma2))
        self.n_obs_ = len(obs)

    def to_state(self):
        """``(arrays, meta)`` of the fitted model (see :meth:`interprim.models.base.Predictor.to_state`); the
        ProMP basis is rebuilt from the parameters on load."""
        self._check_fitted("to_state")
        meta = self._common_state()
        meta.update(order_=[int(i) for i in self.order_], sigma2_=float(self.sigma2_), n_obs_=int(self.n_obs_))
        return {"weights": self.weights_, "mean": self.mean_, "cov": self.cov_}, meta

    def load_state(self, arrays, meta):
        """Restore the state written by :meth:`to_state`."""
        from movement_primitives.promp import ProMP

        self._set_common(meta)
        D = self.n_dofs_
        self.order_ = check.columns("order_", meta["order_"], D)
        if sorted(self.order_) != list(range(D)) or self.order_[:len(self.observed_dofs_)] != self.observed_dofs_:
            check.fail("order_", meta["order_"], f"not the {D} columns with observed_dofs_ first")
        self.sigma2_ = check.number("sigma2_", meta["sigma2_"], positive=True)
        self.n_obs_ = check.integer("n_obs_", meta["n_obs_"], len(self.observed_dofs_), len(self.observed_dofs_))
        P = D * check.integer("params.n_weights", self.n_weights, 1, check.MAX_GRID)
        self.weights_ = check.array("weights", arrays["weights"], (None, P))
        self.mean_ = check.array("mean", arrays["mean"], (P,))
        self.cov_ = check.array("cov", arrays["cov"], (P, P))
        self.promp_ = ProMP(n_dims=self.n_dofs_, n_weights_per_dim=int(self.n_weights))

    def _stats(self, partial, s):
        M = partial.shape[0]
        Psi = self._basis(np.linspace(0.0, s, M)).T  # (M, K)
        return Psi.T @ Psi, Psi.T @ partial, float(np.sum(partial**2)), partial.size

    def phase_log_likelihood(self, partial, s) -> float:
        """``log p(partial | s)`` under the weight distribution (exact, structured evaluation)."""
        from ..core.gaussian import condition

        K = int(self.n_weights)
        G, B, yy, n = self._stats(partial, s)
        idx = np.arange(self.n_obs_ * K).reshape(self.n_obs_, K)
        return condition(self.mean_[: self.n_obs_ * K], self.cov_[: self.n_obs_ * K, : self.n_obs_ * K], idx,
                         G, B, self.sigma2_, yy=yy, n_obs=n, need_cov=False).log_likelihood

    def _predict(self, partial, phase: float | None = None) -> GridPrediction:  # type: ignore[override]  # only the options it names
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
        # compressed observation z = L w_o + noise with L^T L = Psi^T Psi (exact; see interprim.core.gaussian)
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

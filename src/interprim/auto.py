"""The model chosen on the user's own demonstrations: several families compared on held-out folds.

:class:`AutoInteraction` fits nothing by itself: it runs the real-time protocol of
:mod:`interprim.evaluation.realtime` in a ``folds``-fold cross-validation on the *training* demonstrations for
each candidate family -- the Interaction Primitive with the library's defaults (``ip``),
:class:`~interprim.learned.LearnedInteraction` (``learned``), the kernel-weighted demonstrations (``kernel``,
:class:`~interprim.evaluation.kernel.KernelDemonstrations`), the nearest demonstration (``nn``) and the mean
demonstration at the mean speed (``prior``) -- keeps the one with the smallest held-out error of the controlled
agent over the next ``horizon`` seconds, and fits it on all the demonstrations.  Predictions, streams and model
files are the chosen model's (the contract of :mod:`interprim.contract`); ``selection_`` says what was chosen
and by how much.

On the project's untouched hold-out (docs/evaluation.md) a choice made on 12-20 demonstrations is noisy: it
picked a worse family on one NuiSI interaction of six, and over nine tasks it was 0.66x the clock where
``ip`` alone was 0.65x and ``LearnedInteraction`` 0.63x.  It is therefore offered, not the default; compare it
with ``interprim evaluate`` on your data (its ``chosen`` row is this choice, made inside each training fold).
"""

from __future__ import annotations

import numpy as np

from ._blas import one_blas_thread
from .contract import Predictor

__all__ = ["AutoInteraction", "CANDIDATES"]

#: The families compared by default.
CANDIDATES = ("ip", "learned", "kernel", "nn", "prior")


def _classes():
    from .evaluation.baselines import NearestNeighbour, PriorMean
    from .evaluation.kernel import KernelDemonstrations
    from .learned import LearnedInteraction
    from .primitive import InteractionPrimitive

    return {c.__name__: c for c in (InteractionPrimitive, LearnedInteraction, KernelDemonstrations,
                                    NearestNeighbour, PriorMean)}


class AutoInteraction(Predictor):
    """Choose the model family by cross-validation on the training demonstrations, then use it.

    Parameters
    ----------
    observed_dofs : sequence of int
        The observed agent's columns.
    candidates : sequence of str, default CANDIDATES
        Families to compare, among ``ip``, ``learned``, ``ip-paper``, ``kernel``, ``nn``, ``prior``.
    folds : int, default 3
        Folds of the cross-validation (at least 2; fewer demonstrations than folds: leave-one-out).
    horizon : float, default 0.25
        Seconds ahead scored by the real-time protocol.
    stride : int, default 3
        Score every ``stride``-th frame (speed).
    n_basis : int, default 20
        Basis functions of the Interaction Primitive candidates.
    smoothing_window : int or None
        Savitzky-Golay window of the Interaction Primitive candidates.

    Attributes
    ----------
    chosen_ : str
        The family chosen.
    model_ : Predictor
        It, fitted on all the demonstrations.
    selection_ : dict
        ``chosen``, ``cv_errors`` (``{family: mean held-out real-time error}``, ``inf`` when a family could not be
        fitted on a fold), ``runner_up`` and ``margin`` (its error / the chosen one's), ``vs_prior`` (the chosen
        one's error / the mean demonstration's at the mean speed).
    """

    _FITTED = "model_"

    def __init__(self, observed_dofs, candidates=CANDIDATES, folds: int = 3, horizon: float = 0.25, stride: int = 3,
                 n_basis: int = 20, smoothing_window=None):
        self.observed_dofs = observed_dofs
        self.candidates = candidates
        self.folds = folds
        self.horizon = horizon
        self.stride = stride
        self.n_basis = n_basis
        self.smoothing_window = smoothing_window

    def _check(self):
        from .evaluation.realtime import default_methods

        known = default_methods([0])
        bad = [c for c in self.candidates if c not in known]
        if bad or not self.candidates:
            raise ValueError(f"candidates must name some of {sorted(known)}, got {list(self.candidates)!r}")
        if not (isinstance(self.folds, (int, np.integer)) and self.folds >= 2):
            raise ValueError(f"folds must be an integer >= 2, got {self.folds!r}")
        if not (isinstance(self.horizon, (int, float)) and self.horizon > 0):
            raise ValueError(f"horizon must be a positive number of seconds, got {self.horizon!r}")
        if not (isinstance(self.stride, (int, np.integer)) and self.stride >= 1):
            raise ValueError(f"stride must be an integer >= 1, got {self.stride!r}")

    @one_blas_thread
    def fit(self, demos, dt: float | None = None):
        """Compare the candidate families on held-out folds of ``demos``, then fit the best on all of them.

        Parameters
        ----------
        demos : list of ndarray, shape (T_j, D), or Demonstrations
            At least 3 demonstrations (a :class:`~interprim.datasets.Demonstrations` with raw samples gives the
            cross-validation causal prefixes).
        dt : float, optional
            Sampling interval in seconds (default: the Demonstrations' ``dt``, else 0.01).

        Returns
        -------
        AutoInteraction
            ``self``.
        """
        from .evaluation.realtime import RealTimeConfig, choose_method, default_methods

        self._check()
        if dt is None:
            dt = getattr(demos, "dt", None) or 0.01
        n = len(demos)
        if n < 3:
            raise ValueError(f"AutoInteraction needs at least 3 demonstrations to compare families, got {n}")
        obs = [int(i) for i in self.observed_dofs]
        make = default_methods(obs, smoothing_window=self.smoothing_window, n_basis=self.n_basis)
        make = {c: make[c] for c in self.candidates}
        cfg = RealTimeConfig(horizon=float(self.horizon), stride=int(self.stride))
        chosen, errors = choose_method(make, demos, obs, float(dt), cfg, k=min(int(self.folds), n))
        self.model_ = make[chosen]().fit([np.asarray(d, dtype=np.float64) for d in demos], dt=float(dt))
        self.chosen_ = chosen
        self.observed_dofs_ = obs
        self.selection_ = _record(chosen, errors)
        return self

    def predict(self, partial, **kwargs):
        """The chosen model's prediction (:meth:`interprim.contract.Predictor` contract)."""
        self._check_fitted("predict")
        return self.model_.predict(partial, **kwargs)

    def stream(self, robot_state=None):
        """The chosen model's online predictor."""
        self._check_fitted("stream")
        return self.model_.stream(robot_state)

    def to_state(self):
        """``(arrays, meta)``: the chosen model's state with its class and parameters."""
        self._check_fitted("to_state")
        arrays, meta = self.model_.to_state()
        return ({f"model_{k}": v for k, v in arrays.items()},
                {"chosen": self.chosen_, "class": type(self.model_).__name__, "params": self.model_.json_params(),
                 "state": meta, "selection": self.selection_, "observed_dofs_": self.observed_dofs_})

    def load_state(self, arrays, meta):
        """Restore the state written by :meth:`to_state`."""
        cls = _classes()[meta["class"]]
        inner = {k[len("model_"):]: v for k, v in arrays.items() if k.startswith("model_")}
        if hasattr(cls, "from_state"):  # the Interaction Primitive restores itself whole
            self.model_ = cls.from_state(inner, meta["state"])
        else:
            model = cls(**meta["params"])
            model.load_state(inner, meta["state"])
            self.model_ = model
        self.chosen_ = str(meta["chosen"])
        self.selection_ = dict(meta["selection"])
        self.observed_dofs_ = [int(i) for i in meta["observed_dofs_"]]

    def __repr__(self):
        if not hasattr(self, "model_"):
            return f"AutoInteraction(observed_dofs={self.observed_dofs!r}, candidates={list(self.candidates)!r})"
        s = self.selection_
        return (f"AutoInteraction(chose {self.chosen_!r}: held-out real-time error {s['margin']:.2f}x better than "
                f"{s['runner_up']!r}, {s['vs_prior']:.2f}x the mean at the mean speed)")


def _record(chosen, errors) -> dict:
    finite = {m: e for m, e in errors.items() if np.isfinite(e)}
    others = {m: e for m, e in finite.items() if m != chosen}
    runner = min(others, key=others.get) if others else None
    best = finite.get(chosen, float("nan"))
    return {"chosen": chosen, "cv_errors": {m: float(e) for m, e in errors.items()},
            "runner_up": runner, "margin": float(others[runner] / best) if runner and best > 0 else float("nan"),
            "vs_prior": float(best / finite["prior"]) if finite.get("prior", 0) > 0 else float("nan")}

"""The family comparison of the default model: candidates scored on held-out folds, then stacked per look-ahead.

Names no family: it takes ``{name: factory of an unfitted estimator}`` (any :class:`~interprim.models.base.Predictor`)
and the training demonstrations, and returns what the comparison saw and chose.

- :func:`scoring_config`: the inner cross-validation's protocol (every case scored from the next frame to the end of
  the longest training movement).
- :class:`CrossValidation`: the real-time protocol of :mod:`interprim.model_selection.realtime` in a ``k``-fold
  cross-validation for each candidate, case by case (placed predictions and truth), with the stacking solver
  (:meth:`CrossValidation.blend_weights`) and the variance model (:meth:`CrossValidation.blend_scales`).
- :func:`look_ahead_bands`, :func:`weights_at`: the look-ahead bands over which the weights are fitted and the
  weights at any look-ahead.
- :func:`stack`: the blend's weights per band, its members (those carrying :data:`MIN_WEIGHT`) and variance model;
  :func:`choice`: the best single family.

:class:`interprim.models.auto.AutoInteraction` runs them and fits the members; the assessment and the hold-out run
:class:`~interprim.models.auto.AutoInteraction`.
"""

from __future__ import annotations

from collections.abc import Callable, Collection, Iterable, Mapping, Sequence, Sized
from typing import TYPE_CHECKING, Any, cast

import numpy as np
from numpy.typing import ArrayLike

from ..core.preprocessing import column_index, interp_columns, time_normalise
from .metrics import Z90, point_rms
from .realtime import EstimatorLike, RealTimeConfig, folds, realtime_sweep
from .yardsticks import case_groups

if TYPE_CHECKING:
    from ..core.progress import Progress
    from .prefixes import Prefixes

__all__ = ["CrossValidation", "Stacking", "COMBINE", "MIN_WEIGHT", "BAND_LEVELS", "BAND_FLOOR", "look_ahead_bands",
           "variance_model", "blend_parts",
           "crossfit_coverage", "crossfit_coverages", "band_level", "band_levels",
           "weights_at", "scoring_config", "stack", "choice", "choice_record", "fold_message", "case_rms_loss",
           "simplex_minimum"]

#: How the compared families are used: a weighted blend of them (``"blend"``) or the best one alone (``"best"``).
COMBINE = ("blend", "best")

#: The smallest weight (in some look-ahead band) for which a family stays a member of the blend.
MIN_WEIGHT = 0.05

def look_ahead_bands(horizon: float, longest: float) -> np.ndarray:
    """Upper edges (s) of the look-ahead bands over which the blend's weights are fitted: ``horizon`` (the real-time
    band), then doubling, up to ``longest`` (the rest of the longest movement)."""
    edges = [float(horizon)]
    while edges[-1] < longest:
        edges.append(edges[-1] * 2.0)
    return np.array(edges)


def weights_at(ahead: ArrayLike, edges: ArrayLike, W: ArrayLike) -> np.ndarray:
    """Blend weights ``(len(ahead), families)`` at ``ahead`` seconds after now, from the weights ``W`` ``(bands,
    families)`` fitted per look-ahead band (upper edges ``edges``): linear between the bands' middles, held beyond
    the first and the last, renormalised onto the simplex (so the blend moves smoothly from the real-time weights
    to the whole-movement weights, with no jump at a band's edge)."""
    W = np.atleast_2d(np.asarray(W, dtype=np.float64))
    ahead = np.asarray(ahead, dtype=np.float64)
    if W.shape[0] == 1:
        return np.broadcast_to(W[0], (ahead.size, W.shape[1])).copy()
    edges = np.asarray(edges, dtype=np.float64)
    mids = 0.5 * (np.concatenate([[0.0], edges[:-1]]) + edges)
    out = interp_columns(ahead, mids, W)
    out = np.clip(out, 0.0, None)
    return out / np.maximum(out.sum(axis=1, keepdims=True), 1e-300)


def scoring_config(horizon: float, train: Iterable[Sized], dt: float, **kw: Any) -> RealTimeConfig:
    """The inner cross-validation's protocol: every case scored from the next frame to the end of the longest
    training movement, so that the blend's weights and variance are fitted for every look-ahead, not only for the
    real-time ``horizon`` (``kw``: other :class:`~interprim.model_selection.realtime.RealTimeConfig` fields)."""
    longest = max((len(d) - 1) * float(dt) for d in train)
    return RealTimeConfig(horizon=max(float(horizon), longest), **kw)



class Stacking:
    """What :func:`stack` fitted: the members kept and their weights per look-ahead band, and the variance model.

    Attributes
    ----------
    names : list of str
        The members (families carrying at least :data:`MIN_WEIGHT` of some band), in the cross-validation's order.
    W : ndarray, shape (bands, members)
        Their weights per band (rows on the simplex).
    edges : list of float
        Upper edges (s) of the bands.
    scales : dict or None
        The variance model ``{"a", "b", "t"}`` (:meth:`CrossValidation.blend_scales`, ``t``: seconds ahead; None
        when :func:`stack` was asked not to fit it).
    record : dict
        ``weights`` (the real-time band's), ``band_weights``, ``bands``, ``blend_cv_error`` (real-time band,
        in-sample for the weights) and ``variance_model``.
    """

    def __init__(self, names: list[str], W: np.ndarray, edges: list[float], scales: dict[str, Any] | None,
                 record: dict[str, Any]) -> None:
        self.names, self.W, self.edges, self.scales, self.record = names, W, edges, scales, record

    @property
    def band_weights(self) -> dict[str, list[float]]:
        """``{member: [weight per band]}``."""
        return self.record["band_weights"]


def stack(cv: CrossValidation, horizon: float, cost: Callable[[list[str]], float] | None = None,
          budget: float | None = None,
          scales: bool = True) -> Stacking:
    """The blend of the families compared by ``cv``: weights per look-ahead band, members and variance model.

    Weights are fitted per look-ahead band (:func:`look_ahead_bands`: ``horizon``, then doubling to the longest
    look-ahead ``cv`` scored) by :meth:`CrossValidation.blend_weights` on that band's steps; a family that never
    carries :data:`MIN_WEIGHT` of any band is dropped and the weights fitted again without it (until every member
    carries it somewhere); the variance model is fitted on every step with the weights there (:func:`weights_at`).

    With a frame budget (``cost``: a callable giving the modelled seconds a frame of a blend of the named members
    costs; ``budget``: seconds), a blend whose members cost more is not made: among the sets of families that fit
    the budget and to which no other family can be added within it, the one with the smallest sum over the bands of
    :meth:`CrossValidation.band_loss` is blended (ties: the cheaper, then the earlier in ``cv.names``).  Adding a
    family never raises a band's smallest loss, so no smaller set can do better.  The record's ``cost`` says what
    the blend costs and which families were left out for the budget.

    ``scales=False`` skips the variance model (``scales`` None; no ``variance_model``, ``band_level`` in the
    record): for a caller that fits it again after changing the weights
    (:func:`interprim.model_selection.long_range.refine`).
    """
    all_edges = look_ahead_bands(float(horizon), float(cv.t_ahead[-1]))
    steps = [s for i, s in enumerate(cv.band_steps(all_edges)) if i == 0 or cv.valid[:, s].any()]
    edges = [float(cv.t_ahead[s[-1]]) for s in steps]  # the bands with held-out frames, up to their last step
    names, W = _members(cv, cv.names, steps)
    left_out: dict[str, float] = {}
    if cost is not None and budget is not None and cost(names) > budget:
        names, W, left_out = _within_budget(cv, steps, cost, float(budget))
    sub = cv.subset(names)
    W = W / W.sum(axis=1, keepdims=True)
    per_step = weights_at(cv.t_ahead, edges, W)
    band_weights = {m: [float(x) for x in W[:, i]] for i, m in enumerate(names)}
    record: dict[str, Any] = {"weights": {m: float(W[0, i]) for i, m in enumerate(names)},
                              "band_weights": band_weights, "bands": edges, "blend_cv_error": sub.blend_error(per_step)}
    model: dict[str, Any] | None = None
    if scales:
        model = sub.blend_scales(per_step)
        record["band_level"] = model.pop("level")
        model["t"] = cv.t_ahead
        record["variance_model"] = {k: np.asarray(v).tolist() for k, v in model.items()}
    if cost is not None:
        record["cost"] = {"frame": float(cost(names)), "budget": None if budget is None else float(budget),
                          "left_out": left_out}
    return Stacking(names, W, edges, model, record)


def _members(cv: CrossValidation, names: Collection[str], steps: Sequence[np.ndarray]) -> tuple[list[str], np.ndarray]:
    """``(members, W (bands, members))``: the weights per band of the families ``names``, without those that carry
    less than :data:`MIN_WEIGHT` of every band (fitted again without them until none is left)."""
    sub = cv.subset(names)
    W = np.array([sub.blend_weights(s) for s in steps])  # (bands, families)
    while True:
        # a member that never carries MIN_WEIGHT of any band costs a stream per frame for almost nothing: the
        # weights are fitted again without it
        keep = [i for i in range(len(sub.names)) if np.max(W[:, i]) >= MIN_WEIGHT] or [
            int(np.argmax(W.max(axis=0)))]
        if len(keep) == len(sub.names):
            return list(sub.names), W
        sub = sub.subset([sub.names[i] for i in keep])
        W = np.array([sub.blend_weights(s) for s in steps])


def _within_budget(cv: CrossValidation, steps: Sequence[np.ndarray], cost: Callable[[list[str]], float],
                   budget: float) -> tuple[list[str], np.ndarray, dict[str, float]]:
    """``(members, W, left_out)`` of the best blend whose modelled frame fits ``budget`` (see :func:`stack`)."""
    from itertools import combinations

    names = list(cv.names)
    fits = [set(c) for n in range(1, len(names) + 1) for c in combinations(names, n) if cost(list(c)) <= budget]
    if not fits:  # not even one family alone: the cheapest, said so
        cheapest = min(names, key=lambda m: (cost([m]), names.index(m)))
        fits = [{cheapest}]
    maximal = [f for f in fits if not any(f < g for g in fits)]

    def score(fam: set[str]) -> float:
        sub = cv.subset([m for m in names if m in fam])
        return sum(sub.band_loss(s) for s in steps)

    best = min(maximal, key=lambda f: (score(f), cost([m for m in names if m in f]),
                                       sorted(names.index(m) for m in f)))
    chosen = [m for m in names if m in best]
    members, W = _members(cv, chosen, steps)
    left_out = {m: float(cost([m])) for m in names if m not in best}
    return members, W, left_out


def fold_message(why: str, n: int, k: int | None) -> str:
    """``why`` a family could not be fitted on an inner training fold, said of the user's data: how many of the
    ``n`` demonstrations a ``k``-fold cross-validation's smallest training fold holds, and why it is smaller."""
    sets = folds(n, k)
    n_train = n - max(len(f) for f in sets)
    return (f"{why} (in an inner training fold: the {len(sets)}-fold cross-validation trains on {n_train} of your "
            f"{n} demonstrations, holding the others out to score the family)")


class _CaseTable:
    """The compared families' records of the inner cross-validation gathered family by family into the arrays of
    :class:`CrossValidation` (``(families, cases, ...)``, the cases in sorted order): each family's records are
    copied into the arrays as soon as its sweep ends and can then be dropped, so that the fit holds one family's
    records at a time, not every family's (the placed predictions of five families on 30 demonstrations of 200
    frames: about 270 MB).  The arrays hold the records' values, as ``np.array`` of them would.

    A family whose cases or array shapes differ from the first one's keeps its records, and :meth:`arrays` then
    builds the arrays from every family's records (those of the families already copied read back from the
    arrays), on the cases all the families share."""

    #: the per-family fields of a record, in the arrays :meth:`arrays` returns
    FIELDS = ("mean", "trajectory", "phase", "duration")

    def __init__(self, n_families: int) -> None:
        self.n = int(n_families)
        self.names: list[str] = []
        self.keys: list[tuple[int, int]] | None = None  # the first family's cases, sorted
        self.buf: dict[str, np.ndarray] = {}
        self.first: dict[str, Any] = {}  # the first family's truth and fractions
        self.kept: dict[str, dict[tuple[int, int], dict[str, Any]]] = {}  # families whose records are kept

    def add(self, name: str, by: dict[tuple[int, int], dict[str, Any]]) -> None:
        """Add the family ``name``'s records ``by`` (``{(demo, k): record}``, non-empty)."""
        keys = sorted(by)
        if self.keys is None:
            self.keys = keys
            r0 = by[keys[0]]
            self.buf = {f: np.empty((self.n, len(keys)) + np.shape(r0[f])) for f in self.FIELDS}
            self.first = {"truth": np.array([by[c]["truth"] for c in keys], dtype=np.float64),
                          "fraction": [by[c]["fraction"] for c in keys]}
        slot = len(self.names) - len(self.kept)
        shapes = {f: self.buf[f].shape[2:] for f in self.FIELDS}
        if self.kept or keys != self.keys or slot >= self.n or any(
                np.shape(r[f]) != shapes[f] for r in by.values() for f in ("mean", "trajectory")):
            self.kept[name] = by
        else:
            for f in self.FIELDS:
                out = self.buf[f][slot]
                for i, c in enumerate(keys):
                    out[i] = by[c][f]
        self.names.append(name)

    def _records(self, name: str) -> dict[tuple[int, int], dict[str, Any]]:
        """The records of ``name`` (those of a copied family read back from the arrays)."""
        if name in self.kept:
            return self.kept[name]
        assert self.keys is not None  # a family was copied
        slot = self.names.index(name)  # the copied families come first
        out = {c: {f: self.buf[f][slot, i] for f in self.FIELDS} for i, c in enumerate(self.keys)}
        if slot == 0:
            for i, c in enumerate(self.keys):
                out[c].update(truth=self.first["truth"][i], fraction=self.first["fraction"][i])
        return out

    def arrays(self) -> tuple[list[tuple[int, int]], list[float], np.ndarray, dict[str, np.ndarray]]:
        """``(cases, fractions, truth, {field: (families, cases, ...)})`` over the cases every family has (sorted):
        the first family's held-out fraction seen and truth of each case, and the families' arrays of
        :data:`FIELDS`."""
        if self.keys is not None and not self.kept:  # every family copied: the arrays as they are
            m = len(self.names)
            return self.keys, self.first["fraction"], self.first["truth"], {f: self.buf[f][:m] for f in self.FIELDS}
        per = {m: self._records(m) for m in self.names}
        cases = sorted(set.intersection(*(set(per[m]) for m in self.names))) if self.names else []
        first = per[self.names[0]] if self.names else {}
        truth = np.array([first[c]["truth"] for c in cases], dtype=np.float64)
        arrays = {f: np.array([[per[m][c][f] for c in cases] for m in self.names], dtype=np.float64)
                  for f in self.FIELDS}
        return cases, [first[c]["fraction"] for c in cases], truth, arrays


#: Floats of a block of cases that :meth:`CrossValidation._gram` and :func:`blend_parts` hold at a time (about 4 MB).
_CASE_BLOCK = 1 << 19
#: The arrays of :class:`CrossValidation` with one row per family (axis 0), chosen by :meth:`CrossValidation.subset`.
_PER_FAMILY = ("mean", "traj", "phase", "duration")
#: Marks a :meth:`CrossValidation.subset`'s products as those of its parent's ``mean`` rows, not copied yet.
_LAZY = object()


def case_rms_loss(K: np.ndarray, h: np.ndarray, t: np.ndarray,
                  count: np.ndarray) -> Callable[[np.ndarray], tuple[float, np.ndarray]]:
    """The mean over cases of a blend's RMS error, and its gradient, as a function of the weights ``w`` (M,).

    Per case ``c`` the blend's squared error summed over its scored values is ``w' K_c w + 2 d (w' h_c) + d^2 t_c``
    with ``d = sum(w) - 1`` (:meth:`CrossValidation._loss`: ``K_c`` the members' error products, ``h_c`` their
    products with the truth, ``t_c`` the truth's squared sum), over ``count_c`` values.  ``K`` (cases, M, M), ``h``
    (cases, M), ``t``, ``count`` (cases,)."""
    def loss(w: np.ndarray) -> tuple[float, np.ndarray]:
        d = float(np.sum(w)) - 1.0
        Kw = K @ w
        hw = h @ w
        q = np.maximum(Kw @ w + 2.0 * d * hw + d * d * t, 0.0)
        r = np.sqrt(q / count) + 1e-12
        grad = ((Kw + d * h + (hw + d * t)[:, None]) / (r * count)[:, None]).mean(axis=0)
        return float(np.mean(r)), grad

    return loss


def simplex_minimum(loss: Callable[[np.ndarray], tuple[float, np.ndarray]], M: int) -> tuple[np.ndarray, float]:
    """``(w, loss(w))``: weights on the simplex of ``M`` members minimising ``loss`` (a convex function returning its
    value and gradient), by SLSQP from the uniform weights; weights under 1e-3 are set to 0, and the best single
    member (a vertex) is returned instead when it is no worse."""
    from scipy.optimize import minimize

    if M == 1:
        return np.ones(1), loss(np.ones(1))[0]
    start = np.full(M, 1.0 / M)
    best = min(range(M), key=lambda m: loss(np.eye(M)[m])[0])
    res = minimize(loss, start, jac=True, bounds=[(0.0, 1.0)] * M, method="SLSQP",
                   constraints=({"type": "eq", "fun": lambda w: w.sum() - 1.0},),
                   options={"ftol": 1e-10, "maxiter": 300})
    w = np.clip(res.x, 0.0, None)
    w[w < 1e-3] = 0.0
    w = w / w.sum()
    vertex = np.eye(M)[best]
    lw, lv = loss(w)[0], loss(vertex)[0]
    return (w, lw) if lw <= lv else (vertex, lv)


class CrossValidation:
    """What the inner cross-validation of :class:`AutoInteraction` saw, case by case.

    One case is one evaluated frame of one held-out training demonstration; for every family that could be
    fitted on every inner fold, the prediction of the next ``horizon`` seconds placed in time by the family's own
    timing (:func:`interprim.model_selection.realtime.place_in_time`), and the truth.

    Attributes
    ----------
    errors : dict
        ``{family: mean real-time error of the controlled agent}`` (``inf``: could not be fitted on a fold).
    names : list of str
        The families with finite errors, in the order of the arrays below.
    mean : ndarray, shape (n_families, n_cases, H, D)
        Placed predictions.
    truth : ndarray, shape (n_cases, H, D)
    controlled, observed : list of int
        Columns of the two agents.
    """

    #: ``(members,)``: the real-time weights over the members, set on the cases the long-range choice places
    #: (:func:`interprim.model_selection.long_range.candidate_cases`)
    w0: np.ndarray

    def __init__(self, make: Mapping[str, Callable[[], EstimatorLike]], demos: Prefixes | Sequence[ArrayLike],
                 observed_dofs: Iterable[int], dt: float, cfg: RealTimeConfig, k: int | None,
                 horizon: float | None = None, progress: Progress | None = None) -> None:
        import warnings

        from ..core.cache import std_unused
        from ..core.errors import OutOfRangeWarning, RepresentationWarning

        self.observed = [int(i) for i in observed_dofs]
        self.point_dim = int(cfg.point_dim)
        self.dt = float(dt)
        #: seconds of the real-time band (the protocol's look-ahead; ``cfg.horizon`` may reach further)
        self.horizon = float(cfg.horizon if horizon is None else horizon)
        self.errors: dict[str, float]
        self.errors = {}
        table = _CaseTable(len(make))  # the compared families' cases, gathered family by family
        #: ``{family: why it could not be compared}`` for the families with an infinite error
        self.why: dict[str, str] = {}
        for name, factory in make.items():
            try:
                # only the family's errors and placed means are kept: its std and the clock's records are skipped
                # std_unused: only the means are scored, so a fold's fit may skip what only its std needs
                with warnings.catch_warnings(), std_unused():  # warnings about held-out folds, not the user's data
                    warnings.simplefilter("ignore", OutOfRangeWarning)
                    warnings.simplefilter("ignore", RepresentationWarning)
                    recs = realtime_sweep({name: factory}, demos, self.observed, dt, cfg, k=k, trace=True,
                                          std=False, references=False, metrics=False)
            except ValueError as exc:  # e.g. too few demonstrations in an inner training fold for this family
                self.errors[name] = float("inf")
                self.why[name] = fold_message(str(exc).splitlines()[0], len(demos), k)
                continue
            finally:
                if progress is not None:
                    progress.step(f"compared {name}")
            by = {(r["demo"], r["k"]): r for r in recs if r["method"] == name}
            del recs
            self.errors[name] = float(np.mean([self._rt_error(r["mean"], r["truth"]) for r in by.values()])
                                      ) if by else float("inf")
            if np.isfinite(self.errors[name]):
                table.add(name, by)  # copied into the table's arrays: this family's records are dropped here
            del by
        self.names = list(table.names)
        cases, fraction, self.truth, arrays = table.arrays()
        self.mean = arrays["mean"]
        D = self.truth.shape[-1] if self.truth.size else len(self.observed)
        self.controlled = [i for i in range(D) if i not in set(self.observed)]
        H = self.truth.shape[1] if self.truth.ndim == 3 else 0
        #: seconds ahead of every step of the arrays
        self.t_ahead = np.arange(1, H + 1) * self.dt
        #: ``(cases, H)``: whether the step is a frame of the held-out movement (not past its end, where the
        #: protocol holds the last frame); the weights and the band beyond the real-time horizon are fitted on these
        n_left = np.array([int(round(c[1] / f)) - c[1] for c, f in zip(cases, fraction)], dtype=np.int64)
        self.valid = np.arange(H)[None, :] < n_left[:, None] if H else np.zeros((len(cases), 0), dtype=bool)
        self._keep_timing(arrays, cases, demos, k)

    def _keep_timing(self, arrays: dict[str, np.ndarray], cases: list[tuple[int, int]],
                     demos: Prefixes | Sequence[ArrayLike], k: int | None) -> None:
        """What the blend's long-range choice (:mod:`interprim.model_selection.long_range`) re-places: per case,
        ``demo`` (the held-out demonstration), ``elapsed`` (s), ``mean_duration`` (s, of the inner training fold),
        and per family ``traj`` (the prediction on normalised time), ``phase`` and ``duration`` (as placed)."""
        from .prefixes import Prefixes
        from .realtime import folds

        self.demo = np.array([c[0] for c in cases], dtype=np.int64)
        self.elapsed = np.array([(c[1] - 1) * self.dt for c in cases], dtype=np.float64)
        ds = (demos if isinstance(demos, Prefixes) else Prefixes(demos, self.observed)).demos
        lengths = np.array([len(d) for d in ds], dtype=np.float64)
        fold_mean: dict[int, float] = {}
        for held in folds(len(ds), k):
            rest = np.delete(lengths, held)
            fold_mean.update({j: float(np.mean(rest - 1.0)) * self.dt for j in held})
        self.mean_duration = np.array([fold_mean[j] for j in self.demo], dtype=np.float64)
        self.traj, self.phase, self.duration = arrays["trajectory"], arrays["phase"], arrays["duration"]
        #: ``{demo: (G, D)}``: each held-out demonstration on the normalised-time grid (the paper's Fig. 7 measure)
        G = self.traj.shape[2] if self.traj.ndim == 4 else 0
        self.unit_truth = {int(j): time_normalise(np.asarray(ds[j], dtype=np.float64), G) for j in set(self.demo)}

    def __getattr__(self, name: str) -> Any:
        # a per-family array of a :meth:`subset` (or :meth:`cases`) not read yet: its families' rows (its cases) of
        # the parent's array, copied on first use (a subset whose only use is the stacking solver, which reads the
        # shared products, copies none)
        lazy = self.__dict__.get("_lazy")
        if not lazy or name not in lazy:
            raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")
        src, keep = lazy.pop(name)
        value = src[keep]
        self.__dict__[name] = value
        g = self.__dict__.get("_gram_cache")
        if name == "mean" and g is not None and g["mean"] is _LAZY:
            g["mean"] = value
        return value

    def _family_source(self, name: str) -> tuple[np.ndarray | None, np.ndarray | None]:
        """``(array, rows)``: where this object's per-family array ``name`` is (``rows`` None: the array itself,
        else the rows of a parent's array not copied yet); ``(None, None)`` when it has none."""
        if name in self.__dict__:
            return self.__dict__[name], None
        lazy = self.__dict__.get("_lazy") or {}
        if isinstance(lazy.get(name, (None, None))[1], tuple):  # cases of a parent's array (cases): copied now
            return getattr(self, name), None
        return lazy.get(name, (None, None))

    def family_array(self, field: str, i: int) -> np.ndarray:
        """Family ``i``'s rows (of :attr:`names`) of the per-family array ``field`` (``"traj"``, ``"mean"``, ...): a
        view of the array a :meth:`subset` reads them from while it has not copied its own (the same values, without
        a copy of every family's rows)."""
        src, rows = self._family_source(field)
        if src is None:
            return getattr(self, field)[i]
        return src[i] if rows is None else src[rows[i]]

    def cases(self, idx: ArrayLike) -> CrossValidation:
        """The same families restricted to the cases ``idx``."""
        idx = np.asarray(idx)
        out = object.__new__(type(self))
        out.__dict__.update(self.__dict__)
        out.__dict__.pop("_lazy", None)
        for a in ("truth", "valid", "demo", "elapsed", "mean_duration"):
            if hasattr(self, a):
                setattr(out, a, getattr(self, a)[idx])
        lazy: dict[str, tuple[np.ndarray, tuple[Any, ...]]] = {}
        for a in _PER_FAMILY:  # copied when first read (__getattr__; the long-range choice's folds read none)
            src, rows = self._family_source(a)
            out.__dict__.pop(a, None)
            if src is not None:
                lazy[a] = (src, (slice(None), idx) if rows is None else np.ix_(rows, idx))
        out.__dict__["_lazy"] = lazy
        g = self._gram()  # the cases' products, shared (not copied): only their rows are chosen
        out.__dict__["_gram_cache"] = dict(g, mean=_LAZY, truth=out.truth, rows=g["rows"][idx])
        return out

    def _rt_error(self, mean: ArrayLike, truth: ArrayLike) -> float:
        """Real-time error of one case: RMS point error of the controlled agent over the real-time band."""
        n = max(1, int(round(self.horizon / self.dt)))
        mean, truth = np.asarray(mean), np.asarray(truth)
        cols = self.controlled_cols(truth.shape[-1])
        return point_rms((mean[:n] - truth[:n])[:, cols], self.point_dim)  # the band's rows of the difference

    def controlled_cols(self, D: int) -> list[int]:
        """The controlled agent's columns (the observed ones for a single-agent model)."""
        ctrl = [i for i in range(D) if i not in set(self.observed)]
        return ctrl or self.observed

    def band_steps(self, edges: Iterable[float]) -> list[np.ndarray]:
        """Step indices of each look-ahead band (upper edges ``edges`` in seconds; each band non-empty)."""
        out: list[np.ndarray]
        out, lo = [], 0.0
        for e in edges:
            idx = np.flatnonzero((self.t_ahead > lo + 1e-12) & (self.t_ahead <= e + 1e-12))
            if idx.size:
                out.append(idx)
            lo = e
        return out

    def subset(self, names: Collection[str]) -> CrossValidation:
        """The same cases restricted to the families ``names`` (those with finite errors, in this order)."""
        keep = [i for i, m in enumerate(self.names) if m in set(names)]
        out = object.__new__(type(self))
        out.__dict__.update(self.__dict__)
        out.errors = {m: e for m, e in self.errors.items() if m in set(names)}
        out.names = [self.names[i] for i in keep]
        lazy: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        for a in _PER_FAMILY:  # copied when first read (__getattr__)
            src, rows = self._family_source(a)
            out.__dict__.pop(a, None)
            if src is not None:
                lazy[a] = (src, np.asarray(keep if rows is None else [rows[i] for i in keep], dtype=np.intp))
        out.__dict__["_lazy"] = lazy
        out.__dict__["_gram_cache"] = dict(self._gram(), mean=_LAZY)  # shared: its families read by name
        return out

    def _gram(self) -> dict[str, Any]:
        """The products of the families' held-out errors from which every stacking loss is computed, per case
        ``c`` and step ahead ``h`` over the controlled columns ``j``: ``G[c, h, m, n] = sum_j E_mchj E_nchj``
        (``E = mean - truth``), ``u[c, h, m] = sum_j E_mchj T_chj`` and ``t[c, h] = sum_j T_chj^2``; ``names``
        orders ``m`` and ``rows`` maps this object's cases to ``c``.  Computed once per cross-validation (its
        :meth:`subset` and :meth:`cases` share it) and again only when ``mean`` or ``truth`` is replaced."""
        g = self.__dict__.get("_gram_cache")
        mean = self.__dict__.get("mean", _LAZY)  # _LAZY: the rows of the parent's, whose products g holds
        if g is not None and g["mean"] is mean and g["truth"] is self.truth:
            return g
        c = column_index(self.controlled or self.observed)  # a slice when contiguous: no copy of the members' arrays
        T = np.ascontiguousarray(self.truth[..., c])  # (cases, H, C)
        n_case, H, C = T.shape
        M = self.mean.shape[0]
        G = np.empty((n_case, H, M, M))
        U = np.empty((M, n_case, H))
        # the errors E = mean - truth a block of cases at a time, into one small buffer: every product is a sum over
        # the columns of one case and step, the same numbers as from the whole (M, cases, H, C) array of errors,
        # without its memory (tens of MB, new pages for every cross-validation)
        step = max(1, min(n_case, _CASE_BLOCK // max(M * H * C, 1)))
        E = np.empty((M, step, H, C))
        for c0 in range(0, n_case, step):
            c1 = min(c0 + step, n_case)
            Eb, Tb = E[:, :c1 - c0], T[c0:c1]
            np.subtract(self.mean[:, c0:c1, :, c], Tb[None], out=Eb)
            for m in range(M):  # one pass over the cases per pair of families (faster than tiny batched products)
                for n in range(m + 1):
                    G[c0:c1, :, m, n] = G[c0:c1, :, n, m] = np.einsum("chj,chj->ch", Eb[m], Eb[n])
            U[:, c0:c1] = np.einsum("mchj,chj->mch", Eb, Tb)
        g = {"mean": self.mean, "truth": self.truth, "names": list(self.names), "rows": np.arange(n_case),
             "G": G, "u": np.moveaxis(U, 0, 2), "t": np.einsum("chj,chj->ch", T, T)}
        self.__dict__["_gram_cache"] = g
        return g

    def blend_weights(self, steps: ArrayLike | None = None) -> np.ndarray:
        """Weights on the simplex (one per family of :attr:`names`) that minimise the blend's mean error of the
        controlled agent over the cases at the look-ahead ``steps`` (default: every step): the RMS over the case's
        steps inside its held-out movement (:attr:`valid`; the real-time band counts every step, as the protocol
        does), averaged over cases -- for the real-time band the very figure :attr:`errors` reports (stacking,
        Breiman 1996, on the protocol's own loss: a convex problem whose solution is a convex combination, so the
        blend can always fall back on a single family).  Squared-error stacking was tried first: a few large errors
        decided the weights and the blend came out worse than its best member on the protocol's loss."""
        if len(self.names) == 1:
            return np.ones(1)
        return self._solve(steps)[0]

    def band_loss(self, steps: ArrayLike | None = None) -> float:
        """The smallest mean error :meth:`blend_weights` reaches over the look-ahead ``steps`` (its own loss, on
        the truth's scale; what a set of families can do in that band, used to compare sets under a budget)."""
        return self._solve(steps)[1]

    def _solve(self, steps: ArrayLike | None) -> tuple[np.ndarray, float]:
        """``(weights, their loss in units of the truth's RMS)`` of :meth:`blend_weights`."""
        return simplex_minimum(self._loss(steps), len(self.names))

    def _loss(self, steps: ArrayLike | None) -> Callable[[np.ndarray], tuple[float, np.ndarray]]:
        """The stacking loss of weights ``w`` over ``steps`` and its gradient (a closure over the band's arrays).

        Per case, the blend's squared error over the band is a quadratic in ``w`` whose coefficients are sums of
        :meth:`_gram`'s products: with ``E_m = P_m - T`` and ``d = sum(w) - 1``, ``w P - T = w E + d T``, so
        ``|w P - T|^2 = w' K w + 2 d (w' h) + d^2 t`` (``K``, ``h``, ``t``: the products summed over the band's
        steps inside the held-out movement).  The sums are formed once per band, and each evaluation costs
        ``O(cases M^2)`` instead of a pass over every prediction; the values are those of the direct sum up to
        rounding (no cancellation: ``K`` holds the members' own errors)."""
        g = self._gram()
        C = len(self.controlled or self.observed)
        H = self.truth.shape[1]
        sel = np.arange(H) if steps is None else np.asarray(steps)
        n_rt = max(1, int(round(self.horizon / self.dt)))
        mask = self.valid[:, sel] | (sel < n_rt)[None, :]  # (cases, S)
        keep = mask.any(axis=1)
        mask = mask[keep]
        rows = g["rows"][keep]
        cols = [g["names"].index(m) for m in self.names]
        tt = g["t"][np.ix_(rows, sel)]  # (cases, S)
        scale = max(float(np.sqrt(np.sum(tt) / max(tt.size * C, 1))), 1e-300)  # the truth's RMS
        Wm = mask.astype(np.float64)
        K = np.einsum("cs,csmn->cmn", Wm, g["G"][np.ix_(rows, sel, cols, cols)]) / scale / scale
        h = np.einsum("cs,csm->cm", Wm, g["u"][np.ix_(rows, sel, cols)]) / scale / scale
        t = np.einsum("cs,cs->c", Wm, tt) / scale / scale
        count = Wm.sum(axis=1) * C
        return case_rms_loss(K, h, t, count)

    def blend_scales(self, w: ArrayLike, level: float | None = None) -> dict[str, Any]:
        """The blend's variance model over the look-ahead, fitted to its held-out errors: per step ahead ``h`` and
        column ``j``, ``var = a[h, j] * spread^2 + b[h, j]`` with ``spread^2`` the weighted disagreement of the
        members, ``sum_m w_m (y_m - mean)^2``.  Where the spread alone is narrower than the held-out error,
        ``a = 1`` and ``b`` adds the rest; where it is wider, ``b = 0`` and ``a < 1`` narrows it, so that the mean
        predicted variance equals the mean squared held-out error at every step and column.  Held-out errors are
        heavier-tailed than a normal distribution, so matching the variance alone leaves the 90 % band short; both
        ``a`` and ``b`` are then scaled, per step and agent, by ``(q / 1.645)^2`` with ``q`` the quantile at level
        ``L`` of the standardised held-out errors ``|e| / sd``.

        ``L`` is chosen per agent by cross-fitting (:func:`band_level`): the variance model fitted on two thirds of
        the held-out demonstrations must cover 90 % of the frames of all of them when each third is covered by
        the model it did not see, and at least 85 % (:data:`BAND_FLOOR`) of each third's, the thirds contiguous in
        recording order.  A model fitted and calibrated on the same cases is optimistic (per-step quantiles of
        12-20 recordings are noisy): with ``L = 0.9`` the band covered 80-91 % (mean 88 %) of the robot's rest of
        the movement in outer folds of the development recordings; the cross-fitted level raised that to 83-93 %
        (mean 89 %), and the floor on each third to 84-94 % (mean 91 %; on the outer fold that predicts the latest
        recordings 83-96 % -> 86-98 %).

        The members' own std is not used: it does not carry over from the inner folds' smaller training sets to
        the final fit (``LearnedInteraction``'s was 4x its error when fitted on 9 NuiSI demonstrations, about
        right on 13), whereas their disagreement and the residual do.

        ``level``: a fixed quantile level for both agents instead (e.g. 0.9, the level before the cross-fitting).

        Returns ``{"a": (H, D), "b": (H, D), "level": {"controlled": L, "observed": L}}``.
        """
        w = np.asarray(w, dtype=np.float64)
        w = (w[:, None] if w.ndim == 1 else w.T)[:, None, :, None]  # (M, 1, H or 1, 1)
        n_rt = max(1, int(round(self.horizon / self.dt)))
        valid = self.valid | (np.arange(self.truth.shape[1]) < n_rt)[None, :]  # (cases, H)
        agents = {k: c for k, c in (("controlled", self.controlled), ("observed", self.observed)) if c}
        parts = blend_parts(self.mean, w)  # the blend and its members' spread, per case: shared by every fit below
        if level is not None:
            levels = {k: float(level) for k in agents}
        else:
            levels = band_levels(self.mean, self.truth, valid, w, agents, self.demo, parts=parts)
        a, b = variance_model(self.mean, self.truth, valid, w, agents, levels, parts=parts)
        return {"a": a, "b": b, "level": levels}

    def blend_error(self, w: ArrayLike) -> float:
        """The blend's mean real-time error of the controlled agent over the cases, as :attr:`errors` measures it
        (in-sample for the weights: an optimistic figure)."""
        w = np.asarray(w, dtype=np.float64)
        if w.ndim == 2:  # per-step weights (H, M): the real-time band's
            w = cast(np.ndarray, w[0])
        n = max(1, int(round(self.horizon / self.dt)))
        mix = np.tensordot(w, self.mean[:, :, :n], axes=1)
        e = (mix - self.truth[:, :n])[..., self.controlled or self.observed]
        n_case, H, C = e.shape
        pd = self.point_dim if C % self.point_dim == 0 else 1
        point2 = np.sum(e.reshape(n_case, H, C // pd, pd) ** 2, axis=3)  # squared point errors
        return float(np.mean(np.sqrt(point2.mean(axis=(1, 2)))))



#: The quantile levels :func:`band_level` tries, from the nominal 90 %.
BAND_LEVELS = tuple(np.round(np.arange(0.90, 0.9801, 0.01), 2))


def blend_parts(mean: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(mix, case_spread)``, each ``(cases, H, D)``: the blend of the members' predictions ``mean`` ``(M, cases, H,
    D)`` with the weights ``w`` (broadcastable to ``mean``) and the members' weighted disagreement around it,
    ``sum_m w_m (y_m - mix)^2``.  Both are computed case by case, so those of a subset of the cases are the
    subset's rows, to the bit: :func:`crossfit_coverages` and :func:`variance_model` take them once for all."""
    # np.sum(w * mean, axis=0) and np.sum(w * (mean - mix) ** 2, axis=0) member by member: the same products,
    # added in the same order to the same zero start (numpy's sum over the first axis adds its rows in turn), without
    # the (M, cases, H, D) temporaries
    full = np.broadcast_shapes(np.shape(w), mean.shape)
    w, mean = np.broadcast_to(w, full), np.broadcast_to(mean, full)  # views
    shape = full[1:]
    mix = np.zeros(shape)
    spread = np.zeros(shape)
    # a block of cases at a time (every number is of one case, step and column), through one small buffer
    n = shape[0] if shape else 1
    step = max(1, _CASE_BLOCK // max(int(np.prod(shape[1:])), 1))
    tmp = np.empty((min(step, n),) + tuple(shape[1:])) if shape else np.empty(())
    for c0 in range(0, n, step):
        b = slice(c0, c0 + step) if shape else ...
        mb, sb = mix[b], spread[b]  # views
        t = tmp[: mb.shape[0]] if shape else tmp
        for m in range(full[0]):
            np.multiply(w[m][b], mean[m][b], out=t)
            mb += t
        for m in range(full[0]):
            np.subtract(mean[m][b], mb, out=t)
            np.square(t, out=t)
            np.multiply(w[m][b], t, out=t)
            sb += t
    return mix, spread


def _matched_variance(mean: np.ndarray | None, truth: np.ndarray, valid: np.ndarray, w: np.ndarray,
                      parts: tuple[np.ndarray, np.ndarray] | None = None
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, int]:
    """``(a, b, mix, case_spread, has, last)``: the variance model matched to the held-out squared error step by step
    (before its quantile scaling; :meth:`CrossValidation.blend_scales`) on the cases given, the blend ``mix`` and the
    members' weighted disagreement per case, the steps with valid cases and the last of them (``parts``: the
    cases' :func:`blend_parts`, else computed)."""
    # ``mean`` is given whenever ``parts`` is not
    mix, case_spread = blend_parts(cast(np.ndarray, mean), w) if parts is None else parts
    n_valid = valid.sum(axis=0)
    has = n_valid > 0
    last = int(np.flatnonzero(has)[-1]) if has.any() else 0
    vw = valid[:, :, None].astype(np.float64)

    # mean over the valid cases of every step, held from the last step that has any
    def step_mean(x: np.ndarray) -> np.ndarray:
        m = np.sum(x * vw, axis=0) / np.maximum(n_valid, 1)[:, None]
        m[~has] = m[last]
        return m

    spread = step_mean(case_spread)
    err2 = step_mean((mix - truth) ** 2)
    wide = spread > err2
    a = np.where(wide, err2 / np.where(spread > 0, spread, 1.0), 1.0)
    b = np.where(wide, 0.0, err2 - spread)
    return a, b, mix, case_spread, has, last


def _step_quantiles(z: np.ndarray, valid: np.ndarray, cols: Sequence[int], levels: Sequence[float] | np.ndarray,
                    has: np.ndarray, last: int) -> np.ndarray:
    """``(len(levels), H)``: per step, the quantiles at ``levels`` of the standardised errors ``z`` of the columns
    ``cols`` over the step's valid cases (the nominal ``Z90`` where none, held from the last step that has any)."""
    q = np.full((len(levels), z.shape[1]), Z90)
    for h in np.flatnonzero(has):
        q[:, h] = np.quantile(z[:, h][valid[:, h]][:, cols], levels, method="higher")  # step h alone
    q[:, ~has] = q[:, [last]]
    return q


def variance_model(mean: np.ndarray, truth: np.ndarray, valid: np.ndarray, w: np.ndarray,
                   agents: Mapping[str, Sequence[int]], level: Mapping[str, float],
                   parts: tuple[np.ndarray, np.ndarray] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``(a, b)``, each ``(H, D)``: the variance model of :meth:`CrossValidation.blend_scales` fitted on the cases
    given (``mean`` ``(M, cases, H, D)``, ``truth`` and ``valid`` of those cases, ``w`` the blend's weights
    broadcastable to ``mean``), its standardised errors' quantile at ``level[agent]`` for the columns
    ``agents[agent]`` (``parts``: :func:`blend_parts` of ``mean`` and ``w``, else computed)."""
    a, b, mix, case_spread, has, last = _matched_variance(mean, truth, valid, w, parts)
    z = np.abs(mix - truth) / np.sqrt(np.maximum(a * case_spread + b, 1e-300))
    for agent, cols in agents.items():
        if cols and z.shape[0]:
            q = _step_quantiles(z, valid, cols, [level[agent]], has, last)[0]
            r2 = (np.maximum(q, 1e-6) / Z90)[:, None] ** 2
            a[:, cols] *= r2
            b[:, cols] *= r2
    return a, b


def crossfit_coverages(mean: np.ndarray, truth: np.ndarray, valid: np.ndarray, w: np.ndarray, cols: Sequence[int],
                       groups: ArrayLike, levels: ArrayLike = BAND_LEVELS, k: int = 3,
                       parts: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """``(len(levels),)``: the 90 % band's coverage of the columns ``cols`` on held-out demonstrations when its
    variance model (:func:`variance_model`, quantile at each of ``levels``) is fitted on the others: the cases split
    into ``k`` groups of whole demonstrations (``groups``: each case's demonstration), each group covered by the
    model of the other groups' cases; the mean over demonstrations of the fraction of valid steps inside the band.

    The level only scales the matched model: a frame is inside the band of level ``L`` when its error over the
    matched std is at most that step's ``L``-quantile of the training cases' (``1.645 sd`` with ``sd`` scaled by
    ``q / 1.645``), so every level is read from one fit per group (``parts``: :func:`blend_parts` of ``mean`` and
    ``w``, else computed)."""
    return _crossfit(mean, truth, valid, w, [cols], groups, levels, k, parts)[0]


def _crossfit(mean: np.ndarray, truth: np.ndarray, valid: np.ndarray, w: np.ndarray, col_sets: Sequence[Sequence[int]],
              groups: ArrayLike, levels: ArrayLike = BAND_LEVELS, k: int = 3,
              parts: tuple[np.ndarray, np.ndarray] | None = None) -> list[np.ndarray]:
    """:func:`crossfit_coverages` of each of the column sets ``col_sets``, one variance model fitted per group for
    all of them (what a set's coverage reads of it, its columns, is computed as for that set alone)."""
    return [np.mean(c, axis=0) if len(c) else np.ones(len(np.atleast_1d(levels)))
            for c, _ in _crossfit_demos(mean, truth, valid, w, col_sets, groups, levels, k, parts)]


def _crossfit_demos(mean: np.ndarray, truth: np.ndarray, valid: np.ndarray, w: np.ndarray,
                    col_sets: Sequence[Sequence[int]], groups: ArrayLike, levels: ArrayLike = BAND_LEVELS, k: int = 3,
                    parts: tuple[np.ndarray, np.ndarray] | None = None) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per column set, ``(cover, group)``: each held-out demonstration's cross-fitted coverage at every level
    ``(demos, len(levels))`` (:func:`crossfit_coverages` before its mean over demonstrations) and the contiguous
    group it was covered in ``(demos,)``."""
    levels = np.atleast_1d(np.asarray(levels, dtype=np.float64))
    g = case_groups(groups, k)
    mix, case_spread = blend_parts(mean, w) if parts is None else parts
    per_demo: list[list[np.ndarray]] = [[] for _ in col_sets]
    per_group: list[list[int]] = [[] for _ in col_sets]
    for gi in np.unique(g):
        tr, te = g != gi, g == gi
        if not tr.any():
            continue
        truth_tr = truth[tr]
        a, b, mix_tr, spread_tr, has, last = _matched_variance(None, truth_tr, valid[tr], w,
                                                               (mix[tr], case_spread[tr]))
        z_tr = np.abs(mix_tr - truth_tr) / np.sqrt(np.maximum(a * spread_tr + b, 1e-300))
        sd_all = np.sqrt(np.maximum(a * case_spread[te] + b, 1e-300))
        err_all = np.abs(mix[te] - truth[te])
        v, d = valid[te], np.asarray(groups)[te]
        for cols, out, grp in zip(col_sets, per_demo, per_group):
            q = np.maximum(_step_quantiles(z_tr, valid[tr], cols, levels, has, last), 1e-6)  # (L, H)
            sd = sd_all[..., column_index(cols)]  # views of consecutive columns
            err = err_all[..., column_index(cols)]
            for j in np.unique(d):
                sel = d == j
                if not v[sel].any():
                    continue
                # inside at level L: err <= q_L * sd at every (case, step, column) of this demonstration
                r = (err[sel] / np.maximum(sd[sel], 1e-300))[v[sel]]  # (frames, cols)
                qh = np.broadcast_to(q[:, None, :], (len(levels),) + v[sel].shape)[:, v[sel]]  # (L, frames)
                out.append(np.mean(r[None] <= qh[:, :, None] * (1 + 1e-12), axis=(1, 2)))
                grp.append(int(gi))
    return [(np.array(o).reshape(len(o), len(levels)), np.array(gr, dtype=np.int64))
            for o, gr in zip(per_demo, per_group)]


def crossfit_coverage(mean: np.ndarray, truth: np.ndarray, valid: np.ndarray, w: np.ndarray, cols: Sequence[int],
                      groups: ArrayLike, level: float, k: int = 3) -> float:
    """:func:`crossfit_coverages` at one ``level``."""
    return float(crossfit_coverages(mean, truth, valid, w, cols, groups, [level], k)[0])


def band_level(mean: np.ndarray, truth: np.ndarray, valid: np.ndarray, w: np.ndarray, cols: Sequence[int],
               groups: ArrayLike, target: float = 0.9, parts: tuple[np.ndarray, np.ndarray] | None = None,
               floor: float | None = None) -> float:
    """The smallest level of :data:`BAND_LEVELS` at which the cross-fitted band covers ``target`` of the held-out
    demonstrations' frames and at least ``floor`` (default :data:`BAND_FLOOR`) of each contiguous group's
    (:func:`crossfit_coverages`; the last level when none does, the first with fewer than two demonstrations)."""
    return band_levels(mean, truth, valid, w, {"cols": cols}, groups, target, parts, floor)["cols"]


#: The least coverage :func:`band_levels` asks of the band on each contiguous third of the held-out demonstrations
#: (in recording order), besides ``target`` over all of them: 85 %, the lower end of the range a user is promised on
#: every task (issue 37: 85-95 %).  People change over a session, so a band that covers 90 % on average while it
#: covers 80 % of one stretch of the recordings is not one a user can plan with on the next recordings.
BAND_FLOOR = 0.85


def band_levels(mean: np.ndarray, truth: np.ndarray, valid: np.ndarray, w: np.ndarray,
                agents: Mapping[str, Sequence[int]], groups: ArrayLike, target: float = 0.9,
                parts: tuple[np.ndarray, np.ndarray] | None = None, floor: float | None = None) -> dict[str, float]:
    """:func:`band_level` of each agent's columns (``agents``: ``{name: cols}``), the cross-fitted variance models
    shared (``{name: level}``, the numbers :func:`band_level` gives each).

    A level is taken when the band fitted on the other groups covers ``target`` of all held-out demonstrations'
    frames (the mean of their coverages) and at least ``floor`` of each group's, the groups being the contiguous
    thirds of :func:`~interprim.model_selection.yardsticks.case_groups`: recordings made later in a session are
    covered by a band fitted on the earlier ones as well as the other way round.  ``floor=0`` asks for the mean
    alone."""
    if len(np.unique(groups)) < 2:
        return {k: float(BAND_LEVELS[0]) for k in agents}
    floor = BAND_FLOOR if floor is None else float(floor)
    demos = _crossfit_demos(mean, truth, valid, w, list(agents.values()), groups, parts=parts)
    out: dict[str, float] = {}
    for name, (cover, grp) in zip(agents, demos):
        ok = np.mean(cover, axis=0) >= target if len(cover) else np.ones(len(BAND_LEVELS), dtype=bool)
        for gi in np.unique(grp):
            ok &= np.mean(cover[grp == gi], axis=0) >= floor
        idx = np.flatnonzero(ok)
        out[name] = float(BAND_LEVELS[idx[0]] if idx.size else BAND_LEVELS[-1])
    return out


def choice(cv: CrossValidation, order: Sequence[str]) -> tuple[str, dict[str, Any]]:
    """``(best family, selection record)`` from a :class:`CrossValidation` (ties: the earlier in ``order``)."""
    errors = cv.errors
    finite = {m: e for m, e in errors.items() if np.isfinite(e)}
    if not finite:
        why = "; ".join(f"{m}: {w}" for m, w in getattr(cv, "why", {}).items())
        raise ValueError("no candidate family could be fitted on every inner training fold"
                         + (f" ({why})" if why else ""))
    chosen = min(finite, key=lambda m: (finite[m], list(order).index(m)))
    return chosen, choice_record(chosen, errors)


def choice_record(chosen: str, errors: dict[str, float]) -> dict[str, Any]:
    """The selection record of ``chosen`` among ``errors`` (``{family: held-out error}``): ``chosen``,
    ``cv_errors``, ``runner_up``, ``margin`` (its error / the chosen one's) and ``vs_prior``."""
    finite = {m: e for m, e in errors.items() if np.isfinite(e)}
    others = {m: e for m, e in finite.items() if m != chosen}
    runner = min(others, key=lambda m: others[m]) if others else None
    best = finite.get(chosen, float("nan"))
    return {"chosen": chosen, "cv_errors": {m: float(e) for m, e in errors.items()},
            "runner_up": runner, "margin": float(others[runner] / best) if runner and best > 0 else float("nan"),
            "vs_prior": float(best / finite["prior"]) if finite.get("prior", 0) > 0 else float("nan")}

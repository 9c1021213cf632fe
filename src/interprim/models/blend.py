"""A convex combination of fitted models' predictions placed in time, with weights per look-ahead: :class:`Blend`,
its prediction (:class:`BlendPrediction`) and its stream (:class:`BlendStream`).

Made by :class:`~interprim.models.auto.AutoInteraction` from the weights and variance model that the family
comparison fitted on held-out folds (:func:`interprim.model_selection.stacking.stack`).
"""

from __future__ import annotations

import math

import numpy as np

from ..core import state_checks as check
from ..core._compiled import registry as _registry
from ..core.cache import DerivedCache
from ..core.cv import DEFAULT_HORIZON
from ..core.errors import ModelFileError
from ..core.preprocessing import interp_columns, unit_grid
from ..core.validation import as_2d_finite
from ..io import estimator_from_state
from ..model_selection.realtime import place_in_time
from ..model_selection.stacking import weights_at
from . import registry
from .base import BaseStream, Predictor, training_set
from .grid import GridPrediction

__all__ = ["Blend", "BlendPrediction", "BlendStream", "member_from_state", "place_members_np", "share_phase_models",
           "spread_std_np", "weights_on_np"]

#: The blend's own frame cost in microseconds: ``a + b members + c members x DoFs`` (:meth:`Blend.frame_overhead`).
_OVERHEAD_US = (0.0, 33.06, 7.52372)
#: The same for one ``predict`` (:meth:`Blend.predict_overhead`).
_PREDICT_OVERHEAD_US = (0.0, 95.9, 3.08596)
#: A band weight (normalised, at most 1) at or above which a member's interpolated weight is positive at every
#: look-ahead: :func:`numpy.interp`'s rounding moves its values by a few units in the last place of 1 (1e-16).
_SURE_WEIGHT = 1e-12


def member_from_state(cls_name: str, params: dict, arrays: dict, state: dict):
    """A blend's member (or the model of an :class:`~interprim.models.auto.AutoInteraction`) from its class name,
    parameters and state (:func:`interprim.io.estimator_from_state`; a family of the registry or a :class:`Blend`)."""
    cls = Blend if cls_name == "Blend" else registry.class_named(cls_name)
    if cls is None:
        raise ValueError(f"a blend member of class {cls_name!r}, which is not a family of interprim's registry "
                         f"(known: {', '.join(f.cls.__name__ for f in registry.FAMILIES.values())})")
    return estimator_from_state(cls, params, arrays, state)


def share_phase_models(members: dict) -> int:
    """Members whose learned phases are the same fit share one object; returns how many took another's.

    The Interaction Primitive with the learned phase (its ``phase_model_``) and
    :class:`~interprim.models.learned.LearnedInteraction` (its ``phase_``) fit the same
    :class:`~interprim.phase.learned.LearnedPhase` on the same observed columns with the library's defaults, and
    both estimate it on the same frames after every frame.  Shared, the estimate is computed once a frame: the shared
    phase model keeps its last estimate (:meth:`~interprim.phase.learned.LearnedPhase.keep_last_estimate`), a
    function of the frames its features read, so the same numbers come back.  A member that can take another phase
    model (:meth:`~interprim.models.learned.LearnedInteraction.use_phase_model`) takes an equal one met before it (the
    same settings and fitted arrays, bit for bit); nothing else changes."""
    from ..phase.learned import LearnedPhase

    found = [pm for est in members.values()
             if isinstance(pm := getattr(getattr(est, "fitted_", None), "phase_model_", None), LearnedPhase)]
    shared = 0
    for est in members.values():
        use, ph = getattr(est, "use_phase_model", None), getattr(est, "phase_", None)
        if use is None or not isinstance(ph, LearnedPhase):
            continue
        same = next((q for q in found if q is ph or q.same_fit(ph)), None)
        if same is None:
            found.append(ph)
        elif same is not ph and use(same):
            same.keep_last_estimate()
            shared += 1
    return shared


def _on_grid(pred, u) -> np.ndarray:
    """``pred.trajectory(len(u))`` on the grid ``u`` (``linspace(0, 1, n)``): a tabulated prediction whose own times
    are that grid is read as it is (interpolating at its own sample points gives its values), another one
    interpolated as its ``trajectory`` does."""
    times = getattr(pred, "times", None)
    if type(pred).trajectory is GridPrediction.trajectory and times is not None:
        if times.shape == u.shape and (times is u or np.array_equal(times, u)):
            return pred.mean
        return interp_columns(u, times, pred.mean)  # GridPrediction.trajectory's values, without its wrapper
    grid_mean = getattr(pred, "grid_mean", None)  # trajectory's values by a cheaper path (an IP's Prediction)
    return pred.trajectory(u.shape[0]) if grid_mean is None else grid_mean(u.shape[0])


def place_members_np(u, ahead, sv, dv, s: float, R: float, h: float, grids, W) -> tuple:
    """``(Y, mean)``: every member's values read at its own normalised time on the common grid ``u`` and their
    weighted sum ``mean = sum_j W[:, j] Y[j]`` (the numpy reference of the compiled ``blend.place_members``).

    Member ``j`` (phase ``sv[j]``, duration ``dv[j]``; ``grids[j]`` its values on ``u``) is at ``s_j + a / D_j``
    at ``a = ahead`` seconds after now; with a shared end (``R`` seconds from now, NaN for none) beyond the
    real-time band of ``h`` seconds it runs there by :func:`interprim.model_selection.long_range.member_units`'s
    operations for one member; before now (``u < s``, the blend's phase) at ``u s_j / s``."""
    Y = np.empty_like(grids)
    past = u < s
    for j in range(len(sv)):
        sm, Dm = float(sv[j]), float(dv[j])
        um = ahead / Dm
        um += sm  # own = s_m + t / D_m
        if not np.isnan(R):  # long_range.member_units of one member, the same operations
            Rm = max(R, h)
            uh = min(sm + h / Dm, 1.0)
            if Rm > h:
                after = (ahead - h) * (1.0 - uh) / max(Rm - h, 1e-9) + uh
            else:
                after = np.ones_like(ahead)
            um = np.where(ahead <= h + 1e-12, um, after)
        np.minimum(np.maximum(um, 0.0, out=um), 1.0, out=um)
        um[past] = u[past] * (sm / s if s > 0 else 1.0)
        np.minimum(np.maximum(um, 0.0, out=um), 1.0, out=um)
        Y[j] = interp_columns(um, u, grids[j])
    return Y, np.einsum("gm,mgd->gd", W, Y)


def weights_on_np(u, s: float, D: float, mids, table) -> tuple:
    """``(ahead, W, zeros)``: the look-ahead ``max((u - s) D, 0)`` (s) of every point of the grid ``u`` (the blend's
    phase ``s``, duration ``D``), the weights there (:func:`~interprim.model_selection.stacking.weights_at`'s
    operations on the bands' weights ``table`` (B, M) at the bands' middles ``mids``) and the number of weights equal
    to 0 (the numpy reference of the compiled ``blend.weights_on``)."""
    ahead = (u - s) * D
    np.maximum(ahead, 0.0, out=ahead)
    W = _band_weights(ahead, mids, table)
    return ahead, W, int(W.size - np.count_nonzero(W))


def _band_weights(ahead, mids, table) -> np.ndarray:
    """:func:`~interprim.model_selection.stacking.weights_at`'s operations on the bands' weights ``table`` (B, M) at
    their middles ``mids``, read at ``ahead`` (n,) seconds: ``(n, M)`` (without numpy.clip's wrapper; the quotients
    in place)."""
    out = interp_columns(ahead, mids, table)
    np.maximum(out, 0.0, out=out)  # numpy.clip(out, 0, None)'s values
    total = out.sum(axis=1, keepdims=True)
    np.maximum(total, 1e-300, out=total)
    return np.divide(out, total, out=out)


def spread_std_np(Y, mean, W, ahead, steps, a, b, scaled: bool):
    """``(std, positive)``: the blend's std ``sqrt(clip(var, 0))`` on the grid with ``var = a(ahead) spread +
    b(ahead)`` (:meth:`Blend.variance`; ``spread`` alone unless ``scaled``) and the members' weighted disagreement
    ``spread = sum_j W[:, j] (Y[j] - mean)^2``; ``positive``: the number of points with ``var > 0`` (the numpy
    reference of the compiled ``blend.spread_std``)."""
    spread = np.einsum("gm,mgd->gd", W, (Y - mean[None]) ** 2)
    var = interp_columns(ahead, steps, a) * spread + interp_columns(ahead, steps, b) if scaled else spread
    return np.sqrt(np.clip(var, 0.0, None)), int(np.count_nonzero(var > 0))


class Blend(Predictor):
    """A convex combination of fitted models' predictions, each placed in time by its own timing, with weights that
    depend on how far ahead the prediction is.

    After ``k`` observed frames each member ``m`` says where "now" is in its normalised time (``s_m``) and how long
    the movement lasts (``D_m``; :func:`interprim.model_selection.realtime.place_in_time`).  The blend's own timing is
    the weighted mean ``s = sum w_m(0) s_m``, ``D = sum w_m(0) D_m`` with the real-time weights; its mean at
    normalised time ``u``, ``a = (u - s) D`` seconds ahead of now, is ``sum w_m(a) y_m(u_m)`` with
    ``u_m = s_m + a / D_m`` (the same instant in seconds for every member) and ``u_m = u s_m / s`` before now (where
    ``a = 0``).  The weights ``w(a)`` were fitted per look-ahead band on held-out folds
    (:func:`~interprim.model_selection.stacking.weights_at`): the next ``horizon`` seconds, then bands doubling in
    length to the end of the longest demonstration.  Its variance is the members' weighted disagreement
    ``sum w_m(a) (y_m - mean)^2``, scaled per column and per second ahead to the held-out errors (``scales``).

    Made by :class:`~interprim.models.auto.AutoInteraction`; :meth:`fit` refits the members with the stored
    weights (members of the registry's families).

    Parameters
    ----------
    observed_dofs : sequence of int
    weights : dict
        ``{family: weight}``, or ``{family: [weight per band]}`` with ``bands`` (families of
        :data:`interprim.models.registry.FAMILIES`).
    scales : dict, optional
        ``{"a": (H, D), "b": (H, D), "t": (H,)}``: the variance ``a * spread + b`` at ``t`` seconds ahead (default
        ``a = 1, b = 0``: the spread alone; without ``t``, ``H`` steps spanning ``horizon``).
    horizon : float
        Seconds of the real-time band.
    n_basis, smoothing_window
        Settings of the Interaction Primitive members.
    bands : list of float, optional
        Upper edges (s) of the look-ahead bands of the weights (None: one set of weights for every look-ahead).
    remaining : float, optional
        None: every member runs at its own duration ``D_m``.  A number ``lam``: beyond ``horizon`` the members run
        to one shared end, ``R`` seconds from now, the members' remaining duration shrunk toward the clock's by
        ``lam`` (:func:`interprim.model_selection.long_range.remaining_duration`, chosen on the inner folds' rest
        of the movement); up to ``horizon`` each keeps its own speed.  A member's name ``p`` (the partner's pace,
        :data:`interprim.model_selection.long_range.PACE`): the shared end is that member's own remaining duration
        ``max(1 - s_p, 0) D_p`` (:func:`interprim.model_selection.long_range.pace_remaining`); the member may carry
        weight 0 in every band, timing the others only.
    past : dict, optional
        ``{family: weight}``: the weights of the robot's past (the grid before now, ``u < s``; chosen on the inner
        folds by :func:`interprim.model_selection.long_range.past_choice`); None: the real-time weights there.  A
        family may carry weight here alone (weight 0 in every band).
    """

    _FITTED = "members_"
    #: 2: weights per look-ahead band, the variance model's own time axis; 3: ``remaining`` may name a member;
    #: 4: ``past``, the weights of the robot's past
    STATE_VERSION = 4
    #: points of the normalised-time grid on which the members' predictions are read
    N_GRID = 201

    def __init__(self, observed_dofs, weights, scales=None, horizon: float = DEFAULT_HORIZON,
                 n_basis: int = 20, smoothing_window=None, bands=None, remaining=None, past=None):
        self.observed_dofs = observed_dofs
        self.past = past
        self.remaining = remaining
        self.weights = weights
        self.scales = scales
        self.horizon = horizon
        self.n_basis = n_basis
        self.smoothing_window = smoothing_window
        self.bands = bands

    @classmethod
    def from_fitted(cls, observed_dofs, members: dict, weights: dict, scales, demos, dt: float,
                    horizon: float = DEFAULT_HORIZON, bands=None, n_basis: int = 20,
                    smoothing_window=None, remaining=None, past=None) -> Blend:
        """A blend of already fitted ``members`` (``{family: model}``) trained on ``demos`` at ``dt``."""
        sc = None if scales is None else {k: np.asarray(v, dtype=np.float64).tolist() for k, v in scales.items()}
        blend = cls(list(observed_dofs), dict(weights), sc, horizon, n_basis, smoothing_window,
                    None if bands is None else [float(b) for b in bands],
                    None if remaining is None else remaining if isinstance(remaining, str) else float(remaining),
                    None if past is None else {str(m): float(w) for m, w in past.items()})
        blend.adopt(members, demos, dt)
        return blend

    def _weight_table(self):
        """``(names, W (bands, M), edges)`` of the stored weights."""
        names = list(self.weights)
        if self.bands is None:
            W = np.array([[float(self.weights[m]) for m in names]])
            return names, W, np.array([np.inf])
        W = np.array([[float(x) for x in self.weights[m]] for m in names]).T
        if W.shape[0] != len(self.bands):
            raise ValueError(f"weights have {W.shape[0]} bands, bands has {len(self.bands)} edges")
        return names, W, np.asarray(self.bands, dtype=np.float64)

    def _past_weights(self, names) -> np.ndarray | None:
        """``past`` as ``(members,)`` weights on the simplex in the order of ``names`` (None without it)."""
        if self.past is None:
            return None
        if not isinstance(self.past, dict) or not self.past:
            raise ValueError(f"past must be a non-empty dict {{family: weight}} or None, got {self.past!r}")
        unknown = [m for m in self.past if m not in names]
        if unknown:
            raise ValueError(f"past names {unknown}, not members of the blend (members: {names})")
        w = np.array([float(self.past.get(m, 0.0)) for m in names])
        if np.any(w < 0) or not np.all(np.isfinite(w)) or w.sum() <= 0:
            raise ValueError(f"past weights must be finite, non-negative and not all zero, got {self.past!r}")
        return w / w.sum()

    def adopt(self, members, demos, dt):
        """Take ``members`` (``{family: fitted model}``, trained on ``demos`` at ``dt``) as the fitted blend."""
        names, W, edges = self._weight_table()
        if np.any(W < 0) or not np.all(np.isfinite(W)) or np.any(W.sum(axis=1) <= 0):
            raise ValueError("weights must be finite, non-negative and not all zero in any band")
        if isinstance(self.remaining, str) and self.remaining not in names:
            raise ValueError(f"remaining={self.remaining!r} names no member of the blend (members: {names}): the "
                             "shared end is read from a member's own timing, so that member must be in weights")
        w_past = self._past_weights(names)
        self.members_ = {m: members[m] for m in names}
        share_phase_models(self.members_)  # one learned phase estimate a frame for the members that read the same
        self._derived = DerivedCache()  # values derived from the fitted state (the variance model's arrays)
        self._names, self._W, self._edges = names, W / W.sum(axis=1, keepdims=True), edges
        #: the real-time weights (look-ahead 0), which place the blend in time after every frame
        self._w_now = weights_at(np.zeros(1), edges, self._W)[0]
        #: the weights of the robot's past over the members (None: the real-time weights there)
        self._w_past = w_past
        #: the normalised weights C-contiguous, as the compiled ``blend.weights_on`` reads them
        self._W_table = np.ascontiguousarray(self._W)
        #: the bands' middles, between which :func:`weights_at` interpolates (computed once, not per frame)
        self._mids = 0.5 * (np.concatenate([[0.0], edges[:-1]]) + edges) if len(edges) > 1 else None
        #: the members weighted somewhere on a grid after now, before now, or on both sides (None: read from the
        #: weights of each prediction)
        self._active_by_side = self._members_by_side()
        self.observed_dofs_ = [int(i) for i in self.observed_dofs]
        self.dt_ = float(dt)
        self.mean_duration_ = float(np.mean([len(d) - 1 for d in demos])) * self.dt_
        self.n_dofs_ = int(np.asarray(demos[0]).shape[1])
        self._set_controlled()

    def _members_by_side(self) -> tuple[list[int], list[int], list[int]] | None:
        """``(after, past, both)``: the indices of the members with a nonzero weight at some point of a prediction's
        grid whose points all lie after now (``u >= s``), all before now (``u < s``, weighted by ``past``), or on
        both sides; None when a member's weight after now may be 0 at some look-ahead and not at another (each
        prediction's weights then say which members are weighted, :meth:`_active`).

        A member's weight after now is its bands' weights (normalised, at most 1) read at the look-ahead by
        :func:`numpy.interp`'s operations, clipped at 0 and divided by the members' sum (at most their number, so
        a positive weight stays positive): exactly 0 at every look-ahead when it is 0 in every band, and positive
        at every finite look-ahead when it is at least :data:`_SURE_WEIGHT` in every band.  The rule needs the
        bands' middles increasing, as the interpolation reads them."""
        W = self._W
        if self._mids is not None and W.shape[1] > 1 and not np.all(np.diff(self._mids) > 0):
            return None
        after = np.all(W >= _SURE_WEIGHT, axis=0)
        if not np.all(after | np.all(W == 0.0, axis=0)):
            return None
        past = after if self._w_past is None else self._w_past != 0.0  # without past weights: never read (n_past 0)
        return (np.flatnonzero(after).tolist(), np.flatnonzero(past).tolist(),
                np.flatnonzero(after | past).tolist())

    def _set_controlled(self) -> None:
        """``controlled_dofs_``: every column not observed (what each prediction carries, listed once)."""
        seen = set(self.observed_dofs_)
        self.controlled_dofs_ = [i for i in range(self.n_dofs_) if i not in seen]

    def fit(self, demos, dt: float | None = None, times=None, columns=None):
        """Fit every member on ``demos`` (the weights and scales are kept); ``dt``, ``times`` and ``columns`` as
        :meth:`interprim.models.base.Predictor.fit` takes them."""
        data = training_set(demos, dt, times=times, columns=columns)
        train, dt = list(data.arrays), data.dt
        bad = [m for m in self.weights if m not in registry.FAMILIES]
        if bad or not self.weights:
            raise ValueError(f"weights must name some of {list(registry.FAMILIES)}, got {list(self.weights)!r}")
        make = registry.factories(list(self.weights), registry.Settings(
            tuple(self.observed_dofs), n_basis=self.n_basis, smoothing_window=self.smoothing_window,
            horizon=float(self.horizon)))
        self.adopt({m: make[m]().fit(train, dt=dt) for m in self.weights}, train, dt)
        return self

    def weights_at(self, ahead) -> np.ndarray:
        """The blend's weights ``(len(ahead), members)`` at ``ahead`` seconds after now
        (:func:`~interprim.model_selection.stacking.weights_at`)."""
        self._check_fitted("weights_at")
        return weights_at(np.atleast_1d(ahead), self._edges, self._W)

    def variance(self, spread, ahead):
        """``a * spread + b`` with the variance model at ``ahead`` seconds after now (held at the ends)."""
        model = self.variance_tables()
        if model is None:
            return spread
        steps, a, b = model
        return interp_columns(ahead, steps, a) * spread + interp_columns(ahead, steps, b)

    def variance_tables(self):
        """``(steps, a, b)`` arrays of the variance model (``scales``; None without one), converted from the stored
        lists once and again only when ``scales`` or ``horizon`` is replaced (a prediction's std reads them)."""
        derived = self.__dict__.get("_derived")
        if derived is None:  # not fitted: nothing kept
            return self._build_variance_model()
        return derived.get_or_build("variance_model", (self.scales, self.horizon), self._build_variance_model)

    def _build_variance_model(self):
        """``(steps, a, b)`` of ``scales`` as contiguous arrays (None without a variance model)."""
        model = None
        if self.scales:
            a = np.asarray(self.scales["a"], dtype=np.float64)
            b = np.asarray(self.scales["b"], dtype=np.float64)
            if "t" in self.scales:
                steps = np.asarray(self.scales["t"], dtype=np.float64)
            else:
                steps = np.arange(1, a.shape[0] + 1) * (float(self.horizon) / a.shape[0])
            model = (np.ascontiguousarray(steps), np.ascontiguousarray(a), np.ascontiguousarray(b))
        return model

    def combine(self, preds: dict, n_frames: int, n_grid: int | None = None):
        """The blended prediction of the members' predictions ``{family: pred}`` after ``n_frames`` observed frames
        (a :class:`~interprim.models.grid.GridPrediction` whose std is computed when first asked for).

        Called after every streamed frame, so it works on scalars where it can and reads a member tabulated on the
        grid itself without interpolating it (the same numbers as the general formulas, see the comments)."""
        n_grid = self.N_GRID if n_grid is None else int(n_grid)
        names = self._names
        w0 = self._w_now
        dt, mean_dur = self.dt_, self.mean_duration_
        timing = [place_in_time(preds[m], n_frames, dt, mean_dur) for m in names]
        sv, dv = zip(*timing)
        s_all, d_all = np.array(sv), np.array(dv)  # what the placing of the members reads, made once
        s = float(w0.dot(s_all))  # numpy.dot's product (the array's method: no dispatch)
        D = float(w0.dot(d_all))
        R = None
        if isinstance(self.remaining, str):  # one shared end: a member's own (long_range.pace_remaining)
            sp, Dp = timing[names.index(self.remaining)]
            R = max(1.0 - sp, 0.0) * Dp
        elif self.remaining is not None:  # one shared end beyond the real-time band (long_range.remaining_duration)
            # remaining_duration's operations for one case: Rb = w0 . (max(1 - s_m, 0) D_m), Rc = max(mean - t, 0)
            Rb = float(w0.dot([max(1.0 - a, 0.0) * b for a, b in timing]))
            Rc = max(mean_dur - (n_frames - 1) * dt, 0.0)
            R = max(Rc + float(self.remaining) * (Rb - Rc), 0.0)
        if R is not None:
            R = max(R, float(self.horizon))  # the real-time band is the members' own (long_range.member_units)
            if s < 1.0 - 1e-9:  # the blend's normalised time ends where the members end
                D = R / (1.0 - s)
        u = unit_grid(n_grid)
        zeros = -1
        if self._mids is not None and self._W.shape[1] > 1:  # weights per band: the look-ahead and the weights
            kernel = _registry.kernel("blend.weights_on")
            if kernel is not None:
                ahead, W = np.empty(n_grid), np.empty((n_grid, self._W.shape[1]))
                zeros = kernel(u, s, D, self._mids, self._W_table, ahead, W)
            if zeros < 0:
                ahead, W, zeros = weights_on_np(u, s, D, self._mids, self._W)
        else:
            ahead = (u - s) * D
            np.maximum(ahead, 0.0, out=ahead)
            W = self._weights_on(ahead)  # (n_grid, M)
        n_past = 0
        if self._w_past is not None and s > 0.0:  # the robot's past (u < s) by its own weights
            n_past = int(u.searchsorted(s))  # the points u < s: the grid increases, they are its first n_past
            W[:n_past] = self._w_past
        # a member with no weight at any point of this prediction (e.g. one weighted in the real-time band alone,
        # once the rest of the movement is shorter than it) is not read: its trajectory is not computed
        active = self._active(W, n_past, s, D)
        if len(active) < len(names):
            W = W[:, active]
            s_all, d_all = s_all[active], d_all[active]
        grids = np.empty((len(active), n_grid, self.n_dofs_))  # each member read on the grid straight into its row
        for k, i in enumerate(active):
            grids[k] = _on_grid(preds[names[i]], u)
        h = float(self.horizon)
        Rv = np.nan if R is None else float(R)
        kernel = _registry.kernel("blend.place_members")
        Y = np.empty_like(grids)
        mean = np.empty((n_grid, self.n_dofs_))
        if kernel is None or not kernel(u, ahead, s_all, d_all, s, Rv, h, grids, np.ascontiguousarray(W), Y, mean,
                                        np.empty(n_grid)):
            Y, mean = place_members_np(u, ahead, s_all, d_all, s, Rv, h, grids, W)
        return BlendPrediction(self, u, mean, Y, W, ahead, phase=s, duration=D, n_observed=n_frames)

    def _active(self, W, n_past: int, s: float, D: float) -> list[int]:
        """The indices of the members with a nonzero weight at some point of ``W`` (n, M), the weights of a
        prediction (phase ``s``, duration ``D``) whose first ``n_past`` points are before now; every member when
        no weight is 0.  Read from the members' weights in the bands (:meth:`_members_by_side`) when ``s`` and ``D``
        are finite (no look-ahead is NaN), else from ``W``."""
        n = W.shape[0]
        sets = self._active_by_side
        if sets is not None and n > 0 and math.isfinite(s) and math.isfinite(D):
            return sets[0] if n_past == 0 else sets[1] if n_past == n else sets[2]
        if np.count_nonzero(W) == W.size:
            return list(range(W.shape[1]))
        return np.flatnonzero(W.any(axis=0)).tolist()

    def _weights_on(self, ahead) -> np.ndarray:
        """:func:`~interprim.model_selection.stacking.weights_at` of the fitted weights at ``ahead`` (the same
        operations, with the bands' middles computed once)."""
        if self._mids is None or self._W.shape[1] == 1:  # one set of weights (a single member's: 1 everywhere)
            return np.broadcast_to(self._W[0], (ahead.size, self._W.shape[1])).copy()
        return _band_weights(ahead, self._mids, self._W)

    @staticmethod
    def frame_overhead(n_members: int, n_dofs: int) -> float:
        """Modelled seconds a blend of ``n_members`` members adds to their own streamed frames (placing each in
        time, the weights over the look-ahead, reading each member on the common grid, combining): the same
        deterministic cost model as :func:`interprim.models.registry.frame_cost`, calibrated with it
        (``python -m benchmarks.auto --calibrate``); 0 for a single family, which is not blended."""
        if n_members < 2:
            return 0.0
        a, b, c = _OVERHEAD_US
        return (a + b * n_members + c * n_members * n_dofs) * 1e-6

    @staticmethod
    def predict_overhead(n_members: int, n_dofs: int) -> float:
        """Modelled seconds a blend of ``n_members`` members adds to their own ``predict`` calls (the prefix checked
        once, the combination): :func:`interprim.models.registry.predict_cost`'s model, calibrated with it; 0 for a
        single family."""
        if n_members < 2:
            return 0.0
        a, b, c = _PREDICT_OVERHEAD_US
        return (a + b * n_members + c * n_members * n_dofs) * 1e-6

    def predict(self, partial, **kwargs):
        """The blend of every member's prediction for the observed frames ``partial`` ``(M, n_observed)``."""
        self._check_fitted("predict")
        if kwargs:
            raise TypeError(f"Blend.predict takes only the observed frames, got {sorted(kwargs)}")
        x = np.asarray(partial, dtype=np.float64)
        preds, checked = {}, None
        for m, est in self.members_.items():
            fast = getattr(est, "predict_checked", None)  # a member's prediction of checked frames, unmarked
            if fast is None:
                preds[m] = est.predict(x)
                continue
            if checked is None:  # checked once, as the members check it (the combination reads no member's mark)
                checked = as_2d_finite(x, "partial", n_cols=len(self.observed_dofs_), min_rows=1)
            preds[m] = fast(checked)
        return self.combine(preds, len(x))

    def stream(self, robot_state=None):
        """An online blend: every member's own stream, combined after each frame (equals :meth:`predict`)."""
        self._check_fitted("stream")
        if robot_state is not None:
            raise ValueError("robot_state: a blend does not roll out from a robot state; pass None")
        return BlendStream(self)

    def to_state(self):
        """``(arrays, meta)``: every member's state, prefixed by its family."""
        self._check_fitted("to_state")
        arrays, members = {}, {}
        for m, est in self.members_.items():
            if registry.class_named(type(est).__name__) is not type(est):
                raise ValueError(f"member {m!r} is a {type(est).__name__}, not a family of interprim's registry: a "
                                 "model file names registered families only (add a Family row to "
                                 "interprim.models.registry.FAMILIES to save it)")
            a, meta = est.to_state()
            arrays.update({f"{m}__{k}": v for k, v in a.items()})
            members[m] = {"class": type(est).__name__, "params": est.json_params(), "state": meta,
                          "version": int(est.STATE_VERSION)}
        return arrays, {"members": members, "dt": self.dt_, "mean_duration": self.mean_duration_,
                        "n_dofs": self.n_dofs_, "observed_dofs_": self.observed_dofs_}

    def load_state(self, arrays, meta):
        """Restore the state written by :meth:`to_state`."""
        if not isinstance(self.weights, dict) or not self.weights:
            check.fail("params.weights", self.weights, "not a {member: weight} record")
        n_dofs = check.integer("n_dofs", meta["n_dofs"], 1, check.MAX_GRID)
        obs = check.columns("observed_dofs_", meta["observed_dofs_"], n_dofs)
        if check.columns("params.observed_dofs", self.observed_dofs, n_dofs) != obs:
            check.fail("params.observed_dofs", self.observed_dofs, f"not the fitted observed_dofs_ {obs}")
        dt = check.number("dt", meta["dt"], positive=True)
        mean_duration = check.number("mean_duration", meta["mean_duration"], positive=True)
        members = {}
        for m in self.weights:
            info = meta["members"][m]
            inner = {k[len(m) + 2:]: v for k, v in arrays.items() if k.startswith(f"{m}__")}
            try:
                est = member_from_state(info["class"], info["params"], inner, info["state"])
            except ModelFileError as exc:
                raise check.prefixed(f"member {m!r}: ", exc) from None
            if getattr(est, "n_dofs_", n_dofs) != n_dofs or list(est.observed_dofs_) != obs:
                check.fail(f"members.{m}", info["class"], f"a member of observed columns {est.observed_dofs_} "
                           f"of {getattr(est, 'n_dofs_', '?')}, not the blend's {obs} of {n_dofs}")
            members[m] = est
        self._check_scales(n_dofs)
        self.adopt(members, [np.zeros((2, n_dofs))], dt)
        self.mean_duration_ = mean_duration
        self.observed_dofs_ = obs
        self._set_controlled()

    def _check_scales(self, n_dofs: int) -> None:
        """The variance model ``scales`` of a model file (``a``, ``b``: ``(H, n_dofs)`` finite, not negative; ``t``:
        ``(H,)`` increasing positive seconds) and ``horizon``, checked before a prediction's std reads them."""
        check.number("params.horizon", self.horizon, positive=True)
        if self.bands is not None:  # the look-ahead bands' edges (seconds), the last may be inf
            edges = np.asarray(self.bands, dtype=np.float64) if isinstance(self.bands, list) else None
            if edges is None or edges.ndim != 1 or edges.size == 0 or np.any(np.isnan(edges)) \
                    or np.any(edges <= 0) or np.any(np.diff(edges) <= 0):
                check.fail("params.bands", self.bands, "not increasing positive look-ahead edges")
        sc = self.scales
        if not sc:
            return
        if not isinstance(sc, dict) or not {"a", "b"} <= set(sc):
            check.fail("params.scales", sc, "not a variance model {'a': ..., 'b': ...}")
        a = check.array("params.scales.a", sc["a"], (None, n_dofs), nonneg=True)
        check.array("params.scales.b", sc["b"], a.shape, nonneg=True)
        if a.shape[0] == 0:
            check.fail("params.scales.a", sc["a"], "an empty variance model")
        if "t" in sc:
            t = check.array("params.scales.t", sc["t"], (a.shape[0],), positive=True)
            if np.any(np.diff(t) <= 0):
                check.fail("params.scales.t", sc["t"], "not increasing")

    def __repr__(self):
        w = ", ".join(f"{m} {np.atleast_1d(x)[0]:.2f}" for m, x in self.weights.items())
        return f"Blend({w}{'' if self.bands is None else f'; {len(self.bands)} look-ahead bands'})"


class BlendPrediction(GridPrediction):
    """The blend's prediction: its mean on the grid, its std (the members' weighted disagreement through the
    variance model) computed when first asked for."""

    def __init__(self, blend, u, mean, Y, W, ahead, phase, duration, n_observed):
        super().__init__(u, mean, None, phase=phase, observed_dofs=blend.observed_dofs_,
                         controlled_dofs=blend.controlled_dofs_, method="blend",
                         duration=duration, mean_duration=blend.mean_duration_, n_observed=n_observed)
        self._parts = (blend, Y, W, ahead)

    @property
    def std_values(self):
        """The predictive std on the grid (the variance model at each point's look-ahead), computed once."""
        parts = self.__dict__.get("_parts")
        if parts is None:
            return self.__dict__.get("_std")
        blend, Y, W, ahead = parts
        model = blend.variance_tables()
        steps, a, b = (_NO_STEPS, _NO_SCALE, _NO_SCALE) if model is None else model
        kernel = _registry.kernel("blend.spread_std")
        std = np.empty_like(self.mean)
        positive = -1 if kernel is None else kernel(Y, self.mean, np.ascontiguousarray(W), ahead, steps, a, b,
                                                    model is not None, std)
        if positive < 0:
            std, positive = spread_std_np(Y, self.mean, W, ahead, steps, a, b, model is not None)
        self.__dict__["_std"] = std if positive > 0 else None
        self.__dict__["_parts"] = None
        return self.__dict__["_std"]

    @std_values.setter
    def std_values(self, value):
        self.__dict__["_std"] = value


#: the variance model's placeholders for a blend without one (the spread alone)
_NO_STEPS = np.array([0.0, 1.0])
_NO_SCALE = np.zeros((2, 1))


class BlendStream(BaseStream):
    """Online :class:`Blend`: one stream per member, combined after every frame (``update`` equals ``predict``;
    ``extend`` is :class:`~interprim.models.base.BaseStream`'s, frame by frame)."""

    def __init__(self, blend: Blend):
        self.blend = blend
        self.streams = {m: est.stream() for m, est in blend.members_.items()}
        self._n = 0

    @property
    def n_frames(self) -> int:
        """Frames received since the stream was created or last reset."""
        return self._n

    def reset(self, robot_state=None):
        """Forget all frames (start a new interaction)."""
        for st in self.streams.values():
            st.reset()
        self._n = 0

    def update(self, frame, need_cov: bool = False):
        """Add one observed frame; returns the blended prediction of every frame seen."""
        preds = {m: st.update(frame) for m, st in self.streams.items()}
        self._n += 1
        return self.blend.combine(preds, self._n)


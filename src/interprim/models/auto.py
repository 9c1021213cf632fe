"""The model chosen on the user's own demonstrations: several families compared on held-out folds, then blended.

:class:`AutoInteraction` (what ``interprim fit`` gives by default) runs the family comparison of
:mod:`interprim.model_selection.stacking` -- the real-time protocol of :mod:`interprim.model_selection.realtime` in a
``folds``-fold cross-validation on the *training* demonstrations -- for each candidate family: by default the
Interaction Primitive with the library's defaults (``ip``), :class:`~interprim.models.learned.LearnedInteraction`
(``learned``), the kernel-weighted demonstrations (``kernel``, :class:`~interprim.models.kernel.KernelDemonstrations`),
the nearest demonstration (``nn``) and the mean demonstration at the mean speed (``prior``); a user's own family joins
as a ``(name, factory)`` pair.  From the held-out predictions it fits a :class:`~interprim.models.blend.Blend`: the
convex weights that minimise the protocol's own error per look-ahead band (stacking; a choice of one family made on
12-20 demonstrations proved noisy: on the project's hold-out it picked a worse family on one NuiSI interaction of
six), and a variance fitted to the held-out errors step by step over the look-ahead, within a frame budget (a
multiple of the Interaction Primitive's streamed frame on the same data, by a deterministic cost model: see
``frame_budget``).  ``combine="best"`` keeps the family with the smallest held-out error alone.  Predictions,
streams and model files follow :mod:`interprim.models.base`; ``selection_`` says what was compared and chosen, and by
how much.
"""

from __future__ import annotations

import dataclasses
import warnings
from collections.abc import Callable

import numpy as np

from ..core import state_checks as check
from ..core.blas import one_blas_thread
from ..core.cache import DerivedCache, records_unused, shared_fits, std_unused
from ..core.cv import DEFAULT_HORIZON
from ..core.errors import ModelFileError, PaceWarning
from ..core.input_range import CHECKED_BY_CALLER, duration_range, fit_input_range, mark
from ..core.progress import Progress
from ..model_selection import long_range, memory, stacking
from . import registry
from .base import CheckedStream, Predictor, training_set
from .blend import Blend, member_from_state
from .primitive.estimator import InteractionPrimitive
from .training import pace_trend

__all__ = ["AutoInteraction", "CANDIDATES", "DEFAULT_FRAME_BUDGET", "DEFAULT_FRAME_BUDGET_FLOOR",
           "DEFAULT_PREDICT_BUDGET_FLOOR", "Budget", "budget_phase",
           "budget_coupling", "recording_factory"]

#: The families compared by default (:data:`interprim.models.registry.CANDIDATES`).
CANDIDATES = registry.CANDIDATES

#: The default frame budget: a blend's modelled streamed frame at most this many times the Interaction Primitive's
#: (issue 37's target: a frame at most 3x the IP's, on any data).
DEFAULT_FRAME_BUDGET = 3.0
#: seconds (modelled) a streamed frame may always cost, however cheap the Interaction Primitive is on the data: a
#: robot's control loop plans in milliseconds, and on small data sets 3x the IP's frame is a fraction of one
DEFAULT_FRAME_BUDGET_FLOOR = 0.001
#: seconds (modelled) a ``predict`` call (from half the movement) may always cost: a call outside the control loop
DEFAULT_PREDICT_BUDGET_FLOOR = 0.002

#: Where ``selection_["cost"]["ip_phase"]``, the phase that times the frame budget's Interaction Primitive, comes from.
INNER_FOLDS = "inner folds"
ALL_DEMONSTRATIONS = "fitted on all the demonstrations"


def recording_factory(factory, built: list):
    """``factory``, appending every estimator it builds to ``built`` (the inner folds' fits, read after them)."""
    def build():
        est = factory()
        built.append(est)
        return est
    return build


def _over_budget(costs: dict, names: list, budget: float) -> dict:
    """``{family: modelled frame}`` of the families ``names`` whose frame alone exceeds ``budget`` (none of them can
    be in a blend within it); the cheapest stays when none fits."""
    over = {m: float(costs[m]) for m in names if costs.get(m) is not None and costs[m] > budget}
    if over and len(over) == len(names):
        over.pop(min(over, key=lambda m: (over[m], names.index(m))))
    return over


def budget_phase(fits, k: int) -> str | None:
    """The Interaction Primitive's phase for the frame budget's yardstick (:class:`~interprim.models.registry.
    FrameSizes`), read from its fits on the ``k`` inner training folds ``fits``: ``"learned"`` when more than half of
    them chose the learned phase, else the phase most of the others chose (the first fold's on a tie); None when
    fewer than ``k`` fits were made (the IP could not be fitted on every fold, or was not compared).

    The cost model distinguishes the learned phase from the others (2-3x cheaper, registry's ``ip-learned``); its
    own cross-validation chooses it (``phase_method="cv"``), on all the demonstrations much as on two thirds of
    them: on the benchmark's three data sets the three inner folds chose what the fit on all of them chose.
    """
    return _inner_choice([f.phase_method_used() for f in fits if getattr(f, "fitted_", None) is not None], k,
                         "learned")


def _inner_choice(chosen: list, k: int, first: str) -> str | None:
    """What the ``k`` inner-fold fits ``chosen`` (one choice each) say: ``first`` when more than half of them chose
    it, else the choice most of the others made (the first fold's on a tie); None when fewer than ``k`` made one."""
    if len(chosen) < k:
        return None
    if 2 * chosen.count(first) > len(chosen):
        return first
    others = [c for c in chosen if c != first]
    return max(others, key=lambda c: (others.count(c), -others.index(c)))


@dataclasses.dataclass(frozen=True)
class Budget:
    """The frame budget of :meth:`AutoInteraction.budget_model` on one data set.  ``cost(members)`` is what the
    budget bounds, in seconds of a streamed frame: a blend's modelled frame (``frame_of``) or, if more, its
    modelled ``predict`` (``predict_of``) as a share of the predict's budget, times ``budget`` (so that ``cost <=
    budget`` bounds both); ``costs``: ``cost`` of each family alone (None: not costed); ``budget``,
    ``predict_budget``: seconds (None: no budget); ``ip_frame``, ``ip_predict``: the Interaction Primitive's."""

    costs: dict
    cost: Callable[[list], float]
    ip_frame: float
    budget: float | None
    frame_of: Callable[[list], float]
    predict_of: Callable[[list], float]
    ip_predict: float
    predict_budget: float | None


def budget_coupling(fits, k: int) -> str | None:
    """The learned interaction's coupling for the frame budget (:class:`~interprim.models.registry.FrameSizes`),
    read from its fits on the ``k`` inner training folds ``fits``: ``"ppca"`` when more than half of them chose it,
    else the method most of the others chose (the first fold's on a tie); None when fewer than ``k`` fits were made.

    Its own cross-validation chooses the coupling, and the reduced-rank one (``"ppca"``) costs 3-5x a frame of the
    linear smoothers (registry's ``learned-ppca``): on the benchmark's data sets the learned frame measured 0.17 ms
    (ridge), 0.26 ms (a blend of ridge and kernel) and 0.82 ms (ppca) at 30 demonstrations x (7 + 7) DoFs.
    """
    return _inner_choice([f.coupling_.method_ for f in fits if getattr(f, "coupling_", None) is not None], k, "ppca")


class AutoInteraction(Predictor):
    """The model chosen on the user's own demonstrations: several families compared on held-out folds.

    ``fit`` runs the real-time protocol of :mod:`interprim.model_selection.realtime` in a ``folds``-fold
    cross-validation on the *training* demonstrations for each candidate family and then, with ``combine="blend"``
    (the default), fits a convex combination of the families' predictions placed in time, with weights that
    minimise the held-out error (stacking) and a std calibrated to the held-out error step by step over the
    look-ahead (:class:`~interprim.models.blend.Blend`); with ``combine="best"`` it uses the family with the
    smallest held-out error alone.
    Predictions, streams and model files follow :mod:`interprim.models.base`; ``selection_`` says what was chosen and
    by how much.

    Parameters
    ----------
    observed_dofs : sequence of int
        The observed agent's columns.
    candidates : sequence, default CANDIDATES
        Families to compare: names of :data:`interprim.models.registry.FAMILIES` (``ip``, ``learned``,
        ``ip-paper``, ``kernel``, ``nn``, ``prior``, ...; built with this model's settings) or ``(name, factory)``
        pairs, ``factory()`` returning an unfitted :class:`~interprim.models.base.Predictor` of the user's own
        (as scikit-learn's ``StackingRegressor(estimators=...)``); a model file stores a registered family only.
    combine : {"blend", "best"}, default "blend"
        Blend the families, or keep the best one.
    folds : int, default 3
        Folds of the cross-validation (at least 2; fewer demonstrations than folds: leave-one-out).
    horizon : float, default DEFAULT_HORIZON (0.25)
        Seconds ahead scored by the real-time protocol (and over which the blend's std is calibrated).
    stride : int, default 3
        Score every ``stride``-th frame (speed).
    max_prefixes : int or None, default 16
        Score at most this many prefixes of each held-out demonstration (the stride grows for long demonstrations:
        :class:`~interprim.model_selection.realtime.RealTimeConfig` ``max_frames``), so that the fit's cost does not
        grow with the sampling rate; None: every ``stride``-th frame.  The prefixes of one demonstration are
        strongly correlated and the selection's noise is over demonstrations: on the replayed development folds 16
        chose as well as 24 on every yardstick, at 10-20 % less of the fit (docs/evaluation-history.md).
    n_basis : int, default 20
        Basis functions of the Interaction Primitive candidates.
    smoothing_window : int or None
        Savitzky-Golay window of the Interaction Primitive candidates.
    point_dim : int, default 1
        Columns per point in the error (3 for 3-D positions), as in
        :class:`~interprim.model_selection.realtime.RealTimeConfig`.
    progress : bool, default False
        Show the fit's progress (a tqdm bar when installed, else one line per step on stderr); ``interprim fit``
        turns it on.
    frame_budget : float or None, default DEFAULT_FRAME_BUDGET (3.0)
        The most a streamed frame (``stream.update`` + ``trajectory(100)``) may cost, as a multiple of the
        Interaction Primitive's on the same data, or ``frame_budget_floor`` seconds if that is more; and the same
        multiple of the IP's ``predict`` (from half the movement), or ``predict_budget_floor`` seconds if that is
        more (None: no bound).  Costs come from a deterministic cost model
        (:func:`interprim.models.registry.frame_cost`, :func:`~interprim.models.registry.predict_cost`,
        :meth:`~interprim.models.blend.Blend.frame_overhead`: a formula per family and cost class in the sizes of
        the data -- demonstrations, frames, DoFs, basis -- whose constants were calibrated once on an idle machine
        in ``benchmarks/auto.py``), not from timings taken during the fit: one input gives one model whatever the
        machine's load.  Two families' costs depend on what their own cross-validation chooses: the Interaction
        Primitive's on its phase, the learned interaction's on its coupling (the reduced-rank one costs 3-5x the
        linear smoothers).  What most of their inner-fold fits chose times them, and each is fitted on all the
        demonstrations only when the model keeps it (then its own choice times the budget, and the selection is
        made again if that choice is of the other cost class; the fit is an IP fit cheaper when the IP is not
        kept).  A family whose cost alone exceeds the budget is not compared at all (nor fitted: the fit is
        cheaper too); when the best blend exceeds it, the best set of families within it is blended instead
        (:func:`interprim.model_selection.stacking.stack`).  ``selection_["cost"]`` and :meth:`summary` say what
        the model's frame and predict cost and what was left out for the budget.  A user's own family (a
        ``(name, factory)`` pair not named after a registry family) has no cost model: it is not counted, and said
        so.
    frame_budget_floor : float, default DEFAULT_FRAME_BUDGET_FLOOR (0.001)
        Seconds (modelled, on an idle machine) a streamed frame may always cost: the budget is the larger of
        ``frame_budget`` times the Interaction Primitive's frame and this.  Where the IP's frame is a fraction of a
        millisecond (small data sets, few DoFs), a multiple of it would leave out the families that carry the
        accuracy, for a saving no control loop needs; 0 makes the budget purely relative.
    predict_budget_floor : float or None, default DEFAULT_PREDICT_BUDGET_FLOOR (0.002)
        The same for a ``predict`` call (outside the control loop; the aligned families redo a DTW of the whole
        prefix there, which their streams do frame by frame, so that on long recordings their predict, not their
        frame, decides whether they fit).  None: a predict is not bounded (a robot that only streams).

    Attributes
    ----------
    observed_dofs_, controlled_dofs_, n_dofs_, dt_, mean_duration_, columns_
        The two agents' columns, the number of columns, the sampling interval, the mean duration (s) and the
        column names (``None`` without names) of the demonstrations.
    chosen_ : str
        The family with the smallest held-out error (``"blend"`` is not a family: see ``weights_``).
    weights_ : dict
        ``{family: weight}`` of the blend (``{chosen_: 1.0}`` with ``combine="best"``).
    model_ : Predictor
        The model used: a :class:`~interprim.models.blend.Blend` or the chosen family, fitted on all the demonstrations.
        A blend's band comes from its own variance model and its members' means, never from a member's std: an
        Interaction Primitive member is kept without a calibration of its std (``calibrate=False``,
        ``calibration_`` None; measuring it cost a quarter of the Interaction Primitive's own fit), while the
        Interaction Primitive as the whole model keeps its calibration.
    selection_ : dict
        ``chosen``, ``cv_errors`` (``{family: mean held-out real-time error}``, ``inf`` when a family could not be
        fitted on a fold), ``runner_up`` and ``margin`` (its error / the chosen one's), ``vs_prior`` (the chosen
        one's error / the mean demonstration's at the mean speed), ``combine``, ``weights`` and, for a blend,
        ``blend_cv_error`` (in-sample for its weights), ``blend_vs_best``, ``variance_model`` (``a``, ``b`` of
        :meth:`interprim.model_selection.stacking.CrossValidation.blend_scales`) and ``band_level`` (its quantile
        level per agent, chosen by cross-fitting: :func:`interprim.model_selection.stacking.band_level`);
        ``cost``: ``frame`` (the
        model's modelled streamed frame, s), ``ip_frame`` (the Interaction Primitive's on the same data),
        ``frame_budget``, ``budget`` (s), ``predict``, ``ip_predict`` and ``predict_budget`` (the same for a
        ``predict`` from half the movement), the two floors, ``left_out`` and ``left_out_predict`` (``{family:
        its modelled frame / predict}`` of the families left out for the budget), ``not_costed``, ``ip_phase``
        (the phase that times the IP's frame; None without a budget) and ``ip_phase_from`` (``"inner folds"``:
        the phase most of the IP's inner-fold fits chose, the model keeping no IP; ``"fitted on all the
        demonstrations"``: the IP's own, fitted on all of them because the model keeps it or the IP was not
        compared), ``learned_coupling`` and ``learned_coupling_from`` (the same for the coupling that times the
        learned interaction's frame, :func:`budget_coupling`; None when it is not costed by its folds).  ``pace``:
        how the demonstrations' durations change with their order (:func:`~interprim.models.training.pace_trend`;
        a significant trend raises a
        :class:`~interprim.core.errors.PaceWarning` once and :meth:`summary` says it).
    """

    _FITTED = "model_"
    _CHECKS_INPUT = True
    #: 2: the training frames' range (the out-of-range check) and per-look-ahead blend weights
    STATE_VERSION = 2
    CANDIDATES = CANDIDATES

    def __init__(self, observed_dofs, candidates=CANDIDATES, combine: str = "blend", folds: int = 3,
                 horizon: float = DEFAULT_HORIZON, stride: int = 3, n_basis: int = 20, smoothing_window=None,
                 point_dim: int = 1, progress: bool = False, frame_budget: float | None = DEFAULT_FRAME_BUDGET,
                 frame_budget_floor: float = DEFAULT_FRAME_BUDGET_FLOOR,
                 predict_budget_floor: float | None = DEFAULT_PREDICT_BUDGET_FLOOR, max_prefixes: int | None = 16):
        self.observed_dofs = observed_dofs
        self.candidates = candidates
        self.combine = combine
        self.folds = folds
        self.horizon = horizon
        self.stride = stride
        self.n_basis = n_basis
        self.smoothing_window = smoothing_window
        self.point_dim = point_dim
        self.progress = progress
        self.frame_budget = frame_budget
        self.frame_budget_floor = frame_budget_floor
        self.predict_budget_floor = predict_budget_floor
        self.max_prefixes = max_prefixes

    def _check(self):
        known = list(registry.FAMILIES)
        cands = list(self.candidates) if isinstance(self.candidates, (list, tuple)) else None
        bad = [c for c in cands or [] if not (c in known if isinstance(c, str) else (
            isinstance(c, tuple) and len(c) == 2 and isinstance(c[0], str) and callable(c[1])))]
        if bad or not cands:
            raise ValueError(f"candidates must name some of {known} or be (name, factory) pairs, got "
                             f"{self.candidates!r}")
        names = [c if isinstance(c, str) else c[0] for c in cands]
        if len(set(names)) < len(names):
            raise ValueError(f"candidates: each name once, got {names}")
        if self.combine not in stacking.COMBINE:
            raise ValueError(f"combine must be one of {stacking.COMBINE}, got {self.combine!r}")
        if not (isinstance(self.folds, (int, np.integer)) and self.folds >= 2):
            raise ValueError(f"folds must be an integer >= 2, got {self.folds!r}")
        if not (isinstance(self.horizon, (int, float)) and self.horizon > 0):
            raise ValueError(f"horizon must be a positive number of seconds, got {self.horizon!r}")
        if not (isinstance(self.stride, (int, np.integer)) and self.stride >= 1):
            raise ValueError(f"stride must be an integer >= 1, got {self.stride!r}")
        mp = self.max_prefixes
        if mp is not None and not (isinstance(mp, (int, np.integer)) and not isinstance(mp, bool) and mp >= 1):
            raise ValueError(f"max_prefixes must be an integer >= 1 or None, got {mp!r}")
        if not (isinstance(self.point_dim, (int, np.integer)) and self.point_dim >= 1):
            raise ValueError(f"point_dim must be an integer >= 1, got {self.point_dim!r}")
        fb = self.frame_budget
        if fb is not None and not (isinstance(fb, (int, float, np.integer, np.floating)) and not isinstance(fb, bool)
                                   and np.isfinite(fb) and fb > 0):
            raise ValueError(f"frame_budget must be a positive multiple of the Interaction Primitive's frame, or "
                             f"None (no budget), got {fb!r}")
        for name in ("frame_budget_floor", "predict_budget_floor"):
            fl = getattr(self, name)
            if fl is None and name == "predict_budget_floor":  # a predict not bounded
                continue
            if not (isinstance(fl, (int, float, np.integer, np.floating)) and not isinstance(fl, bool)
                    and np.isfinite(fl) and fl >= 0):
                raise ValueError(f"{name} must be a number of seconds >= 0"
                                 f"{' or None' if name == 'predict_budget_floor' else ''}, got {fl!r}")

    def frame_costs(self, sizes: registry.FrameSizes) -> dict:
        """``{candidate: modelled seconds of one streamed frame}`` on data of ``sizes``
        (:func:`interprim.models.registry.frame_cost`; a ``(name, factory)`` pair named after a registry family is
        costed as that family, any other is not: None)."""
        names = [c if isinstance(c, str) else c[0] for c in self.candidates]
        return {m: registry.frame_cost(m, sizes) for m in names}

    def budget_model(self, sizes: registry.FrameSizes, names) -> Budget:
        """The frame budget on data of ``sizes`` for the candidates ``names`` (:class:`Budget`): a blend's modelled
        streamed frame (:meth:`~interprim.models.blend.Blend.frame_overhead` included) within the larger of
        ``frame_budget`` times the IP's and ``frame_budget_floor``, and its modelled ``predict`` (from half the
        movement, :func:`~interprim.models.registry.predict_cost`) within the larger of ``frame_budget`` times the
        IP's and ``predict_budget_floor``."""
        keep = set(names)
        frame = {m: c for m, c in self.frame_costs(sizes).items() if m in keep}
        pred = {m: registry.predict_cost(m, sizes) if c is not None else None for m, c in frame.items()}
        ip_frame, ip_predict = registry.frame_cost("ip", sizes), registry.predict_cost("ip", sizes)
        assert ip_frame is not None and ip_predict is not None  # the registry's ip has a cost model
        budget = predict_budget = None
        if self.frame_budget is not None:
            budget = max(float(self.frame_budget) * ip_frame, float(self.frame_budget_floor))
            if self.predict_budget_floor is not None:
                predict_budget = max(float(self.frame_budget) * ip_predict, float(self.predict_budget_floor))

        def frame_of(members) -> float:
            return float(sum(frame[m] or 0.0 for m in members)) + Blend.frame_overhead(len(members), sizes.n_dofs)

        def predict_of(members) -> float:
            return float(sum(pred[m] or 0.0 for m in members)) + Blend.predict_overhead(len(members), sizes.n_dofs)

        def cost(members) -> float:  # the frame, or the predict's share of its budget in frame seconds if more
            f = frame_of(members)
            if budget is None or predict_budget is None:
                return f
            return max(f, predict_of(members) * budget / predict_budget)

        costs = {m: None if c is None else cost([m]) for m, c in frame.items()}
        return Budget(costs, cost, ip_frame, budget, frame_of, predict_of, ip_predict, predict_budget)

    def _yardstick(self, train, dt, progress):
        """The Interaction Primitive of ``train`` fitted on all of it, as the frame budget's yardstick and, when the
        model keeps it, its ip member (:func:`interprim.models.registry.yardstick_ip`)."""
        with std_unused():  # its std's calibration is measured only if it becomes the whole model (final)
            ref = registry.yardstick_ip(self.settings(), train, dt)
        progress.grow(1)
        progress.step("fitted ip (the frame budget's yardstick)")
        return ref

    def factories(self) -> dict:
        """``{family: factory of an unfitted estimator}`` of the candidates: a registry name built with this model's
        settings (:meth:`settings`), a ``(name, factory)`` pair as given."""
        named = registry.factories([c for c in self.candidates if isinstance(c, str)], self.settings())
        return dict((c, named[c]) if isinstance(c, str) else (c[0], c[1]) for c in self.candidates)

    def json_params(self) -> dict:
        """The parameters as a model file stores them (a ``(name, factory)`` candidate by its name)."""
        import copy

        named = copy.copy(self)
        named.candidates = [c if isinstance(c, str) else c[0] for c in self.candidates]
        return Predictor.json_params(named)

    def settings(self) -> registry.Settings:
        """The settings every member is built with (given once here and passed down to each family)."""
        return registry.Settings(tuple(self.observed_dofs), n_basis=self.n_basis,
                                 smoothing_window=self.smoothing_window, horizon=float(self.horizon))

    @one_blas_thread
    def fit(self, demos, dt: float | None = None, times=None, columns=None):
        """Compare the candidate families on held-out folds of ``demos``, then fit the blend (or the best) on all.

        Parameters
        ----------
        demos : list of ndarray, shape (T_j, D), or Demonstrations
            At least 3 demonstrations (a :class:`~interprim.datasets.Demonstrations` with raw samples gives the
            cross-validation causal prefixes).
        dt : float, optional
            Sampling interval in seconds (default: the Demonstrations' ``dt``, else 0.01).
        times, columns : optional
            Time stamps per demonstration and column names, as :meth:`interprim.models.base.Predictor.fit` takes
            them (read by :func:`~interprim.models.training.training_set`).

        Returns
        -------
        AutoInteraction
            ``self``.
        """
        with shared_fits():  # a fit two families make on the same data is made once (the observed agent's timing)
            return self._fit_families(demos, dt, times, columns)

    def _fit_families(self, demos, dt, times, columns):
        """:meth:`fit`'s work (inside :func:`~interprim.core.cache.shared_fits`)."""
        self._check()
        data = training_set(demos, dt, times=times, columns=columns)
        train, dt, cols = list(data.arrays), data.dt, None if data.columns is None else list(data.columns)
        n = len(train)
        if n < 3:
            raise ValueError(f"AutoInteraction needs at least 3 demonstrations to compare families, got {n}")
        # a Demonstrations sampled at a common interval keeps its raw samples (the training set's ``raw`` and
        # ``times``: causal prefixes in the inner CV); irregular stamps were resampled above and the CV sees the
        # resampled frames
        cv_demos = data if data.raw is not None and data.times is not None else train
        factories = self.factories()
        make = dict(factories)  # the families compared (the ip's factory recording its inner-fold fits)
        sizes = registry.FrameSizes(n, float(np.mean([len(d) for d in train])), len(self.observed_dofs),
                                    int(train[0].shape[1]), int(self.n_basis))
        progress = Progress(self.progress, len(make))
        ref = None  # the Interaction Primitive fitted on all the demonstrations, when fitted
        ip_folds: list = []  # the Interaction Primitives of the inner folds, when the registry's ip is compared
        phase_from = None  # where the budget's IP phase comes from (None: no budget)
        budgeted = self.frame_budget is not None and len(make) > 1
        if budgeted and "ip" in make and "ip" in self.candidates:
            # the budget's yardstick is the IP's frame, which its phase (chosen by its own cross-validation) moves by
            # up to 2.5x: its inner-fold fits say which phase (budget_phase), so the IP is fitted on all the
            # demonstrations only when the model keeps it; until the folds tell, its dearer phase
            make["ip"] = recording_factory(make["ip"], ip_folds)
            sizes = dataclasses.replace(sizes, phase="likelihood")
        elif budgeted:
            ref = self._yardstick(train, dt, progress)
            sizes = dataclasses.replace(sizes, phase=ref.phase_method_used())
            phase_from = ALL_DEMONSTRATIONS
        learned_ref = None  # the learned interaction fitted on all the demonstrations, when fitted for the budget
        learned_folds: list = []  # its fits on the inner folds, when the registry's learned is compared
        coupling_from = None  # where the budget's learned coupling comes from (None: assumed, its dearer class)
        if budgeted and "learned" in make:  # (a user's own family of that name without a coupling: its dearer)
            # the same for the learned interaction, whose coupling (its own cross-validation's choice) moves its
            # frame by 3-5x: until its inner folds tell, its cheaper one (no family is left out uncompared for a
            # cost it may not have)
            make["learned"] = recording_factory(make["learned"], learned_folds)
            sizes = dataclasses.replace(sizes, coupling="ridge")
        bm = self.budget_model(sizes, list(make))
        costs, cost, budget = bm.costs, bm.cost, bm.budget

        def final(m, member: bool = False):
            """Family ``m`` fitted on all the demonstrations (the yardstick IP when it is the registry's ip): the
            model itself, or with ``member`` a member of the blend.  A blend's band comes from its own variance
            model and its members' means (:class:`~interprim.models.blend.BlendPrediction`): a member's own std is
            never read, so an Interaction Primitive member carries no calibration of its std, and says so
            (:meth:`~interprim.models.primitive.estimator.InteractionPrimitive.without_calibration`:
            ``calibrate=False``, ``calibration_`` None, in its model file too); its means are the calibrated fit's.
            The model alone keeps the calibration it is fitted with."""
            if m == "learned" and learned_ref is not None:  # fitted on all the demonstrations for the budget
                return learned_ref
            reuse = m == "ip" and ref is not None and "ip" in self.candidates
            if not member:
                if reuse:
                    ref.fitted_.measure_deferred()  # in the fit, as an eager fit measures it
                    return ref
                return factories[m]().fit(train, dt=dt)
            est = ref if reuse else factories[m]()
            if not isinstance(est, InteractionPrimitive):
                return est.fit(train, dt=dt)
            if not reuse:
                with std_unused():  # the calibration is deferred, then dropped unmeasured
                    est.fit(train, dt=dt)
            return est.without_calibration()

        left_out = {}
        if budget is not None and len(make) > 1:
            # a family whose frame alone exceeds the budget cannot be in any blend within it: it is neither
            # compared nor fitted (the fit's cost falls with it); the cheapest family stays if none fits
            left_out = _over_budget(costs, list(make), budget)
            make = {m: f for m, f in make.items() if m not in left_out}
            progress.grow(-len(left_out))  # not compared: fewer steps than announced
        cfg = stacking.scoring_config(float(self.horizon), train, dt, stride=int(self.stride),
                                      point_dim=int(self.point_dim),
                                      max_frames=None if self.max_prefixes is None else int(self.max_prefixes))
        cv_all = None
        if len(make) > 1:
            # bounded before it is expanded: the held-out predictions of every family, case and step ahead
            memory.check_memory(len(make), [len(d) for d in train], cfg, dt, int(train[0].shape[1]))
            # looked up at call time (the leakage test spies on stacking.CrossValidation); its fits are scored and
            # discarded: their records of how they chose (selection_) are not read
            with records_unused():
                cv_all = stacking.CrossValidation(make, cv_demos, self.observed_dofs, dt, cfg,
                                                  k=min(int(self.folds), n), horizon=float(self.horizon),
                                                  progress=progress)
        if budgeted and ref is None:
            phase = budget_phase(ip_folds, min(int(self.folds), n))
            phase_from = INNER_FOLDS
            if phase is None:  # the IP was not fitted on every inner fold (or not compared): fitted on all
                ref = self._yardstick(train, dt, progress)
                phase, phase_from = ref.phase_method_used(), ALL_DEMONSTRATIONS
            sizes = dataclasses.replace(sizes, phase=phase)
        if budgeted and learned_folds:
            coupling = budget_coupling(learned_folds, min(int(self.folds), n))
            # not fitted on every inner fold (then not compared): its dearer coupling, should it be kept
            sizes = dataclasses.replace(sizes, coupling="ppca" if coupling is None else coupling)
            coupling_from = None if coupling is None else INNER_FOLDS
        for _ in range(3):  # at most once more for each of the IP and the learned interaction the model keeps
            if budgeted:
                bm = self.budget_model(sizes, list(costs))
                costs, cost, budget = bm.costs, bm.cost, bm.budget
            compared, cv, over = make, cv_all, {}
            if cv_all is not None and budget is not None:  # compared under the dearer phase's budget, over this one
                over = _over_budget(costs, list(make), budget)
                compared = {m: f for m, f in make.items() if m not in over}
                cv = cv_all.subset([m for m in cv_all.errors if m not in over]) if over else cv_all
            if cv is None or len(compared) == 1:  # nothing to compare: the one family, fitted (column names kept)
                chosen = next(iter(compared))
                selection = stacking.choice_record(chosen, {chosen: float("nan")})
                cv = None
            else:
                chosen, selection = stacking.choice(cv, list(compared))
                if cv.why:
                    selection["not_compared"] = dict(cv.why)
            fitted = remaining = None
            if self.combine == "blend" and cv is not None and len(cv.names) > 1:
                # the variance model is fitted once, after the long-range choice has set the weights
                fitted = stacking.stack(cv, float(self.horizon), cost=cost, budget=budget, scales=False)
                # the remaining duration and the weights beyond the real-time band, chosen on the rest of the movement
                fitted, remaining = long_range.refine(cv, fitted, float(self.horizon), cost=cost, budget=budget)
            keeps = fitted.names if fitted is not None else [chosen]
            same = True  # the members kept cost what the budget assumed: the selection stands
            if phase_from == INNER_FOLDS and "ip" in keeps:
                # the model keeps the IP: fitted on all the demonstrations now (it is needed anyway), its own phase
                # is the budget's; when it is not the phase its inner folds chose, the selection is made again
                ref = self._yardstick(train, dt, progress)
                own = dataclasses.replace(sizes, phase=ref.phase_method_used())
                same = registry.same_cost_class("ip", sizes, own)
                phase_from, sizes = ALL_DEMONSTRATIONS, own
            if coupling_from == INNER_FOLDS and "learned" in keeps:  # the same for the learned coupling
                learned_ref = factories["learned"]().fit(train, dt=dt)
                progress.grow(1)
                progress.step("fitted learned (its coupling times the frame budget)")
                own = dataclasses.replace(sizes, coupling=learned_ref.coupling_.method_)
                same = same and registry.same_cost_class("learned", sizes, own)
                coupling_from, sizes = ALL_DEMONSTRATIONS, own
            if same:
                break
        left_out = {**left_out, **over}
        if fitted is not None:
            info = fitted.record
            progress.grow(len(fitted.names))
            members = {}
            for m in fitted.names:
                members[m] = final(m, member=True)
                progress.step(f"fitted {m}")
            self.model_ = Blend.from_fitted(self.observed_dofs, members, fitted.band_weights, fitted.scales, train,
                                            dt, float(self.horizon), bands=fitted.edges, n_basis=self.n_basis,
                                            smoothing_window=self.smoothing_window, remaining=remaining,
                                            past=info.get("past_weights"))
            weights = info["weights"]
            selection.update(combine="blend", **info)
            best = selection["cv_errors"][chosen]
            selection["blend_vs_best"] = selection["blend_cv_error"] / best if best > 0 else float("nan")
        else:
            progress.grow(1)
            self.model_ = final(chosen)
            progress.step(f"fitted {chosen}")
            weights = {chosen: 1.0}
            selection.update(combine="best", weights=weights)
        kept = list(weights)
        record = selection.pop("cost", {})
        left_all = {**left_out, **record.get("left_out", {})}
        selection["cost"] = {"frame": bm.frame_of(kept), "ip_frame": bm.ip_frame, "frame_budget": self.frame_budget,
                             "frame_budget_floor": float(self.frame_budget_floor), "budget": budget,
                             "predict_budget_floor": (None if self.predict_budget_floor is None
                                                      else float(self.predict_budget_floor)),
                             "predict": bm.predict_of(kept), "ip_predict": bm.ip_predict,
                             "predict_budget": bm.predict_budget,
                             "left_out": {m: bm.frame_of([m]) for m in left_all},
                             "left_out_predict": {m: bm.predict_of([m]) for m in left_all},
                             "not_costed": [m for m in kept if costs.get(m) is None],
                             "ip_phase": None if phase_from is None else sizes.phase, "ip_phase_from": phase_from,
                             "learned_coupling": None if coupling_from is None else sizes.coupling,
                             "learned_coupling_from": coupling_from}
        progress.close()
        pace = pace_trend([(len(d) - 1) * dt for d in train])
        selection["pace"] = pace
        if pace is not None and pace["significant"]:
            # said of the caller of fit (past its wrapper and fit itself)
            warnings.warn(PaceWarning(pace_message(pace)), stacklevel=4)
        dt = float(dt)
        self.chosen_ = chosen
        self.weights_ = weights
        self.observed_dofs_ = [int(i) for i in self.observed_dofs]
        self.n_dofs_ = int(train[0].shape[1])
        self.controlled_dofs_ = [i for i in range(self.n_dofs_) if i not in set(self.observed_dofs_)]
        self.dt_ = float(dt)
        self.mean_duration_ = float(np.mean([len(d) - 1 for d in train])) * self.dt_
        self.columns_ = cols
        self.selection_ = selection
        self.set_input_range(fit_input_range(np.concatenate([d[:, self.observed_dofs_] for d in train])))
        self._derived = DerivedCache()  # values derived from the fitted state, filled on first use
        return self

    def predict(self, partial, **kwargs):
        """The model's prediction (:meth:`interprim.models.base.Predictor` contract), with ``input_distance`` and
        ``out_of_range`` of the frames against the training demonstrations (:mod:`interprim.core.input_range`;
        an :class:`~interprim.OutOfRangeWarning` when out of range)."""
        self._check_fitted("predict")
        with CHECKED_BY_CALLER:  # the members' own checks skipped: this model marks and warns once, below
            pred = self.model_.predict(partial, **kwargs)
        return mark(self, pred, self.input_distance(partial), span=self._duration_span())

    def _duration_span(self):
        """:func:`~interprim.core.input_range.duration_range` of this model, read once per fitted (or loaded)
        model: the demonstrated durations do not change between predictions."""
        derived = self.__dict__.get("_derived")
        if derived is None:  # fitted state set by hand rather than by fit or a model file: read it each time
            return duration_range(self)
        return derived.get_or_build("duration_range", (self.model_,), lambda: duration_range(self))

    def stream(self, robot_state=None):
        """The model's online predictor, each prediction marked with the largest input distance of the frames
        seen so far (warned once per stream)."""
        self._check_fitted("stream")
        return CheckedStream(self, self.model_.stream(robot_state))

    def to_state(self):
        """``(arrays, meta)``: the model's state with its class and parameters."""
        self._check_fitted("to_state")
        arrays, meta = self.model_.to_state()
        return ({f"model_{k}": v for k, v in arrays.items()},
                {"chosen": self.chosen_, "class": type(self.model_).__name__, "params": self.model_.json_params(),
                 "state": meta, "selection": self.selection_, "observed_dofs_": self.observed_dofs_,
                 "weights": self.weights_, "n_dofs_": self.n_dofs_, "dt_": self.dt_, "columns_": self.columns_,
                 "mean_duration_": self.mean_duration_,
                 "input_range": [np.asarray(self.input_range_[0]).tolist(), np.asarray(self.input_range_[1]).tolist(),
                                 float(self.input_range_[2])]})

    def load_state(self, arrays, meta):
        """Restore the state written by :meth:`to_state`."""
        inner = {k[len("model_"):]: v for k, v in arrays.items() if k.startswith("model_")}
        n_dofs = check.integer("n_dofs_", meta["n_dofs_"], 1, check.MAX_GRID)
        obs = check.columns("observed_dofs_", meta["observed_dofs_"], n_dofs)
        if check.columns("params.observed_dofs", self.observed_dofs, n_dofs) != obs:
            check.fail("params.observed_dofs", self.observed_dofs, f"not the fitted observed_dofs_ {obs}")
        try:
            self.model_ = member_from_state(meta["class"], meta["params"], inner, meta["state"])
        except ModelFileError as exc:
            raise check.prefixed("model: ", exc) from None
        if getattr(self.model_, "n_dofs_", n_dofs) != n_dofs or list(self.model_.observed_dofs_) != obs:
            check.fail("class", meta["class"], f"a model of observed columns {self.model_.observed_dofs_} of "
                       f"{getattr(self.model_, 'n_dofs_', '?')}, not the file's {obs} of {n_dofs}")
        self.chosen_ = str(meta["chosen"])
        self.selection_ = dict(meta["selection"])
        self.observed_dofs_ = obs
        self.weights_ = {str(k): check.number(f"weights.{k}", v, nonneg=True)
                         for k, v in meta.get("weights", {self.chosen_: 1.0}).items()}
        self.n_dofs_ = n_dofs
        self.controlled_dofs_ = [i for i in range(self.n_dofs_) if i not in set(self.observed_dofs_)]
        self.dt_ = check.number("dt_", meta["dt_"], positive=True)
        self.mean_duration_ = check.number("mean_duration_", meta["mean_duration_"], positive=True)
        self.columns_ = check.names("columns_", meta.get("columns_"), n_dofs)
        # a file of version 1 has no statistics: no check (input_distance NaN)
        self.set_input_range(meta.get("input_range"))
        if self.input_range_ is not None and self.input_range_[0].shape != (len(self.observed_dofs_),):
            raise ValueError("input_range does not match the observed columns")
        self._derived = DerivedCache()

    def __repr__(self):
        if not hasattr(self, "model_"):
            return f"AutoInteraction(observed_dofs={self.observed_dofs!r}, candidates={list(self.candidates)!r})"
        s = self.selection_
        if s.get("runner_up") is None:
            return f"AutoInteraction({self.chosen_!r} alone)"
        best = (f"best family {self.chosen_!r}: held-out real-time error {s['margin']:.2f}x better than "
                f"{s['runner_up']!r}, {s['vs_prior']:.2f}x the mean at the mean speed")
        if s.get("combine") == "blend":
            w = ", ".join(f"{m} {x:.2f}" for m, x in sorted(self.weights_.items(), key=lambda kv: -kv[1]))
            return f"AutoInteraction(blend of {w}; {s['blend_vs_best']:.2f}x the best family's error; {best})"
        return f"AutoInteraction(chose {self.chosen_!r}: {best[len('best family ' + repr(self.chosen_)) + 2:]})"

    def summary(self) -> str:
        """A few lines: what was compared, what was chosen, and by how much."""
        s = self.selection_
        if s.get("runner_up") is None:
            return "\n".join([f"model: {self.chosen_} alone ({type(self.model_).__name__})", *self._pace_lines(),
                              *self._cost_lines()])
        lines = ["held-out real-time error of the controlled agent, by family (inner cross-validation):"]
        why = s.get("not_compared", {})
        for m, e in sorted(s["cv_errors"].items(), key=lambda kv: kv[1]):
            tag = " <- best" if m == self.chosen_ else ""
            if np.isfinite(e):
                lines.append(f"  {m:10s} {e:.4g}{tag}")
            else:
                lines.append(f"  {m:10s} not compared: {why.get(m, 'could not be fitted on every inner fold')}")
        if s.get("combine") == "blend":
            w = ", ".join(f"{m} {x:.2f}" for m, x in sorted(self.weights_.items(), key=lambda kv: -kv[1]))
            lines.append(f"blend: {w} -> {s['blend_cv_error']:.4g} ({s['blend_vs_best']:.2f}x the best family; "
                         f"in-sample for its weights)")
            lines += long_range.summary_lines(s)
            lv = s.get("band_level")
            if lv:
                lines.append("90 % band: the held-out errors' quantile at " + ", ".join(
                    f"{100 * lv[k]:.0f} % for the {'robot' if k == 'controlled' else 'partner'}" for k in lv)
                    + " (the smallest level that covers 90 % of demonstrations left out of its calibration, and"
                    + f" {100 * stacking.BAND_FLOOR:.0f} % of each third of them in recording order)")
        else:
            lines.append(f"using {self.chosen_} alone")
        return "\n".join(lines + self._pace_lines() + self._cost_lines())

    def _pace_lines(self) -> list:
        """The demonstrations' pace drift, when significant (:func:`~interprim.models.training.pace_trend`)."""
        pace = self.selection_.get("pace")
        return [pace_message(pace)] if pace is not None and pace.get("significant") else []

    def _cost_lines(self) -> list:
        """What the model's streamed frame costs (modelled) against the budget, and what was left out for it."""
        c = self.selection_.get("cost")
        if not c:  # a model file of an older version
            return []
        ip_frame = c["ip_frame"]
        line = (f"streamed frame (modelled): {1e3 * c['frame']:.2f} ms, {c['frame'] / ip_frame:.1f}x the "
                f"Interaction Primitive's {1e3 * ip_frame:.2f} ms on these data")
        notes = []
        if c.get("ip_phase"):  # the phase that times the IP's frame, and where it was read
            notes.append(f"its {c['ip_phase']} phase, " + (
                "as most of its inner-fold fits chose" if c.get("ip_phase_from") == INNER_FOLDS
                else "fitted on all the demonstrations"))
        if c.get("learned_coupling") and "learned" in self.weights_:  # the coupling that times the learned member
            notes.append(f"the learned interaction's {c['learned_coupling']} coupling, " + (
                "as most of its inner-fold fits chose" if c.get("learned_coupling_from") == INNER_FOLDS
                else "fitted on all the demonstrations"))
        if c.get("budget") is not None:
            floor = c.get("frame_budget_floor")
            rule = f"{c['frame_budget']:g}x" if floor is None else \
                f"the larger of {c['frame_budget']:g}x and {1e3 * floor:.2f} ms"
            notes.append(f"budget, {rule}: {1e3 * c['budget']:.2f} ms")
        if notes:
            line += " (" + "; ".join(notes) + ")"
        out = [line]
        if c.get("predict") is not None:  # the same for a predict call
            line = (f"predict from half the movement (modelled): {1e3 * c['predict']:.2f} ms, "
                    f"{c['predict'] / c['ip_predict']:.1f}x the Interaction Primitive's {1e3 * c['ip_predict']:.2f} ms")
            if c.get("predict_budget") is not None:
                line += f" (budget: {1e3 * c['predict_budget']:.2f} ms)"
            out.append(line)
        if c.get("left_out"):
            preds = c.get("left_out_predict", {})
            out.append("left out for the budget: " + ", ".join(
                f"{m} ({1e3 * v:.2f} ms a frame" + (f", {1e3 * preds[m]:.2f} ms a predict)" if m in preds else ")")
                for m, v in sorted(c["left_out"].items(), key=lambda kv: kv[1])))
        if c.get("not_costed"):
            out.append("not costed (no cost model): " + ", ".join(c["not_costed"]))
        return out


def pace_message(pace: dict) -> str:
    """What :func:`~interprim.models.training.pace_trend`'s significant trend means for the fitted model."""
    p = "p < 0.001" if pace["p"] < 0.001 else f"p = {pace['p']:.3f}"
    way = "shorter" if pace["change"] < 0 else "longer"
    return (f"the demonstrations' durations change with their order (Spearman rho {pace['rho']:+.2f} over "
            f"{pace['n']} demonstrations, {p}; the last third {abs(100 * pace['change']):.0f} % {way} than the "
            f"first, {pace['last']:.2f} s against {pace['first']:.2f} s): the cross-validation mixes early and late "
            "demonstrations, so its figures may be optimistic for a partner at a new pace; check the model on "
            "recordings made after these ('interprim evaluate --data' predicts the latest third of the "
            "demonstrations from the earlier two thirds: its forward check)")

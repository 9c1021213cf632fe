"""Evaluating a user's demonstrations with every model interprim offers: the real-time and whole-movement
protocols of :mod:`interprim.evaluation.realtime` for each method, the family chosen and the blend that
``interprim fit`` makes (:class:`~interprim.models.auto.AutoInteraction`) fitted inside each outer training fold
only, and a verdict.

This sits above :mod:`interprim.models.auto`, which itself uses the protocols: the protocols know nothing of the
models chosen with them.  ``interprim evaluate`` runs :func:`evaluate_demonstrations`.
"""

from __future__ import annotations

import numpy as np

from .evaluation import realtime as rt
from .evaluation.nested import (
    YARDSTICKS,
    forward_sentences,
    measure_fitted,
    nested_choice_records,
    split_holdout,
    yardstick_table,
)
from .model_selection.prefixes import Prefixes

__all__ = ["evaluate_demonstrations", "forward_check", "FORWARD_FROM"]

#: The fewest recordings the forward check runs on: its latest third then holds at least 2 (a standard error).
FORWARD_FROM = 6


def _trainable(make, demos, k, dt, log=None) -> dict:
    """``make`` without the methods that cannot be fitted on the smallest training set of the folds.

    With few demonstrations (training sets under :data:`~interprim.evaluation.realtime.ALL_METHODS_FROM` - 1),
    each method is fitted once on the first demonstrations as a probe; one that refuses them (``ValueError``: too
    few for its cross-validation) is left out, and ``log`` (if given) receives a one-line note naming it and why.
    """
    n_train = len(demos) - max(len(f) for f in rt.folds(len(demos), k))
    if n_train >= rt.ALL_METHODS_FROM - 1:
        return dict(make)
    keep = {}
    for name, factory in make.items():
        try:
            factory().fit(demos[:n_train], dt=dt)
        except ValueError as exc:
            if log is not None:
                log(f"{name} left out: it cannot be fitted on the {n_train} demonstrations of a training fold "
                    f"({' '.join(str(exc).split())})")
            continue
        keep[name] = factory
    if not keep:
        raise ValueError(f"no method can be fitted on the {n_train} demonstrations of a training fold")
    return keep


def evaluate_demonstrations(demos, observed_dofs, dt: float, k: int | None = None,
                            cfg: rt.RealTimeConfig | None = None, smoothing_window=None, n_basis: int = 20,
                            methods=None, whole_movement=(0.4, 0.6, 0.8), progress: bool = False, log=None,
                            nested: bool = True, inner_k: int = 3, data: str = "DEMOS", observed: str = "COLS",
                            rest_stride: int | None = 3):
    """Every protocol of this module on one set of demonstrations (a user's recordings or a built-in set).

    Returns ``(records, summary, verdict_sentence)``; see
    :func:`~interprim.evaluation.realtime.realtime_sweep`, :func:`~interprim.evaluation.realtime.summarise_realtime`
    and :func:`~interprim.evaluation.realtime.nested_verdict`.  ``methods``: names among ``ip``, ``learned``,
    ``ip-paper``, ``kernel``, ``nn``, ``prior`` (default all).  ``demos`` may be a
    :class:`~interprim.datasets.Demonstrations` with raw samples (causal prefixes).  Needs at least
    :data:`~interprim.evaluation.realtime.MIN_DEMONSTRATIONS` (3) demonstrations; with fewer than
    :data:`~interprim.evaluation.realtime.ALL_METHODS_FROM` (5; leave-one-out) a method that cannot be fitted on a
    training fold (``ip`` needs
    3 demonstrations to train on, ``learned`` 4) is left out, with a note to ``log`` (a callable taking one
    line).

    With ``nested`` (default), the method a verdict names is chosen for each outer fold by an ``inner_k``-fold
    cross-validation on that fold's training demonstrations only (real-time error of the controlled agent),
    and its outer records are reported as the method ``"chosen"``: no choice is made on a test fold.

    ``rest_stride``: every method is also scored over the rest of the movement in seconds (every remaining frame
    after every ``rest_stride``-th frame seen; records with ``"protocol": "rest"``, summarised as ``rest_*`` by
    :func:`~interprim.evaluation.realtime.summarise_with_rest`); None leaves it out.
    """
    cfg = rt.RealTimeConfig() if cfg is None else cfg
    source = demos
    prefixes = Prefixes(demos, observed_dofs)
    demos = prefixes.demos
    if len(demos) < rt.MIN_DEMONSTRATIONS:
        raise ValueError(f"the evaluation needs at least {rt.MIN_DEMONSTRATIONS} demonstrations (each fold trains on "
                         f"at least 2), got {len(demos)}")
    make = rt.default_methods(observed_dofs, smoothing_window=smoothing_window, n_basis=n_basis)
    if methods is not None:
        unknown = [m for m in methods if m not in make]
        if unknown:
            raise ValueError(f"unknown method(s) {unknown}; expected some of {sorted(make)}")
        make = {m: make[m] for m in methods}
    make = _trainable(make, demos, k, dt, log)
    if whole_movement and "prior" not in make:
        make["prior"] = rt.default_methods(observed_dofs)["prior"]
    recs = rt.realtime_sweep(make, prefixes, observed_dofs, dt, cfg, k=k, progress=progress,
                             whole_movement=whole_movement, rest_stride=rest_stride)
    if nested:
        choices, blended = _nested_choices(make, source, prefixes, observed_dofs, dt, cfg, k, inner_k, whole_movement,
                                           rest_stride)
        recs = recs + nested_choice_records(recs, choices) + blended
    summary = rt.summarise_with_rest(recs)
    if nested:
        return recs, summary, rt.nested_verdict(summary, recs, data=data, observed=observed)
    cands = [m for m in ("ip", "learned") if m in summary] or [next(iter(make))]
    best = min(cands, key=lambda m: summary[m].get("rt_ctrl", np.inf))
    return recs, summary, f"{best}: " + rt.verdict(summary, best)


def _default_model(make, observed_dofs, cfg, folds: int):
    """The model ``interprim fit`` makes by default (:class:`~interprim.models.auto.AutoInteraction`), its candidate
    families the evaluated methods of ``make`` among its own (each built as the evaluation builds it; with fewer than
    two of them, every evaluated method, and the best one kept: ``combine="best"``), unfitted."""
    from .models.auto import CANDIDATES, AutoInteraction

    blendable = [m for m in make if m in CANDIDATES]
    names = blendable if len(blendable) >= 2 else list(make)
    return AutoInteraction(observed_dofs, candidates=[(m, make[m]) for m in names],
                           combine="blend" if len(blendable) >= 2 else "best", folds=int(folds), horizon=cfg.horizon,
                           stride=max(cfg.stride, 3), point_dim=cfg.point_dim)


def _nested_choices(make, source, prefixes, observed_dofs, dt, cfg, k, inner_k, whole_movement,
                    rest_stride=None) -> tuple:
    """What is chosen inside each outer fold's training demonstrations only: ``({demo: the family with the smallest
    inner cross-validated error}, outer records of the blend)``.

    Each outer training fold is given to :class:`~interprim.models.auto.AutoInteraction` -- the model ``interprim
    fit`` makes by default, with the evaluated methods among its candidate families (each built as the evaluation
    builds it) -- whose inner ``inner_k``-fold cross-validation chooses the family (``chosen_``) and fits the blend
    (method ``"auto"``; only when at least two candidates could be compared).  With fewer than two of its candidate
    families evaluated, the choice is made among all the evaluated methods (``combine="best"``)."""
    rest_cfg = None if rest_stride is None else cfg.rest(rest_stride)
    choices, out = {}, []
    for held in rt.folds(len(prefixes), k):
        train = [i for i in range(len(prefixes)) if i not in set(held)]
        kk = min(int(inner_k), len(train))
        if not (kk >= 2 and len(train) >= 3):
            for j in held:
                choices[j] = next(iter(make))
            continue
        arrays = [prefixes.demos[i] for i in train]
        # the training fold with its raw samples (causal prefixes in the inner cross-validation), or its arrays
        fold = source.take(train) if prefixes.causal and hasattr(source, "take") else arrays
        auto = _default_model(make, observed_dofs, cfg, kk)
        try:
            auto.fit(fold, dt=dt)
            best = auto.chosen_
        except ValueError:  # no family could be fitted on every inner training fold
            best, auto = next(iter(make)), None  # no fitted default on this fold
        for j in held:
            choices[j] = best
        if auto is None or auto.selection_.get("combine") != "blend":
            continue
        tag = "blend " + ", ".join(f"{m} {x:.2f}" for m, x in auto.weights_.items())
        for j in held:
            def pre(kf, j=j):
                return prefixes(j, kf)

            for r in rt.realtime_fold(auto, arrays, prefixes.demos[j], observed_dofs, dt, cfg, name="auto",
                                      fitted=True, prefix=pre):
                if r["method"] == "auto":
                    out.append(dict(r, demo=int(j), chosen=tag))
            if rest_cfg is not None:  # the rest of the movement in seconds, from the same fit
                for r in rt.realtime_fold(auto, arrays, prefixes.demos[j], observed_dofs, dt, rest_cfg, name="auto",
                                          fitted=True, prefix=pre, references=False):
                    out.append(dict(r, demo=int(j), protocol="rest", chosen=tag))
            if whole_movement:
                for r in rt.whole_movement_fold(auto, prefixes.demos[j], observed_dofs, whole_movement,
                                                point_dim=cfg.point_dim, name="auto", prefix=pre):
                    out.append(dict(r, demo=int(j), protocol="whole", chosen=tag))
    return choices, out


def forward_check(demos, observed_dofs, dt: float, cfg: rt.RealTimeConfig | None = None, smoothing_window=None,
                  n_basis: int = 20, methods=None, inner_k: int = 3, rest_stride: int = 3, fractions=(0.6,),
                  log=None) -> dict | None:
    """The latest third of the recordings predicted by every method and by the default blend fitted on the earlier
    two thirds only, as a robot predicts after its demonstrations (``interprim evaluate --data``'s forward check).

    A cross-validation mixes early and late recordings, so it cannot see what changes over a session (on NuiSI the
    partner's pace: docs/evaluation.md, "Forward in recording order"); this is the user's own hold-out
    (:func:`~interprim.evaluation.nested.split_holdout`: the last third in the file's order), scored with every
    yardstick of :func:`~interprim.evaluation.nested.measure_fitted` (real time, the rest of the movement in
    seconds, the whole movement after ``fractions`` seen; causal prefixes when ``demos`` holds raw samples).
    ``"auto"`` is :class:`~interprim.models.auto.AutoInteraction` with the evaluated families as candidates (its
    inner ``inner_k``-fold cross-validation on the earlier recordings), as :func:`evaluate_demonstrations` builds
    it.  ``log`` (a callable taking one line) hears of each fit.

    Returns ``None`` with fewer than :data:`FORWARD_FROM` recordings, else ``{"latest": indices, "records":
    [...], "table": yardstick_table, "sentences": [...]}``.
    """
    cfg = rt.RealTimeConfig() if cfg is None else cfg
    prefixes = Prefixes(demos, observed_dofs)
    n = len(prefixes)
    if n < FORWARD_FROM:
        return None
    early, latest = split_holdout(n)
    make = rt.default_methods(observed_dofs, smoothing_window=smoothing_window, n_basis=n_basis)
    if methods is not None:
        make = {m: make[m] for m in methods}
    if "prior" not in make:  # the whole movement's reference
        make["prior"] = rt.default_methods(observed_dofs)["prior"]
    arrays = [prefixes.demos[i] for i in early]
    # fitted on the earlier recordings with their raw samples when they have them (causal prefixes inside)
    raw = prefixes.causal and hasattr(demos, "take")
    fit_on = demos.take(early) if raw else arrays
    test = Prefixes(demos.take(latest) if raw else [prefixes.demos[i] for i in latest], observed_dofs)

    def fitted():
        for m, factory in make.items():
            try:
                yield m, factory().fit(fit_on, dt=dt)
            except ValueError as exc:  # too few earlier recordings for its own cross-validation
                if log is not None:
                    log(f"forward check: {m} left out ({' '.join(str(exc).split())})")
        try:
            yield "auto", _default_model(make, observed_dofs, cfg, min(int(inner_k), len(early))).fit(fit_on, dt=dt)
        except ValueError as exc:
            if log is not None:
                log(f"forward check: the default blend left out ({' '.join(str(exc).split())})")

    records: list = []
    first = True
    for m, est in fitted():
        got = measure_fitted(est, m, arrays, test, observed_dofs, dt, cfg.point_dim, horizon=cfg.horizon,
                             stride=cfg.stride, rest_stride=rest_stride, fractions=fractions, references=first)
        first = False
        records += [dict(r, demo=latest[r["demo"]]) for r in got["causal"]]
        if log is not None:
            log(f"forward check: {m} fitted on the earlier {len(early)} recordings, measured on the latest "
                f"{len(latest)}")
    methods_seen = list(dict.fromkeys(r["method"] for r in records))
    order = ["auto"] + [m for m in methods_seen if m not in ("auto", "clock", "oracle-duration")] + [
        m for m in ("clock", "oracle-duration") if m in methods_seen]
    return {"latest": list(latest), "records": records, "table": yardstick_table(records, order, YARDSTICKS),
            "sentences": forward_sentences(records, n, latest)}

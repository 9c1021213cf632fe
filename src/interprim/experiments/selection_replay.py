"""The default's choices replayed in nested folds of the development recordings, from the members' predictions.

What :class:`~interprim.models.auto.AutoInteraction` chooses on its inner folds (the stacked weights, the long-range
choice, the band's variance model) is a function of the inner cross-validation's held-out predictions
(:class:`~interprim.model_selection.stacking.CrossValidation`).  This experiment computes, for each development task
(NuiSI's first two thirds, the synthetic benchmark drawn with seed 0: never the hold-out,
:data:`interprim.evaluation.nested.HOLDOUT`):

* the **outer** predictions: a 3-fold cross-validation of every candidate family over the development recordings
  (members fitted on two thirds, predicting the causal prefixes of the third), what a blend fitted on those two
  thirds combines;
* the **inner** cross-validation of each outer fold's training recordings, what ``AutoInteraction.fit`` sees there;

then applies a rule to each inner cross-validation, composes its blend from the outer predictions (the members
placed in time as :class:`~interprim.models.blend.Blend` places them) and scores it on the outer fold with the
yardsticks of :func:`interprim.model_selection.long_range.inner_yardsticks` (real time and the rest of the movement
÷ the clock and ÷ the mean at the true duration, the whole movement at 60 % ÷ the mean demonstration) and the 90 %
band's coverage over the rest of the movement, for each agent.  A rule is replayed in seconds, so rules can be
compared on the same folds (the whole fit is not repeated: the figures are those of the composition, with the frame
budget of ``AutoInteraction``'s defaults).

Each yardstick is given twice: the mean over the three outer folds, and ``(latest third)``, the outer fold that holds
out the latest third of the development recordings and is fitted on the earlier two thirds -- the one fold that
predicts forward in recording order, as a robot does after its demonstrations.  People repeating an interaction
change their pace over a session (NuiSI's development recordings of highfive1, handshake2 and fistbump2 get 0.2-0.3 s
shorter from the first third to the last), which the backward folds average away.

Rules: ``default`` (as ``AutoInteraction.fit`` chooses), ``band at 90 %`` (the variance model's quantile level fixed
at the nominal 90 %, as before it was chosen by cross-fitting), each family alone (at its own timing), and ``true
end`` (the default's weights with every member placed to the held-out recording's true end: a bound that needs the
future, to show how much a perfect remaining duration would give).

``--tasks lasa`` replays them with few demonstrations (:func:`lasa_tasks`: the 30 LASA shapes, 7 recordings each):
the outer folds hold out one recording each (the members fitted on the other six, the inner cross-validation in 3
folds, as the fit makes it), and each ratio is the geometric mean over the seven (``replay(aggregate="geometric")``;
there "latest third" is the fold that holds out the last recording).

``--tasks characters`` replays the same rules on recordings of another kind, made elsewhere
(:func:`character_tasks`: four handwritten letters of the UCI Character Trajectories set, 30 each, the pen's
x observed and its y predicted).  They are not interactions, and no rule was chosen on them: they show whether
what holds on the development tasks carries to data the rules were not developed on.  ``--letters`` replaces the
four letters (:data:`CHARACTER_LETTERS`) by others of the set's 20; :data:`FRESH_LETTERS` are the sixteen others,
kept apart as a check on recordings no rule was tried on (docs/evaluation.md gives their replay).

Run (about 3 minutes on a 2-core machine; about 45 s more for four letters, 6 minutes for the LASA shapes)::

    python -m interprim.experiments.selection_replay [--tasks nuisi,synthetic,characters,lasa] [--letters aesw]
        [--out DIR]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path

import numpy as np

from ..model_selection import long_range, stacking
from ..model_selection.realtime import folds
from ..model_selection.yardsticks import place_cases
from ..models import registry
from ..models.auto import AutoInteraction, budget_coupling, budget_phase, recording_factory

__all__ = ["task_folds", "choose", "default_rule", "single_rule", "replay", "coverage", "tables", "character_tasks",
           "CHARACTER_LETTERS", "FRESH_LETTERS", "lasa_tasks", "main"]

Z90 = 1.6448536269514722


#: prefixes scored per held-out recording of the outer folds: the replay's yardstick, fixed (the inner
#: cross-validations score as the default's fit does, ``AutoInteraction.max_prefixes``)
OUTER_PREFIXES = 24


def task_folds(dev, obs, dt: float, point_dim: int, k: int = 3, inner_k: int | None = None) -> tuple:
    """``(outer, [(held, inner, sizes)])``: the outer cross-validation (``k`` folds) of every default candidate over
    the development recordings ``dev`` and, per outer fold, the inner one (``inner_k`` folds, default ``k``; the
    fit's own is ``AutoInteraction.folds``, 3) over its training recordings and the sizes
    its frame budget is computed from: ``sizes`` is ``(assumed, own)``, the sizes with the Interaction Primitive's
    phase and the learned interaction's coupling read from their inner-fold fits
    (:func:`~interprim.models.auto.budget_phase`, :func:`~interprim.models.auto.budget_coupling`) and with those of
    the two fitted on all the training recordings, which the fit uses for a family its model keeps
    (:func:`choose`)."""
    auto = AutoInteraction(obs, point_dim=point_dim)
    make = auto.factories()
    arrays = [np.asarray(x, dtype=np.float64) for x in dev]
    cfg = stacking.scoring_config(0.25, arrays, dt, stride=3, point_dim=point_dim, max_frames=OUTER_PREFIXES)
    outer = stacking.CrossValidation(make, dev, obs, dt, cfg, k=k, horizon=0.25)
    inner = []
    ik = k if inner_k is None else int(inner_k)
    for held in folds(len(dev), k):
        keep = [i for i in range(len(dev)) if i not in set(held)]
        d = dev.take(keep) if hasattr(dev, "take") else [dev[i] for i in keep]
        tr = [np.asarray(x, dtype=np.float64) for x in d]
        c = stacking.scoring_config(0.25, tr, dt, stride=3, point_dim=point_dim, max_frames=auto.max_prefixes)
        own = registry.yardstick_ip(auto.settings(), tr, dt).phase_method_used()
        own_coupling = make["learned"]().fit(tr, dt=dt).coupling_.method_
        fits: list = []
        learned_fits: list = []
        cv = stacking.CrossValidation(dict(make, ip=recording_factory(make["ip"], fits),
                                           learned=recording_factory(make["learned"], learned_fits)),
                                      d, obs, dt, c, k=ik, horizon=0.25)
        sizes = registry.FrameSizes(len(tr), float(np.mean([len(x) for x in tr])), len(obs), int(tr[0].shape[1]),
                                    int(auto.n_basis), phase=own, coupling=own_coupling)
        assumed = dataclasses.replace(sizes, phase=budget_phase(fits, ik) or own,
                                      coupling=budget_coupling(learned_fits, ik) or "ppca")
        inner.append((held, cv, (assumed, sizes)))
    return outer, inner


#: the letters :func:`character_tasks` replays: two closed strokes, one reversing, one zigzag
CHARACTER_LETTERS = "aesw"
#: the set's other sixteen letters, kept apart as a check the rules had not seen (``--letters``)
FRESH_LETTERS = "bcdghlmnopqruvyz"


def character_tasks(path=None, letters: str = CHARACTER_LETTERS, n: int = 30, step: int = 2) -> list:
    """``[(name, demos, observed, dt, point_dim)]``: handwritten letters as two-agent tasks, the pen's x (column 0)
    observed and its y predicted (:func:`~interprim.datasets.load_character_trajectories`; the first ``n`` samples
    of each letter in file order, every ``step``-th frame of the 200 Hz recordings)."""
    from ..datasets import load_character_trajectories

    out = []
    for letter, d in load_character_trajectories(path, letters=letters, max_per_letter=n).items():
        demos = [np.asarray(x, dtype=np.float64)[::step] for x in d]
        out.append((f"characters/{letter}", demos, [0], float(d.dt) * step, 1))
    return out


def lasa_tasks(shapes=None, dt: float = 0.05, subsample: int = 10) -> list:
    """``[(name, demos, observed, dt, point_dim)]``: the LASA shapes (EPFL; the optional extra ``interprim[lasa]``)
    as two-agent tasks with few demonstrations: 7 each, the pen's x (column 0) observed and its y predicted, each
    demonstration (:func:`~interprim.datasets.load_lasa` at ``subsample``) read at its own time stamps onto a grid of
    ``dt`` seconds over its own duration (:func:`~interprim.core.preprocessing.resample_step`; 4-7 s: 40-160 frames
    at 0.05 s).  ``shapes``: all 30 by default."""
    from ..core.preprocessing import resample_step
    from ..datasets import lasa_shapes, load_lasa

    out = []
    for shape in (lasa_shapes() if shapes is None else list(shapes)):
        d = load_lasa(shape, subsample=subsample)
        demos = [resample_step(np.asarray(x, dtype=np.float64), t, dt)[0] for x, t in zip(d, d.times)]
        out.append((f"lasa/{shape}", demos, [0], float(dt), 1))
    return out


def _budget(cv, sizes: registry.FrameSizes) -> tuple:
    """``(cost, budget)`` of ``AutoInteraction``'s default frame budget on an inner fold's data of ``sizes``."""
    bm = AutoInteraction([]).budget_model(sizes, cv.names)
    return bm.cost, bm.budget


def choose(rule, cv, sizes: tuple):
    """``rule``'s choice on the inner cross-validation ``cv`` with the frame budget as ``AutoInteraction.fit`` sets
    it: timed by the IP's phase and the learned interaction's coupling from their inner-fold fits, and made again
    with those of the family fitted on all the training recordings when the choice keeps it and its cost class is
    the other (``sizes``: :func:`task_folds`)."""
    current, own = sizes
    fixed: set = set()
    choice = None
    for _ in range(3):
        choice = rule(cv, *_budget(cv, current))
        if choice is None:
            return None
        same = True
        for family, field in (("ip", "phase"), ("learned", "coupling")):
            if family in choice["names"] and family not in fixed:
                fixed.add(family)
                mine = dataclasses.replace(current, **{field: getattr(own, field)})
                same = same and registry.same_cost_class(family, current, mine)
                current = mine
        if same:
            break
    return choice


def default_rule(level: float | None = None):
    """The rule ``AutoInteraction.fit`` applies to its inner cross-validation (``level``: the band's quantile level
    fixed, instead of chosen by cross-fitting)."""
    def rule(cv, cost, budget) -> dict:
        fitted = stacking.stack(cv, 0.25, cost=cost, budget=budget, scales=False)
        fitted, lam = long_range.refine(cv, fitted, 0.25, cost=cost, budget=budget, level=level)
        return {"names": list(fitted.names), "W": np.asarray(fitted.W), "edges": list(fitted.edges),
                "scales": fitted.scales, "lam": lam, "past": fitted.record.get("past_weights")}
    return rule


def single_rule(family: str):
    """One family alone, at its own timing, with its variance model fitted as the blend's."""
    def rule(cv, cost, budget) -> dict | None:
        if family not in cv.names:
            return None
        sub = cv.subset([family])
        scales = sub.blend_scales(np.ones((len(sub.t_ahead), 1)))
        scales.pop("level")
        return {"names": [family], "W": np.ones((1, 1)), "edges": [0.25], "scales": scales, "lam": None}
    return rule


def coverage(placed, W, edges, scales) -> dict:
    """``{agent: fraction}`` of the rest of the movement's frames inside the blend's 90 % band."""
    per_step = long_range.schedule(placed.t_ahead, edges, W)
    mix = np.einsum("hm,mchd->chd", per_step, placed.mean)
    spread = np.einsum("hm,mchd->chd", per_step, (placed.mean - mix[None]) ** 2)
    H = mix.shape[1]
    a, b = (np.asarray(scales[k], dtype=np.float64) for k in ("a", "b"))
    a = np.vstack([a, np.repeat(a[-1:], max(0, H - len(a)), axis=0)])[:H]  # held after the inner folds' last step
    b = np.vstack([b, np.repeat(b[-1:], max(0, H - len(b)), axis=0)])[:H]
    inside = np.abs(mix - placed.truth) <= Z90 * np.sqrt(np.maximum(a[None] * spread + b[None], 1e-300))
    return {agent: float(inside[..., cols][placed.valid].mean())
            for agent, cols in (("robot", placed.controlled), ("human", placed.observed)) if cols}


def _outer(outer, held, choice: dict, true_end: bool = False) -> dict:
    """The yardsticks and band coverage of the blend ``choice`` composed from the outer predictions of ``held``."""
    idx = np.flatnonzero(np.isin(outer.demo, held))
    names = choice["names"]
    allowed = names + [m for m in ("prior",) if m in outer.names and m not in names]
    sub = outer.subset([m for m in outer.names if m in allowed]).cases(idx)
    W = np.zeros((choice["W"].shape[0], len(sub.names)))
    for i, m in enumerate(names):
        W[:, sub.names.index(m)] = choice["W"][:, i]
    sub.w0 = W[0]
    placed = sub.cases(np.arange(len(sub.demo)))
    lam = choice["lam"]
    if true_end:  # every member to the held-out recording's true end (a bound: needs the future)
        R = sub.valid.sum(axis=1) * sub.dt
        placed.mean = np.stack([place_cases(sub.traj[i], long_range.member_units(
            sub.phase[i], sub.duration[i], sub.t_ahead, R, sub.horizon)) for i in range(len(sub.names))])
    else:
        placed.mean = long_range.replaced(sub, lam)
    past = choice.get("past")
    out = {k: v[0] for k, v in long_range.inner_yardsticks(
        placed, W, choice["edges"], lam, past=None if past is None else [past.get(m, 0.0) for m in sub.names]).items()}
    if true_end:  # the whole movement's timing is the blend's own: only the seconds-based yardsticks are bounds
        out = {k: v for k, v in out.items() if not k.startswith("whole")}
    out.update({f"band over the rest, {a}": c for a, c in coverage(placed, W, choice["edges"],
                                                                     choice["scales"]).items()})
    return out


def replay(outer, inner, rules: dict, aggregate: str = "mean") -> dict:
    """``{rule: {yardstick: mean over the outer folds}}`` for one task (``outer``, ``inner``: :func:`task_folds`; a
    rule named ``"true end"`` is the default's weights placed to the true end).

    ``aggregate="geometric"``: the ratios' geometric mean over the outer folds instead (the coverages' mean still),
    for folds that hold out one recording each, where a recording unlike the others (its reference's error small)
    would weigh on an arithmetic mean of ratios as much as all the others together."""
    if aggregate not in ("mean", "geometric"):
        raise ValueError(f"aggregate must be 'mean' or 'geometric', got {aggregate!r}")
    res: dict = {}
    # the fold that holds out the latest recordings (folds are contiguous, in recording order)
    latest = max(range(len(inner)), key=lambda i: max(inner[i][0]))
    for rname, rule in rules.items():
        rows = []
        for held, cv, sizes in inner:
            if rname == "true end":
                rows.append(_outer(outer, held, choose(default_rule(), cv, sizes), true_end=True))
                continue
            choice = choose(rule, cv, sizes)
            if choice is None:
                break
            rows.append(_outer(outer, held, choice))
        else:
            res[rname] = {k: _aggregate([r[k] for r in rows], aggregate != "mean" and not k.startswith("band"))
                          for k in rows[0]}
            res[rname].update({f"{k} (latest third)": float(rows[latest][k]) for k in rows[0]})
    return res


def _aggregate(values: list, geometric: bool) -> float:
    """The mean of ``values`` over the outer folds, or their geometric mean."""
    v = np.asarray(values, dtype=np.float64)
    return float(np.exp(np.mean(np.log(v)))) if geometric else float(np.mean(v))


def tables(results: dict) -> str:
    """Markdown tables, one per yardstick: rules by task, with the geometric mean (the mean for coverages)."""
    tasks = list(results)
    rules = list(dict.fromkeys(r for t in tasks for r in results[t]))
    keys = list(dict.fromkeys(k for t in tasks for r in results[t].values() for k in r))
    out = []
    for k in keys:
        cov = k.startswith("band")
        out += [f"**{k}**", "", "| rule | " + " | ".join(tasks) + (" | mean |" if cov else " | geo-mean |"),
                "|---" * (len(tasks) + 2) + "|"]
        for r in rules:
            vals = [results[t].get(r, {}).get(k, float("nan")) for t in tasks]
            ok = [v for v in vals if np.isfinite(v)]
            agg = (np.mean(ok) if cov else float(np.exp(np.mean(np.log(ok))))) if ok else float("nan")
            out.append(f"| {r} | " + " | ".join("—" if not np.isfinite(v) else f"{v:.2f}" for v in vals)
                       + f" | {agg:.2f} |")
        out.append("")
    return "\n".join(out)


def main(argv=None) -> int:
    """The command line of this module (see the module docstring); returns the exit status."""
    from ..core.blas import single_thread
    from .holdout import holdout_tasks

    ap = argparse.ArgumentParser(prog="python -m interprim.experiments.selection_replay",
                                 description=__doc__.split("\n")[0])
    ap.add_argument("--tasks", default="nuisi,synthetic",
                    help="comma-separated: nuisi, synthetic (the development tasks), characters (four letters), "
                         "lasa (30 shapes of 7 recordings; needs interprim[lasa])")
    ap.add_argument("--letters", default=CHARACTER_LETTERS,
                    help=f"the letters --tasks characters replays (default {CHARACTER_LETTERS}; the set's others: "
                         f"{FRESH_LETTERS})")
    ap.add_argument("--data", default=None, help="NuiSI file (default: the shared data folder)")
    ap.add_argument("--out", default=None, help="folder for replay.json and replay.md (outside the repository)")
    args = ap.parse_args(argv)
    rules = {"default": default_rule(), "band at 90 %": default_rule(level=0.9), "true end": None,
             **{m: single_rule(m) for m in registry.CANDIDATES}}
    results = {}
    which = tuple(t.strip() for t in args.tasks.split(","))
    unknown = sorted(set(which) - {"nuisi", "synthetic", "characters", "lasa"})
    if unknown:
        ap.error(f"unknown task set(s): {', '.join(unknown)} (known: nuisi, synthetic, characters, lasa)")
    if "characters" in which:
        letters = args.letters.strip()
        known = set(CHARACTER_LETTERS + FRESH_LETTERS)
        bad = sorted(set(letters) - known)
        if not letters:
            ap.error("--letters: no letter given")
        if bad:
            ap.error(f"--letters: {''.join(bad)}: not among the set's letters ({''.join(sorted(known))})")
        if len(set(letters)) != len(letters):
            ap.error(f"--letters: {letters!r} repeats a letter")
    elif args.letters != CHARACTER_LETTERS:
        ap.error("--letters is read with --tasks characters only")
    tasks = [(name, dev, obs, dt, pdim) for name, dev, _hold, obs, dt, pdim, _orc in holdout_tasks(which, args.data)]
    if "characters" in which:
        tasks += character_tasks(letters=letters)
    if "lasa" in which:
        try:
            tasks += lasa_tasks()
        except ImportError as exc:  # the optional extra is missing: its message names the install command
            ap.error(f"--tasks lasa: {exc}")
    with single_thread():
        for name, dev, obs, dt, pdim in tasks:
            few = name.startswith("lasa/")  # one recording held out per outer fold, the fit's 3 inner folds
            outer, inner = task_folds(dev, obs, dt, pdim, k=len(dev) if few else 3, inner_k=3)
            results[name] = replay(outer, inner, rules, aggregate="geometric" if few else "mean")
            print(f"{name}: replayed", flush=True)
    md = tables(results)
    print(md)
    if args.out is not None:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        (out / "replay.json").write_text(json.dumps(results))
        (out / "replay.md").write_text(md + "\n")
        print(f"wrote {out / 'replay.json'} and {out / 'replay.md'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

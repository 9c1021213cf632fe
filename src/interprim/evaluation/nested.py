"""Choices made inside the training data only: the model chosen by inner cross-validation, and the hold-out.

Every number the project reports comes from predictions whose every choice was made without the held-out
recording: hyper-parameters (inside each estimator's ``fit``), the method a verdict names
(:func:`interprim.evaluation.realtime.choose_method`, run on the training folds of each outer fold: nested
cross-validation), and the final figures come from a
hold-out fixed in advance (:func:`split_holdout`, :data:`HOLDOUT`), not looked at while developing.
"""

from __future__ import annotations

import math

import numpy as np

from ..core.cv import paired_gain

__all__ = ["HOLDOUT", "split_holdout", "nested_choice_records", "standard_error_ratio", "measure_fitted",
           "nested_sweep", "YARDSTICKS", "yardstick_table", "yardstick_markdown", "FORWARD_RIVALS", "WHOLE_RIVALS",
           "beaten_by", "forward_sentences"]

#: The untouched hold-out, fixed on 2026-11-26 before any new model was developed (docs/evaluation.md):
#: for every real data set, the last third of each interaction's recordings in the file's order (NuiSI: the
#: highest demo numbers); for the synthetic benchmark (:func:`interprim.synthetic.benchmark_tasks`), the
#: demonstrations drawn with ``seed=1`` (development uses ``seed=0``).
HOLDOUT = {"fraction": 1.0 / 3.0, "synthetic_dev_seed": 0, "synthetic_holdout_seed": 1}


def split_holdout(n: int) -> tuple:
    """``(development indices, hold-out indices)`` of ``n`` recordings: the hold-out is the last third."""
    n = int(n)
    if n < 3:
        raise ValueError(f"a hold-out split needs at least 3 recordings, got {n}")
    n_hold = max(1, int(math.ceil(n * HOLDOUT["fraction"])))
    return list(range(n - n_hold)), list(range(n - n_hold, n))


def nested_choice_records(records, choices, name: str = "chosen") -> list:
    """Copies of the outer records of the method chosen in each outer fold, renamed ``name``.

    ``choices``: ``{demo index: chosen method}`` (one choice per outer fold, made on its training folds).
    """
    out = []
    for r in records:
        j = r.get("demo")
        if j is not None and choices.get(j) == r["method"]:
            c = dict(r)
            c["method"] = name
            c["chosen"] = r["method"]
            out.append(c)
    return out


def standard_error_ratio(records, a: str, b: str, key: str = "rt_ctrl", protocol=None) -> tuple:
    """``(ratio of means a / b, its standard error)`` over demonstrations, from per-demo mean errors (paired).

    The standard error is the delta-method one of the ratio of two paired means; with fewer than two
    demonstrations it is NaN.  ``protocol``: the records counted for a key other than ``wm_*`` (the whole-movement
    records, ``protocol="whole"``): ``None`` the real-time ones, ``"rest"`` the rest of the movement.
    """
    per: dict = {}
    for r in records:
        if key.startswith("wm"):
            if r.get("protocol") != "whole":
                continue
        elif r.get("protocol") != protocol:
            continue
        if key in r and r["method"] in (a, b):
            per.setdefault(r["demo"], {}).setdefault(r["method"], []).append(r[key])
    pairs = np.array([(np.mean(v[a]), np.mean(v[b])) for v in per.values() if a in v and b in v])
    if len(pairs) == 0:
        return float("nan"), float("nan")
    ma, mb = pairs.mean(axis=0)
    ratio = ma / mb
    if len(pairs) < 2:
        return float(ratio), float("nan")
    _, se = paired_gain(pairs[:, 0], ratio * pairs[:, 1])  # the paired standard error of a - ratio b
    return float(ratio), float(se / mb)


def measure_fitted(est, name: str, train, test, observed_dofs, dt: float, point_dim: int = 1, horizon: float = 0.25,
                   stride: int = 1, rest_stride: int = 3, fractions=(0.6,), oracles=None, references: bool = True,
                   prefix_sets=None) -> dict:
    """Every yardstick of one fitted estimator on held-out recordings: ``{prefix kind: records}``.

    For each held-out recording of ``test`` (a :class:`~interprim.model_selection.prefixes.Prefixes`, causal
    prefixes when it holds raw samples): real time (the next ``horizon`` seconds after every ``stride``-th frame
    from 20 to 90 %; no ``protocol``), the rest of the movement in seconds (every remaining frame, every
    ``rest_stride``-th frame seen; ``protocol="rest"``) and the paper's Fig. 7 measure (whole movement in normalised
    time after each of ``fractions`` seen; ``protocol="whole"``).  ``references`` adds the clock, the mean at the
    true duration and, with ``oracles``, the oracle; records carry ``demo`` (the index in ``test``).
    ``prefix_sets``: ``{kind: Prefixes}`` of the same recordings (default ``{"causal": test}``).
    """
    from ..model_selection.realtime import RealTimeConfig, realtime_fold, whole_movement_fold

    cfg = RealTimeConfig(point_dim=point_dim, horizon=float(horizon), stride=int(stride))
    rest_cfg = cfg.rest(rest_stride)
    sets = prefix_sets or {"causal": test}
    out: dict = {p: [] for p in sets}
    for j, rec in enumerate(test.demos):
        orc = None if oracles is None or not references else oracles[j]
        for p, P in sets.items():
            def pre(k, j=j, P=P):
                return P(j, k)

            recs = realtime_fold(est, train, rec, observed_dofs, dt, cfg, name=name, fitted=True, prefix=pre,
                                 oracle=orc, references=references)
            recs += [dict(r, protocol="whole") for r in
                     whole_movement_fold(est, rec, observed_dofs, fractions, point_dim=point_dim, name=name,
                                         prefix=pre, oracle=orc)]
            recs += [dict(r, protocol="rest") for r in
                     realtime_fold(est, train, rec, observed_dofs, dt, rest_cfg, name=name, fitted=True, prefix=pre,
                                   oracle=orc, references=references)]
            for r in recs:
                r["demo"] = j
            out[p] += recs
    return out


def nested_sweep(make, demos, observed_dofs, dt: float, k: int = 3, point_dim: int = 1, stride: int = 3,
                 rest_stride: int = 3, fractions=(0.6,), oracles=None, log=None) -> list:
    """The whole fitting procedure evaluated in ``k`` outer folds: every method of ``make`` (``{name: factory}``;
    e.g. :class:`~interprim.models.auto.AutoInteraction`, whose inner cross-validation then runs inside each outer
    training fold) fitted on the outer training recordings and measured on the held-out ones with every yardstick
    (:func:`measure_fitted`).  ``demos``: a :class:`~interprim.datasets.Demonstrations` (causal prefixes) or a list
    of arrays; ``oracles``: one per recording (synthetic data).  Returns the records, ``demo`` numbering ``demos``.
    """
    from ..model_selection.prefixes import Prefixes
    from ..model_selection.realtime import folds

    n = len(demos)
    out = []
    for held in folds(n, k):
        keep = [i for i in range(n) if i not in set(held)]
        if hasattr(demos, "take"):
            train_d, test_d = demos.take(keep), demos.take(held)
        else:
            train_d, test_d = [demos[i] for i in keep], [demos[i] for i in held]
        train = [np.asarray(x, dtype=np.float64) for x in train_d]
        test = Prefixes(test_d, observed_dofs)
        orc = None if oracles is None else [oracles[i] for i in held]
        for first, (name, factory) in enumerate(make.items()):
            est = factory().fit(train_d, dt=dt)
            recs = measure_fitted(est, name, train, test, observed_dofs, dt, point_dim, stride=stride,
                                  rest_stride=rest_stride, fractions=fractions, oracles=orc,
                                  references=first == 0)["causal"]
            for r in recs:
                r["demo"] = held[r["demo"]]
            out += recs
            if log is not None:
                log(f"    fold {held[0]}..{held[-1]}: {name} fitted and measured")
    return out


#: The yardsticks of :func:`yardstick_table`: ``(label, key, protocol, reference)``.
YARDSTICKS = (("real time ÷ clock", "rt_ctrl", None, "clock"),
              ("real time ÷ mean at the true duration", "rt_ctrl", None, "oracle-duration"),
              ("rest of the movement ÷ clock", "rt_ctrl", "rest", "clock"),
              ("rest of the movement ÷ mean at the true duration", "rt_ctrl", "rest", "oracle-duration"),
              ("whole movement at 60 % (normalised time) ÷ mean demonstration", "wm_ctrl", "whole", "prior"))


def yardstick_table(records, methods, yardsticks=YARDSTICKS) -> dict:
    """``{label: {method: (ratio, standard error)}}``: every method's error ÷ the reference's on each yardstick
    (ratios of means over the held-out demonstrations, paired standard errors; :func:`standard_error_ratio`)."""
    out = {}
    for label, key, protocol, ref in yardsticks:
        out[label] = {m: standard_error_ratio(records, m, ref, key=key, protocol=protocol) for m in methods}
    return out


#: The forward check's methods compared with the default blend in its sentences: the families a user can fit alone,
#: and the clock (the mean demonstration at the mean speed, ``prior``'s prediction in seconds, named once).
FORWARD_RIVALS = ("ip", "learned", "ip-paper", "kernel", "nn", "clock")

#: The same on the paper's whole-movement measure (normalised time), where the clock has no figure of its own: its
#: reference there, the mean demonstration (``prior``), takes its place.
WHOLE_RIVALS = tuple("prior" if m == "clock" else m for m in FORWARD_RIVALS)


def beaten_by(records, target: str, rivals, key: str = "rt_ctrl", protocol=None) -> list:
    """``[(rival, ratio, standard error)]``: every method of ``rivals`` whose error on ``key`` (records of
    ``protocol``; see :func:`standard_error_ratio`) is below ``target``'s by more than one standard error (paired
    over the recordings), ``ratio`` = the rival's error ÷ ``target``'s."""
    out = []
    for m in rivals:
        r, se = standard_error_ratio(records, m, target, key=key, protocol=protocol)
        if np.isfinite(r) and np.isfinite(se) and r < 1.0 - se:
            out.append((m, r, se))
    return out


def forward_sentences(records, n_recordings: int, latest) -> list:
    """What a verdict says of the forward check (:func:`interprim.assessment.forward_check`): the default blend's
    (``"auto"``) error on the ``latest`` recordings (their indices) ÷ the clock's, in real time and over the rest of
    the movement, its 90 % band's coverage of the controlled agent there (the mean over recordings), its whole
    movement ÷ the mean demonstration's, and every rival of :data:`FORWARD_RIVALS` (of :data:`WHOLE_RIVALS` on the
    whole movement) that beats it on one of the three by more than one standard error (paired over the latest
    recordings, :func:`beaten_by`)."""
    latest = list(latest)
    head = (f"Your latest {len(latest)} of {n_recordings} recordings, predicted by models fitted on the earlier ones "
            f"(as a robot predicts after its demonstrations): ")
    rt_, _ = standard_error_ratio(records, "auto", "clock")
    rest, _ = standard_error_ratio(records, "auto", "clock", protocol="rest")
    if not np.isfinite(rt_):
        return [head + "the default blend could not be fitted on the earlier recordings."]
    per_demo: dict = {}  # the band's coverage over the rest, per recording (each counts once)
    for r in records:
        if r["method"] == "auto" and r.get("protocol") == "rest" and np.isfinite(r.get("cov_ctrl", np.nan)):
            per_demo.setdefault(r["demo"], []).append(r["cov_ctrl"])
    cov = float(np.mean([np.mean(v) for v in per_demo.values()])) if per_demo else float("nan")
    band = (f"; its 90 % band covers {cov:.0%} of the controlled agent's frames over the rest" if np.isfinite(cov)
            else "")
    whole, _ = standard_error_ratio(records, "auto", "prior", key="wm_ctrl")
    out = [head + f"the default blend has {rt_:.2f}x the clock's error in real time"
           + (f" and {rest:.2f}x over the rest of the movement" if np.isfinite(rest) else "")
           + (f", and {whole:.2f}x the mean demonstration's on the whole movement" if np.isfinite(whole) else "")
           + band + "."]
    checks: list[tuple[str, str, str | None, tuple[str, ...]]] = [
        ("real time", "rt_ctrl", None, FORWARD_RIVALS), ("the rest of the movement", "rt_ctrl", "rest", FORWARD_RIVALS)]
    if any(r.get("protocol") == "whole" for r in records):
        checks.append(("the whole movement", "wm_ctrl", None, WHOLE_RIVALS))
    beaten = [f"{m} in {what} ({r:.2f}x ± {se:.2f} its error)" for what, key, protocol, rivals in checks
              for m, r, se in beaten_by(records, "auto", rivals, key, protocol)]
    if beaten:
        n = sum(len(c[3]) for c in checks)
        out.append("Beating it there by more than a standard error: " + "; ".join(beaten) + ". Either your later "
                   "recordings differ from the earlier ones (e.g. the partner's pace changes over the session), which "
                   f"the cross-validation, mixing them, cannot see, or, with {n} comparisons "
                   "made, one is won by chance: check the model on recordings made after these, or fit the family "
                   "named ('interprim fit --model NAME'; the clock and the mean demonstration are '--model prior').")
    return out


def yardstick_markdown(table, title: str = "") -> str:
    """One task's :func:`yardstick_table` as markdown: a row per method, a column per yardstick, each cell the
    ratio ± its standard error ("—" where the method has no such figure; a method with none left out)."""
    labels = list(table)
    methods = list(table[labels[0]]) if labels else []
    lines = ([f"**{title}**", ""] if title else []) + [
        "| method | " + " | ".join(labels) + " |", "|---" * (len(labels) + 1) + "|"]
    for m in methods:
        cells = []
        for label in labels:
            r, se = table[label][m]
            cells.append("—" if not np.isfinite(r) else f"{r:.2f} ± {se:.2f}" if np.isfinite(se) else f"{r:.2f}")
        if all(c == "—" for c in cells):
            continue
        lines.append(f"| {m} | " + " | ".join(cells) + " |")
    return "\n".join(lines)

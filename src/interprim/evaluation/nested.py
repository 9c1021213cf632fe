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

__all__ = ["HOLDOUT", "split_holdout", "nested_choice_records", "standard_error_ratio"]

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


def standard_error_ratio(records, a: str, b: str, key: str = "rt_ctrl") -> tuple:
    """``(ratio of means a / b, its standard error)`` over demonstrations, from per-demo mean errors (paired).

    The standard error is the delta-method one of the ratio of two paired means; with fewer than two
    demonstrations it is NaN.
    """
    per: dict = {}
    for r in records:
        if r.get("protocol") == "whole" and not key.startswith("wm"):
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

"""The shared cross-validation rules (interprim.core.cv) and resampling (interprim.core.preprocessing), tested directly,
and a check that no other module writes its own copy of them."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

import interprim
from interprim.core import cv
from interprim.core.preprocessing import (
    interp_columns,
    resample_step,
    resample_uniform,
    step_count,
    step_grid,
    time_normalise,
)

SRC = Path(interprim.__file__).resolve().parent


# ----------------------------------------------------------------------------------------------------- folds
@pytest.mark.parametrize("order", cv.FOLD_ORDERS)
def test_folds_partition_every_index_once_and_are_deterministic(order):
    for n in range(1, 26):
        for k in (None, 1, 2, 3, 4, 5, 7, n, n + 3):
            sets = cv.folds(n, k, order, rng=np.random.default_rng(5))
            again = cv.folds(n, k, order, rng=np.random.default_rng(5))
            assert [s.tolist() for s in sets] == [s.tolist() for s in again]
            assert len(sets) == cv.n_folds(k, n)
            allidx = np.concatenate(sets)
            assert sorted(allidx.tolist()) == list(range(n)), (n, k)
            assert all(s.size >= 1 and np.all(np.diff(s) > 0) for s in sets)  # non-empty, sorted
            sizes = [s.size for s in sets]
            assert max(sizes) - min(sizes) <= 1
            labels = cv.fold_labels(n, k, order, rng=np.random.default_rng(5))
            assert all((labels[s] == f).all() for f, s in enumerate(sets))


def test_fold_orders_by_hand():
    assert [f.tolist() for f in cv.folds(7, 3, "interleaved")] == [[0, 3, 6], [1, 4], [2, 5]]
    assert [f.tolist() for f in cv.folds(7, 3, "contiguous")] == [[0, 1], [2, 3, 4], [5, 6]]  # cut at round(7 i/3)
    sh = cv.folds(7, 3, "shuffled", rng=np.random.default_rng(0))
    assert [f.size for f in sh] == [3, 2, 2]  # the longer runs first
    perm = np.random.default_rng(0).permutation(7)
    assert [f.tolist() for f in sh] == [sorted(perm[:3]), sorted(perm[3:5]), sorted(perm[5:])]
    assert cv.fold_labels(7, 3).tolist() == [0, 1, 2, 0, 1, 2, 0]  # j mod k
    # leave-one-out whenever k >= n or k is None, whatever the order
    for order in cv.FOLD_ORDERS:
        assert [f.tolist() for f in cv.folds(4, None, order, rng=np.random.default_rng(0))] == [[0], [1], [2], [3]]


def test_n_folds_clips_to_two_and_to_n():
    assert [cv.n_folds(k, 10) for k in (None, 0, 1, 2, 5, 10, 40)] == [10, 2, 2, 2, 5, 10, 10]
    assert cv.n_folds(5, 1) == 1 and cv.n_folds(None, 0) == 0


def test_shuffled_leave_one_out_draws_nothing_and_needs_rng():
    rng = np.random.default_rng(3)
    cv.folds(5, None, "shuffled", rng=rng)
    cv.folds(5, 9, "shuffled", rng=rng)
    assert rng.integers(1 << 30) == np.random.default_rng(3).integers(1 << 30)
    with pytest.raises(ValueError, match="needs rng"):
        cv.folds(5, 2, "shuffled")
    with pytest.raises(ValueError, match="order must be one of"):
        cv.folds(5, 2, "random")


def test_the_callers_folds_are_the_shared_rule():
    from interprim.evaluation import realtime
    from interprim.experiments import handwriting

    for n in range(2, 15):
        for k in (None, 2, 3, 5, 20):
            got = realtime.folds(n, k)
            assert got == [f.tolist() for f in cv.folds(n, k, "contiguous")]
            assert all(type(j) is int for f in got for j in f)
            a = handwriting._folds(n, k, np.random.default_rng(n))
            b = cv.folds(n, k, "shuffled", rng=np.random.default_rng(n))
            assert [x.tolist() for x in a] == [x.tolist() for x in b]
    with pytest.raises(ValueError, match="k >= 2"):
        realtime.folds(5, 1)
    assert realtime.folds(1, 1) == [[0]]


# --------------------------------------------------------------------------------- one-standard-error rule
def test_paired_gain_by_hand():
    gain, se = cv.paired_gain([3.0, 5.0, 4.0], [1.0, 2.0, 3.0])  # differences 2, 3, 1
    assert gain == pytest.approx(2.0, abs=1e-15)
    assert se == pytest.approx(1.0 / math.sqrt(3.0), rel=1e-15)  # std (ddof=1) 1 over sqrt(3)
    gain, se = cv.paired_gain([1.0, 2.0, 3.0], [3.0, 5.0, 4.0])
    assert gain == pytest.approx(-2.0, abs=1e-15) and se == pytest.approx(1.0 / math.sqrt(3.0), rel=1e-15)
    gain, se = cv.paired_gain([2.0], [1.5])  # one case: no standard error
    assert gain == 0.5 and se == np.inf
    g, s = cv.paired_gain(np.ones((4, 3)), np.zeros((4, 1)))  # per candidate along axis 0
    assert g.tolist() == [1.0, 1.0, 1.0] and s.tolist() == [0.0, 0.0, 0.0]


def test_within_one_standard_error_of_paired_differences():
    rng = np.random.default_rng(2)
    base = rng.uniform(1.0, 2.0, 40)  # the cases' own spread, shared by every candidate
    E = np.stack([base, base + 0.01 + 0.001 * rng.standard_normal(40), base + rng.normal(0.005, 0.2, 40),
                  np.full(40, np.inf)], axis=1)
    ok = cv.within_one_se(E)
    # candidate 1 is worse by 0.01 with a paired SE of ~1.6e-4: out; candidate 2 is as close on average but its
    # differences spread 0.2 (SE ~0.03): in; the excluded (inf) candidate stays out; the best is in
    assert ok.tolist() == [True, False, True, False]
    assert cv.within_one_se(E[:1]).tolist() == [True, True, True, False]  # one case: no standard error, all finite in


def test_within_one_se_edge_cases():
    # exact ties: every tied candidate is in (excess 0 <= se 0); the first of them is the best
    E = np.array([[1.0, 1.0, 2.0], [2.0, 2.0, 3.0], [3.0, 3.0, 4.0]])
    assert cv.within_one_se(E).tolist() == [True, True, False]  # the third: excess 1 with se 0
    # shape of the candidates' axes is kept (cases, 2, 2)
    rng = np.random.default_rng(0)
    E = rng.uniform(size=(6, 2, 2))
    E[:, 1, 1] = E[:, 0, 0] - 0.5  # clearly the best
    ok = cv.within_one_se(E)
    assert ok.shape == (2, 2) and ok[1, 1] and not ok[0, 0]
    # all candidates excluded but one: that one is the best and alone
    E = np.full((5, 3), np.inf)
    E[:, 2] = 1.0
    assert cv.within_one_se(E).tolist() == [False, False, True]
    # the rule against an explicit computation
    E = rng.normal(1.0, 0.1, size=(12, 5)) + np.linspace(0, 0.05, 5)
    best = int(np.argmin(E.mean(axis=0)))
    d = E - E[:, [best]]
    want = d.mean(axis=0) <= d.std(axis=0, ddof=1) / np.sqrt(12)
    assert cv.within_one_se(E).tolist() == want.tolist()


# ------------------------------------------------------------------------------------------- the prefix rule
def test_observed_frames_lengths():
    of = cv.observed_frames
    assert of(10, 0.25) == 3  # round(2.5) = 2 (halves to even), at least 3
    assert of(10, 0.35) == 4 and of(10, 0.45) == 4 and of(10, 0.55) == 6  # round halves to even: 3.5->4, 4.5->4
    assert of(10, 0.0) == 3 and of(10, 1.0) == 10 and of(2, 0.5) == 2  # at most T, even below 3
    assert of(10, 1.0, keep=1) == 9 and of(3, 0.9, keep=1) == 2  # at most T - keep, which wins over min_frames
    assert of(100, 0.02, min_frames=5) == 5 and of(100, 0.4, min_frames=5) == 40
    assert cv.MIN_OBSERVED_FRAMES == 3
    from interprim.model_selection import prefixes as protocol

    assert protocol.observed_frames is cv.observed_frames  # the evaluation's protocol states the core's rule


# ------------------------------------------------------------------------------------------------ resampling
def _reference(x_new, x, y):
    return np.column_stack([np.interp(x_new, x, y[:, d]) for d in range(y.shape[1])])


def test_interp_columns_equals_numpy_interp():
    rng = np.random.default_rng(1)
    x = np.cumsum(rng.uniform(0.1, 1.0, 30))
    y = rng.normal(size=(30, 4))
    x_new = np.linspace(x[0] - 1.0, x[-1] + 1.0, 77)  # held outside, as np.interp
    assert np.array_equal(interp_columns(x_new, x, y), _reference(x_new, x, y))
    assert np.array_equal(interp_columns(x[3] + 0.01, x, y), _reference([x[3] + 0.01], x, y)[0])  # scalar
    assert interp_columns(x_new, x, np.empty((30, 0))).shape == (77, 0)


def test_step_grid_keeps_the_step_and_stops_at_the_end():
    assert step_count(0.3, 0.1) == 4  # 0.3 / 0.1 = 2.9999999999999996: the tolerance counts the last frame
    assert step_count(0.29, 0.1) == 3 and step_count(0.0, 0.1) == 1
    g = step_grid(1.234, 0.1)
    assert g.size == 13 and np.array_equal(g, np.arange(13) * 0.1)
    rng = np.random.default_rng(2)
    t = 5.0 + np.cumsum(np.r_[0.0, rng.uniform(0.005, 0.015, 60)])
    y = rng.normal(size=(61, 3))
    ys, ts = resample_step(y, t, 0.01)
    assert ts[0] == t[0] and ts[-1] <= t[-1] + 1e-12 and ts.size == step_count(t[-1] - t[0], 0.01)
    assert np.array_equal(ts, t[0] + np.arange(ts.size) * 0.01)
    assert np.array_equal(ys, _reference(ts, t, y))


def test_resample_uniform_and_time_normalise_equal_numpy_interp():
    rng = np.random.default_rng(3)
    t = np.cumsum(np.r_[0.0, rng.uniform(0.005, 0.015, 40)])
    y = rng.normal(size=(41, 2))
    yu, tu = resample_uniform(y, t, dt=0.01)
    assert np.array_equal(yu, _reference(tu, t, y)) and tu[-1] == t[-1]
    yn = time_normalise(y, 25)
    assert np.array_equal(yn, _reference(np.linspace(0, 1, 25), np.linspace(0, 1, 41), y))


# ------------------------------------------------------------------------------- one home for each rule
def _sources():
    for path in sorted(SRC.rglob("*.py")):
        yield path.relative_to(SRC).as_posix(), path.read_text(encoding="utf-8")


#: (what, pattern, the modules allowed to hold it)
RULES = [
    ("a fold split with array_split", r"array_split\(", {"core/cv.py"}),
    ("interleaved folds by slicing or modulo", r"\[\w+::\w+\]|np\.arange\(\w+\) % ", {"core/cv.py"}),
    ("contiguous fold edges", r"linspace\(0, \w+, \w+ \+ 1\)", {"core/cv.py"}),
    ("a one-standard-error helper", r"def _?within_one_se|_within_one_se\(", {"core/cv.py"}),
    ("a standard error computed by hand", r"ddof=1\)\s*/\s*(math|np)\.sqrt", {"core/cv.py"}),
    ("the prefix length round(p T) written out", r"round\(\s*\w+\s*\*\s*T\s*\)", {"core/cv.py"}),
    ("a per-column np.interp loop", r"(stack|array|column_stack)\(\[np\.interp\(|\[:, \w+\] = np\.interp\(",
     # causal_prefix: each column interpolated from its own raw stream's samples (a different abscissa each)
     {"core/preprocessing.py", "model_selection/prefixes.py"}),
    ("a step grid counted by hand", r"\+ 1e-9\)\) \+ 1",
     # the rollout's integration steps in canonical time (not a resampling of data)
     {"core/preprocessing.py", "core/dmp.py"}),
]


@pytest.mark.parametrize("what,pattern,allowed", RULES, ids=[r[0] for r in RULES])
def test_each_rule_has_one_home(what, pattern, allowed):
    found = [f"{name}:{text.count(chr(10), 0, m.start()) + 1} {m.group(0)}"
             for name, text in _sources() if name not in allowed for m in re.finditer(pattern, text)]
    assert not found, f"{what} outside {sorted(allowed)}:\n" + "\n".join(found)


def test_the_checks_see_a_copy():
    copies = {
        "a fold split with array_split": "return np.array_split(perm, k)",
        "interleaved folds by slicing or modulo": "folds = [np.arange(n)[k::K] for k in range(K)]",
        "contiguous fold edges": "edges = np.linspace(0, S, k + 1).round()",
        "a one-standard-error helper": "ok = _within_one_se(E)",
        "a standard error computed by hand": "se = float(diff.std(ddof=1) / math.sqrt(n))",
        "the prefix length round(p T) written out": "M = int(min(T, max(3, round(p * T))))",
        "a per-column np.interp loop": "np.stack([np.interp(u, g, Y[:, d]) for d in range(D)], axis=1)",
        "a step grid counted by hand": "n = int(np.floor(t[-1] / dt + 1e-9)) + 1",
    }
    for what, pattern, _ in RULES:
        assert re.search(pattern, copies[what]), what

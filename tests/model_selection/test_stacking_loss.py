"""The stacking loss of the default model's inner cross-validation (interprim.model_selection.stacking): computed
from the held-out errors' products, it equals the direct sum over every prediction, on every band, family subset
and case subset, and follows a replaced set of placed predictions."""

import numpy as np
import pytest

from interprim.model_selection.stacking import CrossValidation


def _cv(rng, M=3, n_case=30, H=12, D=3):
    cv = object.__new__(CrossValidation)
    cv.names = [f"f{i}" for i in range(M)]
    cv.truth = rng.normal(size=(n_case, H, D)) + 2.0
    cv.mean = cv.truth[None] + rng.normal(0.0, 0.3, (M, n_case, H, D)) * rng.uniform(0.5, 2.0, (M, 1, 1, 1))
    cv.valid = np.arange(H)[None, :] < rng.integers(1, H + 1, n_case)[:, None]
    cv.observed, cv.controlled = [0], [1, 2]
    cv.horizon, cv.dt, cv.point_dim = 0.2, 0.05, 1
    cv.t_ahead = np.arange(1, H + 1) * cv.dt
    cv.errors = {m: 0.0 for m in cv.names}
    return cv


def _direct(cv, steps, w):
    """The loss and gradient as a sum over every case, step and column (what the products stand for)."""
    c = cv.controlled
    sel = np.arange(cv.truth.shape[1]) if steps is None else np.asarray(steps)
    n_rt = max(1, int(round(cv.horizon / cv.dt)))
    mask = (cv.valid[:, sel] | (sel < n_rt)[None, :])
    keep = mask.any(axis=1)
    P = cv.mean[:, keep][:, :, sel][..., c]
    T = cv.truth[keep][:, sel][..., c]
    scale = np.sqrt(np.mean(T * T))
    P, T = P / scale, T / scale
    W = mask[keep][:, :, None].astype(float)
    count = W.sum(axis=(1, 2)) * len(c)
    e = (np.tensordot(w, P, axes=1) - T) * W
    r = np.sqrt(np.sum(e * e, axis=(1, 2)) / count) + 1e-12
    grad = np.einsum("mcsj,csj->m", P, e / (r * count)[:, None, None]) / len(r)
    return float(np.mean(r)), grad


@pytest.mark.parametrize("steps", [None, np.arange(0, 4), np.arange(4, 12), np.array([2, 7, 11])])
def test_the_loss_from_products_equals_the_direct_sum(steps):
    rng = np.random.default_rng(7)
    cv = _cv(rng)
    sets = [(cv, "all"), (cv.subset(["f0", "f2"]), "subset"), (cv.cases(np.arange(5, 25)), "cases"),
            (cv.cases(np.arange(3, 28)).subset(["f1", "f2"]).cases(np.arange(2, 20)), "nested")]
    for sub, _ in sets:
        loss = sub._loss(steps)
        M = len(sub.names)
        for w in [np.full(M, 1.0 / M), np.eye(M)[0], rng.dirichlet(np.ones(M)), rng.uniform(0, 1, M)]:
            got, grad = loss(w)
            want, want_grad = _direct(sub, steps, w)  # off the simplex too (the solver may step there)
            assert got == pytest.approx(want, rel=1e-10)
            np.testing.assert_allclose(grad, want_grad, rtol=1e-8, atol=1e-12)


def test_replaced_predictions_are_not_read_from_stale_products():
    rng = np.random.default_rng(8)
    cv = _cv(rng)
    w = np.array([0.2, 0.5, 0.3])
    before = cv._loss(None)(w)[0]
    placed = cv.cases(np.arange(len(cv.truth)))
    placed.mean = cv.mean + 0.5  # as the long-range choice re-places the members
    got = placed._loss(None)(w)[0]
    assert got == pytest.approx(_direct(placed, None, w)[0], rel=1e-10) and got != pytest.approx(before)
    assert cv._loss(None)(w)[0] == before


def test_the_weights_are_those_of_the_direct_loss():
    """The solver on the products reaches the weights the direct sum's minimiser reaches (float noise)."""
    from scipy.optimize import minimize

    rng = np.random.default_rng(9)
    cv = _cv(rng, M=4)
    w = cv.blend_weights()
    res = minimize(lambda x: _direct(cv, None, x), np.full(4, 0.25), jac=True, bounds=[(0.0, 1.0)] * 4,
                   method="SLSQP", constraints=({"type": "eq", "fun": lambda x: x.sum() - 1.0},),
                   options={"ftol": 1e-12, "maxiter": 300})
    assert _direct(cv, None, w)[0] <= res.fun + 1e-9
    np.testing.assert_allclose(w, np.clip(res.x, 0, None) / np.clip(res.x, 0, None).sum(), atol=1e-4)


def test_subsets_read_their_families_rows_only_when_asked_and_give_the_same_arrays():
    """A subset of the families copies its rows of the per-family arrays on first read (the solver reads the shared
    products only); what it then holds is the parent's rows, through any chain of subsets and case selections."""
    rng = np.random.default_rng(9)
    cv = _cv(rng, M=4)
    cv.traj = rng.normal(size=cv.mean.shape[:2] + (7, 3))
    cv.phase, cv.duration = rng.uniform(0, 1, cv.mean.shape[:2]), rng.uniform(1, 2, cv.mean.shape[:2])
    sub = cv.subset(["f0", "f2", "f3"]).subset(["f0", "f3"])
    assert "mean" not in sub.__dict__ and "traj" not in sub.__dict__  # nothing copied yet
    sub.blend_weights(np.arange(4))  # the solver: the shared products only
    assert "mean" not in sub.__dict__
    for a in ("mean", "traj", "phase", "duration"):
        np.testing.assert_array_equal(getattr(sub, a), getattr(cv, a)[[0, 3]])
    idx = np.arange(4, 21)
    nested = cv.subset(["f1", "f2"]).cases(idx)
    for a in ("mean", "traj", "phase", "duration"):
        np.testing.assert_array_equal(getattr(nested, a), getattr(cv, a)[1:3][:, idx])
    with pytest.raises(AttributeError):
        sub.no_such_array  # noqa: B018


def test_the_band_levels_of_both_agents_at_once_are_those_of_each_alone():
    from interprim.model_selection import stacking

    rng = np.random.default_rng(10)
    cv = _cv(rng, n_case=60)
    cv.demo = np.repeat(np.arange(12), 5)
    w = np.array([0.5, 0.3, 0.2])[:, None, None, None]
    agents = {"controlled": cv.controlled, "observed": cv.observed}
    both = stacking.band_levels(cv.mean, cv.truth, cv.valid, w, agents, cv.demo)
    shared = stacking._crossfit(cv.mean, cv.truth, cv.valid, w, list(agents.values()), cv.demo)
    for (name, cols), cover in zip(agents.items(), shared):
        assert both[name] == stacking.band_level(cv.mean, cv.truth, cv.valid, w, cols, cv.demo)
        np.testing.assert_array_equal(cover, stacking.crossfit_coverages(cv.mean, cv.truth, cv.valid, w, cols, cv.demo))
    parts = stacking.blend_parts(cv.mean, w)
    a, b = stacking.variance_model(cv.mean, cv.truth, cv.valid, w, agents, both)
    a2, b2 = stacking.variance_model(cv.mean, cv.truth, cv.valid, w, agents, both, parts=parts)
    np.testing.assert_array_equal(a, a2)
    np.testing.assert_array_equal(b, b2)


@pytest.mark.parametrize("block", [1, 7 * 12 * 2 * 3, 1 << 19])  # one case, 7 cases, every case per block
def test_the_products_computed_block_by_block_equal_those_of_all_the_errors(monkeypatch, block):
    """The products are computed a block of cases at a time (no array of every error); each is a sum over one
    case's and step's columns, so they equal, bit for bit, those of the whole array of errors."""
    from interprim.model_selection import stacking

    monkeypatch.setattr(stacking, "_CASE_BLOCK", block)
    rng = np.random.default_rng(11)
    for controlled in ([1, 2], [0, 2]):  # consecutive columns (a view) and not (a copy)
        cv = _cv(rng, M=3, n_case=30)
        cv.controlled, cv.observed = controlled, [1] if controlled == [0, 2] else [0]
        g = cv._gram()
        T = cv.truth[..., controlled]
        E = cv.mean[..., controlled] - T[None]
        for m in range(3):
            for n in range(3):
                np.testing.assert_array_equal(g["G"][:, :, m, n], np.einsum("chj,chj->ch", E[m], E[n]))
        np.testing.assert_array_equal(g["u"], np.moveaxis(np.einsum("mchj,chj->mch", E, T), 0, 2))
        np.testing.assert_array_equal(g["t"], np.einsum("chj,chj->ch", T, T))


@pytest.mark.parametrize("block", [1, 12 * 3 * 4, 1 << 19])  # one case, 4 cases, every case per block
def test_the_blend_parts_computed_block_by_block_equal_the_sums_over_the_members(monkeypatch, block):
    """:func:`blend_parts` adds the members' weighted predictions (and their weighted squared disagreement) a
    block of cases at a time: the numbers of numpy's sums over the members (which add them in turn), bit for bit,
    for weights per member or per member and step."""
    from interprim.model_selection import stacking

    monkeypatch.setattr(stacking, "_CASE_BLOCK", block)
    rng = np.random.default_rng(12)
    cv = _cv(rng, M=3, n_case=30)
    for w in (np.array([0.5, 0.3, 0.2])[:, None, None, None], rng.dirichlet(np.ones(3), 12).T[:, None, :, None]):
        mix, spread = stacking.blend_parts(cv.mean, w)
        want = np.sum(w * cv.mean, axis=0)
        np.testing.assert_array_equal(mix, want)
        np.testing.assert_array_equal(spread, np.sum(w * (cv.mean - want) ** 2, axis=0))


def test_a_familys_rows_are_read_from_the_parent_without_copying_every_familys():
    """``family_array`` gives a family's rows of a per-family array, equal to the subset's own array's row; for a
    subset that has not copied its array yet, a view of the parent's (no copy of every family's rows)."""
    rng = np.random.default_rng(13)
    cv = _cv(rng, M=4)
    cv.traj = rng.normal(size=(4, cv.truth.shape[0], 9, 3))
    sub = cv.subset(["f1", "f3"])
    nested = cv.subset(["f0", "f2", "f3"]).subset(["f0", "f3"])
    for s, rows in ((cv, [0, 1, 2, 3]), (sub, [1, 3]), (nested, [0, 3])):
        for i, r in enumerate(rows):
            got = s.family_array("traj", i)
            assert np.shares_memory(got, cv.traj)  # read from the parent, not copied
            np.testing.assert_array_equal(got, cv.traj[r])
    assert "traj" not in sub.__dict__ and "traj" not in nested.__dict__
    np.testing.assert_array_equal(sub.traj[1], sub.family_array("traj", 1))  # and once copied, the copy's rows

"""The coupling's conditioning methods, one type each (interprim.models.conditioners), against their definitions."""

import numpy as np
import pytest

from interprim.models.conditioners import (
    CONDITIONERS,
    PPCA,
    Blend,
    Context,
    Kernel,
    Mean,
    Ridge,
    conditioner,
    target_block,
)


@pytest.fixture(scope="module")
def ctx():
    rng = np.random.default_rng(4)
    n, per, p, q = 7, 3, 6, 10
    X = rng.normal(size=(n * per, p))
    groups = np.repeat(np.arange(n), per)
    Y = rng.normal(size=(n, q))
    x = rng.normal(size=(2, p))
    return Context.of(X, groups, Y, x)


def test_ridge_is_eq18_with_the_relative_noise(ctx):
    lam = 0.3
    R, p = ctx.Xc.shape
    S_xx = ctx.Xc.T @ ctx.Xc / R
    sigma2 = lam * np.trace(S_xx) / p
    want = (ctx.Xc @ np.linalg.solve(S_xx + sigma2 * np.eye(p), ctx.xc.T)).T / R
    np.testing.assert_allclose(Ridge(lam).weights(ctx), want, rtol=1e-10, atol=1e-12)


def test_kernel_runs_from_the_nearest_row_to_the_mean(ctx):
    d2, _ = ctx.distances()
    near = Kernel(1e-4).weights(ctx) + 1.0 / ctx.R
    assert np.array_equal(np.argmax(near, axis=1), np.argmin(d2, axis=1)) and np.all(near.max(axis=1) > 0.999)
    np.testing.assert_allclose(Kernel(1e6).weights(ctx), 0.0, atol=1e-9)  # every row alike: the mean
    assert np.array_equal(Mean().weights(ctx), np.zeros((2, ctx.R)))


def test_blend_is_the_weighted_sum_and_keys_round_trip(ctx):
    b = Blend((0.1, 0.5, 0.25))
    np.testing.assert_array_equal(b.weights(ctx), 0.25 * Ridge(0.1).weights(ctx) + 0.75 * Kernel(0.5).weights(ctx))
    for c in (Mean(), Ridge(0.1), PPCA(2), Kernel(0.5), b):
        again = conditioner(*c.key)
        assert type(again) is type(c) and again.param == c.param
        np.testing.assert_array_equal(again.predict(ctx)[0], c.predict(ctx)[0])
    assert set(CONDITIONERS) == {"mean", "ridge", "ppca", "kernel", "blend"}
    with pytest.raises(ValueError, match="unknown coupling method 'lasso'"):
        conditioner("lasso", 1.0)


def test_the_leverage_of_the_mean_is_one_over_n(ctx):
    mean, h = Mean().predict(ctx)
    np.testing.assert_allclose(mean, np.broadcast_to(ctx.ybar, mean.shape))
    np.testing.assert_allclose(h, 1.0 / ctx.P.shape[1])


def test_a_given_target_block_gives_the_same_ppca(ctx):
    given = Context(ctx.Xc, ctx.xc, ctx.P, ctx.ybar, ctx.Ydc, target_block(ctx.P, ctx.Ydc, ctx.R))
    np.testing.assert_array_equal(PPCA(3).weights(given), PPCA(3).weights(Context.from_mapping(dict(ctx))))


@pytest.mark.parametrize("R, p", [(60, 12), (12, 40)])
def test_ridge_weights_by_a_cholesky_solve_equal_the_svd_formula(R, p):
    """The ridge's weights, solved on the smaller Gram matrix, are ``x_c V diag(S / (S^2 + R sigma^2)) U^T`` of the
    rows' thin SVD (rounding apart), over the whole grid of ``lambda``, on smooth (ill-conditioned) rows too."""
    from interprim.models.coupling import DEFAULT_RIDGE_GRID

    rng = np.random.default_rng(4)
    t = np.linspace(0.0, 1.0, p)
    X = np.sin(np.outer(rng.uniform(1, 3, R), t) + rng.uniform(0, 1, (R, 1))) + 1e-4 * rng.normal(size=(R, p))
    groups = np.repeat(np.arange(R // 2 if R % 2 == 0 else R), 2 if R % 2 == 0 else 1)
    ctx = Context.of(X, groups, rng.normal(size=(len(np.unique(groups)), 3)), rng.normal(size=(3, p)))
    U, S, Vt = np.linalg.svd(ctx.Xc, full_matrices=False)
    for lam in DEFAULT_RIDGE_GRID:
        sigma2 = lam * float(np.sum(S**2)) / (R * p)
        want = (ctx.xc @ Vt.T * (S / (S**2 + R * sigma2))) @ U.T
        got = Ridge(lam).weights(ctx)
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-9 * np.abs(want).max())

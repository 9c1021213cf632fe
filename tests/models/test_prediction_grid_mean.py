"""Prediction.grid_mean (what a blend reads of its Interaction Primitive member after every frame) gives
trajectory's numbers bit for bit: without PCA (the latent map a selection of columns), with PCA, and with a
non-finite value."""

import numpy as np
import pytest

import interprim as ip
from interprim.synthetic import two_agent_demos


@pytest.mark.parametrize("observed, pca", [([0, 1], None), ([2, 3], None), ([1, 3], None), ([0, 1], 2)])
def test_grid_mean_is_trajectory(observed, pca):
    demos = [np.hstack([d, d[:, :1] ** 2]) for d in two_agent_demos(8, seed=6, frames=60, noise=0.01)]
    model = ip.InteractionPrimitive(observed, pca_components=pca).fit(demos, dt=0.05)
    x = demos[2][:25, observed]
    for p in (model.predict(x), model.stream().extend(x)):
        for n in (2, 101, 201):
            assert np.array_equal(p.grid_mean(n), p.trajectory(n))


def test_a_non_finite_trajectory_takes_the_product():
    demos = two_agent_demos(6, seed=1, frames=50, noise=0.01)
    model = ip.InteractionPrimitive([0, 1]).fit(demos, dt=0.05)
    p = model.predict(demos[0][:20, [0, 1]])
    p._post.mean[3] = np.inf  # a diverged posterior: inf * 0 in the product is NaN, as trajectory gives it
    with np.errstate(invalid="ignore"):
        a, b = p.grid_mean(51), p.trajectory(51)
    assert np.array_equal(a, b, equal_nan=True)
    assert np.isnan(a).any()

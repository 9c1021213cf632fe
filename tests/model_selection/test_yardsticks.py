"""The yardsticks a user reads (rest of the movement, the mean at the true duration, standard errors) and the
one-standard-error choice, on cases with a known answer."""

import numpy as np
import pytest

from interprim.model_selection.yardsticks import (
    case_rms,
    clock_units,
    demo_means,
    one_se_choice,
    place_cases,
    ratio_se,
    true_duration_units,
)


def test_case_rms_counts_only_the_masked_steps_and_whole_points():
    pred = np.zeros((2, 3, 4))
    truth = np.zeros((2, 3, 4))
    truth[0, :, 1] = 3.0
    truth[0, :, 2] = 4.0  # a 2-D point (cols 1, 2) off by 5 on every step of case 0
    truth[1, 2, 1] = 100.0  # a step of case 1 outside its mask
    mask = np.array([[True, True, False], [True, True, False]])
    out = case_rms(pred, truth, mask, cols=[1, 2], point_dim=2)
    assert out == pytest.approx([5.0, 0.0])


def test_ratio_se_is_exact_for_proportional_errors_and_weights_each_demonstration_once():
    b = np.array([1.0, 2.0, 2.0, 4.0])
    groups = np.array([0, 1, 1, 2])  # demo 1 has two cases
    r, se = ratio_se(2.0 * b, b, groups)
    assert r == pytest.approx(2.0) and se == pytest.approx(0.0, abs=1e-12)
    assert demo_means(b, groups) == pytest.approx([1.0, 2.0, 4.0])
    a = np.array([1.0, 3.0, 5.0])  # per demo, against b per demo 1, 2, 4: ratio of means 9 / 7
    r, se = ratio_se(a, [1.0, 2.0, 4.0])
    d = a - r * np.array([1.0, 2.0, 4.0])
    assert r == pytest.approx(9.0 / 7.0)
    assert se == pytest.approx(d.std(ddof=1) / np.sqrt(3) / (7.0 / 3.0))


def test_one_se_choice_prefers_the_simplest_within_the_noise():
    rng = np.random.default_rng(0)
    groups = np.repeat(np.arange(10), 5)
    noise = rng.normal(0.0, 0.1, size=50)
    errors = {"mean": 1.0 + noise, "blend": 0.99 + rng.normal(0.0, 0.1, size=50)}  # better by less than its noise
    chosen, table = one_se_choice(errors, groups, ["mean", "blend"])
    assert chosen == "mean"
    assert table["mean"]["vs_best"] <= table["mean"]["se"]
    errors["blend"] = 0.5 + noise  # better by far more than its noise
    assert one_se_choice(errors, groups, ["mean", "blend"])[0] == "blend"
    # tried from the complex end, the complex one is kept while the simpler is not better by more than the noise
    errors["blend"] = 1.01 + rng.normal(0.0, 0.1, size=50)
    assert one_se_choice(errors, groups, ["blend", "mean"])[0] == "blend"


def test_the_mean_at_the_true_duration_reproduces_a_recording_that_is_the_mean_stretched():
    dt = 0.05
    G = 201
    grid = np.linspace(0.0, 1.0, G)
    mean = np.stack([np.sin(np.pi * grid), grid ** 2], axis=1)  # (G, 2)
    T = 61  # 3 s: the recording is the mean played at 3 s
    rec = np.stack([np.sin(np.pi * np.linspace(0, 1, T)), np.linspace(0, 1, T) ** 2], axis=1)
    k = np.array([20, 40])
    t = np.arange(1, 21) * dt
    u = true_duration_units(k, [T, T], t, dt)
    placed = place_cases(np.stack([mean, mean]), u)
    idx = np.minimum(k[:, None] + np.arange(20)[None, :], T - 1)
    assert np.max(np.abs(placed - rec[idx])) < 1e-3
    # the clock at a mean duration of 2 s runs 1.5x too fast: it reaches the end early and holds it
    uc = clock_units(k, t, dt, mean_duration=2.0)
    assert uc[1, -1] == pytest.approx((39 * dt + 1.0) / 2.0)
    assert np.allclose(place_cases(np.stack([mean, mean]), uc)[1, -5:], mean[-1])


def test_place_cases_reads_each_case_as_interp_columns_on_either_path():
    # the compiled path writes every case into one array; the numpy path stacks interp_columns: the same numbers
    from interprim.core._compiled import registry
    from interprim.core.preprocessing import interp_columns

    rng = np.random.default_rng(4)
    Y = rng.normal(size=(6, 21, 3))
    u = rng.uniform(-0.2, 1.2, size=(6, 15))
    u[:, ::4] = np.linspace(0.0, 1.0, 21)[rng.integers(0, 21, size=(6, 4))]  # on the grid
    grid = np.linspace(0.0, 1.0, 21)
    want = np.stack([interp_columns(np.clip(u[c], 0.0, 1.0), grid, Y[c]) for c in range(6)])
    for which in ("compiled", "numpy"):
        with registry.forced(which):
            got = place_cases(Y, u)
        assert got.shape == (6, 15, 3) and np.array_equal(got, want)

"""Tests of the high-five experiment and of ``interprim demo``."""

import json

import numpy as np
import pytest
from _dtw_reference import brute_force_dtw

from interprim.cli import build_parser, main
from interprim.experiments.highfive import (
    format_summary,
    nearest_neighbours,
    open_end_dtw_prefix_costs,
)


def test_open_end_dtw_prefix_costs_match_textbook_recursion():
    rng = np.random.default_rng(0)
    q = np.cumsum(rng.standard_normal((17, 2)), axis=0)
    r = np.cumsum(rng.standard_normal((23, 2)), axis=0)
    D, _ = brute_force_dtw(r, q)  # (reference, query)
    expected = D.min(axis=0)  # Eq. 8, open end, for every prefix of the query
    np.testing.assert_allclose(open_end_dtw_prefix_costs(q, r), expected, rtol=1e-12)
    np.testing.assert_allclose(open_end_dtw_prefix_costs(q, r, use_numba=False), expected, rtol=1e-12)


def test_open_end_dtw_prefix_of_reference_costs_nothing():
    s = np.linspace(0, 1, 50)
    ref = np.stack([np.sin(3 * s), s**2], axis=1)
    costs = open_end_dtw_prefix_costs(ref[:20], ref)
    np.testing.assert_allclose(costs, 0.0, atol=1e-14)
    # a time-warped (slower) copy still matches almost perfectly, a shifted copy does not
    slow = np.stack([np.sin(3 * s[:30] * 0.8), (s[:30] * 0.8) ** 2], axis=1)
    assert open_end_dtw_prefix_costs(slow, ref)[-1] < 0.01
    assert open_end_dtw_prefix_costs(slow + 0.5, ref)[-1] > 1.0


def test_nearest_neighbours_finds_the_source_demo():
    rng = np.random.default_rng(1)
    refs = [np.cumsum(rng.standard_normal((30 + 3 * j, 2)), axis=0) for j in range(6)]
    for j in range(6):
        idx = nearest_neighbours(refs[j], refs, [5, 15, 30])
        assert np.all(idx == j)


def test_cli_lists_demo_and_validates_arguments(capsys):
    help_text = build_parser().format_help()
    assert "demo" in help_text
    assert main(["demo", "--n-train", "0", "--quiet"]) == 1
    err = capsys.readouterr().err
    assert "--n-train" in err and "positive" in err


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("demo")
    code = main(["demo", "--quick", "--out", str(out), "--quiet", "--jobs", "1", "--seed", "0"])
    return code, out


@pytest.mark.slow  # the whole demo pipeline (data by optimal control, figures, animation)
def test_demo_quick_writes_all_files(quick_run):
    code, out = quick_run
    assert code == 0
    for name in ("fig5_setup.png", "fig6_samples.png", "fig7_mse.png", "fig8_goals.png"):
        data = (out / name).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10_000
    gif = (out / "highfive.gif").read_bytes()
    assert gif[:6] in (b"GIF89a", b"GIF87a") and 10_000 < len(gif) < 2_000_000
    report = (out / "report.md").read_text()
    for key in ("Fig. 7", "Fig. 8", "Fig. 6", "prior mean", "nearest neighbour", "fig7_mse.png"):
        assert key in report


@pytest.mark.slow
def test_demo_quick_results_are_sane(quick_run):
    _, out = quick_run
    r = json.loads((out / "results.json").read_text())
    P = r["percents"]
    assert P == list(range(10, 101, 10))
    j100, j80 = P.index(100), P.index(80)
    ctrl, obs = r["fig7"]["controlled"], r["fig7"]["observed"]
    # every number is a finite, non-negative MSE
    for agent in (ctrl, obs):
        for m in ("ip", "prior", "nn"):
            v = np.asarray(agent[m]["mean"])
            assert v.shape == (len(P),) and np.all(np.isfinite(v)) and np.all(v >= 0)
    # conditioning on the whole observed movement beats the unconditioned prior
    assert ctrl["ip"]["mean"][j100] < ctrl["prior"]["mean"][j100]
    assert obs["ip"]["mean"][j80] < obs["prior"]["mean"][j80]
    # with the true phase, the response is clearly better than the prior (the model itself works)
    if ctrl.get("ip_known_phase"):
        assert ctrl["ip_known_phase"]["mean"][j100] < 0.8 * ctrl["prior"]["mean"][j100]
        assert obs["ip_known_phase"]["mean"][j100] < 1e-3
    # the prior baseline does not depend on the observation
    assert np.ptp(ctrl["prior"]["mean"]) == 0
    # Fig. 8: predicted goals are in the right region (tens of cm at most) and beat the nearest neighbour
    f8 = r["fig8"]
    assert f8["percent"] == 60
    assert 0 < f8["mean_distance_m"]["ip"] < 0.2
    assert f8["mean_distance_m"]["ip"] < f8["mean_distance_m"]["nn"]
    assert np.asarray(f8["predicted_goals"]).shape == (r["data"]["n_test"], 2)
    # Fig. 6: goal spreads are positive and in a plausible range
    s40, s60 = r["fig6"]["goal_spread_m_mean_over_test"]
    assert 0 < s40 < 1 and 0 < s60 < 1
    # phase estimation is close to the truth half-way through
    assert abs(r["phase"]["mean_estimate"][P.index(50)] - r["phase"]["mean_true"][P.index(50)]) < 0.1
    # the data really reach the goals
    assert r["data"]["max_hand_error_m"] < 1e-3
    # the animation: the library's defaults beside the paper's IP, numbers of its last frame in results and report
    a = r["animation"]
    assert a["n_frames"] == r["config"]["gif_frames"] and a["test_index"] == r["fig6"]["example_test_index"]
    for key in ("default", "paper"):
        assert 0 < a[key]["phase"] <= 1 and a[key]["true_phase"] == 1.0
        assert 0 <= a[key]["distance_m"] < 1 and 0 <= a[key]["distance_at_true_phase_m"] < 1
        assert f"robot hand {100 * a[key]['distance_m']:.1f} cm" in (out / "report.md").read_text()
    assert "controlled" in format_summary(r)

"""The nested evaluation of a whole fitting procedure and the hold-out's tables with standard errors."""

import pytest

from interprim.evaluation.nested import YARDSTICKS, nested_sweep, standard_error_ratio, yardstick_table
from interprim.experiments.holdout import readme_table, yardstick_tables
from interprim.models.registry import default_methods
from interprim.synthetic import two_agent_demos


@pytest.fixture(scope="module")
def records():
    demos = two_agent_demos(6, seed=1, frames=60, noise=0.01)
    make = {m: f for m, f in default_methods([0, 1]).items() if m in ("prior", "nn")}
    return nested_sweep(make, demos, [0, 1], 0.05, k=3, stride=4, rest_stride=6)


def test_every_method_is_measured_on_every_yardstick_in_every_outer_fold(records):
    for m in ("prior", "nn", "clock", "oracle-duration"):
        got = {r["demo"] for r in records if r["method"] == m and r.get("protocol") is None}
        assert got == set(range(6)), m
        assert {r["demo"] for r in records if r["method"] == m and r.get("protocol") == "rest"} == set(range(6))
    assert {r["demo"] for r in records if r["method"] == "nn" and r.get("protocol") == "whole"} == set(range(6))
    # the clock and the mean at the true duration are added once per held-out frame, not once per method
    n_clock = sum(r["method"] == "clock" and r.get("protocol") is None for r in records)
    assert n_clock == sum(r["method"] == "prior" and r.get("protocol") is None for r in records)


def test_the_mean_played_by_the_clock_is_the_clock_on_every_yardstick(records):
    table = yardstick_table(records, ["prior", "nn"])
    assert set(table) == {y[0] for y in YARDSTICKS}
    for label in ("real time ÷ clock", "rest of the movement ÷ clock"):
        r, se = table[label]["prior"]
        assert r == pytest.approx(1.0, rel=1e-3) and se == pytest.approx(0.0, abs=1e-3)  # up to its grid
    assert table["whole movement at 60 % (normalised time) ÷ mean demonstration"]["prior"][0] == pytest.approx(1.0)
    # the rest of the movement is its own protocol: its records are not mixed into the real-time figure
    rest = standard_error_ratio(records, "nn", "clock", protocol="rest")
    rt = standard_error_ratio(records, "nn", "clock")
    assert rest[0] != pytest.approx(rt[0])
    assert table["rest of the movement ÷ clock"]["nn"] == pytest.approx(rest)


def test_tables_of_the_hold_out_show_ratios_with_standard_errors_and_geometric_means():
    ys = {"causal": {"rest of the movement ÷ clock": {"auto": (0.5, 0.1), "ip": (0.8, 0.05), "clock": (1.0, 0.0)}}}
    results = {"a": {"yardsticks": ys, "summary": {"causal": {"auto": {"rest_rt_ctrl_vs_clock": 0.5}}}},
               "synthetic/b": {"yardsticks": {"causal": {"rest of the movement ÷ clock": {
                   "auto": (2.0, 0.2), "ip": (0.8, 0.05), "clock": (1.0, 0.0)}}},
                   "summary": {"causal": {"auto": {"rest_rt_ctrl_vs_clock": 2.0}}}}}
    md = yardstick_tables(results)
    assert "| auto | 0.50 ± 0.10 | 2.00 ± 0.20 | 1.00 |" in md
    assert "| ip | 0.80 ± 0.05 | 0.80 ± 0.05 | 0.80 |" in md
    assert "| clock |" not in md  # the reference itself is left out
    readme = readme_table(results)
    assert "| `AutoInteraction` (what `interprim fit` makes) | — / — | — / — | 0.50 / 1.00 |" in readme

"""The real-time protocol (interprim.evaluation.realtime): placement in time, baselines, calibration, folds."""

import numpy as np
import pytest

from interprim.core.preprocessing import time_normalise
from interprim.evaluation.realtime import RealTimeConfig, folds, realtime_fold, realtime_sweep, summarise_realtime
from interprim.models.demonstrations import PriorMean


def _demos(n=6, seed=0):
    """Two-agent demos with different durations: the controlled agent mirrors the observed one."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        T = int(rng.integers(40, 80))
        t = np.linspace(0.0, 1.0, T)
        a = 1.0 + 0.3 * rng.normal()
        obs = np.stack([a * np.sin(np.pi * t), t], axis=1)
        out.append(np.hstack([obs, -obs[:, :1] * 2.0]))
    return out


class _Truth:
    """Knows the held-out demonstration: predicts it exactly, with the true phase and duration."""

    def __init__(self, demo, dt):
        self.demo, self.dt = demo, dt

    def fit(self, demos, dt=None):
        return self

    def predict(self, partial):
        T = len(self.demo)
        k = len(partial)
        demo = self.demo

        class P:
            normalised_time = (k - 1) / (T - 1)
            duration = (T - 1) * self.dt

            @staticmethod
            def trajectory(n):
                return time_normalise(demo, n)

            @staticmethod
            def std(n):
                return np.full((n, demo.shape[1]), 1e-6)

        return P()


def test_a_method_that_knows_the_truth_has_zero_error_and_the_clock_is_its_own_baseline():
    demos = _demos()
    dt = 0.02
    test, train = demos[0], demos[1:]
    cfg = RealTimeConfig(n_grid=2001)
    recs = realtime_fold(_Truth(test, dt), train, test, [0, 1], dt, cfg, name="truth")
    truth = [r for r in recs if r["method"] == "truth"]
    assert len(truth) == int(np.floor(0.9 * len(test))) - int(np.ceil(0.2 * len(test))) + 1
    assert max(r["phase_err"] for r in truth) < 1e-12
    assert max(r["rt_ctrl"] for r in truth) < 1e-3  # interpolation of a 2001-point grid only
    clock = [r for r in recs if r["method"] == "clock"]
    assert min(r["rt_ctrl"] for r in clock) >= 0 and np.mean([r["rt_ctrl"] for r in clock]) > 0.01
    # the oracle-duration mean has the true phase by construction
    assert max(r["phase_err"] for r in recs if r["method"] == "oracle-duration") == 0.0


def test_a_method_without_timing_is_played_by_the_clock():
    demos = _demos(seed=1)
    recs = realtime_sweep({"prior": lambda: PriorMean([0, 1], n=201)}, demos, [0, 1], 0.02, RealTimeConfig(stride=3))
    s = summarise_realtime(recs)
    assert s["prior"]["rt_ctrl_vs_clock"] == pytest.approx(1.0, rel=1e-9)
    assert s["prior"]["phase_err_vs_clock"] == pytest.approx(1.0, rel=1e-9)
    assert np.isfinite(s["prior"]["cov_ctrl"])  # PriorMean has a std: calibration is measured
    assert s["oracle-duration"]["phase_err"] == 0.0


def test_folds_cover_every_demo_once():
    for n, k in [(7, None), (7, 3), (10, 10), (10, 4)]:
        f = folds(n, k)
        assert sorted(i for fold in f for i in fold) == list(range(n))
    with pytest.raises(ValueError, match="k >= 2"):
        folds(5, 1)
    with pytest.raises(ValueError, match="at least 3 demonstrations"):
        realtime_sweep({"prior": lambda: PriorMean([0])}, _demos()[:2], [0], 0.02)


def test_verdict_says_plainly_whether_the_human_helps():
    from interprim.evaluation.realtime import markdown_table, verdict

    base = {"clock": {"rt_ctrl": 0.1, "rt_ctrl_vs_clock": 1.0, "phase_err_vs_clock": 1.0}}
    good = dict(base, ip={"rt_ctrl": 0.077, "rt_ctrl_vs_clock": 0.77, "phase_err_vs_clock": 0.6})
    assert verdict(good).startswith("conditioning on the human improves the robot's real-time prediction by 23 %")
    assert "40 % closer" in verdict(good)
    same = dict(base, ip={"rt_ctrl": 0.099, "rt_ctrl_vs_clock": 0.99, "phase_err_vs_clock": 1.0})
    assert verdict(same).startswith("does not help on this data")
    worse = dict(base, ip={"rt_ctrl": 0.13, "rt_ctrl_vs_clock": 1.3, "phase_err_vs_clock": 1.2})
    assert verdict(worse).startswith("hurts on this data")
    assert "| clock |" in markdown_table(good) and "| ip |" in markdown_table(good)


@pytest.mark.slow  # the evaluate command end to end
def test_evaluate_command_on_a_users_file(tmp_path, capsys):
    """``interprim evaluate --data FILE``: every protocol on the user's own recordings, a verdict, files."""
    import json

    from interprim.cli import main
    from interprim.datasets import save_demonstrations
    from interprim.synthetic import two_agent_demos

    path = save_demonstrations(tmp_path / "demos.csv", two_agent_demos(6, seed=3), dt=0.01,
                               columns=["h1", "h2", "r1", "r2", "r3"])
    out = tmp_path / "eval"
    assert main(["evaluate", "--data", str(path), "--observed", "h1,h2", "--folds", "3", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "verdict: " in printed and "| clock |" in printed and "| ip |" in printed
    res = json.loads((out / "realtime.json").read_text())
    assert res["summary"]["ip"]["rt_ctrl_vs_clock"] < 0.8  # synthetic data: the human helps
    v = res["verdict"]
    assert v.startswith("chosen inside the training folds: ")  # nested: no choice on a test fold
    assert "Conditioning on the human helps" in v
    assert f"To fit the blend: interprim fit {path} --observed h1,h2 -o model.npz; the chosen family alone: " in v
    assert "chosen" in res["summary"] and res["summary"]["chosen"]["rt_ctrl_vs_clock"] < 0.8
    assert res["summary"]["auto"]["rt_ctrl_vs_clock"] < 0.8 and "| auto |" in printed
    assert "| chosen |" in printed
    assert (out / "report.md").read_text().count("|") > 20
    # no observed columns named and none in the file: a one-line error naming the flag
    assert main(["evaluate", "--data", str(path), "--out", str(out)]) != 0
    assert "--observed is required" in capsys.readouterr().err


@pytest.mark.slow  # fits and evaluates several methods
def test_learned_interaction_places_its_prediction_in_time_and_beats_the_clock_on_synthetic_data():
    """LearnedInteraction (learned phase -> phase-robust coupling): the realtime interface, a phase that is a
    pure function of the prefix (a stream of predictions equals the batch ones), and a real gain."""
    import interprim as ip
    from interprim.synthetic import two_agent_demos

    demos = two_agent_demos(16, seed=4)
    est = ip.LearnedInteraction([0, 1]).fit(demos[:12], dt=0.01)
    d = demos[13]
    p = est.predict(d[:60, :2])
    assert 0 < p.normalised_time <= 1 and p.duration > 0 and p.phase_std >= 0
    assert p.trajectory(50).shape == (50, 5) and np.all(p.std(50) >= 0)
    st = est.stream()  # frame by frame: the stream's prediction after 60 frames is the batch one
    for frame in d[:60, :2]:
        q = st.update(frame)
    np.testing.assert_array_equal(p.trajectory(50), q.trajectory(50))
    np.testing.assert_array_equal(p.std(50), q.std(50))
    assert q.normalised_time == p.normalised_time and q.n_observed == 60
    s = summarise_realtime(realtime_sweep({"learned": lambda: ip.LearnedInteraction([0, 1])}, demos, [0, 1], 0.01,
                                          RealTimeConfig(stride=8), k=4))
    assert s["learned"]["rt_ctrl_vs_clock"] < 0.6 and s["learned"]["phase_err_vs_clock"] < 0.8


def test_records_without_metrics_hold_the_same_placed_predictions():
    """``metrics=False`` (a caller that scores the placed means itself) leaves the errors out, nothing else."""
    demos = _demos(6)
    kw = dict(k=3, trace=True, std=False, references=False)
    make = {"prior": lambda: PriorMean([0, 1])}
    full = realtime_sweep(make, demos, [0, 1], 0.01, RealTimeConfig(stride=5), **kw)
    lean = realtime_sweep(make, demos, [0, 1], 0.01, RealTimeConfig(stride=5), metrics=False, **kw)
    assert len(full) == len(lean) > 0
    for a, b in zip(full, lean):
        assert "rt_ctrl" in a and not any(key.startswith(("rt_", "cov_", "z_")) for key in b)
        assert (a["demo"], a["k"], a["phase"]) == (b["demo"], b["k"], b["phase"])
        np.testing.assert_array_equal(a["mean"], b["mean"])
        np.testing.assert_array_equal(a["truth"], b["truth"])


@pytest.mark.parametrize("T, stride, cap, expected_step", [(60, 3, 24, 3), (400, 3, 24, 12), (400, 1, None, 1),
                                                           (41, 1, 5, 6)])
def test_max_frames_bounds_the_evaluated_frames_of_a_long_movement(T, stride, cap, expected_step):
    """``max_frames`` caps the evaluated frames of one held-out movement (0.2-0.9 of it): the stride grows with the
    movement's length beyond ``stride * max_frames`` frames, else it is ``stride``; the frames stay evenly spaced
    from the first one."""
    rng = np.random.default_rng(3)
    test = np.cumsum(rng.normal(size=(T, 3)), axis=0)
    recs = realtime_fold(_Truth(test, 0.02), [test], test, [0, 1], 0.02,
                         RealTimeConfig(stride=stride, max_frames=cap), fitted=True, references=False)
    ks = [r["k"] for r in recs]
    k0, k1 = int(np.ceil(0.2 * T)), int(np.floor(0.9 * T))
    assert ks == list(range(k0, k1 + 1, expected_step))
    if cap is not None:
        assert len(ks) <= cap

"""The rest of the movement in seconds in the evaluation of a user's recordings (``interprim evaluate --data``):
every method, the family chosen inside the folds and the default blend scored over every remaining frame, from the
same fits as the real-time protocol, summarised beside it and named in the verdict."""

from dataclasses import replace

import numpy as np
import pytest

from interprim.assessment import evaluate_demonstrations
from interprim.core.preprocessing import time_normalise
from interprim.evaluation import realtime as rt
from interprim.model_selection.realtime import scored_frames
from interprim.synthetic import two_agent_demos

DT = 0.02
OBS = [0, 1]


@pytest.fixture(scope="module")
def demos():
    return two_agent_demos(9, seed=3, frames=60, noise=0.01)


def _counting(make):
    """``(factories, counts)``: each factory of ``make`` counting the models it builds."""
    counts = {m: 0 for m in make}

    def wrap(m, f):
        def build():
            counts[m] += 1
            return f()
        return build

    return {m: wrap(m, f) for m, f in make.items()}, counts


def test_the_rest_of_the_movement_is_scored_from_the_same_fits_after_every_third_frame(demos):
    """With ``rest_stride`` the sweep fits each method once per fold, as without it; its real-time records are
    unchanged; and each held-out demonstration gets a rest record per method after every 3rd scored frame, the
    clock's error there being the mean demonstration at the mean duration against every remaining frame."""
    make = {m: f for m, f in rt.default_methods(OBS).items() if m in ("ip", "prior")}
    cfg = rt.RealTimeConfig(stride=2)
    plain, n_plain = _counting(make)
    with_rest, n_rest = _counting(make)
    base = rt.realtime_sweep(plain, demos, OBS, DT, cfg, k=3)
    recs = rt.realtime_sweep(with_rest, demos, OBS, DT, cfg, k=3, rest_stride=3)
    assert n_rest == n_plain == {"ip": 3, "prior": 3}
    np.testing.assert_equal([r for r in recs if r.get("protocol") is None], base)  # NaN equal to NaN
    rest = [r for r in recs if r.get("protocol") == "rest"]
    rest_cfg = replace(cfg, stride=3)
    for j, d in enumerate(demos):
        want = list(scored_frames(len(d), rest_cfg))
        for m in ("ip", "prior", "clock", "oracle-duration"):
            assert [r["k"] for r in rest if r["demo"] == j and r["method"] == m] == want
    # the clock by hand on one case: the training fold's mean, time-normalised, played at its mean duration
    j, fold = 7, [6, 7, 8]
    train = [demos[i] for i in range(len(demos)) if i not in fold]
    mean = np.mean([time_normalise(x, cfg.n_grid) for x in train], axis=0)
    mean_dur = float(np.mean([len(x) - 1 for x in train])) * DT
    T = len(demos[j])
    k = scored_frames(T, rest_cfg)[2]
    t = (k - 1) * DT + np.arange(1, T - k + 1) * DT  # seconds since the first frame of every remaining frame
    grid = np.linspace(0.0, 1.0, cfg.n_grid)
    pred = np.column_stack([np.interp(np.clip(t / mean_dur, 0, 1), grid, mean[:, c]) for c in (2, 3, 4)])
    err = pred - demos[j][k:, 2:]
    got = next(r for r in rest if r["demo"] == j and r["method"] == "clock" and r["k"] == k)
    assert got["rt_ctrl"] == pytest.approx(np.sqrt(np.mean(err ** 2)), rel=1e-12)


def test_a_users_evaluation_reports_every_method_over_the_rest_of_the_movement(demos):
    """``evaluate_demonstrations`` (what ``interprim evaluate --data FILE`` runs) summarises the rest of the
    movement for every method, the chosen family and the default blend fitted inside the folds, beside real
    time; the clock's ratio is 1; the table and the verdict carry it; without ``rest_stride`` nothing changes."""
    cfg = rt.RealTimeConfig(stride=2)
    recs, summary, sentence = evaluate_demonstrations(demos, OBS, DT, k=3, methods=["ip", "nn", "prior"], cfg=cfg,
                                                      whole_movement=(0.6,))
    for m in ("ip", "nn", "prior", "chosen", "auto", "clock", "oracle-duration"):
        assert np.isfinite(summary[m]["rest_rt_ctrl_vs_clock"]), m
        assert np.isfinite(summary[m]["rest_rt_ctrl_vs_oracle"]), m
    assert summary["clock"]["rest_rt_ctrl_vs_clock"] == 1.0
    assert summary["oracle-duration"]["rest_rt_ctrl_vs_oracle"] == 1.0
    for m in ("auto", "chosen"):  # every held-out demonstration, over the rest too
        assert sorted({r["demo"] for r in recs if r["method"] == m and r.get("protocol") == "rest"}) == list(range(9))
    assert 0.0 <= summary["auto"]["rest_cov_ctrl"] <= 1.0
    # the rest of the movement is further ahead than the next 0.25 s: the clock's error there is larger
    assert summary["clock"]["rest_rt_ctrl"] > summary["clock"]["rt_ctrl"]
    table = rt.markdown_table(summary)
    assert "rest of the movement, controlled, x clock" in table.splitlines()[0]
    assert f"the blend has {summary['auto']['rest_rt_ctrl_vs_clock']:.2f}x the clock's error" in sentence
    assert f"the chosen model has {summary['chosen']['rest_rt_ctrl_vs_clock']:.2f}x" in sentence
    recs0, summary0, sentence0 = evaluate_demonstrations(demos, OBS, DT, k=3, methods=["ip", "nn", "prior"],
                                                         cfg=cfg, whole_movement=(0.6,), rest_stride=None)
    np.testing.assert_equal(recs0, [r for r in recs if r.get("protocol") != "rest"])
    assert not any(k.startswith("rest_") for v in summary0.values() for k in v)
    assert "rest of the movement" not in sentence0


def test_the_clock_named_when_it_beats_a_model_over_the_rest():
    """The verdict says so when the clock's error over the rest of the movement is smaller than the model's by more
    than one standard error (paired over demonstrations), and not otherwise."""
    recs = []
    for j in range(6):
        for m, e in (("clock", 1.0 + 0.01 * j), ("auto", 1.5 + 0.02 * j)):
            recs.append({"method": m, "demo": j, "k": 5, "rt_ctrl": e, "protocol": "rest"})
    summary = {"auto": {"rest_rt_ctrl_vs_clock": 1.5, "rest_rt_ctrl_vs_oracle": 1.4, "rest_cov_ctrl": 0.8}}
    said = " ".join(rt._rest_sentences(summary, recs, "auto", "the blend"))
    assert "The clock beats the blend there" in said
    better = [dict(r, rt_ctrl=r["rt_ctrl"] * (0.5 if r["method"] == "auto" else 1.0)) for r in recs]
    said = " ".join(rt._rest_sentences(summary, better, "auto", "the blend"))
    assert "1.50x the clock's error" in said and "beats" not in said and "band covers 80%" in said
    summary["auto"]["rest_cov_ctrl"] = float("nan")  # a method without a band (the nearest demonstration)
    said = " ".join(rt._rest_sentences(summary, better, "auto", "the blend"))
    assert "(it gives no band)" in said and "nan" not in said

"""The forward check of ``interprim evaluate --data``: the latest third of a user's recordings predicted by every
method and by the default blend fitted on the earlier two thirds only, as a robot predicts after its
demonstrations, with every yardstick and its standard error, and a verdict that names any rival beating the blend
there by more than one standard error."""

import json

import numpy as np
import pytest

from interprim import PaceWarning
from interprim.assessment import FORWARD_FROM, forward_check
from interprim.cli import main
from interprim.evaluation import realtime as rt
from interprim.evaluation.nested import (
    FORWARD_RIVALS,
    WHOLE_RIVALS,
    YARDSTICKS,
    beaten_by,
    forward_sentences,
    yardstick_markdown,
)
from interprim.synthetic import two_agent_demos

DT = 0.02
OBS = [0, 1]


def _session(n, seed=0):
    """``n`` recordings whose durations shrink with their order (a partner speeding up over a session)."""
    out = []
    for i in range(n):
        out += two_agent_demos(1, seed=seed + i, frames=70 - 3 * i, noise=0.01, stretch=(0.95, 1.05))
    return out


def _spying(monkeypatch):
    """Every training set a model of the evaluation's factories is fitted on (the default blend's inner folds
    included, since it is built from the same factories)."""
    seen = []
    real = rt.default_methods

    def spy(*a, **kw):
        make = real(*a, **kw)

        def wrap(f):
            def build():
                est = f()
                fit = est.fit

                def recorded(demos, *args, **kwargs):
                    seen.append([np.asarray(d) for d in getattr(demos, "demos", demos)])
                    return fit(demos, *args, **kwargs)

                est.fit = recorded
                return est
            return build

        return {m: wrap(f) for m, f in make.items()}

    monkeypatch.setattr(rt, "default_methods", spy)
    return seen


def test_every_model_is_fitted_on_the_earlier_recordings_and_scored_on_the_latest(monkeypatch):
    """9 recordings: every fit (each family's and the blend's inner folds) sees only recordings 0-5, every record
    is of recordings 6-8, every yardstick of every method is in the table, and the clock's ratio to itself is 1."""
    demos = _session(9)
    seen = _spying(monkeypatch)
    with pytest.warns(PaceWarning):  # the earlier recordings already speed up: the blend's fit says so
        res = forward_check(demos, OBS, DT, methods=["ip", "learned", "nn"], cfg=rt.RealTimeConfig(stride=4))
    assert res["latest"] == [6, 7, 8]
    early = demos[:6]
    assert len(seen) >= 4 + 3  # ip, learned, nn, prior alone; the blend's inner folds and members
    for train in seen:
        for d in train:
            assert any(d.shape == e.shape and np.array_equal(d, e) for e in early)
    assert {r["demo"] for r in res["records"]} == {6, 7, 8}
    assert {r["method"] for r in res["records"]} >= {"auto", "ip", "learned", "nn", "prior", "clock"}
    assert {r.get("protocol") for r in res["records"]} == {None, "rest", "whole"}
    table = res["table"]
    assert list(table) == [label for label, *_ in YARDSTICKS]
    assert list(table["real time ÷ clock"])[0] == "auto"
    for label in ("real time ÷ clock", "rest of the movement ÷ clock"):
        r, se = table[label]["clock"]
        assert r == 1.0 and se == 0.0
        r, se = table[label]["auto"]
        assert np.isfinite(r) and np.isfinite(se) and r > 0
    assert res["sentences"][0].startswith("Your latest 3 of 9 recordings, predicted by models fitted on the earlier")
    md = yardstick_markdown(table)
    assert md.splitlines()[0].startswith("| method | real time ÷ clock |") and "| auto | " in md


def test_fewer_recordings_than_the_check_needs_give_no_check():
    assert forward_check(_session(FORWARD_FROM - 1), OBS, DT, methods=["nn"]) is None


def _records(errors, protocol=None):
    """Real-time (or rest) records ``{method: [error per demonstration]}``, one case per demonstration."""
    out = []
    for m, es in errors.items():
        for j, e in enumerate(es):
            r = {"method": m, "demo": 10 + j, "rt_ctrl": float(e)}
            if protocol is not None:
                r["protocol"] = protocol
            out.append(r)
    return out


def test_the_verdict_names_a_rival_only_when_it_beats_the_blend_by_more_than_a_standard_error():
    auto = [1.0, 1.2, 0.9, 1.1]
    recs = _records({"auto": auto, "clock": [2.0, 2.4, 1.8, 2.2],
                     "learned": [0.5, 0.6, 0.45, 0.55],  # half the blend's error on every recording: named
                     "kernel": [0.9, 1.4, 0.7, 1.2]})  # 0.96x on average, noisier than that: not named
    rest = _records({"auto": auto, "clock": [2.0, 2.4, 1.8, 2.2], "kernel": [0.9, 1.4, 0.7, 1.2]}, "rest")
    for r, c in zip([r for r in rest if r["method"] == "auto"], [0.7, 1.0, 0.9, 0.9]):
        r["cov_ctrl"] = c
    # a second case of recording 10: its mean 0.8, the mean over recordings 0.9 (0.88 over cases)
    rest.append(dict(rest[0], k=7, cov_ctrl=0.9))
    out = forward_sentences(recs + rest, 12, [10, 11, 12, 13])
    assert out[0] == ("Your latest 4 of 12 recordings, predicted by models fitted on the earlier ones (as a robot "
                      "predicts after its demonstrations): the default blend has 0.50x the clock's error in real "
                      "time and 0.50x over the rest of the movement; its 90 % band covers 90% of the controlled "
                      "agent's frames over the rest.")
    assert len(out) == 2 and "learned in real time (0.50x ± 0.00 its error)" in out[1]
    assert f"with {2 * len(FORWARD_RIVALS)} comparisons made, one is won by chance" in out[1]  # said plainly
    assert "kernel" not in out[1] and "the rest of the movement (" not in out[1]
    calm = _records({"auto": auto, "clock": [2.0, 2.4, 1.8, 2.2], "kernel": [0.9, 1.4, 0.7, 1.2]})
    assert len(forward_sentences(calm, 12, [10, 11, 12, 13])) == 1
    assert set(FORWARD_RIVALS) >= {"learned", "ip", "kernel", "nn", "clock"} and "prior" not in FORWARD_RIVALS


def _whole(errors):
    """Whole-movement records ``{method: [error per demonstration]}`` (the paper's measure, one per demonstration)."""
    return [{"method": m, "demo": 10 + j, "protocol": "whole", "fraction": 0.6, "wm_ctrl": float(e)}
            for m, es in errors.items() for j, e in enumerate(es)]


def test_the_whole_movement_is_read_and_its_rivals_named():
    """With whole-movement records the verdict gives the blend's whole movement ÷ the mean demonstration's and names
    a family (or the mean itself, which stands for the clock there) that beats it there by more than a standard
    error; the comparisons it counts grow by the whole movement's rivals."""
    auto = [1.0, 1.2, 0.9, 1.1]
    rt_recs = _records({"auto": auto, "clock": [2.0, 2.4, 1.8, 2.2]})
    whole = _whole({"auto": auto, "prior": [1.1, 1.3, 1.0, 1.2], "learned": [0.8, 0.9, 0.75, 0.85],
                    "kernel": [0.7, 1.5, 0.6, 1.4]})  # learned 0.79x, steady; kernel 1.0x, noisy
    out = forward_sentences(rt_recs + whole, 12, [10, 11, 12, 13])
    assert out[0].endswith("the default blend has 0.50x the clock's error in real time, and 0.91x the mean "
                           "demonstration's on the whole movement.")
    assert "learned in the whole movement (0.79x ± 0.02 its error)" in out[1]
    assert "kernel" not in out[1] and "prior in" not in out[1]
    assert f"with {2 * len(FORWARD_RIVALS) + len(WHOLE_RIVALS)} comparisons made" in out[1]
    assert "prior" in WHOLE_RIVALS and "clock" not in WHOLE_RIVALS
    # the mean demonstration beating the blend on the whole movement is named like any rival
    worse = _whole({"auto": [1.5, 1.8, 1.4, 1.6], "prior": [1.1, 1.3, 1.0, 1.2]})
    assert [m for m, _, _ in beaten_by(worse, "auto", WHOLE_RIVALS, key="wm_ctrl")] == ["prior"]


def test_the_cross_validated_verdict_names_a_family_better_on_the_whole_movement():
    """The verdict of ``interprim evaluate --data`` says when a family alone beats the default blend on the paper's
    whole-movement measure by more than a standard error, and says nothing of it otherwise."""
    rng = np.random.default_rng(0)
    auto = 1.0 + 0.1 * rng.random(8)
    recs = [dict(r, chosen="learned", k=5) for r in _records({"auto": auto, "chosen": auto * 1.02,
                                                              "clock": 2 * auto, "learned": auto * 1.02})]

    def verdict(learned_whole):
        whole = _whole({"auto": auto, "chosen": learned_whole, "learned": learned_whole, "prior": auto * 1.05})
        summary = rt.summarise_with_rest(recs + whole)
        return rt.nested_verdict(summary, recs + whole, data="d.csv", observed="x")
    named = verdict(auto * 0.8)
    assert ("On the whole movement (the paper's measure, in normalised time), more than a standard error better "
            "than the blend (2 compared): learned (0.80x ± 0.00 its error).") in named
    assert "On the whole movement (the paper" not in verdict(auto * 1.01)


def _csv(path, n):
    lines = ["demo,time,hx,hy,rq"]
    for d in range(n):
        T = 34 - d  # a partner getting faster over the session
        s = np.sin(np.linspace(0, np.pi, T)) * (1 + 0.05 * d)
        for k in range(T):
            lines.append(f"{d},{0.02 * k!r},{float(s[k])!r},{float(s[k] / 2)!r},{float(0.7 * s[k] + 0.01 * d)!r}")
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.mark.parametrize("forward", [True, False])
def test_evaluate_writes_the_forward_check_unless_told_not_to(tmp_path, capsys, forward):
    data = _csv(tmp_path / "session.csv", 7)
    out = tmp_path / "ev"
    code = main(["evaluate", "--data", str(data), "--observed", "hx,hy", "--methods", "nn,prior", "--folds", "3",
                 "--n-basis", "5", "--no-figures", "--out", str(out)] + ([] if forward else ["--no-forward"]))
    printed = capsys.readouterr()
    assert code == 0, printed.err
    report = (out / "report.md").read_text()
    doc = json.loads((out / "realtime.json").read_text())
    if forward:
        assert "**Forward in recording order: the latest 3 recordings" in report and "**Forward check:**" in report
        assert doc["forward"]["latest"] == [4, 5, 6]
        assert {r["demo"] for r in doc["forward"]["records"]} == {4, 5, 6}
        assert doc["forward"]["verdict"].startswith("Your latest 3 of 7 recordings")
        assert "forward check: Your latest 3 of 7 recordings" in printed.out
        assert "forward check: auto fitted on the earlier 4 recordings" in printed.err
    else:
        assert "Forward" not in report and "forward" not in doc and "forward check" not in printed.out


def test_evaluate_says_why_the_forward_check_is_left_out_for_few_recordings(tmp_path, capsys):
    data = _csv(tmp_path / "few.csv", FORWARD_FROM - 1)
    code = main(["evaluate", "--data", str(data), "--observed", "hx,hy", "--methods", "nn", "--folds", "3",
                 "--n-basis", "5", "--no-figures", "--out", str(tmp_path / "ev")])
    err = capsys.readouterr().err
    assert code == 0
    assert f"forward check left out: it predicts the latest third of the recordings from the earlier two thirds " \
           f"and needs at least {FORWARD_FROM} recordings, got {FORWARD_FROM - 1}" in err

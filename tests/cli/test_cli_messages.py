"""Messages a person reads: one line per warning cause, flags without stray '=', the predict header, the serve
warm-up inside the training range, fit and evaluate reading a file the same way."""

from __future__ import annotations

import re
import warnings

import numpy as np

import interprim as ip
from interprim.cli import build_parser, main
from interprim.core.errors import DataFileWarning
from interprim.datasets import save_demonstrations
from interprim.synthetic import two_agent_demos


def _irregular(tmp_path, n=6, seed=0):
    rng = np.random.default_rng(seed)
    demos = two_agent_demos(n, seed=seed, frames=50)
    times = [np.cumsum(np.r_[0.0, 0.03 + 0.006 * rng.random(len(d) - 1)]) for d in demos]
    return save_demonstrations(tmp_path / "irr.csv", demos, times, columns=["hx", "hy", "j1", "j2", "j3"],
                               observed=["hx", "hy"])


def test_help_has_no_stray_equals_or_double_percent(capsys):
    parser = build_parser()
    sub = parser._subparsers._group_actions[0].choices
    for name in ("fit", "evaluate", "predict", "serve"):
        text = sub[name].format_help()
        assert "%%" not in text, name
        assert not re.search(r"--[a-z-]+= ", text), name
    assert "observe 10-100 % of the observed agent" in " ".join(sub["evaluate"].format_help().split())


def test_a_warning_cause_is_one_line_once_with_a_count(capsys):
    from interprim.cli import _OncePerCause

    once = _OncePerCause(build_parser(), "fit")
    for k in range(17):  # one cause, its numbers differing from fold to fold
        once.show(ip.RepresentationWarning(f"the DMPs with n_basis=5 cannot represent these movements ({0.6 + k / 100}x"
                                           " the spread)"), ip.RepresentationWarning, "/x/ensemble.py", 104)
    once.show(DataFileWarning("a.c3d: 1 of 4 markers left out"), DataFileWarning, "/x/y.py", 1)
    once.show(DataFileWarning("b.c3d: 1 of 4 markers left out"), DataFileWarning, "/x/y.py", 1)
    once.summary()
    err = capsys.readouterr().err
    assert err.count("\n") == 4 and "ensemble.py" not in err, err  # 1 + 2 files + the count
    assert err.startswith("warning: the DMPs with --n-basis 5 cannot represent these movements (0.6x the spread) "
                          "(RepresentationWarning)")
    assert "a.c3d: 1 of 4" in err and "b.c3d: 1 of 4" in err
    assert "was raised 17 times in all (its numbers may differ)" in err


def test_fit_prints_a_data_warning_once_without_the_source_line(tmp_path, capsys):
    path = _irregular(tmp_path)
    code = main(["fit", str(path), "--model", "ip", "--n-basis", "3", "-o", str(tmp_path / "m.npz")])
    cap = capsys.readouterr()
    assert code == 0, cap.err
    lines = [x for x in cap.err.splitlines() if x.startswith("warning:")]
    assert len(lines) == len(set(lines)) and not any(re.search(r"\.py:\d+", x) for x in cap.err.splitlines())


def test_fit_and_evaluate_read_irregular_stamps_the_same_way(tmp_path, capsys):
    path = _irregular(tmp_path)
    code = main(["fit", str(path), "--model", "ip", "--n-basis", "5", "-o", str(tmp_path / "m.npz")])
    out = capsys.readouterr().out
    assert code == 0
    note = re.search(r"resampled at their median interval ([\d.]+) s \(as --resample ([\d.]+)\)", out)
    assert note, out
    dt = float(note.group(1))
    assert f"dt={dt:.4g} s" in out
    code = main(["evaluate", "--data", str(path), "--methods", "prior", "--no-figures", "--out",
                 str(tmp_path / "ev")])
    cap = capsys.readouterr()
    assert code == 0, cap.err
    assert f"resampled at their median interval {note.group(1)} s" in cap.err


def test_predict_header_says_true_false_and_leaves_out_unknown_values(tmp_path, capsys):
    demos = two_agent_demos(6, seed=2, frames=40)
    path = save_demonstrations(tmp_path / "d.csv", demos, dt=0.02, columns=["hx", "hy", "j1", "j2", "j3"],
                               observed=["hx", "hy"])
    assert main(["fit", str(path), "--model", "nn", "-o", str(tmp_path / "m.npz")]) == 0
    part = save_demonstrations(tmp_path / "p.csv", [demos[0][:20, :2]], dt=0.02, columns=["hx", "hy"])
    assert main(["predict", str(tmp_path / "m.npz"), str(part), "-o", str(tmp_path / "out.csv")]) == 0
    head = [x for x in (tmp_path / "out.csv").read_text().splitlines() if x.startswith("#")]
    assert "# out_of_range: false" in head and "# duration_out_of_range: false" in head
    assert not any("nan" in x for x in head), head


def test_duration_far_outside_the_demonstrated_ones_is_flagged():
    from interprim.core.input_range import DURATION_FACTOR, duration_range, mark

    demos = two_agent_demos(6, seed=3, frames=50)
    m = ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=5).fit(demos, dt=0.02)
    lo, hi = duration_range(m)
    assert (lo, hi) == (float(m.durations_.min()), float(m.durations_.max()))
    pred = m.predict(demos[0][:25, :2])
    assert not pred.duration_out_of_range
    for d, flagged in ((hi * DURATION_FACTOR * 1.01, True), (hi * DURATION_FACTOR * 0.99, False),
                       (lo / DURATION_FACTOR * 0.99, True)):
        pred.duration = d
        mark(m, pred, pred.input_distance, warn=False)
        assert pred.duration_out_of_range is flagged


def test_server_reply_carries_the_duration_flag_and_warm_up_stays_in_range():
    import json

    from interprim.server import compute

    demos = two_agent_demos(6, seed=4, frames=50)
    m = ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=5).fit(demos, dt=0.02)
    frames = compute.warm_up_frames(m, 2)
    assert frames.shape == (20, 2) and m.input_distance(frames) < m.input_limit_
    with warnings.catch_warnings():
        warnings.simplefilter("error", ip.OutOfRangeWarning)
        st = m.stream()
        for f in frames:
            p = st.update(f)
    assert not p.out_of_range
    from interprim.server.models import entry_for

    # the server's own warm-up on a model trained far from 0 (real mocap in mm, say): no OutOfRangeWarning on start
    far = ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=5).fit([d + 500.0 for d in demos], dt=0.02)
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        compute.warm_up([entry_for("far", far)])
    assert not [w for w in rec if issubclass(w.category, ip.OutOfRangeWarning)], [str(w.message) for w in rec]

    e = entry_for("m", m)
    op = compute.OpenModel("m", [e], [m.stream()], [list(range(5))], 5, False)
    reply = json.loads(compute.compute_prediction(op, demos[0][0, :2], 1, None))
    assert reply["duration_out_of_range"] is False and reply["out_of_range"] is False


def _slow_partner(demos, factor=3.0, share=0.6, dt=0.02):
    """The first ``share`` of a demonstration's observed agent performed ``factor`` times slower."""
    from interprim.core.preprocessing import resample_uniform

    d = demos[0]
    slow = resample_uniform(d, np.arange(len(d)) * factor * dt, dt=dt)[0]
    return slow[: int(len(d) * factor * share), :2]


def test_a_partner_three_times_slower_is_flagged_in_python_predict_and_the_server(tmp_path, capsys):
    import json

    from interprim.server import compute
    from interprim.server.models import entry_for

    demos = two_agent_demos(8, seed=3, frames=60)
    m = ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=6, phase_method="dtw").fit(
        demos, dt=0.02, columns=["hx", "hy", "j1", "j2", "j3"])
    slow = _slow_partner(demos)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        pred = m.predict(slow)
        usual = m.predict(demos[1][:36, :2])
    assert pred.duration > 1.5 * m.durations_.max() and pred.duration_out_of_range and not pred.out_of_range
    assert not usual.duration_out_of_range
    # the command line
    m.save(tmp_path / "m.npz")
    part = save_demonstrations(tmp_path / "slow.csv", [slow], dt=0.02, columns=["hx", "hy"])
    assert main(["predict", str(tmp_path / "m.npz"), str(part), "-o", str(tmp_path / "out.csv")]) == 0
    out = capsys.readouterr().out
    assert re.search(r"WARNING: the predicted duration [\d.]+ s is far outside the demonstrated ones \(0\.94-1\.36 s; "
                     r"flagged beyond 1\.5x\)", out), out
    assert "# duration_out_of_range: true" in (tmp_path / "out.csv").read_text()
    # the server's replies
    op = compute.OpenModel("m", [entry_for("m", m)], [m.stream()], [list(range(5))], 5, False)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        replies = [json.loads(compute.compute_prediction(op, f, k + 1, None)) for k, f in enumerate(slow)]
    assert replies[-1]["duration_out_of_range"] is True and replies[-1]["out_of_range"] is False


def test_fit_error_table_states_the_files_unit(tmp_path, capsys):
    demos = two_agent_demos(5, seed=5, frames=40)
    path = save_demonstrations(tmp_path / "d.csv", demos, dt=0.02, columns=["hx", "hy", "j1", "j2", "j3"],
                               observed=["hx", "hy"])
    path.write_text("# units: m\n" + path.read_text())
    assert main(["fit", str(path), "-o", str(tmp_path / "m.npz")]) == 0
    out = capsys.readouterr().out
    assert "held-out real-time error of the controlled agent" in out
    assert "(errors in m: the unit of the controlled columns, as the file states it)" in out


def test_demo_without_the_promp_baseline_prints_no_empty_slice_warning(tmp_path, monkeypatch, capsys):
    """The optional Interaction ProMP baseline skipped: its row is 'n/a', not a numpy 'Mean of empty slice'."""
    import interprim.models.promp as promp

    class Missing:
        def __init__(self, *a, **k):
            raise ImportError("No module named 'movement_primitives' (made missing by the test)")

    monkeypatch.setattr(promp, "InteractionProMP", Missing)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        code = main(["demo", "--quick", "--no-gif", "--quiet", "--jobs", "1", "--out", str(tmp_path / "demo")])
    cap = capsys.readouterr()
    assert code == 0, cap.err
    assert "Mean of empty slice" not in cap.err + cap.out and "RuntimeWarning" not in cap.err
    import json

    res = json.loads((tmp_path / "demo" / "results.json").read_text())
    assert res["fig8"]["mean_distance_m"]["promp"] is None

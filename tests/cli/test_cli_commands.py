"""What the commands print and write: the 'interprim fit' command that evaluate's verdict prints reproduces what was
evaluated, and no command leaves an output file (or a temporary one) behind when it fails."""

import re
import shlex

import numpy as np
import pytest

import interprim.datasets as datasets
from interprim.cli import main


def _record_loads(monkeypatch):
    """Every set load_demonstrations returns, in order (the CLI imports it from interprim.datasets when run)."""
    seen = []
    real = datasets.load_demonstrations

    def spy(*a, **kw):
        ds = real(*a, **kw)
        seen.append(ds)
        return ds

    monkeypatch.setattr(datasets, "load_demonstrations", spy)
    return seen


def _printed_fit(out: str) -> list:
    m = re.search(r"To fit (?:it|the blend): (interprim fit .*? -o model\.npz)", out)
    assert m, out
    return shlex.split(m.group(1))


def _csv_with_observed_line(path, n=6, seed=0):
    """Irregular stamps, a missing value inside each demonstration, the observed columns named in the file."""
    rng = np.random.default_rng(seed)
    lines = ["# observed: human x, human_y", "demo,time,human x,human_y,robot_q"]
    for d in range(n):
        t = np.cumsum(rng.uniform(0.018, 0.022, 30))
        t -= t[0]
        s = np.sin(np.linspace(0, np.pi, 30)) * (1 + 0.1 * d)
        for k in range(30):
            hx = "nan" if k == 10 else repr(float(s[k]))
            lines.append(f"{d},{float(t[k])!r},{hx},{float(s[k] / 2)!r},{float(0.7 * s[k] + 0.01 * d)!r}")
    path.write_text("\n".join(lines) + "\n")
    return path


def test_evaluate_prints_a_fit_command_that_reads_the_same_data_csv(tmp_path, capsys, monkeypatch):
    data = _csv_with_observed_line(tmp_path / "my demos.csv")
    seen = _record_loads(monkeypatch)
    code = main(["evaluate", "--data", str(data), "--methods", "nn", "--folds", "3", "--n-basis", "6",
                 "--max-nan-gap", "1", "--resample", "0.02", "--no-figures", "--out", str(tmp_path / "ev")])
    out = capsys.readouterr().out
    assert code == 0
    words = _printed_fit(out)
    assert "None" not in words
    assert words[words.index("--observed") + 1] == "human x,human_y"  # from the file's '# observed:' line
    for flag, value in (("--max-nan-gap", "1"), ("--resample", "0.02"), ("--n-basis", "6")):
        assert words[words.index(flag) + 1] == value
    words[-1] = str(tmp_path / "model.npz")
    assert main(words[1:]) == 0, capsys.readouterr().err
    evaluated, fitted = seen[0], seen[-1]
    assert fitted.columns == evaluated.columns and fitted.observed_dofs == evaluated.observed_dofs
    for a, b in zip(evaluated.demos, fitted.demos):
        np.testing.assert_array_equal(a, b)


def test_evaluate_prints_a_fit_command_that_reads_the_same_data_c3d(tmp_path, capsys, monkeypatch):
    pytest.importorskip("ezc3d")
    from test_loaders_mocap import LABELS, handover, write_c3d

    xyz = np.concatenate([handover(30, seed=k) for k in range(6)])  # six reaches in one take, frames 1-180
    write_c3d(tmp_path / "take.c3d", xyz, LABELS)
    ranges = ",".join(f"{1 + 30 * k}-{30 + 30 * k}" for k in range(6))
    seen = _record_loads(monkeypatch)
    code = main(["evaluate", "--data", str(tmp_path / "take.c3d"), "--markers", "A:RHand,B:RHand",
                 "--split-frames", ranges, "--observed", "A:RHand_x,A:RHand_y,A:RHand_z", "--methods", "nn",
                 "--folds", "3", "--n-basis", "6", "--no-figures", "--out", str(tmp_path / "ev")])
    out = capsys.readouterr().out
    assert code == 0
    words = _printed_fit(out)
    assert words[words.index("--markers") + 1] == "A:RHand,B:RHand"
    assert words[words.index("--split-frames") + 1] == ranges
    words[-1] = str(tmp_path / "model.npz")
    assert main(words[1:]) == 0, capsys.readouterr().err
    evaluated, fitted = seen[0], seen[-1]
    assert len(fitted) == 6 and fitted.columns == evaluated.columns
    for a, b in zip(evaluated.demos, fitted.demos):
        np.testing.assert_array_equal(a, b)


# ----------------------------------------------------------------------------- output only on success
def _leftovers(folder):
    """Everything in ``folder`` (recursively), as names relative to it."""
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


def _two_agent_csv(path):
    from interprim.datasets import save_demonstrations
    from interprim.synthetic import two_agent_demos

    return save_demonstrations(path, two_agent_demos(5, seed=1), dt=0.01, columns=["h1", "h2", "r1", "r2", "r3"],
                               observed=["h1", "h2"])


def test_fit_that_fails_while_saving_leaves_no_file(tmp_path, monkeypatch):
    import interprim as ip

    data = _two_agent_csv(tmp_path / "demos.csv")
    out = tmp_path / "models" / "model.npz"

    def broken_save(self, path):
        with open(path, "wb") as fh:
            fh.write(b"PK\x03\x04 half a model")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(ip.InteractionPrimitive, "save", broken_save)
    with pytest.raises(OSError, match="No space left"):
        main(["fit", str(data), "--model", "ip", "--n-basis", "5", "-o", str(out)])
    assert _leftovers(tmp_path / "models") == []
    out.write_bytes(b"the model of yesterday")  # an earlier output is left as it was
    with pytest.raises(OSError):
        main(["fit", str(data), "--model", "ip", "--n-basis", "5", "-o", str(out)])
    assert out.read_bytes() == b"the model of yesterday" and _leftovers(out.parent) == ["model.npz"]
    monkeypatch.undo()
    assert main(["fit", str(data), "--model", "ip", "--n-basis", "5", "-o", str(out)]) == 0
    assert _leftovers(out.parent) == ["model.npz"] and ip.InteractionPrimitive.load(out).n_dofs_ == 5


@pytest.mark.parametrize("suffix", [".csv", ".npz"])
def test_predict_that_fails_while_writing_leaves_no_file(tmp_path, monkeypatch, suffix, capsys):
    data = _two_agent_csv(tmp_path / "demos.csv")
    assert main(["fit", str(data), "--model", "ip", "--n-basis", "5", "-o", str(tmp_path / "m.npz")]) == 0
    from interprim.datasets import save_demonstrations
    from interprim.synthetic import two_agent_demos

    data = save_demonstrations(tmp_path / "part.csv", [two_agent_demos(1, seed=9)[0][:, :2]], dt=0.01,
                               columns=["h1", "h2"])
    out = tmp_path / "pred" / f"p{suffix}"
    out.parent.mkdir()
    if suffix == ".npz":
        def broken(path, **arrays):
            with open(path, "wb") as fh:
                fh.write(b"PK half")
            raise OSError(28, "No space left on device")

        monkeypatch.setattr(np, "savez", broken)
    else:
        real_repr = repr
        calls = {"n": 0}

        def broken_repr(x):  # fails in the middle of the table
            calls["n"] += 1
            if calls["n"] > 50:
                raise OSError(28, "No space left on device")
            return real_repr(x)

        import builtins

        monkeypatch.setattr(builtins, "repr", broken_repr)
    with pytest.raises(OSError):
        main(["predict", str(tmp_path / "m.npz"), str(data), "--observe-fraction", "0.5", "-o", str(out)])
    monkeypatch.undo()
    assert _leftovers(out.parent) == []
    assert main(["predict", str(tmp_path / "m.npz"), str(data), "--observe-fraction", "0.5", "-o", str(out)]) == 0
    assert _leftovers(out.parent) == [out.name]


def test_evaluate_that_fails_while_writing_leaves_no_report(tmp_path, monkeypatch, capsys):
    import interprim.evaluation.realtime as rt

    data = _two_agent_csv(tmp_path / "demos.csv")
    real = rt.save_report

    def broken(*a, **kw):
        real(*a, **kw)  # every file written, then a failure (e.g. the figure's backend)
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(rt, "save_report", broken)
    out = tmp_path / "ev"
    with pytest.raises(OSError):
        main(["evaluate", "--data", str(data), "--methods", "nn", "--folds", "3", "--n-basis", "5", "--no-figures",
              "--out", str(out)])
    assert not out.exists() and _leftovers(tmp_path) == ["demos.csv"]


def test_evaluate_sweep_that_fails_while_writing_leaves_no_results(tmp_path, monkeypatch):
    import interprim.evaluation as ev

    def broken(res, summary, out):
        (out / "results.json").write_text("{half")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(ev, "run_sweep", lambda *a, **k: {})
    monkeypatch.setattr(ev, "summarise", lambda res: {})
    monkeypatch.setattr(ev, "save_results", broken)
    with pytest.raises(OSError):
        main(["evaluate", "--data", "synthetic", "--methods", "prior", "--no-figures", "--out", str(tmp_path / "ev")])
    assert _leftovers(tmp_path) == []


def test_handwriting_that_fails_leaves_no_results(tmp_path, monkeypatch):
    import interprim.experiments.handwriting as hw

    def broken(out, **kw):
        (out / "results.json").write_text("{half")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(hw, "run_handwriting", broken)
    with pytest.raises(OSError):
        main(["handwriting", "--shapes", "none", "--no-figures", "--out", str(tmp_path / "hw")])
    assert _leftovers(tmp_path) == []


def test_demo_that_fails_leaves_no_files(tmp_path, monkeypatch):
    import interprim.experiments.highfive as hf

    def broken(out, cfg, **kw):
        (out / "fig5_setup.png").write_bytes(b"\x89PNG half")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(hf, "run_highfive", broken)
    (tmp_path / "demo").mkdir()
    (tmp_path / "demo" / "notes.txt").write_text("mine")  # a file of the user's in the output folder is kept
    with pytest.raises(OSError):
        main(["demo", "--quiet", "--out", str(tmp_path / "demo")])
    assert _leftovers(tmp_path) == ["demo", "demo/notes.txt"]


# ----------------------------------------------------------------------------- numbers that cannot be given
def test_equal_length_demonstrations_give_no_phase_ratio_but_a_reason():
    """With demonstrations of equal length the clock's phase error is ~1e-17: the ratio to it was printed as
    1034665772332312.12; now it is left out, and the table and the verdict say why."""
    from interprim.evaluation.realtime import markdown_table, summarise_realtime, verdict

    recs = []
    for j in range(4):
        recs.append({"method": "clock", "phase_err": 1e-17 * (j + 1), "rt_ctrl": 0.2, "rt_obs": 0.1})
        recs.append({"method": "ip", "phase_err": 0.01, "rt_ctrl": 0.1, "rt_obs": 0.05})
    summary = summarise_realtime(recs)
    assert "phase_err_vs_clock" not in summary["ip"]
    assert summary["ip"]["rt_ctrl_vs_clock"] == pytest.approx(0.5)
    table = markdown_table(summary)
    assert "e+" not in table and "1034665772332312" not in table
    assert "Phase error x clock: not given, the clock's phase error is 2e-17" in table
    assert "timing cannot be compared with the clock's" in verdict(summary, "ip")
    recs.append({"method": "clock", "phase_err": 0.02, "rt_ctrl": 0.2, "rt_obs": 0.1})  # unequal: a ratio
    assert summarise_realtime(recs)["ip"]["phase_err_vs_clock"] == pytest.approx(0.01 / (0.02 / 5), rel=1e-9)


def test_evaluate_the_papers_configuration_on_built_in_data(tmp_path, capsys):
    """``interprim evaluate --data synthetic --methods ip-paper`` (a default method of the sweep) runs to its table:
    the sweep builds its variants from the registry's rows (the paper's ``sigma2="residual"``)."""
    pytest.importorskip("joblib")
    pytest.importorskip("tqdm")
    code = main(["evaluate", "--data", "synthetic", "--methods", "ip-paper", "--quick", "--no-recognition",
                 "--no-figures", "--backend", "threading", "--out", str(tmp_path / "ev")])
    out = capsys.readouterr().out
    assert code == 0 and "ip-paper" in out
    import json

    res = json.loads((tmp_path / "ev" / "results.json").read_text())
    recs = [r for r in res["folds"] if r["method"] == "ip-paper"]
    assert len(recs) == 4 * 5 and all(np.isfinite(r["rmse_ctrl"]) for r in recs)


def test_evaluate_with_a_horizon_prints_a_fit_command_for_that_horizon(tmp_path, capsys, monkeypatch):
    """``interprim evaluate --horizon 0.5`` prints an ``interprim fit`` command that fits for 0.5 s, and that
    command's model scores its candidates and tunes its kernel member for 0.5 s."""
    data = _csv_with_observed_line(tmp_path / "demos.csv")
    code = main(["evaluate", "--data", str(data), "--methods", "nn", "--folds", "3", "--horizon", "0.5",
                 "--resample", "0.02", "--max-nan-gap", "1", "--no-figures", "--out", str(tmp_path / "ev")])
    out = capsys.readouterr().out
    assert code == 0
    words = _printed_fit(out)
    assert words[words.index("--horizon") + 1] == "0.5"
    words[-1] = str(tmp_path / "model.npz")
    assert main(words[1:] + ["--model", "kernel"]) == 0, capsys.readouterr().err
    import interprim as ip

    model = ip.load_any(tmp_path / "model.npz")
    assert model.horizon == 0.5 and model.model_.horizon == 0.5


def test_fit_max_prefixes_option(tmp_path, capsys):
    """``interprim fit --max-prefixes N`` caps the prefixes the default scores per held-out demonstration and is
    stored with the model (``none``: no cap); refused for one family alone and for a value that is not a whole
    number >= 1, before anything is written."""
    data = _csv_with_observed_line(tmp_path / "demos.csv")
    out = tmp_path / "m.npz"
    import interprim as ip

    assert main(["fit", str(data), "--resample", "0.02", "--max-nan-gap", "1", "--max-prefixes", "8",
                 "-o", str(out)]) == 0
    capsys.readouterr()
    assert ip.load_any(out).max_prefixes == 8
    assert main(["fit", str(data), "--resample", "0.02", "--max-nan-gap", "1", "--max-prefixes", "none",
                 "-o", str(out)]) == 0
    capsys.readouterr()
    assert ip.load_any(out).max_prefixes is None
    out.unlink()
    assert main(["fit", str(data), "--resample", "0.02", "--max-nan-gap", "1", "--model", "nn",
                 "--max-prefixes", "8", "-o", str(out)]) != 0
    assert "--max-prefixes" in capsys.readouterr().err and not out.exists()
    for bad in ("0", "-3", "2.5", "x"):
        with pytest.raises(SystemExit):
            main(["fit", str(data), "--max-prefixes", bad, "-o", str(out)])
        assert "whole number of prefixes" in capsys.readouterr().err
    assert not out.exists()


def test_fit_frame_budget_option(tmp_path, capsys):
    """``interprim fit --frame-budget X`` bounds the default's frame (``none``: no bound), is refused for one family
    alone and for a value that is not a positive number, and the printed summary says what the frame costs."""
    data = _csv_with_observed_line(tmp_path / "demos.csv")
    out = tmp_path / "m.npz"
    assert main(["fit", str(data), "--resample", "0.02", "--max-nan-gap", "1", "--model", "nn", "--frame-budget", "2",
                 "-o", str(out)]) != 0
    assert "--frame-budget" in capsys.readouterr().err and not out.exists()
    with pytest.raises(SystemExit):
        main(["fit", str(data), "--frame-budget", "-1", "-o", str(out)])
    capsys.readouterr()
    assert main(["fit", str(data), "--resample", "0.02", "--max-nan-gap", "1", "--frame-budget", "1.5",
                 "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert "streamed frame (modelled)" in text and "the larger of 1.5x and 1.00 ms" in text
    import interprim as ip

    assert ip.load_any(out).frame_budget == 1.5
    # the floor in milliseconds: 0 makes the budget the multiple alone
    assert main(["fit", str(data), "--resample", "0.02", "--max-nan-gap", "1", "--frame-budget", "1.5",
                 "--frame-budget-floor", "0", "-o", str(out)]) == 0
    assert "the larger of 1.5x and 0.00 ms" in capsys.readouterr().out
    assert ip.load_any(out).frame_budget_floor == 0.0
    assert main(["fit", str(data), "--resample", "0.02", "--max-nan-gap", "1", "--frame-budget", "1.5",
                 "--predict-budget-floor", "0.5", "-o", str(out)]) == 0
    assert "predict from half the movement (modelled)" in capsys.readouterr().out
    assert ip.load_any(out).predict_budget_floor == 0.0005
    assert main(["fit", str(data), "--resample", "0.02", "--max-nan-gap", "1", "--predict-budget-floor", "none",
                 "-o", str(out)]) == 0
    assert ip.load_any(out).predict_budget_floor is None
    assert main(["fit", str(data), "--resample", "0.02", "--max-nan-gap", "1", "--model", "nn",
                 "--frame-budget-floor", "1", "-o", str(out)]) != 0
    assert "--frame-budget-floor" in capsys.readouterr().err
    for bad in ("-1", "nan", "inf", "x"):
        with pytest.raises(SystemExit):
            main(["fit", str(data), "--frame-budget-floor", bad, "-o", str(out)])
        assert "milliseconds" in capsys.readouterr().err

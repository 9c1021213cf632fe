"""Time stamps uniform up to rounding (30 Hz written with 3 or 5 decimals) are uniform in every command, by one rule
(:func:`interprim.datasets._base.sampling`); truly irregular stamps get a message saying by how much they deviate."""

import re

import numpy as np
import pytest

from interprim.datasets import load_demonstrations, save_demonstrations
from interprim.datasets._base import UNIFORM_TOLERANCE, sampling


def _cli(argv, capsys):
    from interprim.cli import main

    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def demos(n=5, T=45, seed=0):
    rng = np.random.default_rng(seed)
    out = []
    for k in range(n):
        s = np.linspace(0, 1, T + 2 * k)
        a = rng.uniform(0.8, 1.2) * (3 * s**2 - 2 * s**3)
        out.append(np.column_stack([a, 0.5 * a, np.sin(np.pi * s) * a, 2 * a]))
    return out


def write_rounded(path, ys, decimals, rate=30.0):
    """A CSV whose time column is k / rate written with ``decimals`` decimals (0.033, 0.067, 0.1, ...)."""
    with open(path, "w") as fh:
        fh.write("# observed: h_x, h_y\ndemo,time,h_x,h_y,r_x,r_y\n")
        for i, y in enumerate(ys):
            for k, row in enumerate(y):
                fh.write(f"{i},{round(k / rate, decimals):.{decimals}f},"
                         + ",".join(repr(float(v)) for v in row) + "\n")
    return path


@pytest.mark.parametrize("decimals", [3, 5])
def test_rounded_30hz_stamps_are_uniform(decimals):
    t = [np.round(np.arange(T) / 30, decimals) for T in (40, 57)]
    s = sampling(t)
    assert s.uniform and s.dt == pytest.approx(1 / 30, rel=1e-4)
    assert s.rounding == pytest.approx(0.5 * 10.0**-decimals)
    assert sampling(t, dt=1 / 30).uniform and not sampling(t, dt=1 / 29).uniform


def test_coarse_rounding_does_not_hide_a_dropped_frame():
    assert sampling([np.arange(20) / 10]).uniform  # 10 Hz written with one decimal: exact
    dropped = np.delete(np.round(np.arange(20) / 10, 1), 7)
    s = sampling([dropped])
    assert not s.uniform and s.rounding == 0.0 and "off a uniform grid" in s.describe()
    dropped = np.delete(np.round(np.arange(40) / 30, 2), 20)  # 30 Hz with 2 decimals (rounding 15 % of dt)
    assert sampling([np.round(np.arange(40) / 30, 2)]).uniform and not sampling([dropped]).uniform


def test_irregular_stamps_say_by_how_much():
    t = np.arange(40) / 30
    t[17] += 0.004  # 12 % of the interval
    s = sampling([t])
    assert not s.uniform and s.frame == 17 and s.deviation == pytest.approx(0.004, rel=0.05)
    assert "demonstration 0, frame 17 is 3.99 ms (12 %" in s.describe() and "% of the interval" in s.describe()
    t[17] -= 0.004 - 0.2 * UNIFORM_TOLERANCE / 30  # a fifth of the tolerance: uniform
    assert sampling([t]).uniform
    assert "different sampling intervals (demonstration 'b': 0.01 s, demonstration 'a': 0.0125 s)" in sampling(
        [np.arange(20) / 80, np.arange(20) / 100]).describe(["a", "b"])


def test_every_command_takes_rounded_stamps(tmp_path, capsys):
    import interprim as ip

    ys = demos()
    csv = write_rounded(tmp_path / "d.csv", ys, 3)
    ds = load_demonstrations(csv)
    assert ds.dt == pytest.approx(1 / 30, rel=1e-4)  # the least-squares interval, not the median 0.033
    model = tmp_path / "m.npz"
    code, out, err = _cli(["fit", "--model", "ip", csv, "--n-basis", "5", "-o", model], capsys)
    assert code == 0, err
    m = ip.InteractionPrimitive.load(model)
    assert m.dt_ == pytest.approx(1 / 30, rel=1e-4)
    # predict: the same frames with rounded stamps or without stamps (at the model's dt) give one answer
    part = tmp_path / "part.csv"
    write_rounded(part, [ys[1][:20]], 3)
    save_demonstrations(tmp_path / "bare.npz", [ys[1][:20]], dt=1.0, columns=["h_x", "h_y", "r_x", "r_y"])
    bare = np.load(tmp_path / "bare.npz")
    np.savez(tmp_path / "bare.npz", demo_000=bare["demo_000"], columns=bare["columns"])
    outs = []
    for src in (part, tmp_path / "bare.npz"):
        code, out, err = _cli(["predict", model, src, "-o", tmp_path / "p.npz"], capsys)
        assert code == 0, err
        outs.append(np.load(tmp_path / "p.npz")["mean"])
    np.testing.assert_array_equal(outs[0], outs[1])
    # serve: the replay keeps the file's frames (already on the model's grid up to rounding)
    from interprim.cli.serve import _attach_replays
    from interprim.server.models import load_models

    models = load_models([model])
    _attach_replays(models, [f"m={csv}"])
    np.testing.assert_allclose(models["m"].meta["replay"]["interactions"][2]["observed"], ys[2][:, :2], atol=1e-6)
    # evaluate: accepted, and irregular stamps are refused saying by how much
    code, out, err = _cli(["evaluate", "--data", csv, "--n-basis", "5", "--no-figures", "--out",
                           tmp_path / "ev"], capsys)
    assert code == 0, err
    text = csv.read_text().splitlines()
    parts = text[10].split(",")
    parts[1] = f"{float(parts[1]) + 0.005:.3f}"
    text[10] = ",".join(parts)
    (tmp_path / "bad.csv").write_text("\n".join(text) + "\n")
    # irregular stamps: read as 'interprim fit' reads them (resampled at their median interval), said in a note
    code, out, err = _cli(["evaluate", "--data", tmp_path / "bad.csv", "--methods", "prior", "--no-figures", "--out",
                           tmp_path / "ev2"], capsys)
    assert code == 0, err
    assert "note: the time stamps are not uniform: demonstration '0', frame 8 is 5" in err
    assert "% of the interval) off a uniform grid of 0.0333" in err
    assert re.search(r"resampled at their median interval 0\.033 s \(as --resample 0\.033\); give --resample DT", err)
    code, out, err = _cli(["fit", tmp_path / "bad.csv", "--model", "ip", "--n-basis", "5", "-o", model], capsys)
    assert code == 0 and "resampled at their median interval 0.033 s" in out and "dt=0.033 s" in out, out

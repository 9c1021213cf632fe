"""The control loops of examples/05_stream_control_loop.py and of the tutorial (step 8) keep their rate on every
branch, also when the partner's input is out of range (a ``continue`` once skipped the wait: 198 ticks in 0.01 s).

Timed on a fake clock: ``time.perf_counter`` returns the fake time and ``time.sleep`` advances it, so the work of
a tick takes no time and the wake-up times are exact.  No wall-clock assertion.
"""

from __future__ import annotations

import runpy
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import interprim.sim

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "scripts"))
from doc_outputs import TUTORIAL, blocks  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]


class FakeClock:
    """``perf_counter`` and ``sleep`` of a clock that moves only when the program sleeps."""

    def __init__(self):
        self.now = 1000.0
        self.wakes = []

    def perf_counter(self):
        return self.now

    def sleep(self, seconds):
        assert seconds >= 0.0
        self.now += seconds
        self.wakes.append(self.now)


def _partner_in(monkeypatch, scale):
    """``interprim.sim.highfive_recordings`` with the held-out partner's columns multiplied by ``scale``
    (1000: millimetres given to a model trained in metres)."""
    original = interprim.sim.highfive_recordings

    def recordings(*args, **kwargs):
        ds = original(*args, **kwargs)
        if kwargs.get("region") != "test":
            return ds
        out = []
        for d in ds.demos:
            d = np.array(d, dtype=np.float64)
            d[:, :2] *= scale
            out.append(d)
        return out

    monkeypatch.setattr(interprim.sim, "highfive_recordings", recordings)
    return original


def _check_rate(clock, start, n_ticks, dt):
    wakes = np.array(clock.wakes)
    assert len(wakes) == n_ticks, f"{len(wakes)} waits for {n_ticks} ticks"
    np.testing.assert_allclose(wakes - start, dt * np.arange(1, n_ticks + 1), rtol=0, atol=1e-9)


@pytest.mark.parametrize("scale", [1.0, 1000.0], ids=["in-range", "millimetres"])
def test_example_loop_keeps_its_rate(monkeypatch, capsys, scale):
    clock = FakeClock()
    original = _partner_in(monkeypatch, scale)
    monkeypatch.setattr(time, "perf_counter", clock.perf_counter)
    monkeypatch.setattr(time, "sleep", clock.sleep)
    start = clock.now
    with pytest.warns(interprim.OutOfRangeWarning) if scale != 1.0 else _nothing():
        ns = runpy.run_path(str(ROOT / "examples" / "05_stream_control_loop.py"), run_name="__main__")
    out = capsys.readouterr().out
    n_ticks = len(original(1, seed=7, region="test", noise=0.0)[0]) + 30
    assert ns["n_ticks"] == n_ticks
    _check_rate(clock, start, n_ticks, ns["dt"])
    if scale != 1.0:
        assert out.count("input out of range") == 1, out  # said once, then the robot holds
        assert np.allclose(ns["q"], interprim.sim.controlled_arm().rest)  # and it never moved
    else:
        assert "out of range" not in out


def test_tutorial_loop_keeps_its_rate(monkeypatch, tmp_path, capsys):
    import interprim as ip

    code = [b.body for b in blocks(TUTORIAL.read_text()) if b.lang == "python" and "stream.update" in b.body
            and "next_tick" in b.body]
    assert len(code) == 1, "the tutorial's control loop (step 8) not found"
    demos = interprim.sim.highfive_recordings(20, seed=0)
    ip.InteractionPrimitive(observed_dofs=demos.observed_dofs, n_basis=10).fit(demos).save(tmp_path / "model.npz")
    monkeypatch.chdir(tmp_path)
    original = _partner_in(monkeypatch, 1000.0)
    clock = FakeClock()
    monkeypatch.setattr(time, "perf_counter", clock.perf_counter)
    monkeypatch.setattr(time, "sleep", clock.sleep)
    start = clock.now
    ns = {"__name__": "__main__"}
    with pytest.warns(ip.OutOfRangeWarning):
        exec(compile(code[0], str(TUTORIAL), "exec"), ns)
    n_ticks = len(original(1, seed=7, region="test")[0]) + 30
    _check_rate(clock, start, n_ticks, ns["model"].dt_)
    assert ns["pred"].out_of_range


class _nothing:
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False

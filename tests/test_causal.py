"""Causal prefixes: a prediction sees only what a robot had recorded by the time of its last frame."""

import numpy as np
import pytest

from interprim.datasets import Demonstrations, RawStream, load_nuisi
from interprim.evaluation.protocol import Prefixes, causal_prefix
from interprim.evaluation.realtime import RealTimeConfig, realtime_sweep


def _raw_set(rng, n=4, dt=0.05):
    """Demonstrations interpolated onto a 20 Hz grid from irregular ~9 Hz raw samples (like NuiSI)."""
    demos, times, raw = [], [], []
    for _ in range(n):
        t_raw = np.cumsum(rng.uniform(0.08, 0.14, size=25))
        t_raw -= t_raw[0]
        v = np.cumsum(rng.normal(size=(25, 3)), axis=0)
        grid = np.arange(int(np.floor(t_raw[-1] / dt)) + 1) * dt
        demos.append(np.stack([np.interp(grid, t_raw, v[:, c]) for c in range(3)], axis=1))
        times.append(grid)
        raw.append([RawStream(t_raw, (0, 1), v[:, :2]), RawStream(t_raw, (2,), v[:, 2:])])
    return Demonstrations(demos, times, ["a", "b", "c"], dt=dt, observed_dofs=[0, 1], raw=raw)


def test_prefix_never_uses_a_sample_after_its_end_time(rng):
    ds = _raw_set(rng)
    for j, (t, streams) in enumerate(zip(ds.times, ds.raw)):
        for k in range(1, len(t) + 1):
            got = causal_prefix(t, streams, k, [0, 1])
            # change every raw sample recorded after the prefix's last frame: the prefix must not move
            later = [RawStream(s.times, s.columns, np.where((s.times > t[k - 1])[:, None], 1e6, s.values))
                     for s in streams]
            np.testing.assert_array_equal(causal_prefix(t, later, k, [0, 1]), got)
            # inside the span of the samples it saw, it is the full recording's interpolation
            last = streams[0].times[np.searchsorted(streams[0].times, t[k - 1], side="right") - 1]
            inside = t[:k] <= last
            np.testing.assert_allclose(got[inside], ds.demos[j][:k][inside][:, :2], rtol=0, atol=1e-12)


def test_full_recording_interpolation_looks_ahead_on_nuisi():
    """The look-ahead is real on NuiSI: the uncut interpolation's last frame differs from the causal one,
    and perturbing the raw samples after the cut changes the former but not the latter."""
    ds = load_nuisi(None, action="highfive1")
    P = Prefixes(ds, ds.observed_dofs)
    assert P.causal
    moved = []
    for j, x in enumerate(ds.demos):
        k = round(0.5 * len(x))
        moved.append(np.max(np.abs(P(j, k)[-1] - x[k - 1, ds.observed_dofs])))
    assert np.median(moved) > 1e-3  # metres: the uncut interpolation uses a later raw sample
    for j in range(len(ds)):  # frame 0: the last raw sample of agent 1 at or before the grid's start
        s = ds.raw[j][0]
        i = np.searchsorted(s.times, ds.times[j][0] + 1e-9, side="right") - 1
        assert i >= 0
        np.testing.assert_array_equal(P(j, 1)[0], s.values[i])


def test_select_keeps_raw_streams_aligned(rng):
    ds = _raw_set(rng)
    sub = ds.select(["c", "a"])
    assert sub.observed_dofs == [1]
    P = Prefixes(sub, [1, 0])
    full = Prefixes(ds, [0, 2])
    np.testing.assert_array_equal(P(0, 9), full(0, 9))


class Spy:
    """An estimator that remembers what it was given and predicts the training mean."""

    def __init__(self, log):
        self.log = log

    def fit(self, demos, dt=None):
        self.train = [np.array(d) for d in demos]
        self.log.append(("fit", self.train))
        return self

    def predict(self, partial):
        self.log.append(("predict", np.array(partial)))
        from interprim.evaluation.baselines import PriorMean

        return PriorMean([0, 1]).fit(self.train).predict(partial)


def test_realtime_sweep_predicts_from_causal_prefixes_only(rng):
    ds = _raw_set(rng, n=5)
    log = []
    recs = realtime_sweep({"spy": lambda: Spy(log)}, ds, [0, 1], ds.dt, RealTimeConfig(horizon=0.1), k=5,
                          whole_movement=(0.5,))
    assert recs
    P = Prefixes(ds, [0, 1])
    fits = [e for e in log if e[0] == "fit"]
    preds = [e[1] for e in log if e[0] == "predict"]
    assert len(fits) == 5
    for partial in preds:
        # every partial equals the causal prefix of some demonstration, and never the uncut interpolation
        # when the two differ
        matches = [j for j in range(len(ds)) if np.array_equal(partial, P(j, len(partial)))]
        assert matches, "a prediction saw something other than a causal prefix"
    lookahead = sum(not np.array_equal(P(j, k), ds.demos[j][:k, :2])
                    for j in range(len(ds)) for k in range(3, len(ds.demos[j])))
    assert lookahead > 0  # the test data does have a look-ahead to avoid


def test_causal_prefix_errors_name_the_problem(rng):
    ds = _raw_set(rng, n=1)
    t, s = ds.times[0], ds.raw[0]
    with pytest.raises(ValueError, match="k must be"):
        causal_prefix(t, s, 0, [0])
    with pytest.raises(ValueError, match="column 5"):
        causal_prefix(t, s, 3, [5])
    late = [RawStream(s[0].times + 1.0, s[0].columns, s[0].values)]
    with pytest.raises(ValueError, match="no raw sample"):
        causal_prefix(t, late, 2, [0])

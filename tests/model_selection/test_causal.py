"""Causal prefixes: a prediction sees only what a robot had recorded by the time of its last frame."""

import numpy as np
import pytest

from interprim.datasets import Demonstrations, RawStream, load_nuisi
from interprim.evaluation.realtime import RealTimeConfig, realtime_sweep
from interprim.model_selection.prefixes import Prefixes, causal_prefix


def _nuisi_file():
    """The NuiSI file of the shared data folder, or None on a clone without it (as the other data tests)."""
    from interprim.datasets import data_dir

    try:
        f = data_dir() / "nuisi_v1" / "nuisi_v1_segmented.npz"
    except FileNotFoundError:  # DataNotFoundError is a FileNotFoundError
        return None
    return f if f.is_file() else None


needs_nuisi = pytest.mark.skipif(_nuisi_file() is None, reason="NuiSI data (../shared/data/nuisi_v1) not found")


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


@needs_nuisi
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
        from interprim.models.demonstrations import PriorMean

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


def test_take_keeps_raw_samples_and_labels_of_the_chosen_recordings(rng):
    ds = _raw_set(rng, n=5)
    sub = ds.take([3, 1])
    assert len(sub) == 2 and sub.labels == [ds.labels[3], ds.labels[1]]
    for i, j in enumerate([3, 1]):
        np.testing.assert_array_equal(sub.demos[i], ds.demos[j])
        np.testing.assert_array_equal(sub.times[i], ds.times[j])
        assert sub.raw[i] is ds.raw[j]
    # the causal prefixes of the subset are those of the full set
    P, Q = Prefixes(ds, [0, 1]), Prefixes(sub, [0, 1])
    assert Q.causal
    np.testing.assert_array_equal(Q(0, 7), P(3, 7))
    with pytest.raises(IndexError, match="index 9 out of range for 5"):
        ds.take([0, 9])


@needs_nuisi
def test_development_only_sweep_never_loads_the_holdout():
    """``EvalConfig(development_only=True)``: the NuiSI tasks hold the first two thirds of the recordings."""
    from interprim.evaluation.nested import split_holdout
    from interprim.evaluation.sweep import EvalConfig, load_task

    full = load_task("nuisi", "handshake2", EvalConfig())
    dev = load_task("nuisi", "handshake2", EvalConfig(development_only=True))
    keep, hold = split_holdout(len(full.demos))
    assert len(dev.demos) == len(keep) < len(full.demos)
    for i, j in enumerate(keep):
        np.testing.assert_array_equal(dev.demos[i], full.demos[j])
        np.testing.assert_array_equal(dev.prefix(i, 9), full.prefix(j, 9))
    held = {full.demos[j].tobytes() for j in hold}
    assert not any(d.tobytes() in held for d in dev.demos)


def test_remeasure_tables_and_deciles():
    from interprim.experiments.remeasure import calibration_deciles, realtime_tables

    recs = [{"method": "ip", "fraction": f, "z_ctrl": z, "z_obs": 2 * z} for f, z in
            [(0.21, 1.0), (0.29, 3.0), (0.55, 0.5), (0.9, 4.0), (0.95, 9.0)]]
    recs.append({"method": "ip", "fraction": 0.25, "protocol": "whole", "z_ctrl": 100.0})
    d = calibration_deciles(recs)
    assert d["ip"]["ctrl"] == {"0.2": 2.0, "0.5": 0.5, "0.8": 4.0}  # 0.95 is past the last decile
    assert d["ip"]["obs"]["0.2"] == 4.0
    summary = {"ip": {"rt_ctrl_vs_clock": 0.5, "cov_ctrl": 0.9}, "clock": {"rt_ctrl_vs_clock": 1.0}}
    res = {"highfive1": {"summary": summary, "deciles": d},
           "wave1": {"summary": {"ip": {"rt_ctrl_vs_clock": 2.0, "cov_ctrl": 0.8}}, "deciles": {}}}
    md = realtime_tables(res, methods=("ip",))
    assert "| ip | 0.50 | 2.00 | 1.00 |" in md  # geometric mean over the NuiSI tasks
    assert "| ip | 0.90 | 0.80 | 0.85 |" in md  # coverage: arithmetic mean
    assert "| highfive1 | robot | 2.00 | — | — | 0.50 | — | — | 4.00 |" in md

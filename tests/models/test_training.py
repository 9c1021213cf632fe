"""One validated training set, read once (issue 35): the adapter ``interprim.models.training.training_set``."""

import sys

import numpy as np
import pytest

from interprim.models import registry, training
from interprim.models.training import TrainingSet, training_set
from interprim.synthetic import two_agent_demos
from interprim.testing import jittered_demonstrations

FAST = [n for n, f in registry.FAMILIES.items() if not f.needs]


def _spy(monkeypatch, module, name):
    """Count the calls of ``module.name`` from every interprim module that holds it (however it was imported)."""
    real = getattr(module, name)
    calls = []

    def spy(*args, **kwargs):
        calls.append(args)
        return real(*args, **kwargs)

    for mod_name, mod in list(sys.modules.items()):
        if mod_name.startswith("interprim") and getattr(mod, name, None) is real:
            monkeypatch.setattr(mod, name, spy)
    return calls


@pytest.mark.parametrize("name", FAST)
def test_a_fit_of_irregular_stamps_resamples_each_demonstration_once(name, monkeypatch):
    """The base class used to read the demonstrations again after the family's fit (for the input range), so an
    irregular set was resampled twice per fit; the adapter now builds the set once and both use it."""
    from interprim.core import preprocessing

    ds, durations = jittered_demonstrations(7, seed=2)
    calls = _spy(monkeypatch, preprocessing, "resample_uniform")
    model = registry.factories([name], registry.Settings((0, 1)))[name]().fit(ds)
    assert len(calls) == len(ds)
    assert [c[0].shape[0] for c in calls] == [len(d) for d in ds.demos]  # the raw recordings, each once
    assert model.mean_duration_ == pytest.approx(np.mean(durations), rel=0.05)


def test_every_family_takes_a_training_set_and_a_fold_of_it_without_reading_again(monkeypatch):
    from interprim.core import validation

    demos = two_agent_demos(8, seed=3)
    data = training_set(demos, dt=0.02)
    fold = data.take([0, 2, 3, 5, 6, 7])
    assert [a is data.arrays[i] for a, i in zip(fold.arrays, (0, 2, 3, 5, 6, 7))] == [True] * 6
    assert fold.dt == 0.02 and len(fold) == 6
    calls = _spy(monkeypatch, validation, "as_2d_finite")

    def reads():  # checks of whole demonstrations (a phase model checks its own observed columns: not counted)
        return [c for c in calls if str(c[1]).startswith("demos") and c[0].shape[1] == data.n_dofs]

    partial = demos[1][:40, :2]
    for name in FAST:
        make = registry.factories([name], registry.Settings((0, 1)))[name]
        a = make().fit(fold)
        assert not reads(), name  # no demonstration read again
        b = make().fit([demos[i] for i in (0, 2, 3, 5, 6, 7)], dt=0.02)  # the public form: the same model
        assert len(reads()) == 6, name  # each read once, by the adapter
        del calls[:]
        np.testing.assert_array_equal(a.predict(partial).trajectory(30), b.predict(partial).trajectory(30))


def test_the_training_set_is_frozen_and_keeps_what_the_source_said():
    ds, _ = jittered_demonstrations(4, seed=0)
    data = training_set(ds)
    assert isinstance(data, TrainingSet) and data.resampled and data.columns == tuple(ds.columns)
    assert data.observed_dofs == (0, 1) and data.raw is None
    dts = [float(np.median(np.diff(t))) for t in ds.times]
    assert min(dts) <= data.dt <= max(dts)
    with pytest.raises(ValueError):
        data.arrays[0][0, 0] = 1.0  # read-only
    with pytest.raises(AttributeError):
        data.dt = 0.5
    assert training_set(data) is data
    with pytest.raises(ValueError, match="dt=0.5 differs"):
        training_set(data, dt=0.5)
    with pytest.raises(IndexError, match="out of range"):
        data.take([4])
    assert list(data.durations) == pytest.approx([(len(a) - 1) * data.dt for a in data.arrays])
    assert data.frames([1]).shape == (sum(data.lengths), 1)


def test_the_adapter_names_what_is_wrong():
    demos = two_agent_demos(3, seed=1)
    with pytest.raises(TypeError, match="list"):
        training_set("demos.csv")
    with pytest.raises(ValueError, match=r"demos\[1\] has 3 columns but demos\[0\] has 5"):
        training_set([demos[0], demos[1][:, :3]])
    with pytest.raises(ValueError, match="either dt or times"):
        training_set(demos, dt=0.01, times=[np.arange(len(d)) * 0.01 for d in demos])
    with pytest.raises(ValueError, match="columns has 2 names"):
        training_set(demos, columns=["a", "b"])
    with pytest.raises(ValueError, match="empty"):
        training_set([])
    assert training.uniform_demonstrations(demos, 0.05)[1] == 0.05


def test_a_training_set_keeps_the_raw_samples_for_causal_prefixes():
    """A Demonstrations interpolated from raw samples (a slow sensor) keeps them in its TrainingSet, so the causal
    prefixes of a cross-validation (model_selection.prefixes.Prefixes) come from the set itself, folds included."""
    from interprim.datasets import Demonstrations, RawStream
    from interprim.model_selection.prefixes import Prefixes

    demos, times, raw = [], [], []
    for d in two_agent_demos(4, seed=6):
        t = np.arange(len(d)) * 0.01
        slow = np.arange(0, len(d), 7)  # the observed agent recorded every 7th frame
        raw.append([RawStream(t[slow], (0, 1), d[slow, :2]), RawStream(t, (2, 3, 4), d[:, 2:])])
        demos.append(np.column_stack([np.column_stack([np.interp(t, t[slow], d[slow, c]) for c in (0, 1)]),
                                      d[:, 2:]]))
        times.append(t)
    ds = Demonstrations(demos, times, [f"c{i}" for i in range(5)], dt=0.01, observed_dofs=[0, 1], raw=raw)
    data = training_set(ds)
    assert data.raw is not None and not data.resampled and data.dt == 0.01
    ours, theirs = Prefixes(data.take([2, 3]), [0, 1]), Prefixes(ds, [0, 1]).subset([2, 3])
    assert ours.causal
    for j, k in ((0, 10), (1, 23), (1, 40)):
        np.testing.assert_array_equal(ours(j, k), theirs(j, k))
    assert not np.array_equal(ours(1, 23), data.arrays[3][:23, :2])  # causal: not the interpolated frames
    assert training_set(ds, dt=0.01).raw is not None  # its own interval, given again: still its raw samples
    assert training_set(ds, dt=0.02).raw is None  # another interval: the arrays are read on that grid

    # the default's inner cross-validation takes its causal prefixes from the training set
    from interprim import AutoInteraction
    from interprim.model_selection import stacking

    seen = []

    class Stop(Exception):
        pass

    def spy(make, cv_demos, *args, **kwargs):
        seen.append(cv_demos)
        raise Stop

    mp = pytest.MonkeyPatch()
    mp.setattr(stacking, "CrossValidation", spy)
    try:
        for kw in ({}, {"dt": 0.01}):
            with pytest.raises(Stop):
                AutoInteraction([0, 1], candidates=["prior", "nn"], frame_budget=None).fit(ds, **kw)
    finally:
        mp.undo()
    assert all(Prefixes(s, [0, 1]).causal for s in seen) and len(seen) == 2
    np.testing.assert_array_equal(Prefixes(seen[1], [0, 1])(3, 23), Prefixes(ds, [0, 1])(3, 23))

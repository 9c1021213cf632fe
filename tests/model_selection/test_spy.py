"""A spy over the whole evaluation: no prediction ever sees anything derived from its held-out recording.

Every method of ``evaluate_demonstrations`` (the library's defaults, LearnedInteraction, the paper's
configuration, nearest neighbour, the mean) is wrapped; the spy identifies every array an estimator is given
(training demonstrations, observed prefixes) and asserts that

* a prediction is made only from a causal prefix (raw samples recorded by its last frame; never the uncut
  interpolation), of a demonstration that was not in that estimator's training data;
* ``predict`` gets the prefix alone: no duration, no phase, no keyword;
* while the nested choice for an outer fold is made, no estimator is fitted on or predicts any demonstration
  of that outer fold (the choice, a hyper-parameter, is made on its training folds only).
"""

import numpy as np
import pytest

from interprim.datasets import Demonstrations, RawStream
from interprim.evaluation import realtime
from interprim.model_selection.prefixes import Prefixes


def _data(seed=3, n=8, dt=0.05):
    rng = np.random.default_rng(seed)
    demos, times, raw = [], [], []
    for _ in range(n):
        t_raw = np.cumsum(rng.uniform(0.08, 0.14, size=22))
        t_raw -= t_raw[0]
        u = t_raw / t_raw[-1]
        base = np.stack([np.sin(np.pi * u), u ** 2, 0.5 * np.sin(np.pi * u) + u], axis=1)
        v = base * rng.uniform(0.7, 1.3) + 0.02 * rng.normal(size=base.shape)
        grid = np.arange(int(np.floor(t_raw[-1] / dt)) + 1) * dt
        demos.append(np.stack([np.interp(grid, t_raw, v[:, c]) for c in range(3)], axis=1))
        times.append(grid)
        raw.append([RawStream(t_raw, (0, 1), v[:, :2]), RawStream(t_raw, (2,), v[:, 2:])])
    return Demonstrations(demos, times, ["a", "b", "c"], dt=dt, observed_dofs=[0, 1], raw=raw)


class _Spy:
    def __init__(self, inner, name, world):
        self.inner, self.name, self.world = inner, name, world

    def fit(self, demos, dt=None):
        ids = set()
        for d in demos:
            hit = [j for j, x in enumerate(self.world.ds.demos) if x.shape == d.shape and np.array_equal(x, d)]
            assert len(hit) == 1, "fit was given an array that is not one of the recordings"
            ids.add(hit[0])
        self.train_ids = ids
        self.world.check_allowed(ids)
        self.world.fits += 1
        self.inner.fit(demos, dt=dt)
        return self

    def predict(self, *args, **kwargs):
        assert len(args) == 1 and not kwargs, f"{self.name}.predict got more than the observed prefix"
        partial = np.asarray(args[0])
        k = len(partial)
        src = [j for j in range(len(self.world.ds)) if len(self.world.ds.demos[j]) >= k
               and np.array_equal(partial, self.world.P(j, k))]
        assert src, f"{self.name} was given something other than a causal prefix"
        assert not set(src) & self.train_ids, f"{self.name} predicts a recording it was trained on"
        self.world.check_allowed(set(src))
        self.world.predicts += 1
        return self.inner.predict(partial)


class _World:
    def __init__(self, ds):
        self.ds, self.P = ds, Prefixes(ds, ds.observed_dofs)
        self.allowed = None
        self.fits = self.predicts = self.choices = 0

    def check_allowed(self, ids):
        if self.allowed is not None:
            assert ids <= self.allowed, "the nested choice saw a demonstration of its outer test fold"


@pytest.mark.slow
def test_no_prediction_sees_its_held_out_recording(monkeypatch):
    ds = _data()
    world = _World(ds)
    real_methods = realtime.default_methods

    def spied_methods(*a, **kw):
        return {name: (lambda f=f, name=name: _Spy(f(), name, world)) for name, f in real_methods(*a, **kw).items()}

    from interprim.model_selection import stacking as auto

    real_cv = auto.CrossValidation

    def spied_cv(make, demos, *a, **kw):  # the nested choice (and the blend's weights) of each outer fold
        allowed = set()
        for d in demos.demos:
            allowed |= {j for j, x in enumerate(ds.demos) if x.shape == d.shape and np.array_equal(x, d)}
        world.allowed = allowed
        world.choices += 1
        try:
            return real_cv(make, demos, *a, **kw)
        finally:
            world.allowed = None

    monkeypatch.setattr(realtime, "default_methods", spied_methods)
    monkeypatch.setattr(auto, "CrossValidation", spied_cv)
    from interprim.assessment import evaluate_demonstrations

    recs, summary, sentence = evaluate_demonstrations(
        ds, [0, 1], ds.dt, k=3, inner_k=2, cfg=realtime.RealTimeConfig(horizon=0.1, stride=4),
        whole_movement=(0.6,))
    assert world.choices == 3 and world.fits > 15 and world.predicts > 50
    assert "chosen" in summary and sentence.startswith("chosen inside the training folds")
    chosen = {r["demo"]: r["chosen"] for r in recs if r["method"] == "chosen"}
    assert sorted(chosen) == list(range(len(ds)))
    # the blend interprim fit makes, fitted inside each outer fold, predicted every held-out recording too
    assert "auto" in summary and sorted({r["demo"] for r in recs if r["method"] == "auto"}) == list(range(len(ds)))

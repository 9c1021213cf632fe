"""The synthetic benchmark has an honest floor: it cannot be solved by reading parameters."""

import numpy as np
import pytest

from interprim.core.preprocessing import time_normalise
from interprim.synthetic import benchmark_tasks, two_agent_demos


def _robot_rmse(pred, truth):
    return float(np.sqrt(np.mean((pred - truth) ** 2)))


@pytest.fixture(scope="module")
def tasks():
    return benchmark_tasks(30, seed=0), benchmark_tasks(15, seed=1)


def test_deterministic_and_seeds_differ():
    a = benchmark_tasks(3, seed=0)
    b = benchmark_tasks(3, seed=0)
    c = benchmark_tasks(3, seed=1)
    for name in a:
        for x, y, z in zip(a[name].demos, b[name].demos, c[name].demos):
            np.testing.assert_array_equal(x, y)
            assert x.shape != z.shape or not np.allclose(x, z)


def test_every_task_has_the_required_properties(tasks):
    dev, _ = tasks
    assert set(dev) == {"reach", "handover", "wave"} and dev["wave"].periodic
    for task in dev.values():
        lengths = {len(d) for d in task.demos}
        assert len(lengths) > 10  # durations vary
        for d, o in zip(task.demos, task.oracles):
            assert d.shape == o.shape
            resid = d - o
            # noise on both agents
            assert np.std(np.diff(resid[:, 0])) > 0.005 and np.std(np.diff(resid[:, 2])) > 0.005


def _readout(train, test, n=100, seen=1.0):
    """The best linear read-out of the robot's whole movement from the human's (time-normalised, ridge):
    what 'reading the parameters' can do."""
    def feats(d):
        h = time_normalise(d[: max(3, int(seen * len(d)))], n)[:, :2].ravel()
        return np.concatenate([h, [len(d) / 100.0, 1.0]])
    X = np.stack([feats(d) for d in train])
    Y = np.stack([time_normalise(d, n)[:, 2:].ravel() for d in train])
    W = np.linalg.solve(X.T @ X + 1e-3 * np.eye(X.shape[1]), X.T @ Y)
    return [(np.stack([feats(d)]) @ W).reshape(n, -1) for d in test]


def test_nothing_beats_the_oracle_and_the_floor_is_above_zero(tasks):
    dev, hold = tasks
    for name in dev:
        truth = [time_normalise(d, 100)[:, 2:] for d in hold[name].demos]
        oracle = [time_normalise(o, 100)[:, 2:] for o in hold[name].oracles]
        mean = np.mean([time_normalise(d, 100)[:, 2:] for d in dev[name].demos], axis=0)
        e_oracle = np.mean([_robot_rmse(o, t) for o, t in zip(oracle, truth)])
        e_mean = np.mean([_robot_rmse(mean, t) for t in truth])
        readout = _readout(dev[name].demos, hold[name].demos)
        e_read = np.mean([_robot_rmse(r, t) for r, t in zip(readout, truth)])
        assert 0.05 * e_mean < e_oracle < 0.7 * e_mean, name  # an honest floor above zero
        assert e_read > 1.05 * e_oracle, name  # reading the whole human movement does not reach it


def test_the_smoke_test_set_is_solved_by_reading_parameters():
    """Why two_agent_demos proves only that code runs: a read-out of its first 20 % predicts the robot almost
    exactly (the benchmark above cannot be solved that way)."""
    train, test = two_agent_demos(30, seed=0), two_agent_demos(10, seed=7)
    mean = np.mean([time_normalise(d, 100)[:, 2:] for d in train], axis=0)
    truth = [time_normalise(d, 100)[:, 2:] for d in test]
    e_mean = np.mean([_robot_rmse(mean, t) for t in truth])
    e_read = np.mean([_robot_rmse(r, t) for r, t in zip(_readout(train, test, seen=0.2), truth)])
    assert e_read < 0.05 * e_mean


def test_bad_arguments_are_named():
    with pytest.raises(ValueError, match="unknown task"):
        benchmark_tasks(3, names=("dance",))
    with pytest.raises(ValueError, match="n must be"):
        benchmark_tasks(0)

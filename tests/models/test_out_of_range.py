"""Input far outside the training demonstrations (wrong units, columns, frame) is flagged and warned about."""

import warnings

import numpy as np
import pytest

import interprim as ip
from interprim.synthetic import two_agent_demos


@pytest.fixture(scope="module")
def model_and_demos():
    demos = two_agent_demos(12, seed=0)
    return ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=10, sigma2=1e-3).fit(demos, dt=0.01), demos


def test_training_like_input_is_in_range_and_silent(model_and_demos):
    m, demos = model_and_demos
    held_out = two_agent_demos(4, seed=5)
    with warnings.catch_warnings():
        warnings.simplefilter("error", ip.OutOfRangeWarning)
        for d in held_out:
            p = m.predict(d[:50, :2])
            assert not p.out_of_range and 0 < p.input_distance < m.input_limit_
            s = m.stream()
            for f in d[:30, :2]:
                q = s.update(f)
            assert not q.out_of_range


@pytest.mark.parametrize("factor", [1000.0, 100.0])
def test_wrong_units_are_flagged_in_batch_and_stream(model_and_demos, factor):
    m, demos = model_and_demos
    z = demos[0][:60, :2] * factor  # millimetres (or centimetres) given to a model trained in metres
    with pytest.warns(ip.OutOfRangeWarning, match="standard deviations"):
        p = m.predict(z)
    assert p.out_of_range and p.input_distance > m.input_limit_
    s = m.stream()
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        preds = [s.update(f) for f in z]
    flags = [q.out_of_range for q in preds]
    assert flags[-1] and flags == sorted(flags)  # flagged from the first far frame on, until reset
    for k in (0, 10, 59):  # the stream's running distance is the batch one of the same prefix
        assert preds[k].input_distance == pytest.approx(m.input_distance(z[: k + 1]), rel=1e-12)
    assert sum(isinstance(x.message, ip.OutOfRangeWarning) for x in w) == 1  # once per interaction, not per frame
    s.reset()
    q = s.update(demos[0][0, :2])
    assert not q.out_of_range  # reset forgets


def test_the_check_survives_save_and_load(model_and_demos, tmp_path):
    m, demos = model_and_demos
    m.save(tmp_path / "m.npz")
    loaded = ip.InteractionPrimitive.load(tmp_path / "m.npz")
    np.testing.assert_array_equal(loaded.input_mean_, m.input_mean_)
    np.testing.assert_array_equal(loaded.input_std_, m.input_std_)
    assert loaded.input_limit_ == m.input_limit_
    with pytest.warns(ip.OutOfRangeWarning):
        assert loaded.predict(demos[1][:40, :2] * 1000).out_of_range


def test_the_warning_points_at_the_callers_line(model_and_demos):
    """However many of the library's calls lie between (the estimator, its fitted state, a stream), the
    warning is attributed to the line that called predict / update."""
    model, demos = model_and_demos[0], model_and_demos[1]
    frames = demos[0][:40, model.observed_dofs_] * 1000.0  # millimetres to a model in metres
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        model.predict(frames)
        stream = model.stream()
        for f in frames[:5]:
            stream.update(f)
    hits = [w for w in caught if issubclass(w.category, ip.OutOfRangeWarning)]
    assert len(hits) == 2 and all(w.filename == __file__ for w in hits), [(w.filename, w.lineno) for w in hits]


def test_a_caller_that_checks_itself_silences_the_inner_checks_in_its_own_thread_only(model_and_demos):
    """Inside ``CHECKED_BY_CALLER`` (a wrapper that marks the prediction itself) a model neither computes its input
    distance nor warns; a prediction in another thread at the same time checks as usual; after it, as before."""
    import threading

    from interprim.core.input_range import CHECKED_BY_CALLER, checked_by_caller

    m, demos = model_and_demos
    z = demos[0][:60, :2] * 1000.0
    other = {}

    def elsewhere():
        other["inside"] = checked_by_caller()
        other["distance"] = m.input_distance(z)

    with warnings.catch_warnings():
        warnings.simplefilter("error", ip.OutOfRangeWarning)
        with CHECKED_BY_CALLER:
            assert checked_by_caller()
            p = m.predict(z)
            s = m.stream()
            for f in z[:5]:
                s.update(f)
            t = threading.Thread(target=elsewhere)
            t.start()
            t.join()
    assert np.isnan(p.input_distance) and not p.out_of_range
    assert other["inside"] is False and other["distance"] > m.input_limit_
    assert not checked_by_caller()
    with pytest.warns(ip.OutOfRangeWarning):
        assert m.predict(z).out_of_range

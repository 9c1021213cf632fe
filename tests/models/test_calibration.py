"""Calibrated predictive std (interprim.models.primitive.calibration): look-ahead-aware factors, held-out coverage on
data with known noise, shrinkage, model files with and without the look-ahead arrays."""

from __future__ import annotations

import math

import numpy as np
import pytest

import interprim as ip
from interprim import io as ipio
from interprim.evaluation.realtime import RealTimeConfig, realtime_fold
from interprim.models.primitive.calibration import Calibration, _shrink
from interprim.synthetic import two_agent_demos

NOISE = 0.05  # i.i.d. per frame and column: larger than the model's own errors on this data
N_TRAIN = 30


@pytest.fixture(scope="module")
def noisy():
    train = two_agent_demos(N_TRAIN, seed=0, noise=NOISE)
    test = two_agent_demos(16, seed=1, noise=NOISE)
    model = ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=10).fit(train, dt=0.01)
    return model, train, test


def _hand_made(lookaheads=(-0.2, 0.0, 0.05, 0.5)):
    fr = np.array([0.2, 0.8])
    h = np.asarray(lookaheads, dtype=float)
    c_o = np.array([[1.0, 2.0, 3.0, 4.0], [5.0, 6.0, 7.0, 8.0]])
    c_c = 10 * c_o
    col = np.empty((2, 4, 5))
    col[:] = [1.0, 2.0, 1.0, 0.5, 2.0]
    col[:, :, 1] = [1.0, 2.0, 3.0, 4.0]  # column 1 relative to its agent: varies with the look-ahead
    return Calibration(fr, c_o, c_c, 4, lookaheads=h, column_scale=col)


def test_factors_interpolate_in_phase_and_lookahead_and_hold_at_the_ends():
    cal = _hand_made()
    # at a measured fraction and node: the stored scale
    assert cal.factors(0.2, 0.05) == (3.0, 30.0)
    # half-way between fractions and between two look-ahead nodes: the bilinear mean of the four corners
    c_o, c_c = cal.factors(0.5, 0.025)
    assert c_o == pytest.approx((2 + 3 + 6 + 7) / 4) and c_c == pytest.approx(10 * c_o)
    # beyond the last node / before the first / outside the fractions: held
    assert cal.factors(0.8, 0.9)[0] == 8.0 and cal.factors(0.2, -0.7)[0] == 1.0 and cal.factors(0.05, 0.5)[0] == 4.0
    # per column: the agent's factor times the column's own
    u = np.array([0.0, 0.2, 0.25, 1.0])
    f = cal.column_factors(0.2, u, [0, 1], [2, 3, 4])
    co, cc = cal.factors(0.2, u - 0.2)
    r1 = np.interp(u - 0.2, cal.lookaheads, [1.0, 2.0, 3.0, 4.0])
    np.testing.assert_allclose(f, np.column_stack([co, r1 * co, cc, 0.5 * cc, 2 * cc]))
    # the look-ahead matters: the observed past, now, the near and the far future differ
    assert len(set(np.round(f[:, 0], 12))) == 4


def test_one_dimensional_scales_act_at_every_lookahead():
    cal = Calibration(np.array([0.1, 0.9]), np.array([1.0, 3.0]), np.array([2.0, 4.0]), 2)
    assert cal.problem(5) is None
    assert cal.factors(0.5) == (2.0, 3.0)
    f = cal.column_factors(0.5, np.linspace(0, 1, 7), [0, 1], [2, 3, 4])
    np.testing.assert_array_equal(f, np.tile([2.0, 2.0, 3.0, 3.0, 3.0], (7, 1)))


def test_shrinkage_keeps_real_deviations_and_removes_noise():
    rng = np.random.default_rng(0)
    n = 400
    var = np.full(n, 0.01)
    noise = rng.normal(0.0, 0.1, n)  # sampling noise with exactly the stated variance
    # no true deviation: everything is noise, the estimates collapse onto the parent
    np.testing.assert_allclose(_shrink(noise, var, 0.0), 0.0, atol=0.03)
    # true deviations of spread 1 (100x the noise variance): kept with weight 1 / (1 + 0.01) up to the moment
    # estimate of tau^2 (relative error ~ sqrt(2 / n) = 7 %)
    true = rng.normal(0.0, 1.0, n)
    out = _shrink(true + noise, var, 0.0)
    w = np.polyfit(true + noise, out, 1)[0]
    assert 1 / (1 + 0.01 / (1 - 3 * math.sqrt(2 / n))) <= w <= 1
    # NaN estimates (nothing measured) stay NaN; infinite variance (one demonstration) goes to the parent
    out = _shrink(np.array([np.nan, 2.0, 1.0, -1.0]), np.array([0.1, np.inf, 0.1, 0.1]), 0.5)
    assert np.isnan(out[0]) and out[1] == 0.5


def test_prediction_std_applies_each_points_lookahead_factor(noisy):
    model, _, test = noisy
    m = model.with_fitted(calibration_=_hand_made())
    p = m.predict(test[0][:90, :2])
    n = 51
    u = np.linspace(0, 1, n)
    want = m.calibration_.column_factors(p.normalised_time, u, [0, 1], [2, 3, 4])
    np.testing.assert_allclose(p.std(n), p.std(n, calibrated=False) * want, rtol=1e-12)
    # samples spread about the mean as std says (trajectories are affine in theta)
    smp = p.samples(4000, n, random_state=0)
    ratio = smp.std(axis=0)[1:] / p.std(n)[1:]  # the first point is the fixed start
    ok = np.isfinite(ratio) & (p.std(n)[1:] > 1e-9)
    assert np.all(np.abs(ratio[ok] - 1) < 5 / math.sqrt(2 * 4000))  # sd of a sample std: 1/sqrt(2n) relative


def test_fitted_scales_depend_on_the_lookahead(noisy):
    model, _, _ = noisy
    cal = model.calibration_
    assert cal is not None and cal.problem(5) is None
    assert cal.lookaheads.size >= 6 and np.any(cal.lookaheads < 0) and np.any(cal.lookaheads > 0)
    assert cal.scale_observed.shape == (cal.fractions.size, cal.lookaheads.size)
    assert cal.column_scale.shape == cal.scale_observed.shape + (5,)
    # the observed agent's own near future (pinned by the frames just seen) and its far future are not
    # predicted equally well relative to the posterior std: the scales differ along the look-ahead
    fut = cal.lookaheads > 0
    row = cal.scale_observed[2, fut]
    assert row.max() / row.min() > 1.2


#: The acceptance region of the calibration check: coverage of the 90 % band and RMS error / RMS std, per agent.
#: Narrow enough that a std off by 20 % either way fails (x 0.8: coverage about 0.81, ratio about 1.2;
#: x 1.2: coverage about 0.95, ratio about 0.83), wide enough for the estimation error of factors fitted on
#: 30 training demonstrations (the ratio's standard error over the 40 test demonstrations is 0.02-0.05).
COVERAGE_OK = (0.85, 0.94)
RATIO_OK = (0.88, 1.14)


def _calibration_check(traces, scale=1.0):
    """``{agent: (coverage, RMS error / RMS std)}`` of the real-time protocol's traces with the std times ``scale``."""
    out = {}
    for agent, cols in (("obs", [0, 1]), ("ctrl", [2, 3, 4])):
        e = np.concatenate([(t["mean"] - t["truth"])[:, cols].ravel() for t in traces])
        sd = scale * np.concatenate([t["std"][:, cols].ravel() for t in traces])
        out[agent] = (float(np.mean(np.abs(e) <= 1.6448536269514722 * sd + 1e-12)),
                      float(np.sqrt(np.mean(e ** 2)) / np.sqrt(np.mean(sd ** 2))))
    return out


def _passes(check):
    return all(COVERAGE_OK[0] <= c <= COVERAGE_OK[1] and RATIO_OK[0] <= r <= RATIO_OK[1] for c, r in check.values())


@pytest.mark.slow
def test_calibrated_band_holds_on_new_demonstrations_and_the_check_bites(noisy):
    """New demonstrations of the synthetic set with i.i.d. noise: the real-time protocol's 90 % band (next 0.25 s,
    20-90 % seen) covers 85-94 % of both agents' coordinates with RMS error / RMS std within 0.88-1.14; and the
    same check fails when the std is 20 % too small or too large (so a calibration off by that much is caught)."""
    model, train, _ = noisy
    test = two_agent_demos(40, seed=1, noise=NOISE)
    cfg = RealTimeConfig(stride=4)
    traces = []
    for d in test:
        recs = [r for r in realtime_fold(model, train, d, [0, 1], 0.01, cfg, fitted=True, trace=True)
                if r["method"] == "method"]
        traces.extend(recs)
    # the check computes what the protocol reports
    cov_obs = np.mean([np.mean(np.abs(t["mean"] - t["truth"])[:, :2] <= 1.6448536269514722 * t["std"][:, :2] + 1e-12)
                       for t in traces])
    assert cov_obs == pytest.approx(np.mean([t["cov_obs"] for t in traces]), abs=1e-12)
    check = _calibration_check(traces)
    assert _passes(check), check
    for scale in (0.8, 1.2):
        assert not _passes(_calibration_check(traces, scale)), (scale, _calibration_check(traces, scale))


def _arrays_of(path):
    meta, arrays = ipio.read_archive(path)
    return meta, dict(arrays)


def _write_arrays(path, meta, arrays):
    meta = dict(meta)
    meta["checksums"] = {k: ipio.checksum(v) for k, v in arrays.items()}
    ipio.write_archive(path, meta, arrays)


def test_model_file_round_trip_keeps_the_calibration(noisy, tmp_path):
    model, _, test = noisy
    model.save(tmp_path / "m.npz")
    loaded = ip.InteractionPrimitive.load(tmp_path / "m.npz")
    a, b = model.calibration_.to_arrays(), loaded.calibration_.to_arrays()
    assert a.keys() == b.keys() and {"lookaheads", "column_scale"} <= set(a)
    for k in a:
        np.testing.assert_array_equal(a[k], b[k])
    z = test[1][:70, :2]
    np.testing.assert_array_equal(model.predict(z).std(33), loaded.predict(z).std(33))


def test_version_2_file_with_one_dimensional_calibration_loads(noisy, tmp_path):
    """A file written before look-ahead-aware calibration (version 2: ``(F,)`` scales, no look-aheads, no
    per-column factors) loads, and its scales act at every look-ahead as they did."""
    model, _, test = noisy
    model.save(tmp_path / "m.npz")
    meta, arrays = _arrays_of(tmp_path / "m.npz")
    meta["format_version"] = 2
    del arrays["calibration_lookaheads"], arrays["calibration_column_scale"]
    arrays["calibration_fractions"] = np.array([0.1, 0.3, 0.5, 0.7, 0.9])
    arrays["calibration_scale_observed"] = np.array([0.5, 0.6, 0.7, 0.8, 0.9])
    arrays["calibration_scale_controlled"] = np.array([1.5, 1.6, 1.7, 1.8, 1.9])
    _write_arrays(tmp_path / "v2.npz", meta, arrays)
    old = ip.InteractionPrimitive.load(tmp_path / "v2.npz")
    assert old.calibration_.lookaheads is None and old.calibration_.column_scale is None
    p = old.predict(test[2][:100, :2])
    c_o = np.interp(p.normalised_time, old.calibration_.fractions, arrays["calibration_scale_observed"])
    c_c = np.interp(p.normalised_time, old.calibration_.fractions, arrays["calibration_scale_controlled"])
    np.testing.assert_allclose(p.std(20), p.std(20, calibrated=False) * [c_o, c_o, c_c, c_c, c_c], rtol=1e-12)


@pytest.mark.parametrize("edit, message", [
    (lambda a: a.pop("calibration_lookaheads"), r"scale_observed has shape \(9, \d+\), expected \(9,\)"),
    (lambda a: a.update(calibration_column_scale=np.ones(3)), r"column_scale has shape \(3,\), expected \(9, \d+, 5\)"),
    (lambda a: a.update(calibration_lookaheads=a["calibration_lookaheads"][::-1].copy()),
     "lookaheads are not increasing"),
    (lambda a: a.pop("calibration_fractions"), "KeyError: 'fractions'"),
])
def test_inconsistent_calibration_arrays_are_refused_clearly(noisy, tmp_path, edit, message):
    model, _, _ = noisy
    model.save(tmp_path / "m.npz")
    meta, arrays = _arrays_of(tmp_path / "m.npz")
    edit(arrays)
    _write_arrays(tmp_path / "bad.npz", meta, arrays)
    with pytest.raises(ip.ModelFileError, match=r"bad\.npz: arrays 'calibration_\*' are not a calibration: " + message):
        ip.InteractionPrimitive.load(tmp_path / "bad.npz")


def test_version_3_file_is_refused_by_a_reader_of_versions_1_and_2_with_a_clear_message(noisy, tmp_path, monkeypatch):
    """What an older interprim says about a file with the look-ahead arrays (it reads versions 1 and 2)."""
    model, _, _ = noisy
    model.save(tmp_path / "m.npz")
    assert _arrays_of(tmp_path / "m.npz")[0]["format_version"] == 3
    monkeypatch.setattr(ipio, "READ_VERSIONS", (1, 2))
    with pytest.raises(ip.ModelFileError, match="format_version 3 is not supported by this interprim"):
        ip.InteractionPrimitive.load(tmp_path / "m.npz")


@pytest.mark.parametrize("value", ["with-cv"])
def test_calibrate_with_cv_means_when_sigma2_is_cross_validated(tmp_path, value):
    """``calibrate="with-cv"`` (the default) calibrates with ``sigma2="cv"`` and not with the paper's residual;
    the value, old or new, survives get_params, clone and the model file."""
    from interprim.cli.fit import _calibrate

    clone = pytest.importorskip("sklearn.base").clone

    assert ip.InteractionPrimitive([0, 1]).get_params()["calibrate"] == "with-cv"
    demos = two_agent_demos(8, seed=0, frames=60)
    m = ip.InteractionPrimitive([0, 1], n_basis=6, calibrate=value).fit(demos[:7], dt=0.01)
    assert m.calibration_ is not None
    assert clone(m).get_params()["calibrate"] == value
    m.save(tmp_path / "m.npz")
    back = ip.InteractionPrimitive.load(tmp_path / "m.npz")
    assert back.get_params()["calibrate"] == value
    part = demos[7][:25, :2]
    np.testing.assert_array_equal(back.predict(part).std(20), m.predict(part).std(20))
    paper = ip.InteractionPrimitive([0, 1], n_basis=6, sigma2="residual", calibrate=value).fit(demos[:7], dt=0.01)
    assert paper.calibration_ is None
    assert ip.InteractionPrimitive([0, 1], n_basis=6, sigma2="residual", calibrate=True).fit(
        demos[:7], dt=0.01).calibration_ is not None
    few = ip.InteractionPrimitive([0, 1], n_basis=6, calibrate=value).fit(demos[:5], dt=0.01)
    assert few.calibration_ is None  # fewer than 6 demonstrations: no calibration
    assert [_calibrate(t) for t in ("with-cv", "on", "off")] == ["with-cv", True, False]


def test_a_fit_inside_std_unused_measures_its_calibration_on_first_use_with_the_same_numbers(noisy):
    """A cross-validation that scores means only (interprim.core.cache.std_unused) defers the calibration's held-out
    folds; asked for later (std, a copy's std, a model file), it is the eager fit's, to the bit."""
    import copy

    from interprim.core.cache import std_deferred, std_unused

    model, train, test = noisy
    with std_unused():
        assert std_deferred()
        lazy = ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=10).fit(train, dt=0.01)
    assert not std_deferred()
    st = lazy.fitted_
    assert "calibration_" not in st.__dict__ and "_calibration_pending" in st.__dict__  # not measured yet
    partial = test[0][:40, :2]
    np.testing.assert_array_equal(lazy.predict(partial).trajectory(50), model.predict(partial).trajectory(50))
    assert "calibration_" not in st.__dict__  # the mean does not need it
    twin = copy.copy(lazy)  # a copy made before it is measured reads the same calibration
    np.testing.assert_array_equal(twin.predict(partial).std(50), model.predict(partial).std(50))
    assert st.__dict__["calibration_"] is twin.calibration_ and "_calibration_pending" not in st.__dict__
    np.testing.assert_array_equal(lazy.predict(partial).std(50), model.predict(partial).std(50))
    with std_unused():
        kept = ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=10).fit(train, dt=0.01)
    bare = kept.without_calibration()  # what the default does with it as a blend's member: dropped, unmeasured
    assert bare.calibrate is False and bare.json_params()["calibrate"] is False and bare.calibration_ is None
    assert "_calibration_pending" not in bare.fitted_.__dict__ and "_calibration_pending" in kept.fitted_.__dict__
    np.testing.assert_array_equal(bare.predict(partial).trajectory(50), model.predict(partial).trajectory(50))
    np.testing.assert_array_equal(bare.predict(partial).std(50), model.predict(partial).std(50, calibrated=False))
    kept.fitted_.measure_deferred()  # what the default does with its yardstick IP when it is the whole model
    assert "calibration_" in kept.fitted_.__dict__ and "_calibration_pending" not in kept.fitted_.__dict__
    np.testing.assert_array_equal(kept.predict(partial).std(50), model.predict(partial).std(50))
    model.fitted_.measure_deferred()  # an eager fit deferred nothing
    eager, deferred = model.calibration_.to_arrays(), lazy.calibration_.to_arrays()
    assert eager.keys() == deferred.keys()
    for k, v in eager.items():
        np.testing.assert_array_equal(v, deferred[k])

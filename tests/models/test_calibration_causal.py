"""The Interaction Primitive's calibration on causal prefixes: a partner tracked slower than the grid.

When the demonstrations carry their raw samples (an irregular recording interpolated onto a grid, as NuiSI), a robot
at frame ``k`` has only the samples recorded by then: the last one is held, stale.  The calibration's held-out cases
then see the same causal prefixes (:class:`interprim.model_selection.prefixes.Prefixes`), so the band of the
partner's next frames is scaled to the errors a robot makes, not to those of an uncut interpolation.
"""

from __future__ import annotations

import numpy as np
import pytest

import interprim as ip
from interprim.datasets import Demonstrations, RawStream
from interprim.evaluation.realtime import RealTimeConfig, realtime_fold
from interprim.model_selection.prefixes import Prefixes
from interprim.models.primitive.calibration import fit_calibration, held_out_sums
from interprim.synthetic import two_agent_demos

DT = 0.01
OBS = [0, 1]


def _slow_partner(n, seed):
    """``two_agent_demos`` whose observed agent was recorded every 6-11 frames (the robot's own joints every frame):
    the grid's observed columns are the interpolation of those samples, which a robot has only once recorded."""
    rng = np.random.default_rng(seed)
    demos, times, raw = [], [], []
    for d in two_agent_demos(n, seed=seed, noise=0.005):
        T = d.shape[0]
        t = np.arange(T) * DT
        idx = np.unique(np.r_[0, np.cumsum(rng.integers(6, 12, size=T)), T - 1])
        idx = idx[idx < T]
        grid_obs = np.stack([np.interp(t, t[idx], d[idx, c]) for c in OBS], axis=1)
        demos.append(np.hstack([grid_obs, d[:, 2:]]))
        times.append(t)
        raw.append([RawStream(t[idx], (0, 1), d[idx][:, OBS]), RawStream(t, (2, 3, 4), d[:, 2:])])
    return Demonstrations(demos, times, ["o1", "o2", "c1", "c2", "c3"], dt=DT, observed_dofs=OBS, raw=raw)


@pytest.fixture(scope="module")
def slow():
    ds = _slow_partner(12, seed=3)
    arrays = [np.asarray(x) for x in ds]
    causal = ip.InteractionPrimitive(observed_dofs=OBS, n_basis=10).fit(ds)
    plain = ip.InteractionPrimitive(observed_dofs=OBS, n_basis=10).fit(arrays, dt=DT)
    return ds, arrays, causal, plain


def _same(a, b):
    x, y = a.to_arrays(), b.to_arrays()
    return x.keys() == y.keys() and all(np.array_equal(x[k], y[k]) for k in x)


def test_a_fit_on_raw_samples_calibrates_on_causal_prefixes(slow):
    ds, arrays, causal, plain = slow
    # the same fitted prior, phase and noise: only the band's calibration differs
    np.testing.assert_array_equal(causal.thetas_, plain.thetas_)
    assert causal.sigma2_ == plain.sigma2_
    P = Prefixes(ds, OBS)
    assert P.causal
    assert _same(causal.calibration_, fit_calibration(causal.fitted_, arrays, prefixes=P))
    assert _same(plain.calibration_, fit_calibration(plain.fitted_, arrays))
    assert not _same(causal.calibration_, plain.calibration_)
    # the summary says what the calibration's held-out cases saw, also after a round trip through a model file
    assert "calibrated on held-out folds (causal prefixes of the recorded samples)" in causal.summary()
    assert "calibrated on held-out folds\n" in plain.summary() + "\n" and "causal" not in plain.summary()


def test_the_summary_of_a_loaded_model_still_names_the_causal_calibration(slow, tmp_path):
    _, _, causal, _ = slow
    causal.save(tmp_path / "ip.npz")
    back = ip.InteractionPrimitive.load(tmp_path / "ip.npz")
    assert "(causal prefixes of the recorded samples)" in back.summary()
    assert _same(back.calibration_, causal.calibration_)


def test_the_stale_partner_widens_the_partners_band_near_now(slow):
    """At look-aheads near now the partner's band is what the stale last sample costs: larger on causal prefixes.
    The robot's own band moves far less."""
    _, _, causal, plain = slow
    h = causal.calibration_.lookaheads
    near = (h >= 0) & (h <= 0.1)
    c_obs = causal.calibration_.scale_observed[:, near].mean()
    p_obs = plain.calibration_.scale_observed[:, near].mean()
    c_ctrl = causal.calibration_.scale_controlled[:, near].mean()
    p_ctrl = plain.calibration_.scale_controlled[:, near].mean()
    assert c_obs > 1.5 * p_obs, (c_obs, p_obs)
    assert abs(np.log(c_ctrl / p_ctrl)) < abs(np.log(c_obs / p_obs)), (c_ctrl, p_ctrl, c_obs, p_obs)


def test_prefixes_of_plain_arrays_give_the_plain_sums(slow):
    """One input, one answer: the held-out sums with the prefixes of plain arrays (their first frames) are those
    without prefixes, to the bit."""
    _, arrays, _, plain = slow
    a = held_out_sums(plain.fitted_, arrays)
    b = held_out_sums(plain.fitted_, arrays, prefixes=Prefixes(arrays, OBS))
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x, y)


def test_the_causal_band_covers_a_new_slow_partner_better(slow):
    """On new recordings of the slow partner, seen as a robot sees them (causal prefixes), the partner's 90 % band
    over the next 0.25 s (the real-time protocol, 20-90 % seen) covers closer to 90 % with the causal calibration,
    and the robot's mean is the same."""
    ds, arrays, causal, plain = slow
    test = _slow_partner(10, seed=11)
    P = Prefixes(test, OBS)
    cov, err = {}, {}
    for name, m in (("causal", causal), ("plain", plain)):
        recs = [r for j, d in enumerate(test)
                for r in realtime_fold(m, arrays, np.asarray(d), OBS, DT, RealTimeConfig(stride=4), fitted=True,
                                       prefix=lambda k, j=j: P(j, k), references=False)]
        cov[name] = float(np.mean([r["cov_obs"] for r in recs]))
        err[name] = [r["rt_ctrl"] for r in recs]
    assert err["causal"] == err["plain"]
    assert abs(cov["causal"] - 0.9) < abs(cov["plain"] - 0.9), cov
    assert cov["causal"] >= 0.8, cov


def _late_partner(ds, start):
    """``ds`` whose partner's first recorded sample comes ``start`` seconds after each grid's first frame."""
    raw = []
    for streams in ds.raw:
        s = streams[0]
        keep = s.times >= start
        raw.append([RawStream(s.times[keep], s.columns, s.values[keep]), *streams[1:]])
    return Demonstrations(ds.demos, ds.times, ds.columns, dt=ds.dt, observed_dofs=ds.observed_dofs, raw=raw)


def test_first_frame_is_where_a_causal_prefix_begins():
    late = _late_partner(_slow_partner(4, seed=5), 0.2)
    P = Prefixes(late, OBS)
    for j in range(len(late)):
        k0 = P.first_frame(j)
        assert 1 < k0 < len(late[j])
        with pytest.raises(ValueError, match="no raw sample at or before"):
            P(j, k0 - 1)
        assert P(j, k0).shape == (k0, 2)
    assert Prefixes([np.asarray(x) for x in late], OBS).first_frame(0) == 1
    with pytest.raises(ValueError, match="none of the raw streams"):
        Prefixes(late, [0, 1, 5]).first_frame(0)


def test_a_partner_recorded_late_is_calibrated_from_where_it_was_seen(slow):
    """Held-out cases before the partner's first sample are left out (a robot could not predict there), not a crash."""
    ds, arrays, causal, _ = slow
    late = _late_partner(ds, 0.2)
    model = ip.InteractionPrimitive(observed_dofs=OBS, n_basis=10).fit(late)
    assert model.calibration_ is not None and model.calibration_.problem(5) is None
    np.testing.assert_array_equal(model.thetas_, causal.thetas_)
    sums, _, _ = held_out_sums(model.fitted_, arrays, prefixes=Prefixes(late, OBS))
    full, _, _ = held_out_sums(model.fitted_, arrays, prefixes=Prefixes(ds, OBS))
    seen = sums[..., 2].sum(axis=(2, 3)) > 0  # (demonstration, fraction) cases scored
    assert not seen.all() and seen[:, -1].all()  # the earliest fractions of some cases left out, the latest kept
    assert (full[..., 2].sum(axis=(2, 3)) > 0).all()

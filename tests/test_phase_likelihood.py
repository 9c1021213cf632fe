"""Phase estimation by the marginal likelihood of the observation (interprim.phase_likelihood)."""

import numpy as np
import pytest

import interprim as ip
from interprim.phase import open_end_dtw
from interprim.phase_likelihood import estimate_phase, phase_log_likelihood, track_phase


@pytest.fixture(scope="module")
def lik_model(synthetic):
    train, _ = synthetic
    return ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=15, phase_method="likelihood").fit(train, dt=0.01)


def _cases(test, fractions=(0.3, 0.5, 0.7, 0.9)):
    for d in test:
        T = d.shape[0]
        for p in fractions:
            M = int(round(p * T))
            yield d[:M, :2], (M - 1) / (T - 1)


def test_likelihood_phase_beats_dtw_on_goal_varying_demos(synthetic, lik_model):
    _, test = synthetic
    N1 = lik_model.reference_.shape[0] - 1
    e_lik, e_dtw = [], []
    for z, s_true in _cases(test):
        e_dtw.append(abs(open_end_dtw(lik_model.reference_, z, return_path=False).n_star / N1 - s_true))
        e_lik.append(abs(lik_model.predict(z).normalised_time - s_true))
    assert np.mean(e_lik) < 0.05
    assert np.mean(e_lik) < 0.5 * np.mean(e_dtw)


def test_phase_noise_is_selected_and_reported(lik_model):
    assert lik_model.phase_sigma2_ > 0
    sel = lik_model.selection_
    assert sel["phase_sigma2"] == lik_model.phase_sigma2_
    assert len(sel["phase_error"]) == len(sel["phase_sigma2_grid"])


def test_estimate_phase_maximises_the_curve(synthetic, lik_model):
    _, test = synthetic
    z = test[0][:80, :2]
    est = estimate_phase(lik_model, z, refine=True)
    assert 0.0 < est.s_end <= 1.0
    assert est.grid.shape == est.curve.shape
    assert est.log_posterior >= est.curve.max() - 1e-9
    # the likelihood at the estimate is higher than far away from it
    far = 1.0 if est.s_end < 0.5 else 0.1
    assert phase_log_likelihood(lik_model, z, est.s_end) > phase_log_likelihood(lik_model, z, far)


def test_known_phase_bypasses_estimation(synthetic, lik_model):
    _, test = synthetic
    p = lik_model.predict(test[0][:60, :2], phase=0.4)
    assert p.normalised_time == pytest.approx(0.4)


def test_stream_tracks_phase_with_local_search(synthetic, lik_model):
    _, test = synthetic
    d = test[1]
    T = d.shape[0]
    st = lik_model.stream()
    for k in range(int(0.7 * T)):
        pred = st.update(d[k, :2], need_cov=False)
    s_true = (int(0.7 * T) - 1) / (T - 1)
    assert abs(pred.normalised_time - s_true) < 0.08
    assert abs(track_phase(lik_model, d[: int(0.7 * T), :2], None, 0) - s_true) < 0.1


def test_phase_method_validated_and_saved(tmp_path, synthetic, lik_model):
    train, test = synthetic
    with pytest.raises(ValueError, match="phase_method"):
        ip.InteractionPrimitive(observed_dofs=[0, 1], phase_method="magic").fit(train, dt=0.01)
    path = tmp_path / "m.npz"
    lik_model.save(path)
    m2 = ip.InteractionPrimitive.load(path)
    assert m2.phase_method == "likelihood"
    assert m2.phase_sigma2_ == lik_model.phase_sigma2_
    p = m2.predict(test[0][:100, :2])  # the same phase and prediction after the round trip
    p0 = lik_model.predict(test[0][:100, :2])
    assert p.normalised_time == pytest.approx(p0.normalised_time, abs=1e-12)
    np.testing.assert_allclose(p.trajectory(20), p0.trajectory(20), atol=1e-10)

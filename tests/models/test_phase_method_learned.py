"""InteractionPrimitive(phase_method="learned"): the learned phase inside the estimator, batch and stream, files."""

import numpy as np
import pytest

import interprim as ip
from interprim.synthetic import two_agent_demos


@pytest.fixture(scope="module")
def fitted():
    demos = two_agent_demos(16, seed=6)
    m = ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=12, sigma2=1e-3, phase_method="learned")
    return m.fit(demos[:12], dt=0.01), demos[12:]


def test_predict_uses_the_learned_phase(fitted):
    m, test = fitted
    assert m.phase_model_ is not None
    d = test[0]
    k = 70
    p = m.predict(d[:k, :2])
    est = m.phase_model_.estimate(d[:k, :2])
    assert p.normalised_time == pytest.approx(est.phase, abs=1e-12)
    errs = [abs(m.predict(d[:k, :2]).normalised_time - (k - 1) / (len(d) - 1)) for d in test]
    assert np.mean(errs) < 0.1


def test_stream_equals_batch_with_the_learned_phase(fitted):
    """The learned phase is a function of the prefix: every frame of a stream gives the batch prediction."""
    m, test = fitted
    d = test[1]
    s = m.stream()
    for k in range(1, 90):
        q = s.update(d[k - 1, :2])
        if k in (5, 30, 60, 89):
            p = m.predict(d[:k, :2])
            assert q.normalised_time == pytest.approx(p.normalised_time, abs=1e-12), k
            np.testing.assert_allclose(q.trajectory(40), p.trajectory(40), rtol=1e-9, atol=1e-12)


def test_partner_holding_still_after_the_end_leaves_the_prediction_unchanged(fitted):
    """Past the end of the movement the learned phase stays at 1: the prediction is conditioned on the frames up to
    where it first reached 1, so still frames do not move the robot's goal, in a stream as in batch."""
    from interprim.phase import movement_prefix

    m, test = fitted
    d = test[2]
    T = len(d)
    ext = np.vstack([d[:, :2], np.repeat(d[-1:, :2], 25, axis=0)])  # the partner holds still for 25 frames
    s = m.stream()
    preds = []
    for k in range(1, len(ext) + 1):
        q = s.update(ext[k - 1])
        if k >= T - 5:
            p = m.predict(ext[:k])
            assert q.n_observed == p.n_observed, k
            np.testing.assert_allclose(q.trajectory(40), p.trajectory(40), rtol=1e-9, atol=1e-12)
            preds.append(p)
    ended = [p for p in preds if p.phase >= 1.0]
    assert len(ended) >= 20  # the phase reaches 1 at most a few frames after the true end
    M1 = ended[0].n_observed
    assert all(p.n_observed == M1 for p in ended)
    est = m.phase_model_.estimate
    assert est(ext[:M1]).phase >= 1.0 > est(ext[:M1 - 1]).phase  # the first prefix whose phase is 1
    goals = np.array([p.trajectory(50)[-1] for p in ended])
    assert np.ptp(goals, axis=0).max() == 0.0  # no wobble: the same prediction for every still frame
    # other phase methods, and a phase below 1, keep every frame
    z = ext[: T - 10]
    assert movement_prefix(m, z, 0.5 * (m.reference_.shape[0] - 1)) is z


def test_learned_phase_survives_save_and_load(fitted, tmp_path):
    m, test = fitted
    m.save(tmp_path / "m.npz")
    loaded = ip.InteractionPrimitive.load(tmp_path / "m.npz")
    assert loaded.phase_method == "learned" and loaded.phase_model_.method_ == m.phase_model_.method_
    z = test[2][:50, :2]
    assert loaded.predict(z).normalised_time == m.predict(z).normalised_time
    np.testing.assert_array_equal(loaded.predict(z).trajectory(30), m.predict(z).trajectory(30))


def test_auto_chooses_the_phase_with_the_smaller_held_out_error(tmp_path):
    """phase_method="cv" on clean synthetic data keeps the likelihood phase (far more accurate there), and
    the choice it made is used by predict and stream and kept in the model file."""
    demos = two_agent_demos(16, seed=6)
    m = ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=12, sigma2=1e-3, phase_method="cv").fit(demos, dt=0.01)
    lik = m.selection_["phase_error_refined"]
    lp = ip.LearnedPhase().fit([d[:, :2] for d in demos], dt=0.01)
    assert m.selection_["learned_phase_error"] == pytest.approx(lp.cv_error_)
    assert m.phase_method_ == ("learned" if lp.cv_error_ < lik else "likelihood")
    assert m.phase_method_ == "likelihood" and m.phase_model_ is None  # 0.2x vs 0.3x the clock on this data
    z = demos[3][:60, :2]
    ref = ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=12, sigma2=1e-3, phase_method="likelihood").fit(
        demos, dt=0.01)
    assert m.predict(z).normalised_time == ref.predict(z).normalised_time
    m.save(tmp_path / "a.npz")
    assert ip.InteractionPrimitive.load(tmp_path / "a.npz").phase_method_ == "likelihood"


@pytest.mark.slow  # fits on recordings-like data with both phases
def test_auto_is_the_default_and_picks_the_learned_phase_on_recordings_of_people():
    """The default phase_method "cv" picks the learned phase on a NuiSI interaction (held-out phase error
    0.026 vs 0.034 for the likelihood phase on highfive1; 0.78x vs 0.99x the clock in real time over 5 folds),
    and the likelihood phase on the simulated data (test above)."""
    from interprim.datasets import DataNotFoundError, load_nuisi

    try:
        demos = list(load_nuisi(None, action="highfive1", observed="right_arm", controlled="right_hand", dt=0.05))
    except DataNotFoundError:
        pytest.fail("the NuiSI data (../shared/data) is needed: CI has it beside the clone")
    m = ip.InteractionPrimitive(observed_dofs=list(range(9))).fit(demos, dt=0.05)
    assert m.phase_method == "cv"
    sel = m.selection_
    assert m.phase_method_ == "learned", sel
    assert sel["learned_phase_error"] < sel["phase_error_refined"]
    assert sel["learned_phase_error"] < sel["clock_phase_error"]


def test_calibration_folds_refit_the_learned_phase():
    """The calibration's fold models (interprim.models.primitive.calibration.fold_model) refit a learned phase on the
    kept demonstrations only: the full model's phase model has seen the held-out prefixes, which made the held-out
    timing, and so the calibrated band, optimistic (NuiSI fistbump2 covered 82 % for a 90 % band)."""
    from interprim.models.primitive.calibration import fold_model

    demos = two_agent_demos(12, seed=2)
    m = ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=10, phase_method="learned").fit(demos, dt=0.01)
    assert m.calibration_ is not None
    keep = list(range(9))
    observed = [d[:, :2] for d in demos]
    f = fold_model(m, keep, observed)
    assert f.phase_model_ is not m.phase_model_ and f.phase_model_.n_demos_ == 9
    ref = ip.LearnedPhase(**m.phase_model_.get_params()).fit([observed[i] for i in keep], dt=m.dt_)
    z = demos[10][:50, :2]
    assert f.phase_model_.estimate(z).phase == ref.estimate(z).phase
    assert fold_model(m, keep).phase_model_ is m.phase_model_  # without the observed columns: unchanged

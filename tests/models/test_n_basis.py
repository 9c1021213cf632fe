"""n_basis="cv": the number of basis functions chosen from the demonstrations by held-out error (issue 19, part 2)."""

import warnings

import numpy as np
import pytest

import interprim as ip
from interprim.models.primitive.estimator import N_BASIS_GRID, choose_n_basis
from interprim.synthetic import benchmark_tasks


@pytest.fixture(scope="module")
def wave():
    return benchmark_tasks(12, seed=0, names=("wave",))["wave"]


def test_a_periodic_movement_gets_more_basis_functions_than_a_reach(wave):
    reach = benchmark_tasks(12, seed=0, names=("reach",))["reach"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ip.RepresentationWarning)
        mw = ip.InteractionPrimitive(wave.observed_dofs, n_basis="cv").fit(wave.demos, dt=wave.dt)
        mr = ip.InteractionPrimitive(reach.observed_dofs, n_basis="cv").fit(reach.demos, dt=reach.dt)
    kw, kr = mw.selection_["n_basis"]["chosen"], mr.selection_["n_basis"]["chosen"]
    assert kw > kr and kw >= 20 and kr <= 15
    # the chosen number is the one the fitted state uses, and a model file keeps it
    assert mw.params_per_dof_ == kw + 1 and mw.thetas_.shape[1] == mw.n_latent_ * (kw + 1)
    rec = mw.selection_["n_basis"]
    assert rec["candidates"] == [k for k in N_BASIS_GRID if k + 1 <= min(len(d) for d in wave.demos) // 2]
    errs = np.array(rec["cv_error"])
    i = rec["candidates"].index(kw)
    assert errs[i] <= 1.01 * errs.min() or errs[i] < errs[0]  # the choice is among the best, not the first
    # the periodic movement is represented better with the number chosen than with the reach's
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ip.RepresentationWarning)
        mk = ip.InteractionPrimitive(wave.observed_dofs, n_basis=kr).fit(wave.demos, dt=wave.dt)
    assert mw.representation_["controlled"]["mean_offset"] < mk.representation_["controlled"]["mean_offset"]


def test_the_held_out_error_is_that_of_a_model_fitted_without_the_demonstration(wave):
    """The leave-one-out mean equals the prior mean of a model fitted on the other demonstrations (each
    demonstration's DMP parameters depend on it alone), so the criterion really is held out."""
    demos = wave.demos[:6]
    obs = wave.observed_dofs
    params = ip.InteractionPrimitive(obs, n_basis="cv").json_params()
    from interprim.models.primitive.estimator import InteractionPrimitive

    D = demos[0].shape[1]
    ctrl = [i for i in range(D) if i not in obs]
    rec = choose_n_basis(params, demos, wave.dt, None, obs, ctrl, None, grid=(15,), n=51)
    K, j = 15, 2
    others = [d for i, d in enumerate(demos) if i != j]
    m = InteractionPrimitive(obs, n_basis=K, sigma2="residual", phase_method="dtw", calibrate=False)
    m.fit(demos, dt=wave.dt)
    loo = InteractionPrimitive(obs, n_basis=K, sigma2="residual", phase_method="dtw", calibrate=False)
    loo.fit(others, dt=wave.dt)
    th = m.thetas_.reshape(len(demos), m.n_latent_, K + 1)
    np.testing.assert_allclose(loo.prior_.mean.reshape(m.n_latent_, K + 1),
                               (th.sum(axis=0) - th[j]) / (len(demos) - 1), rtol=1e-12, atol=1e-12)
    assert rec["chosen"] == 15 and len(rec["cv_error"]) == 1 and np.isfinite(rec["cv_error"][0])


def test_cv_survives_params_clone_and_model_files(wave, tmp_path):
    from sklearn.base import clone

    m = ip.InteractionPrimitive(wave.observed_dofs, n_basis="cv")
    assert clone(m).get_params()["n_basis"] == "cv"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ip.RepresentationWarning)
        m.fit(wave.demos[:8], dt=wave.dt)
    m.save(tmp_path / "m.npz")
    back = ip.InteractionPrimitive.load(tmp_path / "m.npz")
    k = m.selection_["n_basis"]["chosen"]
    assert back.n_basis == k and back.selection_["n_basis"]["chosen"] == k  # the file holds the number chosen
    x = wave.demos[9][:60, wave.observed_dofs]
    np.testing.assert_allclose(back.predict(x).trajectory(30), m.predict(x).trajectory(30), rtol=0, atol=1e-10)


@pytest.mark.parametrize("bad", ["auto", 1, 2.5, True, None])
def test_bad_n_basis_is_named(wave, bad):
    with pytest.raises(ValueError, match="n_basis must be an integer >= 2 or 'cv'"):
        ip.InteractionPrimitive(wave.observed_dofs, n_basis=bad).fit(wave.demos[:4], dt=wave.dt)

"""A refit starts from nothing: no value derived from an earlier fit survives it (issue 20's refit bug)."""

import copy

import numpy as np
import pytest

import interprim as ip
from interprim.synthetic import two_agent_demos

CONFIGS = {
    "dtw": dict(sigma2=1e-3, covariance="ridge", phase_method="dtw", calibrate=False),
    "likelihood-pca": dict(sigma2=1e-3, phase_method="likelihood", pca_components=(2, 2), calibrate=False),
}


def _use(model, partial):
    pred = model.predict(partial)
    pred.std(30)
    pred.response(20)
    pred.samples(3, 30, random_state=0)
    pred.completion(10)
    return pred


@pytest.mark.parametrize("config", sorted(CONFIGS))
def test_refit_on_fewer_columns_equals_a_fresh_fit(config):
    demos = two_agent_demos(12, seed=3)  # 5 columns: 2 observed, 3 controlled
    fewer = [d[:, :4] for d in demos]
    kw = dict(observed_dofs=[0, 1], n_basis=8, **CONFIGS[config])
    model = ip.InteractionPrimitive(**kw).fit(demos, dt=0.01)
    first = _use(model, demos[0][:60, :2])
    assert first.trajectory(30).shape == (30, 5)
    model.fit(fewer, dt=0.01)  # the same instance, one controlled column fewer
    fresh = ip.InteractionPrimitive(**kw).fit(fewer, dt=0.01)
    got, want = _use(model, fewer[1][:70, :2]), _use(fresh, fewer[1][:70, :2])
    assert got.trajectory(30).shape == (30, 4)
    np.testing.assert_array_equal(got.trajectory(30), want.trajectory(30))
    np.testing.assert_array_equal(got.std(30), want.std(30))
    for a, b in zip(got.response(20), want.response(20)):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(got.samples(3, 30, random_state=0), want.samples(3, 30, random_state=0))
    assert got.phase == want.phase


def test_derived_values_are_not_attributes_and_copies_do_not_share_them():
    demos = two_agent_demos(8, seed=4)
    model = ip.InteractionPrimitive([0, 1], n_basis=8, sigma2=1e-3, phase_method="likelihood",
                                    calibrate=False).fit(demos, dt=0.01)
    before = set(vars(model))
    _use(model, demos[0][:50, :2])
    assert set(vars(model)) == before  # predicting adds no attribute to the estimator
    twin = copy.copy(model)
    assert twin.fitted_.cached("x", (), lambda: 1) == 1 and model.fitted_.cached("x", (), lambda: 2) == 2


# ----------------------------------------------------------------------------- scikit-learn conventions
def test_get_params_set_params_and_clone():
    sklearn_base = pytest.importorskip("sklearn.base")
    demos = two_agent_demos(8, seed=4)
    model = ip.InteractionPrimitive([0, 1], n_basis=8, sigma2=1e-3, pca_components=(2, 2), phase_method="dtw",
                                    calibrate=False)
    params = model.get_params(deep=True)
    assert params == model.get_params(deep=False) and params["pca_components"] == (2, 2)
    assert set(params) == set(ip.InteractionPrimitive([0]).get_params())
    assert model.set_params(n_basis=9, ridge=1e-5) is model and model.n_basis == 9 and model.ridge == 1e-5
    with pytest.raises(ValueError, match="no parameter 'n_basiss'"):
        model.set_params(n_basiss=3)
    model.fit(demos, dt=0.01)
    twin = sklearn_base.clone(model)
    assert type(twin) is ip.InteractionPrimitive and twin.get_params() == model.get_params()
    assert not hasattr(twin, "prior_")  # a clone is unfitted
    with pytest.raises(ip.NotFittedError):
        twin.predict(demos[0][:20, :2])
    twin.fit(demos, dt=0.01)
    part = demos[1][:60, :2]
    np.testing.assert_array_equal(twin.predict(part).trajectory(20), model.predict(part).trajectory(20))


@pytest.mark.parametrize("name, value, match", [
    ("calibrate", "yes", "calibrate must be True, False or 'with-cv'"),
    ("n_steps", 0, "n_steps must be a positive integer"),
    ("n_steps", 2.5, "n_steps must be a positive integer"),
    ("ridge", -1.0, "ridge must be a finite number >= 0"),
    ("ridge", "big", "ridge must be a finite number >= 0"),
    ("covariance", "full", "covariance must be one of"),
    ("reference", 99, r"reference=99 is not a demo index \(0..7\)"),
    ("reference", "median", "reference must be 'mean' or a demo index"),
])
def test_every_parameter_is_checked_before_the_cross_validation(monkeypatch, name, value, match):
    import interprim.models.primitive.selection

    def expensive(*args, **kwargs):  # pragma: no cover - reaching it is the failure
        raise AssertionError("the cross-validation ran before the parameters were checked")

    monkeypatch.setattr(interprim.models.primitive.selection, "select_hyperparameters", expensive)
    model = ip.InteractionPrimitive([0, 1], n_basis=8, **{name: value})  # sigma2="cv": selection would run
    with pytest.raises(ValueError, match=match):
        model.fit(two_agent_demos(8, seed=4), dt=0.01)


@pytest.mark.parametrize("name, old", [("sigma2", "auto"), ("phase_method", "auto"), ("calibrate", "auto")])
def test_the_old_value_auto_is_refused_with_its_name_of_today(name, old):
    """"auto" meant several things; each option now has its own name ("residual", "cv", "with-cv"), and "auto"
    is refused with a message naming the choices (model files of 0.1.0 are read with the new names)."""
    with pytest.raises(ValueError, match=name):
        ip.InteractionPrimitive([0, 1], n_basis=8, **{name: old}).fit(two_agent_demos(8, seed=4), dt=0.01)


def test_a_model_file_with_the_old_values_loads_under_the_new_names(tmp_path):
    import json
    import zipfile

    demos = two_agent_demos(8, seed=4)
    m = ip.InteractionPrimitive([0, 1], n_basis=8, sigma2="residual", calibrate=False).fit(demos, dt=0.01)
    m.save(tmp_path / "new.npz")
    with zipfile.ZipFile(tmp_path / "new.npz") as z:
        members = {n: z.read(n) for n in z.namelist()}
    meta = json.loads(np.load(tmp_path / "new.npz")["metadata"].tobytes())
    meta["params"].update(sigma2="auto", phase_method="auto")  # as 0.1.0 wrote them
    import io as _io
    buf = _io.BytesIO()
    np.save(buf, np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8))
    members["metadata.npy"] = buf.getvalue()
    with zipfile.ZipFile(tmp_path / "old.npz", "w") as z:
        for n, data in members.items():
            z.writestr(n, data)
    old = ip.InteractionPrimitive.load(tmp_path / "old.npz")
    assert old.sigma2 == "residual" and old.phase_method == "cv"


def test_to_state_from_state_round_trip():
    """The model file's content without the file: ``from_state(*to_state())`` is the same model."""
    demos = two_agent_demos(8, seed=4)
    m = ip.InteractionPrimitive([0, 1], n_basis=8, sigma2=1e-3, pca_components=(2, 2), phase_method="likelihood",
                                calibrate=False).fit(demos, dt=0.01)
    arrays, meta = m.to_state()
    twin = ip.InteractionPrimitive.from_state(arrays, meta)
    part = demos[1][:60, :2]
    a, b = m.predict(part), twin.predict(part)
    np.testing.assert_array_equal(a.trajectory(30), b.trajectory(30))
    np.testing.assert_array_equal(a.std(30), b.std(30))
    bad = dict(arrays, thetas=arrays["thetas"][:, :-1])
    with pytest.raises(ip.ModelFileError, match="<state>: array 'thetas' has shape"):
        ip.InteractionPrimitive.from_state(bad, meta)


# ----------------------------------------------------------------------------- the fitted state
# (interprim.models.primitive.fitted)
def test_fit_builds_a_new_fitted_state_and_the_attributes_are_its_read_only_views():
    from interprim.models.primitive.fitted import FITTED_NAMES, FittedPrimitive

    demos = two_agent_demos(8, seed=4)
    model = ip.InteractionPrimitive([0, 1], n_basis=8, sigma2=1e-3, phase_method="likelihood", calibrate=False)
    assert "fitted_" not in vars(model) and not hasattr(model, "prior_")
    model.fit(demos, dt=0.01)
    first = model.fitted_
    assert isinstance(first, FittedPrimitive)
    for name in FITTED_NAMES:  # every fitted attribute is the state's own object
        if hasattr(first, name):
            assert getattr(model, name) is getattr(first, name), name
    with pytest.raises(AttributeError):
        model.prior_ = None  # read-only: the state is changed only by a new fit
    prior, part = first.prior_, demos[2][:60, :2]
    before = model.predict(part).trajectory(20)
    model.fit([d[:, :4] for d in demos], dt=0.01)
    assert model.fitted_ is not first and first.prior_ is prior  # a new state; the old one is untouched
    assert model.predict(part).trajectory(20).shape == (20, 4)
    np.testing.assert_array_equal(first.predict(part).trajectory(20), before)  # the old state still predicts


def test_fitted_state_round_trip_and_with_fitted_with_params():
    from interprim.models.primitive.fitted import FittedPrimitive

    demos = two_agent_demos(8, seed=4)
    model = ip.InteractionPrimitive([0, 1], n_basis=8, sigma2=1e-3, phase_method="likelihood",
                                    calibrate=False).fit(demos, dt=0.01)
    st, part = model.fitted_, demos[1][:60, :2]
    arrays, meta = st.to_state()
    twin = FittedPrimitive.from_state(arrays, meta, model.json_params())
    np.testing.assert_array_equal(twin.predict(part).trajectory(30), model.predict(part).trajectory(30))
    # with_fitted: a copy with its own store; the original is unchanged
    wide = st.with_fitted(sigma2_=10.0 * st.sigma2_)
    assert wide.sigma2_ == 10.0 * st.sigma2_ and st.sigma2_ == model.sigma2_
    assert wide.conditioner() is not st.conditioner()
    with pytest.raises(ValueError, match="not fitted attributes"):
        st.with_fitted(n_basis=3)
    # a phase_method set on the estimator after fit is used by its next predict (the state's with_params)
    model.phase_method = "dtw"
    got = model.predict(part)
    want = st.with_params(phase_method="dtw").predict(part)
    assert model.fitted_ is st and st.phase_method == "likelihood"
    np.testing.assert_array_equal(got.trajectory(30), want.trajectory(30))
    assert got.n_star == want.n_star

"""Model files whose values are wrong (metadata edited by hand or by a buggy writer, arrays re-checksummed) are
refused on load with a ModelFileError naming the field, never a crash, a huge allocation or a silent wrong answer;
demonstrations of one frame and an n_basis the data cannot support are refused by fit."""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np
import pytest

import interprim as ip
from interprim.core.errors import ModelFileError
from interprim.io import checksum, read_archive, write_archive
from interprim.models.blend import Blend
from interprim.models.demonstrations import NearestNeighbour, PriorMean
from interprim.models.files import load_any
from interprim.models.kernel import KernelDemonstrations
from interprim.models.learned import LearnedInteraction
from interprim.models.promp import InteractionProMP
from interprim.synthetic import two_agent_demos

DT = 0.02


@pytest.fixture(scope="module")
def demos():
    return two_agent_demos(6, seed=0, frames=40)


@pytest.fixture(scope="module")
def models(demos):
    """Tiny fitted models of every family a file may hold (a few demonstrations of ~40 frames)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        out = {
            "ip": ip.InteractionPrimitive([0, 1], n_basis=5, n_steps=200).fit(demos, dt=DT),
            "prior": PriorMean([0, 1], n=50).fit(demos, dt=DT),
            "nn": NearestNeighbour([0, 1], n=50).fit(demos, dt=DT),
            "kernel": KernelDemonstrations([0, 1], n=51).fit(demos, dt=DT),
            "learned": LearnedInteraction([0, 1]).fit(demos, dt=DT),
            "promp": InteractionProMP([0, 1]).fit(demos, dt=DT),
        }
        out["blend"] = Blend.from_fitted([0, 1], {"nn": out["nn"], "prior": out["prior"]},
                                         {"nn": 0.5, "prior": 0.5},
                                         {"a": [[1.0] * 5] * 3, "b": [[0.01] * 5] * 3}, demos, DT)
        out["auto"] = ip.AutoInteraction([0, 1], candidates=("nn", "prior"), n_basis=5).fit(demos, dt=DT)
    return out


@pytest.fixture(scope="module")
def files(models, tmp_path_factory):
    d = tmp_path_factory.mktemp("models")
    out = {}
    for name, m in models.items():
        out[name] = d / f"{name}.npz"
        m.save(out[name])
    return out


def edited(src: Path, dst: Path, edit) -> Path:
    """A copy of the model file ``src`` with ``edit(meta, data)`` applied and the checksums made to match, as a
    hand edit or a buggy writer would leave it."""
    meta, data = read_archive(src)
    edit(meta, data)
    meta["checksums"] = {k: checksum(v) for k, v in data.items()}
    write_archive(dst, meta, data)
    return dst


def _set(*keys, value):
    """An edit setting ``meta[keys[0]]...[keys[-1]] = value``."""
    def edit(meta, data):
        d = meta
        for k in keys[:-1]:
            d = d[k]
        d[keys[-1]] = value(d[keys[-1]]) if callable(value) else value
    return edit


def _array(name, change):
    def edit(meta, data):
        data[name] = change(data[name])
    return edit


def _not_pd(c):
    c = c.copy()
    big = 10 * float(np.max(np.abs(c)))
    c[0, 1] = c[1, 0] = big  # positive diagonal, a negative eigenvalue
    return c


NAN = float("nan")

CASES = [
    # 1. the Interaction Primitive
    ("ip", _set("params", "n_steps", value=10**11), "n_steps"),
    ("ip", _set("params", "n_steps", value=0), "n_steps"),
    ("ip", _set("dt", value=0.0), "'dt'"),
    ("ip", _set("dt", value=NAN), "'dt'"),
    ("ip", _set("mean_duration", value=0.0), "'mean_duration'"),
    ("ip", _set("sigma2", value=-1.0), "'sigma2'"),
    ("ip", _set("sigma2", value=NAN), "'sigma2'"),
    ("ip", _set("beta_y", value=NAN), "'beta_y'"),
    ("ip", _set("params", "alpha_y", value=NAN), "alpha_y"),
    ("ip", _set("phase_sigma2", value=-1.0), "'phase_sigma2'"),
    ("ip", _set("params", "phase_method", value="bogus"), "phase_method"),
    ("ip", _array("durations", lambda a: -a), "'durations'"),
    ("ip", _array("prior_cov", lambda c: -c), "'prior_cov'"),
    ("ip", lambda m, d: (d.pop("prior_diag"), d.pop("prior_factor"), d.update(prior_cov=_not_pd(d["prior_cov"]))),
     "'prior_cov'"),
    ("ip", _array("prior_cov", _not_pd), "'prior_cov'"),
    ("ip", _set("columns", value=["a", "b"]), "columns"),
    ("ip", _set("observed_dofs", value=[0, 8]), "observed_dofs"),
    ("ip", _set("params", "observed_dofs", value=[0, 8]), "observed_dofs"),
    # 2. the other families
    ("prior", _array("mean", lambda a: np.where(np.arange(a.size).reshape(a.shape) == 7, np.nan, a)), "'mean'"),
    ("prior", _array("mean", lambda a: np.ascontiguousarray(a[:, :2])), "'mean'"),
    ("prior", _array("std", lambda a: -a - 1.0), "'std'"),
    ("prior", _set("params", "n", value=10**11), "params.n"),
    ("prior", _set("state", "observed_dofs_", value=[0, 8]), "observed_dofs_"),
    ("prior", _set("state", "dt_", value=0.0), "'dt_'"),
    ("prior", _set("state", "mean_duration_", value=NAN), "'mean_duration_'"),
    ("nn", _array("lengths", lambda a: a * 1000), "'lengths'"),
    ("nn", _set("params", "n", value=10**11), "params.n"),
    ("nn", _array("observed", lambda a: a[:, :1].copy()), "'observed'"),
    ("kernel", _set("state", "bandwidth_", value=0.0), "'bandwidth_'"),
    ("kernel", _set("state", "bandwidth_", value=NAN), "'bandwidth_'"),
    ("kernel", _set("state", "cost_scale_", value=-1.0), "'cost_scale_'"),
    ("kernel", _set("params", "n", value=10**11), "params.n"),
    ("kernel", _array("lengths", lambda a: a * 1000), "'lengths'"),
    ("kernel", _array("std_floor", lambda a: -a - 1.0), "'std_floor'"),
    ("learned", _set("state", "phase", "dt_", value=0.0), "phase.dt_"),
    ("learned", _set("state", "phase", "mean_duration_", value=-1.0), "phase.mean_duration_"),
    ("learned", _array("coupling_residual_var_", lambda a: -a - 1.0), "residual_var_"),
    ("learned", _set("state", "coupling", "params", "n_out", value=10**11), "n_out"),
    ("learned", _set("state", "observed_dofs_", value=[0, 8]), "observed_dofs_"),
    ("learned", _set("state", "dt_", value=0.0), "'dt_'"),
    ("promp", _set("state", "sigma2_", value=-1.0), "'sigma2_'"),
    ("promp", _array("cov", lambda a: np.ascontiguousarray(a[:3])), "'cov'"),
    ("promp", _set("state", "order_", value=[0, 1, 2, 2, 4]), "order_"),
    ("blend", _set("params", "scales", "a", value=lambda a: (-np.asarray(a) - 1.0).tolist()), "scales"),
    ("blend", _set("state", "observed_dofs_", value=[0, 8]), "observed_dofs_"),
    ("blend", _set("state", "dt", value=0.0), "'dt'"),
    ("blend", _set("state", "members", "prior", "state", "mean_duration_", value=0.0), "mean_duration_"),
    ("auto", _array("model_prior__mean", lambda a: np.full_like(a, np.nan)), "'mean'"),
    ("auto", _set("state", "columns_", value=["a", "b"]), "columns_"),
    ("auto", _set("state", "observed_dofs_", value=[0, 8]), "observed_dofs_"),
    ("auto", _set("state", "mean_duration_", value=0.0), "mean_duration_"),
    ("auto", _set("state", "weights", "nn", value=NAN), "weights"),
    ("auto", _set("state", "params", "bands", value=lambda b: [b[0], NAN] + b[2:]), "bands"),
]


@pytest.mark.parametrize("family, edit, field", CASES, ids=[f"{c[0]}-{c[2]}-{i}" for i, c in enumerate(CASES)])
def test_bad_values_are_refused_naming_the_field(files, tmp_path, family, edit, field):
    bad = edited(files[family], tmp_path / f"bad-{family}.npz", edit)
    with pytest.raises(ModelFileError) as info:
        load_any(bad)
    msg = str(info.value)
    assert field in msg, msg
    assert msg.startswith(str(bad)), msg  # names the file


@pytest.mark.parametrize("family", ["ip", "prior", "nn", "kernel", "learned", "promp", "blend", "auto"])
def test_valid_file_loads_and_predicts_identically(models, files, family, demos):
    partial = demos[0][:15, :2]
    before = models[family].predict(partial)
    after = load_any(files[family]).predict(partial)
    np.testing.assert_array_equal(before.trajectory(30), after.trajectory(30))
    s0, s1 = before.std(30), after.std(30)
    assert (s0 is None) == (s1 is None)
    if s0 is not None:
        np.testing.assert_array_equal(s0, s1)
    # an edited copy that changes nothing is still valid
    same = edited(files[family], files[family].with_name(f"same-{family}.npz"), lambda m, d: None)
    np.testing.assert_array_equal(load_any(same).predict(partial).trajectory(30), before.trajectory(30))


@pytest.mark.parametrize("exc", [MemoryError("no memory"), ZeroDivisionError("division by zero"),
                                 np.linalg.LinAlgError("not positive definite"), ValueError("bad")])
def test_what_building_raises_becomes_a_model_file_error(files, monkeypatch, exc):
    """The last line of defence: what building a model from the file's values raises is a ModelFileError."""
    def boom(self, arrays, meta):
        raise exc

    monkeypatch.setattr(PriorMean, "load_state", boom)
    with pytest.raises(ModelFileError, match="prior.npz: .*" + type(exc).__name__):
        load_any(files["prior"])


@pytest.mark.parametrize("exc", [MemoryError("no memory"), ZeroDivisionError("division by zero"),
                                 np.linalg.LinAlgError("not positive definite")])
def test_what_building_an_ip_raises_becomes_a_model_file_error(files, monkeypatch, exc):
    from interprim.models.primitive.fitted import FittedPrimitive

    def boom(self):
        raise exc

    monkeypatch.setattr(FittedPrimitive, "setup_derived", boom)
    with pytest.raises(ModelFileError, match="ip.npz: inconsistent values in the model file: " + type(exc).__name__):
        load_any(files["ip"])


# 3. the baselines refuse demonstrations of one frame
@pytest.mark.parametrize("make", [lambda: PriorMean([0, 1]), lambda: NearestNeighbour([0, 1]),
                                  lambda: KernelDemonstrations([0, 1], bandwidth=1.0)])
def test_baselines_refuse_one_frame_demonstrations(make):
    demos = [np.random.default_rng(j).random((30, 5)) for j in range(4)]
    demos[2] = demos[2][:1]
    with pytest.raises(ValueError, match=r"demos\[2\] has 1 frames; at least 2 are needed"):
        make().fit(demos, dt=0.01)
    with pytest.raises(ValueError, match=r"demos\[0\] has 1 frames"):
        make().fit([np.random.default_rng(0).random((1, 5))] * 4, dt=0.01)


# 4. the Interaction Primitive refuses an n_basis its data cannot support, before any work
def test_n_basis_beyond_the_frames_is_refused(demos):
    shortest = min(len(d) for d in demos)
    with pytest.raises(ValueError, match=rf"n_basis=3000 .* n_basis must be at most {shortest}"):
        ip.InteractionPrimitive([0, 1], n_basis=3000).fit(demos, dt=DT)
    with pytest.raises(ValueError, match=rf"n_basis={shortest + 1} .*at most {shortest}"):
        ip.InteractionPrimitive([0, 1], n_basis=shortest + 1).fit(demos, dt=DT)


def test_n_basis_beyond_the_covariance_bound_is_refused():
    with pytest.raises(ValueError, match=r"n_basis=3500 makes 17505 parameters .* n_basis must be at most \d+"):
        ip.InteractionPrimitive._check_n_basis(3500, 5, 4000)
    ip.InteractionPrimitive._check_n_basis(20, 5, 4000)  # the default is fine


def test_n_steps_beyond_the_rollout_bound_is_refused_by_fit(demos):
    with pytest.raises(ValueError, match="n_steps=100000000000 .* n_steps must be at most"):
        ip.InteractionPrimitive([0, 1], n_basis=5, n_steps=10**11).fit(demos, dt=DT)


def test_nan_in_json_is_a_number_that_is_refused(files, tmp_path):
    """JSON's NaN reaches the checks as a float (the audit's dt = NaN) and is named."""
    bad = edited(files["ip"], tmp_path / "nan.npz", _set("mean_duration", value=math.nan))
    with pytest.raises(ModelFileError, match="'mean_duration'"):
        load_any(bad)


@pytest.mark.parametrize("window", [2, 4, 0])
def test_an_even_or_too_small_smoothing_window_is_refused_as_its_message_says(demos, window):
    with pytest.raises(ValueError, match=rf"smoothing_window must be None or an odd integer >= 3, got {window}"):
        ip.InteractionPrimitive([0, 1], n_basis=5, smoothing_window=window).fit(demos, dt=DT)

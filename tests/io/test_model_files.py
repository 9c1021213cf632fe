"""Model files (interprim.io): exact round trip of every fitted attribute, checksums, corruption fuzzing,
files of format version 1, files that are not models at all, and the CLI's one-line errors."""

from __future__ import annotations

import dataclasses
import io
import json
import math
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

import interprim as ip
from interprim import io as ipio
from interprim.core._compiled import loader as _fast
from interprim.synthetic import two_agent_demos

CONFIGS = {
    "default": {},
    "pca": {"pca_components": (2, 2)},
    "forcing": {"observation": "forcing"},
    "paper": {"observation": "forcing", "sigma2": "residual", "phase_method": "dtw"},  # fit sets no selection_
    "learned": {"phase_method": "learned"},  # a learned phase model inside the file
}


@pytest.fixture(scope="module")
def data():
    _fast.warmup()  # one code path (compiled, or numpy without numba) for every prediction of this module
    return two_agent_demos(14, seed=3, frames=120), two_agent_demos(3, seed=11, frames=120)


@pytest.fixture(scope="module")
def models(data):
    train, _ = data
    return {name: ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=10, **kw).fit(
        train, dt=0.01, columns=["o1", "o2", "c1", "c2", "c3"]) for name, kw in CONFIGS.items()}


@pytest.fixture(scope="module")
def saved(models, tmp_path_factory):
    d = tmp_path_factory.mktemp("models")
    paths = {}
    for name, m in models.items():
        paths[name] = d / f"{name}.npz"
        m.save(paths[name])
    return paths


# ----------------------------------------------------------------------------- helpers
def fitted_attributes(model) -> dict:
    """Every public fitted attribute (``name_``) of a model (the views of its fitted state)."""
    from interprim.models.primitive.fitted import FITTED_NAMES

    return {k: getattr(model, k) for k in FITTED_NAMES if hasattr(model, k)}


def assert_same(a, b, where="model"):
    """Deep equality: arrays bitwise (dtype, shape, bytes), floats exactly (NaN == NaN), objects by attributes."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        assert isinstance(a, np.ndarray) and isinstance(b, np.ndarray), where
        assert a.dtype == b.dtype and a.shape == b.shape, (where, a.dtype, b.dtype, a.shape, b.shape)
        assert np.ascontiguousarray(a).tobytes() == np.ascontiguousarray(b).tobytes(), where
    elif isinstance(a, dict):
        assert isinstance(b, dict) and set(a) == set(b), (where, set(a) ^ set(b) if isinstance(b, dict) else b)
        for k in a:
            assert_same(a[k], b[k], f"{where}[{k!r}]")
    elif isinstance(a, (list, tuple)):
        assert isinstance(b, (list, tuple)) and len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b)):
            assert_same(x, y, f"{where}[{i}]")
    elif isinstance(a, float) and math.isnan(a):
        assert isinstance(b, float) and math.isnan(b), where
    elif a is None or isinstance(a, (bool, int, float, str, np.number)):
        assert a == b and (a is None) == (b is None), (where, a, b)
    elif dataclasses.is_dataclass(a) or hasattr(a, "__dict__"):
        assert type(a) is type(b), where
        va, vb = vars(a), vars(b)
        assert_same({k: v for k, v in va.items() if not k.startswith("_")},
                    {k: v for k, v in vb.items() if not k.startswith("_")}, f"{where}.{type(a).__name__}")
    else:
        assert a == b, (where, a, b)


def prediction_outputs(model, partials):
    """Everything a user reads from predictions (batch and stream) on the same inputs."""
    out = []
    for z in partials:
        p = model.predict(z)
        out += [p.phase, p.duration, p.log_likelihood, p.trajectory(40), p.std(40), p.goal,
                p.samples(3, 40, random_state=0)]
    s = model.stream()
    for frame in partials[0]:
        p = s.update(frame)
    out += [p.phase, p.log_likelihood, p.trajectory(40)]
    return out


def partials_of(data):
    _, test = data
    return [test[0][:50, :2], test[1][:80, :2]]


def assert_identical_model(loaded, model, data):
    assert loaded.json_params() == model.json_params()
    assert_same(fitted_attributes(loaded), fitted_attributes(model))
    assert_same(prediction_outputs(loaded, partials_of(data)), prediction_outputs(model, partials_of(data)),
                "predictions")


# ----------------------------------------------------------------------------- round trip (item 4)
@pytest.mark.parametrize("name", list(CONFIGS))
def test_round_trip_keeps_every_fitted_attribute_and_predictions(models, saved, data, name):
    model = models[name]
    attrs = fitted_attributes(model)
    expected = {"selection_", "prior_", "thetas_", "reference_", "columns_", "phase_sigma2_", "sigma2_", "dt_",
                "durations_", "pca_observed_", "pca_controlled_", "start_position_", "start_velocity_"}
    if name == "paper":
        expected.discard("selection_")  # sigma2="residual" with the DTW phase selects nothing
    assert expected <= set(attrs), expected - set(attrs)
    loaded = ip.InteractionPrimitive.load(saved[name])
    assert set(fitted_attributes(loaded)) == set(attrs)
    assert_identical_model(loaded, model, data)
    if name == "default":  # the README's Quick start reads it
        assert loaded.selection_["sigma2"] == model.sigma2_ and "cv_error" in loaded.selection_
    if name == "pca":
        assert loaded.pca_observed_.explained_variance_ratio_.shape == (2,)
    # the prior's diagonal + low-rank form comes back too (the compiled conditioning uses it)
    assert loaded.prior_.factor is not None and loaded.prior_.diag is not None


def test_saved_twice_gives_the_same_file_content(models, tmp_path):
    m = models["default"]
    m.save(tmp_path / "a.npz")
    ip.InteractionPrimitive.load(tmp_path / "a.npz").save(tmp_path / "b.npz")
    with zipfile.ZipFile(tmp_path / "a.npz") as za, zipfile.ZipFile(tmp_path / "b.npz") as zb:
        assert za.namelist() == zb.namelist()
        for n in za.namelist():
            assert za.read(n) == zb.read(n), n


def test_metadata_holds_a_checksum_of_every_array(saved):
    with zipfile.ZipFile(saved["pca"]) as z:
        names = {n[:-4] for n in z.namelist()}
        meta = json.loads(np.load(io.BytesIO(z.read("metadata.npy"))).tobytes())
    assert meta["format_version"] == ipio.FORMAT_VERSION == 3
    assert set(meta["checksums"]) == names - {"metadata"}
    assert {"prior_diag", "prior_factor", "pca_observed_explained_variance_ratio"} <= names
    for entry in meta["checksums"].values():
        assert set(entry) == {"dtype", "shape", "sha256"} and len(entry["sha256"]) == 64


# ----------------------------------------------------------------------------- corruption (item 1)
def _rewrite(src: Path, dst: Path, edit):
    """Copy a model archive member by member (zip CRCs recomputed), ``edit(name, bytes) -> bytes``."""
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w", zipfile.ZIP_DEFLATED) as zout:
        for info in zin.infolist():
            zout.writestr(info.filename, edit(info.filename, zin.read(info.filename)))


def test_checksum_catches_corruption_the_zip_crc_cannot_see(saved, tmp_path):
    """A changed array whose archive member was rewritten with a valid CRC-32 is caught by its SHA-256."""
    with zipfile.ZipFile(saved["pca"]) as z:
        names = [n for n in z.namelist() if n != "metadata.npy"]
    assert len(names) >= 10
    for member in names:
        bad = tmp_path / f"bad_{member}.npz"

        def flip_last_byte(name, raw, member=member):
            return raw[:-1] + bytes([raw[-1] ^ 0x01]) if name == member else raw

        _rewrite(saved["pca"], bad, flip_last_byte)
        with pytest.raises(ip.ModelFileError) as info:
            ip.InteractionPrimitive.load(bad)
        msg = str(info.value)
        assert str(bad) in msg and f"checksum of array '{member[:-4]}' does not match" in msg, msg


def test_removed_or_added_array_is_refused(saved, tmp_path):
    missing = tmp_path / "missing.npz"
    with zipfile.ZipFile(saved["default"]) as zin, zipfile.ZipFile(missing, "w") as zout:
        for info in zin.infolist():
            if info.filename != "thetas.npy":
                zout.writestr(info.filename, zin.read(info.filename))
    with pytest.raises(ip.ModelFileError, match=r"\['thetas'\] listed in the metadata are missing"):
        ip.InteractionPrimitive.load(missing)
    extra = tmp_path / "extra.npz"
    _rewrite(saved["default"], extra, lambda n, raw: raw)
    with zipfile.ZipFile(extra, "a") as z:
        buf = io.BytesIO()
        np.save(buf, np.zeros(3))
        z.writestr("sneaky.npy", buf.getvalue())
    with pytest.raises(ip.ModelFileError, match=r"\['sneaky'\] are not listed"):
        ip.InteractionPrimitive.load(extra)


@pytest.mark.slow  # hundreds of corrupted files
def test_fuzz_byte_flips_truncations_insertions(models, saved, data, tmp_path):
    """500 random corruptions of a model file: each raises ModelFileError naming the file, or loads identically."""
    model, good = models["default"], saved["default"]
    raw = good.read_bytes()
    reference = prediction_outputs(model, partials_of(data))
    rng = np.random.default_rng(20261124)
    bad = tmp_path / "fuzzed.npz"
    outcomes = {"error": 0, "identical": 0}
    kinds = {"flip": 0, "truncate": 0, "insert": 0}
    for trial in range(500):
        kind = ("flip", "flip", "truncate", "insert")[trial % 4]
        kinds[kind] += 1
        if kind == "flip":  # 1-3 bytes, each XORed with a nonzero value
            b = bytearray(raw)
            for pos in rng.integers(0, len(raw), size=int(rng.integers(1, 4))):
                b[pos] ^= int(rng.integers(1, 256))
            b = bytes(b)
        elif kind == "truncate":
            b = raw[: int(rng.integers(0, len(raw)))]
        else:
            pos = int(rng.integers(0, len(raw) + 1))
            b = raw[:pos] + rng.integers(0, 256, size=int(rng.integers(1, 9))).astype(np.uint8).tobytes() + raw[pos:]
        bad.write_bytes(b)
        try:
            loaded = ip.InteractionPrimitive.load(bad)
        except ip.ModelFileError as exc:
            msg = str(exc)
            assert msg.startswith(f"{bad}: ") and "\n" not in msg, msg
            assert "pickle" not in msg.lower(), msg
            outcomes["error"] += 1
            continue
        # loaded in spite of the change (e.g. a flipped time stamp of a zip entry): must be the same model
        assert loaded.json_params() == model.json_params()
        assert_same(fitted_attributes(loaded), fitted_attributes(model), f"trial {trial} ({kind})")
        assert_same(prediction_outputs(loaded, partials_of(data)), reference, f"trial {trial} predictions")
        outcomes["identical"] += 1
    assert sum(outcomes.values()) == 500 and kinds == {"flip": 250, "truncate": 125, "insert": 125}
    assert outcomes["error"] >= 400, outcomes  # nearly every change of the bytes is a detected corruption


# ----------------------------------------------------------------------------- version 1 files (item 2)
def _save_v1(model, path, legacy_columns_array=False):
    """The writer of format version 1, as it was (no checksums, no selection, no prior factor, no PCA ratios)."""
    meta = {
        "format": "interprim-model",
        "format_version": 1,
        "params": model.json_params(),
        "observed_dofs": list(model.observed_dofs_),
        "controlled_dofs": list(model.controlled_dofs_),
        "n_dofs": int(model.n_dofs_),
        "n_observed_latent": int(model.n_observed_latent_),
        "n_latent": int(model.n_latent_),
        "beta_y": float(model.beta_y_),
        "dt": float(model.dt_),
        "mean_duration": float(model.mean_duration_),
        "sigma2": float(model.sigma2_),
        "phase_sigma2": (None if getattr(model, "phase_sigma2_", None) is None else float(model.phase_sigma2_)),
        "covariance_method": model.prior_.method,
        "shrinkage": float(model.prior_.shrinkage),
        "n_demos": int(model.n_demos_),
        "columns": getattr(model, "columns_", None),
    }
    arrays = {
        "prior_mean": model.prior_.mean,
        "prior_cov": model.prior_.cov,
        "thetas": model.thetas_,
        "reference": model.reference_,
        "start_position": model.start_position_,
        "start_velocity": model.start_velocity_,
        "durations": model.durations_,
    }
    for agent in ("observed", "controlled"):
        pca = getattr(model, f"pca_{agent}_")
        if pca is not None:
            arrays[f"pca_{agent}_mean"] = pca.mean_
            arrays[f"pca_{agent}_components"] = pca.components_
    if legacy_columns_array:  # the oldest files: column names as a string array, not in the metadata
        arrays["columns"] = np.array(meta.pop("columns"))
    arrays["metadata"] = np.frombuffer(json.dumps(meta).encode("utf-8"), dtype=np.uint8)
    with open(path, "wb") as fh:
        np.savez_compressed(fh, **arrays)


@pytest.mark.parametrize("name", list(CONFIGS))
def test_version_1_files_still_load(models, data, tmp_path, name):
    model = models[name]
    if model.phase_method_used() == "learned":  # version 1 predates the learned phase: such a model has no v1 file
        assert name == "learned" or model.phase_method == "cv"
        model = model.with_fitted(phase_method_="likelihood", phase_model_=None)
        model.phase_method = "likelihood"
    path = tmp_path / "v1.npz"
    _save_v1(model, path, legacy_columns_array=name == "pca")
    loaded = ip.InteractionPrimitive.load(path)
    assert loaded.json_params() == model.json_params()
    assert loaded.columns_ == model.columns_ == ["o1", "o2", "c1", "c2", "c3"]
    assert not hasattr(loaded, "selection_")  # version 1 did not store it
    attrs = fitted_attributes(model)
    # everything version 1 stored comes back bitwise
    for key in ("thetas_", "reference_", "start_position_", "start_velocity_", "durations_", "sigma2_",
                "phase_sigma2_", "dt_", "beta_y_", "n_demos_", "observed_dofs_", "controlled_dofs_"):
        assert_same(getattr(loaded, key), attrs[key], key)
    assert_same(loaded.prior_.mean, model.prior_.mean) and assert_same(loaded.prior_.cov, model.prior_.cov)
    # the same predictions (the low-rank form of the prior is rebuilt, or the dense form used: to rounding);
    # version 1 had no calibration of the predictive std: compare with the model's uncalibrated posterior
    assert loaded.calibration_ is None
    uncal = model.with_fitted(calibration_=None)
    for a, b in zip(prediction_outputs(loaded, partials_of(data)), prediction_outputs(uncal, partials_of(data))):
        np.testing.assert_allclose(a, b, rtol=1e-8, atol=1e-10)
    # and saving it again writes the current version
    loaded.save(tmp_path / "v3.npz")
    with zipfile.ZipFile(tmp_path / "v3.npz") as z:
        assert json.loads(np.load(io.BytesIO(z.read("metadata.npy"))).tobytes())["format_version"] == 3


def test_unknown_version_is_refused(saved, tmp_path):
    def bump(name, raw):
        if name != "metadata.npy":
            return raw
        meta = json.loads(np.load(io.BytesIO(raw)).tobytes())
        meta["format_version"] = 4
        buf = io.BytesIO()
        np.save(buf, np.frombuffer(json.dumps(meta).encode(), np.uint8))
        return buf.getvalue()

    _rewrite(saved["default"], tmp_path / "v4.npz", bump)
    with pytest.raises(ip.ModelFileError, match="format_version 4 is not supported .*reads versions 1, 2, 3"):
        ip.InteractionPrimitive.load(tmp_path / "v4.npz")


# ----------------------------------------------------------------------------- not model files (item 3)
def _not_models(d: Path) -> dict:
    files = {}
    (d / "demos.csv").write_text("time,x,y\n0,1,2\n0.1,1,2\n")
    files["demos.csv"] = "not a readable .npz archive"
    (d / "notes.txt").write_text("hello\n")
    files["notes.txt"] = "not a readable .npz archive"
    (d / "empty.npz").write_bytes(b"")
    files["empty.npz"] = "empty file"
    (d / "random.npz").write_bytes(np.random.default_rng(0).integers(0, 256, 4096).astype(np.uint8).tobytes())
    files["random.npz"] = "not a readable .npz archive"
    np.save(d / "array.npy", np.arange(5.0))
    files["array.npy"] = r"single NumPy array \(\.npy\)"
    np.savez(d / "other.npz", a=np.zeros(3), b=np.ones((2, 2)))
    files["other.npz"] = r"without interprim model metadata; it holds \['a', 'b'\]"
    np.savez(d / "objects.npz", a=np.array([{"x": 1}], dtype=object))
    files["objects.npz"] = r"without interprim model metadata"
    np.savez(d / "objmeta.npz", metadata=np.array([{"format": "interprim-model"}], dtype=object))
    files["objmeta.npz"] = "array 'metadata' has dtype object, but model files hold only numeric arrays"
    np.savez(d / "othermeta.npz", metadata=np.frombuffer(b'{"format": "something-else"}', np.uint8))
    files["othermeta.npz"] = "format is 'something-else'"
    with zipfile.ZipFile(d / "plain.zip", "w") as z:
        z.writestr("readme.txt", "not numpy")
    files["plain.zip"] = "without interprim model metadata; it holds no arrays"
    return files


def test_non_model_files_are_refused_without_mentioning_pickles(tmp_path):
    for name, match in _not_models(tmp_path).items():
        with pytest.raises(ip.ModelFileError, match=match) as info:
            ip.InteractionPrimitive.load(tmp_path / name)
        msg = str(info.value)
        assert msg.startswith(f"{tmp_path / name}: ") and "not" in msg and "interprim model file" in msg, msg
        assert "pickle" not in msg.lower(), msg
    assert isinstance(info.value, ValueError) and ip.ModelFileError is ipio.ModelFileError
    with pytest.raises(ip.ModelFileError, match="no such model file"):
        ip.InteractionPrimitive.load(tmp_path / "nope.npz")
    with pytest.raises(ip.ModelFileError, match="is a directory"):
        ip.InteractionPrimitive.load(tmp_path)


def test_loading_never_unpickles(saved, tmp_path, monkeypatch):
    """A model file whose metadata is a pickled object is refused without calling pickle at all."""
    import pickle

    calls = []
    monkeypatch.setattr(pickle, "load", lambda *a, **k: calls.append(a))
    monkeypatch.setattr(pickle, "loads", lambda *a, **k: calls.append(a))
    np.savez(tmp_path / "p.npz", metadata=np.array([{"format": "interprim-model"}], dtype=object))
    with pytest.raises(ip.ModelFileError):
        ip.InteractionPrimitive.load(tmp_path / "p.npz")
    ip.InteractionPrimitive.load(saved["default"])
    assert calls == []


# ----------------------------------------------------------------------------- CLI (item 5)
def _cli(*args, timeout=120):
    exe = Path(sys.executable).with_name("interprim")
    cmd = [str(exe)] if exe.exists() else [sys.executable, "-m", "interprim.cli"]
    return subprocess.run(cmd + list(args), capture_output=True, text=True, timeout=timeout)


@pytest.fixture(scope="module")
def bad_models(saved, tmp_path_factory):
    d = tmp_path_factory.mktemp("bad")
    raw = saved["default"].read_bytes()
    b = bytearray(raw)
    with zipfile.ZipFile(saved["default"]) as z:
        info = z.getinfo("prior_cov.npy")
    b[info.header_offset + 30 + len(info.filename) + info.compress_size // 2] ^= 0xFF  # inside the deflate data
    (d / "flipped.npz").write_bytes(bytes(b))
    (d / "truncated.npz").write_bytes(raw[: len(raw) // 3])
    (d / "demos.csv").write_text("time,x,y\n0,1,2\n0.1,1,2\n")
    np.savez(d / "other.npz", a=np.zeros(3))
    partial = d / "partial.csv"
    partial.write_text("time,o1,o2\n" + "".join(f"{0.01 * i},{0.01 * i},0\n" for i in range(10)))
    return d


@pytest.mark.parametrize("bad", ["flipped.npz", "truncated.npz", "demos.csv", "other.npz"])
def test_cli_predict_with_bad_model_file_prints_one_line(bad_models, bad, tmp_path):
    path = bad_models / bad
    r = _cli("predict", str(path), str(bad_models / "partial.csv"), "-o", str(tmp_path / "o.csv"))
    assert r.returncode == 2, r.stderr
    assert r.stdout == "" and r.stderr.count("\n") == 1, r.stderr
    line = r.stderr.strip()
    assert line.startswith(f"interprim predict: error: {path}: "), line
    assert "Traceback" not in line and "pickle" not in line.lower(), line
    if bad in ("demos.csv", "other.npz"):
        assert "not an interprim model file" in line, line
    assert not (tmp_path / "o.csv").exists()


@pytest.mark.parametrize("bad", ["flipped.npz", "demos.csv"])
def test_cli_serve_with_bad_model_file_prints_one_line(bad_models, bad):
    pytest.importorskip("websockets")
    path = bad_models / bad
    r = _cli("serve", str(path), "--port", "0")
    assert r.returncode == 2, r.stderr
    assert r.stderr.count("\n") == 1 and "Traceback" not in r.stderr, r.stderr
    # the server names the model it could not serve, then the file and what is wrong with it
    assert r.stderr.startswith(f"interprim serve: error: cannot serve model '{path.stem}': {path}: "), r.stderr
    what = "truncated or corrupt model file" if bad == "flipped.npz" else "not an interprim model file"
    assert what in r.stderr and "pickle" not in r.stderr.lower(), r.stderr


# ----------------------------------------------------------------------------- other CLI errors (item 5)
def test_cli_evaluate_with_a_user_file_is_one_line(tmp_path):
    # a user's file is evaluated (tests/model_selection/test_realtime.py); a bad one is one line naming it, before any
    # work
    (tmp_path / "demos.csv").write_text("time,x,y\n0,1,2\n0.1,1,2\n")
    r = _cli("evaluate", "--data", str(tmp_path / "demos.csv"), "--out", str(tmp_path / "ev"))
    assert r.returncode == 1 and r.stdout == "" and r.stderr.count("\n") == 1, r.stderr
    assert r.stderr.startswith(f"interprim evaluate: error: {tmp_path / 'demos.csv'}: only 2 frame(s)"), r.stderr
    assert not (tmp_path / "ev").exists()
    r = _cli("evaluate", "--data", str(tmp_path / "nothere.csv"), "--out", str(tmp_path / "ev"))
    assert r.returncode == 1 and r.stderr.count("\n") == 1 and "no such file or folder" in r.stderr, r.stderr
    r = _cli("evaluate", "--data", "nuisi,nope", "--out", str(tmp_path / "ev"))
    assert r.returncode == 1 and r.stderr.count("\n") == 1, r.stderr
    assert r.stderr.startswith("interprim evaluate: error: --data nope: not a built-in data set; expected nuisi,")
    r = _cli("evaluate", "--data", "synthetic", "--methods", "ip-position,nope", "--out", str(tmp_path / "ev"))
    assert r.returncode == 1 and r.stderr.count("\n") == 1, r.stderr
    assert "--methods: unknown method 'nope'" in r.stderr


def test_cli_messages_name_flags_not_python_arguments(tmp_path, capsys):
    from interprim.cli import main

    rows = [f"{0.1 * i:.1f},{i},{2 * i}" for i in range(8)]
    rows[3] = rows[3].split(",")[0] + ",," + rows[3].split(",")[2]
    rows[4] = rows[4].split(",")[0] + ",nan," + rows[4].split(",")[2]
    (tmp_path / "gap.csv").write_text("time,x,y\n" + "\n".join(rows) + "\n")
    out = str(tmp_path / "m.npz")
    assert main(["fit", "--model", "ip", str(tmp_path / "gap.csv"), "--observed", "x", "-o", out, "--max-nan-gap",
                 "1"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "max_nan_gap" not in err, err
    assert "a run of 2 missing values (--max-nan-gap 1) starting at line 5" in err
    assert err.rstrip().endswith("or interpolate interior gaps of up to 2 frames with --max-nan-gap 2"), err
    # a run at the start cannot be interpolated: no advice to pass an option that cannot help
    rows = [f"{0.1 * i:.1f},{i},{2 * i}" for i in range(8)]
    rows[0] = "0.0,,0"
    (tmp_path / "start.csv").write_text("time,x,y\n" + "\n".join(rows) + "\n")
    assert main(["fit", "--model", "ip", str(tmp_path / "start.csv"), "--observed", "x", "-o", out, "--max-nan-gap",
                 "3"]) == 1
    err = capsys.readouterr().err
    assert "at the start or end starting at line 2" in err and err.rstrip().endswith("fill or cut them"), err
    assert "nan-gap" not in err and "max_nan_gap" not in err
    # the Python API keeps naming its own argument
    from interprim.datasets import load_demonstrations

    with pytest.raises(ip.DataFileError, match=r"with max_nan_gap=2$"):
        load_demonstrations(tmp_path / "gap.csv", max_nan_gap=1)
    # a server option
    pytest.importorskip("websockets")
    assert main(["serve", "--max-sessions", "0", "--port", "0", "x.npz"]) == 1
    err = capsys.readouterr().err
    assert "--max-sessions must be" in err and "max_sessions" not in err, err
    # a file name that contains an argument name is left alone
    assert main(["fit", "--model", "ip", str(tmp_path / "max_nan_gap.csv"), "--observed", "x", "-o", out]) == 1
    assert "max_nan_gap.csv" in capsys.readouterr().err

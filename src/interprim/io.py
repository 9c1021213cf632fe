"""Safe model files.

Format (``format = "interprim-model"``): a ZIP archive of ``.npy`` members (as
written by ``numpy.savez_compressed``) holding plain numeric arrays, plus one
member ``metadata``: a ``uint8`` array of a UTF-8 JSON document
(hyper-parameters, column layout, fitted scalars, checksums).  It is read
member by member with :mod:`zipfile` (whose CRC-32 of every member is checked)
and a strict ``.npy`` parser that accepts only numeric, boolean and string
dtypes, so loading a model never unpickles or executes anything.

Versions (``format_version``):

* **3** (written now): version 2 with a look-ahead-aware calibration of the predictive std: the arrays
  ``calibration_lookaheads (H,)`` and ``calibration_column_scale (F, H, D)``, and ``calibration_scale_{observed,
  controlled}`` of shape ``(F, H)`` (:class:`~interprim.models.primitive.calibration.Calibration`).  An older interprim refuses
  the file with "format_version 3 is not supported"; version 1 and 2 files still load (a version 2
  calibration, ``(F,)`` scales, acts at every look-ahead as it did).
* **2**: ``metadata`` also holds
  ``checksums``, ``{name: {"dtype", "shape", "sha256"}}`` for every other array
  (SHA-256 of the array's C-ordered bytes); ``selection`` (``selection_``,
  the hyper-parameter selection record of ``fit``, or ``null``); and the
  arrays ``prior_diag``/``prior_factor`` (the diagonal + low-rank form of the
  prior covariance), ``pca_*_explained_variance_ratio`` and ``calibration_{fractions,scale_observed,
  scale_controlled,n_cases}`` (:class:`~interprim.models.primitive.calibration.Calibration`) and ``input_mean``/``input_std``
  (with ``input_limit`` in the metadata: the out-of-range check of the observed frames) when the model has them.
* **1**: the same without ``checksums``, ``selection`` and those arrays;
  still read (every array's shape is checked, the rest is unset or rebuilt).

Every problem -- a missing, empty, truncated or corrupt file, a checksum that
does not match, a file that is not an interprim model at all (text, CSV, a
plain ``.npy``, a ``.npz`` of other arrays) or an unknown version -- raises
:class:`~interprim.core.errors.ModelFileError` with a message that names the file
and what is wrong.

Arrays: ``prior_mean (P,)``, ``prior_cov (P, P)``, ``thetas (S, P)``,
``reference (N, D_o')``, ``start_position (D')``, ``start_velocity (D')``,
``durations (S,)``, optionally ``prior_diag (P,)``, ``prior_factor (P, r)`` and, with PCA,
``pca_{observed,controlled}_{mean,components,explained_variance_ratio}``;
``P = D' (n_basis + 1)`` and ``D'`` the number of (latent) DoFs, observed first.

Metadata: ``params`` (every constructor argument, so the file reproduces the
model's configuration, e.g. ``phase_method``), the column layout and names
(``observed_dofs``, ``controlled_dofs``, ``columns`` or ``null``), and the fitted
scalars (``dt``, ``sigma2``, ``phase_sigma2``, ``shrinkage``, ...).  Files of
older interprim versions without ``columns``/``phase_sigma2``/``input_noise``
load with those unset.
"""

from __future__ import annotations

import hashlib
import io
import json
import math
import struct
import zipfile
import zlib
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from .core.errors import ModelFileError
from .core.gaussian import GaussianPrior
from .core.preprocessing import PCA

FORMAT = "interprim-model"
FORMAT_VERSION = 3
READ_VERSIONS = (1, 2, 3)

__all__ = ["model_kind", "save_model", "load_model", "model_state", "model_from_state", "fitted_from_state",
           "save_estimator", "load_estimator",
           "FORMAT", "FORMAT_VERSION", "READ_VERSIONS"]

_ZIP_MAGIC = b"PK\x03\x04"
_NPY_MAGIC = b"\x93NUMPY"
# numeric, boolean and (for the legacy 'columns' array) unicode strings; never objects
_DTYPE_KINDS = "biufcU"
# exceptions that zipfile / zlib / the .npy header parser raise on damaged bytes
_READ_ERRORS = (zipfile.BadZipFile, zipfile.LargeZipFile, zlib.error, EOFError, OSError, ValueError, KeyError,
                IndexError, NotImplementedError, RuntimeError, struct.error, OverflowError, MemoryError,
                SyntaxError, TypeError)


def _checksum(arr: np.ndarray) -> dict:
    arr = np.asarray(arr)
    return {"dtype": arr.dtype.str, "shape": list(arr.shape),
            "sha256": hashlib.sha256(np.ascontiguousarray(arr).tobytes()).hexdigest()}


def _metadata(model) -> dict:
    return {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
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


def _arrays(model) -> dict:
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
    return arrays


def save_model(model, path) -> None:
    """Write a fitted :class:`~interprim.InteractionPrimitive` to ``path`` (``.npz``, format version 3): its
    :meth:`~interprim.models.primitive.estimator.InteractionPrimitive.to_state`, each array checksummed."""
    path = Path(path)
    arrays, meta = model.to_state()
    meta["checksums"] = {k: _checksum(v) for k, v in arrays.items()}
    _write(path, meta, arrays)


def model_state(model):
    """``(arrays, meta)`` of a fitted Interaction Primitive as a model file holds them (without checksums;
    :meth:`~interprim.models.primitive.estimator.InteractionPrimitive.to_state`)."""
    meta = _metadata(model)
    arrays = _arrays(model)
    for name in ("diag", "factor"):  # the prior's diagonal + low-rank form (exact reload of the fast path)
        value = getattr(model.prior_, name, None)
        if value is not None:
            arrays[f"prior_{name}"] = np.asarray(value)
    for agent in ("observed", "controlled"):
        pca = getattr(model, f"pca_{agent}_")
        if pca is not None and getattr(pca, "explained_variance_ratio_", None) is not None:
            arrays[f"pca_{agent}_explained_variance_ratio"] = pca.explained_variance_ratio_
    arrays = {k: np.asarray(v) for k, v in arrays.items()}
    if getattr(model, "input_mean_", None) is not None:  # the out-of-range check's training statistics
        arrays["input_mean"] = np.asarray(model.input_mean_)
        arrays["input_std"] = np.asarray(model.input_std_)
        meta["input_limit"] = float(model.input_limit_)
    meta["phase_method_used"] = model.phase_method_used()
    pm = getattr(model, "phase_model_", None)  # the learned phase (phase_method="learned")
    if pm is not None:
        pm_arrays, meta["phase_model"] = pm.to_state()
        for k, v in pm_arrays.items():
            arrays[f"phase_model_{k}"] = np.asarray(v)
    cal = getattr(model, "calibration_", None)  # calibrated predictive std (interprim.models.primitive.calibration)
    if cal is not None:
        for k, v in cal.to_arrays().items():
            arrays[f"calibration_{k}"] = np.asarray(v)
    meta["selection"] = getattr(model, "selection_", None)
    meta["representation"] = getattr(model, "representation_", None)  # absent in files before 2026-11-26
    return arrays, meta


def save_estimator(model, path) -> None:
    """Write a fitted model other than the Interaction Primitive (any :class:`~interprim.models.base.Predictor`).

    The same container as :func:`save_model` (format version 3: checksummed ``.npy`` members and a JSON
    ``metadata``), with ``metadata["model"]`` the class name, ``metadata["model_version"]`` its
    ``STATE_VERSION``, ``params`` its constructor arguments and ``state`` the JSON part of its
    :meth:`~interprim.models.base.Predictor.to_state`.
    """
    path = Path(path)
    arrays, state = model.to_state()
    arrays = {k: np.asarray(v) for k, v in arrays.items()}
    rng = getattr(model, "input_range_", None)
    if rng is not None and "input_range" not in state:  # the out-of-range check of the model contract
        state = dict(state, input_range=[np.asarray(rng[0]).tolist(), np.asarray(rng[1]).tolist(), float(rng[2])])
    meta = {"format": FORMAT, "format_version": FORMAT_VERSION, "model": type(model).__name__,
            "model_version": int(model.STATE_VERSION), "params": model.json_params(), "state": state,
            "checksums": {k: _checksum(v) for k, v in arrays.items()}}
    _write(path, meta, arrays)


def load_estimator(path, model_class):
    """Read a model written by :func:`save_estimator` as a ``model_class`` (no pickle, every array checked)."""
    path = Path(path)
    meta, data = _read_archive(path)
    name = model_class.__name__
    kind = meta.get("model", "InteractionPrimitive")
    _expect(kind == name, path, f"holds a {kind} model, not a {name}")
    version = meta.get("model_version")
    _expect(type(version) is int and 1 <= version <= model_class.STATE_VERSION, path,
            f"{name} model_version {version!r} is not supported by this interprim "
            f"(reads 1..{model_class.STATE_VERSION})")
    try:
        model = model_class(**meta["params"])
        model.load_state(data, meta["state"])
        if "input_range" in meta["state"] and getattr(model, "input_range_", None) is None:
            model.set_input_range(meta["state"]["input_range"])
    except ModelFileError:
        raise
    except (KeyError, TypeError, ValueError, IndexError) as exc:
        raise ModelFileError(f"{path}: corrupt {name} model file ({type(exc).__name__}: {exc})") from None
    return model


def _write(path: Path, meta: dict, arrays: dict) -> None:
    arrays = dict(arrays)
    arrays["metadata"] = np.frombuffer(json.dumps(meta).encode("utf-8"), dtype=np.uint8)
    # write to a temporary file first so that a crash never leaves a half-written model behind
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "wb") as fh:
        np.savez_compressed(fh, **arrays)
    tmp.replace(path)


def _expect(cond: bool, path, msg: str):
    if not cond:
        raise ModelFileError(f"{path}: {msg}")


def _parse_npy(raw: bytes, path, name: str) -> np.ndarray:
    """A ``.npy`` member's array; refuses object/structured dtypes and any size mismatch (never unpickles)."""
    fh = io.BytesIO(raw)
    version = np.lib.format.read_magic(fh)
    if version == (1, 0):
        shape, fortran, dtype = np.lib.format.read_array_header_1_0(fh)
    elif version == (2, 0):
        shape, fortran, dtype = np.lib.format.read_array_header_2_0(fh)
    else:
        raise ValueError(f".npy version {version} is not supported")
    _expect(not dtype.hasobject and dtype.fields is None and dtype.kind in _DTYPE_KINDS, path,
            f"not a readable interprim model file: array '{name}' has dtype {dtype}, "
            "but model files hold only numeric arrays")
    count = math.prod(shape)
    offset = fh.tell()
    _expect(len(raw) - offset == count * dtype.itemsize, path,
            f"array '{name}' is truncated or corrupt ({len(raw) - offset} bytes of data for shape {shape}, {dtype})")
    arr = np.frombuffer(raw, dtype=dtype, count=count, offset=offset)
    return arr.reshape(shape, order="F" if fortran else "C").copy(order="K")


MAX_ARCHIVE_BYTES = 1 << 30  # the sum of a model file's members once decompressed (1 GiB)
MAX_METADATA_BYTES = 16 << 20  # its metadata member (JSON) once decompressed
_NPY_HEADER_SLACK = 1 << 16  # bytes a .npy member may hold besides its data (magic + header)


def _read_member(zf, info, path, name: str, budget: int, want=None) -> np.ndarray:
    """One ``.npy`` member, read through a bounded reader: its header first (dtype and shape, no data), then
    exactly the data bytes it declares.  Refused before anything is decompressed when the member's declared
    (uncompressed) size is over ``budget`` or does not match ``want`` (``{"dtype", "shape"}`` from the
    metadata's checksums table); the reader never returns more than the declared size (zipfile stops there and
    checks the CRC-32), and the header must account for exactly that size."""
    declared = int(info.file_size)
    _expect(declared <= budget, path,
            f"array '{name}' declares {declared} bytes uncompressed, over the limit of {budget} bytes for a model "
            f"file (compressed {int(info.compress_size)} bytes): refusing to decompress it")
    if isinstance(want, dict):
        try:
            n = math.prod(int(d) for d in want.get("shape", ())) * np.dtype(want.get("dtype")).itemsize
        except (TypeError, ValueError):
            n = None
        _expect(n is not None and n <= declared <= n + _NPY_HEADER_SLACK, path,
                f"array '{name}' declares {declared} bytes uncompressed, but the metadata gives it shape "
                f"{want.get('shape')} and dtype {want.get('dtype')}: refusing to decompress it")
    with zf.open(info) as fh:
        version = np.lib.format.read_magic(fh)
        if version == (1, 0):
            shape, fortran, dtype = np.lib.format.read_array_header_1_0(fh)
        elif version == (2, 0):
            shape, fortran, dtype = np.lib.format.read_array_header_2_0(fh)
        else:
            raise ValueError(f".npy version {version} is not supported")
        _expect(not dtype.hasobject and dtype.fields is None and dtype.kind in _DTYPE_KINDS, path,
                f"not a readable interprim model file: array '{name}' has dtype {dtype}, "
                "but model files hold only numeric arrays")
        count = math.prod(shape)
        nbytes = count * dtype.itemsize
        offset = fh.tell()
        _expect(offset + nbytes == declared, path,
                f"array '{name}' is truncated or corrupt ({declared - offset} bytes of data for shape {shape}, "
                f"{dtype})")
        raw = fh.read(nbytes)
        _expect(len(raw) == nbytes, path, f"array '{name}' is truncated or corrupt ({len(raw)} bytes of data for "
                                          f"shape {shape}, {dtype})")
    arr = np.frombuffer(raw, dtype=dtype, count=count)
    return arr.reshape(shape, order="F" if fortran else "C").copy(order="K")


def _read_archive(path: Path):
    """``(meta, arrays)`` of a model file, every member's CRC-32 and (version 2) SHA-256 checked.

    Bounded before expanded: the members' declared sizes are checked (against the metadata's shapes and dtypes
    from version 2 on, and against :data:`MAX_ARCHIVE_BYTES` in all) before any member is decompressed."""
    if not path.exists():
        raise ModelFileError(f"{path}: no such model file")
    if path.is_dir():
        raise ModelFileError(f"{path}: is a directory, not an interprim model file")
    try:
        with open(path, "rb") as fh:
            head = fh.read(8)
    except OSError as exc:
        raise ModelFileError(f"{path}: cannot read the model file: {exc.strerror or exc}") from None
    if not head:
        raise ModelFileError(f"{path}: empty file; not an interprim model file")
    if head.startswith(_NPY_MAGIC):
        raise ModelFileError(f"{path}: a single NumPy array (.npy), not an interprim model file "
                             "(save models with InteractionPrimitive.save or 'interprim fit')")
    if not head.startswith(_ZIP_MAGIC):
        raise ModelFileError(f"{path}: not an interprim model file (not a readable .npz archive; "
                             "save models with InteractionPrimitive.save or 'interprim fit')")
    try:
        with zipfile.ZipFile(path) as zf:
            members = {}
            for info in zf.infolist():
                if info.filename.endswith(".npy"):
                    members[info.filename[:-4]] = info
            if "metadata" not in members and {"prior_mean", "prior_cov", "thetas"} & set(members):
                raise ModelFileError(f"{path}: corrupt model file: its 'metadata' entry is missing")
            if "metadata" not in members:
                raise ModelFileError(f"{path}: not an interprim model file (a .npz archive without interprim "
                                     f"model metadata; it holds {sorted(members) or 'no arrays'})")
            total = sum(int(i.file_size) for i in members.values())
            _expect(total <= MAX_ARCHIVE_BYTES, path,
                    f"its arrays declare {total} bytes uncompressed, over the limit of {MAX_ARCHIVE_BYTES} bytes for "
                    "a model file: refusing to decompress them (a damaged file, or a zip bomb)")
            meta_arr = _read_member(zf, members["metadata"], path, "metadata", MAX_METADATA_BYTES)
            try:
                meta = json.loads(meta_arr.astype(np.uint8).tobytes().decode("utf-8"))
            except (ValueError, UnicodeDecodeError) as exc:
                raise ModelFileError(f"{path}: corrupt metadata: {exc}") from None
            _expect(isinstance(meta, dict) and meta.get("format") == FORMAT, path,
                    "not an interprim model file (format is "
                    f"{meta.get('format') if isinstance(meta, dict) else None!r}, expected {FORMAT!r})")
            version = meta.get("format_version")
            _expect(type(version) is int and version in READ_VERSIONS, path,
                    f"format_version {version!r} is not supported by this interprim (reads versions "
                    f"{', '.join(map(str, READ_VERSIONS))}); a newer interprim wrote it?")
            sums = meta.get("checksums") if version >= 2 else None
            if version >= 2:
                _expect(isinstance(sums, dict), path, "corrupt metadata: no 'checksums' table")
                extra = sorted(set(members) - set(sums) - {"metadata"})
                _expect(not extra, path, f"array(s) {extra} are not listed in the metadata's checksums")
            data = {}
            for name, info in members.items():
                if name != "metadata":
                    data[name] = _read_member(zf, info, path, name, MAX_ARCHIVE_BYTES,
                                              want=sums.get(name) if sums else None)
    except ModelFileError:
        raise
    except _READ_ERRORS as exc:
        kind = type(exc).__name__ if type(exc).__name__ != "error" else f"{type(exc).__module__}.error"  # zlib.error
        raise ModelFileError(f"{path}: truncated or corrupt model file, not a readable .npz archive "
                             f"({kind}: {exc})") from None
    if version >= 2:
        sums = meta.get("checksums")
        _expect(isinstance(sums, dict), path, "corrupt metadata: no 'checksums' table")
        missing = sorted(set(sums) - set(data))
        _expect(not missing, path, f"array(s) {missing} listed in the metadata are missing")
        extra = sorted(set(data) - set(sums))
        _expect(not extra, path, f"array(s) {extra} are not listed in the metadata's checksums")
        for name, arr in data.items():
            want = sums[name]
            _expect(isinstance(want, dict) and _checksum(arr) == want, path,
                    f"checksum of array '{name}' does not match: the file is corrupt")
    return meta, data


def load_model(path, model_class):
    """Read a model written by :func:`save_model` (format version 1, 2 or 3; no pickle, every array checked) as a
    ``model_class`` (:class:`~interprim.models.primitive.estimator.InteractionPrimitive`)."""
    path = Path(path)
    meta, data = _read_archive(path)
    kind = meta.get("model", "InteractionPrimitive")
    _expect(kind == "InteractionPrimitive", path, f"holds a {kind} model, not an InteractionPrimitive")
    return model_class.from_state(data, meta, source=path)


def _renamed_values(params: dict, old: dict) -> dict:
    """A model file's parameters with values of older releases under their names of today (``old``:
    ``{parameter: {old value: new value}}``): a file format migration, not an alias of the API."""
    out = dict(params)
    for name, table in old.items():
        v = out.get(name)
        if isinstance(v, str) and v in table:
            out[name] = table[v]
    return out


def model_from_state(data: dict, meta: dict, model_class, path="<state>"):
    """The model of ``(data, meta)`` (a model file's arrays and metadata, format versions 1-3), every array
    checked; problems raise :class:`~interprim.core.errors.ModelFileError` naming ``path``
    (:meth:`~interprim.models.primitive.estimator.InteractionPrimitive.from_state`)."""
    try:
        model = model_class(**_renamed_values(meta["params"], getattr(model_class, "OLD_VALUES", {})))
        params = model.json_params()  # the file's parameters, with the defaults of those it predates
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise ModelFileError(f"{path}: incomplete or inconsistent model file: {exc!r}") from None
    fitted = fitted_from_state(data, meta, params, path)
    try:
        model.load_fitted(fitted)
    except (TypeError, ValueError, OverflowError) as exc:
        raise ModelFileError(f"{path}: inconsistent model parameters: {exc}") from None
    return model


def fitted_from_state(data: dict, meta: dict, params: dict, path="<state>") -> dict:
    """The fitted attributes (names ending in ``_``) of ``(data, meta)``, a model file's arrays and metadata
    (format versions 1-3), every array checked, for a model with the parameters ``params`` (complete, as
    :meth:`~interprim.models.primitive.estimator.InteractionPrimitive.json_params` gives them); problems raise
    :class:`~interprim.core.errors.ModelFileError` naming ``path``
    (:meth:`~interprim.models.primitive.fitted.FittedPrimitive.from_state` builds the state from them)."""
    phase_method = params["phase_method"]
    try:
        st = SimpleNamespace()  # the fitted attributes
        st.observed_dofs_ = [int(i) for i in meta["observed_dofs"]]
        st.controlled_dofs_ = [int(i) for i in meta["controlled_dofs"]]
        st.n_dofs_ = int(meta["n_dofs"])
        st.n_observed_latent_ = int(meta["n_observed_latent"])
        st.n_latent_ = int(meta["n_latent"])
        st.beta_y_ = float(meta["beta_y"])
        st.dt_ = float(meta["dt"])
        st.mean_duration_ = float(meta["mean_duration"])
        st.sigma2_ = float(meta["sigma2"])
        ps2 = meta.get("phase_sigma2")  # noise of the likelihood phase estimator (absent in older files)
        st.phase_sigma2_ = None if ps2 is None else float(ps2)
        st.n_demos_ = int(meta["n_demos"])
        cols = meta.get("columns")  # column names (absent in older files; the CLI's legacy 'columns' array)
        if cols is None and "columns" in data:
            cols = [str(c) for c in data["columns"]]
        _expect(cols is None or (isinstance(cols, list) and len(cols) == st.n_dofs_), path,
                f"columns {cols!r} do not name the model's {st.n_dofs_} columns")
        st.columns_ = None if cols is None else [str(c) for c in cols]
        sel = meta.get("selection")  # hyper-parameter selection record (version 2; absent when fit made none)
        _expect(sel is None or isinstance(sel, dict), path, "corrupt metadata: 'selection' is not a record")
        if sel is not None:
            st.selection_ = sel
        rep = meta.get("representation")  # how well the DMPs represent the demonstrations (newer files)
        _expect(rep is None or isinstance(rep, dict), path, "corrupt metadata: 'representation' is not a record")
        if rep is not None:
            st.representation_ = rep
        st.prior_ = GaussianPrior(data["prior_mean"], data["prior_cov"], str(meta["covariance_method"]),
                                  float(meta["shrinkage"]), data.get("prior_diag"), data.get("prior_factor"))
        st.thetas_ = data["thetas"]
        st.reference_ = data["reference"]
        st.start_position_ = data["start_position"]
        st.start_velocity_ = data["start_velocity"]
        st.durations_ = data["durations"]
        st.input_mean_ = st.input_std_ = st.input_limit_ = None  # absent in older files: no check
        if "input_mean" in data:
            st.input_mean_, st.input_std_ = data["input_mean"], data["input_std"]
            st.input_limit_ = float(meta["input_limit"])
            n_o = len(st.observed_dofs_)
            _expect(st.input_mean_.shape == (n_o,) and st.input_std_.shape == (n_o,)
                    and bool(np.all(st.input_std_ > 0)) and st.input_limit_ > 0, path,
                    f"arrays 'input_mean'/'input_std' are not ({n_o},) statistics with a positive spread")
        st.phase_model_ = None
        if meta.get("phase_model") is not None:
            from .phase.learned import LearnedPhase

            st.phase_model_ = LearnedPhase.from_state(
                {k[len("phase_model_"):]: v for k, v in data.items() if k.startswith("phase_model_")},
                meta["phase_model"])
        used = meta.get("phase_method_used")  # absent in files older than phase_method="cv": as set there
        st.phase_method_ = str(used if used is not None else
                               (phase_method if phase_method != "cv" else "likelihood"))
        _expect(st.phase_method_ in ("dtw", "likelihood", "learned"), path,
                f"unknown phase method {st.phase_method_!r} in the metadata")
        used = st.phase_method_ if phase_method == "cv" else phase_method
        _expect(used != "learned" or st.phase_model_ is not None, path,
                "the phase method is 'learned' but the file holds no phase model")
        st.calibration_ = None
        if any(k.startswith("calibration_") for k in data):
            from .models.primitive.calibration import Calibration

            try:
                st.calibration_ = Calibration.from_arrays({k[len("calibration_"):]: v for k, v in data.items()
                                                           if k.startswith("calibration_")})
            except (KeyError, TypeError, ValueError) as exc:
                raise ModelFileError(f"{path}: arrays 'calibration_*' are not a calibration: "
                                     f"{type(exc).__name__}: {exc}") from None
            bad = st.calibration_.problem(len(st.observed_dofs_) + len(st.controlled_dofs_))
            _expect(bad is None, path, f"arrays 'calibration_*' are not a calibration: {bad}")
        for agent in ("observed", "controlled"):
            pca = None
            if f"pca_{agent}_mean" in data:
                comps = data[f"pca_{agent}_components"]
                _expect(comps.ndim == 2, path, f"array 'pca_{agent}_components' has shape {comps.shape}")
                pca = PCA(comps.shape[0])
                pca.mean_ = data[f"pca_{agent}_mean"]
                pca.components_ = comps
                evr = data.get(f"pca_{agent}_explained_variance_ratio")
                if evr is not None:
                    pca.explained_variance_ratio_ = evr
            setattr(st, f"pca_{agent}_", pca)
    except ModelFileError:
        raise
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise ModelFileError(f"{path}: incomplete or inconsistent model file: {exc!r}") from None

    q = int(params["n_basis"]) + 1
    P = st.n_latent_ * q
    checks = {
        "prior_mean": (P,), "prior_cov": (P, P), "thetas": (st.n_demos_, P),
        "start_position": (st.n_latent_,), "start_velocity": (st.n_latent_,), "durations": (st.n_demos_,),
    }
    if "prior_diag" in data or "prior_factor" in data:
        _expect("prior_diag" in data and "prior_factor" in data, path,
                "the prior's diagonal + low-rank form needs both 'prior_diag' and 'prior_factor'")
        checks["prior_diag"] = (P,)
        f = data["prior_factor"]
        _expect(f.ndim == 2 and f.shape[0] == P, path, f"array 'prior_factor' has shape {f.shape}, expected ({P}, r)")
    for key, shape in checks.items():
        arr = data[key]
        _expect(arr.shape == shape, path, f"array '{key}' has shape {arr.shape}, expected {shape}")
    for key in list(checks) + ["reference"] + [k for k in data if k.startswith(("pca_", "prior_", "input_"))]:
        arr = data[key]
        _expect(np.issubdtype(arr.dtype, np.floating) and bool(np.all(np.isfinite(arr))), path,
                f"array '{key}' is not finite floating point")
    ref = st.reference_
    _expect(ref.ndim == 2 and ref.shape[1] == st.n_observed_latent_ and ref.shape[0] >= 2, path,
            f"array 'reference' has shape {ref.shape}, expected (N>=2, {st.n_observed_latent_})")
    _expect(sorted(st.observed_dofs_ + st.controlled_dofs_) == list(range(st.n_dofs_)), path,
            "observed_dofs and controlled_dofs do not partition the columns")
    return vars(st)


def model_kind(path) -> str:
    """The model class a model file names (``metadata["model"]``; files of version 1 hold the Interaction
    Primitive), after the whole file has been checked as a container."""
    path = Path(path)
    meta, _ = _read_archive(path)
    kind = meta.get("model", "InteractionPrimitive")
    _expect(isinstance(kind, str), path, f"metadata 'model' must be a class name, got {kind!r}")
    return kind

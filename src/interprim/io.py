"""Safe model files: the container every model is saved in (what a model keeps is its own business:
:meth:`~interprim.models.base.Predictor.to_state`, and for the Interaction Primitive
:mod:`interprim.models.primitive.state_io`, whose arrays the versions below describe).

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
  controlled}`` of shape ``(F, H)`` (:class:`~interprim.models.primitive.calibration.Calibration`).  An older interprim
  refuses the file with "format_version 3 is not supported"; version 1 and 2 files still load (a version 2
  calibration, ``(F,)`` scales, acts at every look-ahead as it did).
* **2**: ``metadata`` also holds
  ``checksums``, ``{name: {"dtype", "shape", "sha256"}}`` for every other array
  (SHA-256 of the array's C-ordered bytes); ``selection`` (``selection_``,
  the hyper-parameter selection record of ``fit``, or ``null``); and the
  arrays ``prior_diag``/``prior_factor`` (the diagonal + low-rank form of the
  prior covariance), ``pca_*_explained_variance_ratio`` and ``calibration_{fractions,scale_observed,
  scale_controlled,n_cases}`` (:class:`~interprim.models.primitive.calibration.Calibration`) and
  ``input_mean``/``input_std`` (with ``input_limit`` in the metadata: the out-of-range check of the observed frames)
  when the model has them.
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
import json
import math
import os
import struct
import tokenize
import zipfile
import zlib
from pathlib import Path
from typing import Any

import numpy as np

from .core.errors import ModelFileError

FORMAT = "interprim-model"
FORMAT_VERSION = 3
READ_VERSIONS = (1, 2, 3)

__all__ = ["model_kind", "save_estimator", "load_estimator", "estimator_from_state", "read_archive", "write_archive",
           "checksum", "expect", "FORMAT", "FORMAT_VERSION", "READ_VERSIONS", "MAX_ARCHIVE_BYTES", "MAX_METADATA_BYTES"]

_ZIP_MAGIC = b"PK\x03\x04"
_NPY_MAGIC = b"\x93NUMPY"
# numeric, boolean and (for the legacy 'columns' array) unicode strings; never objects
_DTYPE_KINDS = "biufcU"
# exceptions that zipfile / zlib / the .npy header parser raise on damaged bytes
_READ_ERRORS = (zipfile.BadZipFile, zipfile.LargeZipFile, zlib.error, EOFError, OSError, ValueError, KeyError,
                IndexError, NotImplementedError, RuntimeError, struct.error, OverflowError, MemoryError,
                SyntaxError, TypeError, tokenize.TokenError)  # a .npy header is parsed as a Python literal


def checksum(arr: np.ndarray) -> dict[str, Any]:
    """``{"dtype", "shape", "sha256"}`` of an array (SHA-256 of its C-ordered bytes), as the metadata keeps it."""
    arr = np.asarray(arr)
    return {"dtype": arr.dtype.str, "shape": list(arr.shape),
            "sha256": hashlib.sha256(np.ascontiguousarray(arr).tobytes()).hexdigest()}


def save_estimator(model: Any, path: str | os.PathLike[str]) -> None:
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
            "checksums": {k: checksum(v) for k, v in arrays.items()}}
    write_archive(path, meta, arrays)


def load_estimator(path: str | os.PathLike[str], model_class: type[Any]) -> Any:
    """Read a model written by :func:`save_estimator` as a ``model_class`` (no pickle, every array checked)."""
    path = Path(path)
    meta, data = read_archive(path)
    name = model_class.__name__
    kind = meta.get("model", "InteractionPrimitive")
    expect(kind == name, path, f"holds a {kind} model, not a {name}")
    version = meta.get("model_version")
    expect(type(version) is int and 1 <= version <= model_class.STATE_VERSION, path,
            f"{name} model_version {version!r} is not supported by this interprim "
            f"(reads 1..{model_class.STATE_VERSION})")
    try:
        model = estimator_from_state(model_class, meta["params"], data, meta["state"], source=path)
    except ModelFileError:
        raise
    except (KeyError, TypeError, ValueError, IndexError) as exc:
        raise ModelFileError(f"{path}: corrupt {name} model file ({type(exc).__name__}: {exc})") from None
    return model


def estimator_from_state(model_class: Any, params: dict[str, Any], arrays: dict[str, np.ndarray],
                         state: dict[str, Any], source: str | os.PathLike[str] = "<state>") -> Any:
    """The fitted ``model_class`` of its parameters ``params`` and the ``(arrays, state)`` of its ``to_state``: the
    one way a model is rebuilt from its state (a model file, a blend's member).  A class with its own
    ``from_state`` (the Interaction Primitive, whose state carries its parameters) restores itself; any other is
    built from ``params`` and given the state (``load_state``), with the out-of-range statistics when the state has
    them."""
    if hasattr(model_class, "from_state"):
        return model_class.from_state(arrays, state, source=source)
    model = model_class(**params)
    model.load_state(arrays, state)
    if "input_range" in state and getattr(model, "input_range_", None) is None:
        model.set_input_range(state["input_range"])
    return model


def write_archive(path: Path, meta: dict[str, Any], arrays: dict[str, np.ndarray]) -> None:
    """Write ``arrays`` and the JSON ``meta`` as one model file at ``path`` (through a temporary file moved into
    place, so a failure never leaves a half-written model)."""
    arrays = dict(arrays)
    arrays["metadata"] = np.frombuffer(json.dumps(meta).encode("utf-8"), dtype=np.uint8)
    # write to a temporary file first so that a crash never leaves a half-written model behind
    tmp = path.with_name(path.name + ".tmp")
    try:
        with open(tmp, "wb") as fh:
            np.savez_compressed(fh, **arrays)  # type: ignore[arg-type]  # numpy's stub mixes in its own keywords
        tmp.replace(path)
    except BaseException:
        tmp.unlink(missing_ok=True)  # a failed save leaves neither the model nor its temporary file
        raise


def expect(cond: bool, path: str | os.PathLike[str], msg: str) -> None:
    """Raise :class:`~interprim.core.errors.ModelFileError` ``"{path}: {msg}"`` unless ``cond``."""
    if not cond:
        raise ModelFileError(f"{path}: {msg}")


MAX_ARCHIVE_BYTES = 1 << 30  # the sum of a model file's members once decompressed (1 GiB)
MAX_METADATA_BYTES = 16 << 20  # its metadata member (JSON) once decompressed
_NPY_HEADER_SLACK = 1 << 16  # bytes a .npy member may hold besides its data (magic + header)


def _read_member(zf: zipfile.ZipFile, info: zipfile.ZipInfo, path: Path, name: str, budget: int,
                 want: dict[str, Any] | None = None) -> np.ndarray:
    """One ``.npy`` member, read through a bounded reader: its header first (dtype and shape, no data), then
    exactly the data bytes it declares.  Refused before anything is decompressed when the member's declared
    (uncompressed) size is over ``budget`` or does not match ``want`` (``{"dtype", "shape"}`` from the
    metadata's checksums table); the reader never returns more than the declared size (zipfile stops there and
    checks the CRC-32), and the header must account for exactly that size."""
    declared = int(info.file_size)
    expect(declared <= budget, path,
            f"array '{name}' declares {declared} bytes uncompressed, over the limit of {budget} bytes for a model "
            f"file (compressed {int(info.compress_size)} bytes): refusing to decompress it")
    if isinstance(want, dict):
        try:
            n = math.prod(int(d) for d in want.get("shape", ())) * np.dtype(want.get("dtype")).itemsize
        except (TypeError, ValueError):
            n = None
        expect(n is not None and n <= declared <= n + _NPY_HEADER_SLACK, path,
                f"array '{name}' declares {declared} bytes uncompressed, but the metadata gives it shape "
                f"{want.get('shape')} and dtype {want.get('dtype')}: refusing to decompress it")
    from ._npz import read_npy_header  # the one .npy header guard (also of data files)

    with zf.open(info) as fh:
        shape, fortran, dtype = read_npy_header(fh)
        expect(not dtype.hasobject and dtype.fields is None and dtype.kind in _DTYPE_KINDS, path,
                f"not a readable interprim model file: array '{name}' has dtype {dtype}, "
                "but model files hold only numeric arrays")
        count = math.prod(shape)
        nbytes = count * dtype.itemsize
        offset = fh.tell()
        expect(offset + nbytes == declared, path,
                f"array '{name}' is truncated or corrupt ({declared - offset} bytes of data for shape {shape}, "
                f"{dtype})")
        raw = fh.read(nbytes)
        expect(len(raw) == nbytes, path, f"array '{name}' is truncated or corrupt ({len(raw)} bytes of data for "
                                          f"shape {shape}, {dtype})")
    arr = np.frombuffer(raw, dtype=dtype, count=count)
    out: np.ndarray = arr.reshape(shape, order="F" if fortran else "C").copy(order="K")
    return out


def read_archive(path: Path) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
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
            expect(total <= MAX_ARCHIVE_BYTES, path,
                    f"its arrays declare {total} bytes uncompressed, over the limit of {MAX_ARCHIVE_BYTES} bytes for "
                    "a model file: refusing to decompress them (a damaged file, or a zip bomb)")
            meta_arr = _read_member(zf, members["metadata"], path, "metadata", MAX_METADATA_BYTES)
            try:
                meta = json.loads(meta_arr.astype(np.uint8).tobytes().decode("utf-8"))
            except (ValueError, UnicodeDecodeError) as exc:
                raise ModelFileError(f"{path}: corrupt metadata: {exc}") from None
            expect(isinstance(meta, dict) and meta.get("format") == FORMAT, path,
                    "not an interprim model file (format is "
                    f"{meta.get('format') if isinstance(meta, dict) else None!r}, expected {FORMAT!r})")
            version = meta.get("format_version")
            expect(type(version) is int and version in READ_VERSIONS, path,
                    f"format_version {version!r} is not supported by this interprim (reads versions "
                    f"{', '.join(map(str, READ_VERSIONS))}); a newer interprim wrote it?")
            sums = meta.get("checksums") if version >= 2 else None
            if version >= 2:
                expect(isinstance(sums, dict), path, "corrupt metadata: no 'checksums' table")
                extra = sorted(set(members) - set(sums or ()) - {"metadata"})
                expect(not extra, path, f"array(s) {extra} are not listed in the metadata's checksums")
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
        expect(isinstance(sums, dict), path, "corrupt metadata: no 'checksums' table")
        missing = sorted(set(sums) - set(data))
        expect(not missing, path, f"array(s) {missing} listed in the metadata are missing")
        extra = sorted(set(data) - set(sums))
        expect(not extra, path, f"array(s) {extra} are not listed in the metadata's checksums")
        for name, arr in data.items():
            want = sums[name]
            expect(isinstance(want, dict) and checksum(arr) == want, path,
                    f"checksum of array '{name}' does not match: the file is corrupt")
    return meta, data


def model_kind(path: str | os.PathLike[str]) -> str:
    """The model class a model file names (``metadata["model"]``; files of version 1 hold the Interaction
    Primitive), after the whole file has been checked as a container."""
    path = Path(path)
    meta, _ = read_archive(path)
    kind = meta.get("model", "InteractionPrimitive")
    expect(isinstance(kind, str), path, f"metadata 'model' must be a class name, got {kind!r}")
    return str(kind)

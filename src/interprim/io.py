"""Safe model files.

Format (``format = "interprim-model"``, ``format_version = 1``): a NumPy
``.npz`` archive of plain numeric arrays plus one array ``metadata`` holding a
UTF-8 JSON document (hyper-parameters, column layout, scalars).  It is read
with ``allow_pickle=False``, so loading a model never executes code; every
array's shape is checked against the metadata, and a missing, truncated,
corrupt or unknown-version file raises :class:`~interprim.errors.ModelFileError`
naming the problem.

Arrays: ``prior_mean (P,)``, ``prior_cov (P, P)``, ``thetas (S, P)``,
``reference (N, D_o')``, ``start_position (D')``, ``start_velocity (D')``,
``durations (S,)`` and, with PCA, ``pca_{observed,controlled}_{mean,components}``;
``P = D' (n_basis + 1)`` and ``D'`` the number of (latent) DoFs, observed first.

Metadata: ``params`` (every constructor argument, so the file reproduces the
model's configuration, e.g. ``phase_method``), the column layout and names
(``observed_dofs``, ``controlled_dofs``, ``columns`` or ``null``), and the fitted
scalars (``dt``, ``sigma2``, ``phase_sigma2``, ``shrinkage``, ...).  Files of
older interprim versions without ``columns``/``phase_sigma2``/``input_noise``
load with those unset.
"""

from __future__ import annotations

import json
import zipfile
from pathlib import Path

import numpy as np

from .errors import ModelFileError
from .gaussian import GaussianPrior
from .preprocessing import PCA

FORMAT = "interprim-model"
FORMAT_VERSION = 1

__all__ = ["save_model", "load_model", "FORMAT", "FORMAT_VERSION"]


def save_model(model, path) -> None:
    """Write a fitted :class:`~interprim.InteractionPrimitive` to ``path`` (``.npz``)."""
    path = Path(path)
    meta = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "params": model.get_params(),
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
    arrays["metadata"] = np.frombuffer(json.dumps(meta).encode("utf-8"), dtype=np.uint8)
    # write to a temporary file first so that a crash never leaves a half-written model behind
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "wb") as fh:
        np.savez_compressed(fh, **arrays)
    tmp.replace(path)


def _expect(cond: bool, path, msg: str):
    if not cond:
        raise ModelFileError(f"{path}: {msg}")


def load_model(path, model_class):
    """Read a model written by :func:`save_model` (no pickle, every shape checked) as a ``model_class``."""
    path = Path(path)
    if not path.exists():
        raise ModelFileError(f"{path}: no such model file")
    try:
        with np.load(path, allow_pickle=False) as f:
            data = {k: f[k] for k in f.files}
    except (zipfile.BadZipFile, OSError, ValueError, EOFError, KeyError) as exc:
        raise ModelFileError(f"{path}: not a readable interprim model file (.npz): {exc}") from None
    _expect("metadata" in data, path, "missing 'metadata' entry; not an interprim model file")
    try:
        meta = json.loads(data["metadata"].astype(np.uint8).tobytes().decode("utf-8"))
    except (ValueError, UnicodeDecodeError) as exc:
        raise ModelFileError(f"{path}: corrupt metadata: {exc}") from None
    _expect(isinstance(meta, dict) and meta.get("format") == FORMAT, path,
            f"format is {meta.get('format') if isinstance(meta, dict) else None!r}, expected {FORMAT!r}")
    version = meta.get("format_version")
    _expect(version == FORMAT_VERSION, path,
            f"format_version {version!r} is not supported by this interprim (reads version {FORMAT_VERSION})")
    try:
        model = model_class(**meta["params"])
        model.observed_dofs_ = [int(i) for i in meta["observed_dofs"]]
        model.controlled_dofs_ = [int(i) for i in meta["controlled_dofs"]]
        model.n_dofs_ = int(meta["n_dofs"])
        model.n_observed_latent_ = int(meta["n_observed_latent"])
        model.n_latent_ = int(meta["n_latent"])
        model.beta_y_ = float(meta["beta_y"])
        model.dt_ = float(meta["dt"])
        model.mean_duration_ = float(meta["mean_duration"])
        model.sigma2_ = float(meta["sigma2"])
        ps2 = meta.get("phase_sigma2")  # noise of the likelihood phase estimator (absent in older files)
        model.phase_sigma2_ = None if ps2 is None else float(ps2)
        model.n_demos_ = int(meta["n_demos"])
        cols = meta.get("columns")  # column names (absent in older files; the CLI's legacy 'columns' array)
        if cols is None and "columns" in data:
            cols = [str(c) for c in data["columns"]]
        _expect(cols is None or (isinstance(cols, list) and len(cols) == model.n_dofs_), path,
                f"columns {cols!r} do not name the model's {model.n_dofs_} columns")
        model.columns_ = None if cols is None else [str(c) for c in cols]
        model.prior_ = GaussianPrior(data["prior_mean"], data["prior_cov"], str(meta["covariance_method"]),
                                     float(meta["shrinkage"]))
        model.thetas_ = data["thetas"]
        model.reference_ = data["reference"]
        model.start_position_ = data["start_position"]
        model.start_velocity_ = data["start_velocity"]
        model.durations_ = data["durations"]
        for agent in ("observed", "controlled"):
            pca = None
            if f"pca_{agent}_mean" in data:
                comps = data[f"pca_{agent}_components"]
                pca = PCA(comps.shape[0])
                pca.mean_ = data[f"pca_{agent}_mean"]
                pca.components_ = comps
            setattr(model, f"pca_{agent}_", pca)
    except (KeyError, TypeError, ValueError) as exc:
        raise ModelFileError(f"{path}: incomplete or inconsistent model file: {exc!r}") from None

    q = model.n_basis + 1
    P = model.n_latent_ * q
    checks = {
        "prior_mean": (P,), "prior_cov": (P, P), "thetas": (model.n_demos_, P),
        "start_position": (model.n_latent_,), "start_velocity": (model.n_latent_,), "durations": (model.n_demos_,),
    }
    for key, shape in checks.items():
        arr = data[key]
        _expect(arr.shape == shape, path, f"array '{key}' has shape {arr.shape}, expected {shape}")
        _expect(np.issubdtype(arr.dtype, np.floating) and bool(np.all(np.isfinite(arr))), path,
                f"array '{key}' is not finite floating point")
    ref = model.reference_
    _expect(ref.ndim == 2 and ref.shape[1] == model.n_observed_latent_ and ref.shape[0] >= 2, path,
            f"array 'reference' has shape {ref.shape}, expected (N>=2, {model.n_observed_latent_})")
    _expect(bool(np.all(np.isfinite(ref))), path, "array 'reference' is not finite")
    _expect(sorted(model.observed_dofs_ + model.controlled_dofs_) == list(range(model.n_dofs_)), path,
            "observed_dofs and controlled_dofs do not partition the columns")
    model._setup()
    return model

"""The Interaction Primitive's model files: its fitted state to and from the safe container of :mod:`interprim.io`.

The container (checksummed ``.npy`` members and a JSON ``metadata`` member in a zip, read with bounded reads) is
:mod:`interprim.io`'s; this module knows what an Interaction Primitive keeps (the parameters, the fitted state of
:class:`~interprim.models.primitive.fitted.FittedPrimitive`), checks every array of it when a file is read, and
reads the files of older format versions (1-3) and the option values of older releases.
"""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np

from ...core import state_checks as check
from ...core.errors import ModelFileError
from ...core.gaussian import GaussianPrior
from ...core.preprocessing import PCA
from ...core.state_checks import building
from ...io import FORMAT, FORMAT_VERSION, checksum, expect, read_archive, write_archive

__all__ = ["save_model", "model_state", "load_model", "model_from_state", "fitted_from_state"]


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
    meta["checksums"] = {k: checksum(v) for k, v in arrays.items()}
    write_archive(path, meta, arrays)


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


def load_model(path, model_class):
    """Read a model written by :func:`save_model` (format version 1, 2 or 3; no pickle, every array checked) as a
    ``model_class`` (:class:`~interprim.models.primitive.estimator.InteractionPrimitive`)."""
    path = Path(path)
    meta, data = read_archive(path)
    kind = meta.get("model", "InteractionPrimitive")
    expect(kind == "InteractionPrimitive", path, f"holds a {kind} model, not an InteractionPrimitive")
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
    with building(path):
        n_dofs = check.integer("n_dofs", meta.get("n_dofs"), 1, check.MAX_GRID)
        n_demos = check.integer("n_demos", meta.get("n_demos"), 1, check.MAX_GRID)
    try:  # the parameters as fit checks them (n_steps and the rollout's size, phase_method, alpha_y, ...)
        model.check_params(n_dofs, n_demos)
    except (TypeError, ValueError) as exc:
        raise ModelFileError(f"{path}: inconsistent parameters in field 'params': {exc}") from None
    fitted = fitted_from_state(data, meta, params, path)
    try:
        with building(path):  # the derived state (basis, rollout) built from the file's values
            model.load_fitted(fitted)
    except (TypeError, OverflowError) as exc:
        raise ModelFileError(f"{path}: inconsistent model parameters: {exc}") from None
    return model


def fitted_from_state(data: dict, meta: dict, params: dict, path="<state>") -> dict:
    """The fitted attributes (names ending in ``_``) of ``(data, meta)``, a model file's arrays and metadata
    (format versions 1-3), every array checked, for a model with the parameters ``params`` (complete, as
    :meth:`~interprim.models.primitive.estimator.InteractionPrimitive.json_params` gives them); problems raise
    :class:`~interprim.core.errors.ModelFileError` naming ``path``
    (:meth:`~interprim.models.primitive.fitted.FittedPrimitive.from_state` builds the state from them)."""
    with building(path):
        fitted = _fitted_from_state(data, meta, params, path)
        _check_values(fitted, params)
    return fitted


def _check_values(st: dict, params: dict) -> None:
    """The fitted scalars and the prior of a model file, checked before a prediction divides by them or factors
    the covariance: ModelFileError naming the field (:mod:`interprim.core.state_checks`)."""
    for field, name in (("beta_y", "beta_y_"), ("dt", "dt_"), ("mean_duration", "mean_duration_"),
                        ("sigma2", "sigma2_")):
        st[name] = check.number(field, st[name], positive=True)
    if st["phase_sigma2_"] is not None:
        st["phase_sigma2_"] = check.number("phase_sigma2", st["phase_sigma2_"], positive=True)
    check.integer("n_observed_latent", st["n_observed_latent_"], 1, st["n_latent_"])
    check.array("durations", st["durations_"], positive=True)
    prior = st["prior_"]
    cov = np.asarray(prior.cov)
    scale = float(np.max(np.abs(cov))) if cov.size else 0.0
    if cov.size and not np.allclose(cov, cov.T, rtol=1e-8, atol=1e-12 * scale):
        raise ModelFileError("array 'prior_cov' is not symmetric")
    d = np.diag(cov)
    if np.any(d < 0):
        j = int(np.argmin(d))
        raise ModelFileError(f"array 'prior_cov' is not a covariance: prior_cov[{j}, {j}] = {float(d[j])!r} < 0")
    factored = prior.diag is not None and prior.factor is not None
    if factored:  # diag(prior_diag) + prior_factor prior_factor^T: the same covariance, semi-definite by its form
        check.array("prior_diag", prior.diag, nonneg=True)
        f = np.asarray(prior.factor)
        gap = cov - f @ f.T
        gap[np.diag_indices_from(gap)] -= np.asarray(prior.diag)
        if cov.size and float(np.max(np.abs(gap))) > 1e-6 * max(scale, 1e-300):
            raise ModelFileError("arrays 'prior_diag'/'prior_factor' and 'prior_cov' are not the same covariance")
    elif cov.size and not _semidefinite(cov):
        raise ModelFileError("array 'prior_cov' is not a covariance: it is not positive semi-definite")


def _semidefinite(cov: np.ndarray) -> bool:
    """Whether the symmetric ``cov`` is positive semi-definite up to rounding (a Cholesky factor of it with a
    relative jitter of 1e-9, else its smallest eigenvalue against its largest)."""
    jitter = 1e-9 * max(float(np.mean(np.abs(np.diag(cov)))), 1e-300)
    try:
        np.linalg.cholesky(cov + jitter * np.eye(cov.shape[0]))
        return True
    except np.linalg.LinAlgError:
        ev = np.linalg.eigvalsh(cov)
        return bool(ev[0] >= -1e-8 * max(abs(float(ev[-1])), 1e-300))


def _fitted_from_state(data: dict, meta: dict, params: dict, path="<state>") -> dict:
    """:func:`fitted_from_state` without the checks of the values (:func:`_check_values`)."""
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
        expect(cols is None or (isinstance(cols, list) and len(cols) == st.n_dofs_), path,
                f"columns {cols!r} do not name the model's {st.n_dofs_} columns")
        st.columns_ = None if cols is None else [str(c) for c in cols]
        sel = meta.get("selection")  # hyper-parameter selection record (version 2; absent when fit made none)
        expect(sel is None or isinstance(sel, dict), path, "corrupt metadata: 'selection' is not a record")
        if sel is not None:
            st.selection_ = sel
        rep = meta.get("representation")  # how well the DMPs represent the demonstrations (newer files)
        expect(rep is None or isinstance(rep, dict), path, "corrupt metadata: 'representation' is not a record")
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
            expect(st.input_mean_.shape == (n_o,) and st.input_std_.shape == (n_o,)
                    and bool(np.all(st.input_std_ > 0)) and st.input_limit_ > 0, path,
                    f"arrays 'input_mean'/'input_std' are not ({n_o},) statistics with a positive spread")
        st.phase_model_ = None
        if meta.get("phase_model") is not None:
            from ...phase.learned import LearnedPhase

            st.phase_model_ = LearnedPhase.from_state(
                {k[len("phase_model_"):]: v for k, v in data.items() if k.startswith("phase_model_")},
                meta["phase_model"])
        used = meta.get("phase_method_used")  # absent in files older than phase_method="cv": as set there
        st.phase_method_ = str(used if used is not None else
                               (phase_method if phase_method != "cv" else "likelihood"))
        expect(st.phase_method_ in ("dtw", "likelihood", "learned"), path,
                f"unknown phase method {st.phase_method_!r} in the metadata")
        used = st.phase_method_ if phase_method == "cv" else phase_method
        expect(used != "learned" or st.phase_model_ is not None, path,
                "the phase method is 'learned' but the file holds no phase model")
        st.calibration_ = None
        if any(k.startswith("calibration_") for k in data):
            from .calibration import Calibration

            try:
                st.calibration_ = Calibration.from_arrays({k[len("calibration_"):]: v for k, v in data.items()
                                                           if k.startswith("calibration_")})
            except (KeyError, TypeError, ValueError) as exc:
                raise ModelFileError(f"{path}: arrays 'calibration_*' are not a calibration: "
                                     f"{type(exc).__name__}: {exc}") from None
            bad = st.calibration_.problem(len(st.observed_dofs_) + len(st.controlled_dofs_))
            expect(bad is None, path, f"arrays 'calibration_*' are not a calibration: {bad}")
        for agent in ("observed", "controlled"):
            pca = None
            if f"pca_{agent}_mean" in data:
                comps = data[f"pca_{agent}_components"]
                expect(comps.ndim == 2, path, f"array 'pca_{agent}_components' has shape {comps.shape}")
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
        expect("prior_diag" in data and "prior_factor" in data, path,
                "the prior's diagonal + low-rank form needs both 'prior_diag' and 'prior_factor'")
        checks["prior_diag"] = (P,)
        f = data["prior_factor"]
        expect(f.ndim == 2 and f.shape[0] == P, path, f"array 'prior_factor' has shape {f.shape}, expected ({P}, r)")
    for key, shape in checks.items():
        arr = data[key]
        expect(arr.shape == shape, path, f"array '{key}' has shape {arr.shape}, expected {shape}")
    for key in list(checks) + ["reference"] + [k for k in data if k.startswith(("pca_", "prior_", "input_"))]:
        arr = data[key]
        expect(np.issubdtype(arr.dtype, np.floating) and bool(np.all(np.isfinite(arr))), path,
                f"array '{key}' is not finite floating point")
    ref = st.reference_
    expect(ref.ndim == 2 and ref.shape[1] == st.n_observed_latent_ and ref.shape[0] >= 2, path,
            f"array 'reference' has shape {ref.shape}, expected (N>=2, {st.n_observed_latent_})")
    expect(sorted(st.observed_dofs_ + st.controlled_dofs_) == list(range(st.n_dofs_)), path,
            "observed_dofs and controlled_dofs do not partition the columns")
    return vars(st)

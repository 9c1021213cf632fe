"""Loading the models a server serves (saved model files, or demo models fitted at start-up)."""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..core.errors import ModelFileError

_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.\-]{0,63}$")


@dataclass
class ModelEntry:
    """One served model and the metadata sent to clients in ``welcome``."""

    name: str
    model: Any
    kind: str = "interaction"  # "interaction" (two agents) or "single" (e.g. handwriting)
    source: str = ""
    meta: dict = field(default_factory=dict)  # JSON-able extras: extent, geometry, replay data ...

    @property
    def observed_dofs(self) -> list[int]:
        """Data columns of the observed agent (the frames clients send), in the model's order."""
        return [int(i) for i in self.model.observed_dofs_]

    @property
    def controlled_dofs(self) -> list[int]:
        """Data columns of the controlled agent (empty for a single-agent model)."""
        return [int(i) for i in self.model.controlled_dofs_]

    @property
    def n_observed(self) -> int:
        """Number of values in one frame."""
        return len(self.model.observed_dofs_)

    @property
    def n_dofs(self) -> int:
        """Number of data columns of the model (both agents)."""
        return int(self.model.n_dofs_)

    @property
    def names(self) -> list[str]:
        """Names of the model's data columns (all ``n_dofs``): the served metadata's, the model file's, or
        ``dof_0``, ``dof_1``, ... (the default of :func:`interprim.datasets.save_demonstrations`)."""
        names = self.meta.get("columns") or getattr(self.model, "columns_", None)
        if names is None or len(names) != self.n_dofs:
            return [f"dof_{i}" for i in range(self.n_dofs)]
        return [str(c) for c in names]

    @property
    def units(self) -> list:
        """Unit of each data column (a string), or ``None`` where unknown (model files store no units;
        ``meta["units"]``: a list of ``n_dofs`` entries or a dict name -> unit)."""
        units = self.meta.get("units")
        if isinstance(units, dict):
            return [None if units.get(n) is None else str(units[n]) for n in self.names]
        if isinstance(units, (list, tuple)) and len(units) == self.n_dofs:
            return [None if u is None else str(u) for u in units]
        return [None] * self.n_dofs

    @property
    def min_frames(self) -> int:
        """Frames of an interaction before predictions are conditioned on them (``min_observed``)."""
        return int(getattr(self.model, "min_observed", 1))

    def start(self) -> list | None:
        """Mean start position of the demonstrations in every data column, or ``None`` if unknown."""
        try:
            st = self.model.fitted_  # an Interaction Primitive's fitted state (interprim.models.primitive.fitted)
            M, off = st.latent_map()
            return [float(v) for v in M @ np.asarray(st.start_position_, dtype=np.float64) + off]
        except Exception:  # a stand-in model without these attributes
            return None

    def describe(self) -> dict:
        """The model's entry in ``welcome`` and ``/api/info``: name, kind, columns, ``dt``, mean duration
        and the JSON-able extras (``title``, ``extent``, ``columns``, ``world``) of ``meta``."""
        out = {
            "name": self.name,
            "kind": self.kind,
            "n_dofs": self.n_dofs,
            "observed_dofs": self.observed_dofs,
            "controlled_dofs": self.controlled_dofs,
            "dt": float(self.model.dt_),
            "mean_duration": float(self.model.mean_duration_),
            "alpha_x": float(getattr(self.model, "alpha_x", 3.0)),
            "names": self.names,
            "units": self.units,
            "min_frames": self.min_frames,
            "start": self.start(),
            "replay": "replay" in self.meta,
        }
        out.update({k: v for k, v in self.meta.items() if k in ("title", "extent", "columns", "world")})
        return out


def check_name(name: str, source: str) -> str:
    if not _NAME.match(name) or name in ("recognise", "auto"):
        raise ModelFileError(
            f"model name {name!r} (from {source}) must be 1-64 characters of letters, digits, '_', '.', '-' "
            "and not 'recognise' (the request to recognise among models) or 'auto'; rename the file"
        )
    return name


def entry_for(name: str, model, *, source: str = "", kind: str | None = None, meta: dict | None = None) -> ModelEntry:
    """Wrap a fitted model; ``kind`` defaults to ``single`` when it has no controlled DoFs."""
    check_name(name, source or "code")
    try:
        n_ctrl = len(model.controlled_dofs_)
        _ = model.observed_dofs_, model.n_dofs_, model.dt_, model.mean_duration_
    except AttributeError as exc:
        raise ModelFileError(f"model {name!r} ({source or 'code'}) is not a fitted interprim model: {exc}") from None
    if kind is None:
        kind = "single" if n_ctrl == 0 else "interaction"
    return ModelEntry(name=name, model=model, kind=kind, source=source, meta=dict(meta or {}))


def load_models(paths) -> dict[str, ModelEntry]:
    """Load saved model files; the name of each is its file stem.

    Raises
    ------
    FileNotFoundError
        A path does not exist.
    interprim.ModelFileError
        A file is corrupt / of the wrong format, or two files share a stem.
    """
    from ..models.files import load_any

    out: dict[str, ModelEntry] = {}
    for p in paths:
        path = Path(p)
        if not path.exists():
            raise FileNotFoundError(f"model file {str(path)!r} does not exist")
        if path.is_dir():
            raise ModelFileError(f"model file {str(path)!r} is a directory, expected a saved model (.npz)")
        name = check_name(path.stem, str(path))
        if name in out:
            raise ModelFileError(
                f"two model files are both named {name!r} ({out[name].source} and {path}); model names are "
                "file stems and must be unique"
            )
        try:
            model = load_any(str(path))  # whatever 'interprim fit' saved
        except ModelFileError as exc:
            msg = str(exc)
            if str(path) not in msg:
                msg = f"{path}: {msg}"
            raise ModelFileError(f"cannot serve model {name!r}: {msg}") from None
        except (OSError, ValueError, KeyError, EOFError) as exc:  # a core that lets a raw error through
            raise ModelFileError(f"cannot serve model {name!r}: {path} is not a readable model file: {exc}") from None
        out[name] = entry_for(name, model, source=str(path))
    return out


def replay_json(model, demos, *, names=None, units=None, source: str = "", max_interactions: int | None = None) -> dict:
    """The JSON of ``GET /api/replay/MODEL``: demonstrations to stream to the model (the page's *Replay*).

    Parameters
    ----------
    model : fitted InteractionPrimitive
    demos : list of ndarray, shape (T_i, n_dofs)
        Whole interactions in the model's data columns, sampled at the model's ``dt_``.
    names, units : list, optional
        Column names / units (default: the model's names, units unknown).
    source : str
        Where they come from (shown by the page), e.g. ``"training demonstrations (demos.csv)"``.
    max_interactions : int, optional
        At most this many are kept (the first ones); default all (the page lists every one).

    Returns
    -------
    dict
        ``dt`` (s), ``columns`` (names of all data columns), ``units``, ``observed_dofs``,
        ``controlled_dofs``, ``source`` and ``interactions``: per interaction ``observed``
        (``T x len(observed_dofs)``, the frames to send, in frame order), ``controlled_truth``
        (``T x len(controlled_dofs)``, what the controlled agent did; absent for single-agent models)
        and ``duration`` (s).
    """
    obs = [int(i) for i in model.observed_dofs_]
    ctrl = [int(i) for i in model.controlled_dofs_]
    D = int(model.n_dofs_)
    dt = float(model.dt_)
    if names is None:
        names = getattr(model, "columns_", None) or [f"dof_{i}" for i in range(D)]
    out = []
    demos = list(demos) if max_interactions is None else list(demos)[: int(max_interactions)]
    for i, d in enumerate(demos):
        d = np.asarray(d, dtype=np.float64)
        if d.ndim != 2 or d.shape[1] != D or d.shape[0] < 2 or not np.all(np.isfinite(d)):
            raise ValueError(f"replay interaction {i}: expected a finite (T >= 2, {D}) array, got shape {d.shape}")
        it = {"observed": np.round(d[:, obs], 6).tolist(), "duration": (d.shape[0] - 1) * dt}
        if ctrl:
            it["controlled_truth"] = np.round(d[:, ctrl], 6).tolist()
        out.append(it)
    return {"dt": dt, "columns": [str(n) for n in names], "units": list(units) if units is not None else [None] * D,
            "observed_dofs": obs, "controlled_dofs": ctrl, "source": source, "interactions": out}


def load_replay(entry: ModelEntry, path, **options) -> dict:
    """Read demonstrations for ``entry`` from a data file (as ``interprim fit`` reads them) into :func:`replay_json`.

    Columns are matched by name when the model knows its column names, else by position; frames are
    resampled to the model's ``dt`` (unless already on it up to rounding).  ``options`` are the recording
    keywords of :func:`interprim.datasets.load_demonstrations` (``length_unit``, ``topics``, ``joints``,
    ``markers``, splitting, ``max_nan_gap``), as ``interprim fit`` takes them.

    Raises
    ------
    interprim.DataFileError
        The file cannot be read or lacks one of the model's columns.
    ValueError
        The file has a different number of columns than a model without column names.
    """
    from ..datasets import load_demonstrations

    model = entry.model
    named = getattr(model, "columns_", None)
    dt = float(model.dt_)
    ds = load_demonstrations(path, columns=list(named) if named else None, dt=dt, resample_dt=dt, **options)
    if ds.n_dofs != entry.n_dofs:
        raise ValueError(f"{path} has {ds.n_dofs} columns; model {entry.name!r} has {entry.n_dofs}")
    return replay_json(model, ds.demos, names=entry.names, units=entry.units,
                       source=f"demonstrations from {Path(path).name}")

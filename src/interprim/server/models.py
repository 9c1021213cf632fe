"""Loading the models a server serves (saved model files, or demo models fitted at start-up)."""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..errors import ModelFileError

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
        }
        out.update({k: v for k, v in self.meta.items() if k in ("title", "extent", "columns", "world")})
        return out


def check_name(name: str, source: str) -> str:
    if not _NAME.match(name) or name == "auto":
        raise ModelFileError(
            f"model name {name!r} (from {source}) must be 1-64 characters of letters, digits, '_', '.', '-' "
            "and not 'auto'; rename the file"
        )
    return name


def entry_for(name: str, model, *, source: str = "", kind: str | None = None, meta: dict | None = None) -> ModelEntry:
    """Wrap a fitted model; ``kind`` defaults to ``single`` when it has no controlled DoFs."""
    check_name(name, source or "code")
    try:
        n_ctrl = len(model.controlled_dofs_)
        _ = model.observed_dofs_, model.n_dofs_, model.dt_, model.mean_duration_
    except AttributeError as exc:
        raise ModelFileError(f"model {name!r} ({source or 'code'}) is not a fitted InteractionPrimitive: {exc}") from None
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
    from ..primitive import InteractionPrimitive

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
            model = InteractionPrimitive.load(str(path))
        except ModelFileError as exc:
            msg = str(exc)
            if str(path) not in msg:
                msg = f"{path}: {msg}"
            raise ModelFileError(f"cannot serve model {name!r}: {msg}") from None
        except (OSError, ValueError, KeyError, EOFError) as exc:  # a core that lets a raw error through
            raise ModelFileError(f"cannot serve model {name!r}: {path} is not a readable model file: {exc}") from None
        out[name] = entry_for(name, model, source=str(path))
    return out

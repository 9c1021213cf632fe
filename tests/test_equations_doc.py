"""docs/equations.md names only functions that exist, and Eq. 9 has one convention (issue 20)."""

from __future__ import annotations

import importlib
import math
import pkgutil
import re
from pathlib import Path

import numpy as np
import pytest

import interprim

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "equations.md"
SKIP_PREFIXES = ("np.", "model.", "pred.", "self.")


def _modules():
    mods = []
    for info in pkgutil.walk_packages(interprim.__path__, "interprim."):
        if info.name.endswith("__main__") or any(part in info.name for part in (".server", ".experiments", ".sim",
                                                                                 ".cli")):
            continue
        try:
            mods.append(importlib.import_module(info.name))
        except ImportError:  # an optional extra that is not installed
            continue
    return mods


def _resolve(name: str, modules) -> bool:
    parts = name.split(".")
    for k in range(len(parts), 0, -1):  # the longest importable module prefix, then attributes
        try:
            obj = importlib.import_module("interprim." + ".".join(parts[:k]))
        except ImportError:
            continue
        try:
            for p in parts[k:]:
                obj = getattr(obj, p)
            return True
        except AttributeError:
            return False
    for mod in modules:  # Class.attribute: the class from any module of the package
        obj = getattr(mod, parts[0], None)
        if isinstance(obj, type):
            try:
                for p in parts[1:]:
                    obj = getattr(obj, p)
                return True
            except AttributeError:
                if len(parts) == 2 and _sets_attribute(getattr(mod, parts[0]), parts[1]):
                    return True  # an instance attribute the class sets (fitted attributes, Prediction.x)
    return False


def _sets_attribute(cls, attr: str) -> bool:
    import inspect

    src = "".join(inspect.getsource(k) for k in cls.__mro__ if k.__module__.startswith("interprim"))
    return re.search(rf"self\.{re.escape(attr)}\s*=", src) is not None


def test_every_name_in_equations_md_exists():
    text = DOC.read_text(encoding="utf-8")
    names = set(re.findall(r"`([A-Za-z_][\w]*(?:\.[A-Za-z_][\w]*)+)`", text))
    modules = _modules()
    missing = []
    for n in sorted(names):
        if n.startswith(SKIP_PREFIXES):
            continue
        if n.endswith(".py"):
            if not (ROOT / n).exists() and not (ROOT / "src" / "interprim" / n).exists():
                missing.append(n)
            continue
        if not _resolve(n, modules):
            missing.append(n)
    assert len(names) > 40  # the table was read
    assert not missing, f"docs/equations.md names what does not exist: {missing}"


def test_test_files_named_in_equations_md_exist():
    text = DOC.read_text(encoding="utf-8")
    files = set(re.findall(r"`(tests/[\w/]+\.py)`", text))
    assert files and all((ROOT / f).exists() for f in files), sorted(f for f in files if not (ROOT / f).exists())


def test_eq9_one_convention(fitted_paper, synthetic):
    """Eq. 9 in the code: the fraction seen is ``s = n*/(N-1)`` with the 0-based reference index ``n*`` (frame 0
    at s = 0, frame N-1 at s = 1, the DMP's normalised time), and ``x = canonical_phase(s)``.  The paper's
    ``n*/N`` with a 1-based ``n*`` (:func:`~interprim.phase.dtw.phase_from_index`) maps the same frames to
    ``(n*+1)/N``, at most ``1/N`` away (docs/equations.md)."""
    from interprim.core.basis import canonical_phase
    from interprim.phase.dtw import phase_from_index

    fitted = fitted_paper  # the paper's configuration: the DTW phase, an integer n*
    _, test = synthetic
    N = fitted.reference_.shape[0]
    for M in (40, 90, 150):
        pred = fitted.predict(test[0][:M, :2])
        s = pred.n_star / (N - 1)
        assert pred.normalised_time == pytest.approx(s, abs=1e-12)
        assert pred.x == pytest.approx(float(canonical_phase(pred.phase, fitted.alpha_x)), rel=1e-14)
        paper = phase_from_index(pred.n_star, N, fitted.alpha_x)
        assert abs(-math.log(paper) / fitted.alpha_x - s) <= 1.0 / N + 1e-12
    assert phase_from_index(N - 1, N, 3.0) == pytest.approx(math.exp(-3.0))  # both end at s = 1
    assert float(canonical_phase(np.array([0.0]), 3.0)[0]) == 1.0

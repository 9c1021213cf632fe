"""The documentation site builds with ``mkdocs build --strict`` (no warning: no broken link, no docstring
that griffe cannot parse) and its reference pages hold the rendered API and equations."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


pytestmark = pytest.mark.slow  # builds the documentation site (mkdocs) once for the module


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    out = tmp_path_factory.mktemp("site")
    env = dict(os.environ, NO_MKDOCS_2_WARNING="1")
    proc = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "-d", str(out)], cwd=ROOT,
                          env=env, capture_output=True, text=True, timeout=900)
    log = proc.stdout + proc.stderr
    assert proc.returncode == 0, f"mkdocs build --strict failed:\n{log[-6000:]}"
    warnings = [line for line in log.splitlines() if line.startswith(("WARNING", "ERROR"))]
    assert not warnings, "\n".join(warnings)
    return out


def _page(site, path):
    f = site / path / "index.html"
    assert f.is_file(), f"{path} was not built"
    return f.read_text(encoding="utf-8")


@pytest.mark.parametrize("page, symbols", [
    ("reference/dmp", ["interprim.core.basis.Basis", "interprim.core.dmp.fit_weights",
                       "interprim.core.dmp.LinearRollout"]),
    ("reference/phase", ["interprim.phase.estimate_phase", "interprim.phase.dtw.open_end_dtw",
                         "interprim.phase.dtw.IncrementalDTW.update", "interprim.phase.learned.LearnedPhase"]),
    ("reference/distribution", ["interprim.models.primitive.estimator.InteractionPrimitive",
                                "interprim.models.primitive.estimator.InteractionPrimitive.fit",
                                "interprim.models.primitive.estimator.InteractionPrimitive.predict",
                                "interprim.core.gaussian.fit_prior"]),
    ("reference/conditioning", ["interprim.core.gaussian.condition", "interprim.core.gaussian.condition_literal",
                                "interprim.models.primitive.prediction.Prediction.trajectory",
                                "interprim.models.primitive.stream.Stream.update"]),
    ("reference/client", ["interprim.server.client.Client.reset", "interprim.server.client.AsyncClient.frame"]),
    ("reference/server", ["interprim.server.app.InterprimServer.start", "interprim.server.app.ServerThread.stop"]),
    ("reference/errors", ["interprim.core.errors.ModelFileError", "interprim.core.errors.OutOfRangeWarning"]),
    ("reference/auto", ["interprim.models.auto.AutoInteraction", "interprim.models.blend.Blend",
                        "interprim.model_selection.stacking.CrossValidation",
                        "interprim.model_selection.realtime.realtime_fold"]),
    ("reference/contract", ["interprim.models.base.Predictor", "interprim.models.registry.Family",
                            "interprim.models.demonstrations.PriorMean.fit", "interprim.testing.check_predictor"]),
    ("reference/cv", ["interprim.core.cv.folds", "interprim.core.cv.within_one_se",
                      "interprim.core.cv.observed_frames"]),
    ("reference/evaluation", ["interprim.evaluation.sweep.run_sweep"]),
])
def test_reference_pages_render_the_api(site, page, symbols):
    html = _page(site, page)
    for sym in symbols:
        # a heading with the symbol's anchor, followed by its rendered docstring
        m = re.search(rf'id="{re.escape(sym)}"', html)
        assert m, f"{sym} is not rendered on {page}"
        # its contents come before the next symbol's heading (a typed signature can run to many kilobytes of markup)
        own = html.find('class="doc doc-heading"', m.end())  # the symbol's own heading (its anchor opens it)
        nxt = html.find('class="doc doc-heading"', own + 1) if own >= 0 else -1
        entry = html[m.end():nxt if nxt >= 0 else len(html)]
        assert 'class="doc doc-contents' in entry, f"{sym} has no rendered contents"


def test_predict_entry_has_signature_and_parameters(site):
    html = _page(site, "reference/distribution")
    start = html.index('id="interprim.models.primitive.estimator.InteractionPrimitive.predict"')
    entry = re.sub(r"<[^>]+>", " ", html[start:start + 20000])
    for text in ("partial", "robot_state", "Predict the interaction from a partial observation"):
        assert text in entry


@pytest.mark.parametrize("page, equations", [
    ("reference/dmp", range(1, 5)), ("reference/phase", range(5, 10)),
    ("reference/distribution", range(10, 15)), ("reference/conditioning", range(15, 19)),
])
def test_paper_pages_carry_their_equations_for_mathjax(site, page, equations):
    html = _page(site, page)
    blocks = re.findall(r'<div class="arithmatex">(.*?)</div>', html, flags=re.S)
    tagged = " ".join(blocks)
    for k in equations:
        assert f"(Eq. {k})" in tagged, f"Eq. {k} is not a rendered equation on {page}"
    assert "mathjax" in html.lower()


def test_generated_pages_and_links(site):
    home = _page(site, "")
    text = re.sub(r"\s+", " ", re.sub(r"<[^>]+>", "", home))
    assert "The two commands" in text and "bash scripts/test.sh" in text
    assert 'href="equations/"' in home  # README's docs/equations.md, rewritten for the site
    assert "Keep a Changelog" in _page(site, "changelog") or "Unreleased" in _page(site, "changelog")
    assert "MIT License" in _page(site, "license")
    assert "scripts/lint.sh" in _page(site, "contributing")  # CONTRIBUTING.md, its link to the architecture page
    assert 'href="../architecture/"' in _page(site, "contributing")
    assert (site / "protocol.schema.json").is_file()
    cli = _page(site, "reference/cli")
    assert "interprim evaluate" in cli and "--scheduler" in cli
    # nothing is loaded from font services: the site needs no network but the MathJax script
    assert "fonts.googleapis" not in home

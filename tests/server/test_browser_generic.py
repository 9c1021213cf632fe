"""The live page's generic view ("Any model") in a real headless Chromium, for a model that is not a demo model.

The model is made the way a user makes one: synthetic two-agent data (:mod:`interprim.synthetic`) written to a
CSV by :func:`interprim.datasets.save_demonstrations` with the user's column names, fitted with ``interprim fit``,
served from the ``.npz`` file with its training CSV as replay data (what ``interprim serve --replay`` loads) and
units.  The page must label the plots from the ``opened`` reply, draw the predicted series with their band, show
the phase and the out-of-range flag, and flag a 1000x scaled input.  Waits are on page state; the drag runs on
the page's virtual clock (``window.ipClock``).

Skipped only when Chromium (or its driver) is not installed: ``apt-get install -y chromium chromium-driver``.
"""

from __future__ import annotations

import pytest
from test_browser import CHROMIUM, DRIVER, driver, wait_for  # noqa: F401  (the driver fixture)

pytestmark = [
    pytest.mark.skipif(CHROMIUM is None or DRIVER is None,
                       reason="needs Chromium and its driver: apt-get install -y chromium chromium-driver"),
    pytest.mark.filterwarnings("ignore:the observed frames are"),  # the server's warning about the x1000 input
    pytest.mark.slow,  # a browser driving the live page
]

NAMES = ["hand_x", "hand_y", "arm_a", "arm_b", "arm_c"]
UNITS = ["m", "m", "rad", "rad", "rad"]


@pytest.fixture(scope="module")
def user_server(tmp_path_factory):
    import numpy as np

    from interprim.cli import main as cli
    from interprim.datasets import save_demonstrations
    from interprim.server.app import InterprimServer, ServerConfig, ServerThread
    from interprim.server.models import load_models, load_replay
    from interprim.synthetic import two_agent_demos

    d = tmp_path_factory.mktemp("user-model")
    save_demonstrations(d / "synth.csv", two_agent_demos(16, seed=3, frames=120), dt=0.01, columns=NAMES)
    assert cli(["fit", "--model", "ip", str(d / "synth.csv"), "--observed", "hand_x,hand_y", "--n-basis", "8",
                "-o", str(d / "synth.npz")]) == 0
    # a second user model, listed first, so that the test has to select "synth"
    rng = np.random.default_rng(0)
    one = [np.sin(np.linspace(0, 3, 80))[:, None] * rng.uniform(0.8, 1.2) for _ in range(6)]
    save_demonstrations(d / "a_wave.csv", one, dt=0.01, columns=["angle"])
    assert cli(["fit", "--model", "ip", str(d / "a_wave.csv"), "--observed", "angle", "--n-basis", "6",
                "-o", str(d / "a_wave.npz")]) == 0
    models = load_models([d / "a_wave.npz", d / "synth.npz"])
    entry = models["synth"]
    entry.meta["units"] = UNITS
    entry.meta["replay"] = load_replay(entry, d / "synth.csv")
    srv = InterprimServer(models, ServerConfig(port=0))
    with ServerThread(srv) as st:
        yield st


def gen(drv):
    """Page state and the panel's texts, read in one script (consistent with each other)."""
    return drv.execute_script(
        """const g = window.ipState.gen, t = (id) => document.getElementById(id).textContent;
           return {state: g, phaseText: t('gen-phase'), oorText: t('gen-oor'), distText: t('gen-dist'),
                   canvasOor: document.getElementById('gen-canvas').dataset.outOfRange,
                   canvasSeries: JSON.parse(document.getElementById('gen-canvas').dataset.series)};""")


def test_generic_view_replay_labels_band_phase_and_out_of_range(user_server, driver):  # noqa: F811
    from selenium.webdriver.support.ui import Select

    # record whether "no high-five model loaded" is ever visible, from before the page's own scripts run
    driver.execute_cdp_cmd("Page.addScriptToEvaluateOnNewDocument", {"source": """
        window.__hfErrorShown = false;
        new MutationObserver(() => {
          const e = document.getElementById('hf-error'), v = document.getElementById('view-highfive');
          if (e && v && e.textContent && !v.hidden) window.__hfErrorShown = true;
        }).observe(document, {subtree: true, childList: true, characterData: true, attributes: true});"""})
    driver.get(user_server.url)
    wait_for(driver, "return window.ipState && window.ipState.ready")
    # only user models: the page starts on the generic view (no "no high-five model loaded" dead end, not even
    # for a moment before it switches)
    assert driver.execute_script("return window.__hfErrorShown") is False
    assert driver.execute_script("return document.getElementById('view-generic').hidden") is False
    assert driver.execute_script("return document.getElementById('view-highfive').hidden") is True
    driver.find_element("id", "tab-generic").click()
    assert driver.execute_script("return window.ipState.gen.model") == "a_wave"
    Select(driver.find_element("id", "gen-model")).select_by_value("synth")
    wait_for(driver,
             "const g = window.ipState.gen; return g.model === 'synth' && g.opened && g.opened.model === 'synth'"
                     " && g.replayAvailable > 0")
    opened = driver.execute_script("return window.ipState.gen.opened")
    assert opened["column_names"] == NAMES and opened["column_units"] == UNITS
    assert opened["observed_names"] == NAMES[:2] and opened["std"] is True

    Select(driver.find_element("id", "gen-replay-index")).select_by_value("2")
    driver.find_element("id", "gen-replay").click()
    # replies in (one per frame), the phase well into the movement and a frame drawn after that reply
    wait_for(driver, "const g = window.ipState.gen; return g.predictions >= 40 && g.phase !== null && g.phase >= 0.4")
    wait_for(driver, "const d = window.ipState.gen.drawn; return d && d.phaseLine && d.series.every(s => s.mean)")
    r = gen(driver)
    st, drawn = r["state"], r["state"]["drawn"]
    labels = [f"{n} [{u}]" for n, u in zip(NAMES, UNITS)]
    assert [s["label"] for s in drawn["series"]] == labels == r["canvasSeries"]
    assert [s["role"] for s in drawn["series"]] == ["observed"] * 2 + ["controlled"] * 3
    assert all(s["mean"] and s["band"] for s in drawn["series"]) and drawn["band"] == 5
    assert all(s["sent"] >= 40 for s in drawn["series"][:2])  # the frames sent, on the observed rows
    assert st["conditioned"] is True and 0.4 <= st["phase"] <= 1
    assert r["phaseText"] == f"{st['phase']:.3f}"
    assert st["outOfRange"] is False and r["oorText"] == "false" and r["canvasOor"] == "false"
    assert st["inputDistance"] < 8 and st["error"] is None  # a training demonstration: in range
    wait_for(driver, "return !window.ipState.gen.active")
    driver.save_screenshot(str(_artifacts() / "browser_generic_replay.png"))

    # the time axis in seconds
    Select(driver.find_element("id", "gen-time")).select_by_value("s")
    wait_for(driver, "return window.ipState.gen.drawn.xLabel === 'time [s]'")

    # the same interaction in the wrong units (x1000): the flag must say so
    Select(driver.find_element("id", "gen-scale")).select_by_value("1000")
    driver.find_element("id", "gen-replay").click()
    wait_for(driver, "const g = window.ipState.gen; return g.predictions >= 5 && g.outOfRange === true")
    r = gen(driver)
    assert r["oorText"] == "true" and r["canvasOor"] == "true"
    assert r["state"]["inputDistance"] > 100
    wait_for(driver, "return window.ipState.gen.drawn.series.every(s => s.mean)")
    # the phase label and the out-of-range banner do not overlap
    wait_for(driver, "const d = window.ipState.gen.drawn; return d.banner && d.phaseLabel")
    b, lab = driver.execute_script("const d = window.ipState.gen.drawn; return [d.banner, d.phaseLabel]")
    apart = (lab["x"] >= b["x"] + b["w"] or b["x"] >= lab["x"] + lab["w"] or lab["y"] >= b["y"] + b["h"]
             or b["y"] >= lab["y"] + lab["h"])
    assert apart, (b, lab)
    driver.save_screenshot(str(_artifacts() / "browser_generic_x1000.png"))
    logs = [e for e in driver.get_log("browser") if e.get("level") == "SEVERE"]
    assert not logs, logs


def test_generic_view_drag_one_dof(user_server, driver):  # noqa: F811
    """Drag hand_y up on its plot (virtual clock): frames carry the dragged value, the others the model's."""
    from selenium.webdriver.support.ui import Select

    driver.get(user_server.url)
    wait_for(driver, "return window.ipState && window.ipState.ready")
    driver.find_element("id", "tab-generic").click()
    Select(driver.find_element("id", "gen-model")).select_by_value("synth")
    wait_for(driver,
             "const g = window.ipState.gen; return g.model === 'synth' && g.opened && g.opened.model === 'synth'"
                     " && g.drawn && g.drawn.series.length === 5")
    # from the value at the demonstrations' mean start up by 30 % of the row's scale, in 40 pointer moves of 10 ms
    result = driver.execute_script(
        """const c = document.getElementById('gen-canvas'), g = window.ipState.gen;
           const v0 = window.ipState.info.models.find(m => m.name === 'synth').start[1];
           const row = g.drawn.series[1];
           const range = JSON.parse(JSON.stringify(window.ipView.genRange(1)));
           const v1 = v0 + 0.3 * (range[1] - range[0]);
           let t = 0; window.ipClock = () => t;
           const ev = (type, v) => { const p = window.ipView.genValueToClient(1, v);
             c.dispatchEvent(new PointerEvent(type, {clientX: p[0], clientY: p[1], pointerId: 9, isPrimary: true,
                                                    bubbles: true, pointerType: 'mouse', buttons: 1})); };
           ev('pointerdown', v0);
           for (let i = 1; i <= 40; i++) { t += 10; ev('pointermove', v0 + (v1 - v0) * i / 40); }
           t += 50; ev('pointerup', v1);
           t += 1e6;
           return {v0, v1, range, label: row.label};""")
    wait_for(driver, "const g = window.ipState.gen; return !g.active && g.frames >= 30 && g.predictions >= g.frames")
    driver.execute_script("delete window.ipClock")
    st = driver.execute_script("return window.ipState.gen")
    assert st["dragged"] == "hand_y" and st["error"] is None
    # one pixel of the row is (range / row height in CSS pixels); the last frame is the release point to within two of
    # them
    px = (result["range"][1] - result["range"][0]) / driver.execute_script("return window.ipView.genRowHeight(1)")
    assert abs(st["lastFrame"][1] - result["v1"]) < 2 * px, (st["lastFrame"], result)
    assert st["conditioned"] is True and st["phase"] is not None
    assert all(isinstance(v, (int, float)) for v in st["lastFrame"]), st["lastFrame"]  # a NaN would be None


def _artifacts():
    from pathlib import Path

    out = Path(__file__).resolve().parents[2] / "test-artifacts"
    out.mkdir(exist_ok=True)
    return out

"""End to end: the live page in a real headless Chromium (Debian's ``chromium`` + ``chromium-driver``).

Starts a server with the demo models (a small high-five model from ``interprim.sim`` and the letter
models), loads the page, performs a scripted mouse drag of the human hand along a held-out test
interaction, checks that the robot arm ended near the high-five point, replays a letter on the
handwriting tab, and saves screenshots to ``test-artifacts/``.

Skipped only when Chromium (or its driver) is not installed:
``apt-get install -y chromium chromium-driver``.
"""

from __future__ import annotations

import json
import math
import shutil
import tempfile
import time
import urllib.request
from pathlib import Path

import pytest

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
DRIVER = shutil.which("chromedriver")
pytestmark = [pytest.mark.skipif(
    CHROMIUM is None or DRIVER is None,
    reason="needs Chromium and its driver: apt-get install -y chromium chromium-driver",
), pytest.mark.slow]  # a browser driving the live page

ARTIFACTS = Path(__file__).resolve().parents[2] / "test-artifacts"


@pytest.fixture(scope="module")
def live_server():
    from interprim.server.app import InterprimServer, ServerConfig, ServerThread
    from interprim.server.demo import highfive_model, highfive_world, letter_models

    models = {"highfive": highfive_model(n_train=24, n_test=2, seed=0)}
    models.update(letter_models(n=10))
    # No rate limit: on the tests' virtual clock the page sends a drag's frames in one burst (all due at once),
    # which the server reads at once (and coalesces); the default burst of 50 would refuse part of it.
    cfg = ServerConfig(port=0, max_rate_hz=100000, rate_burst=100000)
    srv = InterprimServer(models, cfg, extra_info={"highfive_world": highfive_world()})
    with ServerThread(srv) as st:
        yield st


@pytest.fixture(scope="module")
def driver():
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    opts = webdriver.ChromeOptions()
    opts.binary_location = CHROMIUM
    profile = tempfile.mkdtemp(prefix="interprim-chromium-")
    for flag in ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync",
                 "--disable-dev-shm-usage", f"--user-data-dir={profile}", "--window-size=1300,800"):
        opts.add_argument(flag)
    drv = webdriver.Chrome(service=Service(DRIVER), options=opts)
    drv.set_script_timeout(30)
    yield drv
    drv.quit()
    shutil.rmtree(profile, ignore_errors=True)


def wait_for(drv, script, timeout=30.0):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        value = drv.execute_script(script)
        if value:
            return value
        time.sleep(0.05)
    state = drv.execute_script("return JSON.stringify(window.ipState)")[:2000]
    raise AssertionError(f"timed out waiting for: {script}\nstate: {state}")


def path_end_world(drv, q):
    return drv.execute_script(
        """const arm = window.ipState.info.highfive_world.observed_arm; const q = arguments[0];
           let a = arm.base_angle, x = arm.base[0], y = arm.base[1];
           for (let i = 0; i < q.length; i++) { a += arm.sign * q[i]; x += arm.link_lengths[i] * Math.cos(a);
                                                y += arm.link_lengths[i] * Math.sin(a); }
           return [x, y];""", q)


def test_drag_moves_robot_to_the_high_five_point(live_server, driver):
    ARTIFACTS.mkdir(exist_ok=True)
    driver.get(live_server.url)
    wait_for(driver, "return window.ipState && window.ipState.ready")
    assert driver.execute_script("return window.ipState.hf.connected") is True
    replay = json.loads(urllib.request.urlopen(live_server.url + "api/replay/highfive").read())
    test = replay["interactions"][0]
    goal = test["goal"]
    # the human goes 60 % of the way and stops: the robot must anticipate the meeting point
    observed = test["observed"][: int(0.6 * len(test["observed"]))]
    rest_hand = driver.execute_script("return window.ipState.hf.robotHand")
    # the human hand path of the held-out interaction, in page coordinates
    path = driver.execute_script(
        """const arm = window.ipState.info.highfive_world.observed_arm;
           return arguments[0].map(q => {
             let a = arm.base_angle, x = arm.base[0], y = arm.base[1];
             for (let i = 0; i < q.length; i++) { a += arm.sign * q[i]; x += arm.link_lengths[i] * Math.cos(a);
                                                  y += arm.link_lengths[i] * Math.sin(a); }
             return window.ipView.worldToClient(x, y); });""",
        observed,
    )
    # A pointer move every 3 frames (the page interpolates between pointer events), dispatched to the page's
    # own handlers on a virtual clock (window.ipClock): the frames the page samples and sends are then those
    # of the path whatever the load of the machine (real-time input dispatch under load stalls the "human"
    # and changes what the model sees; the replay test below still uses real clicks).
    step = 3
    dt_ms = 1000 * replay["dt"]
    driver.execute_script(
        """const c = document.getElementById('hf-canvas'), path = arguments[0], step = arguments[1],
                 dt = arguments[2];
           let t = 0; window.ipClock = () => t;
           const ev = (type, p) => c.dispatchEvent(new PointerEvent(type, {clientX: p[0], clientY: p[1],
                 pointerId: 7, isPrimary: true, bubbles: true, pointerType: 'mouse', buttons: 1}));
           ev('pointerdown', path[0]);
           const pts = path.filter((_, i) => i > 0 && i % step === 0).concat([path[path.length - 1]]);
           for (const p of pts) { t += dt * step; ev('pointermove', p); }
           t += 100; ev('pointerup', path[path.length - 1]);
           t += 1e6;  // the sampler's grid reaches the last event: every frame becomes due""",
        path, step, dt_ms)
    n_pred = wait_for(driver, "return window.ipState.hf.predictions >= 20 && window.ipState.hf.predictions")
    assert n_pred >= 20
    # after the human stops, every frame is answered (predictions counts the frames the replies cover) and the
    # robot finishes its predicted movement (robotPhase reaches 1): waited for as state, not as wall-clock time
    wait_for(driver, "return !window.ipState.hf.active")
    wait_for(driver, "const h = window.ipState.hf; return h.predictions >= h.frames && h.robotPhase >= 1")
    driver.execute_script("delete window.ipClock")
    st = driver.execute_script("return window.ipState.hf")
    (ARTIFACTS / "browser_highfive_drag_frames.json").write_text(json.dumps(st["sent"]))
    assert st["error"] is None, st["error"]
    human_end = st["humanHand"]
    robot = st["robotHand"]
    meet = st["meetingPoint"]
    d_rest = math.dist(rest_hand, goal)
    d_robot = math.dist(robot, goal)
    d_meet = math.dist(meet, goal)
    driver.save_screenshot(str(ARTIFACTS / "browser_highfive_drag.png"))
    print(f"goal {goal}, human hand {human_end}, robot hand {robot}, meeting point {meet}: "
          f"robot-goal {d_robot:.3f} m (rest {d_rest:.3f} m), meeting point-goal {d_meet:.3f} m")
    assert math.dist(human_end, path_end_world(driver, observed[-1])) < 0.05  # the drag followed the path
    # The frames are those of the path on the virtual clock, so the result is fixed (0.065 m here, with the
    # demo model's input_noise=0.01 rad for pointer input; 1.5 m before input_noise existed): the bound
    # 0.15 m is the size of a hand, the quantity the test is about, not the last run's figure.  Real-time
    # pointer input under load (stalls of the "human") reached 0.34-0.56 m: that is why the clock is virtual.
    assert d_robot < 0.15 and d_robot < 0.25 * d_rest, (robot, goal)
    assert driver.find_element("id", "hf-canvas").get_attribute("data-robot-hand")


def fk_robot_rest(drv, q):
    return drv.execute_script(
        """const arm = window.ipState.info.highfive_world.controlled_arm; const q = arguments[0];
           let a = arm.base_angle, x = arm.base[0], y = arm.base[1];
           for (let i = 0; i < q.length; i++) { a += arm.sign * q[i]; x += arm.link_lengths[i] * Math.cos(a);
                                                y += arm.link_lengths[i] * Math.sin(a); }
           return [x, y];""", q)


def test_replay_button_and_handwriting_tab(live_server, driver):
    ARTIFACTS.mkdir(exist_ok=True)
    driver.get(live_server.url)
    wait_for(driver, "return window.ipState && window.ipState.ready")
    from selenium.webdriver.support.ui import Select

    Select(driver.find_element("id", "hf-replay-frac")).select_by_value("0.6")
    driver.find_element("id", "hf-replay").click()
    wait_for(driver, "return window.ipState.hf.predictions >= 30")
    wait_for(driver, "return !window.ipState.hf.active")
    # every reply in and the robot at the end of its predicted movement (state, not wall-clock time)
    wait_for(driver, "const h = window.ipState.hf; return h.predictions >= h.frames && h.robotPhase >= 1")
    st = driver.execute_script("return window.ipState.hf")
    driver.save_screenshot(str(ARTIFACTS / "browser_highfive_replay60.png"))
    print("replay 60 %:", st["replayGoal"], st["meetingPoint"], st["robotHand"])
    assert math.dist(st["meetingPoint"], st["replayGoal"]) < 0.2
    assert math.dist(st["robotHand"], st["replayGoal"]) < 0.2
    assert st["replayGoal"] is not None
    start = json.loads(urllib.request.urlopen(live_server.url + "api/replay/highfive").read())
    d_rest = math.dist(st["replayGoal"], fk_robot_rest(driver, start["interactions"][0]["controlled_truth"][0]))
    assert d_rest > 1.0  # the robot really had to move
    driver.find_element("id", "tab-writing").click()
    # write an "s" with the mouse: the server must recognise it among c, s, u
    from selenium.webdriver.common.actions.action_builder import ActionBuilder

    from interprim.server.demo import synthetic_letters

    stroke = synthetic_letters("s", 1, seed=7)[0]
    pts = driver.execute_script("return arguments[0].map(p => window.ipView.letterToClient(p[0], p[1]))",
                                stroke[: int(0.7 * len(stroke))].tolist())
    step = 3
    actions = ActionBuilder(driver, duration=10 * step)
    ptr = actions.pointer_action
    ptr.move_to_location(int(round(pts[0][0])), int(round(pts[0][1])))
    ptr.pointer_down()
    for x, y in pts[step::step] + [pts[-1]]:
        ptr.move_to_location(int(round(x)), int(round(y)))
    ptr.pointer_up()
    actions.perform()
    wait_for(driver, "return window.ipState.hw.predictions >= 20 && !window.ipState.hw.active")
    wait_for(driver, "const h = window.ipState.hw; return h.predictions >= h.frames")  # every reply in
    hw = driver.execute_script("return window.ipState.hw")
    driver.save_screenshot(str(ARTIFACTS / "browser_handwriting_drawn.png"))
    assert hw["error"] is None and hw["model"] == "letter_s", hw["probabilities"]
    driver.execute_script("window.ipState.hw.predictions = 0; window.ipState.hw.model = null;")
    driver.find_element("id", "hw-replay").click()  # first letter model: half a letter, completed live
    wait_for(driver, "return window.ipState.hw.predictions >= 20 && !window.ipState.hw.active")
    hw = driver.execute_script("return window.ipState.hw")
    assert hw["error"] is None and hw["model"] == "letter_c", hw
    assert abs(sum(hw["probabilities"].values()) - 1) < 1e-3
    time.sleep(0.3)
    driver.save_screenshot(str(ARTIFACTS / "browser_handwriting.png"))
    logs = [e for e in driver.get_log("browser") if e.get("level") == "SEVERE"]
    assert not logs, logs

"""A client written from docs/protocol.md alone, against a real loopback server.

Everything below the fixture uses only the ``websockets`` library, ``json`` and ``urllib`` and what the
protocol document says (each check names the section it relies on); interprim itself is imported only to
fit two small models and start the server.  If this file needs to know something the document does not
say, the document is incomplete.
"""

from __future__ import annotations

import json
import math
import urllib.error
import urllib.request

import pytest

pytest.importorskip("websockets")

from websockets.exceptions import ConnectionClosed  # noqa: E402
from websockets.sync.client import connect as _connect  # noqa: E402

NAMES = ["hand_x", "hand_y", "arm_a", "arm_b", "arm_c"]
UNITS = ["m", "m", "rad", "rad", "rad"]
REL = 1e-6  # "about 7 significant digits (relative error <= 5e-7)"


# ---------------------------------------------------------------------------- the server (interprim only here)
@pytest.fixture(scope="module")
def server():
    import numpy as np

    import interprim as ip
    from interprim.server.app import InterprimServer, ServerConfig, ServerThread
    from interprim.server.models import entry_for, replay_json
    from interprim.synthetic import two_agent_demos

    train = two_agent_demos(14, seed=5, frames=100)
    pair = ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=8).fit(train, dt=0.01, columns=NAMES)
    waves = [np.sin(np.linspace(0, 3, n))[:, None] * a for n, a in ((80, 1.0), (90, 1.1), (85, 0.9), (95, 1.05))]
    wave = ip.InteractionPrimitive(observed_dofs=[0], n_basis=6).fit(waves, dt=0.01, columns=["angle"])
    models = {
        "pair": entry_for("pair", pair, meta={"units": UNITS,
                                              "replay": replay_json(pair, train[:6], names=NAMES, units=UNITS,
                                                                    source="training demonstrations")}),
        "wave": entry_for("wave", wave),
        "pair_b": entry_for("pair_b", ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=6).fit(
            two_agent_demos(8, seed=6, frames=60, stretch=(0.5, 0.7)), dt=0.01)),
    }
    srv = InterprimServer(models, ServerConfig(port=0, max_rate_hz=100000, rate_burst=100000))
    with ServerThread(srv) as st:
        yield st


# ---------------------------------------------------------------------------- the client (from the document)
class DocClient:
    """Pipelining client: every message gets exactly one reply, in order ("Model of a session")."""

    def __init__(self, url):
        try:
            self.ws = _connect(url, close_timeout=2, legacy=True)
        except TypeError:  # websockets < 16
            self.ws = _connect(url, close_timeout=2)
        self.sent = []  # FIFO of what was sent, popped by each reply ("Resynchronising")
        self.frames_sent = 0  # our own count of frames: the server's seq ("Matching replies to frames")

    def send(self, msg, *, is_frame=False):
        if isinstance(msg, dict):
            text = json.dumps(msg, allow_nan=False)
        else:
            text = msg
        if is_frame:
            self.frames_sent += 1
        self.sent.append((text, self.frames_sent if is_frame else None))
        self.ws.send(text)

    def frame(self, values, t=None):
        msg = {"type": "frame", "frame": [float(v) for v in values]}
        if t is not None:
            msg["t"] = t
        self.send(msg, is_frame=True)

    def recv(self):
        """The next reply, with the message it answers (the newest of them for a prediction that covers several
        frames: "Overload and coalesced replies") and that message's expected seq."""
        reply = json.loads(self.ws.recv(timeout=20))
        for _ in range(max(int(reply.get("covers", 1)), 1) if reply.get("type") == "prediction" else 1):
            sent, expected_seq = self.sent.pop(0)
        return reply, sent, expected_seq

    def recv_frames(self, n):
        """Replies until the ``n`` frames sent last are all answered (a prediction may cover several)."""
        out, left = [], n
        while left > 0:
            r = self.recv()
            out.append(r)
            left -= max(int(r[0].get("covers", 1)), 1) if r[0].get("type") == "prediction" else 1
        return out

    def rpc(self, msg):
        self.send(msg)
        return self.recv()[0]

    def close(self):
        self.ws.close()


def hello_open(url, **open_fields):
    c = DocClient(url)
    w = c.rpc({"type": "hello", "version": 1, "client": "doc client"})
    assert w["type"] == "welcome"
    o = c.rpc({"type": "open", **open_fields})
    assert o["type"] == "opened", o
    return c, w, o


def interp(rows, s):
    """``mean`` at normalised time s on the grid linspace(0, 1, points) ("Using it on a robot")."""
    n = len(rows)
    f = min(max(s, 0.0), 1.0) * (n - 1)
    i = min(int(f), n - 2)
    w = f - i
    return [a * (1 - w) + b * w for a, b in zip(rows[i], rows[i + 1])]


def get_json(url):
    with urllib.request.urlopen(url, timeout=20) as r:
        return json.loads(r.read())


def close_rel(a, b):
    return abs(a - b) <= REL * max(1.0, abs(a), abs(b))


def model_info(welcome, name):
    return next(m for m in welcome["models"] if m["name"] == name)


# ---------------------------------------------------------------------------- the checks
def test_hello_welcome_open_and_labels(server):
    c, w, o = hello_open(server.ws_url, model="pair", points=20)
    try:
        assert w["version"] == 1 and isinstance(w["session"], int)
        assert {"max_sessions", "max_message_bytes", "max_rate_hz", "rate_burst", "max_points",
                "send_queue"} <= set(w["limits"])
        info = model_info(w, "pair")
        # "Model info"
        assert info["kind"] == "interaction" and info["n_dofs"] == 5
        assert info["names"] == NAMES and info["units"] == UNITS
        assert info["observed_dofs"] == [0, 1] and info["controlled_dofs"] == [2, 3, 4]
        assert info["dt"] == pytest.approx(0.01) and info["mean_duration"] > 0 and info["min_frames"] >= 1
        assert len(info["start"]) == 5 and info["replay"] is True
        wave = model_info(w, "wave")
        assert wave["kind"] == "single" and wave["controlled_dofs"] == [] and wave["units"] == [None]
        assert wave["replay"] is False
        # "opened": the controlled columns by default, labelled
        assert o["columns"] == info["controlled_dofs"] and o["column_names"] == ["arm_a", "arm_b", "arm_c"]
        assert o["column_units"] == ["rad"] * 3 and o["observed_names"] == ["hand_x", "hand_y"]
        assert o["observed_dofs"] == [0, 1] and o["observed_units"] == ["m", "m"] and o["n_observed"] == 2
        assert o["points"] == 20 and o["std"] is False and o["min_frames"] == info["min_frames"]
        # dofs "all": every column
        o2 = c.rpc({"type": "open", "model": "pair", "dofs": "all", "points": 5})
        assert o2["columns"] == [0, 1, 2, 3, 4] and o2["column_names"] == NAMES
        # "recognise" with one candidate: lists, as for one model
        o3 = c.rpc({"type": "open", "model": "recognise", "candidates": ["pair"]})
        assert o3["model"] == "recognise" and o3["columns"] == [2, 3, 4] and o3["column_names"] == ["arm_a", "arm_b",
                                                                                                    "arm_c"]
        # several candidates: per-candidate objects; probabilities uniform until conditioned
        o4 = c.rpc({"type": "open", "model": "recognise", "candidates": ["pair", "pair_b"], "points": 5})
        assert o4["columns"] == {"pair": [2, 3, 4], "pair_b": [2, 3, 4]}
        assert o4["column_names"] == {"pair": ["arm_a", "arm_b", "arm_c"], "pair_b": ["dof_2", "dof_3", "dof_4"]}
        assert o4["observed_units"] == {"pair": ["m", "m"], "pair_b": [None, None]}
        for k in range(o4["min_frames"]):
            c.frame([0.01 * k, 0.0])
            p = c.recv()[0]
            assert set(p["probabilities"]) == {"pair", "pair_b"}
            if not p["conditioned"]:
                assert p["probabilities"] == {"pair": 0.5, "pair_b": 0.5} and p["model"] == "pair"
        assert p["conditioned"] is True
        e = c.rpc({"type": "open", "model": "recognise"})  # all loaded models: they observe 2 and 1 DoFs
        assert e["code"] == "bad_message" and "same number" in e["message"]
        err = c.rpc({"type": "open", "model": "nope"})
        assert err["type"] == "error" and err["code"] == "unknown_model" and "pair" in err["message"]
        assert "seq" not in err
    finally:
        c.close()


def test_pipelined_frames_first_frames_and_seq(server):
    replay = get_json(server.url + "api/replay/pair")
    frames = replay["interactions"][0]["observed"]
    c, w, o = hello_open(server.ws_url, model="pair", points=30)
    try:
        n = len(frames)
        for k, f in enumerate(frames):  # all at once, then read ("pipelining")
            c.frame(f, t=1000 + k)
        replies = []  # "Every message answered, in order": a prediction answers covers frames (1 unless behind)
        while not replies or replies[-1][0]["seq"] < n:
            replies.append(c.recv())
        min_frames = o["min_frames"]
        phases = []
        expected_first = 1
        for p, _, _ in replies:
            k = p["seq"]
            assert p["type"] == "prediction" and p["first_seq"] == expected_first, p
            assert p["covers"] == k - p["first_seq"] + 1 >= 1 and p["t"] == 999 + k
            expected_first = k + 1
            assert p["frames"] == k and p["model"] == "pair" and p["columns"] == [2, 3, 4]
            assert len(p["mean"]) == 30 and all(len(r) == 3 for r in p["mean"]) and len(p["goal"]) == 3
            assert "std" not in p and p["out_of_range"] is False and p["compute_ms"] >= 0
            if k < min_frames:  # "The first frames": the prior, no estimates
                assert p["conditioned"] is False
                assert p["phase"] is p["x"] is p["speed"] is p["duration"] is p["log_likelihood"] is None
            else:
                assert p["conditioned"] is True and 0 < p["phase"] <= 1
                assert p["x"] == pytest.approx(math.exp(-model_info(w, "pair")["alpha_x"] * p["phase"]), rel=1e-9)
                assert p["speed"] == pytest.approx(model_info(w, "pair")["mean_duration"] / p["duration"], rel=1e-9)
                assert math.isfinite(p["log_likelihood"])
                phases.append((p["frames"], p["phase"]))
        assert sum(p["covers"] for p, _, _ in replies) == n  # nothing dropped
        # a whole training demonstration: the phase runs to the end, and the time axis agrees with dt; the first
        # conditioned prediction is early in the movement unless a busy server answered it after many frames at once
        # (how many frames a reply covers depends on the machine's load, so the check reads the frames it answers)
        first_frames, first_phase = phases[0]
        assert phases[-1][1] > 0.9 and (first_phase < 0.2 or first_frames > 0.15 * n)
        last = replies[-1][0]
        assert last["duration"] == pytest.approx((n - 1) * replay["dt"] / last["phase"], rel=1e-6)
        r = c.rpc({"type": "reset"})
        assert r == {"type": "reset_done", "seq": n}
        c.frame(frames[0])
        p = c.recv()[0]
        assert p["seq"] == n + 1 and p["frames"] == 1 and p["conditioned"] is False  # a new interaction
    finally:
        c.close()


def test_unparseable_frame_keeps_its_seq_and_garbage_resyncs(server):
    c, _, _ = hello_open(server.ws_url, model="pair", points=5)
    try:
        c.frame([0.0, 0.0], t=1)
        # Python's json.dumps writes NaN unless allow_nan=False: not JSON, but it still is frame 2
        c.send(json.dumps({"type": "frame", "frame": [float("nan"), 0.0], "t": 2}), is_frame=True)
        c.send("this is not a frame")  # garbage that is not a frame: an error without seq
        c.frame([0.01, 0.0], t=3)
        c.send(b"\x00" * 8, is_frame=True)  # binary of the wrong size: bad_frame, counted
        c.frame([0.02, 0.01])
        out = [c.recv() for _ in range(6)]
        (p1, _, s1), (e2, _, s2), (e3, sent3, s3), (p4, _, s4), (e5, _, s5), (p6, _, s6) = out
        assert p1["type"] == "prediction" and p1["seq"] == s1 == 1 and p1["t"] == 1
        assert e2["type"] == "error" and e2["code"] == "bad_json" and e2["seq"] == s2 == 2 and e2["t"] == 2
        assert e3["type"] == "error" and e3["code"] == "bad_json" and "seq" not in e3
        assert sent3 == "this is not a frame" and s3 is None  # the FIFO says which message that was
        assert p4["seq"] == s4 == 3 and p4["t"] == 3 and p4["frames"] == 2  # the bad frames did not enter
        assert e5["code"] == "bad_frame" and e5["seq"] == s5 == 4
        assert p6["seq"] == s6 == 5 and p6["frames"] == 3 and p6["conditioned"] is True
        # a frame with a finite but non-float value: bad_frame with its seq and t
        c.send({"type": "frame", "frame": ["1", 2], "t": 7.5}, is_frame=True)
        e = c.recv()[0]
        assert e["code"] == "bad_frame" and e["seq"] == 6 and e["t"] == 7.5
        # something we meant as a frame but the server cannot recognise as one ("Resynchronising")
        c.send('{"frame": [0.0, 0.0]', is_frame=True)
        e, _, ours = c.recv()
        assert e["type"] == "error" and "seq" not in e and ours == 7
        c.frames_sent -= 1  # the server did not count it
        c.frame([0.03, 0.01])
        p, _, ours = c.recv()
        assert p["type"] == "prediction" and p["seq"] == ours == 7
    finally:
        c.close()


def test_second_hello_changes_nothing(server):
    replay = get_json(server.url + "api/replay/pair")
    frames = replay["interactions"][1]["observed"]
    c, w1, _ = hello_open(server.ws_url, model="pair", points=5)
    try:
        for f in frames[:4]:
            c.frame(f)
        c.recv_frames(4)
        w2 = c.rpc({"type": "hello", "version": 1})
        assert w2["type"] == "welcome" and w2["session"] == w1["session"] and w2["models"] == w1["models"]
        c.frame(frames[4])
        p = c.recv()[0]
        assert p["type"] == "prediction" and p["seq"] == 5 and p["frames"] == 5  # same interaction, same count
        bad = c.rpc({"type": "hello", "version": 99})  # checked like the first: fatal
        assert bad["type"] == "error" and bad["code"] == "bad_version"
        with pytest.raises(ConnectionClosed):
            c.ws.recv(timeout=10)  # closed by the server (1008)
        assert c.ws.close_code == 1008
    finally:
        c.close()


def test_robot_state_forms(server):
    replay = get_json(server.url + "api/replay/pair")
    frames = replay["interactions"][2]["observed"][:12]
    pos, vel = [0.1, -0.2, 0.3], [1.0, 0.5, -0.5]

    def run(**open_fields):
        c, _, o = hello_open(server.ws_url, model="pair", points=11, **open_fields)
        try:
            for f in frames:
                c.frame(f)
            return o, c.recv_frames(len(frames))[-1][0]
        finally:
            c.close()

    o, p_pos = run(robot_state=pos)
    assert o["robot_state"] == pos
    assert all(close_rel(a, b) for a, b in zip(p_pos["mean"][0], pos))  # the controlled columns start there
    _, p_both = run(robot_state=[pos, vel])
    assert all(close_rel(a, b) for a, b in zip(p_both["mean"][0], pos))
    assert max(abs(a - b) for a, b in zip(p_both["mean"][2], p_pos["mean"][2])) > 1e-4  # the velocity counts
    _, p_none = run()
    assert max(abs(a - b) for a, b in zip(p_none["mean"][0], pos)) > 0.05
    c, _, _ = hello_open(server.ws_url, model="pair", points=11)
    try:
        for bad in ([1.0, 2.0], [[1.0, 2.0, 3.0], [1.0]], "here", [1.0, float("inf"), 0.0]):
            text = json.dumps({"type": "open", "model": "pair", "robot_state": bad})  # allow_nan: inf -> Infinity
            e = c.rpc(text)
            assert e["type"] == "error" and e["code"] in ("bad_message", "bad_json"), (bad, e)
            assert "robot_state" in e["message"] or e["code"] == "bad_json"
        e = c.rpc({"type": "open", "model": "wave", "robot_state": [0.0]})
        assert e["code"] == "bad_message" and "robot_state" in e["message"]  # a single-agent model
        # reset with a new robot_state: this and later interactions start there
        assert c.rpc({"type": "reset", "robot_state": pos})["type"] == "reset_done"
        c.frame(frames[0])
        p = c.recv()[0]
        assert all(close_rel(a, b) for a, b in zip(p["mean"][0], pos))
        assert c.rpc({"type": "reset"})["type"] == "reset_done"  # keeps it
        c.frame(frames[0])
        assert all(close_rel(a, b) for a, b in zip(c.recv()[0]["mean"][0], pos))
        assert c.rpc({"type": "reset", "robot_state": [1.0]})["code"] == "bad_message"
    finally:
        c.close()


def test_std_on_and_off(server):
    replay = get_json(server.url + "api/replay/pair")
    frames = replay["interactions"][3]["observed"][:20]
    out = {}
    for std in (False, True):
        c, _, o = hello_open(server.ws_url, model="pair", points=15, std=std)
        try:
            assert o["std"] is std
            for f in frames:
                c.frame(f)
            out[std] = c.recv_frames(len(frames))[-1][0]
        finally:
            c.close()
    assert "std" not in out[False]
    band = out[True]["std"]
    assert len(band) == 15 and all(len(r) == 3 and all(v >= 0 for v in r) for r in band)
    assert max(max(r) for r in band) > 0
    # the band does not change the mean
    assert all(close_rel(a, b) for ra, rb in zip(out[True]["mean"], out[False]["mean"]) for a, b in zip(ra, rb))


def test_replay_json_streams_to_its_model(server):
    replay = get_json(server.url + "api/replay/pair")
    assert replay["dt"] == pytest.approx(0.01) and replay["columns"] == NAMES and replay["units"] == UNITS
    assert replay["observed_dofs"] == [0, 1] and replay["controlled_dofs"] == [2, 3, 4] and replay["source"]
    its = replay["interactions"]
    assert its
    finals, errors = [], []
    for it in its:
        T = len(it["observed"])
        assert len(it["controlled_truth"]) == T and it["duration"] == pytest.approx((T - 1) * replay["dt"])
        c, _, _ = hello_open(server.ws_url, model="pair", points=40)
        try:
            for f in it["observed"]:
                c.frame(f)
            p = c.recv_frames(T)[-1][0]
        finally:
            c.close()
        assert p["conditioned"] and p["phase"] > 0.9 and p["out_of_range"] is False
        finals.append(it["controlled_truth"][-1])
        errors.append([a - b for a, b in zip(p["mean"][-1], it["controlled_truth"][-1])])
    # knowing the whole human movement predicts the robot's final posture better than the average final posture
    mean_final = [sum(col) / len(col) for col in zip(*finals)]
    spread = sum((a - b) ** 2 for f in finals for a, b in zip(f, mean_final))
    assert sum(e ** 2 for err in errors for e in err) < spread
    with pytest.raises(urllib.error.HTTPError) as e:
        urllib.request.urlopen(server.url + "api/replay/wave", timeout=20)
    assert e.value.code == 404
    info = get_json(server.url + "api/info")
    assert model_info(info, "pair")["names"] == NAMES


@pytest.mark.filterwarnings("ignore:the observed frames are")  # the server's warning about the x1000 frame
def test_out_of_range_is_sticky_until_reset_and_close(server):
    replay = get_json(server.url + "api/replay/pair")
    frames = replay["interactions"][0]["observed"][:6]
    c, _, _ = hello_open(server.ws_url, model="pair", points=5)
    try:
        for f in frames[:3]:
            c.frame(f)
        assert all(r[0]["out_of_range"] is False for r in c.recv_frames(3))
        c.frame([1000 * v for v in frames[3]])
        p = c.recv()[0]
        assert p["out_of_range"] is True and p["input_distance"] > 8
        c.frame(frames[4])
        assert c.recv()[0]["out_of_range"] is True  # until the next reset
        assert c.rpc({"type": "reset"})["seq"] == 5
        c.frame(frames[0])
        assert c.recv()[0]["out_of_range"] is False
        closed = c.rpc({"type": "close"})
        assert closed == {"type": "closed", "seq": 6}
        c.frame(frames[0])
        e = c.recv()[0]
        assert e["type"] == "error" and e["code"] == "not_open" and e["seq"] == 7
        assert c.rpc({"type": "open", "model": "wave"})["n_observed"] == 1  # open again to go on
        c.frame([0.5])
        assert c.recv()[0]["seq"] == 8
    finally:
        c.close()

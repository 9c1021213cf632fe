"""The streaming server against real clients on loopback (ephemeral ports, background event loop).

Covers the happy path, every kind of bad input (each must get a clear error on its own
session or a clean close with code + reason, and a log line, without disturbing other sessions),
limits, the token, the HTTP side, and a corrupt model at start-up.  No timing assertions.
"""

from __future__ import annotations

import argparse
import base64
import json
import logging
import os
import socket
import struct
import time
import urllib.error
import urllib.request
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("websockets")

from websockets.exceptions import ConnectionClosed, InvalidStatus  # noqa: E402
from websockets.sync.client import connect as _connect  # noqa: E402

import interprim as ip  # noqa: E402
from interprim.errors import ModelFileError  # noqa: E402
from interprim.server import protocol as P  # noqa: E402
from interprim.server.app import InterprimServer, ServerConfig, ServerThread  # noqa: E402
from interprim.server.client import Client, ServerError  # noqa: E402
from interprim.server.demo import letter_models, synthetic_letters  # noqa: E402
from interprim.server.models import entry_for, load_models  # noqa: E402
from interprim.synthetic import two_agent_demos  # noqa: E402

SCHEMA_PATH = Path(__file__).resolve().parents[1] / "src" / "interprim" / "server" / "static" / "protocol.schema.json"


# ---------------------------------------------------------------------------- fixtures and helpers
def connect(url, **kw):
    kw.setdefault("close_timeout", 2)
    try:
        return _connect(url, legacy=True, **kw)
    except TypeError:  # websockets < 16
        return _connect(url, **kw)


@pytest.fixture(scope="module")
def models():
    train = two_agent_demos(12, seed=0, frames=100)
    m = ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=8).fit(train, dt=0.01)
    one = ip.InteractionPrimitive(observed_dofs=[0], n_basis=6).fit(train, dt=0.01)
    out = {"pair": entry_for("pair", m), "one": entry_for("one", one)}
    out.update(letter_models(n=8, n_basis=10))
    return out


@pytest.fixture(scope="module")
def test_demo():
    return two_agent_demos(1, seed=99, frames=100)[0]


@pytest.fixture(scope="module")
def server(models):
    srv = InterprimServer(models, ServerConfig(port=0, max_rate_hz=100000, rate_burst=100000))
    with ServerThread(srv) as st:
        yield st


@pytest.fixture(scope="module")
def strict(models):
    """A server with small limits."""
    cfg = ServerConfig(port=0, max_sessions=3, max_message_bytes=2048, max_rate_hz=50, rate_burst=5,
                       send_queue=8, write_limit=4096, max_errors=20, max_points=100)
    srv = InterprimServer({"pair": models["pair"]}, cfg)
    with ServerThread(srv) as st:
        yield st


@pytest.fixture(scope="module")
def validator():
    jsonschema = pytest.importorskip("jsonschema")
    schema = json.loads(SCHEMA_PATH.read_text())
    cls = jsonschema.validators.validator_for(schema)
    cls.check_schema(schema)
    server_msg = dict(schema, **{"$ref": "#/$defs/server_message"})
    server_msg.pop("oneOf")
    client_msg = dict(schema, **{"$ref": "#/$defs/client_message"})
    client_msg.pop("oneOf")
    return cls(server_msg), cls(client_msg)


def hello(ws, token=None):
    msg = {"type": "hello", "version": 1}
    if token is not None:
        msg["token"] = token
    ws.send(json.dumps(msg))
    return json.loads(ws.recv(timeout=10))


def opened(url, model="pair", **kw):
    ws = connect(url)
    assert hello(ws)["type"] == "welcome"
    ws.send(json.dumps({"type": "open", "model": model, **kw}))
    reply = json.loads(ws.recv(timeout=10))
    assert reply["type"] == "opened", reply
    return ws


def rpc(ws, msg) -> dict:
    ws.send(msg if isinstance(msg, (str, bytes)) else json.dumps(msg))
    return json.loads(ws.recv(timeout=10))


def frame_msg(f, **kw):
    return json.dumps({"type": "frame", "frame": [float(v) for v in f], **kw})


def wait_until(pred, timeout=20.0):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if pred():
            return True
        time.sleep(0.02)
    return pred()


def n_sessions(st):
    return st.call(lambda: len(st.server.sessions))


def closed_with(ws, timeout=10):
    """Read until the server closes; returns (close code, reason, messages received before)."""
    got = []
    try:
        while True:
            got.append(ws.recv(timeout=timeout))
    except ConnectionClosed as exc:
        rcvd = exc.rcvd
        return (rcvd.code, rcvd.reason, got) if rcvd is not None else (None, "", got)


class RawWS:
    """A hand-made WebSocket client over a plain socket: sends anything, reads only when asked."""

    def __init__(self, port, rcvbuf=None, path="/ws"):
        s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        if rcvbuf:
            s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, rcvbuf)
        s.settimeout(10)
        s.connect(("127.0.0.1", port))
        key = base64.b64encode(os.urandom(16)).decode()
        s.sendall(
            f"GET {path} HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
            f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n".encode()
        )
        buf = b""
        while b"\r\n\r\n" not in buf:
            chunk = s.recv(4096)
            assert chunk, "server closed during the handshake"
            buf += chunk
        assert buf.startswith(b"HTTP/1.1 101"), buf[:100]
        self.sock = s

    def send(self, payload: bytes | str, opcode=None, fin=True):
        if isinstance(payload, str):
            payload, opcode = payload.encode(), opcode or 1
        opcode = opcode or 2
        head = bytes([(0x80 if fin else 0) | opcode])
        n = len(payload)
        if n < 126:
            head += bytes([0x80 | n])
        elif n < 65536:
            head += bytes([0x80 | 126]) + struct.pack(">H", n)
        else:
            head += bytes([0x80 | 127]) + struct.pack(">Q", n)
        mask = os.urandom(4)
        body = bytes(b ^ mask[i % 4] for i, b in enumerate(payload))
        self.sock.sendall(head + mask + body)

    def close(self):
        self.sock.close()


# ---------------------------------------------------------------------------- happy path
def test_happy_path_matches_direct_stream(server, models, test_demo, validator):
    server_v, _ = validator
    with Client(server.ws_url) as c:
        server_v.validate(c.welcome)
        assert {m["name"] for m in c.models} == set(models)
        op = c.open("pair", points=30, std=True)
        server_v.validate(op)
        assert op["columns"] == [2, 3, 4] and op["n_observed"] == 2
        direct = models["pair"].model.stream()
        phases = []
        for k, f in enumerate(test_demo[:, :2], start=1):
            p = c.frame(f, t=k * 0.5)
            server_v.validate(p)
            assert p["seq"] == k and p["t"] == k * 0.5 and p["model"] == "pair"
            mean, std = np.array(p["mean"]), np.array(p["std"])
            assert mean.shape == (30, 3) and std.shape == (30, 3)
            d = direct.update(f)
            np.testing.assert_allclose(mean, d.trajectory(30)[:, 2:], atol=2e-6)
            np.testing.assert_allclose(p["goal"], d.goal[2:], atol=2e-6)
            assert p["phase"] == pytest.approx(d.phase)
            phases.append(p["phase"])
        assert phases[-1] > 0.8 and phases[0] < 0.2
        r = c.reset()
        server_v.validate(r)
        assert r == {"type": "reset_done", "seq": len(test_demo)}
        p = c.frame(test_demo[0, :2])
        np.testing.assert_allclose(p["mean"], models["pair"].model.stream().update(test_demo[0, :2]).trajectory(30)[:, 2:],
                                   atol=2e-6)
        assert c.close_session() == {"type": "closed", "seq": len(test_demo) + 1}
        with pytest.raises(ServerError) as e:
            c.frame(test_demo[0, :2])
        assert e.value.code == "not_open"


def test_binary_frames_equal_json_frames(server, test_demo):
    with Client(server.ws_url) as a, Client(server.ws_url) as b:
        a.open("pair", points=10)
        b.open("pair", points=10)
        for f in test_demo[:40, :2]:  # interleaved: also a session-isolation check
            pa, pb = a.frame(f), b.frame(f, binary=True)
            assert pa["mean"] == pb["mean"] and pa["seq"] == pb["seq"]
            assert "std" not in pa


def test_auto_recognises_the_letter(server, validator):
    server_v, _ = validator
    names = ["letter_c", "letter_s", "letter_u"]
    with Client(server.ws_url) as c:
        op = c.open("auto", candidates=names, points=20, dofs="all")
        assert op["candidates"] == names and set(op["columns"]) == set(names)
        for letter in "cs":
            c.reset()
            stroke = synthetic_letters(letter, 1, seed=42)[0]
            for f in stroke[: int(0.6 * len(stroke))]:
                p = c.frame(f)
            server_v.validate(p)
            assert set(p["probabilities"]) == set(names)
            assert sum(p["probabilities"].values()) == pytest.approx(1.0, abs=1e-5)
            assert p["model"] == f"letter_{letter}", p["probabilities"]
            assert np.array(p["mean"]).shape == (20, 2)


def test_auto_refuses_candidates_of_different_sizes(server, models):
    with Client(server.ws_url) as c:
        with pytest.raises(ServerError) as e:
            c.open("auto", candidates=["pair", "missing"])
        assert e.value.code == "unknown_model" and "missing" in str(e.value)
        for kw in ({"candidates": ["pair", "one"]}, {}):  # default candidates: all loaded models
            with pytest.raises(ServerError) as e:
                c.open("auto", **kw)
            assert e.value.code == "bad_message" and "observe the same number of DoFs" in str(e.value)
        assert c.open("auto", candidates=["pair", "letter_c"])["type"] == "opened"  # both observe 2 DoFs
        assert c.open("one", points=4)["n_observed"] == 1
        assert np.array(c.frame([0.1])["mean"]).shape == (4, 4)


# ---------------------------------------------------------------------------- bad input, one by one
BAD_TEXT = [
    ("{bad", "bad_json"),
    ("", "bad_json"),
    ("[1, 2]", "bad_message"),
    ("null", "bad_message"),
    ('"frame"', "bad_message"),
    ('{"frame": [1, 2]}', "bad_message"),
    ('{"type": 5}', "bad_message"),
    ('{"type": "teleport"}', "unknown_type"),
    ('{"type": "frame", "frame": [NaN, 1]}', "bad_json"),
    ('{"type": "frame", "frame": [Infinity, 1]}', "bad_json"),
    ('{"type": "frame", "frame": [1e400, 1]}', "bad_frame"),
    ('{"type": "frame", "frame": [1]}', "bad_frame"),
    ('{"type": "frame", "frame": [1, 2, 3]}', "bad_frame"),
    ('{"type": "frame", "frame": []}', "bad_frame"),
    ('{"type": "frame", "frame": "1,2"}', "bad_frame"),
    ('{"type": "frame", "frame": {"0": 1}}', "bad_frame"),
    ('{"type": "frame", "frame": ["1", "2"]}', "bad_frame"),
    ('{"type": "frame", "frame": [true, false]}', "bad_frame"),
    ('{"type": "frame", "frame": [[1], [2]]}', "bad_frame"),
    ('{"type": "frame", "frame": [null, 1]}', "bad_frame"),
    ('{"type": "frame", "frame": [1, 2], "t": "now"}', "bad_message"),
    ('{"type": "frame"}', "bad_frame"),
    ('{"type": "frame", "frame": [' + "9" * 400 + ", 1]}", "bad_frame"),
    ('{"type": "open", "model": 7}', "bad_message"),
    ('{"type": "open", "model": "nope"}', "unknown_model"),
    ('{"type": "open", "model": "pair", "points": "many"}', "bad_message"),
    ('{"type": "open", "model": "pair", "points": 1}', "bad_message"),
    ('{"type": "open", "model": "pair", "points": 100000}', "bad_message"),
    ('{"type": "open", "model": "pair", "std": "yes"}', "bad_message"),
    ('{"type": "open", "model": "pair", "dofs": "some"}', "bad_message"),
    ('{"type": "open", "model": "pair", "candidates": ["pair"]}', "bad_message"),
    ('{"type": "open", "model": "auto", "candidates": []}', "bad_message"),
    ('{"type": "open", "model": "pair", "robot_state": ["a"]}', "bad_message"),
    ('{"type": "hello", "version": "1"}', "bad_message"),
    ('{"type": "hello", "token": 5}', "bad_message"),
    ("[" * 30000 + "]" * 30000, "bad_json"),  # deep nesting (RecursionError in the parser)
]


@pytest.mark.parametrize("text,code", BAD_TEXT, ids=[f"{i}-{c}" for i, (_, c) in enumerate(BAD_TEXT)])
def test_bad_text_gets_error_and_session_survives(server, test_demo, validator, text, code):
    server_v, _ = validator
    ws = opened(server.ws_url, points=5)
    try:
        reply = rpc(ws, text)
        server_v.validate(reply)
        assert reply["type"] == "error" and reply["code"] == code, reply
        assert reply["message"]
        # the session still works (a bad "open" leaves the previous model open)
        p = rpc(ws, frame_msg(test_demo[0, :2]))
        assert p["type"] == "prediction", p
    finally:
        ws.close()


BAD_BINARY = [b"", b"\x00" * 7, b"\x00" * 24, os.urandom(15), struct.pack("<2d", float("nan"), 1.0),
              struct.pack("<2d", 1.0, float("inf")), struct.pack(">2d", 1.0, 2.0)[:15]]


@pytest.mark.parametrize("data", BAD_BINARY, ids=range(len(BAD_BINARY)))
def test_bad_binary_frames(server, test_demo, data):
    ws = opened(server.ws_url, points=5)
    try:
        reply = rpc(ws, data)
        assert reply["type"] == "error" and reply["code"] == "bad_frame" and reply["seq"] == 1, reply
        assert rpc(ws, frame_msg(test_demo[0, :2]))["seq"] == 2
    finally:
        ws.close()


def test_order_of_messages(server, test_demo):
    ws = connect(server.ws_url)
    try:
        r = rpc(ws, frame_msg([0, 0]))
        assert r["code"] == "not_ready" and "hello" in r["message"]
        r = rpc(ws, {"type": "open", "model": "pair"})
        assert r["code"] == "not_ready"
        assert hello(ws)["type"] == "welcome"
        r = rpc(ws, frame_msg([0, 0]))
        assert r["code"] == "not_open"
        assert rpc(ws, {"type": "reset"})["code"] == "not_open"
        assert rpc(ws, {"type": "close"})["code"] == "not_open"
        assert rpc(ws, {"type": "open", "model": "pair"})["type"] == "opened"
        assert rpc(ws, frame_msg(test_demo[0, :2]))["type"] == "prediction"
        # re-open replaces the session's model
        assert rpc(ws, {"type": "open", "model": "letter_c"})["columns"] == [0, 1]
        assert rpc(ws, frame_msg([0.5, 0.5]))["model"] == "letter_c"
    finally:
        ws.close()


def test_bad_version_closes_with_reason(server):
    ws = connect(server.ws_url)
    ws.send(json.dumps({"type": "hello", "version": 99}))
    code, reason, got = closed_with(ws)
    assert code == P.CLOSE_POLICY and "version 99" in reason
    assert json.loads(got[0])["code"] == "bad_version"


def test_invalid_utf8_text_closes_1007(server, test_demo):
    raw = RawWS(server.server.port)
    raw.send(json.dumps({"type": "hello"}))
    raw.send(b'{"type": "frame", "frame": [1, \xff\xfe]}', opcode=1)
    data = b""
    while True:  # read until the server closes the TCP connection
        chunk = raw.sock.recv(65536)
        if not chunk:
            break
        data += chunk
    raw.close()
    assert struct.pack(">H", 1007) in data  # close frame with 1007 (invalid frame payload data)
    with Client(server.ws_url) as c:  # the server is fine
        c.open("pair")
        assert c.frame(test_demo[0, :2])["seq"] == 1


def test_non_websocket_garbage_on_the_port(server, test_demo):
    for junk in (os.urandom(300), b"GET /ws HTTP/1.1\r\n\r\n", b"\x16\x03\x01\x02\x00\x01\x00\x01\xfc\x03\x03"):
        s = socket.create_connection(("127.0.0.1", server.server.port), timeout=1)
        s.sendall(junk)
        try:
            while s.recv(4096):
                pass
        except OSError:
            pass
        s.close()
    with Client(server.ws_url) as c:
        c.open("pair")
        assert c.frame(test_demo[0, :2])["type"] == "prediction"


def test_disconnect_mid_session(server, test_demo, caplog):
    with caplog.at_level(logging.INFO, logger="interprim.server"):
        before = n_sessions(server)
        raw = RawWS(server.server.port)
        raw.send(json.dumps({"type": "hello"}))
        raw.send(json.dumps({"type": "open", "model": "pair"}))
        for f in test_demo[:20, :2]:
            raw.send(frame_msg(f))
        raw.send(b'{"type": "frame", "fr', opcode=1, fin=False)  # half a fragmented message, then vanish
        raw.sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
        raw.close()  # RST, no close frame
        assert wait_until(lambda: n_sessions(server) == before)
    assert any("without a close frame" in r.getMessage() or "ended" in r.getMessage() for r in caplog.records)
    with Client(server.ws_url) as c:
        c.open("pair")
        assert c.frame(test_demo[0, :2])["seq"] == 1


def test_internal_error_in_model_is_contained(test_demo):
    class Boom:
        observed_dofs_, controlled_dofs_, n_dofs_, dt_, mean_duration_ = [0, 1], [2], 3, 0.01, 1.0

        def stream(self, robot_state=None):
            return self

        def update(self, frame):
            if frame[0] > 100:
                raise RuntimeError("kaboom")
            if frame[0] > 50:
                return type("Pred", (), {"phase": float("nan"), "x": 1, "speed": 1, "duration": 1,
                                         "log_likelihood": 0, "goal": np.zeros(3),
                                         "trajectory": lambda self, n: np.zeros((n, 3))})()
            return type("Pred", (), {"phase": 0.5, "x": 1, "speed": 1, "duration": 1, "log_likelihood": 0,
                                     "goal": np.zeros(3), "trajectory": lambda self, n: np.zeros((n, 3))})()

    srv = InterprimServer({"boom": entry_for("boom", Boom())}, ServerConfig(port=0))
    with ServerThread(srv) as st, Client(st.ws_url) as c:
        c.open("boom", points=4)
        assert c.frame([1.0, 1.0])["phase"] == 0.5
        for bad, what in (([200.0, 0.0], "kaboom"), ([60.0, 0.0], "non-finite")):
            with pytest.raises(ServerError) as e:
                c.frame(bad)
            assert e.value.code == "internal" and what in str(e.value)
        assert c.frame([1.0, 1.0])["phase"] == 0.5


# ---------------------------------------------------------------------------- limits
def test_oversized_message_closes_1009_and_others_continue(strict, test_demo):
    good = opened(strict.ws_url, points=5)
    bad = opened(strict.ws_url, points=5)
    try:
        bad.send(json.dumps({"type": "frame", "frame": [0.0] * 2000}))
        code, reason, _ = closed_with(bad)
        assert code == P.CLOSE_TOO_BIG and "2048" in reason
        assert rpc(good, frame_msg(test_demo[0, :2]))["type"] == "prediction"
    finally:
        good.close()


def test_rate_limit_drops_with_error_and_recovers(strict, test_demo):
    ws = opened(strict.ws_url, points=5)
    try:
        n = 30
        for f in test_demo[:n, :2]:
            ws.send(frame_msg(f))
        replies = [json.loads(ws.recv(timeout=10)) for _ in range(n)]
        assert [r["seq"] for r in replies] == list(range(1, n + 1))  # one reply per frame, in order
        limited = [r for r in replies if r["type"] == "error"]
        assert limited and all(r["code"] == "rate_limited" for r in limited)
        assert replies[0]["type"] == "prediction"
        time.sleep(0.5)  # the bucket refills
        assert rpc(ws, frame_msg(test_demo[0, :2]))["type"] == "prediction"
    finally:
        ws.close()


def test_max_sessions(strict):
    assert wait_until(lambda: n_sessions(strict) == 0)
    held = [opened(strict.ws_url) for _ in range(3)]
    try:
        extra = connect(strict.ws_url)
        code, reason, _ = closed_with(extra)
        assert code == P.CLOSE_TRY_AGAIN and "at most 3" in reason
    finally:
        for ws in held:
            ws.close()
    assert wait_until(lambda: n_sessions(strict) == 0)
    opened(strict.ws_url).close()


def test_too_many_errors_in_a_row(strict):
    ws = connect(strict.ws_url)
    hello(ws)
    try:
        for _ in range(25):
            ws.send("{")
            time.sleep(0.025)  # stay under the rate limit
    except ConnectionClosed:
        pass
    code, reason, got = closed_with(ws)
    assert code == P.CLOSE_POLICY and "too many protocol errors" in reason
    assert all(json.loads(g)["code"] == "bad_json" for g in got)


def test_client_that_never_reads_is_closed(models, test_demo, caplog):
    cfg = ServerConfig(port=0, send_queue=8, write_limit=4096, max_rate_hz=100000, rate_burst=100000, max_points=500)
    srv = InterprimServer({"pair": models["pair"]}, cfg)
    with caplog.at_level(logging.WARNING, logger="interprim.server"), ServerThread(srv) as st:
        raw = RawWS(st.server.port, rcvbuf=4096)
        raw.send(json.dumps({"type": "hello"}))
        raw.send(json.dumps({"type": "open", "model": "pair", "points": 500, "std": False}))
        other = Client(st.ws_url)
        other.open("pair", points=5)
        sent = 0
        try:
            for _ in range(40):  # each reply is ~30 kB; never read them
                for f in test_demo[:50, :2]:
                    raw.send(frame_msg(f))
                    sent += 1
                if "not reading" in caplog.text:
                    break
                assert other.frame(test_demo[0, :2])["type"] == "prediction"  # the other session is served
        except OSError:  # the server gave up on us and reset the connection
            pass
        assert wait_until(lambda: "client is not reading" in caplog.text)
        assert wait_until(lambda: n_sessions(st) == 1)  # only `other` is left
        assert other.frame(test_demo[1, :2])["type"] == "prediction"
        other.close()
        raw.close()


def test_token_required_and_checked(models, test_demo):
    with pytest.raises(ValueError, match="without a token"):
        ServerConfig(host="0.0.0.0").validate()
    ServerConfig(host="0.0.0.0", token="x").validate()
    srv = InterprimServer({"pair": models["pair"]}, ServerConfig(port=0, token="s3cret"))
    with ServerThread(srv) as st:
        for tok in (None, "wrong", "s3cret-but-longer"):
            ws = connect(st.ws_url)
            ws.send(json.dumps({"type": "hello", **({"token": tok} if tok else {})}))
            code, reason, got = closed_with(ws)
            assert code == P.CLOSE_POLICY and "token" in reason
            assert json.loads(got[0])["code"] == "unauthorized"
        with Client(st.ws_url, token="s3cret") as c:
            c.open("pair")
            assert c.frame(test_demo[0, :2])["type"] == "prediction"
        with pytest.raises(urllib.error.HTTPError) as e:
            urllib.request.urlopen(st.url + "api/info")
        assert e.value.code == 401
        assert json.loads(urllib.request.urlopen(st.url + "api/info?token=s3cret").read())["token_required"]


def test_cross_origin_websocket_refused(server):
    with pytest.raises(InvalidStatus) as e:
        connect(server.ws_url, origin="http://evil.example")
    assert e.value.response.status_code == 403
    host = server.url.split("//")[1].rstrip("/")
    ws = connect(server.ws_url, origin=f"http://{host}")  # the page's own origin is fine
    assert hello(ws)["type"] == "welcome"
    ws.close()


# ---------------------------------------------------------------------------- HTTP side
def test_http_routes(server, validator):
    get = lambda p: urllib.request.urlopen(server.url + p)  # noqa: E731
    r = get("")
    assert r.headers["Content-Type"].startswith("text/html") and b"hf-canvas" in r.read()
    assert get("static/app.js").headers["Content-Type"].startswith("text/javascript")
    assert b"InterprimClient" in get("static/ipclient.js").read()
    schema = json.loads(get("static/protocol.schema.json").read())
    assert schema["$defs"]["prediction"]
    info = json.loads(get("api/info").read())
    assert info["protocol"] == P.PROTOCOL_VERSION and {m["name"] for m in info["models"]} >= {"pair"}
    assert get("healthz").read() == b"ok\n"
    for path in ("static/../app.py", "static/%2e%2e/app.py", "static/app.py", "nope", "api/replay/pair",
                 "api/replay/../../etc/passwd"):
        with pytest.raises(urllib.error.HTTPError) as e:
            get(path)
        assert e.value.code == 404, path
    assert json.loads(get("api/replay/letter_c").read())["interactions"]


# ---------------------------------------------------------------------------- start-up
def _serve_parser():
    from interprim.cli import serve as cli

    parser = argparse.ArgumentParser(prog="interprim")
    cli.add_parser(parser.add_subparsers(dest="command"))
    return parser


def test_corrupt_model_fails_at_start(tmp_path, models, capsys):
    bad = tmp_path / "broken.npz"
    bad.write_bytes(b"PK\x03\x04 this is not a model" + os.urandom(64))
    with pytest.raises(ModelFileError, match="broken"):
        load_models([bad])
    good = tmp_path / "good.npz"
    models["pair"].model.save(good)
    assert set(load_models([good])) == {"good"}
    trunc = tmp_path / "trunc.npz"
    trunc.write_bytes(good.read_bytes()[: good.stat().st_size // 2])
    with pytest.raises(ModelFileError, match="trunc"):
        load_models([good, trunc])
    with pytest.raises(FileNotFoundError):
        load_models([tmp_path / "missing.npz"])
    dup = tmp_path / "sub"
    dup.mkdir()
    (dup / "good.npz").write_bytes(good.read_bytes())
    with pytest.raises(ModelFileError, match="unique"):
        load_models([good, dup / "good.npz"])
    # through the command: a clear error before anything listens
    args = _serve_parser().parse_args(["serve", str(bad), "--port", "0"])
    with pytest.raises(ModelFileError, match="cannot serve model 'broken'"):
        args.func(args)


def test_cli_options(tmp_path):
    from interprim.errors import InterprimError

    parser = _serve_parser()
    args = parser.parse_args(["serve", "--host", "0.0.0.0", "--port", "0", "x.npz"])
    with pytest.raises(InterprimError, match="without a token"):
        args.func(args)
    args = parser.parse_args(["serve", "--port", "0"])
    with pytest.raises(InterprimError, match="--demo"):
        args.func(args)
    args = parser.parse_args(["serve", "--max-sessions", "0", "--port", "0", "x.npz"])
    with pytest.raises(InterprimError, match="max_sessions"):
        args.func(args)


def test_cli_module_is_registered():
    from interprim import cli

    assert "interprim.cli.serve" in cli.COMMAND_MODULES


def test_protocol_helpers():
    assert P.softmax([0.0, float("-inf"), float("nan")]) == [1.0, 0.0, 0.0]
    assert P.softmax([-1e308, -1e308]) == [0.5, 0.5]
    np.testing.assert_allclose(P.softmax([-1000.0, -1001.0]), [1 / (1 + np.exp(-1)), np.exp(-1) / (1 + np.exp(-1))])
    assert P.decode_binary_frame(P.encode_binary_frame([1.5, -2.0]), 2).tolist() == [1.5, -2.0]
    with pytest.raises(ValueError):
        P.dumps({"x": float("nan")})


# ---------------------------------------------------------------------------- worker processes
def test_worker_processes_give_the_same_predictions(models, test_demo):
    srv = InterprimServer({"pair": models["pair"], "letter_c": models["letter_c"]},
                          ServerConfig(port=0, processes=2, max_rate_hz=100000, rate_burst=100000))
    with ServerThread(srv) as st:
        assert len(st.server._procs.workers) == 2
        with Client(st.ws_url) as a, Client(st.ws_url) as b:  # consecutive session ids: different workers
            a.open("pair", points=10, std=True)
            b.open("pair", points=10)
            da, db = models["pair"].model.stream(), models["pair"].model.stream()
            for k, f in enumerate(test_demo[:30, :2]):
                pa, pb = a.frame(f), b.frame(f, binary=True)
                ea, eb = da.update(f), db.update(f)
                np.testing.assert_allclose(pa["mean"], ea.trajectory(10)[:, 2:], atol=2e-6)
                np.testing.assert_allclose(pa["std"], ea.std(10)[:, 2:], atol=2e-6)
                np.testing.assert_allclose(pb["mean"], eb.trajectory(10)[:, 2:], atol=2e-6)
                if k == 10:
                    b.reset()
                    db = models["pair"].model.stream()
            with pytest.raises(ServerError) as e:
                a.frame([1.0])
            assert e.value.code == "bad_frame"
            a.close_session()
            with pytest.raises(ServerError) as e:
                a.frame(test_demo[0, :2])
            assert e.value.code == "not_open"
            a.open("letter_c", points=5)
            assert a.frame([0.5, 0.5])["model"] == "letter_c"
        assert wait_until(lambda: n_sessions(st) == 0)


def test_async_client_pipelines_frames(server, models, test_demo):
    import asyncio

    from interprim.server.client import AsyncClient

    async def go():
        c = await AsyncClient.connect(server.ws_url)
        async with c:
            assert c.welcome["type"] == "welcome"
            await c.open("pair", points=8)
            for f in test_demo[:20, :2]:  # pipelined: send all, then read all
                await c.send_frame(f, binary=True)
            replies = [await c.recv() for _ in range(20)]
            await c.send_frame([1.0, 2.0, 3.0])
            err = await c.recv_raw()
            return replies, err

    replies, err = asyncio.run(go())
    assert [r["seq"] for r in replies] == list(range(1, 21))
    direct = models["pair"].model.stream()
    for f in test_demo[:20, :2]:
        d = direct.update(f)
    np.testing.assert_allclose(replies[-1]["mean"], d.trajectory(8)[:, 2:], atol=2e-6)
    assert err["type"] == "error" and err["code"] == "bad_frame" and err["seq"] == 21


def test_fair_queueing_serves_the_cheaper_session_first():
    """The scheduler of a compute lane: among waiting frames, the session that used less compute goes first."""
    import asyncio

    from interprim.server.lanes import _Lane, _Session

    order = []

    async def run(job):
        name, cost = job
        order.append(name)
        time.sleep(cost)  # compute time charged to the session
        return name

    async def go():
        lane = _Lane(run)
        heavy = _Session(1, None, "a", asyncio.Queue(), None)
        light = _Session(2, None, "b", asyncio.Queue(), None)
        # the heavy session queues first; while its first frame runs, both queue one more frame
        f1 = lane.submit(heavy, ("heavy-1", 0.05))
        await asyncio.sleep(0)
        f2 = lane.submit(heavy, ("heavy-2", 0.05))
        f3 = lane.submit(light, ("light-1", 0.0))
        assert await f1 == "heavy-1" and await f2 == "heavy-2" and await f3 == "light-1"
        assert heavy.vtime > light.vtime
        # the light session, having used less compute, overtakes frames the heavy one queued earlier
        f4 = lane.submit(heavy, ("heavy-3", 0.0))
        f5 = lane.submit(light, ("light-2", 0.0))
        await asyncio.gather(f4, f5)

    asyncio.run(go())
    assert order[0] == "heavy-1"
    assert order.index("light-1") < order.index("heavy-2")
    assert order.index("light-2") < order.index("heavy-3")


def test_garbage_connections_are_logged(server, caplog):
    with caplog.at_level(logging.WARNING, logger="interprim.server"):
        s = socket.create_connection(("127.0.0.1", server.server.port), timeout=5)
        s.sendall(b"\x00\x01garbage that is not HTTP\r\n\r\n")
        try:
            while s.recv(4096):
                pass
        except OSError:
            pass
        s.close()
        assert wait_until(lambda: "bad HTTP request" in caplog.text or "no complete handshake" in caplog.text)


def _reply_text(op, frames):
    import re

    from interprim.server.compute import compute_prediction

    return [re.sub(r',"compute_ms":[0-9.]+', "", compute_prediction(op, f, k + 1, 0.5 * k if k % 2 else None))
            for k, f in enumerate(frames)]


@pytest.mark.parametrize("std,dofs", [(False, "controlled"), (True, "all")])
def test_reply_encoding_fast_paths_equal_the_reference(models, test_demo, std, dofs):
    """compute_prediction's cached rollout (mean) and its text head give the message that
    Prediction.trajectory + json.dumps would give; the orjson (float32) and printf (%.7g) number formats agree to their precision."""
    from interprim.server import compute

    e = models["pair"]
    cols = e.controlled_dofs if dofs == "controlled" else list(range(e.n_dofs))
    frames = test_demo[:25, :2]
    op = compute._Open("pair", [e], [e.model.stream()], [cols], 17, std)
    fast = [json.loads(t) for t in _reply_text(op, frames)]
    assert op.heads[0][3].ok  # the cached rollout was checked against Prediction.trajectory and is used
    ref_stream = e.model.stream()
    for k, (f, msg) in enumerate(zip(frames, fast)):
        p = ref_stream.update(f)
        assert list(msg)[:2] == ["type", "seq"] and msg["seq"] == k + 1 and msg["model"] == "pair"
        assert msg["columns"] == cols and (msg.get("t") == (0.5 * k if k % 2 else None))
        for key in ("phase", "x", "speed", "duration", "log_likelihood"):
            assert msg[key] == pytest.approx(float(getattr(p, key)), rel=1e-9, abs=1e-12)
        # orjson: float32 written as its shortest round-trip text (rounding to float32, then the shortest
        # text parsed as float64: <= 2**-23 ~ 1.2e-7 relative); printf %.7g: <= 5e-7 relative
        rtol = 1.2e-7 if (compute._orjson is not None and not compute._FORCE_PRINTF) else 5.0001e-7
        np.testing.assert_allclose(msg["mean"], p.trajectory(17)[:, cols], rtol=rtol, atol=1e-30)
        np.testing.assert_allclose(msg["goal"], p.goal[cols], rtol=rtol, atol=1e-30)
        if std:
            np.testing.assert_allclose(msg["std"], p.std(17)[:, cols], rtol=rtol, atol=1e-30)
    old = compute._FORCE_PRINTF
    compute._FORCE_PRINTF = True  # the encoder used without orjson
    try:
        op2 = compute._Open("pair", [e], [e.model.stream()], [cols], 17, std)
        slow = [json.loads(t) for t in _reply_text(op2, frames)]
    finally:
        compute._FORCE_PRINTF = old
    for a, b in zip(fast, slow):
        assert a.keys() == b.keys()
        np.testing.assert_allclose(a["mean"], b["mean"], rtol=1e-6, atol=1e-7)  # %.7g: 5e-7 relative


def test_nonfinite_predictions_are_never_encoded():
    from interprim.server import compute

    for force in (False, True):
        old = compute._FORCE_PRINTF
        compute._FORCE_PRINTF = force
        try:
            for bad in (np.nan, np.inf, -np.inf):
                with pytest.raises(FloatingPointError):
                    compute._json_array(np.array([[0.0, 1.0], [bad, 2.0]]))
            assert json.loads(compute._json_array(np.array([1e-5, -2.5, 0.0]))) == pytest.approx([1e-5, -2.5, 0.0])
        finally:
            compute._FORCE_PRINTF = old


@pytest.mark.parametrize("kind", ["asyncio", "auto"])
def test_event_loop_choice(models, test_demo, kind):
    from interprim.server.app import new_event_loop

    with pytest.raises(ValueError):
        ServerConfig(loop="trio").validate()
    srv = InterprimServer({"pair": models["pair"]}, ServerConfig(port=0, loop=kind))
    with ServerThread(srv) as st, Client(st.ws_url) as c:
        c.open("pair", points=5)
        assert c.frame(test_demo[0, :2])["type"] == "prediction"
        if kind == "asyncio":
            assert type(st.loop).__module__.startswith("asyncio")
    ev = new_event_loop("auto")
    try:
        uv = pytest.importorskip("uvloop") if kind == "auto" else None
        if uv is not None:
            assert type(ev).__module__.startswith("uvloop")
    finally:
        ev.close()


def test_inline_lane_serves_at_once_only_sessions_not_ahead():
    """The inline lane's shortcut (compute in the session's own task) is taken only while no frame is
    waiting and the session has not used more compute than the others; else the frame is queued."""
    import asyncio

    from interprim.server.lanes import _Lane, _Session

    def run(job):
        name, cost = job
        time.sleep(cost)
        return name

    async def go():
        lane = _Lane(run, sync=True)
        heavy = _Session(1, None, "a", asyncio.Queue(), None)
        light = _Session(2, None, "b", asyncio.Queue(), None)
        assert lane.run_now(heavy, ("heavy-1", 0.02)) == "heavy-1"
        assert lane.run_now(heavy, ("heavy-2", 0.0)) is None  # 20 ms ahead: must queue
        f2 = lane.submit(heavy, ("heavy-2", 0.0))
        assert lane.run_now(light, ("light-1", 0.0)) is None  # a frame is waiting: queue behind it (fair order)
        f3 = lane.submit(light, ("light-1", 0.0))
        order = []
        for f in asyncio.as_completed([f2, f3]):
            order.append(await f)
        assert order == ["light-1", "heavy-2"]  # the lighter session first
        assert lane.run_now(light, ("light-2", 0.0)) == "light-2"

    asyncio.run(go())


@pytest.mark.parametrize("loop", ["asyncio", "uvloop"])
def test_worker_replies_larger_than_the_socket_buffer(models, test_demo, loop):
    """Worker-process replies of several hundred kB (many points + band) arrive whole under either
    event loop (uvloop switches the pipe to non-blocking mode: a regression made it a 'dead worker')."""
    if loop == "uvloop":
        pytest.importorskip("uvloop")  # declared in the [serve] extra on Linux and macOS
    srv = InterprimServer({"pair": models["pair"]}, ServerConfig(port=0, processes=1, loop=loop, max_points=5000,
                                                                   max_rate_hz=100000, rate_burst=100000))
    with ServerThread(srv) as st, Client(st.ws_url) as big, Client(st.ws_url) as small:
        big.open("pair", points=5000, std=True)
        small.open("pair", points=10)
        ref = models["pair"].model.stream()
        for f in test_demo[:12, :2]:
            pb, ps = big.frame(f), small.frame(f)
            e = ref.update(f)
            assert pb["type"] == "prediction" and len(pb["mean"]) == 5000 and len(pb["std"]) == 5000
            np.testing.assert_allclose(ps["mean"], e.trajectory(10)[:, 2:], atol=2e-6)
        assert not st.server._procs.workers[0].dead

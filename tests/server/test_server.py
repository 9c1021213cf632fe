"""The streaming server against real clients on loopback (ephemeral ports, background event loop).

Covers the happy path, every kind of bad input (each must get a clear error on its own
session or a clean close with code + reason, and a log line, without disturbing other sessions),
limits, the token, the HTTP side, and a corrupt model at start-up.  No timing assertions.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import socket
import struct
import time
import urllib.error
import urllib.request

import numpy as np
import pytest

from interprim.models.base import BasePrediction, BaseStream

pytest.importorskip("websockets")

from _server_support import (  # noqa: E402,F401  (fixtures and helpers)
    RawWS,
    closed_with,
    connect,
    covered,
    frame_msg,
    hello,
    models,
    n_sessions,
    opened,
    replies_until,
    rpc,
    server,
    strict,
    test_demo,
    validator,
    wait_until,
)
from websockets.exceptions import ConnectionClosed, InvalidStatus  # noqa: E402

from interprim.core.errors import ModelFileError  # noqa: E402
from interprim.server import protocol as P  # noqa: E402
from interprim.server.app import InterprimServer, ServerConfig, ServerThread  # noqa: E402
from interprim.server.client import Client, ServerError  # noqa: E402
from interprim.server.demo import synthetic_letters  # noqa: E402
from interprim.server.models import entry_for, load_models  # noqa: E402


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
            assert p["frames"] == k and p["conditioned"] is d.conditioned is (k >= op["min_frames"])
            if d.conditioned:
                assert p["phase"] == pytest.approx(d.phase) and p["log_likelihood"] == pytest.approx(d.log_likelihood)
                phases.append(p["phase"])
            else:  # the prior: nothing estimated yet
                assert p["phase"] is p["x"] is p["speed"] is p["duration"] is p["log_likelihood"] is None
        assert op["min_frames"] == 3 and len(phases) == len(test_demo) - 2
        assert phases[-1] > 0.8 and phases[0] < 0.2
        r = c.reset()
        server_v.validate(r)
        assert r == {"type": "reset_done", "seq": len(test_demo)}
        p = c.frame(test_demo[0, :2])
        np.testing.assert_allclose(p["mean"], models["pair"].model.stream().update(test_demo[0, :2]).trajectory(30)[:,
                                                                                                                    2:],
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
        op = c.open("recognise", candidates=names, points=20, dofs="all")
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


def test_auto_probabilities_are_the_recognisers(server, models):
    """Issue 20: "recognise" recognises with interprim.models.recognition.Recogniser (the candidates' likelihoods of the
    observed positions at their own most probable phases, with one noise shared by all), not a softmax of each model's
    own-noise log-likelihood; coalesced frames (one reply for several) count as well, and reset starts over."""
    from interprim.models.recognition import Recogniser

    names = ["letter_c", "letter_s", "letter_u"]
    rec = Recogniser({n: models[n].model for n in names})
    stroke = synthetic_letters("s", 1, seed=7)[0]
    with Client(server.ws_url) as c:
        c.open("recognise", candidates=names, points=10, dofs="all")
        for k in (12, 25, 40):
            for f in stroke[:k]:
                p = c.frame(f)
            want = rec.recognise(stroke[:k])
            for n in names:
                assert p["probabilities"][n] == pytest.approx(want.probabilities[n], abs=2e-6), (k, n)
            assert p["model"] == want.label
            c.reset()
    # pipelined (the server may answer several frames with one reply): the newest reply is the same
    ws = connect(server.ws_url)
    try:
        hello(ws)
        rpc(ws, {"type": "open", "model": "recognise", "candidates": names, "points": 10})
        for f in stroke[:40]:
            ws.send(frame_msg(f))
        got = replies_until(ws, 40, timeout=60)
    finally:
        ws.close()
    assert [q for r in got for q in covered(r)] == list(range(1, 41))
    for n in names:
        assert got[-1]["probabilities"][n] == pytest.approx(want.probabilities[n], abs=2e-6)


def test_auto_refuses_candidates_of_different_sizes(server, models):
    with Client(server.ws_url) as c:
        with pytest.raises(ServerError) as e:
            c.open("recognise", candidates=["pair", "missing"])
        assert e.value.code == "unknown_model" and "missing" in str(e.value)
        for kw in ({"candidates": ["pair", "one"]}, {}):  # default candidates: all loaded models
            with pytest.raises(ServerError) as e:
                c.open("recognise", **kw)
            assert e.value.code == "bad_message" and "observe the same number of DoFs" in str(e.value)
        assert c.open("recognise", candidates=["pair", "letter_c"])["type"] == "opened"  # both observe 2 DoFs
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
    ('{"type": "open", "model": "recognise", "candidates": []}', "bad_message"),
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
        raw = RawWS(server.server.port)
        # this connection's own session, by its address and port (a count of all sessions would also see an
        # earlier test's session still leaving on a busy machine)
        me = "%s:%s" % raw.sock.getsockname()[:2]

        def mine():
            return server.call(lambda: [s.id for s in server.server.sessions.values() if s.peer == me])

        raw.send(json.dumps({"type": "hello"}))
        raw.send(json.dumps({"type": "open", "model": "pair"}))
        for f in test_demo[:20, :2]:
            raw.send(frame_msg(f))
        # the session exists once its hello is accepted (a connection holds no slot before): vanish only then
        assert wait_until(lambda: len(mine()) == 1)
        raw.send(b'{"type": "frame", "fr', opcode=1, fin=False)  # half a fragmented message, then vanish
        raw.sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
        raw.close()  # RST, no close frame
        assert wait_until(lambda: not mine())
        # the session leaves the table before its last log line is written: wait for the line, not only the count
        assert wait_until(lambda: any("without a close frame" in r.getMessage() or "ended" in r.getMessage()
                                      for r in caplog.records))
    with Client(server.ws_url) as c:
        c.open("pair")
        assert c.frame(test_demo[0, :2])["seq"] == 1


def test_internal_error_in_model_is_contained(test_demo):
    class Boom(BaseStream):  # a stand-in model that is its own stream (the contract's BaseStream)
        observed_dofs_, controlled_dofs_, n_dofs_, dt_, mean_duration_ = [0, 1], [2], 3, 0.01, 1.0
        n_frames = 0

        def stream(self, robot_state=None):
            return self

        def reset(self, robot_state=None):
            pass

        def update(self, frame, need_cov=False):
            if frame[0] > 100:
                raise RuntimeError("kaboom")
            fields = {"phase": float("nan") if frame[0] > 50 else 0.5, "x": 1, "speed": 1, "duration": 1,
                      "log_likelihood": 0, "goal": np.zeros(3), "trajectory": lambda self, n: np.zeros((n, 3))}
            return type("Pred", (BasePrediction,), fields)()

    srv = InterprimServer({"boom": entry_for("boom", Boom())}, ServerConfig(port=0))
    with ServerThread(srv) as st, Client(st.ws_url) as c:
        c.open("boom", points=4)
        assert c.frame([1.0, 1.0])["phase"] == 0.5
        for bad, what in (([200.0, 0.0], "kaboom"), ([60.0, 0.0], "non-finite")):
            with pytest.raises(ServerError) as e:
                c.frame(bad)
            assert e.value.code == "internal" and what in str(e.value)
        assert c.frame([1.0, 1.0])["phase"] == 0.5
        # "recognise" recognises with the Recogniser, which takes fitted InteractionPrimitives only: refused at open,
        # with the reason, instead of a rule that lets the model with the smallest noise win
        srv2_models = {"boom": entry_for("boom", Boom()), "boom2": entry_for("boom2", Boom())}
    srv2 = InterprimServer(srv2_models, ServerConfig(port=0))
    with ServerThread(srv2) as st, Client(st.ws_url) as c:
        with pytest.raises(ServerError) as e:
            c.open("recognise", candidates=["boom", "boom2"])
        assert e.value.code == "bad_message" and "cannot recognise" in str(e.value) and "boom" in str(e.value)
        c.open("boom", points=4)  # the session goes on
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
        replies = replies_until(ws, n)
        # every frame answered once, in order (a prediction may cover several frames sent back to back)
        assert [q for r in replies for q in covered(r)] == list(range(1, n + 1))
        limited = [r for r in replies if r["type"] == "error"]
        assert limited and all(r["code"] == "rate_limited" and "first_seq" not in r for r in limited)  # one per frame
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


@pytest.mark.slow  # waits for the send buffer to fill and time out
def test_client_that_never_reads_is_closed(models, test_demo, caplog):
    cfg = ServerConfig(port=0, send_queue=8, write_limit=4096, max_rate_hz=100000, rate_burst=100000, max_points=500)
    srv = InterprimServer({"pair": models["pair"]}, cfg)
    with caplog.at_level(logging.WARNING, logger="interprim.server"), ServerThread(srv) as st:
        raw = RawWS(st.server.port, rcvbuf=4096)
        raw.send(json.dumps({"type": "hello"}))
        raw.send(json.dumps({"type": "open", "model": "pair", "points": 500, "std": False}))
        other = Client(st.ws_url)
        other.open("pair", points=5)
        raw_id = st.call(lambda: min(st.server.sessions))

        def answered():  # frames of the raw session answered so far (None once the server has closed it)
            s = st.server.sessions.get(raw_id)
            return None if s is None or s.closing else s.predictions + s.coalesced

        sent = 0
        try:
            # each reply is ~30 kB; never read them.  Frames sent back to back may be answered by one reply
            # (coalesced): wait for each frame's reply to be made, so that each gets one; 2000 x 30 kB is more
            # than the sockets' buffers hold
            for f in np.tile(test_demo[:50, :2], (40, 1)):
                raw.send(frame_msg(f))
                sent += 1
                assert wait_until(lambda: st.call(answered) in (None, sent))
                if st.call(answered) is None:
                    break
                if sent % 50 == 0:
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
    from interprim.core.errors import InterprimError

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


def test_cli_replay_and_units_for_a_model_file(tmp_path):
    """``interprim serve m.npz --replay m=demos.csv --units m=...``: the page's replay data and labels."""
    import interprim as ip
    from interprim.cli.serve import _attach_replays, _attach_units
    from interprim.core.errors import InterprimError
    from interprim.datasets import save_demonstrations
    from interprim.synthetic import two_agent_demos

    names = ["a", "b", "c", "d", "e"]
    demos = two_agent_demos(6, seed=1, frames=60)
    save_demonstrations(tmp_path / "d.csv", demos, dt=0.01, columns=names)
    ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=6).fit(demos, dt=0.01, columns=names).save(tmp_path / "m.npz")
    models = load_models([tmp_path / "m.npz"])
    _attach_units(models, ["m=rad,,rad,m,m"])
    _attach_replays(models, [f"m={tmp_path / 'd.csv'}"])
    e = models["m"]
    assert e.units == ["rad", None, "rad", "m", "m"] and e.describe()["replay"] is True
    r = e.meta["replay"]
    assert r["columns"] == names and r["units"] == e.units and len(r["interactions"]) == 6 and "d.csv" in r["source"]
    np.testing.assert_allclose(r["interactions"][0]["observed"], demos[0][:, :2], atol=1e-6)
    np.testing.assert_allclose(r["interactions"][0]["controlled_truth"], demos[0][:, 2:], atol=1e-6)
    # columns are matched by name: a file with the columns in another order gives the same replay
    save_demonstrations(tmp_path / "shuffled.csv", [d[:, ::-1] for d in demos], dt=0.01, columns=names[::-1])
    _attach_replays(models, [f"m={tmp_path / 'shuffled.csv'}"])
    np.testing.assert_allclose(e.meta["replay"]["interactions"][0]["observed"], demos[0][:, :2], atol=1e-6)
    save_demonstrations(tmp_path / "other.csv", [d[:, :4] for d in demos], dt=0.01, columns=names[:4])
    for call, arg, match in ((_attach_units, "m=rad,rad", "2 units for 5 columns"),
                             (_attach_units, "x=rad", "no model named 'x'"),
                             (_attach_units, "m", "MODEL=VALUE"),
                             (_attach_replays, f"m={tmp_path / 'missing.csv'}", "missing.csv"),
                             (_attach_replays, f"m={tmp_path / 'other.csv'}", "'e'")):
        with pytest.raises(InterprimError, match=match):
            call(models, [arg])


def test_schema_covers_labels_first_frames_and_recovered_seq(server, validator, test_demo):
    """The schema accepts what the server now sends (labels per candidate, unconditioned replies, an error with
    a recovered seq and t) and the client messages the protocol allows (both robot_state forms, reset's)."""
    server_v, client_v = validator
    names = ["letter_c", "letter_s"]
    ws = connect(server.ws_url)
    try:
        hello(ws)
        op = rpc(ws, {"type": "open", "model": "recognise", "candidates": names, "std": True, "points": 4})
        server_v.validate(op)
        assert set(op["column_names"]) == set(names) and op["observed_units"] == {n: [None, None] for n in names}
        p = rpc(ws, frame_msg([0.5, 0.5]))
        server_v.validate(p)
        assert p["conditioned"] is False and p["phase"] is None and p["probabilities"] == {n: 0.5 for n in names}
        e = rpc(ws, '{"type": "frame", "frame": [NaN, 1], "t": 4}')
        server_v.validate(e)
        assert e["code"] == "bad_json" and e["seq"] == 2 and e["t"] == 4
        op = rpc(ws, {"type": "open", "model": "pair", "robot_state": [[0.1, 0.2, 0.3], [0.0, 0.0, 1.0]]})
        server_v.validate(op)
        assert op["column_names"] == ["dof_2", "dof_3", "dof_4"] and op["column_units"] == [None] * 3
    finally:
        ws.close()
    for msg in ({"type": "open", "model": "pair", "robot_state": [0.1, 0.2, 0.3]},
                {"type": "open", "model": "pair", "robot_state": [[0.1, 0.2, 0.3], [0.0, 0.0, 1.0]]},
                {"type": "reset", "robot_state": [0.1, 0.2, 0.3]}, {"type": "reset"}):
        client_v.validate(msg)
    import jsonschema

    for bad in ({"type": "open", "robot_state": [[0.1], [0.2], [0.3]]}, {"type": "open", "robot_state": "x"}):
        with pytest.raises(jsonschema.ValidationError):
            client_v.validate(bad)

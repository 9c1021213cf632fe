"""Fixtures and helpers of the server tests (test_server.py, test_server_internals.py)."""

from __future__ import annotations

import base64
import json
import os
import socket
import struct
import time
from pathlib import Path

import pytest

pytest.importorskip("websockets")

from websockets.exceptions import ConnectionClosed  # noqa: E402
from websockets.sync.client import connect as _connect  # noqa: E402

import interprim as ip  # noqa: E402
from interprim.server.app import InterprimServer, ServerConfig, ServerThread  # noqa: E402
from interprim.server.demo import letter_models  # noqa: E402
from interprim.server.models import entry_for  # noqa: E402
from interprim.synthetic import two_agent_demos  # noqa: E402

SCHEMA_PATH = Path(__file__).resolve().parents[1] / "src" / "interprim" / "server" / "static" / "protocol.schema.json"


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


def covered(reply) -> list:
    """The frame seqs a reply answers: ``first_seq .. seq`` (a prediction or error may cover several frames)."""
    seq = reply["seq"]
    return list(range(reply.get("first_seq", seq), seq + 1))


def replies_until(ws, last_seq, timeout=10):
    """Read replies until the one that answers frame ``last_seq``; returns them all (parsed)."""
    got = []
    while True:
        r = json.loads(ws.recv(timeout=timeout))
        got.append(r)
        if r.get("seq") == last_seq:
            return got


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

    def __init__(self, port, rcvbuf=None, path="/ws", source=None):
        s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        if rcvbuf:
            s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, rcvbuf)
        if source:  # another loopback address (127.0.0.0/8): another client for the server's fair queuing
            s.bind((source, 0))
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

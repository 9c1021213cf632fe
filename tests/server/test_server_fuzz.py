"""Protocol fuzz test (hypothesis): random message sequences never crash the server or break a session.

Every example opens a fresh session on a real loopback server, sends 1-6 random messages (random JSON
values, random "client-like" objects with wrong field types/lengths/NaN, random bytes), then a valid
sentinel frame.  Invariants: every reply is valid JSON conforming to the protocol's JSON schema; the
session either answers the sentinel or was closed with a documented code and a reason; and after
each example a fresh session is served normally.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

pytest.importorskip("websockets")
hypothesis = pytest.importorskip("hypothesis")
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402
from websockets.exceptions import ConnectionClosed  # noqa: E402
from websockets.sync.client import connect as _connect  # noqa: E402

import interprim as ip  # noqa: E402
from interprim.server.app import InterprimServer, ServerConfig, ServerThread  # noqa: E402
from interprim.server.models import entry_for  # noqa: E402
from interprim.synthetic import two_agent_demos  # noqa: E402

SCHEMA = json.loads((Path(__file__).resolve().parents[2] / "src" / "interprim" / "server" / "static"
                     / "protocol.schema.json").read_text())
ALLOWED_CLOSE = {1000, 1007, 1008, 1009}


def connect(url):
    try:
        return _connect(url, legacy=True, close_timeout=2)
    except TypeError:
        return _connect(url, close_timeout=2)


@pytest.fixture(scope="module")
def fuzz_server():
    train = two_agent_demos(8, seed=0, frames=60)
    m = ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=6).fit(train, dt=0.01)
    srv = InterprimServer({"pair": entry_for("pair", m)},
                          ServerConfig(port=0, max_message_bytes=4096, max_rate_hz=100000, rate_burst=100000))
    with ServerThread(srv) as s:
        yield s


@pytest.fixture(scope="module")
def validator():
    jsonschema = pytest.importorskip("jsonschema")
    schema = dict(SCHEMA, **{"$ref": "#/$defs/server_message"})
    schema.pop("oneOf")
    return jsonschema.validators.validator_for(schema)(schema)


scalars = st.one_of(st.none(), st.booleans(), st.integers(-10**30, 10**30), st.floats(allow_nan=True),
                    st.text(max_size=20))
json_values = st.recursive(scalars, lambda c: st.one_of(st.lists(c, max_size=4),
                                                        st.dictionaries(st.text(max_size=8), c, max_size=4)),
                           max_leaves=12)
field_values = st.one_of(json_values, st.lists(st.floats(allow_nan=True, allow_infinity=True), max_size=5),
                         st.sampled_from(["pair", "recognise", "auto", "nope", "all", "controlled"]))
client_like = st.fixed_dictionaries(
    {"type": st.sampled_from(["hello", "open", "frame", "reset", "close", "bogus", 3, None])},
    optional={k: field_values for k in ("model", "frame", "points", "std", "dofs", "candidates", "t", "version",
                                        "token", "robot_state")},
)


def _encode(v) -> str | bytes:
    if isinstance(v, bytes):
        return v
    if isinstance(v, str):
        return v
    return json.dumps(v, allow_nan=True)  # NaN/Infinity tokens on purpose


messages = st.lists(st.one_of(client_like, json_values, st.binary(max_size=40), st.text(max_size=40),
                              st.binary(min_size=16, max_size=16)), min_size=1, max_size=6)


@settings(max_examples=50, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture,
                                                                 HealthCheck.too_slow])
@pytest.mark.slow  # hundreds of generated message sequences
@given(msgs=messages)
def test_protocol_fuzz(fuzz_server, validator, msgs):
    ws = connect(fuzz_server.ws_url)
    try:
        ws.send(json.dumps({"type": "hello", "version": 1}))
        assert json.loads(ws.recv(timeout=10))["type"] == "welcome"
        ws.send(json.dumps({"type": "open", "model": "pair", "points": 4}))
        assert json.loads(ws.recv(timeout=10))["type"] == "opened"
        replies, closed = [], None
        try:
            for m in msgs:
                ws.send(_encode(m))
            ws.send(json.dumps({"type": "open", "model": "pair", "points": 4}))
            ws.send(json.dumps({"type": "frame", "frame": [0.1, 0.2], "t": 424242}))
            while True:
                r = json.loads(ws.recv(timeout=10))
                validator.validate(r)
                replies.append(r)
                if r.get("type") == "prediction" and r.get("t") == 424242:
                    break
        except ConnectionClosed as exc:
            closed = exc.rcvd
        if closed is not None:
            assert closed.code in ALLOWED_CLOSE and closed.reason, closed
    finally:
        ws.close()
    # the server still serves a fresh session
    ws = connect(fuzz_server.ws_url)
    try:
        ws.send(json.dumps({"type": "hello"}))
        ws.recv(timeout=10)
        ws.send(json.dumps({"type": "open", "model": "pair", "points": 4}))
        ws.recv(timeout=10)
        ws.send(json.dumps({"type": "frame", "frame": [0.0, 0.0]}))
        assert json.loads(ws.recv(timeout=10))["type"] == "prediction"
    finally:
        ws.close()

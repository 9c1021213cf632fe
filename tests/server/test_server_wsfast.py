"""The server's per-frame fast path (interprim.server.wsfast): frames split out of the TCP stream by the server
itself and replies written at once.  Whatever way the bytes arrive (many messages in one write, a message split
over several), and whatever is mixed in (control messages, fragmented messages, pings, bad frames), every
message is answered once and in order, and malformed WebSocket frames get the library's close codes."""

from __future__ import annotations

import json
import os
import socket
import struct
import time

import numpy as np
import pytest

pytest.importorskip("websockets")

from _server_support import (  # noqa: E402,F401  (fixtures and helpers)
    RawWS,
    frame_msg,
    models,
    server,
    test_demo,
)

from interprim.server import wsfast  # noqa: E402
from interprim.server.protocol import encode_binary_frame  # noqa: E402


def _client_frame(payload: bytes, opcode: int, fin: bool = True, rsv: int = 0, mask: bool = True) -> bytes:
    """One client frame (RFC 6455 Sec. 5.2), masked unless told otherwise."""
    head = bytes([(0x80 if fin else 0) | rsv | opcode])
    n = len(payload)
    m = 0x80 if mask else 0
    if n < 126:
        head += bytes([m | n])
    elif n < 65536:
        head += bytes([m | 126]) + struct.pack(">H", n)
    else:
        head += bytes([m | 127]) + struct.pack(">Q", n)
    if not mask:
        return head + payload
    key = os.urandom(4)
    return head + key + bytes(b ^ key[i % 4] for i, b in enumerate(payload))


def _text(obj) -> bytes:
    return _client_frame((obj if isinstance(obj, str) else json.dumps(obj)).encode(), 1)


class _Reader:
    """Reads the server's (unmasked) frames from a raw socket: ``(opcode, payload)``."""

    def __init__(self, sock):
        self.sock, self.buf = sock, b""

    def _need(self, n, deadline):
        while len(self.buf) < n:
            self.sock.settimeout(max(0.05, deadline - time.monotonic()))
            chunk = self.sock.recv(65536)
            if not chunk:
                raise ConnectionError("closed")
            self.buf += chunk

    def frame(self, timeout=30.0):
        deadline = time.monotonic() + timeout
        self._need(2, deadline)
        b0, b1 = self.buf[0], self.buf[1]
        n, h = b1 & 0x7F, 2
        if n == 126:
            self._need(4, deadline)
            n, h = struct.unpack(">H", self.buf[2:4])[0], 4
        elif n == 127:
            self._need(10, deadline)
            n, h = struct.unpack(">Q", self.buf[2:10])[0], 10
        self._need(h + n, deadline)
        payload, self.buf = self.buf[h:h + n], self.buf[h + n:]
        return b0 & 0x0F, payload

    def messages(self, until, timeout=30.0):
        """Text messages (parsed) and pongs (``("pong", payload)``) until ``until(msg)`` holds for one."""
        out = []
        while True:
            op, payload = self.frame(timeout)
            msg = json.loads(payload) if op == 1 else ("pong", payload) if op == 10 else ("op", op, payload)
            out.append(msg)
            if until(msg):
                return out


def _answers(replies):
    """Frame seqs in reply order (a prediction covers first_seq .. seq; an error with a seq answers it)."""
    seqs = []
    for r in replies:
        if isinstance(r, dict) and r.get("type") in ("prediction", "error") and "seq" in r:
            seqs += list(range(r.get("first_seq", r["seq"]), r["seq"] + 1))
    return seqs


def _send_chunked(sock, data: bytes, sizes):
    """``data`` in pieces of the given sizes (cycled), each its own send (TCP_NODELAY: separate segments)."""
    sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    i = k = 0
    while i < len(data):
        n = sizes[k % len(sizes)]
        sock.sendall(data[i:i + n])
        i += n
        k += 1
        if k % 7 == 0:
            time.sleep(0.002)  # let some pieces arrive alone


@pytest.mark.parametrize("sizes", [[1 << 20], [1], [3, 1, 7, 2], [23, 5, 64, 9, 2]],
                         ids=["one-write", "byte-by-byte", "small-pieces", "mixed-pieces"])
def test_messages_in_any_pieces_are_answered_once_in_order(server, test_demo, sizes):
    frames = test_demo[:12, :2]
    script = [_text({"type": "hello"}), _text({"type": "open", "model": "pair", "points": 5})]
    script += [_text(frame_msg(f)) for f in frames[:4]]  # seq 1-4, JSON
    script += [_client_frame(encode_binary_frame(f), 2) for f in frames[4:6]]  # seq 5-6, binary
    script += [_client_frame(b"\x00" * 12, 2)]  # seq 7: a binary frame of the wrong size -> bad_frame
    script += [_client_frame(b"ping!", 9)]  # a ping between two frames -> pong
    msg = frame_msg(frames[6]).encode()  # seq 8 as a fragmented message (the library's path)
    script += [_client_frame(msg[:10], 1, fin=False), _client_frame(msg[10:], 0)]
    script += [_text('{"type": "frame", "frame": [1.0, NaN]}')]  # seq 9: not JSON (NaN), still a frame
    script += [_text(frame_msg(f)) for f in frames[7:9]]  # seq 10-11
    script += [_text({"type": "reset"})]
    script += [_text(frame_msg(f)) for f in frames[9:12]]  # seq 12-14
    script += [_text({"type": "close"})]
    raw = RawWS(server.server.port)
    try:
        _send_chunked(raw.sock, b"".join(script), sizes)
        replies = _Reader(raw.sock).messages(lambda m: isinstance(m, dict) and m.get("type") == "closed")
    finally:
        raw.close()
    # the pong is the library's answer to a WebSocket ping, sent when the ping is read (not a protocol reply)
    assert [m for m in replies if not isinstance(m, dict)] == [("pong", b"ping!")]
    kinds = [m["type"] for m in replies if isinstance(m, dict)]
    assert kinds[:2] == ["welcome", "opened"]
    assert kinds[-1] == "closed" and replies[-1]["seq"] == 14
    dicts = [m for m in replies if isinstance(m, dict)]
    assert _answers(dicts) == list(range(1, 15))  # every frame once, in order
    errors = {m["seq"]: m["code"] for m in dicts if m["type"] == "error"}
    assert errors == {7: "bad_frame", 9: "bad_json"}
    order = [(m["type"], m.get("seq")) for m in dicts if m["type"] in ("error", "reset_done")]
    assert order == [("error", 7), ("error", 9), ("reset_done", 11)]
    # the reset comes after the answer to frame 11 and before the answers to 12-14
    i_reset = next(i for i, m in enumerate(dicts) if m["type"] == "reset_done")
    assert max(_answers(dicts[:i_reset])) == 11 and min(_answers(dicts[i_reset:])) == 12
    assert all(m["type"] != "error" or m["code"] != "internal" for m in dicts)


def test_the_numbers_do_not_depend_on_the_path(server, test_demo):
    """A frame's prediction is the same whether the frame came alone (and was answered alone) or in one TCP write
    with others: the last reply of a session fed all at once equals that of a session fed frame by frame."""
    frames = test_demo[:15, :2]
    head = [_text({"type": "hello"}), _text({"type": "open", "model": "pair", "points": 6})]
    one = RawWS(server.server.port)
    try:
        one.sock.sendall(b"".join(head))
        rd = _Reader(one.sock)
        rd.messages(lambda m: isinstance(m, dict) and m.get("type") == "opened")
        last = None
        for f in frames:
            one.sock.sendall(_client_frame(encode_binary_frame(f), 2))
            last = rd.messages(lambda m: isinstance(m, dict) and m.get("type") == "prediction")[-1]
    finally:
        one.close()
    assert last["seq"] == 15 and last["covers"] == 1
    many = RawWS(server.server.port)
    try:
        many.sock.sendall(b"".join(head + [_client_frame(encode_binary_frame(f), 2) for f in frames]))
        got = _Reader(many.sock).messages(lambda m: isinstance(m, dict) and m.get("seq") == 15)
    finally:
        many.close()
    assert _answers([m for m in got if isinstance(m, dict)]) == list(range(1, 16))
    np.testing.assert_allclose(got[-1]["mean"], last["mean"], rtol=1e-5, atol=1e-6)
    assert got[-1]["phase"] == pytest.approx(last["phase"], rel=1e-5)


def _closed_with(port, data: bytes) -> int | None:
    """Send ``data`` after hello + open; the close code the server sends (None: none within the time)."""
    raw = RawWS(port)
    try:
        raw.sock.sendall(_text({"type": "hello"}) + _text({"type": "open", "model": "pair"}))
        rd = _Reader(raw.sock)
        rd.messages(lambda m: isinstance(m, dict) and m.get("type") == "opened")
        raw.sock.sendall(data)
        while True:
            op, payload = rd.frame(timeout=20)
            if op == 8:
                return struct.unpack(">H", payload[:2])[0] if len(payload) >= 2 else None
    except (ConnectionError, OSError):
        return None
    finally:
        raw.close()


@pytest.mark.parametrize("case,code", [("unmasked", 1002), ("rsv-bit", 1002), ("bad-utf8", 1007),
                                       ("unknown-opcode", 1002)])
def test_malformed_websocket_frames_close_with_the_libraries_code(server, test_demo, case, code):
    """Frames the fast path does not take go to the websockets library, which closes as it always did."""
    ok = _client_frame(encode_binary_frame(test_demo[0, :2]), 2)
    bad = {
        "unmasked": _client_frame(frame_msg(test_demo[1, :2]).encode(), 1, mask=False),
        "rsv-bit": _client_frame(frame_msg(test_demo[1, :2]).encode(), 1, rsv=0x40),
        "bad-utf8": _client_frame(b'{"type": "frame", "frame": [1, \xff\xfe]}', 1),
        "unknown-opcode": _client_frame(b"x", 3),
    }[case]
    assert _closed_with(server.server.port, ok + bad + ok) == code
    # the server goes on serving others
    raw = RawWS(server.server.port)
    try:
        raw.sock.sendall(_text({"type": "hello"}) + _text({"type": "open", "model": "pair"}) + ok)
        got = _Reader(raw.sock).messages(lambda m: isinstance(m, dict) and m.get("type") == "prediction")
        assert got[-1]["seq"] == 1
    finally:
        raw.close()


def test_frame_header_lengths():
    for n in (0, 1, 125, 126, 65535, 65536, 70000):
        h = wsfast.frame_header(1, n)
        assert h[0] == 0x81
        if n < 126:
            assert len(h) == 2 and h[1] == n
        elif n < 65536:
            assert len(h) == 4 and h[1] == 126 and struct.unpack(">H", h[2:])[0] == n
        else:
            assert len(h) == 10 and h[1] == 127 and struct.unpack(">Q", h[2:])[0] == n

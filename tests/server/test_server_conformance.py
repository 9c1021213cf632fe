"""RFC 6455 conformance of the server's own frame path (:mod:`interprim.server.wsfast`), against the websockets
library itself.

Each case is a sequence of client frames sent after ``hello`` + ``open``, one write per frame with a short pause
between (so that the session's handler has taken the frames before, as it would on a real network).  The
cases follow those of the websockets library's own protocol tests (``tests/test_protocol.py`` there:
fragmentation and continuation frames, control frames inside and outside fragmented messages, masking,
reserved bits, opcodes, UTF-8, message sizes, close frames).  Every case is sent to a server with the fast
path and to one without it (the library parses every byte); the answers (reply types and seqs, pongs, the
close code) must be the same, and the close code the one the library's tests expect.

Issue 30, finding 2: a whole text frame inside a fragmented message was taken by the fast path and answered
(out of order) where the library closes with 1002 "expected a continuation frame".
"""

from __future__ import annotations

import json
import os
import struct
import time

import pytest

pytest.importorskip("websockets")

from _server_support import RawWS, models  # noqa: E402,F401

from interprim.server.app import InterprimServer, ServerConfig, ServerThread  # noqa: E402

MAX_BYTES = 4096


def _frame(payload: bytes, opcode: int, fin: bool = True, rsv: int = 0, mask: bool = True) -> bytes:
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


TEXT, BINARY, CONT, CLOSE, PING, PONG = 1, 2, 0, 8, 9, 10
F1 = json.dumps({"type": "frame", "frame": [0.1, 0.2]}).encode()
F2 = json.dumps({"type": "frame", "frame": [0.3, 0.4]}).encode()
BIN = struct.pack("<2d", 0.1, 0.2)

# name -> (frames, expected close code or None for a connection that stays open)
CASES = {
    "text inside a fragmented text": ([_frame(F1[:9], TEXT, fin=False), _frame(F2, TEXT), _frame(F1[9:], CONT)], 1002),
    "binary inside a fragmented binary": ([_frame(BIN[:5], BINARY, fin=False), _frame(BIN, BINARY),
                                           _frame(BIN[5:], CONT)], 1002),
    "text inside a fragmented binary": ([_frame(BIN[:5], BINARY, fin=False), _frame(F2, TEXT)], 1002),
    "binary inside a fragmented text": ([_frame(F1[:9], TEXT, fin=False), _frame(BIN, BINARY)], 1002),
    "unexpected continuation": ([_frame(F1, CONT)], 1002),
    "continuation after a whole message": ([_frame(F1, TEXT), _frame(F2, CONT)], 1002),
    "fragmented text in three parts": ([_frame(F1[:5], TEXT, fin=False), _frame(F1[5:12], CONT, fin=False),
                                        _frame(F1[12:], CONT), _frame(F2, TEXT)], None),
    "fragmented binary": ([_frame(BIN[:3], BINARY, fin=False), _frame(BIN[3:], CONT), _frame(F2, TEXT)], None),
    "ping inside a fragmented text": ([_frame(F1[:9], TEXT, fin=False), _frame(b"hi", PING), _frame(F1[9:], CONT),
                                       _frame(F2, TEXT)], None),
    "pong inside a fragmented text": ([_frame(F1[:9], TEXT, fin=False), _frame(b"", PONG), _frame(F1[9:], CONT)], None),
    # the library fails the connection: "incomplete fragmented message"
    "close inside a fragmented text": ([_frame(F1[:9], TEXT, fin=False), _frame(struct.pack(">H", 1000), CLOSE)],
                                       1002),
    "fragmented ping": ([_frame(b"", PING, fin=False)], 1002),
    "fragmented close": ([_frame(struct.pack(">H", 1000), CLOSE, fin=False)], 1002),
    "ping over 125 bytes": ([_frame(b"x" * 126, PING)], 1002),
    "unmasked text": ([_frame(F1, TEXT, mask=False)], 1002),
    "unmasked continuation": ([_frame(F1[:9], TEXT, fin=False), _frame(F1[9:], CONT, mask=False)], 1002),
    "reserved bit 1": ([_frame(F1, TEXT, rsv=0x40)], 1002),
    "reserved bit 3": ([_frame(F1, TEXT, rsv=0x10)], 1002),
    "reserved opcode 3": ([_frame(b"x", 3)], 1002),
    "reserved control opcode 11": ([_frame(b"", 11)], 1002),
    "invalid UTF-8": ([_frame(b'{"type": "frame", "frame": [1, \xff]}', TEXT)], 1007),
    "invalid UTF-8 across fragments": ([_frame(b'{"type": "frame", "x": "\xe2', TEXT, fin=False),
                                        _frame(b'\x28"}', CONT)], 1007),
    "UTF-8 character split across fragments": ([_frame('{"type": "frame", "frame": [0.1, 0.2], "x": "\u00e9'
                                                       .encode()[:-1], TEXT, fin=False),
                                                _frame('\u00e9"}'.encode()[-3:], CONT)], None),
    "message over max_size": ([_frame(b"[" + b"0," * MAX_BYTES + b"0]", TEXT)], 1009),
    "fragmented message over max_size": ([_frame(b"[" + b"0," * (MAX_BYTES // 4), TEXT, fin=False),
                                          _frame(b"0," * (MAX_BYTES // 4), CONT, fin=False),
                                          _frame(b"0," * (MAX_BYTES // 4), CONT, fin=False),
                                          _frame(b"0]", CONT)], 1009),
    "close with a 1-byte payload": ([_frame(b"\x03", CLOSE)], 1002),
    "close with code 999": ([_frame(struct.pack(">H", 999), CLOSE)], 1002),
    "close with a reserved code 1005": ([_frame(struct.pack(">H", 1005), CLOSE)], 1002),
    "close with a non-UTF-8 reason": ([_frame(struct.pack(">H", 1000) + b"\xff\xff", CLOSE)], 1007),
    "close 1001": ([_frame(struct.pack(">H", 1001) + b"bye", CLOSE)], 1001),
    "many whole messages": ([_frame(F1, TEXT), _frame(BIN, BINARY), _frame(F2, TEXT)], None),
}


@pytest.fixture(scope="module")
def pair(models):
    """Two servers on the same model: with the fast path, and with the library doing everything."""
    out = []
    for fast in (True, False):
        cfg = ServerConfig(port=0, fast_path=fast, max_message_bytes=MAX_BYTES, max_rate_hz=1e5, rate_burst=10**5)
        out.append(ServerThread(InterprimServer({"pair": models["pair"]}, cfg)).start())
    yield out
    for st in out:
        st.stop()


def _read(sock, deadline, want=None):
    """The server's frames until it closes, ``want`` frames came, or ``deadline``: a list of ``(opcode, payload)``."""
    buf, out = b"", []
    while time.monotonic() < deadline and (want is None or len(out) < want):
        while len(buf) >= 2:
            n, h = buf[1] & 0x7F, 2
            if n == 126:
                if len(buf) < 4:
                    break
                n, h = struct.unpack(">H", buf[2:4])[0], 4
            elif n == 127:
                if len(buf) < 10:
                    break
                n, h = struct.unpack(">Q", buf[2:10])[0], 10
            if len(buf) < h + n:
                break
            out.append((buf[0] & 0x0F, buf[h:h + n]))
            buf = buf[h + n:]
            if out[-1][0] == CLOSE or (want is not None and len(out) >= want):
                return out
        sock.settimeout(max(0.01, deadline - time.monotonic()))
        try:
            chunk = sock.recv(65536)
        except (TimeoutError, OSError):
            break
        if not chunk:
            break
        buf += chunk
    return out


def _summary(frames) -> list:
    out = []
    for op, payload in frames:
        if op == TEXT:
            m = json.loads(payload)
            out.append((m["type"], m.get("seq"), m.get("code")))
        elif op == CLOSE:
            out.append(("close", struct.unpack(">H", payload[:2])[0] if len(payload) >= 2 else None))
        else:
            out.append((op, payload))
    return out


def _run(port, frames, wait) -> list:
    raw = RawWS(port)
    try:
        raw.sock.sendall(_frame(b'{"type": "hello"}', TEXT) + _frame(b'{"type": "open", "model": "pair"}', TEXT))
        got = _read(raw.sock, time.monotonic() + 10, want=2)
        assert [json.loads(p)["type"] if op == TEXT else op for op, p in got[:2]] == ["welcome", "opened"], got
        for f in frames:
            raw.sock.sendall(f)
            time.sleep(0.03)  # the handler takes what came before (as on a real network)
        return _summary(_read(raw.sock, time.monotonic() + wait))
    finally:
        raw.close()


@pytest.mark.parametrize("name", list(CASES))
def test_fast_path_answers_as_the_library_does(pair, name):
    frames, code = CASES[name]
    wait = 5.0 if code is not None else 1.0  # a closing case ends at the close frame
    fast, library = (_run(st.server.port, frames, wait) for st in pair)
    assert fast == library, (fast, library)
    closes = [x[1] for x in library if x[0] == "close"]
    assert closes == ([code] if code is not None else []), library
    if code is None:  # every message answered once, in order
        seqs = [x[1] for x in library if x[0] in ("prediction", "error")]
        assert seqs == sorted(seqs) and len(seqs) == len(set(seqs)) and seqs, library

"""The server's own CPU per frame (transport: WebSocket in and out, JSON, scheduling), with the stand-in model.

`benchmarks/load_server.py` paces its clients at 100 Hz, so how many frames get a reply of their own depends on
how much CPU the (shared) machine leaves the server, and its "server CPU ms/frame" mixes the two costs.  Here
the two are measured apart, as CPU time of the server process (from /proc, less disturbed by other load than
wall time), with the constant-time stand-in model of `load_server.py`:

* **lockstep**: each of S sessions sends a frame, waits for its reply, sends the next: one reply per frame,
  so the figure is the whole per-frame cost (frame in, reply out);
* **pipelined**: each session sends all its F frames in one write: the server reads them and answers in
  coalesced replies, so the figure is (nearly) the cost of taking a frame in.

    python -m benchmarks.transport_cost                       # JSON frames, S = 20 sessions x F = 500 frames
    python -m benchmarks.transport_cost --binary --repeat 5

Each figure is the smallest of ``--repeat`` runs (the least disturbed by the rest of the machine).
Traffic goes to 127.0.0.1 only.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import multiprocessing as mp
import os
import time

from benchmarks.load_server import _cpu_seconds, _RawSession, _StubModel


def _server_main(port_q, ready, stop):
    """The stand-in model served inline, without rate limits (pipelined sessions send all their frames at once)."""
    from interprim.server.app import InterprimServer, ServerConfig, run
    from interprim.server.models import entry_for

    cfg = ServerConfig(port=0, max_sessions=1000, max_rate_hz=1e9, rate_burst=1 << 30, max_pending=1 << 20,
                       max_unauthenticated=2000, max_unauthenticated_per_address=2000)  # all sessions connect at once

    async def main():
        srv = InterprimServer({"highfive": entry_for("highfive", _StubModel())}, cfg)
        await srv.start()
        port_q.put(srv.port)
        ready.set()
        while not stop.is_set():
            await asyncio.sleep(0.1)
        await srv.stop()

    run(main(), "best")


class _Client(asyncio.Protocol):
    """One session of raw WebSocket: hello + open, then its frames (lockstep or all at once)."""

    def __init__(self, frames: list, lockstep: bool, done):
        self.frames, self.lockstep, self.done = frames, lockstep, done
        self.buf = bytearray()
        self.stage = 0  # 0 handshake, 1 hello sent, 2 open sent, 3 streaming
        self.answered = 0
        self.sent = 0

    def connection_made(self, transport):
        import base64

        self.t = transport
        key = base64.b64encode(os.urandom(16)).decode()
        transport.write(f"GET /ws HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
                        f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n".encode())

    def _next(self):
        if self.lockstep:
            self.t.write(self.frames[self.sent])
            self.sent += 1
        else:
            self.t.write(b"".join(self.frames))
            self.sent = len(self.frames)

    def data_received(self, data):
        buf = self.buf
        buf += data
        if self.stage == 0:
            end = buf.find(b"\r\n\r\n")
            if end < 0:
                return
            del buf[:end + 4]
            self.stage = 1
            self.t.write(_RawSession.encode(json.dumps({"type": "hello", "version": 1})))
        pos = 0
        while len(buf) - pos >= 2:
            n, h = buf[pos + 1] & 0x7F, 2
            if n == 126:
                if len(buf) - pos < 4:
                    break
                n, h = int.from_bytes(buf[pos + 2:pos + 4], "big"), 4
            if len(buf) - pos < h + n:
                break
            body = bytes(buf[pos + h:pos + h + n])
            pos += h + n
            if self.stage == 1:
                self.stage = 2
                self.t.write(_RawSession.encode(json.dumps({"type": "open", "model": "highfive", "points": 50})))
            elif self.stage == 2:
                self.stage = 3
                self._next()
            elif body.startswith(b'{"type":"prediction"'):
                head = body[:120].split(b",")
                covers = int(head[2].split(b":")[1])
                self.answered += covers
                if self.answered >= len(self.frames):
                    if not self.done.done():
                        self.done.set_result(None)
                elif self.lockstep and self.sent == self.answered:
                    self._next()
            else:
                raise RuntimeError(body[:200].decode(errors="replace"))
        del buf[:pos]


async def _run(port, n_sessions, frames, lockstep):
    loop = asyncio.get_running_loop()
    dones = []
    for _ in range(n_sessions):
        fut = loop.create_future()
        await loop.create_connection(lambda f=fut: _Client(frames, lockstep, f), "127.0.0.1", port)
        dones.append(fut)
    await asyncio.wait_for(asyncio.gather(*dones), 120)


def _client(port, n_sessions, frames, lockstep, q, go):
    go.wait()
    asyncio.run(_run(port, n_sessions, frames, lockstep))
    q.put("done")


def measure(n_sessions=20, n_frames=500, binary=False, repeat=3):
    import numpy as np

    from interprim.server.protocol import encode_binary_frame

    rng = np.random.default_rng(0)
    raw = rng.normal(size=(n_frames, 2)).tolist()
    frames = [_RawSession.encode(encode_binary_frame(f) if binary else json.dumps({"type": "frame", "frame": f}))
              for f in raw]
    ctx = mp.get_context("spawn")
    port_q, ready, stop = ctx.Queue(), ctx.Event(), ctx.Event()
    srv = ctx.Process(target=_server_main, args=(port_q, ready, stop))
    srv.start()
    ready.wait(180)
    port = port_q.get(timeout=10)
    out = {}
    try:
        for kind in ("lockstep", "pipelined"):
            best = float("inf")
            for _ in range(repeat):
                q, go = ctx.Queue(), ctx.Event()
                cl = ctx.Process(target=_client, args=(port, n_sessions, frames, kind == "lockstep", q, go))
                cl.start()
                time.sleep(0.3)
                c0 = _cpu_seconds(srv.pid)
                go.set()
                q.get(timeout=180)
                c1 = _cpu_seconds(srv.pid)
                cl.join(30)
                best = min(best, (c1 - c0) / (n_sessions * n_frames) * 1e3)
            out[kind] = best
    finally:
        stop.set()
        srv.join(20)
        if srv.is_alive():
            srv.terminate()
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sessions", type=int, default=20)
    ap.add_argument("--frames", type=int, default=500)
    ap.add_argument("--binary", action="store_true", help="binary frames instead of JSON")
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)
    r = measure(args.sessions, args.frames, args.binary, args.repeat)
    print(f"server CPU per frame ({'binary' if args.binary else 'JSON'} frames, stand-in model, "
          f"{args.sessions} sessions x {args.frames} frames, best of {args.repeat}; load {os.getloadavg()[0]:.1f}): "
          f"lockstep (one reply per frame) {r['lockstep']:.4f} ms, pipelined (coalesced) {r['pipelined']:.4f} ms")
    return r


if __name__ == "__main__":
    main()

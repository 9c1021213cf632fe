"""Load test of ``interprim serve``: N concurrent sessions, each streaming frames at 100 Hz on loopback.

The server runs in its own process (``python -m interprim.cli serve`` equivalent, started here with a
model fitted on the simulated high-five); the clients run in another process (asyncio, one
connection per session, each sending a frame every 10 ms on its own schedule and timing
frame-sent -> the reply that covers it received: a reply answers frames ``first_seq .. seq``, more than
one when the server coalesced a session's frames under overload).  Reports, per N: median and p99
latency, frames coalesced (answered by a later frame's reply), frames lost (never answered, or answered
twice / out of order: checked seq by seq), error replies, the server's CPU use (from /proc) and the
machine's load: the 1-min load average and the CPU used by other processes during the run (the
machine is shared).

    python benchmarks/load_server.py                   # N = 1, 10, 20, 30, 50, 100; 5 s each; writes SERVER_RESULTS.md
    python benchmarks/load_server.py --sessions 50 --seconds 10 --modes procs:2 --phase-method dtw

Traffic goes to 127.0.0.1 only.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import multiprocessing as mp
import os
import platform
import statistics
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def _fit_model(path: Path, n_train: int, phase_method: str | None = None) -> None:
    import interprim as ip
    from interprim.sim import highfive_split

    train, test = highfive_split(n_train, 1, seed=0, progress=False)
    kw = {"phase_method": phase_method} if phase_method else {}  # None: the library's default
    m = ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=15, **kw).fit(train.demos, dt=train.dt)
    m.save(str(path))
    import numpy as np

    np.save(str(path.with_suffix(".test.npy")), test.demos[0][:, :2])


class _StubPrediction:
    """Constant-time stand-in for a Prediction: measures the server's own overhead."""

    def __init__(self, n):
        import numpy as np

        self.phase, self.x, self.speed, self.duration, self.log_likelihood = 0.5, 0.2, 1.0, 1.5, -1.0
        self.goal = np.zeros(5)
        self.conditioned, self.n_observed, self.input_distance, self.out_of_range = True, 1, 0.0, False
        self._traj = np.linspace(0, 1, 5 * 500).reshape(500, 5)

    def trajectory(self, n):
        return self._traj[:n]

    def std(self, n):
        return self._traj[:n]

    def mean_rollout(self, n, columns=None):
        from interprim.models.base import TrajectoryColumns

        return TrajectoryColumns(n, columns)


class _StubModel:
    observed_dofs_, controlled_dofs_, n_dofs_, dt_, mean_duration_ = [0, 1], [2, 3, 4], 5, 0.01, 1.5
    _pred = None

    def stream(self, robot_state=None):
        return self

    def update(self, frame, need_cov=True):
        if self._pred is None:  # one prediction, built once: the stub costs ~nothing per frame
            type(self)._pred = _StubPrediction(len(frame))
        return self._pred

    def extend(self, frames, need_cov=True):  # several frames at once (Stream.extend), as cheap
        return self.update(frames[-1], need_cov)

    def reset(self, robot_state=None):
        pass


def _server_main(model_path, port_q, mode, ready_evt, stop_evt, loop="best"):
    import logging

    logging.basicConfig(level=logging.WARNING)
    from interprim.server.app import InterprimServer, ServerConfig
    from interprim.server.models import entry_for, load_models

    if model_path == "stub":
        models = {"highfive": entry_for("highfive", _StubModel())}
    else:
        models = load_models([model_path])
    workers, processes = mode
    kw = {"loop": loop} if "loop" in ServerConfig.__dataclass_fields__ else {}  # (an older server: asyncio)
    if "max_unauthenticated_per_address" in ServerConfig.__dataclass_fields__:
        # every session of the load client connects at once from 127.0.0.1, before any hello
        kw.update(max_unauthenticated=2000, max_unauthenticated_per_address=2000)
    cfg = ServerConfig(port=0, max_sessions=1000, workers=workers, processes=processes, max_rate_hz=1000,
                       rate_burst=100, **kw)

    async def main():
        srv = InterprimServer(models, cfg)
        await srv.start()
        port_q.put(srv.port)
        ready_evt.set()
        while not stop_evt.is_set():
            await asyncio.sleep(0.1)
        await srv.stop()

    _run(main(), loop if kw else "asyncio")


def _run(main, loop):
    try:
        from interprim.server.app import run
    except ImportError:  # an older interprim (comparisons): asyncio's loop
        return asyncio.run(main)
    return run(main, loop)


def _stat(pid: int):
    with open(f"/proc/{pid}/stat") as f:
        return f.read().rsplit(")", 1)[1].split()


def _cpu_seconds(pid: int) -> float:
    """CPU time (user + system) of ``pid`` and its child processes (the worker processes)."""
    total = 0.0
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            fields = _stat(int(entry))
        except OSError:
            continue
        if int(entry) == pid or int(fields[1]) == pid:
            total += int(fields[11]) + int(fields[12])
    return total / os.sysconf("SC_CLK_TCK")


async def _open_session(url, points, std, local=None):
    from websockets.asyncio.client import connect

    kw = {"local_addr": (local, 0)} if local else {}
    ws = await connect(url, max_size=2**22, compression=None, **kw)
    await ws.send(json.dumps({"type": "hello", "version": 1}))
    json.loads(await ws.recv())
    await ws.send(json.dumps({"type": "open", "model": "highfive", "points": points, "std": std}))
    json.loads(await ws.recv())
    return ws


async def _reader(ws, st, loop, n_total):
    while st["got"] + st["errors"] < n_total:
        raw = await ws.recv()
        t = time.perf_counter()
        # Replies start with {"type":"...","seq":N,...}: read the head only, so that the client's own
        # CPU (JSON decoding of trajectories) does not dominate the measurement.
        head = raw[:96]
        if head.startswith('{"type":"prediction","seq":'):
            _covered(st, t, *_head_numbers(head[27:].encode()))
        elif head.startswith('{"type":"error"'):
            _error(st, json.loads(raw))


def _head_numbers(b: bytes):
    """``seq, covers`` from the text after ``"seq":`` of a prediction (``N,"covers":C,...``; an older server
    without ``covers``: one frame per reply)."""
    parts = b.split(b",", 2)
    seq = int(parts[0])
    covers = int(parts[1][9:]) if len(parts) > 1 and parts[1].startswith(b'"covers":') else 1
    return seq, covers


def _covered(st, t, seq, covers):
    """A prediction answering frames ``seq - covers + 1 .. seq`` arrived at ``t``: the latency of each of them,
    and a check that they follow the frames answered before (none skipped, none answered twice)."""
    first = seq - covers + 1
    if first != st["next"]:
        st["bad"] += 1  # a gap or an overlap: counted as lost below
    sent_at = st["sent_at"]
    for q in range(first, seq + 1):
        t_sent = sent_at.pop(q, None)
        if t_sent is None:
            st["bad"] += 1
            continue
        st["lat"].append(t - t_sent)
        st["recv"].append(t)
    st["got"] += covers
    st["coalesced"] += covers - 1
    st["replies"] += 1
    st["next"] = seq + 1


def _error(st, msg):
    seq = msg.get("seq")
    if seq is not None:
        covers = msg.get("covers", 1)
        for q in range(seq - covers + 1, seq + 1):
            st["sent_at"].pop(q, None)
        st["next"] = seq + 1
        st["errors"] += covers
        if msg.get("code") == "rate_limited":
            st["rate_limited"] += covers
    else:
        st["errors"] += 1


def _new_state():
    return {"lat": [], "recv": [], "sent_at": {}, "got": 0, "errors": 0, "coalesced": 0, "replies": 0, "next": 1,
            "bad": 0, "rate_limited": 0}


def _client_main(url, n, seconds, rate_hz, binary, frames, points, std, q, heavy=0, client="raw", loop="best",
                 addresses="each"):
    """All sessions in one asyncio process: connect them all first, then one scheduler sends each
    session's frame every 1/rate_hz s, sessions staggered evenly over the period.

    ``addresses="each"``: every well-behaved session connects from its own loopback address (127.0.1.1, 127.0.1.2,
    ...: one robot each), and the ``heavy`` sessions all from 127.0.2.1 (one client holding them all); ``"one"``:
    every session from 127.0.0.1."""
    import heapq

    from interprim.server.protocol import encode_binary_frame

    payloads = [encode_binary_frame(f) if binary else json.dumps({"type": "frame", "frame": list(f)}) for f in frames]
    reset = json.dumps({"type": "reset"})

    async def main():
        loop_ = asyncio.get_running_loop()
        n_total = int(seconds * rate_hz)
        states = [_new_state() for _ in range(n)]
        # the first `heavy` sessions ask for 500 points with the std band: much more work per frame
        opts = [(500 if i < heavy else points, True if i < heavy else std) for i in range(n)]
        if addresses == "each":
            opts = [o + ("127.0.2.1" if i < heavy else f"127.0.{1 + i // 250}.{1 + i % 250}",)
                    for i, o in enumerate(opts)]
        if client == "raw":
            conns = await asyncio.gather(*[_RawSession.open(url, st, n_total, *o) for st, o in zip(states, opts)])
            readers = [c.done for c in conns]
            frame_msgs = [_RawSession.encode(pl) for pl in payloads]
            reset_msg = _RawSession.encode(reset)

            def sender(c):
                w = c.transport.write
                return lambda data: w(data)

            senders = [sender(c) for c in conns]
        else:
            conns = await asyncio.gather(*[_open_session(url, *o) for o in opts])
            readers = [asyncio.create_task(_reader(ws, st, loop_, n_total)) for ws, st in zip(conns, states)]
            frame_msgs, reset_msg = payloads, reset
            senders = [ws.send for ws in conns]
        q.put("start")
        # time.perf_counter, not loop.time(): uvloop's clock and timers have a 1 ms resolution
        clock = time.perf_counter
        t0 = clock() + 0.2
        period = 1.0 / rate_hz
        heap = [(t0 + (i / n) * period, i, 0) for i in range(n)]
        heapq.heapify(heap)
        is_async = client != "raw"
        while heap:
            when, i, k = heap[0]
            delay = when - clock()
            if delay > 0:
                await asyncio.sleep(delay)
            now = clock() + 0.0005  # a frame due within 0.5 ms goes now (timers may wake up early)
            while heap and heap[0][0] <= now:
                when, i, k = heapq.heappop(heap)
                send, st = senders[i], states[i]
                if k and k % len(frame_msgs) == 0:
                    r = send(reset_msg)  # a new interaction; control replies are not counted
                    if is_async:
                        await r
                st["sent_at"][k + 1] = clock()
                r = send(frame_msgs[k % len(frame_msgs)])
                if is_async:
                    await r
                if k + 1 < n_total:
                    heapq.heappush(heap, (t0 + (k + 1) * period + (i / n) * period, i, k + 1))
        # every frame is answered eventually (the server does not drop frames; when it is behind, TCP flow control
        # holds them back): wait long enough that "lost" counts frames never answered, not late ones
        done, pending = await asyncio.wait(readers, timeout=60.0)
        for t in pending:
            t.cancel()
        if client == "raw":
            await asyncio.gather(*[c.close() for c in conns], return_exceptions=True)
        else:
            await asyncio.gather(*[ws.close() for ws in conns], return_exceptions=True)
        return [{"lat": st["lat"], "recv": st["recv"], "sent": n_total, "errors": st["errors"],
                 "coalesced": st["coalesced"], "replies": st["replies"], "bad": st["bad"],
                 "missing": n_total - st["got"] - st["errors"]} for st in states]

    import resource

    out = _run(main(), loop)
    ru = resource.getrusage(resource.RUSAGE_SELF)
    q.put((out, ru.ru_utime + ru.ru_stime))


class _RawSession(asyncio.Protocol):
    """A minimal WebSocket client (RFC 6455, text/binary frames of one fragment, no extensions) so
    that the load client costs little CPU next to the server on the same cores: client frames are
    encoded (and masked) once per distinct payload, replies are read by their head only (``type`` and
    ``seq`` come first in a prediction) without decoding the JSON.  One fixed mask key per process:
    fine for a loopback benchmark, not for a real client (RFC 6455 wants a fresh key per frame)."""

    MASK = os.urandom(4)

    def __init__(self, st, n_total):
        loop = asyncio.get_running_loop()
        self.st, self.n_total, self.loop = st, n_total, loop
        self.buf = bytearray()
        self.handshaken = loop.create_future()
        self.done = loop.create_future()
        self.closed = loop.create_future()
        self.control = asyncio.Queue()
        self.transport = None

    @classmethod
    def encode(cls, payload, opcode=None) -> bytes:
        data = payload.encode() if isinstance(payload, str) else bytes(payload)
        if opcode is None:
            opcode = 1 if isinstance(payload, str) else 2
        n = len(data)
        head = bytes([0x80 | opcode])
        if n < 126:
            head += bytes([0x80 | n])
        elif n < 65536:
            head += bytes([0x80 | 126]) + n.to_bytes(2, "big")
        else:
            head += bytes([0x80 | 127]) + n.to_bytes(8, "big")
        m = cls.MASK
        return head + m + bytes(b ^ m[i % 4] for i, b in enumerate(data))

    @classmethod
    async def open(cls, url, st, n_total, points, std, local=None):
        import base64
        from urllib.parse import urlsplit

        u = urlsplit(url)
        loop = asyncio.get_running_loop()
        kw = {"local_addr": (local, 0)} if local else {}
        _, self = await loop.create_connection(lambda: cls(st, n_total), u.hostname, u.port, **kw)
        key = base64.b64encode(os.urandom(16)).decode()
        self.transport.write(
            f"GET {u.path} HTTP/1.1\r\nHost: {u.netloc}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
            f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n".encode())
        await self.handshaken
        self.transport.write(cls.encode(json.dumps({"type": "hello", "version": 1})))
        await self.control.get()
        opening = {"type": "open", "model": "highfive", "points": points, "std": std}
        self.transport.write(cls.encode(json.dumps(opening)))
        reply = await self.control.get()
        assert reply.startswith(b'{"type":"opened"'), reply[:200]
        return self

    def connection_made(self, transport):
        self.transport = transport

    def data_received(self, data):
        t = time.perf_counter()
        buf = self.buf
        buf += data
        if not self.handshaken.done():
            end = buf.find(b"\r\n\r\n")
            if end < 0:
                return
            if not buf.startswith(b"HTTP/1.1 101"):
                self.handshaken.set_exception(RuntimeError(bytes(buf[:200]).decode(errors="replace")))
                return
            del buf[:end + 4]
            self.handshaken.set_result(None)
        st = self.st
        pos, size = 0, len(buf)
        while size - pos >= 2:
            b0, n = buf[pos], buf[pos + 1] & 0x7F
            h = 2
            if n == 126:
                if size - pos < 4:
                    break
                n, h = int.from_bytes(buf[pos + 2:pos + 4], "big"), 4
            elif n == 127:
                if size - pos < 10:
                    break
                n, h = int.from_bytes(buf[pos + 2:pos + 10], "big"), 10
            if size - pos < h + n:
                break
            start = pos + h
            pos = start + n
            op = b0 & 0x0F
            if op == 1 or op == 2:
                if buf.startswith(b'{"type":"prediction","seq":', start):
                    _covered(st, t, *_head_numbers(bytes(buf[start + 27:start + 96])))
                elif buf.startswith(b'{"type":"error"', start):
                    _error(st, json.loads(bytes(buf[start:pos])))
                else:
                    self.control.put_nowait(bytes(buf[start:pos]))
                if st["got"] + st["errors"] >= self.n_total and not self.done.done():
                    self.done.set_result(None)
            elif op == 9:  # ping -> pong
                self.transport.write(self.encode(bytes(buf[start:pos]), opcode=10))
            elif op == 8:  # close: the server's answer to ours, or its own
                if not self.closed.done():
                    self.closed.set_result(bytes(buf[start:pos]))
        del buf[:pos]

    def connection_lost(self, exc):
        if not self.handshaken.done():
            self.handshaken.set_exception(ConnectionError("connection lost during the handshake"))
        for f in (self.done, self.closed):  # unanswered frames are counted as missing
            if not f.done():
                f.set_result(None)

    async def close(self):
        self.transport.write(self.encode((1000).to_bytes(2, "big"), opcode=8))
        try:
            await asyncio.wait_for(asyncio.shield(self.closed), 2.0)
        except Exception:
            pass
        self.transport.close()


def run_one(url, server_pid, n, seconds, binary, frames, points, std, heavy=0, client="raw", loop="best",
            addresses="each"):
    q = mp.Queue()
    p = mp.Process(target=_client_main,
                   args=(url, n, seconds, 100.0, binary, frames, points, std, q, heavy, client, loop, addresses))
    p.start()
    assert q.get(timeout=120) == "start"
    load_before = os.getloadavg()[0]
    time.sleep(0.5)  # the scheduler starts 0.2 s after "start"
    cpu0, t0, busy0 = _cpu_seconds(server_pid), time.monotonic(), _machine_busy()
    client0 = _cpu_seconds(p.pid)
    time.sleep(max(0.5, seconds - 1.0))  # server CPU over (most of) the streaming window only
    cpu1, t1, busy1 = _cpu_seconds(server_pid), time.monotonic(), _machine_busy()
    client1 = _cpu_seconds(p.pid)
    res, client_cpu = q.get(timeout=seconds + 180)
    p.join(30)
    res = res[heavy:]  # latency statistics over the normal sessions only
    lat = sorted(x for r in res for x in r["lat"])
    sent = sum(r["sent"] for r in res)
    errors = sum(r["errors"] for r in res)
    lost = sum(r["missing"] + r["bad"] for r in res)
    rate_limited = sum(r.get("rate_limited", 0) for r in res)

    def pct(v):
        return lat[min(len(lat) - 1, int(round(v / 100 * (len(lat) - 1))))] * 1e3 if lat else float("nan")

    return {
        "N": n,
        "frames": sent,
        "median_ms": statistics.median(lat) * 1e3 if lat else float("nan"),
        "p99_ms": pct(99),
        "max_ms": lat[-1] * 1e3 if lat else float("nan"),
        "replies": sum(r["replies"] for r in res),
        "coalesced": sum(r["coalesced"] for r in res),
        "lost": lost,
        "errors": errors,
        "rate_limited": rate_limited,  # of the well-behaved sessions (the heavy ones are left out above)
        "dropped": lost + errors,
        "server_cpu_pct": 100.0 * (cpu1 - cpu0) / (t1 - t0),
        # the client's whole run (connect, stream, wait for the last replies) over the streaming time
        "client_cpu_pct": 100.0 * client_cpu / seconds,
        # CPU used on the machine by everything but this benchmark's server and client, during the window
        "others_cpu_pct": 100.0 * max(0.0, (busy1 - busy0) - (cpu1 - cpu0) - (client1 - client0)) / (t1 - t0),
        "loadavg_before": load_before,
        "loadavg": os.getloadavg()[0],
        # CPU time the server spent per answered frame: independent of other load on the machine
        "cpu_ms_per_frame": 1e3 * (cpu1 - cpu0) / max(1, sum(t0 <= x <= t1 for r in res for x in r["recv"])),
    }


def _machine_busy() -> float:
    """CPU seconds spent by the whole machine (all cores, all processes) since boot, from /proc/stat."""
    with open("/proc/stat") as f:
        fields = [int(v) for v in f.readline().split()[1:]]
    idle = fields[3] + (fields[4] if len(fields) > 4 else 0)  # idle + iowait
    return (sum(fields[:8]) - idle) / os.sysconf("SC_CLK_TCK")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sessions", type=int, nargs="*", default=[1, 10, 20, 30, 50, 100])
    ap.add_argument("--seconds", type=float, default=5.0)
    ap.add_argument("--modes", nargs="*", default=["inline", "procs:2"],
                    help="server compute modes: inline, threads:N (thread pool), procs:N (worker processes)")
    ap.add_argument("--binary", action="store_true", help="binary frames instead of JSON")
    ap.add_argument("--points", type=int, default=50)
    ap.add_argument("--std", action="store_true", help="ask for the std band too (much more maths per frame)")
    ap.add_argument("--stub", action="store_true",
                    help="serve a constant-time stand-in model: measures the server's own overhead (inline only)")
    ap.add_argument("--out", default=str(HERE / "SERVER_RESULTS.md"))
    ap.add_argument("--no-write", action="store_true")
    ap.add_argument("--heavy", type=int, default=0,
                    help="this many of the N sessions ask for 500 points + std band (noisy neighbours); "
                         "latencies are then reported for the other sessions")
    ap.add_argument("--beside", type=int, default=0, metavar="K",
                    help="run each N twice, back to back: N well-behaved sessions alone, then with K heavy sessions of "
                         "one client beside them (N + K in all), and print the ratio of their p99 latencies")
    ap.add_argument("--addresses", default="each", choices=["each", "one"],
                    help="each: every well-behaved session from its own loopback address, the heavy ones all from "
                         "one (one robot each, one hostile client); one: every session from 127.0.0.1")
    ap.add_argument("--warmup", type=float, default=2.0, metavar="SECONDS",
                    help="stream this long to each new server before the measured rows (0: no warm-up)")
    ap.add_argument("--append", action="store_true", help="append rows to the existing table")
    ap.add_argument("--json", default=None, help="also write the rows to this JSON file")
    ap.add_argument("--loop", default="best", choices=["best", "uvloop", "asyncio"],
                    help="event loop of the server and of the client (best: uvloop if installed)")
    ap.add_argument("--client", default="raw", choices=["raw", "websockets"],
                    help="load client: raw = minimal WebSocket protocol (cheap, leaves the CPU to the server); "
                         "websockets = the websockets library's client")
    ap.add_argument("--phase-method", default=None, choices=["likelihood", "dtw"],
                    help="phase estimator of the served model (default: the library's default)")
    args = ap.parse_args(argv)

    import numpy as np

    tmp = Path(os.environ.get("TMPDIR", "/tmp")) / f"interprim-load-{os.getpid()}"
    tmp.mkdir(parents=True, exist_ok=True)
    model_path = tmp / "highfive.npz"
    print("fitting the high-five model ...", flush=True)
    _fit_model(model_path, 30, args.phase_method)
    frames = np.load(str(model_path.with_suffix(".test.npy"))).tolist()

    rows = []
    for label in args.modes:
        kind, _, num = label.partition(":")
        mode = {"inline": (0, 0), "threads": (int(num or 2), 0), "procs": (0, int(num or 2))}[kind]
        ctx = mp.get_context("spawn")
        port_q, ready, stop = ctx.Queue(), ctx.Event(), ctx.Event()
        srv = ctx.Process(target=_server_main,
                          args=("stub" if args.stub else str(model_path), port_q, mode, ready, stop, args.loop))
        srv.start()
        ready.wait(180)
        url = f"ws://127.0.0.1:{port_q.get(timeout=10)}/ws"
        try:
            if args.warmup > 0:  # the server's first use (caches, worker processes' first turns) in no row
                run_one(url, srv.pid, min(args.sessions), args.warmup, args.binary, frames, args.points, args.std,
                        0, args.client, args.loop, args.addresses)
            runs = [(n, args.heavy) for n in args.sessions]
            if args.beside:
                runs = [x for n in args.sessions for x in ((n, 0), (n + args.beside, args.beside))]
            for n, heavy in runs:
                r = run_one(url, srv.pid, n, args.seconds, args.binary, frames, args.points, args.std, heavy,
                            args.client, args.loop, args.addresses)
                r["mode"] = label + (" (stub model)" if args.stub else "") + (
                    f" + {heavy} heavy session(s) of one client" if heavy else "") + (
                    ", all from one address" if args.addresses == "one" else "") + (
                    f", {args.phase_method} phase" if args.phase_method else "") + (
                    ", binary frames" if args.binary else "") + (
                    f", {args.points} points" if args.points != 50 else "") + (", std band" if args.std else "")
                r["loop"] = _loop_name(args.loop)
                r["client"] = args.client
                rows.append(r)
                print(
                    f"{label:>9} N={n:4d}: {r['frames']} frames, median {r['median_ms']:.2f} ms, "
                    f"p99 {r['p99_ms']:.2f} ms, max {r['max_ms']:.1f} ms, {r['replies']} replies, "
                    f"coalesced {r['coalesced']}, lost {r['lost']}, rate-limited {r['rate_limited']}, "
                    f"errors {r['errors']}, "
                    f"server CPU {r['server_cpu_pct']:.0f} % ({r['cpu_ms_per_frame']:.3f} ms/frame), "
                    f"client CPU {r['client_cpu_pct']:.0f} %, others' CPU {r['others_cpu_pct']:.0f} %, "
                    f"load {r['loadavg_before']:.1f} -> {r['loadavg']:.1f}",
                    flush=True,
                )
            if args.beside:
                for a, b in zip(rows[-len(runs)::2], rows[-len(runs) + 1::2]):
                    print(f"{label:>9} N={a['N']:4d}: p99 with {args.beside} heavy sessions of one client beside them "
                          f"{b['p99_ms']:.2f} ms / alone {a['p99_ms']:.2f} ms = {b['p99_ms'] / a['p99_ms']:.2f}x",
                          flush=True)
        finally:
            stop.set()
            srv.join(20)
            if srv.is_alive():
                srv.terminate()
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))
    if not args.no_write:
        write_results(Path(args.out), rows, args, append=args.append)
    return rows


def _loop_name(kind: str) -> str:
    try:
        from interprim.server.app import new_event_loop
    except ImportError:
        return "asyncio"

    ev = new_event_loop(kind)
    try:
        return "uvloop" if type(ev).__module__.startswith("uvloop") else "asyncio"
    finally:
        ev.close()


def table_row(r) -> str:
    return (f"| {r['mode']} | {r['N']} | {r['frames']} | {r['median_ms']:.2f} | {r['p99_ms']:.2f} | "
            f"{r['max_ms']:.1f} | "
            f"{r['replies']} | {r['coalesced']} | {r['lost']} | {r['errors']} | {r['server_cpu_pct']:.0f} | "
            f"{r['cpu_ms_per_frame']:.3f} | {r['client_cpu_pct']:.0f} | {r['others_cpu_pct']:.0f} | "
            f"{r['loadavg_before']:.1f} -> {r['loadavg']:.1f} |")


def write_results(path: Path, rows, args, append=False):
    import numpy as np
    import websockets

    lines = [
        "# Server load test",
        "",
        "`python benchmarks/load_server.py` — N concurrent sessions, each streaming one frame every 10 ms "
        f"(100 Hz) for {args.seconds:g} s on loopback; {'binary' if args.binary else 'JSON'} frames; each reply "
        f"carries the controlled agent's mean trajectory at {args.points} points"
        f"{' and its std band' if args.std else ''}. Model: simulated high-five (2 observed + 3 controlled "
        "joints, 15 basis functions, 30 demonstrations). Server and clients in separate processes. "
        "Latency = frame sent -> the reply that covers it received (client clock). Coalesced = frames answered "
        "by a later frame's reply (`covers` > 1). Lost = frames never answered (or not in seq order); errors = "
        "frames answered with an error. Server CPU = server process CPU time / wall time (100 % = one core); "
        "others = CPU used by the rest of the (shared) machine meanwhile; load = 1-min load average before -> "
        "after the row.",
        "",
        f"Machine: {os.cpu_count()} CPUs, {platform.platform()}, Python {platform.python_version()}, "
        f"numpy {np.__version__}, websockets {websockets.__version__}.",
        "",
        "| server compute | N sessions | frames | median (ms) | p99 (ms) | max (ms) | replies | frames coalesced | "
        "frames lost | errors | server CPU % | server CPU ms/frame | client CPU % | others' CPU % | load (1 min) |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        lines.append(table_row(r))
    lines.append("")
    if append and path.exists():
        old = path.read_text().rstrip("\n").split("\n")
        table_rows = [ln for ln in lines if ln.startswith("| ") and not ln.startswith("| server compute")]
        path.write_text("\n".join(old + table_rows) + "\n")
    else:
        path.write_text("\n".join(lines) + "\n")
    print(f"wrote {path}")


if __name__ == "__main__":
    sys.exit(0 if main() else 1)

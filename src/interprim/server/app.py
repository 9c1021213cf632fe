"""The WebSocket server: sessions, limits, the HTTP side (page, static files, JSON API).

One WebSocket connection is one *session*.  Inside it the client says ``hello``,
``open``\\s a model (or ``auto`` recognition among several), streams frames and
receives one ``prediction`` (or ``error``) per frame, in order.  Each session
owns its own ``model.stream()``; nothing is shared between sessions except the
read-only fitted models.

Concurrency: the asyncio event loop does all the I/O; the CPU-bound
``stream.update`` + trajectory + JSON encoding of a frame runs either inline on
the loop (``workers=0``) or in a thread pool (``workers=N``).  Per-session
ordering holds in both modes because a session awaits frame ``k`` before it
reads frame ``k+1``.  Replies go through a bounded per-session queue drained by
a writer task, so a client that never reads is detected (queue full) and closed
with code 1008 instead of growing the server's memory.
"""

from __future__ import annotations

import asyncio
import heapq
import hmac
import http
import ipaddress
import itertools
import json
import logging
import mimetypes
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from urllib.parse import parse_qs, urlsplit


from . import protocol as P
from .compute import _Open, _accepts_need_cov, compute_prediction, warm_up
from .models import ModelEntry

log = logging.getLogger("interprim.server")

STATIC_DIR = Path(__file__).resolve().parent / "static"
LOOPBACK_NAMES = {"localhost", "127.0.0.1", "::1"}


@dataclass
class ServerConfig:
    """Limits and options of a server (the ``interprim serve`` flags)."""

    host: str = "127.0.0.1"
    port: int = 8765  # 0 = any free port (tests)
    token: str | None = None
    max_sessions: int = 64
    max_message_bytes: int = 65536
    max_rate_hz: float = 500.0  # messages per second per session (token bucket) ...
    rate_burst: int = 50  # ... with this many messages of burst
    workers: int = 0  # 0 = compute inline on the event loop; N = thread pool of N
    processes: int = 0  # N > 0: sessions pinned to N worker processes (see workers.py); overrides workers
    send_queue: int = 256  # replies pending for one client before it counts as "not reading"
    write_limit: int = 256 * 1024  # bytes buffered in the socket writer before send() waits
    max_points: int = 500
    default_points: int = 50
    max_errors: int = 200  # consecutive protocol errors before the session is closed
    hello_timeout: float = 10.0
    close_timeout: float = 2.0
    ping_interval: float | None = 20.0
    allowed_origins: tuple = ()
    log_errors_per_session: int = 10
    loop: str = "auto"  # event loop: "auto" (uvloop if installed), "uvloop", "asyncio" (see new_event_loop)

    def validate(self) -> None:
        if not is_loopback(self.host) and not self.token:
            raise ValueError(
                f"refusing to listen on {self.host!r} without a token: anyone who can reach it could use the "
                "server. Pass --token (or set INTERPRIM_TOKEN), or keep the default --host 127.0.0.1"
            )
        for name in ("max_sessions", "max_message_bytes", "send_queue", "max_points", "rate_burst", "max_errors"):
            if int(getattr(self, name)) < 1:
                raise ValueError(f"{name} must be at least 1, got {getattr(self, name)}")
        if not self.max_rate_hz > 0:
            raise ValueError(f"max_rate_hz must be positive, got {self.max_rate_hz}")
        if self.workers < 0:
            raise ValueError(f"workers must be >= 0, got {self.workers}")
        if self.processes < 0:
            raise ValueError(f"processes must be >= 0, got {self.processes}")
        if not 2 <= self.default_points <= self.max_points:
            raise ValueError(f"default_points must be in [2, max_points={self.max_points}]")
        if self.loop not in LOOP_KINDS:
            raise ValueError(f"loop must be one of {LOOP_KINDS}, got {self.loop!r}")
        if self.max_message_bytes < 256:
            raise ValueError("max_message_bytes must be at least 256 (a frame message needs room)")


LOOP_KINDS = ("auto", "uvloop", "asyncio")


def new_event_loop(kind: str = "auto") -> asyncio.AbstractEventLoop:
    """A new event loop: uvloop's (libuv, socket I/O and callbacks in C: about a third less CPU per
    frame for the server) when ``kind`` is "uvloop", or "auto" and uvloop is installed; else asyncio's."""
    if kind not in LOOP_KINDS:
        raise ValueError(f"loop must be one of {LOOP_KINDS}, got {kind!r}")
    if kind != "asyncio":
        try:
            import uvloop
        except ImportError:
            if kind == "uvloop":
                raise ImportError("--loop uvloop needs the 'uvloop' package: pip install uvloop") from None
        else:
            return uvloop.new_event_loop()
    return asyncio.new_event_loop()


def run(main, loop: str = "auto"):
    """``asyncio.run(main)`` on :func:`new_event_loop`'s loop."""
    ev = new_event_loop(loop)
    try:
        asyncio.set_event_loop(ev)
        return ev.run_until_complete(main)
    finally:
        try:
            ev.run_until_complete(ev.shutdown_asyncgens())
        finally:
            asyncio.set_event_loop(None)
            ev.close()


def _peer(conn) -> str:
    try:
        return "%s:%s" % tuple(conn.remote_address[:2])
    except Exception:
        return "?"


def is_loopback(host: str) -> bool:
    if host in LOOPBACK_NAMES:
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


class _Bucket:
    """Token bucket: ``rate`` messages per second, ``burst`` at most in one go."""

    def __init__(self, rate: float, burst: int):
        self.rate, self.burst = float(rate), float(burst)
        self.tokens = float(burst)
        self.last = time.monotonic()

    def take(self) -> bool:
        now = time.monotonic()
        self.tokens = min(self.burst, self.tokens + (now - self.last) * self.rate)
        self.last = now
        if self.tokens >= 1.0:
            self.tokens -= 1.0
            return True
        return False


_CLOSE = object()
_OPEN = object()  # websockets.protocol.State.OPEN, set by InterprimServer.start (imported lazily)


@dataclass
class _Session:
    id: int
    ws: object
    peer: str
    out: asyncio.Queue
    bucket: _Bucket
    ready: bool = False
    open: _Open | None = None
    seq: int = 0
    errors: int = 0
    consecutive_errors: int = 0
    predictions: int = 0
    closing: bool = False
    writer: asyncio.Task | None = None
    close_reason: str = ""
    error_counts: dict = field(default_factory=dict)
    vtime: float = 0.0  # compute time used (fair queueing)
    unsent: int = 0  # items put in ``out`` that the writer has not finished sending


class _Lane:
    """One place where predictions are computed (the event loop, a thread, or a worker process),
    shared by several sessions with fair queueing on compute time (start-time fair queueing).

    Each session has at most one frame waiting (its handler awaits the reply before it reads the
    next frame).  Among the waiting frames, the one of the session that has used the least compute
    time goes first.  A session that asks for expensive predictions (many candidates, std band,
    many points) or sends too fast therefore slows itself down, not the other sessions of the lane.
    """

    def __init__(self, run, sync: bool = False):
        self.run = run  # async callable(job) -> reply text; with sync=True a plain callable (inline compute)
        self.sync = sync
        self.heap: list = []
        self.vclock = 0.0
        self.task = None
        self._scheduled = False
        self._tie = itertools.count()

    SLACK = 0.002  # s of compute a session may be ahead of the lane's clock and still be served at once

    def submit(self, s: "_Session", job) -> asyncio.Future:
        loop = asyncio.get_running_loop()
        fut = loop.create_future()
        s.vtime = max(s.vtime, self.vclock)  # an idle session does not bank compute time
        heapq.heappush(self.heap, (s.vtime, next(self._tie), s, job, fut))
        if self.sync:
            if not self._scheduled:
                self._scheduled = True
                loop.call_soon(self._step)
        elif self.task is None or self.task.done():
            self.task = loop.create_task(self._drain())
        return fut

    def run_now(self, s: "_Session", job):
        """Inline lane: compute ``job`` right away if no frame is waiting and ``s`` is at most
        :attr:`SLACK` of compute ahead of the lane's clock (the start time of the last frame served);
        else return ``None``: then :meth:`submit` it and wait for its turn.  Saves a future, a callback
        and two task switches per frame while the lane keeps up (~0.04 ms of the ~0.17 ms per frame);
        a session that uses more compute than the others (or frames waiting) goes through the heap
        as before, so the fair order holds under load."""
        s.vtime = max(s.vtime, self.vclock)
        if self.heap or s.vtime > self.vclock + self.SLACK:
            return None
        self.vclock = s.vtime  # its start time: the lane's clock, as when _step serves a frame
        t0 = time.perf_counter()
        try:
            return self.run(job)
        finally:
            s.vtime += time.perf_counter() - t0

    def _step(self) -> None:
        """Inline lane: compute one waiting frame per event-loop iteration (a plain callback, cheaper
        than a task).  Between two frames the loop reads the sockets, so frames that arrived meanwhile
        join the heap before the next pick, as with :meth:`_drain`."""
        self._scheduled = False
        heap = self.heap
        while heap:
            vt, _, s, job, fut = heapq.heappop(heap)
            self.vclock = vt
            if fut.done():
                continue
            t0 = time.perf_counter()
            try:
                result = self.run(job)
            except Exception as exc:
                fut.set_exception(exc)
            else:
                fut.set_result(result)
            s.vtime += time.perf_counter() - t0
            break
        if heap:
            self._scheduled = True
            asyncio.get_running_loop().call_soon(self._step)

    async def _drain(self) -> None:
        while self.heap:
            vt, _, s, job, fut = heapq.heappop(self.heap)
            self.vclock = vt
            if fut.done():
                continue
            t0 = time.perf_counter()
            try:
                result = await self.run(job)
            except Exception as exc:
                if not fut.done():
                    fut.set_exception(exc)
            else:
                if not fut.done():
                    fut.set_result(result)
            s.vtime += time.perf_counter() - t0
            await asyncio.sleep(0)  # let the other sessions read their next frames and queue them


class InterprimServer:
    """A streaming server for fitted models.

    Parameters
    ----------
    models : dict of name -> ModelEntry
        From :func:`interprim.server.models.load_models` or :func:`interprim.server.demo.demo_models`.
    config : ServerConfig
    extra_info : dict, optional
        Extra JSON sent by ``GET /api/info`` (e.g. the sim's arm geometry).
    """

    def __init__(self, models: dict, config: ServerConfig | None = None, extra_info: dict | None = None):
        self.config = config or ServerConfig()
        self.config.validate()
        if not models:
            raise ValueError("the server needs at least one model (model files, or --demo)")
        self.models: dict[str, ModelEntry] = dict(models)
        self.extra_info = dict(extra_info or {})
        self._ids = itertools.count(1)
        self.sessions: dict[int, _Session] = {}
        self.stats = {"sessions": 0, "predictions": 0, "errors": 0, "rejected": 0}
        c = self.config
        self._pool = ThreadPoolExecutor(c.workers, thread_name_prefix="ip-worker") if c.workers and not c.processes else None
        self._procs = None
        self._lanes: list = []
        self._server = None
        self._static = self._load_static()
        self.port = None

    # ------------------------------------------------------------------ lifecycle
    async def start(self):
        global _OPEN
        from websockets.asyncio.server import ServerConnection, serve
        from websockets.protocol import State

        _OPEN = State.OPEN

        class LoggedConnection(ServerConnection):
            """Logs connections that never complete an HTTP/WebSocket handshake (the library only debug-logs them)."""

            async def handshake(self, *args, **kwargs):
                try:
                    await super().handshake(*args, **kwargs)
                except BaseException as exc:
                    log.warning("connection from %s: no complete handshake (%s)", _peer(self), type(exc).__name__)
                    raise
                if self.request is None and self.protocol.handshake_exc is not None:
                    log.warning("connection from %s: bad HTTP request: %s", _peer(self), self.protocol.handshake_exc)

        c = self.config
        if not c.processes:
            await asyncio.get_running_loop().run_in_executor(None, warm_up, list(self.models.values()))
        if c.processes:
            from .workers import ProcessPool

            pool = ProcessPool(self.models, c.processes)
            loop = asyncio.get_running_loop()
            try:
                await loop.run_in_executor(None, pool.start)
            except BaseException:
                pool.stop()
                raise
            pool.attach(loop)
            self._procs = pool
        self._lanes = self._make_lanes()
        self._server = await serve(
            self._handler,
            c.host,
            c.port,
            process_request=self._process_request,
            max_size=c.max_message_bytes,
            max_queue=16,
            write_limit=c.write_limit,
            compression=None,
            close_timeout=c.close_timeout,
            ping_interval=c.ping_interval,
            ping_timeout=c.ping_interval,
            logger=logging.getLogger("interprim.server.websockets"),
            create_connection=LoggedConnection,
        )
        sock = self._server.sockets[0]
        self.port = sock.getsockname()[1]
        log.info(
            "serving %d model(s) %s on http://%s:%d/ (WebSocket at /ws, protocol v%d, %s)",
            len(self.models),
            sorted(self.models),
            c.host,
            self.port,
            P.PROTOCOL_VERSION,
            ("uvloop, " if type(asyncio.get_running_loop()).__module__.startswith("uvloop") else "")
            + (f"{c.processes} worker process(es)" if c.processes
               else f"{c.workers} worker thread(s)" if c.workers else "inline compute"),
        )
        return self

    def _make_lanes(self) -> list:
        if self._procs is not None:
            procs = self._procs

            async def run_proc(job):
                s, op, frame, seq, t = job
                return await procs.call(s.id, "frame", frame=frame.tolist(), seq=seq, t=t)

            return [_Lane(run_proc) for _ in range(procs.n)]  # session i runs on worker i % n
        if self._pool is not None:
            pool = self._pool

            async def run_thread(job):
                _, op, frame, seq, t = job
                return await asyncio.get_running_loop().run_in_executor(pool, compute_prediction, op, frame, seq, t)

            return [_Lane(run_thread) for _ in range(self.config.workers)]

        def run_inline(job):
            _, op, frame, seq, t = job
            return compute_prediction(op, frame, seq, t)

        return [_Lane(run_inline, sync=True)]

    async def serve_forever(self):
        if self._server is None:
            await self.start()
        await self._server.serve_forever()

    async def stop(self):
        if self._server is not None:
            self._server.close(close_connections=True)
            await self._server.wait_closed()
            self._server = None
        if self._pool is not None:
            self._pool.shutdown(wait=False, cancel_futures=True)
        if self._procs is not None:
            self._procs.stop()
            self._procs = None

    @property
    def url(self) -> str:
        host = self.config.host
        if ":" in host:
            host = f"[{host}]"
        return f"http://{host}:{self.port}/"

    @property
    def ws_url(self) -> str:
        return self.url.replace("http://", "ws://", 1) + "ws"

    # ------------------------------------------------------------------ HTTP side
    def _load_static(self) -> dict:
        files = {}
        if STATIC_DIR.is_dir():
            for p in STATIC_DIR.iterdir():
                if p.is_file() and not p.name.startswith("."):
                    ctype = mimetypes.guess_type(p.name)[0] or "application/octet-stream"
                    if p.suffix == ".js":
                        ctype = "text/javascript"
                    if ctype.startswith("text/") or ctype.endswith("json"):
                        ctype += "; charset=utf-8"
                    files[p.name] = (p.read_bytes(), ctype)
        return files

    def info(self) -> dict:
        c = self.config
        from .. import __version__

        return {
            "server": f"interprim {__version__}",
            "protocol": P.PROTOCOL_VERSION,
            "token_required": bool(c.token),
            "models": [m.describe() for m in self.models.values()],
            "limits": {
                "max_sessions": c.max_sessions,
                "max_message_bytes": c.max_message_bytes,
                "max_rate_hz": c.max_rate_hz,
                "rate_burst": c.rate_burst,
                "max_points": c.max_points,
                "send_queue": c.send_queue,
            },
            **self.extra_info,
        }

    def _http(self, conn, status: int, body: bytes, ctype: str):
        from websockets.datastructures import Headers
        from websockets.http11 import Response

        st = http.HTTPStatus(status)
        headers = Headers(
            [
                ("Content-Type", ctype),
                ("Content-Length", str(len(body))),
                ("Cache-Control", "no-store"),
                ("X-Content-Type-Options", "nosniff"),
                ("Referrer-Policy", "no-referrer"),
                (
                    "Content-Security-Policy",
                    "default-src 'self'; connect-src 'self' ws: wss:; img-src 'self' data:; "
                    "style-src 'self' 'unsafe-inline'; frame-ancestors 'none'",
                ),
                ("Connection", "close"),
            ]
        )
        return Response(st.value, st.phrase, headers, body)

    def _json(self, conn, status: int, obj) -> object:
        return self._http(conn, status, json.dumps(obj).encode(), "application/json; charset=utf-8")

    def _token_ok(self, given) -> bool:
        want = self.config.token
        if not want:
            return True
        return isinstance(given, str) and hmac.compare_digest(given.encode(), want.encode())

    def _origin_ok(self, request) -> bool:
        origin = request.headers.get("Origin")
        if origin is None or origin in self.config.allowed_origins or "*" in self.config.allowed_origins:
            return True  # non-browser clients send no Origin
        try:
            netloc = urlsplit(origin).netloc
        except ValueError:
            return False
        return netloc == request.headers.get("Host")

    def _process_request(self, conn, request):
        try:
            parts = urlsplit(request.path)
        except ValueError:
            return self._json(conn, 400, {"error": "bad request path"})
        path, query = parts.path, parse_qs(parts.query)
        if path == "/ws":
            if not self._origin_ok(request):
                log.warning("rejected WebSocket from origin %r (host %r): cross-site request",
                            request.headers.get("Origin"), request.headers.get("Host"))
                self.stats["rejected"] += 1
                return self._json(conn, 403, {"error": "cross-origin WebSocket refused; start the server with --allow-origin"})
            return None  # go on with the WebSocket handshake
        if path in ("/", "/index.html"):
            body, ctype = self._static["index.html"]
            return self._http(conn, 200, body, ctype)
        if path.startswith("/static/"):
            name = path[len("/static/"):]
            if name in self._static:  # whitelist of files present at start: no path traversal
                body, ctype = self._static[name]
                return self._http(conn, 200, body, ctype)
            return self._json(conn, 404, {"error": f"no static file {name!r}"})
        if path == "/healthz":
            return self._http(conn, 200, b"ok\n", "text/plain; charset=utf-8")
        if path.startswith("/api/"):
            auth = request.headers.get("Authorization", "")
            token = query.get("token", [None])[0] or (auth[7:] if auth.startswith("Bearer ") else None)
            if not self._token_ok(token):
                return self._json(conn, 401, {"error": "missing or wrong token (?token=... or Authorization: Bearer)"})
            if path == "/api/info":
                return self._json(conn, 200, self.info())
            if path.startswith("/api/replay/"):
                name = path[len("/api/replay/"):]
                entry = self.models.get(name)
                if entry is None or "replay" not in entry.meta:
                    return self._json(conn, 404, {"error": f"no replay data for model {name!r}"})
                return self._json(conn, 200, entry.meta["replay"])
        return self._json(conn, 404, {"error": f"not found: {path}"})

    # ------------------------------------------------------------------ sessions
    async def _handler(self, ws):
        c = self.config
        sid = next(self._ids)
        try:
            peer = "%s:%s" % tuple(ws.remote_address[:2])
        except Exception:
            peer = "?"
        if len(self.sessions) >= c.max_sessions:
            self.stats["rejected"] += 1
            log.warning("session %d from %s refused: server full (%d sessions)", sid, peer, c.max_sessions)
            await ws.close(P.CLOSE_TRY_AGAIN, f"server full: at most {c.max_sessions} sessions; try again later")
            return
        s = _Session(sid, ws, peer, asyncio.Queue(maxsize=c.send_queue), _Bucket(c.max_rate_hz, c.rate_burst))
        self.sessions[sid] = s
        self.stats["sessions"] += 1
        s.writer = asyncio.get_running_loop().create_task(self._writer(s))
        log.info("session %d: connected from %s (%d active)", sid, peer, len(self.sessions))
        from websockets.exceptions import ConnectionClosed

        try:
            while not s.closing:
                try:
                    if not s.ready:
                        data = await asyncio.wait_for(ws.recv(), c.hello_timeout)  # (3.10: no asyncio.timeout)
                    else:
                        data = await ws.recv()
                except (TimeoutError, asyncio.TimeoutError):
                    self._fatal(s, P.CLOSE_POLICY, f"no hello within {c.hello_timeout:g} s")
                    break
                except UnicodeDecodeError as exc:  # websockets < 14 raises instead of closing with 1007
                    self._fatal(s, P.CLOSE_INVALID_DATA, f"text message is not valid UTF-8: {exc.reason}")
                    break
                await self._on_message(s, data)
                if not s.out.empty():
                    # Let the writer push the reply to the socket now: the queue then only fills up
                    # when the socket's write buffer is full, i.e. when the client is not reading.
                    await asyncio.sleep(0)
        except ConnectionClosed as exc:
            rcvd, sent = exc.rcvd, exc.sent
            if s.closing:
                pass
            elif sent is not None and sent.code not in (1000, 1001):
                log.warning("session %d: closed by server: %d %s", sid, sent.code, sent.reason)
            elif rcvd is None:
                log.warning("session %d: client disconnected without a close frame after %d frame(s)", sid, s.seq)
            else:
                log.info("session %d: client closed (%d %s)", sid, rcvd.code, rcvd.reason)
        except Exception:  # never let a session bug escape to the library's handler
            log.exception("session %d: internal error; closing the session", sid)
            self._fatal(s, P.CLOSE_INTERNAL, "internal server error (logged)")
        finally:
            self.sessions.pop(sid, None)
            if self._procs is not None and s.open is not None:
                s.open = None
                try:
                    await self._procs.call(sid, "drop")
                except Exception:
                    pass
            if s.closing and s.writer is not None:
                try:  # let the writer send the queued error + close frame
                    await asyncio.wait_for(asyncio.shield(s.writer), c.close_timeout + 1.0)
                except (TimeoutError, asyncio.CancelledError, Exception):
                    pass
            if s.writer is not None and not s.writer.done():
                s.writer.cancel()
            extra = f", errors {s.error_counts}" if s.error_counts else ""
            log.info("session %d: ended (%d frames, %d predictions%s)", sid, s.seq, s.predictions, extra)

    async def _writer(self, s: _Session):
        from websockets.exceptions import ConnectionClosed

        try:
            while True:
                item = await s.out.get()
                if isinstance(item, tuple) and item and item[0] is _CLOSE:
                    await s.ws.close(item[1], item[2])
                    return
                await s.ws.send(item)
                s.unsent -= 1
        except ConnectionClosed:
            return

    def _send(self, s: _Session, text: str) -> None:
        if s.closing:
            return
        try:
            s.out.put_nowait(text)
            s.unsent += 1
        except asyncio.QueueFull:
            reason = f"client is not reading: {self.config.send_queue} replies pending"
            log.warning("session %d: closing 1008: %s", s.id, reason)
            s.closing = True
            s.close_reason = reason
            # Bypass the full queue: close now (the library aborts the TCP connection after close_timeout).
            s.writer.cancel()
            s.writer = asyncio.get_running_loop().create_task(s.ws.close(P.CLOSE_POLICY, reason))

    def _fatal(self, s: _Session, code: int, reason: str, message: dict | None = None) -> None:
        if s.closing:
            return
        log.warning("session %d: closing %d: %s", s.id, code, reason)
        if message is not None:
            self._send(s, P.dumps(message))
        if s.closing:  # _send found the queue full
            return
        s.closing = True
        s.close_reason = reason
        try:
            s.out.put_nowait((_CLOSE, code, reason[:120]))
        except asyncio.QueueFull:
            s.writer.cancel()
            s.writer = asyncio.get_running_loop().create_task(s.ws.close(code, reason[:120]))

    def _error(self, s: _Session, exc: P.ProtocolError, seq=None) -> None:
        s.errors += 1
        if exc.code != "rate_limited":  # dropping is the limit's own answer; not a protocol violation
            s.consecutive_errors += 1
        s.error_counts[exc.code] = s.error_counts.get(exc.code, 0) + 1
        self.stats["errors"] += 1
        if s.errors <= self.config.log_errors_per_session:
            log.warning("session %d: %s: %s%s", s.id, exc.code, exc.message, f" (seq {seq})" if seq else "")
        elif s.errors == self.config.log_errors_per_session + 1:
            log.warning("session %d: further errors are counted, not logged", s.id)
        msg = P.error(exc.code, exc.message, seq=seq)
        if exc.fatal:
            self._fatal(s, P.CLOSE_POLICY, exc.message, msg)
        elif s.consecutive_errors >= self.config.max_errors:
            self._send(s, P.dumps(msg))
            self._fatal(s, P.CLOSE_POLICY, f"too many protocol errors ({s.consecutive_errors} in a row)")
        else:
            self._send(s, P.dumps(msg))

    async def _on_message(self, s: _Session, data) -> None:
        c = self.config
        is_frame = isinstance(data, (bytes, bytearray, memoryview))
        msg = None
        if not is_frame:
            try:
                msg = P.parse_text(data)
            except P.ProtocolError as exc:
                if not s.bucket.take():
                    return self._error(s, P.ProtocolError("rate_limited", f"over {c.max_rate_hz:g} messages/s"))
                return self._error(s, exc)
            is_frame = msg["type"] == "frame"
        seq = None
        if is_frame:
            s.seq += 1
            seq = s.seq
        if not s.bucket.take():
            return self._error(
                s, P.ProtocolError("rate_limited", f"over {c.max_rate_hz:g} messages/s (burst {c.rate_burst}); dropped"), seq
            )
        try:
            if msg is None or msg["type"] == "frame":
                await self._on_frame(s, data, msg, seq)
            else:
                await self._on_control(s, msg)
        except P.ProtocolError as exc:
            self._error(s, exc, seq)

    async def _on_control(self, s: _Session, msg: dict) -> None:
        mtype = msg["type"]
        if mtype == "hello":
            h = P.check_hello(msg)
            if not self._token_ok(h["token"]):
                raise P.ProtocolError("unauthorized", "missing or wrong token in hello", fatal=True)
            s.ready = True
            s.consecutive_errors = 0
            reply = {"type": "welcome", "version": P.PROTOCOL_VERSION, "session": s.id}
            reply.update({k: v for k, v in self.info().items() if k in ("server", "models", "limits")})
            self._send(s, P.dumps(reply))
            return
        if not s.ready:
            raise P.ProtocolError("not_ready", f"send hello first (got {mtype!r})")
        if mtype == "open":
            o = P.check_open(msg, self.models, default_points=self.config.default_points, max_points=self.config.max_points)
            entries = [self.models[n] for n in o["candidates"]]
            streams, cols = [], []
            for e in entries:
                dofs = o["dofs"] or ("all" if e.kind == "single" or not e.controlled_dofs else "controlled")
                cols.append(list(range(e.n_dofs)) if dofs == "all" else e.controlled_dofs)
                if self._procs is None:
                    try:
                        streams.append(e.model.stream(robot_state=o["robot_state"]))
                    except (ValueError, TypeError) as exc:
                        raise P.ProtocolError("bad_message", f"open.robot_state for model {e.name!r}: {exc}") from None
            if self._procs is not None:
                s.open = None
                try:
                    await self._procs.call(s.id, "open", model=o["model"], candidates=o["candidates"], cols=cols,
                                           points=o["points"], std=o["std"], robot_state=o["robot_state"])
                except RuntimeError as exc:
                    raise P.ProtocolError("bad_message", f"open failed: {exc}") from None
            s.open = _Open(o["model"], entries, streams, cols, o["points"], o["std"])
            if streams and _accepts_need_cov(streams[0]):  # mean-only updates are much cheaper without a band
                s.open.update_kw = {"need_cov": o["std"]}
            s.consecutive_errors = 0
            log.info("session %d: opened %s%s", s.id, o["model"],
                     f" among {o['candidates']}" if o["model"] == "auto" else "")
            self._send(s, P.dumps({
                "type": "opened",
                "model": o["model"],
                "candidates": o["candidates"],
                "n_observed": entries[0].n_observed,
                "columns": cols[0] if len(cols) == 1 else {e.name: cl for e, cl in zip(entries, cols)},
                "points": o["points"],
                "std": o["std"],
            }))
            return
        if s.open is None:
            raise P.ProtocolError("not_open", f"{mtype!r} needs an open session: send open first")
        if mtype == "reset":
            if self._procs is not None:
                try:
                    await self._procs.call(s.id, "reset")
                except RuntimeError as exc:
                    raise P.ProtocolError("internal", f"reset failed: {exc}") from None
            for st in s.open.streams:
                st.reset()
            s.open.frames = 0
            s.consecutive_errors = 0
            self._send(s, P.dumps({"type": "reset_done", "seq": s.seq}))
        elif mtype == "close":
            s.open = None
            if self._procs is not None:
                try:
                    await self._procs.call(s.id, "drop")
                except RuntimeError:
                    pass
            s.consecutive_errors = 0
            self._send(s, P.dumps({"type": "closed", "seq": s.seq}))

    async def _on_frame(self, s: _Session, data, msg, seq: int) -> None:
        if not s.ready:
            raise P.ProtocolError("not_ready", "send hello first (got a frame)")
        op = s.open
        if op is None:
            raise P.ProtocolError("not_open", "frame needs an open session: send open first")
        n = op.entries[0].n_observed
        if msg is None:
            frame, t = P.decode_binary_frame(bytes(data), n), None
        else:
            frame, t = P.check_frame(msg, n)
        try:
            lane = self._lanes[s.id % len(self._lanes)]
            job = (s, op, frame, seq, t)
            text = lane.run_now(s, job) if lane.sync else None
            if text is None:
                text = await lane.submit(s, job)
        except Exception as exc:
            self.stats["errors"] += 1
            log.exception("session %d: prediction failed at seq %d", s.id, seq)
            self._send(s, P.dumps(P.error("internal", f"prediction failed: {type(exc).__name__}: {exc}", seq=seq)))
            return
        if s.open is not op:  # closed/reopened while computing
            return
        s.consecutive_errors = 0
        s.predictions += 1
        self.stats["predictions"] += 1
        ws = s.ws
        if (not s.unsent and not s.closing and ws.state is _OPEN and getattr(ws, "paused", True) is False
                and ws.transport.get_write_buffer_size() + len(text) + 16 <= self.config.write_limit):
            # Fast path: nothing queued before this reply and room in the socket's write buffer, so
            # ws.send() writes and returns without suspending (no flow-control wait).  Skips the
            # queue + writer task; a client that does not read fills the buffer and then the queue.
            await ws.send(text)
        else:
            self._send(s, text)


class ServerThread:
    """Run an :class:`InterprimServer` in a background thread with its own event loop.

    >>> with ServerThread(server) as st:   # doctest: +SKIP
    ...     Client(st.ws_url).open("highfive")
    """

    def __init__(self, server: InterprimServer):
        self.server = server
        self.loop = None
        self._thread = None
        self._ready = threading.Event()
        self._error = None

    def start(self) -> "ServerThread":
        def run():
            loop = new_event_loop(self.server.config.loop)
            self.loop = loop
            asyncio.set_event_loop(loop)
            try:
                loop.run_until_complete(self.server.start())
            except BaseException as exc:  # report bind errors to the caller
                self._error = exc
                self._ready.set()
                loop.close()
                return
            self._ready.set()
            try:
                loop.run_forever()
            finally:
                loop.run_until_complete(self.server.stop())
                loop.close()

        self._thread = threading.Thread(target=run, name="interprim-server", daemon=True)
        self._thread.start()
        self._ready.wait(30)
        if self._error is not None:
            raise self._error
        return self

    def stop(self) -> None:
        if self.loop is not None and self._thread is not None and self._thread.is_alive():
            self.loop.call_soon_threadsafe(self.loop.stop)
            self._thread.join(15)

    @property
    def url(self) -> str:
        return self.server.url

    @property
    def ws_url(self) -> str:
        return self.server.ws_url

    def call(self, fn, *args):
        """Run ``fn(*args)`` on the server's loop and return its result (for tests)."""
        import concurrent.futures

        fut: concurrent.futures.Future = concurrent.futures.Future()

        def go():
            try:
                fut.set_result(fn(*args))
            except BaseException as exc:
                fut.set_exception(exc)

        self.loop.call_soon_threadsafe(go)
        return fut.result(10)

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc):
        self.stop()

"""The WebSocket server: sessions, limits, the HTTP side (page, static files, JSON API).

One WebSocket connection is one *session*.  Inside it the client says ``hello``,
``open``\\s a model (or ``auto`` recognition among several), streams frames and
receives ``prediction`` (or ``error``) replies in ``seq`` order; each reply
``covers`` one frame, or, when the server is behind, all the frames the session
sent since its previous reply (every frame still enters the session's stream).
Each session owns its own ``model.stream()``; nothing is shared between sessions
except the read-only fitted models.

Concurrency: the asyncio event loop does all the I/O; the CPU-bound
``stream.update`` + trajectory + JSON encoding runs inline on the loop
(``workers=0``), in a thread pool (``workers=N``) or in worker processes
(``processes=N``), in fair turns over the sessions with pending frames (by client address,
then by session: :mod:`interprim.server.lanes`).  Replies go through a bounded per-session queue
drained by a writer task, so a client that never reads is detected (queue full)
and closed with code 1008 instead of growing the server's memory.

:meth:`InterprimServer.shutdown` (``interprim serve`` on SIGINT/SIGTERM) stops
accepting connections, answers the frames every session has sent, closes each
session with 1001 and joins the worker threads/processes.

Here: the configuration and the server's life cycle.  The server owns its state (the
configuration, the models, the live sessions and the statistics) and three parts it wires
together, each given exactly what it uses: :class:`~interprim.server.http_api.HttpApi`
(page, static files, JSON API), :class:`~interprim.server.lanes.Compute` (the lanes, the
thread pool or the worker processes) and :class:`~interprim.server.sessions.Sessions`
(the WebSocket sessions, which hand their frames to the lanes and get the replies back);
:mod:`interprim.server.compute` computes and encodes one reply.
"""

from __future__ import annotations

import asyncio
import ipaddress
import logging
import threading
from dataclasses import dataclass

from . import protocol as P
from .gate import ConnectionGate, fd_budget
from .http_api import HttpApi
from .lanes import Compute, Session
from .models import ModelEntry
from .sessions import SHUTDOWN_REASON, Sessions

log = logging.getLogger("interprim.server")

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
    max_pending: int = 64  # frames of one session waiting for their turn before the server stops reading it
    write_limit: int = 256 * 1024  # bytes buffered in the socket writer before send() waits
    max_points: int = 500
    default_points: int = 50
    max_errors: int = 200  # consecutive protocol errors before the session is closed
    hello_timeout: float = 5.0  # seconds from TCP accept to an accepted hello
    max_unauthenticated: int = 64  # connections without an accepted hello, in all ...
    max_unauthenticated_per_address: int = 8  # ... and from one IP address (the oldest is aborted for a new one)
    close_timeout: float = 2.0
    ping_interval: float | None = 20.0
    allowed_origins: tuple = ()  # browser Origins allowed besides those of the allowed hosts ("*": any)
    allowed_hosts: tuple = ()  # Host header names allowed besides the loopback names and the bound address
    fast_path: bool = True  # the server's own frame path (interprim.server.wsfast); False: the library does all
    log_errors_per_session: int = 10
    loop: str = "best"  # event loop: "best" (uvloop if installed), "uvloop", "asyncio" (see new_event_loop)

    def validate(self) -> None:
        """Check the limits and options; raises ``ValueError`` naming the first one that is wrong.

        Listening on a non-loopback host needs a ``token``; the port is in 0..65535; the counts must be at least 1,
        the rate positive, ``default_points`` in ``[2, max_points]``, ``loop`` one of ``auto``/``uvloop``/``asyncio``
        and ``max_message_bytes`` at least 256.
        """
        if not is_loopback(self.host) and not self.token:
            raise ValueError(
                f"refusing to listen on {self.host!r} without a token: anyone who can reach it could use the "
                "server. Pass --token (or set INTERPRIM_TOKEN), or keep the default --host 127.0.0.1"
            )
        if not 0 <= int(self.port) <= 65535:  # the socket layer would take it modulo 65536
            raise ValueError(f"port must be in 0..65535 (0: any free port), got {self.port}")
        for name in ("max_sessions", "max_message_bytes", "send_queue", "max_points", "rate_burst", "max_errors",
                     "max_pending", "max_unauthenticated", "max_unauthenticated_per_address"):
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
        if not self.hello_timeout > 0:
            raise ValueError(f"hello_timeout must be positive, got {self.hello_timeout}")
        for h in self.allowed_hosts:
            if not isinstance(h, str) or not h or "/" in h:
                raise ValueError(f"allowed host {h!r} is not a host name or address")
        if self.max_message_bytes < 256:
            raise ValueError("max_message_bytes must be at least 256 (a frame message needs room)")


LOOP_KINDS = ("best", "uvloop", "asyncio")


def new_event_loop(kind: str = "best") -> asyncio.AbstractEventLoop:
    """A new event loop: uvloop's (libuv, socket I/O and callbacks in C: about a third less CPU per
    frame for the server) when ``kind`` is "uvloop", or "best" and uvloop is installed; else asyncio's."""
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


def run(main, loop: str = "best"):
    """``asyncio.run(main)`` on :func:`new_event_loop`'s loop."""
    ev = new_event_loop(loop)
    try:
        asyncio.set_event_loop(ev)
        return ev.run_until_complete(main)
    finally:
        try:
            ev.run_until_complete(ev.shutdown_asyncgens())
            ev.run_until_complete(ev.shutdown_default_executor())  # joins the threads of run_in_executor(None, ...)
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


class InterprimServer:
    """A streaming server for fitted models.

    Parameters
    ----------
    models : dict of name -> ModelEntry
        From :func:`interprim.server.models.load_models` or :func:`interprim.server.demo.demo_models`.
    config : ServerConfig
    extra_info : dict, optional
        Extra JSON sent by ``GET /api/info`` (e.g. the sim's arm geometry).

    Attributes
    ----------
    sessions : dict of id -> session
        The live WebSocket sessions.
    stats : dict
        Counters since start: ``sessions``, ``predictions``, ``coalesced`` (frames answered by a later reply),
        ``errors`` and ``rejected`` (connections refused).
    port : int or None
        The port listened on, once :meth:`start` has bound it.
    http : HttpApi
        The page, static files and JSON API.
    compute : Compute
        Where replies are computed (inline, threads or worker processes).
    ws : Sessions
        The WebSocket sessions.
    """

    def __init__(self, models: dict, config: ServerConfig | None = None, extra_info: dict | None = None):
        self.config = config or ServerConfig()
        self.config.validate()
        if not models:
            raise ValueError("the server needs at least one model (model files, or --demo)")
        self.models: dict[str, ModelEntry] = dict(models)
        self.extra_info = dict(extra_info or {})
        self.sessions: dict[int, Session] = {}
        self.stats = {"sessions": 0, "predictions": 0, "coalesced": 0, "errors": 0, "rejected": 0}
        c = self.config
        # (the gate's deadline is a backstop: the session handler closes a connection without hello politely first)
        self.gate = ConnectionGate(c.max_unauthenticated, c.max_unauthenticated_per_address,
                                   c.hello_timeout + c.close_timeout + 1.0, self.stats)
        self.http = HttpApi(c, self.models, self.stats, self.extra_info)
        self.compute = Compute(self.models, workers=c.workers, processes=c.processes)
        self.ws = Sessions(c, self.models, self.compute, self.sessions, self.stats, self.http.info, self.gate)
        self._server = None
        self.port = None

    def info(self) -> dict:
        """The JSON of ``GET /api/info`` (:meth:`HttpApi.info`): server and protocol versions, whether a token is
        required, the models, the limits and the server's ``extra_info``."""
        return self.http.info()

    # ------------------------------------------------------------------ lifecycle
    async def start(self):
        """Start listening (on the running event loop) and return ``self``; the port is then in ``port``.

        First streams a few frames through each model (so the compiled kernels are loaded before the first
        client) or, with ``processes``, starts the worker processes.
        """
        from websockets.asyncio.server import ServerConnection, serve

        from .wsfast import FastFrames

        gate = self.gate

        class LoggedConnection(FastFrames, ServerConnection):
            """Counted by the server's :class:`~interprim.server.gate.ConnectionGate` from ``accept`` until its hello
            is accepted; logs connections that never complete an HTTP/WebSocket handshake (the library only
            debug-logs them); frames take the fast path of :mod:`interprim.server.wsfast`."""

            def connection_made(self, transport):
                super().connection_made(transport)
                gate.admit(self, transport, asyncio.get_running_loop())

            def connection_lost(self, exc):
                gate.lost(self)
                super().connection_lost(exc)

            async def handshake(self, *args, **kwargs):
                try:
                    await super().handshake(*args, **kwargs)
                except BaseException as exc:
                    log.warning("connection from %s: no complete handshake (%s)", _peer(self), type(exc).__name__)
                    raise
                if self.request is None and self.protocol.handshake_exc is not None:
                    log.warning("connection from %s: bad HTTP request: %s", _peer(self), self.protocol.handshake_exc)

        c = self.config
        if not c.fast_path:
            LoggedConnection.fast_path = False  # the library parses every byte
        sessions, unauth, msg = fd_budget(c.max_sessions, c.max_unauthenticated,
                                          extra=4 * (c.processes or 0) + (c.workers or 0))
        if msg:
            log.warning("%s", msg)
            c.max_sessions, c.max_unauthenticated = sessions, unauth
            self.gate.total = unauth
        await self.compute.start(self.ws.deliver)
        self._server = await serve(
            self.ws.handler,
            c.host,
            c.port,
            process_request=self.http.process_request,
            max_size=c.max_message_bytes,
            max_queue=16,
            write_limit=c.write_limit,
            compression=None,
            close_timeout=c.close_timeout,
            open_timeout=c.hello_timeout,
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
            + self.compute.describe(),
        )
        return self

    async def serve_forever(self):
        """:meth:`start` if needed, then serve until the task is cancelled or :meth:`stop` is called."""
        if self._server is None:
            await self.start()
        await self._server.serve_forever()

    async def shutdown(self, reason: str = SHUTDOWN_REASON) -> None:
        """Stop the server cleanly: stop accepting connections; let every session's frames received so far be
        answered, then close each session with 1001 (going away) and ``reason``; join the worker threads or
        processes.  Bounded: sessions still open ``close_timeout + 5`` s later are aborted.  Idempotent."""
        c = self.config
        self.ws.stop_accepting()
        srv, self._server = self._server, None
        if srv is not None:
            srv.close(close_connections=False)  # stop listening; wait_closed() waits for the handlers
            limit = c.close_timeout + 5.0
            await self.ws.close_all(P.CLOSE_GOING_AWAY, reason, limit)
            try:
                await asyncio.wait_for(srv.wait_closed(), limit)
            except (TimeoutError, asyncio.TimeoutError):
                log.warning("shutting down: %d session(s) still open after %.0f s; aborting them",
                            len(self.sessions), limit)
                self.ws.abort_all()
                try:
                    await asyncio.wait_for(srv.wait_closed(), limit)
                except (TimeoutError, asyncio.TimeoutError):
                    log.error("shutting down: connection handlers did not return; giving up on them")
        self.compute.stop()  # idle by now: the sessions are gone

    async def stop(self):
        """:meth:`shutdown` with the default reason."""
        await self.shutdown()

    @property
    def url(self) -> str:
        """``http://host:port/``, the live page (the port once :meth:`start` has bound it)."""
        host = self.config.host
        if ":" in host:
            host = f"[{host}]"
        return f"http://{host}:{self.port}/"

    @property
    def ws_url(self) -> str:
        """``ws://host:port/ws``, the WebSocket endpoint for the clients."""
        return self.url.replace("http://", "ws://", 1) + "ws"


class ServerThread:
    """Run an :class:`InterprimServer` in a background thread with its own event loop.

    >>> with ServerThread(server) as st:   # doctest: +SKIP
    ...     Client(st.ws_url).open("highfive")
    """

    def __init__(self, server: InterprimServer):
        self.server = server
        self.loop = None
        self._thread: threading.Thread | None = None
        self._ready = threading.Event()
        self._error = None

    def start(self) -> ServerThread:
        """Start the server in a daemon thread; returns ``self`` once it listens (waits up to 30 s).

        An error while starting (e.g. the port is taken) is raised here, in the caller's thread.
        """
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
                try:
                    loop.run_until_complete(self.server.stop())
                    loop.run_until_complete(loop.shutdown_default_executor())
                finally:
                    loop.close()

        self._thread = threading.Thread(target=run, name="interprim-server", daemon=True)
        self._thread.start()
        self._ready.wait(30)
        if self._error is not None:
            raise self._error
        return self

    def stop(self) -> None:
        """Stop the event loop, which stops the server (see :meth:`InterprimServer.stop`); waits up to 15 s."""
        if self.loop is not None and self._thread is not None and self._thread.is_alive():
            self.loop.call_soon_threadsafe(self.loop.stop)
            self._thread.join(15)

    @property
    def url(self) -> str:
        """The server's ``http://host:port/``."""
        return self.server.url

    @property
    def ws_url(self) -> str:
        """The server's ``ws://host:port/ws``."""
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

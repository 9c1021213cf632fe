"""The WebSocket side of the server: one session per connection, its messages, frames and replies.

:class:`Sessions` is given what it uses: the configuration, the models, the compute lanes
(:class:`~interprim.server.lanes.Compute`), the table of live sessions and the statistics it updates,
and the ``/api/info`` JSON that ``welcome`` repeats; :class:`~interprim.server.app.InterprimServer`
owns them and passes :meth:`Sessions.handler` to the WebSocket library.

A session's handler reads its messages as they come.  A valid frame joins the session's pending
frames and its lane computes them in fair turns (:mod:`interprim.server.lanes`: one reply per
turn, which ``covers`` every frame of the turn).  Anything else (a control message, an error reply)
first waits until the session's pending frames are answered, so replies keep the order of ``seq``.
"""

from __future__ import annotations

import asyncio
import itertools
import logging
import time

from . import protocol as P
from . import wsfast
from .compute import OpenModel, Recognition
from .gate import RateLimitedLog
from .http_api import token_ok
from .lanes import Session, TokenBucket, client_key
from .wsfast import FastFrames

SHUTDOWN_REASON = "server shutting down"  # start of the close reason (code 1001) sent to every session at shutdown

log = logging.getLogger("interprim.server")


def _host(ws) -> str:
    """The peer's address without the port (``?`` when unknown)."""
    try:
        return str(ws.remote_address[0])
    except Exception:
        return "?"

_CLOSE = object()


class Sessions:
    """The WebSocket sessions: each one's life (handshake, ``hello``/``open``/``close`` messages, frames, replies and
    errors) and the server's shutdown of all of them.

    Parameters
    ----------
    config : ServerConfig
        Limits and options.
    models : dict of name -> ModelEntry
        The served models (what ``open`` may name).
    compute : interprim.server.lanes.Compute
        Where the sessions' frames are computed (:meth:`deliver` gets the results).
    sessions : dict of id -> session
        The live sessions, kept up to date here (the server's ``sessions``).
    stats : dict
        The server's counters (``sessions``, ``predictions``, ``coalesced``, ``errors``, ``rejected``), updated here.
    info : callable
        ``info()`` -> the ``/api/info`` JSON, whose ``server``, ``models`` and ``limits`` the ``welcome`` repeats.
    """

    def __init__(self, config, models: dict, compute, sessions: dict, stats: dict, info, gate=None):
        self.config = config
        self.gate = gate  # the unauthenticated connections (interprim.server.gate.ConnectionGate)
        self.models = models
        self.compute = compute
        self.sessions = sessions
        self.stats = stats
        self._info = info
        self._ids = itertools.count(1)
        self._fail_log = RateLimitedLog(log, burst=10, period=10.0)  # prediction failures (tracebacks)
        self._conn_log = RateLimitedLog(log, burst=10, period=10.0)  # connections gone before hello
        self.stopping = False  # shutting down: new connections are closed with 1001, messages no longer read

    async def _refuse_full(self, ws, peer: str) -> None:
        self.stats["rejected"] += 1
        log.warning("connection from %s refused: server full (%d sessions)", peer, self.config.max_sessions)
        await ws.close(P.CLOSE_TRY_AGAIN, f"server full: at most {self.config.max_sessions} sessions; try again later")

    async def _await_hello(self, ws, peer: str, t0: float):
        """Read messages until an accepted ``hello`` (returns ``(hello, frames_seen)``) or the end: a wrong token
        (``unauthorized``, close 1008), the hello deadline (close 1008), too many other messages (close 1008) or
        the connection going away (returns ``None``).  Nothing of a session exists yet: replies go straight to the
        socket.  Messages before hello get the usual errors (``not_ready``, ``bad_json``, ...)."""
        from websockets.exceptions import ConnectionClosed

        c = self.config
        loop = asyncio.get_running_loop()
        errors = frames = 0
        limit = min(c.max_errors, 16)
        try:
            while True:
                left = c.hello_timeout - (loop.time() - t0)
                try:
                    if left <= 0:
                        raise asyncio.TimeoutError
                    data = await asyncio.wait_for(ws.recv(), left)  # (3.10: no asyncio.timeout)
                except (TimeoutError, asyncio.TimeoutError):
                    log.warning("connection from %s closed: no hello within %g s", peer, c.hello_timeout)
                    await ws.close(P.CLOSE_POLICY, f"no hello within {c.hello_timeout:g} s")
                    return None
                except UnicodeDecodeError as exc:  # websockets < 14 raises instead of closing with 1007
                    await ws.close(P.CLOSE_INVALID_DATA, f"text message is not valid UTF-8: {exc.reason}")
                    return None
                if self.stopping:
                    await ws.close(P.CLOSE_GOING_AWAY, SHUTDOWN_REASON)
                    return None
                seq = t = None
                try:
                    if not isinstance(data, str):
                        frames += 1
                        seq = frames
                        raise P.ProtocolError("not_ready", "send hello first (got a frame)")
                    try:
                        msg = P.parse_text(data)
                    except P.ProtocolError as exc:
                        if exc.code == "bad_json":
                            looks_like_frame, t = P.scan_unparsed(data)
                            if looks_like_frame:
                                frames += 1
                                seq = frames
                        raise
                    if msg["type"] == "frame":
                        frames += 1
                        seq, t = frames, P.frame_stamp(msg)
                    if msg["type"] != "hello":
                        what = "a frame" if msg["type"] == "frame" else repr(msg["type"])
                        raise P.ProtocolError("not_ready", f"send hello first (got {what})")
                    h = P.check_hello(msg)
                    if not token_ok(c.token, h["token"]):
                        log.warning("connection from %s closed: missing or wrong token in hello", peer)
                        await ws.send(P.dumps(P.error("unauthorized", "missing or wrong token in hello")))
                        await ws.close(P.CLOSE_POLICY, "missing or wrong token in hello")
                        return None
                    return h, frames
                except P.ProtocolError as exc:
                    errors += 1
                    self.stats["errors"] += 1
                    await ws.send(P.dumps(P.error(exc.code, exc.message, seq=seq, t=t)))
                    if exc.fatal:
                        log.warning("connection from %s closed before hello: %s", peer, exc.message)
                        await ws.close(P.CLOSE_POLICY, exc.message[:120])
                        return None
                    if errors >= limit:
                        log.warning("connection from %s closed: %d messages before hello", peer, errors)
                        await ws.close(P.CLOSE_POLICY, f"too many protocol errors ({errors} in a row) before hello")
                        return None
        except ConnectionClosed:
            self._conn_log.log(logging.INFO, "connection from %s: ended before an accepted hello", peer)
            return None

    async def handler(self, ws):
        """Serve one WebSocket connection (the WebSocket library's connection handler) until it closes.

        Authenticate before allocating: until its ``hello`` is accepted (with the token, when the server has
        one) a connection holds no session slot, queue, writer or stream; it is only counted by the server's
        :class:`~interprim.server.gate.ConnectionGate`."""
        c = self.config
        loop = asyncio.get_running_loop()
        t0 = getattr(ws, "gate_t0", None) or loop.time()
        try:
            peer = "%s:%s" % tuple(ws.remote_address[:2])
        except Exception:
            peer = "?"
        if self.stopping:  # accepted while shutting down
            await ws.close(P.CLOSE_GOING_AWAY, SHUTDOWN_REASON)
            return
        if len(self.sessions) >= c.max_sessions:  # no use reading a hello
            await self._refuse_full(ws, peer)
            return
        got = await self._await_hello(ws, peer, t0)
        if got is None:
            return
        if len(self.sessions) >= c.max_sessions:
            await self._refuse_full(ws, peer)
            return
        if self.gate is not None:
            self.gate.authenticated(ws)
        sid = next(self._ids)
        s = Session(sid, ws, peer, asyncio.Queue(maxsize=c.send_queue), TokenBucket(c.max_rate_hz, c.rate_burst),
                    client=client_key(_host(ws)))
        s.seq = got[1]
        if c.fast_path and isinstance(ws, FastFrames) and wsfast.supported(ws):
            s.direct = True
            ws.fast_frame = lambda data: self._fast_frame(s, data)
        self.sessions[sid] = s
        self.stats["sessions"] += 1
        s.writer = loop.create_task(self._writer(s))
        log.info("session %d: connected from %s (%d active)", sid, peer, len(self.sessions))
        from websockets.exceptions import ConnectionClosed

        try:
            self._welcome(s)
            while not s.closing:
                try:
                    data = await ws.recv()
                except UnicodeDecodeError as exc:  # websockets < 14 raises instead of closing with 1007
                    self._fatal(s, P.CLOSE_INVALID_DATA, f"text message is not valid UTF-8: {exc.reason}")
                    break
                if self.stopping:
                    continue  # shutting down: not read any more (the close reason says which frames were answered)
                if self._frame_at_once(s, data):  # the usual message: a valid frame of an open session
                    if s.queued and len(s.pending) >= c.max_pending:
                        await self._far_behind(s)
                    continue
                s.busy = True
                try:
                    queued = await self._on_message(s, data)
                finally:
                    s.busy = False
                    s.wake()
                if not queued and s.unsent:
                    # A reply of the handler's own (control, error): let the writer push it to the socket now,
                    # so the queue only fills up when the socket's write buffer is full (a client not reading).
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
            s.ended = True
            if isinstance(ws, FastFrames):
                ws.fast_frame = None
            s.wake()
            self.sessions.pop(sid, None)
            if self.compute.remote and s.open is not None:
                s.open = None
                try:
                    await self.compute.call(sid, "drop")
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
            log.info("session %d: ended (%d frames, %d predictions, %d frames coalesced%s)", sid, s.seq, s.predictions,
                     s.coalesced, extra)

    async def _writer(self, s: Session):
        from websockets.exceptions import ConnectionClosed

        try:
            while True:
                item = await s.out.get()
                if isinstance(item, tuple) and item and item[0] is _CLOSE:
                    await s.ws.close(item[1], item[2])
                    return
                await s.ws.send(item, text=True)  # (bytes: UTF-8 JSON from a worker process)
                s.unsent -= 1
        except ConnectionClosed:
            return

    def _send(self, s: Session, text) -> None:
        """Send a reply (``str``, or ``bytes`` of UTF-8 JSON): written at once when the session's writer has nothing
        queued and the socket takes it (:func:`~interprim.server.wsfast.write_now`), else queued for the writer
        (order kept: the writer sends what was queued before)."""
        if s.closing:
            return
        if s.direct and s.unsent == 0 and wsfast.write_now(s.ws, text):
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
            if s.writer is not None:
                s.writer.cancel()
            s.writer = asyncio.get_running_loop().create_task(s.ws.close(P.CLOSE_POLICY, reason))

    def _fatal(self, s: Session, code: int, reason: str, message: dict | None = None, level=logging.WARNING) -> None:
        if s.closing:
            return
        log.log(level, "session %d: closing %d: %s", s.id, code, reason)
        if message is not None:
            self._send(s, P.dumps(message))
        if s.closing:  # _send found the queue full
            return
        s.closing = True
        s.close_reason = reason
        try:
            s.out.put_nowait((_CLOSE, code, reason[:120]))
        except asyncio.QueueFull:
            if s.writer is not None:
                s.writer.cancel()
            s.writer = asyncio.get_running_loop().create_task(s.ws.close(code, reason[:120]))

    def _error(self, s: Session, exc: P.ProtocolError, seq=None, t=None) -> None:
        s.errors += 1
        if exc.code != "rate_limited":  # dropping is the limit's own answer; not a protocol violation
            s.consecutive_errors += 1
        s.error_counts[exc.code] = s.error_counts.get(exc.code, 0) + 1
        self.stats["errors"] += 1
        if s.errors <= self.config.log_errors_per_session:
            log.warning("session %d: %s: %s%s", s.id, exc.code, exc.message, f" (seq {seq})" if seq else "")
        elif s.errors == self.config.log_errors_per_session + 1:
            log.warning("session %d: further errors are counted, not logged", s.id)
        msg = P.error(exc.code, exc.message, seq=seq, t=t)
        if exc.fatal:
            self._fatal(s, P.CLOSE_POLICY, exc.message, msg)
        elif s.consecutive_errors >= self.config.max_errors:
            self._send(s, P.dumps(msg))
            self._fatal(s, P.CLOSE_POLICY, f"too many protocol errors ({s.consecutive_errors} in a row)")
        else:
            self._send(s, P.dumps(msg))

    def _frame_at_once(self, s: Session, data) -> bool:
        """A valid frame of a session with an open model, within the rate limit: put it in the session's pending
        frames without a coroutine (the common case, per frame).  ``False`` (nothing done) for anything else,
        which :meth:`_on_message` then handles, errors included."""
        op = s.open
        if op is None or not s.ready:
            return False
        n = op.entries[0].n_observed
        try:
            if isinstance(data, str):
                msg = P.parse_text(data)
                if msg["type"] != "frame":
                    return False
                frame, t = P.check_frame(msg, n)
            elif isinstance(data, bytes):
                frame, t = P.decode_binary_frame(data, n), None
            else:
                return False
        except P.ProtocolError:
            return False
        if not s.bucket.take():  # (an empty bucket stays empty for _on_message's own try)
            return False
        s.seq += 1
        s.pending.append((frame, s.seq, t))
        if not s.queued:
            self.compute.push(s)
        return True

    def _fast_frame(self, s: Session, data) -> bool:
        """A message straight from the connection's bytes (:class:`~interprim.server.wsfast.FastFrames`, offered
        only while no earlier message waits for the handler): taken if it is a valid frame that
        :meth:`_frame_at_once` takes and the handler is between two messages (not waiting for an earlier one's
        turn) and the session is not near ``max_pending``; else ``False`` and the handler gets it, in order."""
        if s.busy or s.closing or s.ended or self.stopping or len(s.pending) + 1 >= self.config.max_pending:
            return False
        return self._frame_at_once(s, data)

    async def _far_behind(self, s: Session) -> None:
        """``max_pending`` frames waiting: stop reading the session until its turn (the server cannot even feed its
        frames to its streams as fast as they come), so that TCP flow control slows the client down."""
        limit = self.config.max_pending
        s.busy = True
        t0 = time.monotonic()
        try:
            await self._until(s, lambda: len(s.pending) < limit or not s.queued)
            # The frames the client sent meanwhile wait in TCP and arrive as one burst when reading resumes: the
            # server's doing, not the client's.  Credit the pause to its rate limit (beyond the burst), so that a
            # client within the rate never gets rate_limited for them; they are coalesced into the next turn.
            s.bucket.credit(time.monotonic() - t0)
        finally:
            s.busy = False
            s.wake()

    async def _on_message(self, s: Session, data) -> bool:
        """Handle one message; ``True`` when it was a frame put in the session's pending frames."""
        c = self.config
        is_frame = isinstance(data, (bytes, bytearray, memoryview))
        msg = None
        if not is_frame:
            try:
                msg = P.parse_text(data)
            except P.ProtocolError as exc:
                seq = t = None
                if exc.code == "bad_json":  # a frame that is not JSON (e.g. NaN) still counts as a frame
                    looks_like_frame, t = P.scan_unparsed(data)
                    if looks_like_frame:
                        s.seq += 1
                        seq = s.seq
                if not s.bucket.take():
                    await self._reply_error(s, P.ProtocolError("rate_limited", f"over {c.max_rate_hz:g} messages/s"),
                                            seq, t)
                else:
                    await self._reply_error(s, exc, seq, t)
                return False
            is_frame = msg["type"] == "frame"
        seq = t = None
        if is_frame:
            s.seq += 1
            seq = s.seq
            t = P.frame_stamp(msg)
        if not s.bucket.take():
            await self._reply_error(
                s, P.ProtocolError("rate_limited",
                                   f"over {c.max_rate_hz:g} messages/s (burst {c.rate_burst}); dropped"), seq, t)
            return False
        try:
            if is_frame:
                assert seq is not None  # counted above
                await self._on_frame(s, data, msg, seq)
                return True
            if s.queued:  # answer the frames received before this message first
                await self._until(s, lambda: not s.queued)
            assert msg is not None  # a control message is parsed text
            await self._on_control(s, msg)
        except P.ProtocolError as exc:
            await self._reply_error(s, exc, seq, t)
        return False

    async def _reply_error(self, s: Session, exc: P.ProtocolError, seq=None, t=None) -> None:
        """:meth:`_error`, after the replies to the frames received before (replies stay in ``seq`` order)."""
        if s.queued:
            await self._until(s, lambda: not s.queued)
        self._error(s, exc, seq, t)

    async def _until(self, s: Session, cond) -> None:
        """Wait until ``cond()`` holds; it is checked whenever the session's lane or handler changes its state."""
        loop = None
        while not cond():
            loop = loop or asyncio.get_running_loop()
            fut = loop.create_future()
            s.waiters.append(fut)
            await fut

    def _welcome(self, s: Session) -> None:
        s.ready = True
        s.consecutive_errors = 0
        reply = {"type": "welcome", "version": P.PROTOCOL_VERSION, "session": s.id}
        reply.update({k: v for k, v in self._info().items() if k in ("server", "models", "limits")})
        self._send(s, P.dumps(reply))

    async def _on_control(self, s: Session, msg: dict) -> None:
        c = self.config
        mtype = msg["type"]
        if mtype == "hello":
            h = P.check_hello(msg)
            if not token_ok(c.token, h["token"]):
                raise P.ProtocolError("unauthorized", "missing or wrong token in hello", fatal=True)
            self._welcome(s)
            return
        if not s.ready:
            raise P.ProtocolError("not_ready", f"send hello first (got {mtype!r})")
        if mtype == "open":
            o = P.check_open(msg, self.models, default_points=c.default_points, max_points=c.max_points)
            entries = [self.models[n] for n in o["candidates"]]
            for e in entries:
                P.check_robot_state_for(o["robot_state"], e.name, len(e.controlled_dofs), "open.robot_state")
            rec = None
            # "recognise": the Recogniser must take the candidates (made here, used in this process)
            if len(entries) > 1:
                try:
                    rec = Recognition(entries)
                except (TypeError, ValueError, AttributeError) as exc:
                    raise P.ProtocolError(
                        "bad_message", f"'recognise' cannot recognise among {o['candidates']}: {exc}") from None
            streams, cols = [], []
            for e in entries:
                dofs = o["dofs"] or ("all" if e.kind == "single" or not e.controlled_dofs else "controlled")
                cols.append(list(range(e.n_dofs)) if dofs == "all" else e.controlled_dofs)
                if not self.compute.remote:
                    try:
                        streams.append(e.model.stream(robot_state=o["robot_state"]))
                    except (ValueError, TypeError) as exc:
                        raise P.ProtocolError("bad_message", f"open.robot_state for model {e.name!r}: {exc}") from None
            if self.compute.remote:
                s.open = None
                try:
                    await self.compute.call(s.id, "open", model=o["model"], candidates=o["candidates"], cols=cols,
                                           points=o["points"], std=o["std"], robot_state=o["robot_state"])
                except RuntimeError as exc:
                    raise P.ProtocolError("bad_message", f"open failed: {exc}") from None
            s.open = OpenModel(o["model"], entries, streams, cols, o["points"], o["std"],
                           recognition=None if self.compute.remote else rec)
            if streams:  # mean-only updates are much cheaper without a band (every stream takes need_cov)
                s.open.update_kw = {"need_cov": o["std"]}
            s.consecutive_errors = 0
            log.info("session %d: opened %s%s", s.id, o["model"],
                     f" among {o['candidates']}" if o["model"] == "recognise" else "")
            self._send(s, P.dumps(_opened(o, entries, cols)))
            return
        if s.open is None:
            raise P.ProtocolError("not_open", f"{mtype!r} needs an open session: send open first")
        if mtype == "reset":
            rs = P.check_reset(msg)
            for e in s.open.entries:
                P.check_robot_state_for(rs, e.name, len(e.controlled_dofs), "reset.robot_state")
            if self.compute.remote:
                try:
                    await self.compute.call(s.id, "reset", robot_state=rs)
                except RuntimeError as exc:
                    raise P.ProtocolError("internal", f"reset failed: {exc}") from None
            s.open.reset(robot_state=rs)
            s.consecutive_errors = 0
            self._send(s, P.dumps({"type": "reset_done", "seq": s.seq}))
        elif mtype == "close":
            s.open = None
            if self.compute.remote:
                try:
                    await self.compute.call(s.id, "drop")
                except RuntimeError:
                    pass
            s.consecutive_errors = 0
            self._send(s, P.dumps({"type": "closed", "seq": s.seq}))

    async def _on_frame(self, s: Session, data, msg, seq: int) -> None:
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
        s.pending.append((frame, seq, t))
        if not s.queued:
            self.compute.push(s)
        elif len(s.pending) >= self.config.max_pending:
            await self._until(s, lambda: len(s.pending) < self.config.max_pending or not s.queued)

    def deliver(self, s: Session, op: OpenModel, batch: list, result) -> None:
        """Send the replies of a computed batch (called by the lanes): ``result`` is ``(texts, failures)`` from
        :func:`~interprim.server.compute.compute_batch`, or the exception that stopped the computation."""
        if isinstance(result, BaseException):
            failures = [(batch[-1][1], f"{type(result).__name__}: {result}")]
            n = len(batch)
            extra = {"covers": n, "first_seq": batch[0][1]} if n > 1 else {}
            texts = [P.dumps(P.error("internal", f"prediction failed: {type(result).__name__}: {result}",
                                     seq=batch[-1][1], t=batch[-1][2], **extra))]
        else:
            texts, failures = result
        for seq, detail in failures:
            self.stats["errors"] += 1
            s.errors += 1
            if detail is None:  # a frame refused by the model's guard (bad_frame), answered on its own
                s.error_counts["bad_frame"] = s.error_counts.get("bad_frame", 0) + 1
                self._fail_log.log(logging.WARNING, "session %d: frame seq %d refused: out of the model's numeric "
                                   "range", s.id, seq)
                continue
            s.error_counts["internal"] = s.error_counts.get("internal", 0) + 1
            first = s.error_counts["internal"] == 1
            # a full traceback for a session's first failure, one line after; at most 10 lines per 10 s in all
            self._fail_log.log(logging.ERROR, "session %d: prediction failed at seq %d%s", s.id, seq,
                               ":\n" + detail.rstrip() if first else f": {detail.rstrip().splitlines()[-1]}")
        if s.ended or s.open is not op:  # gone, or closed while computing
            return
        n_pred = len(texts) - len(failures)
        s.predictions += n_pred
        s.coalesced += len(batch) - len(texts)
        self.stats["predictions"] += n_pred
        self.stats["coalesced"] += len(batch) - len(texts)
        if n_pred:
            s.consecutive_errors = 0
        for text in texts:
            self._send(s, text)

    async def _going_away(self, s: Session, code: int, reason: str) -> None:
        """Shutdown of one session: once the frames it sent are answered (and the handler is between two
        messages), close it with ``code`` and a reason that names the last frame answered."""
        await self._until(s, lambda: s.ended or not (s.busy or s.queued))
        if not s.ended:
            self._fatal(s, code, f"{reason}; frames up to seq {s.seq} answered", level=logging.INFO)

    def stop_accepting(self) -> None:
        """From now on, close new connections with 1001 and stop reading the messages of the live sessions."""
        self.stopping = True

    async def close_all(self, code: int, reason: str, timeout: float) -> None:
        """Close every live session with ``code`` once the frames it sent are answered (:meth:`_going_away`); the
        sessions whose turn has not come within ``timeout`` seconds are left to :meth:`abort_all`."""
        live = list(self.sessions.values())
        if not live:
            return
        log.info("shutting down: closing %d session(s) with %d once their frames are answered", len(live), code)
        loop = asyncio.get_running_loop()
        tasks = [loop.create_task(self._going_away(s, code, reason)) for s in live]
        _, late = await asyncio.wait(tasks, timeout=timeout)
        for t in late:
            t.cancel()

    def abort_all(self) -> None:
        """Abort the TCP connection of every session still open (a shutdown that waited long enough)."""
        for s in list(self.sessions.values()):
            transport = getattr(s.ws, "transport", None)
            if transport is not None:
                transport.abort()


def _opened(o: dict, entries: list, cols: list) -> dict:
    """The ``opened`` reply: what was opened and how to label it (names and units of the returned columns
    and of the frame's values); one list per candidate (an object keyed by name) with ``"recognise"``."""
    def per(fn):
        vals = [fn(e, cl) for e, cl in zip(entries, cols)]
        return vals[0] if len(vals) == 1 else {e.name: v for e, v in zip(entries, vals)}

    return {
        "type": "opened",
        "model": o["model"],
        "candidates": o["candidates"],
        "n_observed": entries[0].n_observed,
        "columns": per(lambda e, cl: list(cl)),
        "points": o["points"],
        "std": o["std"],
        "column_names": per(lambda e, cl: [e.names[i] for i in cl]),
        "column_units": per(lambda e, cl: [e.units[i] for i in cl]),
        "observed_dofs": per(lambda e, cl: e.observed_dofs),
        "observed_names": per(lambda e, cl: [e.names[i] for i in e.observed_dofs]),
        "observed_units": per(lambda e, cl: [e.units[i] for i in e.observed_dofs]),
        "min_frames": max(e.min_frames for e in entries),
        "robot_state": o["robot_state"],
    }

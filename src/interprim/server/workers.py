"""Worker processes for the prediction maths (``interprim serve --processes N``).

The per-frame work (``stream.update`` + trajectory + JSON) is CPU-bound Python and numpy on small
arrays, so threads do not run it in parallel (the GIL).  With ``--processes N`` every session is
pinned to one of N worker processes, which owns that session's ``model.stream()``; the event loop
only does the network I/O.  A slow session then only delays the sessions of its own worker.

Models reach the workers as safe ``.npz`` model files (``model.save`` / :func:`interprim.load_any`, whatever model a
file holds); requests and replies are JSON over a ``multiprocessing`` pipe (``send_bytes``/``recv_bytes``; no
pickle).  A request is one JSON header line, then (for frames) the frames as raw little-endian float64
values; a reply is one JSON header line, then (for predictions) the finished JSON texts for the
client, one per line, so they are not encoded twice.  A session's pending frames go to its worker in
one ``frames`` request (:func:`interprim.server.compute.compute_batch`): ``n`` frames of ``d`` values, the
first one's ``seq`` (the others follow it) and their ``t`` (omitted when none has one).

Workers ignore SIGINT and SIGTERM (Ctrl-C reaches the whole process group): they stop when the server
asks them to at its shutdown, or when their pipe closes because the server is gone.
"""

from __future__ import annotations

import asyncio
import itertools
import json
import logging
import multiprocessing as mp
import os
import signal
import tempfile
import time
from pathlib import Path

log = logging.getLogger("interprim.server")


_STOP_SIGNALS = tuple(getattr(signal, n) for n in ("SIGINT", "SIGTERM") if hasattr(signal, n))


def _worker_main(conn, paths: dict, kinds: dict) -> None:  # runs in the worker process
    for sig in _STOP_SIGNALS:  # the server stops its workers itself (see the module's docstring)
        signal.signal(sig, signal.SIG_IGN)
    import numpy as np

    from ..models.files import load_any
    from .compute import OpenModel, compute_batch, warm_up
    from .models import entry_for

    entries = {n: entry_for(n, load_any(p), source=p, kind=kinds.get(n)) for n, p in paths.items()}
    warm_up(entries.values())
    sessions: dict = {}
    conn.send_bytes(b'{"ready":true}\n')
    while True:
        try:
            data = conn.recv_bytes()
        except (EOFError, OSError):
            return
        head_line, _, payload = data.partition(b"\n")
        req = json.loads(head_line)
        op, rid = req["op"], req["rid"]
        body = b""
        head = {"rid": rid, "ok": True}
        try:
            if op == "frames":
                o = sessions[req["sid"]]
                n, seq0 = int(req["n"]), int(req["seq"])
                block = np.frombuffer(payload, dtype="<f8").reshape(n, int(req["d"]))
                ts = req.get("ts") or [None] * n
                batch = [(block[i], seq0 + i, ts[i]) for i in range(n)]
                t0 = time.perf_counter()
                texts, failures = compute_batch(o, batch)
                head["cost"] = time.perf_counter() - t0  # the lane's fair queuing charges the session this
                body = "\n".join(texts).encode()
                if failures:
                    head["failures"] = failures
            elif op == "open":
                es = [entries[n] for n in req["candidates"]]
                streams = [e.model.stream(robot_state=req.get("robot_state")) for e in es]
                o = OpenModel(req["model"], es, streams, req["cols"], req["points"], req["std"])
                if streams:  # every stream takes need_cov (interprim.models.base)
                    o.update_kw = {"need_cov": req["std"]}
                sessions[req["sid"]] = o
            elif op == "reset":
                sessions[req["sid"]].reset(robot_state=req.get("robot_state"))
            elif op == "drop":
                sessions.pop(req["sid"], None)
            elif op == "stop":
                return
        except Exception as exc:  # reported to the session as an internal error
            head = {"rid": rid, "ok": False, "error": f"{type(exc).__name__}: {exc}"}
        conn.send_bytes(json.dumps(head).encode() + b"\n" + body)


class _Worker:
    def __init__(self, proc, conn):
        self.proc = proc
        self.conn = conn
        self.pending: dict = {}
        self.dead = False


class ProcessPool:
    """N worker processes; ``await pool.call(sid, op, **fields)``."""

    def __init__(self, models: dict, n: int):
        self.models = models
        self.n = int(n)
        self.workers: list[_Worker] = []
        self._rid = itertools.count(1)
        self._tmp: tempfile.TemporaryDirectory | None = None
        self._loop: asyncio.AbstractEventLoop | None = None

    @property
    def loop(self) -> asyncio.AbstractEventLoop:
        """The event loop the pool is attached to (:meth:`attach`)."""
        if self._loop is None:
            raise RuntimeError("the worker pool is not attached to an event loop")
        return self._loop

    def start(self) -> None:
        """Save the models, start the processes and wait until they have loaded them (blocking)."""
        self._tmp = tempfile.TemporaryDirectory(prefix="interprim-serve-")
        paths, kinds = {}, {}
        for name, e in self.models.items():
            src = Path(e.source) if e.source else None
            if src is not None and src.suffix == ".npz" and src.is_file():
                paths[name] = str(src)
            else:
                p = Path(self._tmp.name) / f"{name}.npz"
                e.model.save(str(p))
                paths[name] = str(p)
            kinds[name] = e.kind
        ctx = mp.get_context("spawn")
        # Block SIGINT/SIGTERM in this thread while spawning: the children inherit the mask, so a Ctrl-C during
        # their start-up (before _worker_main ignores it) cannot print a KeyboardInterrupt traceback.
        masked = hasattr(signal, "pthread_sigmask") and bool(_STOP_SIGNALS)
        old_mask = signal.pthread_sigmask(signal.SIG_BLOCK, _STOP_SIGNALS) if masked else None
        try:
            for i in range(self.n):
                parent, child = ctx.Pipe()
                proc = ctx.Process(target=_worker_main, args=(child, paths, kinds), name=f"interprim-worker-{i}",
                                   daemon=True)
                proc.start()
                child.close()
                self.workers.append(_Worker(proc, parent))
        finally:
            if old_mask is not None:
                signal.pthread_sigmask(signal.SIG_SETMASK, old_mask)
        for w in self.workers:
            if not w.conn.poll(120):
                raise RuntimeError(f"worker process {w.proc.name} did not start")
            w.conn.recv_bytes()
        log.info("started %d worker process(es): pids %s", self.n, [w.proc.pid for w in self.workers])

    def attach(self, loop) -> None:
        self._loop = loop
        for w in self.workers:
            loop.add_reader(w.conn.fileno(), self._on_readable, w)
            # uvloop (libuv's poll handle) switches the descriptor to non-blocking mode; the pipe's framed
            # recv_bytes/send_bytes need it blocking, or a reply larger than the socket buffer (500 points +
            # band: ~35 kB) is read half and raises BlockingIOError.  Readiness polling works either way.
            os.set_blocking(w.conn.fileno(), True)

    def _on_readable(self, w: _Worker) -> None:
        # One reply per call: the pipe is readable, so the read does not wait for the worker (it writes each reply
        # whole), and the event loop calls again while more replies are in the pipe.  (Conn.poll() before each
        # read would build a selector per call: it cost more than the rest of a reply.)
        try:
            data = w.conn.recv_bytes()
        except (EOFError, OSError):
            self._lost(w)
            return
        head, _, body = data.partition(b"\n")
        h = json.loads(head)
        fut = w.pending.pop(h["rid"], None)
        if fut is None or fut.done():
            return
        if h["ok"]:
            fut.set_result((h, body))
        else:
            fut.set_exception(RuntimeError(h["error"]))

    def _lost(self, w: _Worker) -> None:
        if w.dead:
            return
        w.dead = True
        try:
            self.loop.remove_reader(w.conn.fileno())
        except Exception:
            pass
        log.error("worker process %s (pid %s) died; its sessions get 'internal' errors", w.proc.name, w.proc.pid)
        for fut in w.pending.values():
            if not fut.done():
                fut.set_exception(RuntimeError("worker process died"))
        w.pending.clear()

    def worker_of(self, sid: int) -> _Worker:
        return self.workers[sid % self.n]

    async def call(self, sid: int, op: str, **fields) -> str:
        """Run ``op`` for session ``sid`` on its worker; returns the reply's body (text)."""
        _, body = await self.request(sid, op, **fields)
        return body.decode()

    async def request(self, sid: int, op: str, payload: bytes = b"", **fields) -> tuple:
        """Run ``op`` for session ``sid`` on its worker (``payload``: raw bytes after the JSON header, the
        frames of a ``frames`` request); returns the reply's ``(header dict, body bytes)``."""
        w = self.worker_of(sid)
        if w.dead:
            raise RuntimeError("worker process died")
        rid = next(self._rid)
        fut = self.loop.create_future()
        w.pending[rid] = fut
        try:
            w.conn.send_bytes(json.dumps({"op": op, "rid": rid, "sid": sid, **fields}).encode() + b"\n" + payload)
        except (OSError, ValueError):
            w.pending.pop(rid, None)
            self._lost(w)
            raise RuntimeError("worker process died") from None
        return await fut

    def stop(self) -> None:
        for w in self.workers:
            try:
                if self._loop is not None and not w.dead:
                    self.loop.remove_reader(w.conn.fileno())
            except Exception:
                pass
            try:
                w.conn.send_bytes(b'{"op":"stop","rid":0,"sid":0}')
            except Exception:
                pass
        for w in self.workers:
            w.proc.join(5)
            if w.proc.is_alive():
                w.proc.terminate()
                w.proc.join(5)
            w.conn.close()
        self.workers = []
        if self._tmp is not None:
            self._tmp.cleanup()
            self._tmp = None


def default_processes() -> int:
    return max(1, (os.cpu_count() or 1))

"""Worker processes for the prediction maths (``interprim serve --processes N``).

The per-frame work (``stream.update`` + trajectory + JSON) is CPU-bound Python and numpy on small
arrays, so threads do not run it in parallel (the GIL).  With ``--processes N`` every session is
pinned to one of N worker processes, which owns that session's ``model.stream()``; the event loop
only does the network I/O.  A slow session then only delays the sessions of its own worker.

Models reach the workers as safe ``.npz`` model files (``model.save`` / ``InteractionPrimitive.load``);
requests and replies are JSON over a ``multiprocessing`` pipe (``send_bytes``/``recv_bytes``; no
pickle).  A reply is one JSON header line, then (for predictions) the finished JSON text for the
client, so it is not encoded twice.
"""

from __future__ import annotations

import asyncio
import itertools
import json
import logging
import multiprocessing as mp
import os
import tempfile
from pathlib import Path

log = logging.getLogger("interprim.server")


def _worker_main(conn, paths: dict, kinds: dict) -> None:  # runs in the worker process
    import numpy as np

    from ..primitive import InteractionPrimitive
    from .compute import _Open, _accepts_need_cov, compute_prediction, warm_up
    from .models import entry_for

    entries = {n: entry_for(n, InteractionPrimitive.load(p), source=p, kind=kinds.get(n)) for n, p in paths.items()}
    warm_up(entries.values())
    sessions: dict = {}
    conn.send_bytes(b'{"ready":true}\n')
    while True:
        try:
            data = conn.recv_bytes()
        except (EOFError, OSError):
            return
        req = json.loads(data)
        op, rid = req["op"], req["rid"]
        body = b""
        head = {"rid": rid, "ok": True}
        try:
            if op == "frame":
                o = sessions[req["sid"]]
                body = compute_prediction(o, np.asarray(req["frame"], dtype=np.float64), req["seq"], req.get("t")).encode()
            elif op == "open":
                es = [entries[n] for n in req["candidates"]]
                streams = [e.model.stream(robot_state=req.get("robot_state")) for e in es]
                o = _Open(req["model"], es, streams, req["cols"], req["points"], req["std"])
                if _accepts_need_cov(streams[0]):
                    o.update_kw = {"need_cov": req["std"]}
                sessions[req["sid"]] = o
            elif op == "reset":
                for st in sessions[req["sid"]].streams:
                    st.reset(robot_state=req.get("robot_state"))
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
        self._tmp = None
        self._loop = None

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
        for i in range(self.n):
            parent, child = ctx.Pipe()
            proc = ctx.Process(target=_worker_main, args=(child, paths, kinds), name=f"interprim-worker-{i}",
                               daemon=True)
            proc.start()
            child.close()
            self.workers.append(_Worker(proc, parent))
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
        try:
            while w.conn.poll():
                data = w.conn.recv_bytes()
                head, _, body = data.partition(b"\n")
                h = json.loads(head)
                fut = w.pending.pop(h["rid"], None)
                if fut is None or fut.done():
                    continue
                if h["ok"]:
                    fut.set_result(body.decode())
                else:
                    fut.set_exception(RuntimeError(h["error"]))
        except (EOFError, OSError):
            self._lost(w)

    def _lost(self, w: _Worker) -> None:
        if w.dead:
            return
        w.dead = True
        try:
            self._loop.remove_reader(w.conn.fileno())
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
        w = self.worker_of(sid)
        if w.dead:
            raise RuntimeError("worker process died")
        rid = next(self._rid)
        fut = self._loop.create_future()
        w.pending[rid] = fut
        try:
            w.conn.send_bytes(json.dumps({"op": op, "rid": rid, "sid": sid, **fields}).encode())
        except (OSError, ValueError):
            w.pending.pop(rid, None)
            self._lost(w)
            raise RuntimeError("worker process died") from None
        return await fut

    def stop(self) -> None:
        for w in self.workers:
            try:
                if self._loop is not None and not w.dead:
                    self._loop.remove_reader(w.conn.fileno())
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

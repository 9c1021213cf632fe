"""Sessions and where their frames are computed: per-session rate limits and fair compute lanes.

A :class:`Session` is one WebSocket connection; a :class:`_Lane` is one place where predictions
are computed (the event loop, a thread or a worker process), shared by several sessions in fair
order (by client address, then by session); :class:`TokenBucket` limits a session's message rate.
:class:`Compute` owns the lanes and what runs them (the thread pool or the worker processes): the server creates
it from its configuration and models, and the sessions (:class:`~interprim.server.sessions.Sessions`) hand it
their frames with :meth:`Compute.push`.

Frames are *coalesced* under overload: a session's handler puts every frame it receives into the
session's ``pending`` list and goes on reading; when the session's turn comes, its lane feeds all
its pending frames to the session's streams (every frame enters the state) and encodes one reply,
for the newest, that says how many frames it covers (:func:`interprim.server.compute.compute_batch`).
"""

from __future__ import annotations

import asyncio
import heapq
import ipaddress
import itertools
import logging
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from .compute import OpenModel, compute_batch, warm_up

if TYPE_CHECKING:
    from .workers import ProcessPool

log = logging.getLogger("interprim.server")


class TokenBucket:
    """Token bucket: ``rate`` messages per second, ``burst`` at most in one go."""

    def __init__(self, rate: float, burst: int):
        self.rate, self.burst = float(rate), float(burst)
        self.tokens = float(burst)
        self.last = time.monotonic()

    def take(self) -> bool:
        now = time.monotonic()
        # (tokens over the burst come from credit(): kept until spent)
        self.tokens = max(self.tokens, min(self.burst, self.tokens + (now - self.last) * self.rate))
        self.last = now
        if self.tokens >= 1.0:
            self.tokens -= 1.0
            return True
        return False

    def credit(self, seconds: float) -> None:
        """Add what ``seconds`` of the rate allow, beyond the burst: the server did not read the client for that
        long, and its frames of that time arrive together."""
        self.tokens = max(self.tokens, 0.0) + max(0.0, seconds) * self.rate


@dataclass
class Session:
    id: int
    ws: Any  # the WebSocket connection (websockets' ServerConnection; the server's extra)
    peer: str
    out: asyncio.Queue
    bucket: TokenBucket
    ready: bool = False
    open: OpenModel | None = None
    seq: int = 0
    errors: int = 0
    consecutive_errors: int = 0
    predictions: int = 0
    coalesced: int = 0  # frames answered by a later frame's reply (sum of covers - 1)
    closing: bool = False
    writer: asyncio.Task | None = None
    close_reason: str = ""
    error_counts: dict = field(default_factory=dict)
    unsent: int = 0  # items put in ``out`` that the writer has not finished sending
    pending: list = field(default_factory=list)  # (frame, seq, t) received, not yet fed to the streams
    queued: bool = False  # waiting for its turn in its lane or being computed (then ``pending`` may grow)
    busy: bool = False  # the handler is inside a message (a control message may await a worker)
    ended: bool = False  # the connection's handler has finished
    waiters: list = field(default_factory=list)  # futures woken when the above change (see Sessions._until)
    direct: bool = False  # replies may be written to the socket at once (interprim.server.wsfast.write_now)
    client: str = ""  # who the session belongs to, for fair queuing (client_key(peer address)): see _Lane
    vtime: float = 0.0  # compute seconds used, in its client's virtual time (fair queuing: see _Lane)

    def wake(self) -> None:
        """Wake the coroutines waiting for a change of ``pending``/``queued``/``busy``/``ended``."""
        if self.waiters:
            ws, self.waiters = self.waiters, []
            for fut in ws:
                if not fut.done():
                    fut.set_result(None)


def client_key(host: str) -> str:
    """The client a connection from address ``host`` (no port) belongs to, for fair queuing: the IPv4 address, or the
    /64 prefix of an IPv6 one (one host may hold a whole /64, so a share per IPv6 address could be multiplied at
    will)."""
    host = str(host).strip("[]")
    try:
        ip = ipaddress.ip_address(host)
    except ValueError:
        return host
    if isinstance(ip, ipaddress.IPv6Address):
        if ip.ipv4_mapped is not None:
            return str(ip.ipv4_mapped)
        return str(ipaddress.ip_network(f"{ip}/64", strict=False))
    return str(ip)


class _Client:
    """A client's place in a lane: its sessions waiting for a turn (a heap by the compute time each has used, in the
    client's own virtual time ``vnow``), and the compute time its turns have used (in the lane's virtual time)."""

    __slots__ = ("key", "ready", "vtime", "vnow", "queued")

    def __init__(self, key: str):
        self.key = key
        self.ready: list = []  # heap of (session's virtual start time, arrival order, session)
        self.vtime = 0.0
        self.vnow = 0.0
        self.queued = False  # in the lane's heap


class _Lane:
    """One place where predictions are computed (the event loop, a thread, or a worker process),
    shared by several sessions in **fair** order.

    A session with pending frames waits for a turn at most once.  When its turn comes the lane takes *all* its
    pending frames (one batch), computes them with ``run(session, op, batch)`` and hands the result to
    ``deliver(session, op, batch, result)``; frames that arrived meanwhile put the session back in line.  So a
    session that is behind gets one reply for all the frames it sent while it waited, instead of one late
    reply per frame, and none starves.

    **Fair queuing by client, then by session.**  Turns are shared out by compute time between *clients*
    (:func:`client_key`: one per address), then in the same way between the sessions of one client.  A client's
    next turn starts at the virtual time its turns have used so far, never before the lane's present: every client
    with work gets an equal share of the lane's compute, whatever its number of sessions and whatever they ask for
    (points, the std band).  One client that opens 14 sessions asking for 500 points with the band therefore gets
    the share of one client, and pays for the rest with its own latency, not the others'; inside a client, a
    session whose turns cost ten times more gets a tenth of the turns.  Equal costs: plain round-robin.

    ``sync=True`` (inline compute): ``run`` is a plain callable, and one session is served per
    iteration of the event loop, so that between two batches the loop reads the sockets and frames that
    arrived meanwhile join their sessions' batches; a turn costs the time ``run`` took.  Else ``run`` is a
    coroutine function returning ``(result, cost)``, with ``cost`` the seconds the batch's computation took where
    it ran (a thread, a worker process), and up to ``depth`` batches (of different sessions) are in flight at
    once, so that a worker process has the next batch in its pipe when it finishes one instead of waiting for the
    event loop's round trip.  (The wall time of an awaited turn would include the batch in front of it in the
    worker's pipe: a cheap session behind an expensive one would pay for it.)

    ``clock`` (seconds, monotonic) measures an inline turn's cost and a failed turn's; the server uses
    :func:`time.perf_counter`, a test passes a clock it advances itself, so that the order of turns does not depend
    on the machine's load.
    """

    def __init__(self, run, deliver, sync: bool = False, depth: int = 2, clock=time.perf_counter):
        self.run = run
        self.clock = clock
        self.deliver = deliver
        self.sync = sync
        self.depth = max(1, int(depth))
        self.queue: list = []  # heap of (virtual start time, arrival order, client); an entry may be stale (below)
        self.clients: dict = {}  # key -> _Client
        self._order = itertools.count()
        self.vnow = 0.0  # virtual time: the start time of the turn being served
        self.inflight = 0
        self._scheduled = False

    def _client(self, s: Session) -> _Client:
        c = self.clients.get(s.client)
        if c is None:
            if len(self.clients) > 64 and len(self.clients) > 4 * len(self.queue):
                self._prune()
            c = self.clients[s.client] = _Client(s.client)
        return c

    def _prune(self) -> None:
        # a client with nothing waiting and no time used beyond the present would start at the present anyway
        self.clients = {k: c for k, c in self.clients.items() if c.queued or c.ready or c.vtime > self.vnow}

    def _queue_client(self, c: _Client) -> None:
        c.vtime = max(c.vtime, self.vnow)
        c.queued = True
        heapq.heappush(self.queue, (c.vtime, next(self._order), c))

    def _enqueue(self, s: Session) -> None:
        c = self._client(s)
        s.vtime = max(s.vtime, c.vnow)
        heapq.heappush(c.ready, (s.vtime, next(self._order), s))
        if not c.queued:
            self._queue_client(c)

    def push(self, s: Session) -> None:
        """Queue ``s`` (which has pending frames and is not queued) for its turn."""
        s.queued = True
        self._enqueue(s)
        if self.sync:
            if not self._scheduled:
                self._scheduled = True
                asyncio.get_running_loop().call_soon(self._step)
        else:
            self._pump()

    def _take(self):
        """The next session's batch: ``(session, open model, frames)``, or ``None`` for a session that has
        ended or has nothing to compute (then it leaves the queue), or when the entry popped was stale."""
        vt, _, c = heapq.heappop(self.queue)
        if vt < c.vtime:  # the client was charged for a turn since it was queued: back in line at its time
            self._queue_client(c)
            return None
        self.vnow = max(self.vnow, vt)
        svt, _, s = heapq.heappop(c.ready)
        c.vnow = max(c.vnow, svt)
        if c.ready:  # its other sessions keep the client's place (a turn in flight is charged when it ends)
            heapq.heappush(self.queue, (c.vtime, next(self._order), c))
        else:
            c.queued = False
        batch, s.pending = s.pending, []
        op = s.open
        if s.ended or op is None or not batch:
            s.queued = False
            s.wake()
            return None
        return s, op, batch

    def _done(self, s: Session, cost: float = 0.0) -> None:
        c = self._client(s)
        c.vtime += cost
        s.vtime += cost
        if s.pending and not s.ended:
            self._enqueue(s)  # frames arrived during its turn: back in line, after what its client used
        else:
            s.queued = False
            s.wake()

    def _step(self) -> None:
        """Inline lane: serve one session per event-loop iteration (a plain callback)."""
        self._scheduled = False
        while self.queue:
            job = self._take()
            if job is None:
                continue
            s, op, batch = job
            t0 = self.clock()
            try:
                result = self.run(s, op, batch)
            except Exception as exc:  # run() reports model failures itself; this is a bug
                result = exc
            cost = self.clock() - t0
            try:
                self.deliver(s, op, batch, result)
            finally:
                self._done(s, cost)
            break
        if self.queue:
            self._scheduled = True
            asyncio.get_running_loop().call_soon(self._step)

    def _pump(self) -> None:
        """Async lane: start batches while fewer than ``depth`` are in flight."""
        while self.queue and self.inflight < self.depth:
            job = self._take()
            if job is None:
                continue
            self.inflight += 1
            asyncio.get_running_loop().create_task(self._serve(*job))

    async def _serve(self, s: Session, op, batch) -> None:
        t0 = self.clock()
        try:
            result, cost = await self.run(s, op, batch)
        except Exception as exc:  # a dead worker process, a bug
            result, cost = exc, self.clock() - t0
        finally:
            self.inflight -= 1
        try:
            self.deliver(s, op, batch, result)
        finally:
            self._done(s, cost)
            self._pump()


def _timed(op, batch):
    """``(compute_batch(op, batch), seconds it took)``, measured in the thread that runs it."""
    t0 = time.perf_counter()
    result = compute_batch(op, batch)
    return result, time.perf_counter() - t0


class Compute:
    """Where the server computes its replies: inline on the event loop, in a thread pool or in worker processes.

    Parameters
    ----------
    models : dict of name -> ModelEntry
        The served models (warmed up, or sent to the worker processes, by :meth:`start`).
    workers : int
        ``0``: compute inline on the event loop; ``N``: in a pool of ``N`` threads.
    processes : int
        ``N > 0``: session ``i`` runs in worker process ``i % N``, which owns its streams (overrides ``workers``).

    :meth:`start` (on the event loop) makes the lanes, each of which hands its results to the ``deliver``
    callback; :meth:`push` queues a session with pending frames on its lane; :meth:`call` runs a session's
    control operation (``open``, ``reset``, ``drop``) in its worker process when ``remote``; :meth:`stop`
    joins the threads or processes.
    """

    def __init__(self, models: dict, workers: int = 0, processes: int = 0):
        self.models = models
        self.workers = int(workers)
        self.processes = int(processes)
        self.pool = ThreadPoolExecutor(self.workers, thread_name_prefix="ip-worker") if (
            self.workers and not self.processes) else None
        self.procs: ProcessPool | None = None  # the worker processes once started
        self.lanes: list = []

    @property
    def remote(self) -> bool:
        """Whether the sessions' streams live in worker processes (else in this process, in each session)."""
        return self.procs is not None

    def describe(self) -> str:
        """Where replies are computed, for the server's log."""
        if self.processes:
            return f"{self.processes} worker process(es)"
        return f"{self.workers} worker thread(s)" if self.workers else "inline compute"

    async def start(self, deliver) -> None:
        """Warm the models up here or start the worker processes, then make the lanes, which hand each computed
        batch to ``deliver(session, open model, batch, result)``."""
        loop = asyncio.get_running_loop()
        if not self.processes:
            await loop.run_in_executor(None, warm_up, list(self.models.values()))
        else:
            from .workers import ProcessPool

            pool = ProcessPool(self.models, self.processes)
            try:
                await loop.run_in_executor(None, pool.start)
            except BaseException:
                pool.stop()
                raise
            pool.attach(loop)
            self.procs = pool
        self.lanes = self._make_lanes(deliver)

    def _make_lanes(self, deliver) -> list:
        if self.procs is not None:
            procs = self.procs

            async def run_proc(s, op, batch):
                block = np.stack([f for f, _, _ in batch]).astype("<f8", copy=False)
                ts = [t for _, _, t in batch]
                kw = {"ts": ts} if any(t is not None for t in ts) else {}
                head, body = await procs.request(s.id, "frames", payload=block.tobytes(), n=block.shape[0],
                                                 d=block.shape[1], seq=batch[0][1], **kw)
                texts = body.split(b"\n") if body else []  # UTF-8 JSON texts, sent as they are
                return (texts, [tuple(f) for f in head.get("failures", ())]), float(head.get("cost", 0.0))

            return [_Lane(run_proc, deliver) for _ in range(procs.n)]  # session i runs on worker i % n
        if self.pool is not None:
            pool = self.pool

            async def run_thread(s, op, batch):
                return await asyncio.get_running_loop().run_in_executor(pool, _timed, op, batch)

            return [_Lane(run_thread, deliver) for _ in range(self.workers)]

        def run_inline(s, op, batch):
            return compute_batch(op, batch)

        return [_Lane(run_inline, deliver, sync=True)]

    def push(self, s: Session) -> None:
        """Queue session ``s`` (pending frames, not queued) on its lane: lane ``s.id % len(lanes)``."""
        self.lanes[s.id % len(self.lanes)].push(s)

    async def call(self, sid: int, op: str, **fields):
        """Run ``op`` for session ``sid`` in its worker process (``remote`` only); raises ``RuntimeError`` when it
        fails there."""
        if self.procs is None:
            raise RuntimeError(f"{op}: the server runs no worker processes")
        return await self.procs.call(sid, op, **fields)

    def stop(self) -> None:
        """Join the worker threads (idle once the sessions are gone) or stop and join the worker processes."""
        if self.pool is not None:
            self.pool.shutdown(wait=True)
            self.pool = None
        if self.procs is not None:
            self.procs.stop()  # asks each worker to stop and joins it
            self.procs = None
            log.info("worker processes stopped")

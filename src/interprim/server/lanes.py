"""Sessions and where their frames are computed: per-session rate limits and fair-queued compute lanes.

A :class:`_Session` is one WebSocket connection; a :class:`_Lane` is one place where predictions
are computed (the event loop, a thread or a worker process), shared by several sessions with
start-time fair queueing on compute time; :class:`_Bucket` limits a session's message rate.
"""

from __future__ import annotations

import asyncio
import heapq
import itertools
import time
from dataclasses import dataclass, field

from .compute import _Open


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

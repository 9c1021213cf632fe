"""Connections that have not authenticated yet: bounded per address and in total, with a deadline.

A TCP connection costs the server a file descriptor and a little memory from the moment it is accepted, before
any HTTP request or ``hello`` is read.  :class:`ConnectionGate` counts every connection from ``accept`` until its
``hello`` is accepted (:meth:`ConnectionGate.authenticated`) or it goes away, and keeps those *unauthenticated*
connections bounded:

* at most ``per_address`` of them from one IP address: a new one evicts (aborts) the **oldest** unauthenticated
  connection of that address.  Someone who parks idle connections therefore cannot keep a token holder out,
  even from the same address: the newest connection gets its chance, and a real client sends ``hello`` within
  a round trip;
* at most ``total`` of them: a new one evicts the oldest connection of the address that holds the most;
* each has ``timeout`` seconds from ``accept`` to send an accepted ``hello``; then it is aborted.  (The
  session handler closes it politely with 1008 a little earlier when the WebSocket handshake is done.)

Authenticated connections are sessions, limited by ``max_sessions``.  :func:`fd_budget` checks, at start, that
the process may open enough file descriptors for all of this, and lowers the limits when it may not.
"""

from __future__ import annotations

import logging
import time
from collections import OrderedDict

log = logging.getLogger("interprim.server")

FD_RESERVE = 48  # descriptors kept for everything but connections: listening sockets, logs, model files, pipes
ACCEPT_BURST = 100  # connections the event loop may accept in one go before the gate sees them (listen backlog)


class RateLimitedLog:
    """At most ``burst`` log lines per ``period`` seconds; the lines dropped are counted and reported with the
    next line that gets through (``"... (N similar messages suppressed)"``)."""

    def __init__(self, logger, burst: int = 10, period: float = 10.0):
        self.logger, self.burst, self.period = logger, int(burst), float(period)
        self.window = time.monotonic()
        self.count = 0
        self.suppressed = 0

    def log(self, level: int, msg: str, *args, exc_info=None) -> bool:
        """Log ``msg % args`` at ``level`` unless over the budget; ``True`` when it was logged."""
        now = time.monotonic()
        if now - self.window >= self.period:
            self.window, self.count = now, 0
        if self.count >= self.burst:
            self.suppressed += 1
            return False
        self.count += 1
        if self.suppressed:
            msg = msg + " (%d similar messages suppressed)"
            args = args + (self.suppressed,)
            self.suppressed = 0
        self.logger.log(level, msg, *args, exc_info=exc_info)
        return True


def _address(transport) -> str:
    try:
        peer = transport.get_extra_info("peername")
        return str(peer[0]) if peer else "?"
    except Exception:
        return "?"


class ConnectionGate:
    """The unauthenticated connections (see the module's docstring).

    Parameters
    ----------
    total : int
        At most this many unauthenticated connections in all.
    per_address : int
        At most this many from one IP address.
    timeout : float
        Seconds from ``accept`` to an accepted ``hello``.
    stats : dict, optional
        Counters updated here: ``evicted`` (connections aborted to make room) and ``timed_out``.
    """

    def __init__(self, total: int, per_address: int, timeout: float, stats: dict | None = None):
        self.total = int(total)
        self.per_address = int(per_address)
        self.timeout = float(timeout)
        self.stats = stats if stats is not None else {}
        self.stats.setdefault("evicted", 0)
        self.stats.setdefault("timed_out", 0)
        self.by_address: dict[str, OrderedDict] = {}  # address -> {connection: (transport, timer)}, oldest first
        self.count = 0
        self._log = RateLimitedLog(log)

    def __len__(self) -> int:
        return self.count

    def admit(self, conn, transport, loop) -> None:
        """A new connection (from ``connection_made``): count it, making room first if a limit is reached."""
        addr = _address(transport)
        held = self.by_address.get(addr)
        if held is not None and len(held) >= self.per_address:
            self._evict(addr, f"more than {self.per_address} unauthenticated connections from {addr}")
        elif self.count >= self.total and self.by_address:
            worst = max(self.by_address, key=lambda a: len(self.by_address[a]))
            self._evict(worst, f"more than {self.total} unauthenticated connections in all")
        timer = loop.call_later(self.timeout, self._expire, conn)
        self.by_address.setdefault(addr, OrderedDict())[conn] = (transport, timer, addr)
        self.count += 1
        conn.gate_address = addr
        conn.gate_t0 = loop.time()

    def _remove(self, conn):
        addr = getattr(conn, "gate_address", None)
        held = self.by_address.get(addr)
        if held is None or conn not in held:
            return None
        item = held.pop(conn)
        if not held:
            del self.by_address[addr]
        self.count -= 1
        item[1].cancel()
        return item

    def authenticated(self, conn) -> None:
        """``conn`` sent an accepted ``hello``: it is a session now, no longer counted here."""
        self._remove(conn)

    def lost(self, conn) -> None:
        """``conn`` went away (from ``connection_lost``)."""
        self._remove(conn)

    def _evict(self, addr: str, why: str) -> None:
        held = self.by_address.get(addr)
        if not held:
            return
        conn = next(iter(held))
        transport, _, _ = self._remove(conn)
        self.stats["evicted"] += 1
        self._log.log(logging.WARNING, "connection from %s aborted before hello: %s (the oldest goes)", addr, why)
        transport.abort()

    def _expire(self, conn) -> None:
        item = self._remove(conn)
        if item is None:
            return
        self.stats["timed_out"] += 1
        self._log.log(logging.WARNING, "connection from %s aborted: no accepted hello within %g s", item[2],
                      self.timeout)
        item[0].abort()


def fd_budget(max_sessions: int, max_unauthenticated: int, *, extra: int = 0, resource_module=None):
    """Check that the process may open a descriptor per session and per unauthenticated connection, plus
    :data:`FD_RESERVE` + :data:`ACCEPT_BURST` + ``extra`` (worker pipes); returns ``(max_sessions,
    max_unauthenticated, message)``.

    When the soft ``RLIMIT_NOFILE`` is too low it is first raised towards the hard limit; if that is not enough,
    both limits are lowered to fit (the unauthenticated connections to a quarter of what is left, at least 4)
    and ``message`` says so (``None`` when nothing had to change).  Without the ``resource`` module (Windows)
    nothing is checked.
    """
    if resource_module is None:
        try:
            import resource as resource_module
        except ImportError:  # pragma: no cover - not POSIX
            return max_sessions, max_unauthenticated, None
    rm = resource_module
    soft, hard = rm.getrlimit(rm.RLIMIT_NOFILE)
    overhead = FD_RESERVE + ACCEPT_BURST + int(extra)
    need = max_sessions + max_unauthenticated + overhead
    if soft != rm.RLIM_INFINITY and soft < need:
        want = need if hard == rm.RLIM_INFINITY else min(need, hard)
        if want > soft:
            try:
                rm.setrlimit(rm.RLIMIT_NOFILE, (want, hard))
                soft = want
            except (ValueError, OSError):
                pass
    if soft == rm.RLIM_INFINITY or soft >= need:
        return max_sessions, max_unauthenticated, None
    room = soft - overhead
    if room < 8:
        raise ValueError(f"the process may open only {soft} files (RLIMIT_NOFILE); the server needs at least "
                         f"{overhead + 8}: raise it with 'ulimit -n'")
    unauth = max(4, min(max_unauthenticated, room // 4))
    sessions = max(1, min(max_sessions, room - unauth))
    msg = (f"the process may open only {soft} files (RLIMIT_NOFILE, hard limit {hard}); lowering max_sessions "
           f"{max_sessions} -> {sessions} and max_unauthenticated {max_unauthenticated} -> {unauth} so that "
           f"connections cannot exhaust it (raise it with 'ulimit -n {need}')")
    return sessions, unauth, msg

"""The per-frame path of the server's WebSocket connections, without the library's per-message machinery.

The :mod:`websockets` library parses every incoming frame with a generator-based parser, queues each
message for the connection's handler coroutine, wakes that coroutine, and sends each reply through an
asynchronous context manager.  At 10,000 frames/s that is most of the server's own CPU.  Here:

* :class:`FastFrames` (mixed into the server's connection class) splits the received bytes into whole
  WebSocket frames itself (RFC 6455 Sec. 5.2: a header, a mask, a payload), and offers each unfragmented,
  masked text or binary frame to ``fast_frame(data)``, a callable of the session (``data``: ``str`` for a
  text frame, ``bytes`` for a binary one) that returns ``True`` when it took the message.  Every other
  frame (control frames, fragments, anything unusual or invalid, and messages the session does not take)
  goes to the library, one whole frame at a time and in order, so its checks, errors and close codes are
  unchanged.  A message is only offered while no earlier message waits for the handler, so the session
  sees its messages in the order they came, and while the library is not in the middle of a fragmented
  message (its ``protocol.current_size`` is ``None``): a whole text or binary frame inside a fragmented
  message is a protocol error (RFC 6455 Sec. 5.4) that the library answers with 1002, so it goes there.
  ``tests/server/test_server_conformance.py`` sends the same malformed sequences (those of the library's own test
  suite: fragmentation, control frames, masking, reserved bits, UTF-8, sizes, close frames) to a server
  with and without this path and requires the same answers and close codes.  The fast path switches itself off for good
  (the library then gets every byte) when the connection leaves the OPEN state, when a frame announces more than
  ``max_size`` bytes, and when it cannot know that the library's parser is at a frame boundary (bytes
  left over from the handshake).
* :func:`write_now` writes a reply's text frame to the transport at once when nothing else is being
  sent (the caller keeps its queue for the other cases: the transport's buffer is full, the connection
  is closing).

Both use attributes of the library's connection and protocol objects (``protocol``, ``protocol.reader``,
``recv_messages``, ``paused``, ``send_in_progress``): :func:`supported` checks them once per
connection, and without them the library does everything, as before.
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING

try:
    from websockets.frames import apply_mask  # the library's C speedup when built, else its Python version
    from websockets.protocol import OPEN
except ImportError:  # pragma: no cover - websockets is a dependency of the server
    apply_mask = OPEN = None  # type: ignore[assignment]  # the server's extra is missing: nothing here runs

if TYPE_CHECKING:  # the mixin's methods call and read the connection class it is mixed into
    from websockets.asyncio.server import ServerConnection as _Connection
else:
    _Connection = object

_TEXT, _BINARY = 0x1, 0x2

log = logging.getLogger("interprim.server")


def supported(conn) -> bool:
    """Whether ``conn`` (a websockets asyncio connection) has what the fast paths use."""
    try:
        return (apply_mask is not None and hasattr(conn.protocol.reader, "buffer")
                and hasattr(conn.recv_messages, "frames") and hasattr(conn, "paused")
                and hasattr(conn, "send_in_progress") and hasattr(conn.protocol, "max_message_size")
                and hasattr(conn.protocol, "current_size"))
    except AttributeError:
        return False


def frame_header(opcode: int, n: int) -> bytes:
    """Header of an unmasked, unfragmented frame (a server's) of ``n`` payload bytes (RFC 6455 Sec. 5.2)."""
    b0 = 0x80 | opcode
    if n < 126:
        return bytes((b0, n))
    if n < 65536:
        return bytes((b0, 126)) + n.to_bytes(2, "big")
    return bytes((b0, 127)) + n.to_bytes(8, "big")


def write_now(conn, data) -> bool:
    """Send ``data`` (text: ``str``, or ``bytes`` holding UTF-8) as one text frame now, if the connection is
    open, not in the middle of another message, and its transport's buffer is below the high-water mark;
    ``False`` (nothing written) otherwise."""
    try:
        proto = conn.protocol
        if (proto.state is not OPEN or conn.paused or conn.send_in_progress is not None or proto.extensions
                or conn.transport is None or conn.transport.is_closing()):
            return False
        pending = proto.data_to_send()  # whatever the library has queued goes first (normally nothing)
        payload = data.encode() if isinstance(data, str) else bytes(data)
        write = conn.transport.write
        for chunk in pending:
            if chunk:
                write(chunk)
        write(frame_header(_TEXT, len(payload)) + payload)
        return True
    except Exception:  # a connection going away: the caller's queue and the library take over
        return False


class FastFrames(_Connection):
    """Mixin for a :class:`websockets.asyncio.server.ServerConnection` subclass: see the module's docstring."""

    fast_frame = None  # set by the session: callable(str | bytes) -> bool
    fast_path = True  # False (ServerConfig.fast_path): the library gets every byte
    _fast_state = 0  # 0: not decided yet (handshake), 1: on, -1: off for good
    _fast_buf = b""

    def data_received(self, data: bytes) -> None:
        st = self._fast_state
        if st < 0:
            return super().data_received(data)
        proto = self.protocol
        if st == 0:
            if proto.state is not OPEN:  # the handshake: the library's
                return super().data_received(data)
            # the first bytes after the handshake: the library's parser is at a frame boundary iff it holds none
            if not self.fast_path or proto.reader.buffer or not supported(self):
                self._fast_state = -1
                return super().data_received(data)
            self._fast_state = 1
        elif proto.state is not OPEN:
            return self._fast_off(data)
        buf = self._fast_buf + data if self._fast_buf else data
        n = len(buf)
        pos = 0
        limit = proto.max_message_size
        queued = self.recv_messages.frames
        while n - pos >= 2:
            b0, b1 = buf[pos], buf[pos + 1]
            length, h = b1 & 0x7F, 2
            if length == 126:
                if n - pos < 4:
                    break
                length, h = int.from_bytes(buf[pos + 2:pos + 4], "big"), 4
            elif length == 127:
                if n - pos < 10:
                    break
                length, h = int.from_bytes(buf[pos + 2:pos + 10], "big"), 10
            if limit is not None and length > limit:  # the library refuses it (1009) and closes
                return self._fast_off(buf[pos:])
            masked = b1 & 0x80
            if masked:
                h += 4
            end = pos + h + length
            if end > n:
                break
            op = b0 & 0x0F
            hook = self.fast_frame
            # Only a whole message (FIN, no RSV bit, masked) that does not start while the library is in the
            # middle of a fragmented one (RFC 6455 Sec. 5.4: the library closes with 1002 "expected a
            # continuation frame"), and only while no earlier message waits for the handler.
            if (hook is not None and (b0 & 0xF0) == 0x80 and masked and (op == _TEXT or op == _BINARY)
                    and proto.current_size is None and not len(queued)):
                payload = apply_mask(buf[pos + h:end], buf[pos + h - 4:pos + h])
                msg = None
                if op == _BINARY:
                    msg = bytes(payload)
                else:
                    try:
                        msg = payload.decode()
                    except UnicodeDecodeError:  # the library closes the connection (1007)
                        msg = None
                if msg is not None:
                    try:
                        taken = hook(msg)
                    except Exception:  # a bug: the library's path (the handler reports and closes the session)
                        log.exception("fast frame path failed; the message goes the library's way")
                        taken = False
                    if taken:
                        pos = end
                        continue
            super().data_received(bytes(buf[pos:end]))  # one whole frame: the library's parser stays aligned
            pos = end
            if proto.state is not OPEN:  # a close frame (or a protocol error): the library's from now on
                return self._fast_off(buf[pos:])
        self._fast_buf = bytes(buf[pos:]) if pos < n else b""

    def _fast_off(self, rest) -> None:
        self._fast_state = -1
        self._fast_buf = b""
        if rest:
            super().data_received(bytes(rest))

    def eof_received(self):
        if self._fast_state > 0 and self._fast_buf:  # an incomplete frame: the library reports it
            self._fast_off(self._fast_buf)
        self._fast_state = -1
        return super().eof_received()

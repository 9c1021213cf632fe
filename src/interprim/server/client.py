"""Python clients of the interprim streaming protocol (``docs/protocol.md``).

:class:`Client` is synchronous (one reply per call; simplest for scripts and
robot loops), :class:`AsyncClient` is for asyncio programs and can pipeline
frames (``send_frame`` then ``recv``).  Replies are plain dicts as documented
in the protocol; an ``error`` reply raises :class:`ServerError`.

>>> from interprim.server import Client                     # doctest: +SKIP
>>> with Client("ws://127.0.0.1:8765/ws") as c:            # doctest: +SKIP
...     c.open("highfive", points=50, std=True)
...     for frame in human_frames:
...         p = c.frame(frame)          # p["phase"], p["mean"], p["std"], p["goal"] ...
"""

from __future__ import annotations

import json

from . import protocol as P


class ServerError(RuntimeError):
    """The server answered with ``{"type": "error"}``; ``code`` and ``reply`` hold the details."""

    def __init__(self, reply: dict):
        self.reply = reply
        self.code = reply.get("code", "?")
        self.seq = reply.get("seq")
        super().__init__(f"{self.code}: {reply.get('message', '')}")


def _check(reply: dict) -> dict:
    if reply.get("type") == "error":
        raise ServerError(reply)
    return reply


def _hello(token, client):
    msg = {"type": "hello", "version": P.PROTOCOL_VERSION, "client": client}
    if token is not None:
        msg["token"] = token
    return json.dumps(msg)


def _open_msg(model, candidates, points, std, dofs, robot_state):
    msg = {"type": "open", "model": model, "std": bool(std)}
    if points is not None:
        msg["points"] = int(points)
    if candidates is not None:
        msg["candidates"] = list(candidates)
    if dofs is not None:
        msg["dofs"] = dofs
    if robot_state is not None:
        msg["robot_state"] = _robot_state(robot_state)
    return json.dumps(msg)


def _robot_state(rs):
    if rs is None:
        return None
    if len(rs) == 2 and all(hasattr(r, "__len__") for r in rs):  # [positions, velocities]
        return [[float(v) for v in r] for r in rs]
    return [float(v) for v in rs]


def _reset_msg(robot_state):
    msg = {"type": "reset"}
    if robot_state is not None:
        msg["robot_state"] = _robot_state(robot_state)
    return json.dumps(msg)


def _frame_msg(frame, t=None, binary=False):
    if binary:
        return P.encode_binary_frame(frame)
    msg = {"type": "frame", "frame": [float(v) for v in frame]}
    if t is not None:
        msg["t"] = t
    return json.dumps(msg)


class Client:
    """Synchronous client (``websockets.sync``).

    Parameters
    ----------
    url : str
        ``ws://host:port/ws``.
    token : str, optional
        Shared token if the server was started with ``--token``.
    timeout : float
        Seconds to wait for each reply.
    """

    def __init__(self, url: str, token: str | None = None, timeout: float = 10.0, **connect_kwargs):
        from websockets.sync.client import connect

        self.timeout = timeout
        kw = dict(open_timeout=timeout, close_timeout=2, **connect_kwargs)
        try:  # websockets >= 16 wants legacy=True for a plain (non-context-manager) connection
            self.ws = connect(url, legacy=True, **kw)
        except TypeError:
            self.ws = connect(url, **kw)
        self.ws.send(_hello(token, "interprim.server.Client"))
        self.welcome = self.recv()
        self.opened: dict | None = None

    @property
    def models(self) -> list:
        """The server's models as listed in its ``welcome`` reply (dicts with ``name``, ``n_dofs``, ``dt``, ...)."""
        return self.welcome["models"]

    def recv(self, timeout: float | None = None) -> dict:
        """Next reply; raises :class:`ServerError` on an error reply."""
        return _check(json.loads(self.ws.recv(timeout=self.timeout if timeout is None else timeout)))

    def open(self, model: str = "recognise", *, candidates=None, points: int | None = None, std: bool = False,
             dofs: str | None = None, robot_state=None) -> dict:
        """Open a model (or ``"recognise"``: recognise among ``candidates``, default all). Returns ``opened``."""
        self.ws.send(_open_msg(model, candidates, points, std, dofs, robot_state))
        self.opened = opened = self.recv()
        return opened

    def frame(self, frame, *, t=None, binary: bool = False) -> dict:
        """Send one observed frame and return its ``prediction``."""
        self.ws.send(_frame_msg(frame, t, binary))
        return self.recv()

    def reset(self, robot_state=None) -> dict:
        """Start a new interaction with the same model (the frames so far are forgotten).

        ``robot_state`` (positions, or ``[positions, velocities]``) replaces the controlled agent's start for
        this interaction and later ones.  Returns the ``reset_done`` reply (``seq``: frames received so far);
        raises :class:`ServerError` (``not_open``) when no model is open.
        """
        self.ws.send(_reset_msg(robot_state))
        return self.recv()

    def close_session(self) -> dict:
        """Close the open model; the connection stays open (``open`` again to go on).

        Returns the ``closed`` reply (``seq``: frames received so far).
        """
        self.ws.send(json.dumps({"type": "close"}))
        return self.recv()

    def close(self) -> None:
        """Close the WebSocket connection (also done on leaving a ``with`` block)."""
        self.ws.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


class AsyncClient:
    """asyncio client; ``await AsyncClient.connect(url)``.

    ``frame()`` waits for the reply; ``send_frame()`` + ``recv()`` pipeline (a server that is behind may then
    answer several pipelined frames with one reply: its ``first_seq .. seq``, ``covers`` frames; see the
    protocol's "Overload and coalesced replies").
    """

    def __init__(self, ws, welcome):
        self.ws = ws
        self.welcome = welcome
        self.opened: dict | None = None

    @classmethod
    async def connect(cls, url: str, token: str | None = None, **connect_kwargs) -> AsyncClient:
        """Connect to ``url`` (``ws://host:port/ws``) and say ``hello``; returns the client once welcomed.

        Parameters
        ----------
        url : str
            ``ws://host:port/ws``.
        token : str, optional
            Shared token if the server was started with ``--token``.
        **connect_kwargs
            Passed to ``websockets.asyncio.client.connect``.

        Raises
        ------
        ServerError
            If the server refuses the ``hello`` (wrong token or protocol version).
        """
        from websockets.asyncio.client import connect

        ws = await connect(url, close_timeout=2, **connect_kwargs)
        await ws.send(_hello(token, "interprim.server.AsyncClient"))
        welcome = _check(json.loads(await ws.recv()))
        return cls(ws, welcome)

    async def recv(self) -> dict:
        """Next reply; raises :class:`ServerError` on an error reply."""
        return _check(json.loads(await self.ws.recv()))

    async def recv_raw(self) -> dict:
        """Next reply without raising on errors."""
        return json.loads(await self.ws.recv())

    async def open(self, model: str = "recognise", *, candidates=None, points: int | None = None, std: bool = False,
                   dofs: str | None = None, robot_state=None) -> dict:
        """Open a model (or ``"recognise"``: recognise among ``candidates``, default all). Returns ``opened``.

        The keyword arguments are the fields of the protocol's ``open`` message (``points``, ``std``,
        ``dofs``, ``robot_state``), as for :meth:`Client.open`.
        """
        await self.ws.send(_open_msg(model, candidates, points, std, dofs, robot_state))
        self.opened = await self.recv()
        return self.opened

    async def send_frame(self, frame, *, t=None, binary: bool = False) -> None:
        """Send one observed frame without waiting for its reply (read it later with :meth:`recv`).

        ``t`` is echoed back in the reply; ``binary=True`` sends the frame as little-endian float64 bytes.
        """
        await self.ws.send(_frame_msg(frame, t, binary))

    async def frame(self, frame, *, t=None, binary: bool = False) -> dict:
        """Send one observed frame and return its ``prediction`` (raises :class:`ServerError` on an error)."""
        await self.send_frame(frame, t=t, binary=binary)
        return await self.recv()

    async def reset(self, robot_state=None) -> dict:
        """Start a new interaction with the same model (see :meth:`Client.reset`); returns the ``reset_done`` reply."""
        await self.ws.send(_reset_msg(robot_state))
        return await self.recv()

    async def close(self) -> None:
        """Close the WebSocket connection (also done on leaving an ``async with`` block)."""
        await self.ws.close()

    async def __aenter__(self):
        return self

    async def __aexit__(self, *exc):
        await self.close()

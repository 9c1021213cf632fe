"""The HTTP side of the server: the page, its static files and the JSON API (``/api/...``), with the
token and origin checks that also guard the WebSocket upgrade.

:class:`HttpApi` is given what it reads (the configuration, the models, the extra ``/api/info`` JSON) and
the statistics it counts refusals in; :class:`~interprim.server.app.InterprimServer` owns them and passes
:meth:`HttpApi.process_request` to the WebSocket library.
"""

from __future__ import annotations

import hmac
import http
import json
import logging
import mimetypes
from pathlib import Path
from urllib.parse import parse_qs, urlsplit

from . import protocol as P

log = logging.getLogger("interprim.server")

STATIC_DIR = Path(__file__).resolve().parent / "static"


def token_ok(want: str | None, given) -> bool:
    """Whether ``given`` is the server's token ``want`` (any value when the server has none); constant time."""
    if not want:
        return True
    return isinstance(given, str) and hmac.compare_digest(given.encode(), want.encode())


class HttpApi:
    """Requests that are not WebSocket frames: static files, ``/api/...`` and the upgrade checks.

    Parameters
    ----------
    config : ServerConfig
        The token, limits and allowed origins.
    models : dict of name -> ModelEntry
        The served models (``/api/info``, ``/api/replay/MODEL``).
    stats : dict
        The server's counters; a refused cross-origin upgrade adds one to ``stats["rejected"]``.
    extra_info : dict, optional
        Extra JSON sent by ``GET /api/info``.
    """

    def __init__(self, config, models: dict, stats: dict, extra_info: dict | None = None):
        self.config = config
        self.models = models
        self.stats = stats
        self.extra_info = {} if extra_info is None else extra_info  # the server's own dict (read at each request)
        self._static = self._load_static()

    @staticmethod
    def _load_static() -> dict:
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
        """The JSON of ``GET /api/info``: server version, protocol version, whether a token is required,
        the models (:meth:`ModelEntry.describe`), the limits, and the server's ``extra_info``."""
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

    def token_ok(self, given) -> bool:
        """Whether ``given`` is the server's token (:func:`token_ok`)."""
        return token_ok(self.config.token, given)

    def _origin_ok(self, request) -> bool:
        origin = request.headers.get("Origin")
        if origin is None or origin in self.config.allowed_origins or "*" in self.config.allowed_origins:
            return True  # non-browser clients send no Origin
        try:
            netloc = urlsplit(origin).netloc
        except ValueError:
            return False
        return netloc == request.headers.get("Host")

    def process_request(self, conn, request):
        """The WebSocket library's ``process_request`` hook: answer a plain HTTP request (page, static file, API,
        ``/healthz``) or refuse a cross-origin upgrade; ``None`` lets a ``/ws`` upgrade go on."""
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
            if not self.token_ok(token):
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

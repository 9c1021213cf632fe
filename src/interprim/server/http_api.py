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

LOOPBACK_HOSTS = ("localhost", "127.0.0.1", "::1")
_WILDCARD = ("", "0.0.0.0", "::")


def split_host(value) -> str | None:
    """The host name of a ``Host`` header value (``name``, ``name:port``, ``[v6]`` or ``[v6]:port``), lower case
    and without a trailing dot; ``None`` when it is not of that form."""
    if not isinstance(value, str) or not value or len(value) > 300:
        return None
    v = value.strip().lower()
    if v.startswith("["):
        end = v.find("]")
        if end < 0 or (v[end + 1:] and not (v[end + 1] == ":" and v[end + 2:].isdigit())):
            return None
        return v[1:end]
    if v.count(":") == 1:
        v, port = v.split(":")
        if not port.isdigit():
            return None
    elif ":" in v:
        return None
    v = v.rstrip(".")
    if not v or any(ch in v for ch in "/@?#\\ "):
        return None
    return v


def allowed_host_names(config) -> frozenset:
    """The ``Host`` names the server answers to: the loopback names, the address it is bound to (unless that
    is a wildcard such as ``0.0.0.0``) and ``config.allowed_hosts`` (``--allow-host``), any port."""
    names = set(LOOPBACK_HOSTS)
    bound = (config.host or "").strip("[]").lower()
    if bound not in _WILDCARD:
        names.add(bound)
    for h in config.allowed_hosts:
        n = h.strip("[]").lower() if h.count(":") > 1 else split_host(h)  # a bare IPv6 address, or name[:port]
        if n:
            names.add(n)
    return frozenset(names)


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
        self.hosts = allowed_host_names(config)
        # /api/replay/MODEL encoded once, here: encoding megabytes of JSON per request blocked the event loop
        # (every session's frames waited for it)
        self._replay = {name: json.dumps(e.meta["replay"]).encode() for name, e in models.items()
                        if "replay" in e.meta}

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

    def _host_ok(self, request) -> bool:
        """Whether the request's ``Host`` is one of :func:`allowed_host_names` (DNS rebinding: a page of
        ``evil.example`` whose name now resolves to this machine sends ``Host: evil.example``)."""
        values = request.headers.get_all("Host") if hasattr(request.headers, "get_all") else [
            request.headers.get("Host")]
        if len(values) != 1:
            return False
        return split_host(values[0]) in self.hosts

    def _origin_ok(self, request) -> bool:
        """Whether the browser ``Origin`` (absent for other clients) is allowed: ``http(s)://`` and one of the allowed
        host names (any port), or listed in ``allowed_origins`` (``--allow-origin``; ``*`` allows any).  Never
        compared with ``Host``, which a rebinding page controls as well."""
        values = request.headers.get_all("Origin") if hasattr(request.headers, "get_all") else [
            request.headers.get("Origin")]
        values = [v for v in values if v is not None]
        if not values:
            return True  # non-browser clients send no Origin
        if len(values) > 1:
            return False
        origin = values[0]
        allowed = self.config.allowed_origins
        if "*" in allowed or origin in allowed or origin.rstrip("/") in allowed:
            return True
        try:
            parts = urlsplit(origin)
            host = parts.hostname
            parts.port  # noqa: B018 - raises ValueError for a bad port
        except ValueError:
            return False
        return parts.scheme in ("http", "https") and host is not None and host.rstrip(".") in self.hosts

    def process_request(self, conn, request):
        """The WebSocket library's ``process_request`` hook: answer a plain HTTP request (page, static file, API,
        ``/healthz``) or refuse a cross-origin upgrade; ``None`` lets a ``/ws`` upgrade go on."""
        try:
            parts = urlsplit(request.path)
        except ValueError:
            return self._json(conn, 400, {"error": "bad request path"})
        path, query = parts.path, parse_qs(parts.query)
        if not self._host_ok(request):
            log.warning("refused %s for Host %r: not an allowed host name", path[:100],
                        str(request.headers.get("Host"))[:100])
            self.stats["rejected"] += 1
            return self._json(conn, 403, {"error": "host not allowed (a DNS-rebinding page?); start the server with "
                                                   "--allow-host NAME to serve this name"})
        if (path == "/ws" or path.startswith("/api/")) and not self._origin_ok(request):
            log.warning("refused %s from origin %r: not an allowed origin", path[:100],
                        str(request.headers.get("Origin"))[:100])
            self.stats["rejected"] += 1
            return self._json(conn, 403,
                              {"error": "cross-origin request refused; start the server with --allow-origin"})
        if path == "/ws":
            if not self._origin_ok(request):
                log.warning("rejected WebSocket from origin %r (host %r): cross-site request",
                            request.headers.get("Origin"), request.headers.get("Host"))
                self.stats["rejected"] += 1
                return self._json(conn, 403,
                                  {"error": "cross-origin WebSocket refused; start the server with --allow-origin"})
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
                body = self._replay.get(name)
                if body is None:
                    return self._json(conn, 404, {"error": f"no replay data for model {name!r}"})
                return self._http(conn, 200, body, "application/json; charset=utf-8")
        return self._json(conn, 404, {"error": f"not found: {path}"})

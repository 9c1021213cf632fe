"""Streaming server for fitted Interaction Primitives, its browser page and Python clients.

``interprim serve MODEL.npz ...`` (or ``--demo``) starts a WebSocket server
(protocol: ``docs/protocol.md``; schema: ``static/protocol.schema.json``) that
answers every observed frame with the phase, the recognised model and the
controlled agent's predicted trajectory, and serves a live page at ``/``.

Needs the ``serve`` extra (``pip install interprim[serve]``: the ``websockets``
library).  Names are loaded lazily so ``import interprim.server`` is cheap.
"""

from __future__ import annotations

import importlib

_LAZY = {
    "PROTOCOL_VERSION": "interprim.server.protocol",
    "ProtocolError": "interprim.server.protocol",
    "Client": "interprim.server.client",
    "AsyncClient": "interprim.server.client",
    "ServerError": "interprim.server.client",
    "InterprimServer": "interprim.server.app",
    "ServerConfig": "interprim.server.app",
    "ServerThread": "interprim.server.app",
    "load_models": "interprim.server.models",
    "ModelEntry": "interprim.server.models",
    "demo_models": "interprim.server.demo",
}

__all__ = list(_LAZY)


def __getattr__(name):
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'interprim.server' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(__all__))

"""The interprim streaming protocol: message parsing and validation.

Pure Python (plus numpy for frames); no networking here, so that the rules can be
tested and reused without a server.  The normative description is
``docs/protocol.md``; the JSON Schema is ``static/protocol.schema.json``.

Every function here raises :class:`ProtocolError` with a machine-readable
``code`` and a human-readable message naming the offending field.
"""

from __future__ import annotations

import json
import math
import re
import struct
from collections.abc import Sequence
from typing import Any, NoReturn, TypeGuard, cast

import numpy as np
from numpy.typing import ArrayLike

PROTOCOL_VERSION = 1
"""Version of the wire protocol.  Bumped on any incompatible change."""

SUPPORTED_VERSIONS = (1,)

CLIENT_TYPES = ("hello", "open", "frame", "reset", "close")

# Error codes sent in {"type": "error", "code": ...}.
ERROR_CODES = {
    "bad_json": "the text message is not valid UTF-8 JSON",
    "bad_message": "the message is not an object, lacks 'type', or a field has the wrong type/value",
    "unknown_type": "the 'type' field names no client message",
    "bad_version": "the client's protocol version is not supported",
    "not_ready": "'hello' must be the first message",
    "unauthorized": "the hello carried no token or a wrong one (the session is then closed with 1008)",
    "not_open": "a frame/reset/close was sent with no open session",
    "unknown_model": "the requested model is not loaded",
    "bad_frame": "the frame has the wrong length, a non-number, NaN or inf, or a bad binary size",
    "rate_limited": "the message exceeded the server's rate limit and was dropped",
    "internal": "the server failed to compute this prediction (logged on the server)",
}

# WebSocket close codes used by the server (RFC 6455 + IANA registry).
CLOSE_NORMAL = 1000
CLOSE_GOING_AWAY = 1001
CLOSE_INVALID_DATA = 1007  # a text message that is not UTF-8
CLOSE_POLICY = 1008  # bad token, client that never reads, too many protocol errors
CLOSE_TOO_BIG = 1009  # message over --max-message-bytes (sent by the websockets library)
CLOSE_INTERNAL = 1011
CLOSE_TRY_AGAIN = 1013  # too many sessions

MAX_POINTS_HARD = 2000
MAX_CANDIDATES = 64


class ProtocolError(Exception):
    """A client message broke the protocol; ``code`` is one of :data:`ERROR_CODES`."""

    def __init__(self, code: str, message: str, *, fatal: bool = False):
        super().__init__(message)
        self.code = code
        self.message = message
        self.fatal = fatal


def _is_number(v: object) -> TypeGuard[float]:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _describe(v: object) -> str:
    text = json.dumps(v, allow_nan=True, default=str) if not isinstance(v, str) else repr(v)
    return text if len(text) <= 60 else text[:57] + "..."


def parse_text(data: str) -> dict[str, Any]:
    """Parse one text message into a dict with a valid ``type``."""
    try:
        msg = _DECODER.decode(data)
    except ProtocolError:
        raise
    except (ValueError, RecursionError) as exc:
        raise ProtocolError("bad_json", f"message is not valid JSON: {exc}") from None
    if not isinstance(msg, dict):
        raise ProtocolError("bad_message", f"message must be a JSON object, got {type(msg).__name__}")
    mtype = msg.get("type")
    if not isinstance(mtype, str):
        raise ProtocolError("bad_message", f"message needs a string field 'type', got {_describe(mtype)}")
    if mtype not in CLIENT_TYPES:
        raise ProtocolError(
            "unknown_type", f"unknown message type {_describe(mtype)}; expected one of {list(CLIENT_TYPES)}"
        )
    return msg


def _reject_constant(name: str) -> NoReturn:
    # json.loads accepts the non-standard tokens NaN, Infinity, -Infinity; the protocol does not.
    raise ProtocolError("bad_json", f"message is not valid JSON: non-standard constant {name} (use finite numbers)")


# one decoder: json.loads(...) with options builds one per call
_DECODER = json.JSONDecoder(parse_constant=_reject_constant)


def check_hello(msg: dict[str, Any]) -> dict[str, Any]:
    """Validate a ``hello``; returns ``{"version": int, "token": str|None, "client": str|None}``."""
    version = msg.get("version", PROTOCOL_VERSION)
    if not isinstance(version, int) or isinstance(version, bool):
        raise ProtocolError("bad_message", f"hello.version must be an integer, got {_describe(version)}")
    if version not in SUPPORTED_VERSIONS:
        raise ProtocolError(
            "bad_version",
            f"protocol version {version} is not supported; this server speaks {list(SUPPORTED_VERSIONS)}",
            fatal=True,
        )
    token = msg.get("token")
    if token is not None and not isinstance(token, str):
        raise ProtocolError("bad_message", "hello.token must be a string")
    client = msg.get("client")
    if client is not None and not isinstance(client, str):
        raise ProtocolError("bad_message", "hello.client must be a string")
    return {"version": version, "token": token, "client": client}


#: The model name of an ``open`` that recognises the interaction among candidates (not a loaded model's name).
RECOGNISE = "recognise"


def check_open(msg: dict[str, Any], models: dict[str, Any], *, default_points: int,
               max_points: int) -> dict[str, Any]:
    """Validate an ``open`` against the loaded ``models`` (name -> entry with ``n_observed``)."""
    name = msg.get("model", RECOGNISE)
    if not isinstance(name, str):
        raise ProtocolError("bad_message",
                            f"open.model must be a string (a model name or {RECOGNISE!r}), got {_describe(name)}")
    if name == "auto":
        raise ProtocolError("bad_message", f"open.model 'auto' is now {RECOGNISE!r}: recognise the interaction among "
                            "open.candidates (default: every loaded model)")
    cands = msg.get("candidates")
    if name == RECOGNISE:
        if cands is None:
            cands = list(models)
        if not isinstance(cands, list) or not cands or not all(isinstance(c, str) for c in cands):
            raise ProtocolError("bad_message", "open.candidates must be a non-empty list of model names")
        if len(cands) > MAX_CANDIDATES:
            raise ProtocolError("bad_message", f"open.candidates has {len(cands)} names; at most {MAX_CANDIDATES}")
        cands = list(dict.fromkeys(cands))
        unknown = [c for c in cands if c not in models]
        if unknown:
            raise ProtocolError(
                "unknown_model", f"unknown model(s) {unknown} in open.candidates; loaded: {sorted(models)}"
            )
        dims = {c: models[c].n_observed for c in cands}
        if len(set(dims.values())) != 1:
            raise ProtocolError(
                "bad_message",
                "'recognise' needs candidates that observe the same number of DoFs; got "
                + ", ".join(f"{c}: {d}" for c, d in dims.items())
                + " (choose them with open.candidates)",
            )
    else:
        if cands is not None:
            raise ProtocolError("bad_message", "open.candidates is only allowed with model 'recognise'")
        if name not in models:
            raise ProtocolError("unknown_model", f"unknown model {name!r}; loaded: {sorted(models)} or 'recognise'")
        cands = [name]
    points = msg.get("points", default_points)
    if not isinstance(points, int) or isinstance(points, bool) or not 2 <= points <= max_points:
        raise ProtocolError("bad_message",
                            f"open.points must be an integer in [2, {max_points}], got {_describe(points)}")
    std = msg.get("std", False)
    if not isinstance(std, bool):
        raise ProtocolError("bad_message", f"open.std must be true or false, got {_describe(std)}")
    dofs = msg.get("dofs")
    if dofs is not None and dofs not in ("controlled", "all"):
        raise ProtocolError("bad_message", f"open.dofs must be 'controlled' or 'all', got {_describe(dofs)}")
    robot_state = check_robot_state(msg.get("robot_state"), "open.robot_state")
    return {
        "model": name,
        "candidates": cands,
        "points": points,
        "std": std,
        "dofs": dofs,
        "robot_state": robot_state,
    }


def check_robot_state(value: object, where: str) -> list[float] | list[list[float]] | None:
    """Validate a ``robot_state``: ``null``, the controlled agent's current positions ``[p1, ..., pn]``, or
    positions and velocities (units per second) ``[[p1, ..., pn], [v1, ..., vn]]``.  The length ``n``
    is checked against each model by :func:`check_robot_state_for`."""
    if value is None:
        return None
    rows = value if isinstance(value, list) and value and all(isinstance(r, list) for r in value) else None
    if rows is not None:
        if len(rows) != 2 or len(rows[0]) != len(rows[1]):
            raise ProtocolError("bad_message", f"{where} as positions and velocities must be two lists of the same "
                                "length [[p1, ..., pn], [v1, ..., vn]], got " + _describe(value))
        flat = rows[0] + rows[1]
    elif isinstance(value, list):
        flat = value
    else:
        flat = None
    if flat is None or not flat or not all(_is_number(v) for v in flat):
        raise ProtocolError("bad_message", f"{where} must be null, a list of numbers (the controlled agent's "
                            "positions) or [[positions], [velocities]], got " + _describe(value))
    try:
        finite = all(math.isfinite(v) for v in flat)
    except OverflowError:  # an integer beyond float range
        finite = False
    if not finite:
        raise ProtocolError("bad_message", f"{where} contains NaN, inf or a number too large for a float64")
    return cast("list[float] | list[list[float]]", value)


def check_robot_state_for(robot_state: list[float] | list[list[float]] | None, name: str, n_controlled: int,
                          where: str) -> None:
    """``robot_state`` (validated by :func:`check_robot_state`) must have ``n_controlled`` values per row."""
    if robot_state is None:
        return
    n = len(robot_state[0]) if isinstance(robot_state[0], list) else len(robot_state)
    if n_controlled == 0:
        raise ProtocolError("bad_message", f"{where}: model {name!r} has no controlled agent; send null")
    if n != n_controlled:
        raise ProtocolError("bad_message", f"{where} has {n} values per row; model {name!r} controls "
                            f"{n_controlled} DoFs (its controlled_dofs, in that order)")


def check_reset(msg: dict[str, Any]) -> list[float] | list[list[float]] | None:
    """Validate a ``reset``; returns its optional ``robot_state``."""
    return check_robot_state(msg.get("robot_state"), "reset.robot_state")


_FRAME_TYPE = re.compile(r'"type"\s*:\s*"frame"')
_T_FIELD = re.compile(r'"t"\s*:\s*(-?(?:0|[1-9][0-9]*)(?:\.[0-9]+)?(?:[eE][+-]?[0-9]+)?)\s*[,}]')


def scan_unparsed(text: str) -> tuple[bool, float | None]:
    """For a text message that is not valid JSON: is it a frame, and its echo stamp ``t`` if readable.

    Lenient on purpose (regular expressions on the raw text): a message containing ``"type": "frame"``
    (any white space) counts as a frame, so that the server's frame numbering (``seq``) stays the one
    the client counts; ``"t": <number>`` gives the stamp to echo in the error.
    """
    if not isinstance(text, str) or len(text) > 1 << 20:
        return False, None
    if _FRAME_TYPE.search(text) is None:
        return False, None
    m = _T_FIELD.search(text)
    t = None
    if m is not None:
        v = float(m.group(1))
        t = v if math.isfinite(v) else None
    return True, t


def frame_stamp(msg: dict[str, Any] | None) -> float | None:
    """A parsed frame message's ``t`` if it is a finite number (echoed in replies and errors), else ``None``."""
    if msg is None:
        return None
    t = msg.get("t")
    if _is_number(t):
        try:
            return float(t) if math.isfinite(t) else None
        except OverflowError:
            return None
    return None


def check_frame(msg: dict[str, Any], n: int) -> tuple[np.ndarray, float | None]:
    """Validate a JSON ``frame``; returns the float64 frame and the optional echo stamp ``t``."""
    frame = msg.get("frame")
    if not isinstance(frame, list):
        raise ProtocolError("bad_frame", f"frame.frame must be a list of {n} numbers, got {_describe(frame)}")
    if len(frame) != n:
        raise ProtocolError("bad_frame", f"frame.frame has {len(frame)} values; this model observes {n} DoFs")
    t = msg.get("t")
    if all(type(v) is float for v in frame) and (t is None or type(t) is float):
        # fast path (the usual frame): floats from JSON; NaN/inf cannot come out of the parser
        # (parse_constant rejects them) but 1e999 parses as inf, so still check
        if all(map(math.isfinite, frame)) and (t is None or math.isfinite(t)):
            return np.array(frame, dtype=np.float64), t
    for i, v in enumerate(frame):
        if not _is_number(v):
            raise ProtocolError("bad_frame", f"frame.frame[{i}] must be a number, got {_describe(v)}")
    try:
        arr = np.array(frame, dtype=np.float64)
    except OverflowError:  # integers beyond float range
        raise ProtocolError("bad_frame", "frame.frame has an integer too large for a float64") from None
    if not np.all(np.isfinite(arr)):
        raise ProtocolError("bad_frame", f"frame.frame contains NaN or inf: {_describe(frame)}")
    if t is not None and not (_is_number(t) and math.isfinite(t)):
        raise ProtocolError("bad_message", f"frame.t must be a finite number (echoed back), got {_describe(t)}")
    return arr, t


def decode_binary_frame(data: bytes, n: int) -> np.ndarray:
    """Decode a binary frame: exactly ``n`` little-endian IEEE-754 float64 values."""
    if len(data) != 8 * n:
        raise ProtocolError(
            "bad_frame",
            f"binary frame has {len(data)} bytes; expected {8 * n} ({n} little-endian float64 values)",
        )
    arr = np.frombuffer(data, dtype="<f8").astype(np.float64)
    if not np.all(np.isfinite(arr)):
        raise ProtocolError("bad_frame", f"binary frame contains NaN or inf: {arr.tolist()}")
    return arr


def encode_binary_frame(frame: Sequence[float] | np.ndarray) -> bytes:
    """Encode a frame for the binary form of ``frame`` (little-endian float64)."""
    values = [float(v) for v in frame]
    return struct.pack(f"<{len(values)}d", *values)


def error(code: str, message: str, **extra: Any) -> dict[str, Any]:
    out = {"type": "error", "code": code, "message": message}
    out.update({k: v for k, v in extra.items() if v is not None})
    return out


def dumps(obj: Any) -> str:
    """Compact JSON; raises ``ValueError`` on NaN/inf (never sent on the wire)."""
    return json.dumps(obj, separators=(",", ":"), allow_nan=False)


def softmax(values: ArrayLike) -> list[float]:
    """Posterior probabilities from log-likelihoods (uniform prior); robust to -inf/NaN."""
    v = np.asarray(values, dtype=np.float64)
    v = np.where(np.isnan(v), -np.inf, v)
    if not np.any(np.isfinite(v)):
        return [1.0 / v.size] * v.size
    v = v - np.max(v[np.isfinite(v)])
    e = np.exp(np.clip(v, -745.0, 0.0))
    e[~np.isfinite(v)] = 0.0
    return [float(v) for v in e / e.sum()]

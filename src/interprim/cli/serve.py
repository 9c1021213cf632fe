"""``interprim serve``: the streaming server and live page (top-level imports stay light)."""

from __future__ import annotations

import os

DESCRIPTION = """\
Serve fitted models over WebSocket (protocol: docs/protocol.md) and a live page in the browser.

A client (a robot controller, the page, interprim.server.Client) opens a session on one model,
or on "recognise" to let the server recognise the interaction among the loaded models, streams the
observed agent's frames and gets after each frame the phase, the recognised model and the
controlled agent's predicted trajectory (mean, optionally a std band).

Open http://127.0.0.1:8765/ for the page: any served model on its "Any model" tab (replay its
demonstrations given with --replay, or drag an observed DoF, and see both agents' predicted DoFs
over time), plus the simulated high-five and handwriting completion (start with --demo to fit the
demo models at start-up)."""

EPILOG = """\
examples:
  interprim serve --demo                      # fit the demo models, open http://127.0.0.1:8765/
  interprim serve highfive.npz letters/a.npz  # model names are the file stems
  interprim serve mine.npz --replay mine=demos.csv --units mine=rad,rad,m,m,m
  interprim serve mine.npz --replay mine=takes/ --units cm   # BVH takes in centimetres (= --length-unit cm)
  interprim serve mine.npz --replay mine=rec.bag --topics /human/wrist,/robot/joint_states
  interprim serve m.npz --host 0.0.0.0 --token "$(openssl rand -hex 16)"

Listening on anything but loopback requires --token (or INTERPRIM_TOKEN); clients send it in
their hello message and the page reads it from ?token=... in its URL.

Ctrl-C (SIGINT) or SIGTERM stops the server cleanly: the frames received so far are answered, every
session is closed with code 1001 "server shutting down (SIG...)", worker threads and processes are
joined; exit status 130 after SIGINT, 0 after SIGTERM. A second signal exits at once."""


def add_parser(subparsers) -> None:
    import argparse

    p = subparsers.add_parser(
        "serve",
        help="serve models over WebSocket with a live browser page",
        description=DESCRIPTION,
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("models", nargs="*", metavar="MODEL", help="saved model files (.npz); name = file stem")
    p.add_argument("--replay", action="append", default=[], metavar="MODEL=DEMOS",
                   help="demonstrations the page can replay to MODEL (served at /api/replay/MODEL): a data file "
                        "or folder as 'interprim fit' reads, e.g. the training CSV (repeatable)")
    p.add_argument("--units", action="append", default=[], metavar="MODEL=U1,U2,...",
                   help="units of MODEL's data columns, in column order (e.g. rad,rad,m; empty = unknown), sent to "
                        "clients to label values (repeatable); a bare length unit (--units cm) is the length unit of "
                        "the --replay recordings, as --length-unit")
    p.add_argument("--demo", action="store_true",
                   help="also fit demo models at start-up: 'highfive' (interprim.sim) and letters c/s/u")
    p.add_argument("--host", default="127.0.0.1", help="interface to listen on (default 127.0.0.1)")
    p.add_argument("--port", type=int, default=8765, help="TCP port (default 8765; 0 = any free port)")
    p.add_argument("--token", default=None,
                   help="shared token clients must send in hello (default: $INTERPRIM_TOKEN); "
                        "required when --host is not loopback")
    p.add_argument("--max-sessions", type=int, default=64, help="concurrent sessions (default 64)")
    p.add_argument("--max-message-bytes", type=int, default=65536,
                   help="largest accepted message; bigger ones close the session with 1009 (default 65536)")
    p.add_argument("--max-rate-hz", type=float, default=500.0,
                   help="messages per second per session; extra ones are dropped with a rate_limited error "
                        "(default 500)")
    p.add_argument("--rate-burst", type=int, default=50, help="burst allowance of the rate limit (default 50)")
    p.add_argument("--workers", type=int, default=0,
                   help="threads for the prediction maths; 0 = on the event loop (default; threads are "
                        "slower for the current core: see benchmarks/SERVER_RESULTS.md)")
    p.add_argument("--processes", type=int, default=0,
                   help="worker processes for the prediction maths, sessions pinned to one each; 0 = none "
                        "(default). Uses several cores: see benchmarks/SERVER_RESULTS.md")
    p.add_argument("--send-queue", type=int, default=256,
                   help="replies pending for one client before it is closed as not reading (default 256)")
    p.add_argument("--max-pending", type=int, default=64,
                   help="frames of one session waiting for their turn (answered together by one reply) before "
                        "the server stops reading that session until its turn (default 64)")
    p.add_argument("--allow-origin", action="append", default=[], metavar="ORIGIN",
                   help="extra browser Origin allowed to open WebSockets and call /api (default: the origins of "
                        "the allowed hosts only)")
    p.add_argument("--allow-host", action="append", default=[], metavar="NAME",
                   help="extra Host name the server answers to (default: localhost, 127.0.0.1, ::1 and the "
                        "--host address; any other Host is refused with 403 against DNS rebinding)")
    p.add_argument("--hello-timeout", type=float, default=5.0,
                   help="seconds from connecting to an accepted hello (default 5)")
    p.add_argument("--max-unauthenticated", type=int, default=64,
                   help="connections without an accepted hello, in all (default 64)")
    p.add_argument("--max-unauthenticated-per-address", type=int, default=8,
                   help="connections without an accepted hello from one IP address; a new one aborts the oldest "
                        "(default 8; raise it behind a reverse proxy)")
    p.add_argument("--loop", default="best", choices=["best", "uvloop", "asyncio"],
                   help="event loop: best (default) = uvloop if installed (about a third less CPU per frame), "
                        "else asyncio's")
    p.add_argument("--log-level", default="INFO", choices=["DEBUG", "INFO", "WARNING", "ERROR"])
    from ._common import MAX_NAN_GAP_HELP

    p.add_argument("--max-nan-gap", type=int, default=None, help="--replay: " + MAX_NAN_GAP_HELP)
    from ._common import add_recording_args

    add_recording_args(p, what="--replay")  # the same recording options as 'interprim fit', for every --replay
    p.set_defaults(func=run)


class _Terminated(BaseException):
    """SIGTERM before the event loop runs (while models load or demo models are fitted)."""


def _on_early_sigterm(signum, frame):
    raise _Terminated()


def run(args) -> int:
    import signal

    previous = signal.signal(signal.SIGTERM, _on_early_sigterm) if hasattr(signal, "SIGTERM") else None
    try:
        return _run(args)
    except _Terminated:
        print("interprim serve: terminated (SIGTERM) before serving", flush=True)
        return 0
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


def _run(args) -> int:
    import asyncio
    import logging
    import signal

    from ..core.errors import InterprimError, ModelFileError

    logging.basicConfig(level=getattr(logging, args.log_level),
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    log = logging.getLogger("interprim.server")
    if args.log_level != "DEBUG":  # the websockets library logs every HTTP request at INFO
        logging.getLogger("interprim.server.websockets").setLevel(logging.WARNING)
    try:
        import websockets  # noqa: F401
    except ImportError:
        raise InterprimError("interprim serve needs the 'websockets' package: pip install 'interprim[serve]'") from None
    from ..server.app import InterprimServer, ServerConfig, new_event_loop
    from ..server.app import run as run_loop
    from ..server.models import load_models

    if not args.models and not args.demo:
        raise InterprimError("give at least one MODEL file, or --demo to fit demo models")
    token = args.token if args.token is not None else (os.environ.get("INTERPRIM_TOKEN") or None)
    config = ServerConfig(
        host=args.host,
        port=args.port,
        token=token,
        max_sessions=args.max_sessions,
        max_message_bytes=args.max_message_bytes,
        max_rate_hz=args.max_rate_hz,
        rate_burst=args.rate_burst,
        workers=args.workers,
        processes=args.processes,
        send_queue=args.send_queue,
        max_pending=args.max_pending,
        allowed_origins=tuple(args.allow_origin),
        allowed_hosts=tuple(args.allow_host),
        hello_timeout=args.hello_timeout,
        max_unauthenticated=args.max_unauthenticated,
        max_unauthenticated_per_address=args.max_unauthenticated_per_address,
        loop=args.loop,
    )
    try:
        config.validate()
    except ValueError as exc:
        raise InterprimError(f"bad option: {exc}") from None  # printed as a clean CLI error
    models = load_models(args.models)  # fails here, before listening, on a corrupt file
    labels, length_unit = _split_units(args.units, args.length_unit)
    _attach_units(models, labels)
    from ._common import recording_options

    options = dict(recording_options(args), max_nan_gap=args.max_nan_gap, length_unit=length_unit)
    _attach_replays(models, args.replay, options)
    extra = {}
    if args.demo:
        from ..server.demo import demo_models

        log.info("fitting demo models (simulated high-five + letters) ...")
        for name, entry in demo_models(progress=True).items():
            if name in models:
                raise ModelFileError(f"a model file is named {name!r} like a demo model; rename it")
            models[name] = entry
    if any(e.meta.get("world") == "highfive" for e in models.values()) or _has_sim():
        try:
            from ..server.demo import highfive_world

            extra["highfive_world"] = highfive_world()
        except Exception:  # the page then draws the arms with default lengths
            pass
    server = InterprimServer(models, config, extra_info=extra)
    stop_signals = [getattr(signal, n) for n in ("SIGINT", "SIGTERM") if hasattr(signal, n)]

    async def main() -> int:
        loop = asyncio.get_running_loop()
        stop = asyncio.Event()
        got: list = []

        def on_signal(sig):
            if got:  # a second signal: the user does not want to wait
                log.warning("%s again: exiting at once", sig.name)
                os._exit(130 if sig == signal.SIGINT else 0)
            got.append(sig)
            stop.set()

        handled = []
        for sig in stop_signals:
            try:
                loop.add_signal_handler(sig, on_signal, sig)
                handled.append(sig)
            except (NotImplementedError, RuntimeError):  # not on this platform: Ctrl-C raises KeyboardInterrupt
                pass
        try:
            await server.start()
            if not got:
                print(f"interprim serve: open {server.url}  (WebSocket {server.ws_url}; Ctrl-C to stop)", flush=True)
            await stop.wait()
        finally:
            why = got[0].name if got else "error"
            log.info("%s: shutting down", why)
            await server.shutdown(f"server shutting down ({why})")
            for sig in handled:
                loop.remove_signal_handler(sig)
        log.info("stopped (%d sessions served, %d predictions, %d frames coalesced)", server.stats["sessions"],
                 server.stats["predictions"], server.stats["coalesced"])
        return 130 if got[0] == signal.SIGINT else 0  # 128 + SIGINT, the shell's code for Ctrl-C

    try:
        new_event_loop(config.loop).close()  # --loop uvloop without uvloop: a clean error before fitting anything
    except ImportError as exc:
        raise InterprimError(str(exc)) from None
    try:
        return run_loop(main(), config.loop)
    except OSError as exc:
        raise InterprimError(f"cannot listen on {args.host}:{args.port}: {exc}") from None


def _pairs(values, flag):
    from ..core.errors import InterprimError

    for text in values:
        name, sep, value = text.partition("=")
        if not sep or not name or not value:
            raise InterprimError(f"{flag} expects MODEL=VALUE, got {text!r}")
        yield name, value


def _entry(models, name, flag, text):
    from ..core.errors import InterprimError

    if name not in models:
        raise InterprimError(f"{flag} {text!r}: no model named {name!r} (loaded: {', '.join(sorted(models))})")
    return models[name]


LENGTH_UNITS = ("mm", "cm", "m", "in", "ft")


def _split_units(values, length_unit):
    """``--units`` values as (MODEL=U1,... entries, the recordings' length unit): a bare ``--units cm`` is the
    length unit of the ``--replay`` recordings, as ``--length-unit cm``."""
    from ..core.errors import InterprimError

    labels, bare = [], []
    for text in values:
        (bare if "=" not in text and text.strip() in LENGTH_UNITS else labels).append(text)
    units = {u.strip() for u in bare} | ({length_unit} if length_unit else set())
    if len(units) > 1:
        raise InterprimError(f"--units/--length-unit: two length units for the --replay recordings: "
                             f"{', '.join(sorted(units))}")
    return labels, (units.pop() if units else None)


def _attach_units(models, values) -> None:
    from ..core.errors import InterprimError

    for name, value in _pairs(values, "--units"):
        e = _entry(models, name, "--units", f"{name}={value}")
        units = [u.strip() or None for u in value.split(",")]
        if len(units) != e.n_dofs:
            raise InterprimError(f"--units {name}={value!r}: {len(units)} units for {e.n_dofs} columns "
                                 f"({', '.join(e.names)})")
        e.meta["units"] = units


def _attach_replays(models, values, options=None) -> None:
    """Load each ``--replay MODEL=DEMOS`` with the recording ``options`` (``load_demonstrations`` keywords)."""
    from ..core.errors import InterprimError
    from ..server.models import load_replay

    for name, path in _pairs(values, "--replay"):
        e = _entry(models, name, "--replay", f"{name}={path}")
        try:
            e.meta["replay"] = load_replay(e, path, **(options or {}))
        except (OSError, ValueError) as exc:  # DataFileError is a ValueError
            raise InterprimError(f"--replay {name}={path}: {exc}") from None


def _has_sim() -> bool:
    import importlib.util

    return importlib.util.find_spec("interprim.sim") is not None

"""The ``interprim`` command line.

Each sub-command lives in its own module of this package, which exposes
``add_parser(subparsers)`` (registering one or more sub-commands with
``set_defaults(func=...)``).  Those modules keep their top-level imports
light; heavy imports happen inside the command functions, so ``--help`` is fast.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from ..core.errors import InterprimError, ModelFileError

# Modules that register sub-commands, in the order they appear in --help.
COMMAND_MODULES = [
    "interprim.cli.demo",
    "interprim.cli.fit",
    "interprim.cli.predict",
    "interprim.cli.handwriting",
    "interprim.cli.serve",
    "interprim.cli.evaluate",
    "interprim.cli.ros2",
]

# The extra named when a command misses an optional module that this extra installs (README: *Install*).
COMMAND_EXTRA = {"demo": "experiments", "evaluate": "experiments", "handwriting": "experiments", "serve": "serve",
                 "ros2": "ros2"}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="interprim",
        description=(
            "Interaction Primitives (Ben Amor et al., ICRA 2014): learn from demonstrations of two "
            "people how a robot should respond to a human partner, then predict that response "
            "from a partial observation of the human."
        ),
        epilog="Run 'interprim COMMAND --help' for the options of one command.",
    )
    from .. import __version__

    parser.add_argument("--version", action="version", version=f"interprim {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMAND_MODULES:
        importlib.import_module(name).add_parser(sub)
    return parser


def flag_names(parser, command, exc) -> str:
    """The message of ``exc`` with the command's Python argument names as flags: ``max_nan_gap=30`` as
    ``--max-nan-gap 30``, ``trim=True`` as ``--trim``, ``time_column=`` (no value) as ``--time-column``.

    One line, unless the error holds a table (``exc.multiline``), which is printed as it is."""
    msg = str(exc) if getattr(exc, "multiline", False) else " ".join(str(exc).split("\n"))
    try:
        sub = parser._subparsers._group_actions[0].choices[command]
    except (AttributeError, IndexError, KeyError, TypeError):  # pragma: no cover
        return msg
    import re

    for action in sub._actions:
        flags = [o for o in action.option_strings if o.startswith("--")]
        if not flags:
            continue
        flag, name = flags[0], re.escape(action.dest)
        lead = r"(?<![\w./\\-])"
        if action.nargs == 0 and action.const is True:  # a store_true flag
            msg = re.sub(lead + name + r"=True\b", flag, msg)
        msg = re.sub(lead + name + r"=(?=[\s,;:)]|$)", flag, msg)  # 'name=' without a value: the flag alone
        msg = re.sub(lead + name + r"=(?=\S)", flag + " ", msg)  # 'name=value': the flag and the value
        if "_" in action.dest:  # a whole word, not part of a file name
            msg = re.sub(lead + name + r"(?![\w/\\-]|\.\w)", flag, msg)
    return msg


class _OncePerCause:
    """Warnings of a command: each cause printed once, as one line ``warning: ...`` (no Python source line), and
    at the end how many times each cause repeated."""

    def __init__(self, parser, command):
        self.parser, self.command = parser, command
        self.seen: dict = {}

    def show(self, message, category, filename, lineno, file=None, line=None):
        import re

        from ..core.errors import DataFileWarning

        text = str(message)
        # one cause: a warning about a file is its own (file names differ); another warning of one category whose
        # numbers differ (a fold's ratios) is one cause
        key = (category.__name__, text if issubclass(category, DataFileWarning) else re.sub(r"\d+(\.\d+)?", "#", text))
        if key in self.seen:
            self.seen[key][0] += 1
            return
        self.seen[key] = [1, text]
        text = flag_names(self.parser, self.command, message if isinstance(message, Exception) else Exception(message))
        print(f"warning: {text} ({category.__name__})", file=sys.stderr)

    def summary(self):
        for (name, _), (n, msg) in self.seen.items():
            if n > 1:
                short = msg if len(msg) <= 60 else msg[:57] + "..."
                print(f"warning: the {name} above ({short!r}) was raised {n} times in all (its numbers may differ)",
                      file=sys.stderr)


def main(argv=None) -> int:
    import warnings

    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    once = _OncePerCause(parser, args.command)
    with warnings.catch_warnings():
        warnings.simplefilter("always")  # counted here, printed once per cause
        warnings.filterwarnings("ignore", category=DeprecationWarning)
        warnings.filterwarnings("ignore", category=PendingDeprecationWarning)
        warnings.showwarning = once.show
        try:
            return _run(parser, args)
        finally:
            once.summary()


def _run(parser, args) -> int:
    try:
        return int(args.func(args) or 0)
    except (InterprimError, FileNotFoundError, IsADirectoryError, PermissionError) as exc:
        print(f"interprim {args.command}: error: {flag_names(parser, args.command, exc)}", file=sys.stderr)
        return 2 if isinstance(exc, ModelFileError) else 1  # a corrupt or non-model file given as MODEL
    except ImportError as exc:  # an optional extra that is not installed: one line naming the pip install
        from .._optional import extra_for_import_error

        msg = extra_for_import_error(exc, prefer=COMMAND_EXTRA.get(args.command))
        if msg is None:
            raise
        print(f"interprim {args.command}: error: {msg}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except SystemError as exc:
        # Ctrl-C while a compiled (numba) function ran: its KeyboardInterrupt comes out as a SystemError
        # ("returned a result with an exception set") caused by it
        if not _interrupted(exc):
            raise
        print("interrupted", file=sys.stderr)
        return 130


def _interrupted(exc: BaseException) -> bool:
    """Whether ``exc`` was caused by a KeyboardInterrupt (anywhere in its chain of causes and contexts)."""
    seen: set[int] = set()
    e: BaseException | None = exc
    while e is not None and id(e) not in seen:
        if isinstance(e, KeyboardInterrupt):
            return True
        seen.add(id(e))
        e = e.__cause__ or e.__context__
    return False


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())

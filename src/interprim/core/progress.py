"""Progress of a long computation, shown only when asked for: a tqdm bar when tqdm is installed (the
``[experiments]`` extra), else (optionally) one line per step on stderr, else nothing.

tqdm is imported when a bar is asked for, never at import time (the core imports no optional package).  Used by
:class:`~interprim.models.auto.AutoInteraction` (``progress=True``, what ``interprim fit`` shows) and by the
real-time protocol's folds (:func:`interprim.model_selection.realtime.realtime_sweep`).
"""

from __future__ import annotations

import sys

__all__ = ["Progress"]


class Progress:
    """A progress display over ``total`` steps (``on=False``: silent).

    Parameters
    ----------
    on : bool
        Show anything at all.
    total : int
        Steps announced (more may be added with :meth:`grow`).
    desc, unit : str
        The bar's label and unit.
    lines : bool, default True
        Without tqdm, print ``"{desc}: step n/total what"`` on stderr after each step (False: silent).
    """

    def __init__(self, on: bool, total: int, desc: str = "fit", unit: str = "step", lines: bool = True):
        self.bar = None
        if on:
            try:
                from tqdm import tqdm
            except ImportError:
                tqdm = None
            if tqdm is not None:
                self.bar = tqdm(total=int(total), desc=desc, unit=unit, leave=False)
            elif lines:
                self.bar = _Lines(int(total), desc)

    def grow(self, n: int) -> None:
        """``n`` more steps than announced (e.g. the members to fit, known once the weights are)."""
        if self.bar is not None:
            self.bar.total += int(n)

    def step(self, what: str = "") -> None:
        """One step done (``what``: a few words on it)."""
        if self.bar is not None:
            if what:
                self.bar.set_postfix_str(what, refresh=False)
            self.bar.update(1)

    def close(self) -> None:
        """The end of the display."""
        if self.bar is not None:
            self.bar.close()

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class _Lines:
    """tqdm's few methods used above, as one line per step on stderr."""

    def __init__(self, total: int, desc: str):
        self.total, self.n, self.what, self.desc = total, 0, "", desc

    def set_postfix_str(self, what: str, refresh: bool = False) -> None:
        self.what = what

    def update(self, k: int) -> None:
        self.n += k
        print(f"{self.desc}: step {self.n}/{self.total} {self.what}", file=sys.stderr, flush=True)

    def close(self) -> None:
        pass

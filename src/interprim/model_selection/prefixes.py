"""The evaluation protocol shared by every experiment: what a prediction may see of a held-out recording.

Two rules:

* **How much is observed.** A held-out demonstration of ``T`` frames observed "``p`` % of the way" shows
  its first :func:`observed_frames` frames: ``round(p T)``, at least 3 (the fewest frames that give a
  phase, a speed and the derivatives of Eq. 15) and at most ``T``.  The rule is defined once, in
  :func:`interprim.core.cv.observed_frames` (the core's own cross-validations use it too), and re-exported here.
* **Causality.** The first ``k`` frames are what a robot would have had at the time of frame ``k``: when the
  demonstrations were interpolated onto a uniform grid from raw samples (NuiSI's ~9 Hz skeletons, a
  resampled recording), frame ``k - 1`` of the grid can be built from a raw sample recorded *after* it.  A
  causal prefix (:func:`causal_prefix`) is rebuilt from the raw samples recorded at or before the time of its
  last frame only: the same interpolation inside that span, and the last raw sample held after it.
  :class:`Prefixes` gives the prefixes of a whole data set, causal whenever the raw samples are known.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import TYPE_CHECKING, cast

import numpy as np
from numpy.typing import ArrayLike

from ..core.cv import MIN_OBSERVED_FRAMES, observed_frames

if TYPE_CHECKING:
    from ..datasets import RawStream

__all__ = ["observed_frames", "MIN_OBSERVED_FRAMES", "causal_prefix", "Prefixes"]

#: Time stamps within this many seconds of a frame's time count as recorded at that time (rounding).
TIME_TOLERANCE = 1e-9


def causal_prefix(times: ArrayLike, streams: Iterable[RawStream], k: int, columns: Sequence[int]) -> np.ndarray:
    """The first ``k`` grid frames of ``columns``, built only from raw samples recorded by frame ``k - 1``'s time.

    Parameters
    ----------
    times : ndarray, shape (T,)
        The uniform grid's time stamps (seconds, on the raw streams' clock).
    streams : sequence of RawStream
        The recorded samples (:class:`interprim.datasets.RawStream`) the grid was interpolated from.
    k : int
        Frames observed, ``1 <= k <= T``.
    columns : sequence of int
        The demonstration's columns to return (each must be held by one stream).

    Returns
    -------
    ndarray, shape (k, len(columns))
        Linear interpolation of the raw samples with time stamp ``<= times[k - 1]`` onto ``times[:k]``; after
        the last such sample its value is held (a robot cannot know where the partner moves next).  Inside the
        span of those samples this equals the full-recording interpolation.

    Raises
    ------
    ValueError
        If ``k`` is out of range, a column is in no stream, or a column has no sample at or before
        ``times[k - 1]`` (nothing had been recorded yet).
    """
    times = np.asarray(times, dtype=np.float64)
    T = times.shape[0]
    if not 1 <= int(k) <= T:
        raise ValueError(f"k must be a number of frames in 1..{T}, got {k}")
    k = int(k)
    t_end = times[k - 1] + TIME_TOLERANCE
    out = np.empty((k, len(columns)))
    where: dict[int, tuple[RawStream, int]] = {}
    for s in streams:
        for j, c in enumerate(s.columns):
            where[int(c)] = (s, j)
    for i, c in enumerate(columns):
        if int(c) not in where:
            raise ValueError(f"column {c} is in none of the raw streams (they hold {sorted(where)})")
        s, j = where[int(c)]
        n = int(np.searchsorted(s.times, t_end, side="right"))
        if n == 0:
            raise ValueError(f"column {c}: no raw sample at or before t = {times[k - 1]:.6g} s "
                             f"(the first is at {s.times[0]:.6g} s)")
        out[:, i] = np.interp(times[:k], s.times[:n], s.values[:n, j])
    return out


class Prefixes:
    """The observed prefixes of a set of demonstrations, causal whenever the raw samples are known.

    Parameters
    ----------
    demos : Demonstrations or sequence of ndarray
        The demonstrations.  A :class:`~interprim.datasets.Demonstrations` with ``raw`` samples gives causal
        prefixes (:func:`causal_prefix`); plain arrays are taken as recorded samples, so their first ``k``
        rows are the prefix.
    observed_dofs : sequence of int
        The observed agent's columns.

    Examples
    --------
    >>> prefixes = Prefixes(load_nuisi(action="highfive1"), observed_dofs)   # doctest: +SKIP
    >>> prefixes(0, 10)        # what a robot had seen of demonstration 0 at its 10th frame
    """

    def __init__(self, demos: Iterable[ArrayLike], observed_dofs: Iterable[int]) -> None:
        self.demos = [np.asarray(d, dtype=np.float64) for d in demos]
        self.observed_dofs = [int(i) for i in observed_dofs]
        raw = getattr(demos, "raw", None)
        times = getattr(demos, "times", None)
        self.causal = raw is not None and times is not None
        # causal: both are given (not None); per demonstration, the raw streams and the grid's time stamps
        self._raw: list[Sequence[RawStream]] | None = (
            list(cast("Iterable[Sequence[RawStream]]", raw)) if self.causal else None)
        self._times: list[np.ndarray] | None = (
            [np.asarray(t, dtype=np.float64) for t in cast("Iterable[ArrayLike]", times)] if self.causal else None)

    def __len__(self) -> int:
        return len(self.demos)

    def __call__(self, j: int, k: int) -> np.ndarray:
        """The first ``k`` frames of demonstration ``j``'s observed columns, as a robot had them then."""
        if not self.causal:
            return self.demos[j][:k, self.observed_dofs]
        times, raw = cast("list[np.ndarray]", self._times), cast("list[Sequence[RawStream]]", self._raw)
        return causal_prefix(times[j], raw[j], k, self.observed_dofs)

    def first_frame(self, j: int) -> int:
        """The fewest frames ``k`` of demonstration ``j`` for which a robot had recorded every observed column at
        least once (1 for plain arrays): a causal prefix exists from there on.

        Raises
        ------
        ValueError
            If an observed column is in none of the demonstration's raw streams.
        """
        if not self.causal:
            return 1
        times, raw = cast("list[np.ndarray]", self._times)[j], cast("list[Sequence[RawStream]]", self._raw)[j]
        first = {int(c): float(s.times[0]) for s in raw for c in s.columns}
        missing = [c for c in self.observed_dofs if c not in first]
        if missing:
            raise ValueError(f"columns {missing} are in none of the raw streams (they hold {sorted(first)})")
        start = max(first[c] for c in self.observed_dofs)
        return int(np.searchsorted(times + TIME_TOLERANCE, start, side="left")) + 1

    def subset(self, indices: Iterable[int]) -> Prefixes:
        """The prefixes of the demonstrations ``indices`` only (renumbered from 0)."""
        idx = list(indices)
        if not self.causal:
            return Prefixes([self.demos[i] for i in idx], self.observed_dofs)
        times, raw = cast("list[np.ndarray]", self._times), cast("list[Sequence[RawStream]]", self._raw)
        return Prefixes(_Recorded([self.demos[i] for i in idx], [times[i] for i in idx],
                                  [raw[i] for i in idx]), self.observed_dofs)


class _Recorded(list[np.ndarray]):
    """Demonstrations with their grid times and raw samples (what :class:`Prefixes` reads)."""

    def __init__(self, demos: Iterable[np.ndarray], times: list[np.ndarray],
                 raw: list[Sequence[RawStream]]) -> None:
        super().__init__(demos)
        self.times, self.raw = times, raw

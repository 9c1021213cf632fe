"""From stamped sensor samples to the model's frame grid: the one rule the ROS 2 bridge applies.

A model is streamed one frame every ``dt`` seconds (its ``dt_``).  Sensor messages come with their own time stamps
(``header.stamp``), at another rate, with jitter, losses, duplicates and the odd late arrival.  :class:`StampGrid`
turns them into grid frames, causally:

* The first sample (and the first after a reset) starts the grid: frame 0 is that sample, at its stamp ``t0``.
* Each later sample with stamp ``t`` (later than the last accepted one) gives the grid frames at
  ``t0 + k * dt`` that lie after the last emitted one and at or before ``t``, each linearly interpolated between
  the previous accepted sample and this one (the rule of the server's pointer input, docs/server.md).  A sample
  that reaches no new grid point gives no frame (it is kept for the next interpolation).
* A sample whose stamp equals the last accepted one is a **duplicate** and is dropped; one older than it by at most
  ``max_gap`` is **late** and is dropped (the grid never goes back in time).  One older by more than ``max_gap``
  is a **clock jump back** (a restarted publisher, a bag played again, a simulation reset): the grid restarts at
  it, as after a gap, so that a reset clock does not make every later message "late".
* A sample more than ``max_gap`` seconds after the last accepted one is a **gap**: interpolating across it would
  invent movement, so the grid restarts at this sample (the bridge starts a new interaction: the stream is reset).
* A sample with a non-finite stamp or value is **invalid** and dropped.

Stamps should be seconds from a recent origin (the bridge subtracts the first message's whole seconds): seconds
since 1970 as a float carry only about 0.2 us of resolution.  A stamp within 1 us of a grid point is on it.

The frames are at most ``max_gap / dt + 1`` per sample, so the work per message is bounded.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["StampGrid", "GridStep", "ON_GRID"]

#: seconds within which a stamp counts as on a grid point (ROS stamps are whole nanoseconds)
ON_GRID = 1e-6


class GridStep:
    """What one sample did: ``status`` (``"start"``, ``"ok"``, ``"duplicate"``, ``"late"``, ``"gap"``, ``"back"``,
    ``"invalid"``), and the grid ``times`` (s, shape ``(k,)``) and ``frames`` (``(k, n)``) it gave (``k`` may be 0)."""

    __slots__ = ("status", "times", "frames")

    def __init__(self, status: str, times, frames):
        self.status, self.times, self.frames = status, times, frames

    @property
    def restarted(self) -> bool:
        """Whether this sample started a new grid (the first one, or after a gap)."""
        return self.status in ("start", "gap", "back")

    def __repr__(self):
        return f"GridStep({self.status!r}, {len(self.times)} frames)"


class StampGrid:
    """Stamped samples -> frames on a uniform grid of interval ``dt`` (see the module docstring).

    Parameters
    ----------
    dt : float
        The grid interval in seconds (the model's ``dt_``).
    max_gap : float
        Longest interval between two samples that is interpolated across (seconds, at least ``dt``).
    """

    def __init__(self, dt: float, max_gap: float = 0.5):
        dt, max_gap = float(dt), float(max_gap)
        if not (math.isfinite(dt) and dt > 0):
            raise ValueError(f"dt must be a positive number of seconds, got {dt!r}")
        if not (math.isfinite(max_gap) and max_gap >= dt):
            raise ValueError(f"max_gap must be at least dt = {dt} s, got {max_gap!r}")
        self.dt, self.max_gap = dt, max_gap
        self.reset()

    def reset(self) -> None:
        """Forget the grid: the next sample starts a new one."""
        self.t0: float | None = None  # grid origin (s)
        self.k = -1  # index of the last emitted grid frame
        self.last_t = math.nan
        self.last_y = np.empty(0)

    @property
    def last_frame_time(self):
        """Time (s) of the last emitted grid frame (``None`` before the first)."""
        return None if self.t0 is None or self.k < 0 else self.t0 + self.k * self.dt

    def add(self, t: float, y) -> GridStep:
        """Add the sample ``y`` (shape ``(n,)``) stamped ``t`` seconds; returns the :class:`GridStep`."""
        t = float(t)
        y = np.asarray(y, dtype=np.float64).reshape(-1)
        empty_t = np.empty(0)
        if not math.isfinite(t) or not np.all(np.isfinite(y)):
            return GridStep("invalid", empty_t, np.empty((0, y.size)))
        if self.t0 is not None and t == self.last_t:
            return GridStep("duplicate", empty_t, np.empty((0, y.size)))
        if self.t0 is not None and self.last_t - self.max_gap <= t < self.last_t:
            return GridStep("late", empty_t, np.empty((0, y.size)))
        if self.t0 is None or abs(t - self.last_t) > self.max_gap or y.size != self.last_y.size:
            status = "start" if self.t0 is None else "back" if t < self.last_t else "gap"
            self.t0, self.k, self.last_t, self.last_y = t, 0, t, y
            return GridStep(status, np.array([t]), y[None, :].copy())
        eps = ON_GRID  # a stamp on the grid up to rounding counts as on it
        k_hi = int(math.floor((t - self.t0 + eps) / self.dt))
        ks = np.arange(self.k + 1, k_hi + 1)
        times = self.t0 + ks * self.dt
        if ks.size:
            w = np.clip((times - self.last_t) / (t - self.last_t), 0.0, 1.0)[:, None]
            frames = (1.0 - w) * self.last_y[None, :] + w * y[None, :]
            on_grid = np.abs(times - t) <= eps
            frames[on_grid] = y  # exactly the sample when it falls on the grid
            self.k = int(k_hi)
        else:
            frames = np.empty((0, y.size))
        self.last_t, self.last_y = t, y
        return GridStep("ok", times, frames)

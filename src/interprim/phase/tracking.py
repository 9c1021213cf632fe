"""Online phase tracking for streams: the likelihood phase by local search (beyond the paper's DTW).

:class:`Tracker` (used by :class:`~interprim.models.primitive.stream.Stream`) scores candidates around the previous
estimate on a fixed lattice of speeds, so the compiled step
(:func:`interprim.core._compiled.phase_likelihood.track_step`) extends each lattice point's statistics by the new
frame instead of recomputing them; it scores with :mod:`interprim.phase.likelihood` and ends where the batch
search ends when the log posterior has one peak (with several, it stays on the peak it tracks, which need not
be the highest one the batch search finds).
"""

from __future__ import annotations

import numpy as np

from ..core._compiled import registry as kernels
from ..core.blas import single_thread
from .likelihood import (
    S_MIN,
    estimate_phase,
    fast_state,
    finish,
    make_scorer,
    phase_noise,
    search_bounds,
    speed_prior_params,
)

__all__: list[str] = []  # used through Stream (the one-shot track_phase was removed: nothing used it)


# ---------------------------------------------------------------------------------------------------------------
# online tracking on a lattice of speeds (used by Stream)

_SLOT_FREE = -(1 << 62)  # = interprim.core._compiled.phase_likelihood.SLOT_FREE (a free slot; no numba import here)
_MAX_GAP = 8  # a slot more frames behind than this is recomputed (a rank-1 step costs ~1/12 of a full one)


def _lattice_candidates(v0: float, kc: int, nh: int, dlog: float, M: int):
    """Candidates of :func:`interprim.core._compiled.phase_likelihood.track_step`: ``(js, s)`` in increasing ``s``, the
    clipped ones merged (``s_min``: the largest such ``j``; ``1``: the smallest)."""
    js: list = []
    ss: list = []
    for j in range(kc - nh, kc + nh + 1):
        s = float(v0 * np.exp(dlog * j)) * (M - 1)
        if s < S_MIN:
            if js and ss[-1] == S_MIN:
                js[-1] = j
                continue
            s = S_MIN
        elif s > 1.0:
            if ss and ss[-1] == 1.0:
                continue
            s = 1.0
        js.append(j)
        ss.append(s)
    return js, np.array(ss)


class Tracker:
    """Online phase of one :class:`~interprim.models.primitive.estimator.Stream` (the likelihood phase, local search).

    The candidates are *speeds* on a fixed lattice ``v_j = v0 exp(dlog j)``, ``dlog = 2 spread /
    (n_candidates - 1)`` (default: 3 candidates 1 % apart), anchored at the first estimate (the batch search's,
    ``v0 = s / (M - 1)`` at ``M = 2``), centred on the previously chosen ``j``: ``s_j = v_j (M - 1)``, clipped
    to ``[S_MIN, 1]`` (clipped candidates merged).  Frame ``m`` of lattice point ``j`` always sits at phase
    ``v_j m``, so the compiled step (:func:`interprim.core._compiled.phase_likelihood.track_step`) extends each
    point's statistics and factors by the new frame (``O(D_o (q^2 + q n) + n^3)``) instead of recomputing them
    (``O(M q (q + D_o) + D_o q^2 n + ...)``).  While the best candidate is at an unclipped edge the window is
    re-centred on it (:meth:`_lattice_step`); the phase returned is then taken off the lattice to the maximum
    of the log posterior by :func:`~interprim.phase.likelihood.finish`, the batch search's own last step.
    Without the kernel (or with a dense prior) the same candidates are scored from scratch.
    """

    def __init__(self, model, n_candidates: int = 3, spread: float = 0.01, speed_prior: bool = True):
        if n_candidates < 1 or n_candidates % 2 == 0:
            raise ValueError("n_candidates must be odd")
        self.model = model
        self.nh = (int(n_candidates) - 1) // 2
        self.dlog = 2.0 * float(spread) / max(int(n_candidates) - 1, 1)
        self.speed_prior = bool(speed_prior)
        self._buf = None
        self._fs = None
        self.reset()

    def reset(self):
        self.v0 = None
        self.kc = 0
        self.Rg = None
        if self._buf is not None:
            self._buf[0][:] = _SLOT_FREE

    def step(self, z) -> float:
        """Phase of the last of the frames ``z`` (the frames seen so far, a prefix of the next call's).

        The lattice step (:meth:`_lattice_step`) finds the best speed on the lattice around the previous one;
        :func:`~interprim.phase.likelihood.finish` then takes the phase to the maximum of the log posterior
        by the same last step as :func:`~interprim.phase.likelihood.estimate_phase`, so that a stream's
        phase is the batch phase of the same frames (within ``1e-3`` of the movement, tested; measured
        ``~1e-6``), not a lattice point ``exp(dlog / 2)`` away, as long as the log posterior has one peak near
        the tracked one: the lattice step is a local search, so it does not jump to a higher peak elsewhere.
        """
        M = z.shape[0]
        if M < 2:
            self.reset()
            return S_MIN
        if self.v0 is None:  # the first estimate: the batch search itself
            s = estimate_phase(self.model, z, speed_prior=self.speed_prior).s_end
            self.v0, self.kc, self.Rg = s / (M - 1), 0, None
            if self._buf is not None:
                self._buf[0][:] = _SLOT_FREE
            return s
        model = self.model
        # what every window and the refinement of this frame share, looked up once per frame
        fs = fast_state(model)
        s2 = phase_noise(model)
        prior = speed_prior_params(model, M) if self.speed_prior else None
        kern = kernels.kernel("phase_likelihood.track_step") if fs is not None else None
        ss, lps, i, found = self._lattice_step(z, fs, s2, prior, kern)
        if not found:  # the maximum moved further than the hops reach: the batch search, lattice re-anchored
            s = estimate_phase(model, z, speed_prior=self.speed_prior).s_end
            self.kc = int(round(np.log(s / (self.v0 * (M - 1))) / self.dlog))
            return s
        return finish(make_scorer(model, z, s2, self.speed_prior, _parts=(fs, prior)), ss, lps, i,
                      *search_bounds(model, M))

    def _lattice_step(self, z, fs, s2, prior, kern):
        """Best lattice point for ``z``: ``(phases, log posteriors, index of the best, found)`` of the last
        window scored (``fs``, ``s2``, ``prior``, ``kern``: the frame's :func:`fast_state`, :func:`phase_noise`,
        speed prior parameters or ``None``, and the compiled step or ``None``).

        When the best point is at an unclipped edge of the window, the window is re-centred on it and scored
        again; ``found`` is false when it is still at an edge after ``_MAX_HOPS`` re-centrings.
        """
        for _ in range(_MAX_HOPS + 1):
            kc0 = self.kc
            ss, lps, i = self._window(z, fs, s2, prior, kern)
            edge = self.kc in (kc0 - self.nh, kc0 + self.nh)
            if not edge or ss[i] <= S_MIN or ss[i] >= 1.0 or self.nh == 0:
                return ss, lps, i, True
        return ss, lps, i, False

    def _window(self, z, fs, s2, prior, kern):
        """Score the window ``kc - nh .. kc + nh``; sets ``kc`` to the best point; returns ``(ss, lps, i)``."""
        M = z.shape[0]
        model = self.model
        if kern is None:
            if self._buf is not None:  # the slots are not kept up to date here
                self._buf[0][:] = _SLOT_FREE
            js, cand = _lattice_candidates(self.v0, self.kc, self.nh, self.dlog, M)
            sc = make_scorer(model, z, s2, self.speed_prior)
            if sc.dense:
                with single_thread():
                    lp = sc(cand)[0]
            else:
                lp = sc(cand)[0]
            i = int(np.argmax(lp))
            self.kc = js[i]
            return cand, lp, i
        if fs is not self._fs or self._buf is None:
            self._fs = fs
            from ..core._compiled.phase_likelihood import track_buffers

            self._buf = track_buffers(fs.q, fs.n_o, fs.Uh.shape[2])
            self._n_out = 2 * self.nh + 1
            self.Rg = None
        if self.Rg is None:
            self.Rg = fs.mean_path(np.ascontiguousarray(z[0]))
        logel, mu, sd = (0.0, 0.0, 1.0) if prior is None else prior
        buf = self._buf
        j, s = kern(fs.Zh, self.Rg, z, M, self.v0, self.kc, self.nh, self.dlog, S_MIN, fs.sq, fs.Uh, fs.K0, s2,
                    self.speed_prior, logel, mu, sd, _MAX_GAP, *buf)
        self.kc = int(j)
        n = self._n_out
        s_out, lp_out = buf[-2][:n], buf[-1][:n]
        if s_out[0] > 0.0 and s_out[n - 1] > 0.0:  # merged (clipped) candidates, marked -1, sit at the ends only
            cand, lp = s_out.copy(), lp_out.copy()
        else:
            keep = s_out > 0.0
            cand, lp = s_out[keep].copy(), lp_out[keep].copy()
        return cand, lp, int(cand.searchsorted(s))


_MAX_HOPS = 8  # window re-centrings per frame before a full search (each moves the speed by up to exp(spread))

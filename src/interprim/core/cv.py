"""The rules every cross-validation in the package shares, each defined once.

Several parts of the library choose something on held-out parts of the *training* demonstrations:
``sigma^2`` and the shrinkage (:mod:`interprim.models.primitive.selection`), the calibration of the predictive std
(:mod:`interprim.models.primitive.calibration`), the coupling model (:mod:`interprim.models.coupling`), the learned
phase (:mod:`interprim.phase.learned`), the kernel baseline's bandwidth and the evaluation's folds
(:mod:`interprim.evaluation`).  They share four rules, which live here:

* **Folds** (:func:`folds`, :func:`fold_labels`, :func:`n_folds`): which demonstrations are held out
  together.  ``"interleaved"`` puts demonstration ``j`` in fold ``j mod k`` (neighbouring recordings, often
  alike, land in different folds); ``"contiguous"`` cuts ``0 .. n - 1`` into ``k`` runs at
  ``round(i n / k)``; ``"shuffled"`` cuts a seeded permutation into ``k`` runs of sizes differing by at most
  one (the larger first) and sorts each.
* **The paired one-standard-error rule** (:func:`paired_gain`, :func:`within_one_se`): every candidate is
  scored on the same held-out cases, so candidates are compared through the per-case *differences* of their
  errors, whose standard error does not carry the cases' own spread (Hastie, Tibshirani and Friedman, *The
  Elements of Statistical Learning*, Sec. 7.10, the one-standard-error rule, on paired differences).  A simpler
  or more conservative candidate is kept unless the best beats it by more than one such standard error.
* **How much of a demonstration is observed** (:func:`observed_frames`): a held-out demonstration of ``T``
  frames observed at fraction ``p`` shows its first ``round(p T)`` frames, at least 3 (the fewest that give a
  phase, a speed and the derivatives of Eq. 15) and at most ``T`` (or ``T - keep`` when ``keep`` frames must
  remain to be predicted).  :mod:`interprim.model_selection.prefixes` states the evaluation's protocol with it.

Resampling, the fourth shared rule, lives with the other preprocessing
(:func:`interprim.core.preprocessing.interp_columns`, :func:`interprim.core.preprocessing.resample_step`).

Pure numpy, no I/O; part of the core (it imports nothing from :mod:`interprim.evaluation`).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

__all__ = ["DEFAULT_HORIZON", "FOLD_ORDERS", "MIN_OBSERVED_FRAMES", "n_folds", "fold_labels", "folds", "paired_gain",
           "within_one_se", "observed_frames"]

#: Seconds ahead that the real-time protocol scores by default (the real-time band of the default model, the
#: look-ahead the kernel family is tuned for, ``--horizon`` of ``interprim fit`` and ``interprim evaluate``): the
#: one place this default is written.
DEFAULT_HORIZON = 0.25

#: How demonstrations are assigned to folds (see :func:`folds`).
FOLD_ORDERS = ("interleaved", "contiguous", "shuffled")

#: The fewest frames a prefix shows: a phase, a speed and the derivatives of Eq. 15 need three.
MIN_OBSERVED_FRAMES = 3


# ----------------------------------------------------------------------------------------------------- folds
def n_folds(requested: int | None, n: int) -> int:
    """The number of folds used for ``n`` demonstrations when ``requested`` are asked for.

    Parameters
    ----------
    requested : int or None
        Folds asked for; ``None`` means leave-one-out.
    n : int
        Number of demonstrations.

    Returns
    -------
    int
        ``n`` for ``None``, otherwise ``requested`` clipped to ``[2, n]`` (never more folds than
        demonstrations; at least 2 so that something is held out), and ``n`` when ``n < 2``.
    """
    n = int(n)
    if requested is None:
        return n
    return int(min(max(int(requested), 2), n))


def fold_labels(n: int, k: int | None, order: str = "interleaved",
                rng: np.random.Generator | None = None) -> np.ndarray:
    """The fold of each of ``n`` demonstrations, shape ``(n,)``, values ``0 .. k' - 1``.

    Parameters
    ----------
    n : int
        Number of demonstrations.
    k : int or None
        Folds (``None``: leave-one-out); clipped by :func:`n_folds`.
    order : {"interleaved", "contiguous", "shuffled"}
        See :func:`folds`.
    rng : numpy.random.Generator, optional
        Needed by ``"shuffled"``.

    Returns
    -------
    ndarray of int, shape (n,)
        ``labels[j]`` is the fold that holds demonstration ``j`` out.
    """
    labels = np.empty(int(n), dtype=np.intp)
    for f, held in enumerate(folds(n, k, order, rng)):
        labels[held] = f
    return labels


def folds(n: int, k: int | None, order: str = "interleaved",
          rng: np.random.Generator | None = None) -> list[np.ndarray]:
    """Held-out index sets of a ``k``-fold cross-validation over ``n`` demonstrations.

    Every index ``0 .. n - 1`` is in exactly one set; the sets are sorted and the result is deterministic
    (``"shuffled"``: given the state of ``rng``).  With ``k`` ``None`` or ``>= n`` every set holds one
    demonstration (leave-one-out) in every order; ``"shuffled"`` then draws nothing from ``rng``.

    Parameters
    ----------
    n : int
        Number of demonstrations.
    k : int or None
        Folds asked for (``None``: leave-one-out); the number used is :func:`n_folds` (``k`` is clipped to
        ``[2, n]``: a caller that must refuse ``k < 2`` checks it).
    order : {"interleaved", "contiguous", "shuffled"}
        ``"interleaved"``: fold ``f`` holds ``f, f + k, f + 2k, ...``.  ``"contiguous"``: fold ``f`` holds
        ``round(f n / k) .. round((f + 1) n / k) - 1``.  ``"shuffled"``: ``rng.permutation(n)`` cut into ``k``
        runs whose sizes differ by at most one (the first ``n mod k`` one longer), each sorted.
    rng : numpy.random.Generator, optional
        The permutation's generator (``"shuffled"`` only).

    Returns
    -------
    list of ndarray of int
        One sorted index array per fold.

    Raises
    ------
    ValueError
        For an unknown ``order`` or ``"shuffled"`` without ``rng``.
    """
    if order not in FOLD_ORDERS:
        raise ValueError(f"order must be one of {FOLD_ORDERS}, got {order!r}")
    n = int(n)
    K = n_folds(k, n)
    if K >= n:
        return [np.array([j], dtype=np.intp) for j in range(n)]
    if order == "interleaved":
        return [np.arange(f, n, K, dtype=np.intp) for f in range(K)]
    if order == "contiguous":
        edges = np.linspace(0, n, K + 1).round().astype(np.intp)
        return [np.arange(edges[f], edges[f + 1], dtype=np.intp) for f in range(K)]
    if rng is None:
        raise ValueError("order='shuffled' needs rng (a numpy Generator)")
    return [np.sort(f) for f in np.array_split(rng.permutation(n), K)]


# --------------------------------------------------------------------------------- one-standard-error rule
def paired_gain(reference: ArrayLike, candidate: ArrayLike,
                axis: int = 0) -> tuple[float | np.ndarray, float | np.ndarray]:
    """How much ``candidate`` improves on ``reference`` over paired held-out cases, and its standard error.

    Parameters
    ----------
    reference, candidate : array_like
        Errors of two candidates on the same held-out cases (along ``axis``; broadcast against each other).
    axis : int
        The cases' axis.

    Returns
    -------
    gain : float or ndarray
        Mean over the cases of ``reference - candidate`` (positive: the candidate is better).
    se : float or ndarray
        Standard error of that mean: the standard deviation of the per-case differences (``ddof=1``) over the
        square root of the number of cases; ``inf`` with fewer than two cases.
    """
    d = np.asarray(reference, dtype=np.float64) - np.asarray(candidate, dtype=np.float64)
    m = d.shape[axis]
    gain = d.mean(axis=axis)
    if m < 2:
        return gain, np.full(np.shape(gain), np.inf)[()]
    return gain, d.std(axis=axis, ddof=1) / math.sqrt(m)


def within_one_se(errors: ArrayLike) -> np.ndarray:
    """Candidates whose mean error exceeds the best's by at most one paired standard error.

    Parameters
    ----------
    errors : array_like, shape (cases, ...)
        Per-case errors of every candidate (the trailing axes index candidates), all scored on the same
        held-out cases; ``inf`` marks an excluded candidate.

    Returns
    -------
    ndarray of bool, shape ``errors.shape[1:]``
        ``True`` for the best candidate (smallest mean error; the first on ties) and for every finite candidate
        ``c`` whose mean excess over the best, ``mean(errors[:, c] - errors[:, best])``, is at most the standard
        error of those paired differences (:func:`paired_gain`; with a single case there is no standard error and
        every finite candidate is within).
        The one-standard-error rule then picks the simplest or most conservative of them.
    """
    E = np.asarray(errors, dtype=np.float64)
    flat = E.reshape(E.shape[0], -1)
    best = int(np.argmin(flat.mean(axis=0)))
    with np.errstate(invalid="ignore"):  # excluded candidates: inf - finite
        excess, se = paired_gain(flat, flat[:, best][:, None], axis=0)
        ok = (excess <= se) & np.isfinite(flat.mean(axis=0))
    ok[best] = True
    return np.asarray(ok.reshape(E.shape[1:]))


# ------------------------------------------------------------------------------------------- the prefix rule
def observed_frames(T: int, fraction: float, min_frames: int = MIN_OBSERVED_FRAMES, keep: int = 0) -> int:
    """Number of frames of a ``T``-frame demonstration observed at ``fraction`` (in [0, 1]) of it.

    Parameters
    ----------
    T : int
        Frames of the demonstration.
    fraction : float
        Fraction observed.
    min_frames : int
        The fewest frames shown (default 3; a model's ``min_observed`` when larger).
    keep : int
        Frames that must remain unobserved (e.g. 1 when the rest of the movement is scored).

    Returns
    -------
    int
        ``round(fraction T)`` (Python's rounding, halves to even), at least ``min_frames``, at most ``T - keep``
        (the upper bound wins when they cross).
    """
    return int(min(T - keep, max(min_frames, round(fraction * T))))

"""One prediction reply of the server: advance a session's streams by a frame and encode the JSON text.

The CPU-bound part of the server, shared by the event loop, the thread pool
(:mod:`interprim.server.app`) and the worker processes
(:mod:`interprim.server.workers`); it imports nothing from either.
"""

from __future__ import annotations

import logging
import math
import time
import warnings
from dataclasses import dataclass, field

import numpy as np

from ..core.blas import single_thread
from ..core.errors import OutOfRangeWarning
from . import protocol as P

log = logging.getLogger("interprim.server")


@dataclass
class OpenModel:
    """An opened model (or set of candidates) inside a session."""

    name: str  # requested: a model name or "recognise"
    entries: list
    streams: list
    cols: list  # per candidate: data columns returned in mean/std/goal
    points: int
    std: bool
    frames: int = 0
    update_kw: dict = field(default_factory=dict)
    heads: list | None = None  # per candidate: constant parts of the reply (see _head_parts)
    recognition: Recognition | None = None  # with several candidates: which one (created on first use)
    history: list = field(default_factory=list)  # blocks of frames in the streams since the last reset (rollback)

    def reset(self, robot_state=None) -> None:
        """A new interaction: reset every stream (with ``robot_state``) and forget the frames seen."""
        for st in self.streams:
            st.reset(robot_state=robot_state)
        self.frames = 0
        self.history = []
        if self.recognition is not None:
            self.recognition.reset()

    def rollback(self) -> None:
        """Put the streams back in the state they had before the frames that made the model fail: reset them
        (same robot state) and feed them again the frames they had taken before."""
        history = self.history
        for st in self.streams:
            st.reset()
        self.frames = 0
        if self.recognition is not None:
            self.recognition.reset()
        self.history = []
        if history:
            block = np.concatenate(history)
            for st in self.streams:
                st.extend(block, **self.update_kw)
            if self.recognition is not None:
                self.recognition.add(block)
            self.frames = block.shape[0]
            self.history = [block]


MAX_INPUT_DISTANCE = 1e6  # standard deviations from the training frames: a frame further away is refused
MAX_ABS_VALUE = 1e12  # the same for a model that does not know its training range


def frame_problem(op: OpenModel, frame: np.ndarray) -> str | None:
    """Why ``frame`` must not enter ``op``'s streams (``None``: it may): a value so far outside every candidate's
    training frames (over :data:`MAX_INPUT_DISTANCE` standard deviations, or over :data:`MAX_ABS_VALUE` when the
    model does not know its range) that the numerics would overflow.  Frames that are merely out of range
    (``out_of_range`` in the reply) are not refused."""
    for e in op.entries:
        m = e.model
        mean, std = getattr(m, "input_mean_", None), getattr(m, "input_std_", None)
        if mean is not None and std is not None:
            with np.errstate(all="ignore"):
                d = float(np.max(np.abs(frame - mean) / std))
            if not d <= MAX_INPUT_DISTANCE:
                return (f"frame value {float(np.max(np.abs(frame))):.3g} is {d:.3g} standard deviations from model "
                        f"{e.name!r}'s training frames (limit {MAX_INPUT_DISTANCE:g}): refused, the session goes on")
    if not float(np.max(np.abs(frame))) <= MAX_ABS_VALUE:
        return f"frame value {float(np.max(np.abs(frame))):.3g} is over {MAX_ABS_VALUE:g}: refused, the session goes on"
    return None


class Recognition:
    """Which of a ``"recognise"`` session's candidates is being observed:
    :class:`interprim.models.recognition.Recogniser` on the frames of the current interaction.

    Each candidate scores the observed positions at its own most probable phase, with **one** position noise for
    all of them (the Recogniser's ``noise="shared"``): with each model's own noise (a softmax of the predictions'
    ``log_likelihood``) the model with the smallest noise would win by its normalising constant alone.

    Raises
    ------
    TypeError, ValueError, AttributeError
        The Recogniser does not take the candidates (e.g. a model that is not a fitted InteractionPrimitive);
        the server checks this when the session opens ``"recognise"``.
    """

    def __init__(self, entries):
        from ..models.recognition import Recogniser

        self.names = [e.name for e in entries]
        self.rec = Recogniser({e.name: e.model for e in entries})
        self.buf = np.empty((64, entries[0].n_observed))
        self.n = 0

    def reset(self) -> None:
        self.n = 0

    def add(self, frames: np.ndarray) -> None:
        """Frames ``(k, n_observed)`` of the interaction, in order."""
        k = frames.shape[0]
        if self.n + k > self.buf.shape[0]:
            cap = self.buf.shape[0]
            while cap < self.n + k:
                cap *= 2
            buf = np.empty((cap, self.buf.shape[1]))
            buf[: self.n] = self.buf[: self.n]
            self.buf = buf
        self.buf[self.n:self.n + k] = frames
        self.n += k

    def posterior(self, preds) -> tuple[list, int]:
        """``(probabilities in candidate order, index of the most probable)``; uniform (and the first candidate)
        while the predictions are not conditioned (too few frames)."""
        if not all(p.conditioned for p in preds) or self.n < 2:
            return [1.0 / len(preds)] * len(preds), 0
        r = self.rec.recognise(self.buf[: self.n])
        probs = [float(r.probabilities[n]) for n in self.names]
        return probs, self.names.index(r.label)



def warm_up_frames(model, n_observed: int, n: int = 20):
    """``n`` frames inside the model's training range: from its training frames' mean, half a standard deviation
    down to half up per column (zeros around 0.05 for a model file without the range)."""
    rng = getattr(model, "input_range_", None)
    s = np.linspace(-0.5, 0.5, n)[:, None]
    if rng is not None and np.shape(rng[0]) == (n_observed,):
        return np.asarray(rng[0], dtype=np.float64) + s * np.asarray(rng[1], dtype=np.float64)
    return (s + 0.5) * 0.1 * np.ones(n_observed)


def warm_up(entries) -> None:
    """Run one prediction per model so that JIT compilation (numba) happens before the first client."""
    for e in entries:
        try:
            st = e.model.stream()
            ramp = warm_up_frames(e.model, e.n_observed)
            with warnings.catch_warnings():  # no OutOfRangeWarning from the warm-up itself
                warnings.simplefilter("ignore", OutOfRangeWarning)
                for k, f in enumerate(ramp):
                    p = st.update(f, need_cov=k % 2 == 1)
            p.trajectory(5)
            p.std(5)
        except Exception:  # a model that cannot predict from zeros will say so to its first client
            log.debug("warm-up of %s failed", e.name, exc_info=True)


_FMT_CACHE: dict = {}
_NONFINITE = "the model produced non-finite values for this frame"


try:  # optional accelerator: numpy arrays to JSON in compiled code
    import orjson as _orjson
except ImportError:  # pragma: no cover - depends on the installation
    _orjson = None  # type: ignore[assignment]  # the module or None, tested before each use


def _json_array(a) -> str:
    """A 1-D or 2-D float array as JSON text, about 7 significant digits.

    With :mod:`orjson` installed: the array rounded to float32 and written with the shortest text
    that reads back to the same float32 (relative error <= 1.2e-7 once parsed as float64; ~6 us for 50 x 3 values).
    Without: ``%.7g`` (relative error <= 5e-7; one %-format for the whole array, ~30 us, still about twice as
    fast as ``json.dumps(a.tolist())``).  Raises ``FloatingPointError`` on NaN/inf, which are not
    JSON (and on values beyond the float32 range with orjson).
    """
    if _orjson is not None and not _FORCE_PRINTF:
        out = _orjson.dumps(np.asarray(a).astype(np.float32, order="C"), option=_orjson.OPT_SERIALIZE_NUMPY)
        # orjson writes NaN/inf as null; numbers are digits, ".", "e", "+", "-" only
        if b"l" in out:
            raise FloatingPointError(_NONFINITE)
        return out.decode()
    a = np.asarray(a, dtype=np.float64)
    key = a.shape
    fmt = _FMT_CACHE.get(key)
    if fmt is None:
        if a.ndim == 1:
            fmt = "[" + ",".join(["%.7g"] * a.shape[0]) + "]"
        else:
            row = "[" + ",".join(["%.7g"] * a.shape[1]) + "]"
            fmt = "[" + ",".join([row] * a.shape[0]) + "]"
        if len(_FMT_CACHE) < 256:
            _FMT_CACHE[key] = fmt
    text = fmt % tuple(a.ravel().tolist())
    # "%.7g" writes NaN/inf as nan/inf/-inf; finite numbers never contain an "n" (a scan of the
    # text is cheaper than np.isfinite on the array)
    if "n" in text:
        raise FloatingPointError(_NONFINITE)
    return text


_FORCE_PRINTF = False  # tests: the fallback encoder even when orjson is installed


_HEAD_FMT = '"phase":%r,"x":%s,"speed":%r,"duration":%r,"log_likelihood":%s,'
_UNCONDITIONED = '"phase":null,"x":null,"speed":null,"duration":null,"log_likelihood":null,"conditioned":false,'


def _num(v: float) -> str:
    """A finite float as JSON (``repr``, as ``%r`` writes it), NaN as ``null``."""
    return "null" if v != v else repr(v)


def _head_parts(op: OpenModel) -> list:
    """Per candidate: the constant JSON of a prediction's head (model name, columns), encoded once per open."""
    parts = op.heads
    if parts is None:
        parts = op.heads = [
            (',"model":%s,' % P.dumps(e.name), '"columns":%s' % P.dumps(cols),
             _column_slice(cols, e.n_dofs), _MeanRollout(op.points, _column_slice(cols, e.n_dofs)))
            for e, cols in zip(op.entries, op.cols)
        ]
    return parts


def _column_slice(cols, n_dofs):
    """``cols`` as a slice when contiguous (a view instead of a fancy-indexing copy)."""
    if cols and list(cols) == list(range(cols[0], cols[0] + len(cols))):
        return slice(cols[0], cols[0] + len(cols))
    return list(cols)


class _MeanRollout:
    """``pred.trajectory(n)[:, cols]`` for the predictions of one model: the prediction contract's
    :meth:`~interprim.models.base.BasePrediction.mean_rollout`, made from the first prediction (for an
    Interaction Primitive the core's :class:`~interprim.models.primitive.prediction.MeanRollout`, the grid's design
    built once).
    """

    __slots__ = ("n", "sel", "fn")

    def __init__(self, n: int, sel):
        self.n, self.sel, self.fn = n, sel, None

    def mean(self, pred) -> np.ndarray:
        fn = self.fn
        if fn is None:
            fn = self.fn = pred.mean_rollout(self.n, self.sel)
        return fn(pred)


def compute_prediction(op: OpenModel, frame: np.ndarray, seq: int, t, covers: int = 1, t0: float | None = None,
                       block: np.ndarray | None = None) -> str:
    """Advance every stream of ``op`` by ``frame`` and encode the ``prediction`` reply (CPU-bound).

    ``covers``: frames this reply answers, ``seq - covers + 1 .. seq``; with ``block`` (all ``covers`` frames,
    ``(covers, n_observed)``, the last one ``frame``) they enter the streams in one ``stream.extend(block)``
    (see :func:`compute_batch`); ``t0``:
    start of their computation (``compute_ms`` counts from there).  The reply is built as text directly
    (same keys, order and number formats as ``P.dumps`` of the message would give): encoding a dict with
    :mod:`json` costs more than the rest of the reply.
    """
    if t0 is None:
        t0 = time.perf_counter()
    update_kw = op.update_kw
    if block is not None:
        preds = [st.extend(block, **update_kw) for st in op.streams]
        op.frames += block.shape[0]
    elif len(op.streams) == 1:
        preds = [op.streams[0].update(frame, **update_kw)]
        op.frames += 1
    else:
        preds = [st.update(frame, **update_kw) for st in op.streams]
        op.frames += 1
    probs = None
    best = 0
    if len(preds) > 1:
        rec = _recognition(op)
        rec.add(block if block is not None else np.asarray(frame, dtype=np.float64)[None])
        probs, best = rec.posterior(preds)
    pred = preds[best]
    model_part, cols_part, sel, rollout = _head_parts(op)[best]
    if pred.conditioned:  # every prediction has the attributes of interprim.models.base.BasePrediction
        vals = (float(pred.phase), float(pred.speed), float(pred.duration))
        if not all(map(math.isfinite, vals)):  # nan / inf: never put them on the wire
            raise FloatingPointError(_NONFINITE)
        # x (a DMP's canonical phase) and the likelihood: null for a model that has none (e.g. a blend)
        x, ll = float(pred.x), float(pred.log_likelihood)
        if math.isinf(x) or math.isinf(ll):
            raise FloatingPointError(_NONFINITE)
        nums = _HEAD_FMT % (vals[0], _num(x), vals[1], vals[2], _num(ll)) + '"conditioned":true,'
    else:  # the prior (too few frames): no phase, speed or likelihood to report
        nums = _UNCONDITIONED
    nums += '"frames":%d,' % pred.n_observed
    parts = ['{"type":"prediction","seq":%d,"covers":%d,"first_seq":%d' % (seq, covers, seq - covers + 1),
             model_part, nums, cols_part]
    # "type", "seq", "covers", "first_seq" first: clients may read them without a full parse
    if probs is not None:
        parts.append(',"probabilities":' + P.dumps({e.name: round(p, 6) for e, p in zip(op.entries, probs)}))
    if t is not None:
        parts.append(',"t":' + P.dumps(t))
    parts += [
        ',"mean":', _json_array(rollout.mean(pred)),
        ',"goal":', _json_array(np.asarray(pred.goal)[sel]),
    ]
    if op.std:
        parts += [',"std":', _json_array(np.asarray(pred.std(op.points))[:, sel])]
    # input far outside the training demonstrations (wrong units, columns, frame of reference): the flag and
    # the largest standardised distance seen since the session's last reset (null for an old model file)
    dist = float(pred.input_distance)
    parts.append(',"out_of_range":%s,"input_distance":%s,"duration_out_of_range":%s' % (
        "true" if pred.out_of_range else "false",
        ("%.6g" % dist) if math.isfinite(dist) else ("1e308" if dist > 0 else "null"),
        "true" if getattr(pred, "duration_out_of_range", False) else "false"))
    parts.append(',"compute_ms":%.4f}' % ((time.perf_counter() - t0) * 1e3))
    return "".join(parts)


def _recognition(op: OpenModel) -> Recognition:
    rec = op.recognition
    if rec is None:
        rec = op.recognition = Recognition(op.entries)
    return rec


def compute_batch(op: OpenModel, batch) -> tuple[list, list]:
    """Feed a session's pending frames ``batch`` (a list of ``(frame, seq, t)``, seqs consecutive) to its
    streams in order and encode **one** reply for the newest: a ``prediction`` with ``covers = len(batch)``.

    Every frame enters the streams (phase estimation and conditioning see all of them): several frames in
    one :meth:`~interprim.models.base.BaseStream.extend` per stream, which every model's stream has and which
    answers exactly what :meth:`~interprim.models.base.BaseStream.update` answers for the last frame (the
    per-frame cost of an IP's stream is then the DTW column and the phase tracker's lattice step only; the
    phase, conditioning and prediction are computed once).  So the reply is the one the last frame would get
    had each frame been answered.  If the model fails, one ``internal`` error with the newest frame's
    ``seq`` and ``t`` answers the whole batch (``covers`` all its frames).  Returns ``(texts, failures)``:
    the reply texts in ``seq`` order (one), and ``(seq, traceback text)`` per failure (for the server's log).

    The whole turn runs on one BLAS thread (:func:`interprim.core.blas.single_thread`): the reply's rollout and
    band included, so that no BLAS pool wakes a second thread (whose spinning would take the other core from the
    rest of the machine) and the turn enters the limiter once.
    """
    with single_thread():
        return _compute_batch(op, batch)


def _compute_batch(op: OpenModel, batch) -> tuple[list, list]:
    t0 = time.perf_counter()
    problems = [frame_problem(op, f) for f, _, _ in batch]
    if not any(problems):
        return _compute_run(op, batch, t0)
    # A frame that would break the numerics is answered with bad_frame and never enters the streams; the runs of
    # good frames around it get their own replies (the replies stay in seq order, each covering its run).
    texts, failures, run = [], [], []
    for item, problem in zip(batch, problems):
        if problem is None:
            run.append(item)
            continue
        if run:
            tx, fl = _compute_run(op, run, t0)
            texts += tx
            failures += fl
            run = []
        texts.append(P.dumps(P.error("bad_frame", problem, seq=item[1], t=item[2])))
        failures.append((item[1], None))  # None: an answer of its own, not a failure to log with a traceback
    if run:
        tx, fl = _compute_run(op, run, t0)
        texts += tx
        failures += fl
    return texts, failures


def _compute_run(op: OpenModel, batch, t0) -> tuple[list, list]:
    """One reply for the frames of ``batch``; if the model fails, an ``internal`` error for them and the streams
    rolled back to before them (:meth:`OpenModel.rollback`), so that the next frames are answered normally."""
    import traceback

    frame, seq, t = batch[-1]
    n = len(batch)
    try:
        block = np.stack([f for f, _, _ in batch]) if n > 1 else None
        text = compute_prediction(op, frame, seq, t, covers=n, t0=t0, block=block)
        op.history.append(block if block is not None else frame[None])
        if len(op.history) > 256:  # one array, not thousands of small ones
            op.history = [np.concatenate(op.history)]
        return [text], []
    except Exception as exc:
        detail = traceback.format_exc()
        try:
            op.rollback()
        except Exception:  # the model fails on frames it took before: start the interaction afresh
            detail += "\n(rollback failed: the session's streams were reset)\n" + traceback.format_exc()
            op.reset()
        extra = {"covers": n, "first_seq": seq - n + 1} if n > 1 else {}
        text = P.dumps(P.error("internal", f"prediction failed: {type(exc).__name__}: {exc}; these frames were "
                                           "left out, the session goes on", seq=seq, t=t, **extra))
        return [text], [(seq, detail)]

"""The server under overload: frames a session sends faster than it is served are coalesced.

Every frame enters the session's streams, but a session that is behind gets one reply for all the
frames it sent since its previous reply, with ``covers`` / ``first_seq`` saying which.  Checked here:
every seq is answered exactly once and in order (by a prediction that covers it or by an error),
every session is served (round robin), and the coalesced reply is the one the newest frame would have
got had every frame been answered.  The overload is made by a test hook, a model whose step waits at a
gate the test opens (no timing assertions; latency is measured by benchmarks/load_server.py).
"""

from __future__ import annotations

import json
import threading

import numpy as np
import pytest

from interprim.models.base import BasePrediction, BaseStream

pytest.importorskip("websockets")

from _server_support import (  # noqa: E402,F401  (fixtures and helpers)
    covered,
    frame_msg,
    models,
    opened,
    replies_until,
    test_demo,
    wait_until,
)

from interprim.server import compute  # noqa: E402
from interprim.server.app import InterprimServer, ServerConfig, ServerThread  # noqa: E402
from interprim.server.client import Client  # noqa: E402
from interprim.server.models import entry_for  # noqa: E402

VOLATILE = ("compute_ms", "covers", "first_seq")  # what may differ between a coalesced reply and a per-frame one


def _same(reply: dict) -> dict:
    return {k: v for k, v in reply.items() if k not in VOLATILE}


def _assert_close(a, b, where="reply"):
    """Same keys, same strings/booleans/None, the same numbers: a coalesced batch enters the streams with one
    Stream.extend, whose answer is update's for the last frame exactly (tests/models/test_stream_extend.py)."""
    if isinstance(a, dict):
        assert isinstance(b, dict) and sorted(a) == sorted(b), where
        for k in a:
            _assert_close(a[k], b[k], f"{where}.{k}")
    elif isinstance(a, list):
        assert isinstance(b, list) and len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b)):
            _assert_close(x, y, f"{where}[{i}]")
    else:
        assert a == b, where


# ---------------------------------------------------------------------------- compute_batch
def _open(models, names, std, points=12):
    entries = [models[n] for n in names]
    streams = [e.model.stream() for e in entries]
    cols = [e.controlled_dofs if e.controlled_dofs else list(range(e.n_dofs)) for e in entries]
    op = compute.OpenModel(names[0] if len(names) == 1 else "recognise", entries, streams, cols, points, std)
    op.update_kw = {"need_cov": std}
    return op


@pytest.mark.parametrize("names,std", [(["pair"], False), (["pair"], True), (["pair", "letter_c"], False)],
                         ids=["mean", "std-band", "auto"])
def test_coalesced_batch_gives_the_reply_of_its_newest_frame(models, test_demo, names, std):
    """Feeding frames j..k and replying once gives the reply frame k gets when every frame is answered (the same
    fields and values but for compute_ms/covers/first_seq), and the streams go on from the same state."""
    frames = test_demo[:60, :2]
    one = _open(models, names, std)
    per_frame = [json.loads(compute.compute_batch(one, [(f, k + 1, float(k))])[0][0]) for k, f in enumerate(frames)]
    assert all(r["covers"] == 1 and r["first_seq"] == r["seq"] for r in per_frame)
    many = _open(models, names, std)
    start = 0
    for size in (1, 2, 7, 3, 13, 1, 20, 13):  # batches of several sizes, 60 frames
        batch = [(frames[k], k + 1, float(k)) for k in range(start, start + size)]
        texts, failures = compute.compute_batch(many, batch)
        assert failures == [] and len(texts) == 1
        r = json.loads(texts[0])
        assert r["type"] == "prediction" and r["seq"] == start + size and r["covers"] == size
        assert r["first_seq"] == start + 1 and r["t"] == float(start + size - 1)  # t: the newest frame's echo
        _assert_close(_same(r), _same(per_frame[start + size - 1]))  # the same prediction
        start += size
    assert start == len(frames) and many.frames == one.frames == len(frames)


class _Boom(BaseStream):
    """A stand-in model (its own stream) whose ``update`` fails on frames with a first value above 100 (a model
    bug); ``extend`` is the contract's default, ``update`` frame by frame."""

    observed_dofs_, controlled_dofs_, n_dofs_, dt_, mean_duration_ = [0, 1], [2], 3, 0.01, 1.0

    def __init__(self):
        self.n = 0

    @property
    def n_frames(self) -> int:
        return self.n

    def stream(self, robot_state=None):
        return self

    def update(self, frame, need_cov=False):
        if frame[0] > 100:
            raise RuntimeError("kaboom")
        self.n += 1
        fields = {"phase": 0.5, "x": 1, "speed": 1, "duration": 1, "log_likelihood": 0, "goal": np.zeros(3),
                  "trajectory": lambda self, n: np.zeros((n, 3))}
        return type("Pred", (BasePrediction,), fields)()

    def reset(self, robot_state=None):
        self.n = 0


def test_a_failing_frame_fails_its_batch_with_one_error_that_covers_it():
    """A batch enters the stream with one ``extend`` (here the contract's default, update per frame): when the model
    fails on one of its frames, one internal error with the newest frame's seq answers every frame of the batch,
    and the next batch goes on."""
    model = _Boom()
    e = entry_for("boom", model)
    op = compute.OpenModel("boom", [e], [model], [[2]], 4, False)
    frames = [[1.0, 0.0], [2.0, 0.0], [200.0, 0.0], [3.0, 0.0], [4.0, 0.0], [5.0, 0.0]]
    texts, failures = compute.compute_batch(op, [(np.array(f), k + 1, None) for k, f in enumerate(frames)])
    assert len(texts) == 1
    r = json.loads(texts[0])
    assert (r["type"], r["code"], r["seq"], r["covers"], r["first_seq"]) == ("error", "internal", 6, 6, 1)
    assert "kaboom" in r["message"] and covered(r) == [1, 2, 3, 4, 5, 6]
    assert [seq for seq, _ in failures] == [6] and "RuntimeError: kaboom" in failures[0][1]
    texts, failures = compute.compute_batch(op, [(np.array([6.0, 0.0]), 7, 0.25), (np.array([7.0, 0.0]), 8, 0.5)])
    r = json.loads(texts[0])
    assert failures == [] and (r["type"], r["seq"], r["covers"], r["first_seq"], r["t"]) == ("prediction", 8, 2, 7, 0.5)
    texts, failures = compute.compute_batch(op, [(np.array([300.0, 0.0]), 9, 1.5)])  # one frame: update
    r = json.loads(texts[0])
    assert (r["type"], r["code"], r["seq"], r["t"]) == ("error", "internal", 9, 1.5) and "covers" not in r


class _BoomExtend(_Boom):
    """As :class:`_Boom`, with its own ``extend`` (as Stream has): it fails when any of its frames is above 100."""

    def __init__(self):
        super().__init__()
        self.calls = []

    def extend(self, frames, need_cov=False):
        self.calls.append(len(frames))
        for f in frames[:-1]:
            if f[0] > 100:
                raise RuntimeError("kaboom")
        return self.update(frames[-1])


def test_a_batch_enters_with_one_extend_and_a_failure_answers_all_its_frames():
    """A coalesced batch enters each stream in one extend call; when it fails, one internal error covers the batch
    (its seq is the newest frame's, with covers/first_seq and the newest frame's t), and the session goes on."""
    model = _BoomExtend()
    e = entry_for("boom", model)
    op = compute.OpenModel("boom", [e], [model], [[2]], 4, False)
    ok = [(np.array([1.0, 0.0]), 1, None), (np.array([2.0, 0.0]), 2, 0.5)]
    texts, failures = compute.compute_batch(op, ok)
    assert failures == [] and model.calls == [2]
    r = json.loads(texts[0])
    assert (r["type"], r["seq"], r["covers"], r["first_seq"], r["t"]) == ("prediction", 2, 2, 1, 0.5)
    bad = [(np.array([1.0, 0.0]), 3, None), (np.array([200.0, 0.0]), 4, None), (np.array([3.0, 0.0]), 5, 7.0)]
    texts, failures = compute.compute_batch(op, bad)
    assert len(texts) == 1 and [q for q, _ in failures] == [5] and "RuntimeError: kaboom" in failures[0][1]
    r = json.loads(texts[0])
    assert (r["type"], r["code"], r["seq"], r["covers"], r["first_seq"], r["t"]) == ("error", "internal", 5, 3, 3, 7.0)
    assert covered(r) == [3, 4, 5] and "kaboom" in r["message"]
    texts, failures = compute.compute_batch(op, [(np.array([4.0, 0.0]), 6, None)])  # one frame: update
    # [2, 3, 2]: the failed batch was rolled back (the streams reset and fed again the 2 frames taken before it)
    assert failures == [] and json.loads(texts[0])["seq"] == 6 and model.calls == [2, 3, 2]


# ---------------------------------------------------------------------------- a real server, overloaded
class Gate:
    """Test hook: while closed, the model's step waits here (a model step as slow as the test wants)."""

    def __init__(self):
        self.opened = threading.Event()
        self.opened.set()
        self.entered = threading.Event()

    def close(self):
        self.entered.clear()
        self.opened.clear()

    def wait(self):
        if not self.opened.is_set():
            self.entered.set()
            assert self.opened.wait(120), "the test never opened the gate"


class GatedModel:
    """A fitted model whose streams' ``update`` passes through ``gate`` first."""

    def __init__(self, model, gate: Gate):
        self._model, self._gate = model, gate

    def __getattr__(self, name):
        return getattr(self._model, name)

    def stream(self, robot_state=None):
        return _GatedStream(self._model.stream(robot_state=robot_state), self._gate)


class _GatedStream(BaseStream):
    def __init__(self, stream, gate):
        self._stream, self._gate = stream, gate

    @property
    def n_frames(self) -> int:
        return self._stream.n_frames

    def update(self, frame, need_cov: bool = False):
        self._gate.wait()
        return self._stream.update(frame, need_cov=need_cov)

    def extend(self, frames, need_cov: bool = False):
        self._gate.wait()
        return self._stream.extend(frames, need_cov=need_cov)

    def reset(self, robot_state=None):
        self._stream.reset(robot_state=robot_state)


@pytest.fixture
def gate():
    g = Gate()
    yield g
    g.opened.set()  # never leave a server thread waiting


def _gated_server(models, gate, **cfg):
    ms = {n: entry_for(n, GatedModel(models[n].model, gate), kind=models[n].kind) for n in ("pair", "letter_c")}
    return InterprimServer(ms, ServerConfig(port=0, max_rate_hz=100000, rate_burst=100000, **cfg))


# the sessions of the overload tests: (open options, frame offset)
SESSIONS = [
    ({"model": "pair", "points": 10}, 0.0),
    ({"model": "pair", "points": 10, "std": True}, 0.01),
    ({"model": "recognise", "candidates": ["pair", "letter_c"], "points": 8}, 0.02),
    ({"model": "pair", "points": 10}, -0.01),
]
N_FRAMES = 40


def _frames(test_demo, offset):
    return test_demo[:N_FRAMES, :2] + offset


def _reference_replies(url, test_demo):
    """The last reply of each session's frames when every frame is answered (one frame at a time)."""
    out = []
    for options, offset in SESSIONS:
        with Client(url) as c:
            c.open(**options)
            for f in _frames(test_demo, offset):
                r = c.frame(f)
                assert r["covers"] == 1
            out.append(r)
    return out


def _check_replies(replies, n_frames):
    """Every frame answered once, in seq order; covers add up to the frames sent."""
    assert [q for r in replies for q in covered(r)] == list(range(1, n_frames + 1))
    assert sum(r.get("covers", 1) for r in replies) == n_frames
    for r in replies:
        if r["type"] == "prediction":
            assert r["covers"] == r["seq"] - r["first_seq"] + 1 >= 1


@pytest.mark.parametrize("mode", ["threads", "inline"])
def test_overloaded_sessions_get_coalesced_replies(models, test_demo, gate, mode):
    """Four sessions send 40 frames each while the model's step is stuck; once it is released, each session
    gets replies that cover every frame (no starvation, no frame lost) and whose last one equals the reply of
    the same frames answered one by one."""
    srv = _gated_server(models, gate, workers=1 if mode == "threads" else 0)
    with ServerThread(srv) as st:
        conns = [opened(st.ws_url, **options) for options, _ in SESSIONS]
        try:
            gate.close()
            conns[0].send(frame_msg(_frames(test_demo, SESSIONS[0][1])[0]))
            assert gate.entered.wait(60)  # the server is inside session 1's first step
            for k, (ws, (_, offset)) in enumerate(zip(conns, SESSIONS)):
                for f in _frames(test_demo, offset)[1 if k == 0 else 0:]:
                    ws.send(frame_msg(f))
            if mode == "threads":  # the loop is free: it reads every frame into its session's pending list
                pending = lambda: st.call(lambda: sorted(len(s.pending) for s in st.server.sessions.values()))  # noqa: E731
                # sessions 1 and 2 have a first batch of one frame in flight (two batches per lane), 3 and 4 wait
                assert wait_until(lambda: pending() == [N_FRAMES - 1] * 2 + [N_FRAMES] * 2)
            gate.opened.set()
            replies = [replies_until(ws, N_FRAMES, timeout=60) for ws in conns]
        finally:
            for ws in conns:
                ws.close()
        reference = _reference_replies(st.ws_url, test_demo)
        stats = st.call(lambda: dict(st.server.stats))
    for rs, ref in zip(replies, reference):
        _check_replies(rs, N_FRAMES)
        assert all(r["type"] == "prediction" for r in rs)
        _assert_close(_same(rs[-1]), _same(ref))  # coalesced == uncoalesced (numbers to 1e-5)
    coalesced = sum(N_FRAMES - len(rs) for rs in replies)
    assert coalesced > 0 and stats["coalesced"] >= coalesced
    if mode == "threads":  # deterministic turns: sessions 1 and 2's first frames, then one turn each, round robin
        expected = [[1, N_FRAMES - 1], [1, N_FRAMES - 1], [N_FRAMES], [N_FRAMES]]
        assert [[r["covers"] for r in rs] for rs in replies] == expected


def test_errors_keep_their_place_among_coalesced_replies(models, test_demo, gate):
    """A bad frame's error comes after the replies to the frames sent before it, and before those after it."""
    srv = _gated_server(models, gate, workers=1)
    frames = _frames(test_demo, 0.0)[:20]
    with ServerThread(srv) as st:
        ws = opened(st.ws_url, model="pair", points=6)
        try:
            gate.close()
            ws.send(frame_msg(frames[0]))
            assert gate.entered.wait(60)
            for f in frames[1:10]:
                ws.send(frame_msg(f))
            ws.send(json.dumps({"type": "frame", "frame": [1.0, 2.0, 3.0]}))  # seq 11: wrong length
            for f in frames[10:]:
                ws.send(frame_msg(f))
            gate.opened.set()
            replies = replies_until(ws, 21, timeout=60)
        finally:
            ws.close()
    _check_replies(replies, 21)
    kinds = [(r["type"], r["seq"]) for r in replies]
    assert kinds[:3] == [("prediction", 1), ("prediction", 10), ("error", 11)]
    assert replies[1]["covers"] == 9 and replies[2]["code"] == "bad_frame"
    assert kinds[-1] == ("prediction", 21)


def test_a_session_far_behind_is_no_longer_read(models, test_demo, gate):
    """With max_pending frames waiting, the server stops reading the session (TCP flow control slows the
    client down) instead of buffering without bound; the frames are all answered once it catches up."""
    srv = _gated_server(models, gate, workers=1, max_pending=4)
    frames = _frames(test_demo, 0.0)[:30]
    with ServerThread(srv) as st:
        ws = opened(st.ws_url, model="pair", points=6)
        try:
            gate.close()
            ws.send(frame_msg(frames[0]))
            assert gate.entered.wait(60)
            for f in frames[1:]:
                ws.send(frame_msg(f))
            state = lambda: st.call(lambda: [(len(s.pending), s.seq) for s in st.server.sessions.values()])  # noqa: E731
            assert wait_until(lambda: state() == [(4, 5)])  # frame 1 computing, 2-5 pending, 6-30 not read
            gate.opened.set()
            replies = replies_until(ws, 30, timeout=60)
        finally:
            ws.close()
    _check_replies(replies, 30)
    assert replies[1]["covers"] == 4  # frames 2-5 in one reply


@pytest.mark.slow  # starts worker processes
def test_worker_processes_coalesce_too(models, test_demo):
    """--processes: a session's pending frames go to its worker in one request; same guarantees."""
    srv = InterprimServer({"pair": models["pair"], "letter_c": models["letter_c"]},
                          ServerConfig(port=0, processes=2, max_rate_hz=100000, rate_burst=100000))
    with ServerThread(srv) as st:
        conns = [opened(st.ws_url, **options) for options, _ in SESSIONS]
        try:
            for ws, (_, offset) in zip(conns, SESSIONS):  # pipelined: all frames, then read
                for f in _frames(test_demo, offset):
                    ws.send(frame_msg(f))
            replies = [replies_until(ws, N_FRAMES, timeout=60) for ws in conns]
        finally:
            for ws in conns:
                ws.close()
        reference = _reference_replies(st.ws_url, test_demo)
    for rs, ref in zip(replies, reference):
        _check_replies(rs, N_FRAMES)
        _assert_close(_same(rs[-1]), _same(ref))

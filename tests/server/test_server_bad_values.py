"""A bad value fails one frame, not the session (issue 30, finding 6): after ``[1e50, 0.2]`` every later frame
got ``internal`` until ``reset``, with a full traceback logged per frame."""

from __future__ import annotations

import json
import logging

import numpy as np
import pytest

pytest.importorskip("websockets")

from _server_support import frame_msg, models, opened, rpc, test_demo  # noqa: E402,F401

from interprim.server import compute  # noqa: E402
from interprim.server.app import InterprimServer, ServerConfig, ServerThread  # noqa: E402


@pytest.fixture
def fresh(models):
    cfg = ServerConfig(port=0, max_rate_hz=1e5, rate_burst=10**5)
    with ServerThread(InterprimServer({"pair": models["pair"]}, cfg)) as st:
        yield st


def test_huge_finite_value_fails_that_frame_only(fresh, test_demo):
    ws = opened(fresh.ws_url)
    clean = opened(fresh.ws_url)
    try:
        good = [test_demo[i, :2] for i in range(30)]
        for f in good[:3]:
            assert rpc(ws, frame_msg(f))["type"] == "prediction"
        r = rpc(ws, frame_msg([1e50, 0.2]))
        assert r["type"] == "error" and r["code"] == "bad_frame" and r["seq"] == 4, r
        assert "standard deviations" in r["message"] and "session goes on" in r["message"]
        after = [rpc(ws, frame_msg(f)) for f in good[3:]]
        assert [a["type"] for a in after] == ["prediction"] * 27, [a.get("code") for a in after]
        # the state is as if the bad frame had never come: same answer as a session that never saw it
        ref = [rpc(clean, frame_msg(f)) for f in good][-1]
        np.testing.assert_allclose(after[-1]["mean"], ref["mean"], rtol=1e-6, atol=1e-9)
        assert after[-1]["phase"] == pytest.approx(ref["phase"], rel=1e-6)
    finally:
        ws.close()
        clean.close()


def test_bad_value_inside_a_coalesced_batch(fresh, test_demo):
    """Sent in one go (answered in turns covering several frames): the bad frame gets its own error, the frames
    around it are answered, in seq order."""
    ws = opened(fresh.ws_url)
    try:
        msgs = [frame_msg(test_demo[i, :2]) for i in range(10)]
        msgs[5] = frame_msg([-1e300, 0.0])
        for m in msgs:
            ws.send(m)
        got = []
        while not got or got[-1]["seq"] < 10:
            got.append(json.loads(ws.recv(timeout=10)))
        covered = []
        for r in got:
            covered += list(range(r.get("first_seq", r["seq"]), r["seq"] + 1))
        assert covered == list(range(1, 11)), got
        bad = [r for r in got if r["type"] == "error"]
        assert [(r["code"], r["seq"]) for r in bad] == [("bad_frame", 6)]
        assert rpc(ws, frame_msg(test_demo[10, :2]))["type"] == "prediction"
    finally:
        ws.close()


def test_model_failure_rolls_back_and_logs_are_rate_limited(fresh, test_demo, monkeypatch, caplog):
    """A frame the model fails on (here: made to fail) gets ``internal``; the session's streams are rolled back so
    the next frames are answered; repeated failures log one traceback per session and at most 10 lines / 10 s."""
    real = compute.compute_prediction

    def failing(op, frame, *a, **kw):
        if frame[0] == 7.0:
            op.streams[0].extend(frame[None] * 1e200, **op.update_kw)  # poison the stream, then fail
            raise FloatingPointError("made to fail")
        return real(op, frame, *a, **kw)

    monkeypatch.setattr(compute, "compute_prediction", failing)
    ws = opened(fresh.ws_url)
    clean = opened(fresh.ws_url)
    caplog.set_level(logging.WARNING, logger="interprim.server")
    try:
        good = [test_demo[i, :2] for i in range(20)]
        for f in good[:5]:
            rpc(ws, frame_msg(f))
        codes = [rpc(ws, frame_msg([7.0, 0.1])).get("code") for _ in range(60)]
        assert codes == ["internal"] * 60
        after = [rpc(ws, frame_msg(f)) for f in good[5:]]
        assert [a["type"] for a in after] == ["prediction"] * 15
        ref = [rpc(clean, frame_msg(f)) for f in good][-1]
        np.testing.assert_allclose(after[-1]["mean"], ref["mean"], rtol=1e-6, atol=1e-9)
    finally:
        ws.close()
        clean.close()
    failed = [r for r in caplog.records if "prediction failed" in r.getMessage()]
    assert 1 <= len(failed) <= 11, len(failed)
    assert sum("Traceback" in r.getMessage() for r in failed) == 1

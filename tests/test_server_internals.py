"""The streaming server's internals against real clients: worker processes, the async client, fair
queueing of the compute lanes, reply encoding and event-loop choice.  No timing assertions."""

from __future__ import annotations

import json
import logging
import socket
import time

import numpy as np
import pytest

pytest.importorskip("websockets")

from interprim.server.app import InterprimServer, ServerConfig, ServerThread  # noqa: E402
from interprim.server.client import Client, ServerError  # noqa: E402

from _server_support import models, n_sessions, server, test_demo, wait_until  # noqa: E402,F401  (fixtures and helpers)


def test_worker_processes_give_the_same_predictions(models, test_demo):
    srv = InterprimServer({"pair": models["pair"], "letter_c": models["letter_c"]},
                          ServerConfig(port=0, processes=2, max_rate_hz=100000, rate_burst=100000))
    with ServerThread(srv) as st:
        assert len(st.server._procs.workers) == 2
        with Client(st.ws_url) as a, Client(st.ws_url) as b:  # consecutive session ids: different workers
            a.open("pair", points=10, std=True)
            b.open("pair", points=10)
            da, db = models["pair"].model.stream(), models["pair"].model.stream()
            for k, f in enumerate(test_demo[:30, :2]):
                pa, pb = a.frame(f), b.frame(f, binary=True)
                ea, eb = da.update(f), db.update(f)
                np.testing.assert_allclose(pa["mean"], ea.trajectory(10)[:, 2:], atol=2e-6)
                np.testing.assert_allclose(pa["std"], ea.std(10)[:, 2:], atol=2e-6)
                np.testing.assert_allclose(pb["mean"], eb.trajectory(10)[:, 2:], atol=2e-6)
                if k == 10:
                    rs = [[0.1, -0.2, 0.3], [0.5, 0.0, -0.5]]  # positions and velocities, in the worker too
                    b.reset(robot_state=rs)
                    db = models["pair"].model.stream(robot_state=rs)
            with pytest.raises(ServerError) as e:
                a.frame([1.0])
            assert e.value.code == "bad_frame"
            a.close_session()
            with pytest.raises(ServerError) as e:
                a.frame(test_demo[0, :2])
            assert e.value.code == "not_open"
            a.open("letter_c", points=5)
            assert a.frame([0.5, 0.5])["model"] == "letter_c"
        assert wait_until(lambda: n_sessions(st) == 0)


def test_async_client_pipelines_frames(server, models, test_demo):
    import asyncio

    from interprim.server.client import AsyncClient

    async def go():
        c = await AsyncClient.connect(server.ws_url)
        async with c:
            assert c.welcome["type"] == "welcome"
            await c.open("pair", points=8)
            for f in test_demo[:20, :2]:  # pipelined: send all, then read all
                await c.send_frame(f, binary=True)
            replies = [await c.recv() for _ in range(20)]
            await c.send_frame([1.0, 2.0, 3.0])
            err = await c.recv_raw()
            return replies, err

    replies, err = asyncio.run(go())
    assert [r["seq"] for r in replies] == list(range(1, 21))
    direct = models["pair"].model.stream()
    for f in test_demo[:20, :2]:
        d = direct.update(f)
    np.testing.assert_allclose(replies[-1]["mean"], d.trajectory(8)[:, 2:], atol=2e-6)
    assert err["type"] == "error" and err["code"] == "bad_frame" and err["seq"] == 21


def test_fair_queueing_serves_the_cheaper_session_first():
    """The scheduler of a compute lane: among waiting frames, the session that used less compute goes first."""
    import asyncio

    from interprim.server.lanes import _Lane, _Session

    order = []

    async def run(job):
        name, cost = job
        order.append(name)
        time.sleep(cost)  # compute time charged to the session
        return name

    async def go():
        lane = _Lane(run)
        heavy = _Session(1, None, "a", asyncio.Queue(), None)
        light = _Session(2, None, "b", asyncio.Queue(), None)
        # the heavy session queues first; while its first frame runs, both queue one more frame
        f1 = lane.submit(heavy, ("heavy-1", 0.05))
        await asyncio.sleep(0)
        f2 = lane.submit(heavy, ("heavy-2", 0.05))
        f3 = lane.submit(light, ("light-1", 0.0))
        assert await f1 == "heavy-1" and await f2 == "heavy-2" and await f3 == "light-1"
        assert heavy.vtime > light.vtime
        # the light session, having used less compute, overtakes frames the heavy one queued earlier
        f4 = lane.submit(heavy, ("heavy-3", 0.0))
        f5 = lane.submit(light, ("light-2", 0.0))
        await asyncio.gather(f4, f5)

    asyncio.run(go())
    assert order[0] == "heavy-1"
    assert order.index("light-1") < order.index("heavy-2")
    assert order.index("light-2") < order.index("heavy-3")


def test_garbage_connections_are_logged(server, caplog):
    with caplog.at_level(logging.WARNING, logger="interprim.server"):
        s = socket.create_connection(("127.0.0.1", server.server.port), timeout=5)
        s.sendall(b"\x00\x01garbage that is not HTTP\r\n\r\n")
        try:
            while s.recv(4096):
                pass
        except OSError:
            pass
        s.close()
        assert wait_until(lambda: "bad HTTP request" in caplog.text or "no complete handshake" in caplog.text)


def _reply_text(op, frames):
    import re

    from interprim.server.compute import compute_prediction

    return [re.sub(r',"compute_ms":[0-9.]+', "", compute_prediction(op, f, k + 1, 0.5 * k if k % 2 else None))
            for k, f in enumerate(frames)]


@pytest.mark.parametrize("std,dofs", [(False, "controlled"), (True, "all")])
def test_reply_encoding_fast_paths_equal_the_reference(models, test_demo, std, dofs):
    """compute_prediction's cached rollout (mean) and its text head give the message that
    Prediction.trajectory + json.dumps would give; the orjson (float32) and printf (%.7g) number formats agree to their precision."""
    from interprim.server import compute

    e = models["pair"]
    cols = e.controlled_dofs if dofs == "controlled" else list(range(e.n_dofs))
    frames = test_demo[:25, :2]
    op = compute._Open("pair", [e], [e.model.stream()], [cols], 17, std)
    fast = [json.loads(t) for t in _reply_text(op, frames)]
    assert op.heads[0][3].ok  # the cached rollout was checked against Prediction.trajectory and is used
    ref_stream = e.model.stream()
    for k, (f, msg) in enumerate(zip(frames, fast)):
        p = ref_stream.update(f)
        assert list(msg)[:2] == ["type", "seq"] and msg["seq"] == k + 1 and msg["model"] == "pair"
        assert msg["columns"] == cols and (msg.get("t") == (0.5 * k if k % 2 else None))
        assert msg["conditioned"] is p.conditioned and msg["frames"] == k + 1
        for key in ("phase", "x", "speed", "duration", "log_likelihood"):
            if p.conditioned:
                assert msg[key] == pytest.approx(float(getattr(p, key)), rel=1e-9, abs=1e-12)
            else:  # the first frames: the prior, no estimates
                assert msg[key] is None
        assert msg["out_of_range"] is p.out_of_range is False
        assert msg["input_distance"] == pytest.approx(p.input_distance, rel=1e-5)  # %.6g
        # orjson: float32 written as its shortest round-trip text (rounding to float32, then the shortest
        # text parsed as float64: <= 2**-23 ~ 1.2e-7 relative); printf %.7g: <= 5e-7 relative
        rtol = 1.2e-7 if (compute._orjson is not None and not compute._FORCE_PRINTF) else 5.0001e-7
        np.testing.assert_allclose(msg["mean"], p.trajectory(17)[:, cols], rtol=rtol, atol=1e-30)
        np.testing.assert_allclose(msg["goal"], p.goal[cols], rtol=rtol, atol=1e-30)
        if std:
            np.testing.assert_allclose(msg["std"], p.std(17)[:, cols], rtol=rtol, atol=1e-30)
    old = compute._FORCE_PRINTF
    compute._FORCE_PRINTF = True  # the encoder used without orjson
    try:
        op2 = compute._Open("pair", [e], [e.model.stream()], [cols], 17, std)
        slow = [json.loads(t) for t in _reply_text(op2, frames)]
    finally:
        compute._FORCE_PRINTF = old
    for a, b in zip(fast, slow):
        assert a.keys() == b.keys()
        np.testing.assert_allclose(a["mean"], b["mean"], rtol=1e-6, atol=1e-7)  # %.7g: 5e-7 relative


def test_reply_marks_out_of_range_input(models, test_demo):
    """Frames in millimetres given to a model trained in metres: every reply says so."""
    from interprim.server import compute

    e = models["pair"]
    op = compute._Open("pair", [e], [e.model.stream()], [e.controlled_dofs], 17, False)
    with pytest.warns(UserWarning, match="standard deviations"):
        msgs = [json.loads(t) for t in _reply_text(op, test_demo[:10, :2] * 1000.0)]
    assert msgs[-1]["out_of_range"] is True and msgs[-1]["input_distance"] > 8


def test_nonfinite_predictions_are_never_encoded():
    from interprim.server import compute

    for force in (False, True):
        old = compute._FORCE_PRINTF
        compute._FORCE_PRINTF = force
        try:
            for bad in (np.nan, np.inf, -np.inf):
                with pytest.raises(FloatingPointError):
                    compute._json_array(np.array([[0.0, 1.0], [bad, 2.0]]))
            assert json.loads(compute._json_array(np.array([1e-5, -2.5, 0.0]))) == pytest.approx([1e-5, -2.5, 0.0])
        finally:
            compute._FORCE_PRINTF = old


@pytest.mark.parametrize("kind", ["asyncio", "auto"])
def test_event_loop_choice(models, test_demo, kind):
    from interprim.server.app import new_event_loop

    with pytest.raises(ValueError):
        ServerConfig(loop="trio").validate()
    srv = InterprimServer({"pair": models["pair"]}, ServerConfig(port=0, loop=kind))
    with ServerThread(srv) as st, Client(st.ws_url) as c:
        c.open("pair", points=5)
        assert c.frame(test_demo[0, :2])["type"] == "prediction"
        if kind == "asyncio":
            assert type(st.loop).__module__.startswith("asyncio")
    ev = new_event_loop("auto")
    try:
        uv = pytest.importorskip("uvloop") if kind == "auto" else None
        if uv is not None:
            assert type(ev).__module__.startswith("uvloop")
    finally:
        ev.close()


def test_inline_lane_serves_at_once_only_sessions_not_ahead():
    """The inline lane's shortcut (compute in the session's own task) is taken only while no frame is
    waiting and the session has not used more compute than the others; else the frame is queued."""
    import asyncio

    from interprim.server.lanes import _Lane, _Session

    def run(job):
        name, cost = job
        time.sleep(cost)
        return name

    async def go():
        lane = _Lane(run, sync=True)
        heavy = _Session(1, None, "a", asyncio.Queue(), None)
        light = _Session(2, None, "b", asyncio.Queue(), None)
        assert lane.run_now(heavy, ("heavy-1", 0.02)) == "heavy-1"
        assert lane.run_now(heavy, ("heavy-2", 0.0)) is None  # 20 ms ahead: must queue
        f2 = lane.submit(heavy, ("heavy-2", 0.0))
        assert lane.run_now(light, ("light-1", 0.0)) is None  # a frame is waiting: queue behind it (fair order)
        f3 = lane.submit(light, ("light-1", 0.0))
        order = []
        for f in asyncio.as_completed([f2, f3]):
            order.append(await f)
        assert order == ["light-1", "heavy-2"]  # the lighter session first
        assert lane.run_now(light, ("light-2", 0.0)) == "light-2"

    asyncio.run(go())


@pytest.mark.parametrize("loop", ["asyncio", "uvloop"])
def test_worker_replies_larger_than_the_socket_buffer(models, test_demo, loop):
    """Worker-process replies of several hundred kB (many points + band) arrive whole under either
    event loop (uvloop switches the pipe to non-blocking mode: a regression made it a 'dead worker')."""
    if loop == "uvloop":
        pytest.importorskip("uvloop")  # declared in the [serve] extra on Linux and macOS
    srv = InterprimServer({"pair": models["pair"]}, ServerConfig(port=0, processes=1, loop=loop, max_points=5000,
                                                                   max_rate_hz=100000, rate_burst=100000))
    with ServerThread(srv) as st, Client(st.ws_url) as big, Client(st.ws_url) as small:
        big.open("pair", points=5000, std=True)
        small.open("pair", points=10)
        ref = models["pair"].model.stream()
        for f in test_demo[:12, :2]:
            pb, ps = big.frame(f), small.frame(f)
            e = ref.update(f)
            assert pb["type"] == "prediction" and len(pb["mean"]) == 5000 and len(pb["std"]) == 5000
            np.testing.assert_allclose(ps["mean"], e.trajectory(10)[:, 2:], atol=2e-6)
        assert not st.server._procs.workers[0].dead

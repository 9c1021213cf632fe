"""The streaming server's internals against real clients: worker processes, the async client, fair
queueing of the compute lanes, reply encoding and event-loop choice.  No timing assertions."""

from __future__ import annotations

import json
import logging
import socket

import numpy as np
import pytest

pytest.importorskip("websockets")

from _server_support import covered, models, n_sessions, server, test_demo, wait_until  # noqa: E402,F401  (fixtures and helpers)

from interprim.server.app import InterprimServer, ServerConfig, ServerThread  # noqa: E402
from interprim.server.client import Client, ServerError  # noqa: E402


@pytest.mark.slow  # starts worker processes
def test_worker_processes_give_the_same_predictions(models, test_demo):
    srv = InterprimServer({"pair": models["pair"], "letter_c": models["letter_c"]},
                          ServerConfig(port=0, processes=2, max_rate_hz=100000, rate_burst=100000))
    with ServerThread(srv) as st:
        assert len(st.server.compute.procs.workers) == 2
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
            replies = []
            while not replies or replies[-1]["seq"] < 20:  # a reply may cover several frames (coalesced)
                replies.append(await asyncio.wait_for(c.recv(), 30))
            await c.send_frame([1.0, 2.0, 3.0])
            err = await asyncio.wait_for(c.recv_raw(), 30)
            return replies, err

    replies, err = asyncio.run(go())
    assert [q for r in replies for q in covered(r)] == list(range(1, 21))
    direct = models["pair"].model.stream()
    for f in test_demo[:20, :2]:
        d = direct.update(f)
    np.testing.assert_allclose(replies[-1]["mean"], d.trajectory(8)[:, 2:], atol=2e-6)
    assert err["type"] == "error" and err["code"] == "bad_frame" and err["seq"] == 21


def _sessions(n):
    import asyncio

    from interprim.server.lanes import Session

    out = []
    for i in range(n):
        s = Session(i + 1, None, "?", asyncio.Queue(), None)
        s.open = object()  # stands for an opened model
        out.append(s)
    return out


def _add(lane, s, *seqs):
    """What a session's handler does with a frame: into the pending list; the session into the lane's queue."""
    for q in seqs:
        s.pending.append((None, q, None))
    if not s.queued:
        lane.push(s)


def test_lane_serves_sessions_round_robin_with_their_whole_backlog():
    """An async lane (threads / worker processes), one batch in flight: a session's turn takes all its pending
    frames; frames that arrive during its turn put it back at the end of the round (no session starves)."""
    import asyncio

    from interprim.server.lanes import _Lane

    served, delivered = [], []

    async def go():
        gate = asyncio.Event()

        async def run(s, op, batch):
            served.append((s.id, [q for _, q, _ in batch]))
            await gate.wait()
            return (["reply"], []), 0.001

        lane = _Lane(run, lambda s, op, batch, result: delivered.append((s.id, result)), depth=1)
        a, b, c = _sessions(3)
        _add(lane, a, 1)
        await asyncio.sleep(0)  # the lane task starts a's first batch and waits at the gate
        assert served == [(1, [1])] and a.queued and not a.pending
        _add(lane, a, 2, 3)  # a sends on during its turn ...
        _add(lane, b, 1)
        _add(lane, c, 1, 2, 3, 4)
        _add(lane, a, 4)
        (client,) = lane.clients.values()  # (all from one address)
        assert [e[2].id for e in sorted(client.ready)] == [2, 3] and len(a.pending) == 3  # ... it is not queued twice
        gate.set()
        while a.queued or b.queued or c.queued:
            await asyncio.sleep(0)

    asyncio.run(go())
    # a's frames 2-4 wait for one turn of b and c, then go in one batch (one reply covers them)
    assert served == [(1, [1]), (2, [1]), (3, [1, 2, 3, 4]), (1, [2, 3, 4])]
    assert [sid for sid, _ in delivered] == [1, 2, 3, 1]


def test_lane_keeps_depth_batches_of_different_sessions_in_flight():
    """depth=2: a worker has the next batch waiting while it computes one; never two batches of one session."""
    import asyncio

    from interprim.server.lanes import _Lane

    running, most, order = set(), [0], []

    async def go():
        async def run(s, op, batch):
            assert s.id not in running  # one batch per session at a time: its stream is updated in order
            running.add(s.id)
            most[0] = max(most[0], len(running))
            order.append((s.id, [q for _, q, _ in batch]))
            await asyncio.sleep(0)
            await asyncio.sleep(0)
            running.discard(s.id)
            return (["reply"], []), 0.001

        lane = _Lane(run, lambda *args: None, depth=2)
        a, b, c = _sessions(3)
        for k in range(1, 6):
            for s in (a, b, c):
                _add(lane, s, k)
            await asyncio.sleep(0)
        while a.queued or b.queued or c.queued:
            await asyncio.sleep(0)

    asyncio.run(go())
    assert most[0] == 2
    for sid in (1, 2, 3):  # each session's frames computed once each, in order
        assert [q for i, qs in order if i == sid for q in qs] == [1, 2, 3, 4, 5]


def test_inline_lane_serves_one_session_per_loop_iteration():
    """The inline lane computes on the event loop: one session's batch per iteration, so that the handlers read
    the frames that arrived meanwhile (they join their session's batch) before the next session is served."""
    import asyncio

    from interprim.server.lanes import _Lane

    served = []

    async def go():
        lane = _Lane(lambda s, op, batch: served.append((s.id, [q for _, q, _ in batch])) or (["r"], []),
                     lambda *args: None, sync=True)
        a, b = _sessions(2)
        _add(lane, a, 1)
        _add(lane, b, 1)
        await asyncio.sleep(0)  # one iteration: a is served, b waits for the next one
        assert served == [(1, [1])] and b.queued and not a.queued
        _add(lane, b, 2)  # arrives before b's turn: same batch
        _add(lane, a, 2)
        while a.queued or b.queued:
            await asyncio.sleep(0)
        ended = _sessions(1)[0]
        _add(lane, ended, 1)
        ended.ended = True  # a session that disconnected before its turn: its frames are not computed
        await asyncio.sleep(0)
        assert not ended.queued

    asyncio.run(go())
    assert served == [(1, [1]), (2, [1, 2]), (1, [2])]


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
    Prediction.trajectory + json.dumps would give; the orjson (float32) and printf (%.7g) number formats agree to their
    precision."""
    from interprim.server import compute

    e = models["pair"]
    cols = e.controlled_dofs if dofs == "controlled" else list(range(e.n_dofs))
    frames = test_demo[:25, :2]
    op = compute.OpenModel("pair", [e], [e.model.stream()], [cols], 17, std)
    fast = [json.loads(t) for t in _reply_text(op, frames)]
    from interprim.models.primitive.prediction import MeanRollout

    assert isinstance(op.heads[0][3].fn, MeanRollout)  # the IP's cached rollout is used (the contract's mean_rollout)
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
        op2 = compute.OpenModel("pair", [e], [e.model.stream()], [cols], 17, std)
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
    op = compute.OpenModel("pair", [e], [e.model.stream()], [e.controlled_dofs], 17, False)
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


@pytest.mark.parametrize("kind", ["asyncio", "best"])
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
    ev = new_event_loop("best")
    try:
        uv = pytest.importorskip("uvloop") if kind == "best" else None
        if uv is not None:
            assert type(ev).__module__.startswith("uvloop")
    finally:
        ev.close()


@pytest.mark.slow  # starts worker processes
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
        assert not st.server.compute.procs.workers[0].dead


def test_replay_lists_every_interaction_loaded():
    """The page's replay list is not cut at 20 (74 NuiSI interactions were loaded and 20 shown)."""
    import interprim as ip
    from interprim.server.models import replay_json
    from interprim.synthetic import two_agent_demos

    demos = two_agent_demos(30, seed=2, frames=40)
    model = ip.InteractionPrimitive([0, 1], n_basis=6, sigma2=1e-3, phase_method="dtw", calibrate=False).fit(
        demos[:10], dt=0.01)
    assert len(replay_json(model, demos)["interactions"]) == 30
    assert len(replay_json(model, demos, max_interactions=5)["interactions"]) == 5


class _TestClock:
    """A clock the test advances itself: a lane's turn costs exactly what the test charges, whatever the load."""

    def __init__(self):
        self.now = 0.0

    def __call__(self) -> float:
        return self.now

    def charge(self, seconds: float) -> None:
        self.now += seconds


def _turns_and_compute(lane_kind, cost, client, total):
    """Sessions that always have a frame waiting, served ``total`` turns by a lane whose turns cost exactly
    ``cost[session id]`` seconds (charged to a test clock: inline lanes read the lane's clock, async lanes are
    told the cost, as a worker reports it).  Returns ``(turns, compute seconds)`` per session."""
    import asyncio

    from interprim.server.lanes import _Lane

    turns = {sid: 0 for sid in cost}
    used = {sid: 0.0 for sid in cost}
    clock = _TestClock()

    async def go():
        done = asyncio.Event()
        sessions = _sessions(len(cost))
        for s in sessions:
            s.client = client[s.id]

        def work(s):
            clock.charge(cost[s.id])
            used[s.id] += cost[s.id]
            turns[s.id] += 1
            return ["reply"], []

        async def run_async(s, op, batch):
            await asyncio.sleep(0)
            return work(s), cost[s.id]

        def deliver(s, op, batch, result):
            if sum(turns.values()) < total:
                s.pending.append((None, 0, None))  # every session always has a frame waiting
            else:
                done.set()

        if lane_kind == "inline":
            lane = _Lane(lambda s, op, batch: work(s), deliver, sync=True, clock=clock)
        else:
            lane = _Lane(run_async, deliver, depth=2, clock=clock)
        for s in sessions:
            _add(lane, s, 1)
        await asyncio.wait_for(done.wait(), 60)

    asyncio.run(go())
    return turns, used


def test_lane_fair_queuing_makes_an_expensive_session_pay_with_its_own_turns():
    """Issue 30, finding 4: one client's expensive sessions (std, 500 points) took the others' time.  Turns are
    ordered by the compute time each session has used: a session whose turns cost ten times more gets a tenth of
    the turns, and the cheap sessions keep theirs.  (Costs charged to a test clock: the same turns on any machine.)"""
    cost = {1: 0.01, 2: 0.001, 3: 0.001}
    turns, used = _turns_and_compute("inline", cost, {1: "127.0.0.1", 2: "127.0.0.1", 3: "127.0.0.1"}, total=120)
    assert abs(turns[2] - turns[3]) <= 1, turns  # equal costs: round robin (the last round may be cut)
    # equal compute, so a tenth of the turns: up to one expensive turn, plus the turns of sessions still in line
    # when the run stops asking (they are served once more)
    assert max(used.values()) - min(used.values()) <= 2 * 0.01 + 1e-12, (turns, used)
    assert turns[1] * 5 <= min(turns[2], turns[3]), turns


@pytest.mark.parametrize("lane_kind", ["inline", "async"])
def test_lane_shares_compute_between_clients_not_sessions(lane_kind):
    """Issue 30, finding 4: one client holding 14 expensive sessions took the other clients' time.  Compute is
    shared out between clients (addresses) first: a client with 5 sessions whose turns cost 4 ms gets the compute
    of a client with two sessions whose turns cost 1 ms (half each), not 10 times more.  (Two light sessions, so
    that they can fill the async lane's two places in flight, as the heavy client does.)  The turns' costs are
    charged to a test clock, so the shares are exact on any machine; the wall-clock measurement of the same
    fairness is a benchmark row (``python -m benchmarks.load_server --beside 14``)."""
    cost = {1: 0.004, 2: 0.004, 3: 0.004, 4: 0.004, 5: 0.004, 6: 0.001, 7: 0.001}
    client = {1: "10.0.0.9", 2: "10.0.0.9", 3: "10.0.0.9", 4: "10.0.0.9", 5: "10.0.0.9", 6: "10.0.0.2",
              7: "10.0.0.2"}
    turns, used = _turns_and_compute(lane_kind, cost, client, total=400)
    heavy = sum(used[i] for i in range(1, 6))
    light = used[6] + used[7]
    share = light / (light + heavy)
    assert 0.45 <= share <= 0.55, (share, used)  # equal compute per client; per session it would be 2/22
    # inside the heavy client, its sessions share its time equally, up to one turn
    per = [turns[i] for i in range(1, 6)]
    assert max(per) - min(per) <= 1, turns
    assert abs(turns[6] - turns[7]) <= 1, turns


def test_lane_compute_shares_do_not_depend_on_the_machine():
    """One input, one answer: the same costs give the same turns, run after run (the lane's order depends only on
    the costs charged, never on the wall clock)."""
    cost = {1: 0.004, 2: 0.001, 3: 0.002}
    client = {1: "10.0.0.1", 2: "10.0.0.1", 3: "10.0.0.3"}
    for kind in ("inline", "async"):
        first = _turns_and_compute(kind, cost, client, total=90)
        assert all(_turns_and_compute(kind, cost, client, total=90) == first for _ in range(3))


def test_sessions_from_two_addresses_are_two_clients(server, test_demo):
    """On loopback, end to end: each session's client for the fair queuing is its connection's address (two loopback
    addresses: two clients; two sessions from one address: one client)."""
    from _server_support import RawWS

    conns = [RawWS(server.server.port, source=a) for a in ("127.0.0.7", "127.0.0.8", "127.0.0.8")]
    for raw in conns:
        raw.send(json.dumps({"type": "hello"}))
        raw.send(json.dumps({"type": "open", "model": "pair"}))
        raw.send(json.dumps({"type": "frame", "frame": list(map(float, test_demo[0, :2]))}))
    try:
        assert wait_until(lambda: sorted(server.call(lambda: [s.client for s in server.server.sessions.values()
                                                              if s.client in ("127.0.0.7", "127.0.0.8")]))
                          == ["127.0.0.7", "127.0.0.8", "127.0.0.8"])
        lanes = server.call(lambda: server.server.compute.lanes)
        assert wait_until(lambda: {"127.0.0.7", "127.0.0.8"} <= set(server.call(
            lambda: [k for lane in lanes for k in lane.clients])))
    finally:
        for raw in conns:
            raw.close()


def test_lane_with_one_client_is_round_robin_by_compute():
    """All sessions from one address (one client): the sessions share the compute as before, by the time they use."""
    cost = {1: 0.004, 2: 0.001, 3: 0.001}
    turns, used = _turns_and_compute("inline", cost, {1: "127.0.0.1", 2: "127.0.0.1", 3: "127.0.0.1"}, total=200)
    assert max(used.values()) - min(used.values()) <= 0.004 + 1e-12, used  # a third each, up to one turn
    assert abs(turns[2] - turns[3]) <= 1, turns


def test_client_key_groups_an_ipv6_prefix():
    """One host can hold a whole IPv6 /64: its addresses count as one client (else its share could be multiplied)."""
    from interprim.server.lanes import client_key

    assert client_key("2001:db8:1:2::5") == client_key("2001:db8:1:2:ffff::1") == "2001:db8:1:2::/64"
    assert client_key("2001:db8:1:3::5") != client_key("2001:db8:1:2::5")
    assert client_key("::ffff:10.1.2.3") == client_key("10.1.2.3") == "10.1.2.3"
    assert client_key("10.1.2.3") != client_key("10.1.2.4")
    assert client_key("?") == "?"


def test_rate_limit_is_credited_for_the_time_the_server_did_not_read():
    """Issue 30, finding 4: when the server stops reading a session that is behind (max_pending), the client's frames
    pile up in TCP and arrive as one burst over the rate limit's burst: they were dropped as rate_limited.  The
    pause is now credited to the bucket (beyond its burst), so a client within the rate loses none of them."""
    from interprim.server.lanes import TokenBucket

    b = TokenBucket(rate=100.0, burst=5)
    assert sum(b.take() for _ in range(50)) == 5  # a burst of 50: 5 pass (what a flooding client gets)
    b.credit(0.4)  # the server did not read the client for 0.4 s: 40 frames at 100 Hz
    assert sum(b.take() for _ in range(40)) == 40
    assert not b.take()

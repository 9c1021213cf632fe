"""Fair compute lanes on the wall clock: the shares one heavy client and one light client really get.

``tests/server/test_server_internals.py`` checks the lane's order with a clock the test advances (each turn charged
exactly its cost), so its assertions hold on any machine.  This benchmark runs the same workload with turns that
really take their time (a busy loop of the stated cost, measured by :func:`time.perf_counter`, as the server
measures them) and prints what each client and session got; on a loaded machine the figures drift from the ideal
(preempted turns cost more than asked), which is why no test asserts them.

    python -m benchmarks.lane_fairness [--turns 400] [--repeat 3]

Workload: client A holds 5 sessions whose turns cost 4 ms, client B 2 sessions whose turns cost 1 ms.  Ideal: each
client gets half of the compute (per session it would be 2 ms of 22 per round, B 9 %); inside A, equal shares.
"""

from __future__ import annotations

import argparse
import asyncio
import os
import time

COST = {1: 0.004, 2: 0.004, 3: 0.004, 4: 0.004, 5: 0.004, 6: 0.001, 7: 0.001}
CLIENT = {1: "10.0.0.9", 2: "10.0.0.9", 3: "10.0.0.9", 4: "10.0.0.9", 5: "10.0.0.9", 6: "10.0.0.2", 7: "10.0.0.2"}


def _session(i: int):
    from interprim.server.lanes import Session, TokenBucket

    s = Session(id=i, ws=None, peer="?", out=asyncio.Queue(), bucket=TokenBucket(1e9, 10**9))
    s.open = object()  # the lane only checks that a model is open
    s.client = CLIENT[i]
    return s


def run(kind: str, turns: int) -> dict:
    """Seconds of compute each session got (measured with the wall clock) in ``turns`` turns of a ``kind`` lane."""
    from interprim.server.lanes import _Lane

    used = {i: 0.0 for i in COST}
    count = [0]

    async def go():
        done = asyncio.Event()
        sessions = [_session(i) for i in COST]

        def work(s):
            t0 = time.perf_counter()
            while time.perf_counter() - t0 < COST[s.id]:  # busy: the turn really takes its cost
                pass
            used[s.id] += time.perf_counter() - t0
            count[0] += 1
            return ["reply"], []

        async def run_async(s, op, batch):
            await asyncio.sleep(0)
            t0 = time.perf_counter()
            result = work(s)
            return result, time.perf_counter() - t0

        def deliver(s, op, batch, result):
            if count[0] < turns:
                s.pending.append((None, 0, None))
            else:
                done.set()

        lane = _Lane(lambda s, op, b: work(s), deliver, sync=True) if kind == "inline" else \
            _Lane(run_async, deliver, depth=2)
        for s in sessions:
            s.pending.append((None, 0, None))
            lane.push(s)
        await asyncio.wait_for(done.wait(), 120)

    asyncio.run(go())
    return used


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--turns", type=int, default=400)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)
    print(f"load average {os.getloadavg()[0]:.1f}; {args.turns} turns per run; ideal: light client's share 0.50")
    print("| lane | run | light client's share | heavy sessions' spread (ms) | heavy per session (ms) |")
    print("|---|---:|---:|---:|---|")
    for kind in ("inline", "async"):
        for r in range(args.repeat):
            used = run(kind, args.turns)
            heavy = [used[i] for i in range(1, 6)]
            light = used[6] + used[7]
            share = light / (light + sum(heavy))
            spread = (max(heavy) - min(heavy)) * 1e3
            print(f"| {kind} | {r + 1} | {share:.3f} | {spread:.1f} | "
                  f"{', '.join(f'{h * 1e3:.0f}' for h in heavy)} |")


if __name__ == "__main__":
    main()

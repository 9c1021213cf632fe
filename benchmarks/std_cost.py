"""What ``std: true`` costs the server per frame (the figure quoted in docs/protocol.md).

Streams the same interactions to a loopback server twice per model, once opened with ``std: false`` and once
with ``std: true``, and reports the median (and 90th percentile) of the server's own time per frame
(``compute_ms`` of the replies: stream update, trajectory, band, JSON encoding).  Frames are sent one at a time
(each waits for its reply), so nothing else competes inside the server.  ``compute_ms`` is wall-clock time, so
on a shared machine it also counts the time other processes held the core; the second figure is the CPU time
of the same computation (``compute_prediction`` called in this process, ``time.thread_time``), which does not.

    .venv/bin/python benchmarks/std_cost.py [--points 50] [--repeats 3]
"""

from __future__ import annotations

import argparse
import statistics

import numpy as np


def _models(n_train: int):
    import interprim as ip
    from interprim.server.demo import highfive_model
    from interprim.server.models import entry_for
    from interprim.synthetic import two_agent_demos

    hf = highfive_model(n_train=n_train, n_test=2, seed=0)
    train = two_agent_demos(20, seed=0, frames=150)
    synth = ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=10).fit(train, dt=0.01)
    test = two_agent_demos(2, seed=99, frames=150)
    return {
        "highfive": (hf, [np.array(it["observed"]) for it in hf.meta["replay"]["interactions"]]),
        "synthetic": (entry_for("synthetic", synth), [d[:, :2] for d in test]),
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--points", type=int, default=50)
    ap.add_argument("--repeats", type=int, default=3, help="passes over the test interactions per setting")
    ap.add_argument("--n-train", type=int, default=40)
    args = ap.parse_args(argv)

    from interprim.server.app import InterprimServer, ServerConfig, ServerThread
    from interprim.server.client import Client

    models = _models(args.n_train)
    srv = InterprimServer({k: e for k, (e, _) in models.items()},
                          ServerConfig(port=0, max_rate_hz=1e6, rate_burst=10**6))
    print(f"points={args.points}, repeats={args.repeats}; compute_ms per frame (server time), median [p90]")
    with ServerThread(srv) as st, Client(st.ws_url) as c:
        for name, (_, tests) in models.items():
            res = {}
            for std in (False, True, False, True):  # interleaved: a drift of the machine's load hits both
                c.open(name, points=args.points, std=std)
                times = res.setdefault(std, [])
                for _ in range(args.repeats):
                    for obs in tests:
                        c.reset()
                        times += [c.frame(f)["compute_ms"] for f in obs]
            med = {k: statistics.median(v) for k, v in res.items()}
            p90 = {k: float(np.percentile(v, 90)) for k, v in res.items()}
            print(f"{name:10s} compute_ms: std off {med[False]:.3f} ms [{p90[False]:.3f}]  std on {med[True]:.3f} ms "
                  f"[{p90[True]:.3f}]  ratio {med[True] / med[False]:.1f}x  ({len(res[True])} frames each)")
    for name, (entry, tests) in models.items():
        cpu = {std: statistics.median(_cpu_ms(entry, tests, args.points, std, args.repeats)) for std in (False, True)}
        print(f"{name:10s} CPU time:   std off {cpu[False]:.3f} ms          std on {cpu[True]:.3f} ms          "
              f"ratio {cpu[True] / cpu[False]:.1f}x")
    return 0


def _cpu_ms(entry, tests, points, std, repeats):
    """CPU time (ms) of each frame's reply, computed as the server computes it (inline lane)."""
    import time

    from interprim.server.compute import OpenModel, _accepts_need_cov, compute_prediction

    cols = entry.controlled_dofs or list(range(entry.n_dofs))
    out = []
    for _ in range(repeats):
        for obs in tests:
            st = entry.model.stream()
            op = OpenModel(entry.name, [entry], [st], [cols], points, std)
            if _accepts_need_cov(st):
                op.update_kw = {"need_cov": std}
            for k, f in enumerate(np.asarray(obs, dtype=np.float64), start=1):
                t0 = time.thread_time()
                compute_prediction(op, f, k, None)
                out.append((time.thread_time() - t0) * 1e3)
    return out


if __name__ == "__main__":
    raise SystemExit(main())

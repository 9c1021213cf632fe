"""What the default model (:class:`interprim.AutoInteraction`, what ``interprim fit`` gives) costs beside the
Interaction Primitive alone, on differently generated data: one table, one run.

Issue 37's targets, at 30 demonstrations x (7 + 7) DoF x 200 frames on at least three data generators (one where
every family ties): one streamed frame (``stream.update`` + ``trajectory(100)``) at most 3x the IP's in the same run
and at most 2 ms on an idle machine; ``predict`` at most 3x; ``fit`` at most 4x.  Also at 20 x (2 + 3) x 150.

Run from the repository root::

    python -m benchmarks.auto              # the table (a few minutes)
    python -m benchmarks.auto --quick      # fewer repeats
    python -m benchmarks.auto --large      # only 30 x (7 + 7) x 200
    python -m benchmarks.auto --calibrate  # measure the frame cost model's constants (process time, one thread)

:mod:`benchmarks.run` runs :func:`bench_auto` too (its rows go to ``benchmarks/RESULTS.md``).  The model's own
modelled frame (``selection_["cost"]``, a deterministic cost model, not a timing) is printed beside the measured one.
"""

from __future__ import annotations

import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT / "src") not in sys.path:
    sys.path.insert(0, str(ROOT / "src"))

#: (demonstrations, observed DoFs, controlled DoFs, frames)
SIZES = ((30, 7, 7, 200), (20, 2, 3, 150))


def shared_factors(S, Do, Dc, T, seed=0):
    """The suite's own synthetic set (:func:`benchmarks.data.make_demos`): both agents driven by shared latent
    factors."""
    from benchmarks.data import make_demos

    return make_demos(S, Do, Dc, T, seed=seed)


def sines_quadratic(S, Do, Dc, T, seed=0):
    """Sines of random amplitude, frequency and phase for the observed agent, a fixed quadratic map of them for the
    controlled one, and a little noise: the families tie on it (issue 37's second row)."""
    rng = np.random.default_rng(seed)
    A, B = rng.normal(size=(Do, Dc)) / np.sqrt(Do), rng.normal(size=(Do, Dc)) / np.sqrt(Do)
    out = []
    for _ in range(S):
        s = np.linspace(0, 1, int(round(T * rng.uniform(0.9, 1.1))))[:, None]
        x = rng.uniform(0.7, 1.3, Do) * np.sin(2 * np.pi * rng.uniform(0.8, 1.2, Do) * s + rng.uniform(-.3, .3, Do))
        out.append(np.hstack([x, x @ A + (x ** 2) @ B]) + 0.01 * rng.standard_normal((len(s), Do + Dc)))
    return out


def reaches(S, Do, Dc, T, seed=0):
    """Minimum-jerk reaches of the observed agent to a random goal at a random speed; the controlled agent reaches
    a linear image of that goal, starting a random 5-20 % of the movement later (a handover)."""
    rng = np.random.default_rng(seed)
    G = rng.normal(size=(Do, Dc)) / np.sqrt(Do)
    out = []
    for _ in range(S):
        n = int(round(T * rng.uniform(0.8, 1.25)))
        u = np.linspace(0, 1, n)[:, None]
        mj = lambda v: 10 * v ** 3 - 15 * v ** 4 + 6 * v ** 5  # noqa: E731
        goal = rng.normal(size=Do)
        start = 0.1 * rng.normal(size=Do)
        lag = rng.uniform(0.05, 0.2)
        xo = start + (goal - start) * mj(u)
        xc = (goal @ G) * mj(np.clip((u - lag) / (1 - lag), 0, 1))
        out.append(np.hstack([xo, xc]) + 0.005 * rng.standard_normal((n, Do + Dc)))
    return out


GENERATORS = {"shared factors": shared_factors, "sines, quadratic coupling (ties)": sines_quadratic,
              "min-jerk reaches": reaches}


def _frame_pass(model, partial, clock=time.perf_counter) -> float:
    """Seconds of one streamed frame (``update`` + ``trajectory(100)``), averaged over one pass of ``partial``."""
    st = model.stream()
    t0 = clock()
    for f in partial:
        st.update(f).trajectory(100)
    return (clock() - t0) / len(partial)


def _frame(model, partial, n, clock=time.perf_counter):
    """Median seconds of one streamed frame (``update`` + ``trajectory(100)``) over ``n`` passes of ``partial``."""
    return float(np.median([_frame_pass(model, partial, clock) for _ in range(n + 1)][1:]))


def _alternating(one_a, one_b, n: int) -> tuple[float, float]:
    """Medians of ``one_a(i)`` and ``one_b(i)`` over ``i = 1 .. n``, the two taken in turn (after one untimed
    round): a slow spell of the machine falls on both sides, so their ratio does not swing with it."""
    a, b = [], []
    for i in range(n + 1):
        a.append(one_a(i))
        b.append(one_b(i))
    return float(np.median(a[1:])), float(np.median(b[1:]))


def _overhead(auto, partial) -> float:
    """The blend's own share of a streamed frame, in CPU time of this thread: placing the members in time, the
    weights over the look-ahead, reading each member on the common grid and combining (``Blend.combine`` +
    ``trajectory(100)``), over the whole frame (the members' ``update`` included).  NaN for a single family."""
    from interprim.models.blend import Blend

    blend = auto.model_
    if not isinstance(blend, Blend):
        return float("nan")
    st, own, total = blend.stream(), 0.0, 0.0
    for i, f in enumerate(partial):
        c0 = time.thread_time()
        preds = {m: s.update(f) for m, s in st.streams.items()}
        c1 = time.thread_time()
        blend.combine(preds, i + 1).trajectory(100)
        c2 = time.thread_time()
        own, total = own + (c2 - c1), total + (c2 - c0)
    return own / total if total > 0 else float("nan")


def _predict_once(model, partial, i: int) -> float:
    """Seconds of ``predict`` + ``trajectory(100)`` on the prefix of ``partial`` ``i`` frames shorter than it (every
    call sees a new prefix, as a controller's calls do: nothing a model kept from the previous call's frames is
    reused)."""
    x = partial[:max(len(partial) - i, 2)]
    t0 = time.perf_counter()
    model.predict(x).trajectory(100)
    return time.perf_counter() - t0


def warm_up() -> None:
    """The compiled kernels loaded and every family fitted once on a tiny set before anything is timed, so that no
    row (the first above all) carries the process's one-time costs, and the default and the IP start alike."""
    import warnings

    import interprim as ip
    from interprim.core._compiled.loader import warmup

    warmup()
    demos = shared_factors(6, 2, 2, 40, seed=3)
    with warnings.catch_warnings():  # about this tiny warm-up set, not the measured data
        warnings.simplefilter("ignore", ip.PaceWarning)
        ip.AutoInteraction([0, 1], frame_budget=None).fit(demos, dt=0.01).predict(demos[0][:20, :2])


def measure(generator, S, Do, Dc, T, quick=False) -> dict:
    """The default and the IP on ``generator``'s data of that size: frame, predict, fit (s), members, modelled frame."""
    import interprim as ip
    from interprim.core.blas import single_thread

    demos = generator(S, Do, Dc, T, seed=0)
    test = generator(1, Do, Dc, T, seed=1000)[0]
    obs = list(range(Do))
    partial = test[: len(test) // 2, :Do]
    warm_up()
    with single_thread():
        t0, c0 = time.perf_counter(), time.thread_time()
        auto = ip.AutoInteraction(obs).fit(demos, dt=0.01)
        fit_auto, cpu_auto = time.perf_counter() - t0, time.thread_time() - c0
        t0, c0 = time.perf_counter(), time.thread_time()
        model = ip.InteractionPrimitive(obs).fit(demos, dt=0.01)
        fit_ip, cpu_ip = time.perf_counter() - t0, time.thread_time() - c0
        n = 3 if quick else 7
        # the default and the IP measured in turn, pass by pass and call by call (_alternating)
        frame, frame_ip = _alternating(lambda i: _frame_pass(auto, partial), lambda i: _frame_pass(model, partial), n)
        predict, predict_ip = _alternating(lambda i: _predict_once(auto, partial, i),
                                           lambda i: _predict_once(model, partial, i), 5 * n)
        out = {"frame": frame, "frame_ip": frame_ip, "predict": predict, "predict_ip": predict_ip,
               "fit": fit_auto, "fit_ip": fit_ip, "fit_cpu": cpu_auto, "fit_ip_cpu": cpu_ip,
               "overhead": _overhead(auto, partial)}
    members = getattr(auto.model_, "members_", {auto.chosen_: None})
    bw = auto.selection_.get("band_weights", {auto.chosen_: [1.0]})
    out["members"] = ", ".join(f"{m} {bw[m][0]:.2f}" + (f"/{max(bw[m]):.2f}" if max(bw[m]) > bw[m][0] else "")
                               for m in members)
    c = auto.selection_["cost"]
    out["modelled"] = c["frame"] / c["ip_frame"]
    out["left_out"] = ", ".join(sorted(c["left_out"])) or "-"
    return out


def table(quick=False, sizes=SIZES, log=print) -> list:
    """One row per data generator and size; returns the rows (dicts) and prints the table."""
    rows = []
    log("| data | size | frame: default / IP (ratio) | predict (ratio) | fit (ratio; CPU time ratio) | "
        "modelled frame ratio | blend's own share of the frame | members (real-time weight / largest) | "
        "left out for the budget |")
    log("|---|---|---|---|---|---|---|---|---|")
    for S, Do, Dc, T in sizes:
        for name, gen in GENERATORS.items():
            r = measure(gen, S, Do, Dc, T, quick)
            r.update(data=name, size=f"{S} x {Do}+{Dc} x {T}")
            rows.append(r)
            share = "-" if not np.isfinite(r["overhead"]) else f"{100 * r['overhead']:.0f} %"
            log(f"| {name} | {r['size']} | {1e3 * r['frame']:.2f} / {1e3 * r['frame_ip']:.2f} ms "
                f"({r['frame'] / r['frame_ip']:.1f}x) | {1e3 * r['predict']:.2f} / {1e3 * r['predict_ip']:.2f} ms "
                f"({r['predict'] / r['predict_ip']:.1f}x) | {r['fit']:.1f} / {r['fit_ip']:.1f} s "
                f"({r['fit'] / r['fit_ip']:.1f}x; CPU {r['fit_cpu'] / r['fit_ip_cpu']:.1f}x) | {r['modelled']:.1f}x | "
                f"{share} | "
                f"{r['members']} | {r['left_out']} |")
    return rows


def bench_auto(quick, make_demos, timed, row):
    """The rows of :mod:`benchmarks.run`: the default beside the IP on each data generator (30 x 7+7 x 200)."""
    print("model chosen on the data (AutoInteraction) beside the Interaction Primitive, per data generator")
    for name, gen in GENERATORS.items():
        S, Do, Dc, T = SIZES[0]
        r = measure(gen, S, Do, Dc, T, quick)
        size = f"{S} demos x {Do}+{Dc} DoF x {T} ({name})"
        note = f"members: {r['members']}; left out for the budget: {r['left_out']}; modelled {r['modelled']:.1f}x"
        row("AutoInteraction: fit (families x inner folds + blend)", size, [r["fit"]],
            "InteractionPrimitive fit (defaults)", [r["fit_ip"]], note=note)
        row("AutoInteraction: predict + trajectory(100)", size, [r["predict"]], "InteractionPrimitive",
            [r["predict_ip"]])
        row("AutoInteraction: stream.update + trajectory(100), one frame", size, [r["frame"]],
            "InteractionPrimitive", [r["frame_ip"]])


def _predict_cpu(model, partial, n: int) -> float:
    """Median process time of ``predict`` + ``trajectory(100)`` over the prefixes of ``partial`` 1 .. ``n`` frames
    shorter than it (each call a new prefix, as :func:`_predict_once`)."""
    out = []
    for i in range(n + 1):
        x = partial[:max(len(partial) - i, 2)]
        t0 = time.process_time()
        model.predict(x).trajectory(100)
        out.append(time.process_time() - t0)
    return float(np.median(out[1:]))


def calibrate(log=print) -> None:
    """Process time of one streamed frame and of one ``predict`` (half the movement seen) of each family, of each
    cost class of the IP (its phase) and of the learned interaction (its coupling), and of blends, at seven sizes;
    the least-squares constants of :data:`interprim.models.registry._COSTS_US` and ``_PREDICT_US`` and of the
    blend's :data:`interprim.models.blend._OVERHEAD_US` (one BLAS thread)."""
    from scipy.optimize import nnls

    from interprim.core.blas import single_thread
    from interprim.models import registry
    from interprim.models.blend import Blend
    from interprim.models.learned import LearnedInteraction

    sizes = [(10, 2, 3, 100), (20, 2, 3, 150), (30, 7, 7, 200), (20, 4, 4, 300), (40, 3, 3, 150), (15, 10, 8, 120),
             (20, 9, 3, 50)]
    fams = ["ip", "learned", "kernel", "nn", "prior"]
    rows: dict = {}  # (what, kind) -> ([features], [microseconds])

    def add(what, kind, z, model, partial):
        if what == "frame":
            t = min(_frame(model, partial, 3, clock=time.process_time) for _ in range(2))
            feats = registry._cost_features(kind, z)
        else:
            t = _predict_cpu(model, partial, 6)
            feats = registry._predict_features(kind, z)
        f, y = rows.setdefault((what, kind), ([], []))
        f.append(feats)
        y.append(t * 1e6)
        return t

    with single_thread():
        for S, Do, Dc, T in sizes:
            demos = shared_factors(S, Do, Dc, T)
            partial = shared_factors(1, Do, Dc, T, seed=1000)[0][: T // 2, :Do]
            obs = list(range(Do))
            z = registry.FrameSizes(S, float(np.mean([len(d) for d in demos])), Do, Do + Dc)
            make = registry.factories(fams, registry.Settings(tuple(obs)))
            members = {m: make[m]().fit(demos, dt=0.01) for m in fams}
            alone: dict = {"frame": {}, "predict": {}}
            variants = []  # (kind, sizes, model): every cost class of the families
            for ph, kind in (("likelihood", "ip"), ("learned", "ip-learned")):
                one = registry.family("ip").build(registry.Settings(tuple(obs), phase_method=ph)).fit(demos, dt=0.01)
                variants.append((kind, dataclasses.replace(z, phase=ph), one))
            for meth in ("ridge", "kernel", "ppca"):
                one = LearnedInteraction(obs, coupling_kwargs={"methods": (meth,)}).fit(demos, dt=0.01)
                if one.coupling_.method_ == meth:  # else its cross-validation kept the mean: not this class's cost
                    z_m = dataclasses.replace(z, coupling=meth)
                    variants.append((registry.COUPLING_CLASSES.get(meth, "learned"), z_m, one))
            variants += [(m, z, members[m]) for m in ("kernel", "nn", "prior")]
            for what in ("frame", "predict"):
                for kind, z_v, model in variants:
                    add(what, kind, z_v, model, partial)
                for m in fams:  # the members as the registry builds them (their own choices), for the blends
                    alone[what][m] = (min(_frame(members[m], partial, 3, clock=time.process_time) for _ in range(2))
                                      if what == "frame" else _predict_cpu(members[m], partial, 6))
                for names in (["ip", "nn"], fams):
                    W = {n: [1.0 / len(names)] * 2 for n in names}
                    b = Blend.from_fitted(obs, {n: members[n] for n in names}, W, None, demos, 0.01, 0.25,
                                          bands=[0.25, 2.0])
                    t = (min(_frame(b, partial, 3, clock=time.process_time) for _ in range(2)) if what == "frame"
                         else _predict_cpu(b, partial, 6))
                    f, y = rows.setdefault((what, "overhead"), ([], []))
                    f.append((1.0, len(names), len(names) * (Do + Dc)))
                    y.append((t - sum(alone[what][n] for n in names)) * 1e6)
            log(f"{S} x {Do}+{Dc} x {T}: " + "; ".join(
                f"{what} " + ", ".join(f"{m} {1e6 * v:.0f} us" for m, v in alone[what].items()) for what in alone))
    for (what, kind), (f, y) in rows.items():
        X, y = np.array(f, dtype=float), np.array(y)
        c, _ = nnls(X, y)
        err = np.round((X @ c - y) / y, 2).tolist()
        log(f"{what} {kind}: constants {np.round(c, 5).tolist()}, relative error {err}")


def main(argv=None) -> int:
    import argparse

    ap = argparse.ArgumentParser(prog="python -m benchmarks.auto", description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="fewer repeats")
    ap.add_argument("--calibrate", action="store_true", help="measure the frame cost model's constants instead")
    ap.add_argument("--large", action="store_true", help="only issue 37's size, 30 x (7 + 7) x 200")
    args = ap.parse_args(argv)
    if args.calibrate:
        calibrate()
    else:
        table(args.quick, sizes=SIZES[:1] if args.large else SIZES)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

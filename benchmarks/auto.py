"""Benchmark rows of :class:`interprim.AutoInteraction` (what ``interprim fit`` gives by default), run by
:mod:`benchmarks.run` beside the Interaction Primitive alone (the helpers are passed in to keep one timing code).

Two sizes (issue 27's): 20 demonstrations x (2 + 3) DoF x 150 frames and 30 x (7 + 7) DoF x 200 frames.  The
ratios to the IP in the same run are the targets: one streamed frame <= 1.5x, predict <= 2x, fit <= 4x."""

from __future__ import annotations

#: (demonstrations, observed DoFs, controlled DoFs, frames)
SIZES = ((20, 2, 3, 150), (30, 7, 7, 200))


def bench_auto(quick, make_demos, timed, row):
    """Fit (the families compared on inner folds, then blended), predict and one streamed frame, beside the IP."""
    import interprim as ip

    print("model chosen on the data (AutoInteraction) beside the Interaction Primitive")
    for S, Do, Dc, T in SIZES:
        demos = make_demos(S, Do, Dc, T, seed=0)
        test = make_demos(1, Do, Dc, T, seed=1000, stretch=(1.0, 1.0))[0]
        obs = list(range(Do))
        size = f"{S} demos x {Do}+{Dc} DoF x {T}"
        t_fit = timed(lambda: ip.AutoInteraction(obs).fit(demos, dt=0.01), n=1, warm=0)
        t_ip = timed(lambda: ip.InteractionPrimitive(obs).fit(demos, dt=0.01), n=1 if quick else 3, warm=0)
        auto = ip.AutoInteraction(obs).fit(demos, dt=0.01)
        model = ip.InteractionPrimitive(obs).fit(demos, dt=0.01)
        weights = ", ".join(f"{m} {w:.2f}" for m, w in auto.weights_.items() if w > 0)
        row("AutoInteraction: fit (families x inner folds + blend)", size, t_fit,
            "InteractionPrimitive fit (defaults)", t_ip, note=f"real-time weights: {weights}")
        M = T // 2
        partial = test[:M, :Do]
        mt = 0.3 if quick else 1.0
        row("AutoInteraction: predict + trajectory(100)", f"{M} frames, {Do}+{Dc} DoF",
            timed(lambda: auto.predict(partial).trajectory(100), min_time=mt),
            "InteractionPrimitive", timed(lambda: model.predict(partial).trajectory(100), min_time=mt))

        def steps(m):
            def run():
                s = m.stream()
                for f in partial:
                    s.update(f).trajectory(100)
            return run

        n = 2 if quick else 5
        row("AutoInteraction: stream.update + trajectory(100), one frame", f"{Do}+{Dc} DoF, mean over {M} frames",
            timed(steps(auto), n=n, warm=1) / M, "InteractionPrimitive", timed(steps(model), n=n, warm=1) / M)

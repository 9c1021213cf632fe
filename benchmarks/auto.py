"""Benchmark rows of :class:`interprim.AutoInteraction` (what ``interprim fit`` gives by default), run by
:mod:`benchmarks.run` beside the Interaction Primitive alone (the helpers are passed in to keep one timing code)."""

from __future__ import annotations


def bench_auto(quick, make_demos, timed, row):
    """Fit (the families compared on inner folds, then blended), predict and one streamed frame, beside the IP."""
    import interprim as ip

    print("model chosen on the data (AutoInteraction)")
    demos = make_demos(20, 2, 3, 150, seed=0)
    test = make_demos(1, 2, 3, 150, seed=1000, stretch=(1.0, 1.0))[0]
    obs = [0, 1]
    t_fit = timed(lambda: ip.AutoInteraction(obs).fit(demos, dt=0.01), n=1, warm=0)
    t_ip = timed(lambda: ip.InteractionPrimitive(obs).fit(demos, dt=0.01), n=1 if quick else 3, warm=0)
    auto = ip.AutoInteraction(obs).fit(demos, dt=0.01)
    model = ip.InteractionPrimitive(obs).fit(demos, dt=0.01)
    weights = ", ".join(f"{m} {w:.2f}" for m, w in auto.weights_.items())
    row("AutoInteraction: fit (5 families x 3 inner folds + blend)", "20 demos x 5 DoF x 150", t_fit,
        "InteractionPrimitive fit (defaults)", t_ip, note=f"blend: {weights}")
    partial = test[:75, :2]
    mt = 0.3 if quick else 1.0
    row("AutoInteraction: predict + trajectory(100)", "75 frames, 2+3 DoF",
        timed(lambda: auto.predict(partial).trajectory(100), min_time=mt),
        "InteractionPrimitive", timed(lambda: model.predict(partial).trajectory(100), min_time=mt))

    def steps(m):
        def run():
            s = m.stream()
            for f in test[:75, :2]:
                s.update(f).trajectory(100)
        return run

    n = 2 if quick else 5
    row("AutoInteraction: stream.update + trajectory(100), one frame", "2+3 DoF, mean over 75 frames",
        timed(steps(auto), n=n, warm=1) / 75, "InteractionPrimitive", timed(steps(model), n=n, warm=1) / 75)

"""Benchmark rows of the learned timing (:mod:`interprim.phase.learned`) and :class:`interprim.LearnedInteraction`,
run by :mod:`benchmarks.run` beside the likelihood phase (the helpers are passed in to keep one timing code)."""

from __future__ import annotations


def bench_learned(quick, fitted_model, make_demos, timed, row):
    """Learned timing (phase.learned) and LearnedInteraction at the reference size, beside the likelihood phase."""
    from interprim.models.learned import LearnedInteraction
    from interprim.phase.learned import LearnedPhase

    print("learned timing")
    demos = make_demos(30, 7, 7, 500, seed=0)
    test = make_demos(1, 7, 7, 500, seed=1000, stretch=(1.0, 1.0))[0]
    obs = [d[:, :7] for d in demos]
    t_fit = timed(lambda: LearnedPhase().fit(obs, dt=0.01), n=1 if quick else 3, warm=0)
    lp = LearnedPhase().fit(obs, dt=0.01)
    row("learned phase: fit (LOO-CV of its regressors)", "30 demos x 7 obs DoF x 500", t_fit)
    partial = test[:250, :7]
    ours = timed(lambda: lp.estimate(partial), min_time=0.3 if quick else 1.0)
    model, _ = fitted_model(phase_method="likelihood")
    peer = timed(lambda: estimate_phase_only(model, partial), min_time=0.3 if quick else 1.0)
    row("learned phase: estimate", "250 frames, 7 obs DoF", ours, "likelihood phase estimate (grid + Brent)", peer)

    def stream_step():
        tr = lp.tracker()
        for f in test[:250, :7]:
            tr.update(f)

    per = timed(stream_step, n=2 if quick else 5, warm=1) / 250
    row("learned phase: tracker.update, one frame", "7 obs DoF", per)
    t_fit2 = timed(lambda: LearnedInteraction(list(range(7))).fit(demos, dt=0.01), n=1, warm=0)
    li = LearnedInteraction(list(range(7))).fit(demos, dt=0.01)
    row("LearnedInteraction: fit (phase + coupling, CV)", "30 demos x 14 DoF x 500", t_fit2)
    row("LearnedInteraction: predict", "250 frames, 7+7 DoF", timed(lambda: li.predict(partial).trajectory(100),
                                                                    min_time=0.3 if quick else 1.0))
    bench_learned_stream(quick, make_demos, row)


def _per_frame(stream, frames, runs):
    """Per-frame wall times (s) of ``stream.update(frame).trajectory(100)`` over ``runs`` whole passes after one
    warm pass (the stream is reset before each), with the answers of the last pass."""
    import time

    import numpy as np

    out, preds = [], []
    for r in range(runs + 1):
        stream.reset()
        preds = []
        for f in frames:
            t0 = time.perf_counter()
            p = stream.update(f)
            p.trajectory(100)
            dt = time.perf_counter() - t0
            if r:
                out.append(dt)
            preds.append(p)
    return np.array(out), preds


def bench_learned_stream(quick, make_demos, row):
    """LearnedInteraction's stream (LearnedStream) beside the generic PrefixStream (predict of the whole prefix per
    frame, what its stream was) and the Interaction Primitive's stream, on the same data in one run: per-frame
    ``update + trajectory(100)`` over whole movements, medians."""
    import numpy as np

    from interprim.models.base import PrefixStream
    from interprim.models.learned import LearnedInteraction
    from interprim.models.primitive.estimator import InteractionPrimitive
    from interprim.synthetic import two_agent_demos

    print("learned interaction stream")
    cases = [("30 demos x 5 DoF (2 obs), synthetic", two_agent_demos(31, seed=0), [0, 1]),
             ("30 demos x 14 DoF (7 obs) x 200", make_demos(31, 7, 7, 200, seed=0), list(range(7)))]
    runs = 1 if quick else 3
    for size, demos, obs in cases:
        train, frames = demos[:30], demos[30][:, obs]
        li = LearnedInteraction(obs).fit(train, dt=0.01)
        ipm = InteractionPrimitive(observed_dofs=obs).fit(train, dt=0.01)
        new, pn = _per_frame(li.stream(), frames, runs)
        old, po = _per_frame(PrefixStream(li), frames, runs)
        ref, _ = _per_frame(ipm.stream(), frames, runs)
        same = all(np.array_equal(a.mean, b.mean) and np.array_equal(a.std_values, b.std_values)
                   for a, b in zip(pn, po))
        agree = "bitwise" if same else "NO"
        note = f"{li.coupling_.method_} coupling; {len(frames)} frames; agreement = new vs predict at every frame"
        row("LearnedInteraction stream: update + trajectory(100)", size, new, "the same model's PrefixStream", old,
            agree, note=note)
        row("LearnedInteraction stream: update + trajectory(100)", size, new, "InteractionPrimitive stream", ref,
            note="defaults of both; the IP's trajectory(100) integrates its DMPs")


def estimate_phase_only(model, partial):
    from interprim.phase.likelihood import estimate_phase

    return estimate_phase(model.fitted_, model.fitted_.observed_to_latent(partial))

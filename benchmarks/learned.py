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


def estimate_phase_only(model, partial):
    from interprim.phase.likelihood import estimate_phase

    return estimate_phase(model, model.observed_to_latent(partial))

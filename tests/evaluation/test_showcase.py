"""The showcase figures: the high-five animation (library defaults beside the paper's IP) and the real-time
figure of one held-out interaction (interprim.evaluation.realtime_plots).  Small cases; the numbers the
figures print are checked against direct ``predict`` calls."""

import math

import numpy as np
import pytest

PIL = pytest.importorskip("PIL.Image")  # matplotlib depends on Pillow


def _gif_frames(path):
    with PIL.open(path) as im:
        assert im.format == "GIF"
        return im.n_frames, im.size


def _png_ok(path):
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    with PIL.open(path) as im:
        im.verify()


# ----------------------------------------------------------------------------- simulated high five
@pytest.fixture(scope="module")
def highfive_case():
    import interprim as ip
    from interprim.experiments.highfive import HighFiveConfig
    from interprim.sim import highfive_split

    train, test = highfive_split(12, 1, seed=0, n_jobs=1, progress=False)
    cfg = HighFiveConfig.quick(gif_frames=12, n_jobs=1)
    default = ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=cfg.n_basis).fit(train.demos, dt=train.dt)
    paper = ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=cfg.n_basis, sigma2=100.0, observation="forcing",
                                    phase_method="dtw").fit(train.demos, dt=train.dt)
    return {"default": default, "paper": paper}, test, cfg


def test_highfive_animation_numbers_are_those_of_predict_on_the_whole_observation(highfive_case, tmp_path):
    from interprim.experiments.highfive_figures import animate, animation_states

    models, test, cfg = highfive_case
    path = tmp_path / "hf.gif"
    res = animate(models, test, 0, cfg, path)
    n, size = _gif_frames(path)
    assert n == res["n_frames"] == cfg.gif_frames
    assert size[0] > size[1]  # two panels side by side
    d, goal, ca = test.demos[0], test.goals[0], test.controlled_arm
    for key, model in models.items():
        pred = model.predict(d[:, :2])  # the whole observation, directly
        end = ca.hand(pred.trajectory(cfg.n_points)[-1, 2:])
        assert res[key]["phase"] == pytest.approx(pred.phase, abs=1e-12)
        assert res[key]["distance_m"] == pytest.approx(float(np.linalg.norm(end - goal)), abs=1e-9)
        assert res[key]["true_phase"] == 1.0
        at_true = ca.hand(model.predict(d[:, :2], phase=1.0).trajectory(cfg.n_points)[-1, 2:])
        assert res[key]["distance_at_true_phase_m"] == pytest.approx(float(np.linalg.norm(at_true - goal)), abs=1e-9)
    # the states behind the frames: every frame predicts from the frames seen; the robot ends at s = 1
    states = animation_states(models, test, 0, cfg, n_samples=2)
    assert len(states) == cfg.gif_frames
    ks = [s["k"] for s in states]
    assert ks[0] == 3 and np.all(np.diff(ks) >= 0) and ks[-1] == len(d)
    hold = [s for s in states if s["hold"]]
    assert hold and all(s["k"] == len(d) for s in hold)
    for key, model in models.items():
        s_robot = [s[key]["s_robot"] for s in hold]
        assert np.all(np.diff(s_robot) > 0) and s_robot[-1] == pytest.approx(1.0, abs=1e-12)
        k = states[2]["k"]  # an observed frame: the robot is at the mean at the estimated phase
        pred = model.predict(d[:k, :2])
        assert states[2][key]["phase"] == pytest.approx(pred.phase, abs=1e-12)
        assert states[2][key]["s_robot"] == pytest.approx(pred.phase, abs=1e-12)
        traj = pred.trajectory(cfg.n_points)
        grid = np.linspace(0, 1, cfg.n_points)
        q = [np.interp(pred.phase, grid, traj[:, c]) for c in range(2, 5)]
        np.testing.assert_allclose(states[2][key]["q"], q, atol=1e-12)
        assert states[2][key]["cloud"].shape[0] == 2


def test_highfive_animation_text_is_legible_at_display_size(highfive_case, tmp_path, monkeypatch):
    """Every text of the GIF (titles, ticks, legend, the numbers) is at least 11 px high at its own size."""
    import interprim.experiments.highfive_figures as hff

    models, test, cfg = highfive_case
    seen = {}

    def capture(fig, canvas, dynamic, states, draw, path, fps):
        draw(states[-1])
        canvas.draw()  # tick labels get their text when drawn
        seen["fig"] = fig

    monkeypatch.setattr(hff, "_write_gif", capture)
    hff.animate(models, test, 0, cfg, tmp_path / "hf.gif")
    fig = seen["fig"]
    texts = [t for t in fig.findobj(lambda a: hasattr(a, "get_fontsize") and hasattr(a, "get_text"))
             if t.get_text().strip() and t.get_visible()]
    assert len(texts) > 20  # titles, tick labels, legend entries, the numbers of each panel
    small = sorted({(t.get_fontsize() * fig.dpi / 72, t.get_text()[:30]) for t in texts})[:3]
    assert small[0][0] >= 11, small


def test_fig6_names_its_model_and_fig8_shows_every_row_of_its_table(highfive_case, tmp_path, monkeypatch):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from interprim.experiments.highfive_common import METHOD_LABELS
    from interprim.experiments.highfive_figures import plot_fig6, plot_fig8

    models, test, cfg = highfive_case
    figs = []
    monkeypatch.setattr(plt, "close", lambda fig=None: figs.append(fig))
    plot_fig6(models["paper"], test, 0, cfg, tmp_path / "f6.png")
    assert "drawn by the paper's IP (forcing values, DTW phase" in figs[-1]._suptitle.get_text()
    n = len(test.goals)
    rng = np.random.default_rng(0)
    methods = ("ip", "ip_likelihood", "ip_default", "nn", "prior")
    ev = {"pred_goals": {m: rng.uniform(0.3, 0.9, (n, 1, 2)) for m in methods},
          "goal_err": {m: np.full((n, 1), 0.01 * (i + 1)) for i, m in enumerate(methods)}}
    plot_fig8(ev, test, type("C", (), {"percents": (60,)})(), tmp_path / "f8.png", percent=60)
    labels = [t.get_text() for t in figs[-1].axes[0].get_legend().get_texts()]
    for i, m in enumerate(methods):
        assert any(lab.endswith(f"{METHOD_LABELS[m]}: {i + 1:.1f} cm") for lab in labels), (m, labels)


def test_highfive_animation_needs_a_known_panel(highfive_case, tmp_path):
    from interprim.experiments.highfive_figures import animate

    _, test, cfg = highfive_case
    with pytest.raises(ValueError, match="default"):
        animate({"mine": None}, test, 0, cfg, tmp_path / "x.gif")


# ----------------------------------------------------------------------------- real-time figure
def _two_people(n=10, seed=3):
    """Small 3-D two-person demonstrations: the observed arm (shoulder, hand) and the partner's hand, each in its
    own frame (x forward, z up), reaching up together with random amplitude and duration."""
    rng = np.random.default_rng(seed)
    demos = []
    for _ in range(n):
        T = int(rng.integers(26, 36))
        s = np.linspace(0, 1, T)
        amp = rng.uniform(0.3, 0.5)
        lift = amp * np.sin(np.pi * np.clip(1.2 * s - 0.1, 0, 1))
        shoulder = np.zeros((T, 3)) + rng.normal(0, 2e-3, (T, 3))
        hand = np.stack([0.2 + 0.3 * lift, -0.1 + 0 * s, -0.5 + lift], axis=1) + rng.normal(0, 2e-3, (T, 3))
        partner = np.stack([0.15 + 0.35 * lift, -0.1 + 0 * s, -0.55 + 1.1 * lift], axis=1) + rng.normal(0, 2e-3, (T, 3))
        demos.append(np.concatenate([shoulder, hand, partner], axis=1))
    return demos


@pytest.fixture(scope="module")
def realtime_case():
    import interprim as ip

    demos = _two_people()
    train, test = demos[1:], demos[0]
    obs = list(range(6))
    models = {"defaults": ip.InteractionPrimitive(observed_dofs=obs, n_basis=8).fit(train, dt=0.05),
              "learned": ip.InteractionPrimitive(observed_dofs=obs, n_basis=8, sigma2=1e-3,
                                                 phase_method="learned").fit(train, dt=0.05)}
    return models, train, test, obs


@pytest.mark.slow  # renders a GIF
def test_realtime_figure_writes_gif_and_png_with_the_protocol_numbers(realtime_case, tmp_path):
    from interprim.evaluation.realtime import RealTimeConfig, realtime_fold, summarise_realtime
    from interprim.evaluation.realtime_plots import realtime_interaction_figure

    models, train, test, obs = realtime_case
    res = realtime_interaction_figure(models, train, test, obs, 0.05, tmp_path / "rt.gif", tmp_path / "rt.png",
                                      n_frames=8, snapshots=(0.4, 0.8))
    n, size = _gif_frames(tmp_path / "rt.gif")
    assert n == res["n_frames"] == 8
    assert size[0] > size[1]
    _png_ok(tmp_path / "rt.png")
    assert set(res["files"]) == {"gif", "png"}
    cfg = RealTimeConfig(point_dim=3)
    for label, model in models.items():
        summ = summarise_realtime(realtime_fold(model, train, test, obs, 0.05, cfg, name=label, fitted=True))
        got = res["models"][label]
        assert got["rt_ctrl"] == summ[label]["rt_ctrl"] and got["clock_rt_ctrl"] == summ["clock"]["rt_ctrl"]
        assert got["rt_ctrl_vs_clock"] == pytest.approx(got["rt_ctrl"] / got["clock_rt_ctrl"], rel=1e-12)
        assert 0 <= got["cov_ctrl"] <= 1 and math.isfinite(got["z_ctrl"])
        k0, k1 = math.ceil(0.2 * len(test)), math.floor(0.9 * len(test))
        assert got["n_evaluated"] == k1 - k0 + 1


def test_realtime_trace_matches_a_direct_prediction(realtime_case):
    """The error drawn for a frame is the point RMS, over the next 0.25 s, of predict() placed in time by its own
    phase and duration; the clock's is the training mean played at the mean duration (computed here by hand)."""
    from interprim.core.preprocessing import time_normalise
    from interprim.evaluation.realtime import RealTimeConfig, realtime_fold

    models, train, test, obs = realtime_case
    dt, k = 0.05, 14
    T = len(test)
    H = 5  # 0.25 s at 20 Hz
    cfg = RealTimeConfig(point_dim=3)
    recs = realtime_fold(models["defaults"], train, test, obs, dt, cfg, name="m", fitted=True, frames=[k], trace=True)
    rec = {r["method"]: r for r in recs}
    plain = {r["method"]: r for r in realtime_fold(models["defaults"], train, test, obs, dt, cfg, name="m",
                                                   fitted=True, frames=[k])}
    assert rec["m"]["rt_ctrl"] == plain["m"]["rt_ctrl"]  # tracing changes nothing
    pred = models["defaults"].predict(test[:k, obs])
    grid = np.linspace(0, 1, cfg.n_grid)
    Y = pred.trajectory(cfg.n_grid)
    u = np.clip(pred.normalised_time + dt * np.arange(1, H + 1) / pred.duration, 0, 1)
    mean = np.stack([np.interp(u, grid, Y[:, c]) for c in range(9)], axis=1)
    truth = test[np.minimum(np.arange(k, k + H), T - 1)]
    rms = math.sqrt(np.mean(np.sum((mean[:, 6:] - truth[:, 6:]) ** 2, axis=1)))
    assert rec["m"]["rt_ctrl"] == pytest.approx(rms, rel=1e-10)
    np.testing.assert_allclose(rec["m"]["mean"], mean, atol=1e-12)
    np.testing.assert_allclose(rec["m"]["truth"], truth, atol=0)
    M = np.mean([time_normalise(d, cfg.n_grid) for d in train], axis=0)
    dur = np.mean([len(d) - 1 for d in train]) * dt
    uc = np.clip(((k - 1) * dt + dt * np.arange(1, H + 1)) / dur, 0, 1)
    clock = np.stack([np.interp(uc, grid, M[:, c]) for c in range(9)], axis=1)
    rms_c = math.sqrt(np.mean(np.sum((clock[:, 6:] - truth[:, 6:]) ** 2, axis=1)))
    assert rec["clock"]["rt_ctrl"] == pytest.approx(rms_c, rel=1e-10)


def test_realtime_figure_rejects_bad_input(realtime_case, tmp_path):
    from interprim.evaluation.realtime import realtime_fold
    from interprim.evaluation.realtime_plots import realtime_interaction_figure

    models, train, test, obs = realtime_case
    with pytest.raises(ValueError, match="whole points"):
        realtime_interaction_figure(models, train, test, obs[:5], 0.05)
    with pytest.raises(ValueError, match="view"):
        realtime_interaction_figure(models, train, test, obs, 0.05, view=(0, 3))
    with pytest.raises(ValueError, match="at least one"):
        realtime_interaction_figure({}, train, test, obs, 0.05)
    with pytest.raises(ValueError, match="frames"):
        realtime_fold(models["defaults"], train, test, obs, 0.05, frames=[len(test) + 1], fitted=True)


# ----------------------------------------------------------------------------- NuiSI (the shared data)
def _nuisi():
    try:
        from interprim.datasets import nuisi_actions

        return nuisi_actions()
    except FileNotFoundError:
        return None


needs_nuisi = pytest.mark.skipif(_nuisi() is None, reason="NuiSI data (../shared/data or $INTERPRIM_DATA) not found")


@pytest.mark.slow  # fits on NuiSI, renders a GIF
@needs_nuisi
def test_nuisi_realtime_figure_holds_the_recording_out(tmp_path):
    from interprim.evaluation.realtime_plots import nuisi_realtime_figure

    # a fast model (fixed sigma2: no cross-validation, no calibration), the learned phase; the figure code is the
    # same as the demo's
    res = nuisi_realtime_figure("highfive1", 2, tmp_path, n_frames=10, methods={"fast": {"sigma2": 1e-3,
                                                                                        "phase_method": "learned"}})
    from interprim.evaluation.nested import split_holdout

    n_dev = len(split_holdout(_nuisi()["highfive1"])[0])
    assert res["n_train"] == n_dev - 1 and res["demo"] == 2  # the other development recordings only
    n, _ = _gif_frames(tmp_path / "nuisi_highfive1_02_realtime.gif")
    assert n == res["n_frames"] == 10
    _png_ok(tmp_path / "nuisi_highfive1_02_realtime.png")
    m = res["models"]["fast"]
    assert 0 < m["rt_ctrl"] < 1 and 0 < m["clock_rt_ctrl"] < 1  # metres
    with pytest.raises(ValueError, match="demo must be"):
        nuisi_realtime_figure("highfive1", 99, tmp_path, gif=False, png=False)
    with pytest.raises(ValueError, match="untouched hold-out"):  # a hold-out recording is refused
        nuisi_realtime_figure("highfive1", n_dev, tmp_path, gif=False, png=False)


@needs_nuisi
def test_demo_nuisi_flag_is_checked_before_the_run(capsys, tmp_path):
    from interprim.cli import main

    assert main(["demo", "--quick", "--quiet", "--out", str(tmp_path), "--nuisi", "dance"]) == 1
    err = capsys.readouterr().err
    assert "--nuisi" in err and "dance" in err and "highfive1" in err
    assert main(["demo", "--quick", "--quiet", "--out", str(tmp_path), "--nuisi", "wave1", "--nuisi-demo", "27"]) == 1
    assert "--nuisi-demo" in capsys.readouterr().err
    assert not any(tmp_path.iterdir())  # nothing ran


@pytest.mark.slow  # the demo's NuiSI section end to end (about a minute)
@needs_nuisi
def test_demo_nuisi_section(monkeypatch, tmp_path, capsys):
    """What ``interprim demo --nuisi`` adds: the figure files, nuisi_realtime.json and a report section whose numbers
    are the figure's (fast models patched in; the code path is the demo's)."""
    import json

    from interprim.cli.demo import _nuisi_figure
    from interprim.evaluation import realtime_plots

    monkeypatch.setattr(realtime_plots, "NUISI_FIGURE_METHODS", {"fast": {"sigma2": 1e-3}})
    (tmp_path / "report.md").write_text("# earlier part\n")
    files = _nuisi_figure("wave1", 1, tmp_path)
    assert files == {"nuisi_gif": "nuisi_wave1_01_realtime.gif", "nuisi_png": "nuisi_wave1_01_realtime.png",
                     "nuisi_results": "nuisi_realtime.json"}
    r = json.loads((tmp_path / "nuisi_realtime.json").read_text())
    m = r["models"]["fast"]
    report = (tmp_path / "report.md").read_text()
    assert report.startswith("# earlier part\n")
    line = (f"fast: {100 * m['rt_ctrl']:.1f} cm vs clock {100 * m['clock_rt_ctrl']:.1f} cm "
            f"({m['rt_ctrl_vs_clock']:.2f}x)")
    assert line in report and line in capsys.readouterr().out
    assert "![gif](nuisi_wave1_01_realtime.gif)" in report
    n, _ = _gif_frames(tmp_path / "nuisi_wave1_01_realtime.gif")
    assert n == r["n_frames"] <= 60

"""Figures of the simulated high-five experiments (paper Sec. IV, Fig. 5-8) and the animation.

Drawn by :func:`interprim.experiments.highfive.run_highfive` (matplotlib: the ``plot`` extra).
"""

from __future__ import annotations

import numpy as np

from ..core.preprocessing import interp_columns
from .highfive_common import METHOD_LABELS, METHODS, goal_spread, n_observed


def _draw_arm(ax, arm, q, **kw):
    pts = arm.forward_kinematics(q)
    (line,) = ax.plot(pts[:, 0], pts[:, 1], "-o", lw=kw.pop("lw", 3), ms=kw.pop("ms", 5), **kw)
    return line


def _goal_box_patches(ax):
    from matplotlib.patches import Rectangle

    from ..sim.highfive import GOAL_BOX, GRID, TEST_CELLS

    (x0, x1), (y0, y1) = GOAL_BOX
    ax.add_patch(Rectangle((x0, y0), x1 - x0, y1 - y0, fill=False, ls="--", lw=0.8, ec="0.4"))
    cw, ch = (x1 - x0) / GRID[0], (y1 - y0) / GRID[1]
    for k, (cx, cy) in enumerate(TEST_CELLS):
        ax.add_patch(
            Rectangle(
                (x0 + cx * cw, y0 + cy * ch), cw, ch, fc="tab:red", alpha=0.18, ec="tab:red", lw=0.6, zorder=5,
                label="held-out (test) goal region" if k == 0 else None,
            )
        )


def _setup_axes(ax, title=None):
    ax.set_aspect("equal")
    ax.set_xlim(-0.25, 1.85)
    ax.set_ylim(-1.45, 0.95)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    if title:
        ax.set_title(title, fontsize=10)


def plot_setup(train, test, path):
    """Fig. 5: the two arms, the training hand paths, goals and attractors."""
    import matplotlib.pyplot as plt

    oa, ca = train.observed_arm, train.controlled_arm
    fig, ax = plt.subplots(figsize=(6.4, 6.0))
    _goal_box_patches(ax)
    for i in range(len(train)):
        ho, hc = train.hands(i)
        ax.plot(ho[:, 0], ho[:, 1], color="tab:blue", lw=0.5, alpha=0.35)
        ax.plot(hc[:, 0], hc[:, 1], color="tab:green", lw=0.5, alpha=0.35)
    ax.plot(*train.attractors[:, 0].T, "x", color="tab:blue", ms=3, alpha=0.6, label="attractors (observed)")
    ax.plot(*train.attractors[:, 1].T, "x", color="tab:green", ms=3, alpha=0.6, label="attractors (controlled)")
    ax.plot(*train.goals.T, "k.", ms=4, label="training goals")
    ax.plot(*test.goals.T, "o", mfc="none", mec="tab:red", ms=5, label="test goals")
    _draw_arm(ax, oa, oa.rest, color="tab:blue", alpha=0.35)
    _draw_arm(ax, ca, ca.rest, color="tab:green", alpha=0.35)
    _draw_arm(ax, oa, train.demos[0][-1, :2], color="tab:blue", label="observed agent (2 links)")
    _draw_arm(ax, ca, train.demos[0][-1, 2:], color="tab:green", label="controlled agent (3 links)")
    _setup_axes(ax, f"Simulated high-five (Fig. 5): {len(train)} optimal-control demonstrations")
    ax.legend(loc="upper left", fontsize=6.5, ncol=1, framealpha=0.9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_fig6(model, test, idx, cfg, path, percents=(40, 60), model_label=None):
    """Fig. 6: posterior samples of the controlled agent's task-space trajectory; returns goal spreads (m).

    ``model_label`` names the model that drew the samples in the figure's title (default: the paper's IP)."""
    import matplotlib.pyplot as plt

    oa, ca = test.observed_arm, test.controlled_arm
    d = test.demos[idx]
    fig, axes = plt.subplots(1, len(percents), figsize=(5.2 * len(percents), 4.8), sharey=True)
    spreads = []
    for ax, p in zip(np.atleast_1d(axes), percents):
        k = n_observed(len(d), p)
        pred = model.predict(d[:k, :2])
        S = pred.samples(cfg.n_samples, cfg.n_points, random_state=cfg.seed)
        spread, ends = goal_spread(S[:, :, 2:], ca)
        spreads.append(spread)
        hands = ca.hand(S[:, :, 2:])
        for h in hands:
            ax.plot(h[:, 0], h[:, 1], color="tab:red", lw=0.7, alpha=0.45)
        ax.plot(*ends.T, ".", color="darkred", ms=4)
        mean_h = ca.hand(pred.trajectory(cfg.n_points)[:, 2:])
        ax.plot(mean_h[:, 0], mean_h[:, 1], color="darkred", lw=2, label="posterior mean")
        true_h = ca.hand(d[:, 2:])
        ax.plot(true_h[:, 0], true_h[:, 1], "k--", lw=1.2, label="ground truth (controlled)")
        obs_h = oa.hand(d[:k, :2])
        ax.plot(obs_h[:, 0], obs_h[:, 1], color="tab:blue", lw=2.5, label=f"observed {p} %")
        _draw_arm(ax, oa, d[k - 1, :2], color="tab:blue", alpha=0.6)
        _draw_arm(ax, ca, ca.rest, color="tab:green", alpha=0.6)
        ax.plot(*test.goals[idx], "o", mfc="none", mec="k", ms=10, mew=1.5, label="true goal")
        _setup_axes(ax, f"{p} % observed: goal spread {100 * spread:.1f} cm ({cfg.n_samples} samples)")
        ax.legend(loc="lower center", fontsize=7)
    label = model_label or "paper's IP (forcing values, DTW phase, σ² on a validation set)"
    fig.suptitle(f"Fig. 6: posterior samples of the robot's hand path drawn by the {label}", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return spreads


def plot_fig7(ev, cfg, path):
    """Fig. 7: MSE vs % observed for both agents, IP and baselines (mean, shaded inter-quartile range)."""
    import matplotlib.pyplot as plt

    P = np.asarray(cfg.percents)
    styles = {
        "ip": dict(color="tab:red", lw=2.2),
        "ip_likelihood": dict(color="tab:orange", lw=1.8),
        "ip_known_phase": dict(color="tab:red", lw=1.0, ls="--"),
        "ip_default": dict(color="tab:green", lw=1.8),
        "prior": dict(color="0.45", lw=1.5, ls=":"),
        "nn": dict(color="tab:purple", lw=1.5, ls="-."),
        "promp": dict(color="tab:cyan", lw=1.5, ls="-", marker="s"),
    }
    fig, axes = plt.subplots(1, 2, figsize=(10.5, 4.2))
    for ax, key, title in zip(axes, ("mse_obs", "mse_ctrl"),
                              ("observed agent (prediction)", "controlled agent (inferred response)")):
        for m in METHODS:
            a = ev[key][m]
            if np.all(np.isnan(a)):
                continue
            st = dict(styles[m])
            ax.plot(P, np.nanmean(a, axis=0), marker=st.pop("marker", "o"), ms=3, label=METHOD_LABELS[m], **st)
            if m in ("ip", "nn"):
                ax.fill_between(P, np.nanpercentile(a, 25, axis=0), np.nanpercentile(a, 75, axis=0),
                                color=styles[m]["color"], alpha=0.12, lw=0)
        ax.set_xlabel("% of the observed agent's movement seen")
        ax.set_ylabel("MSE of joint angles [rad$^2$]")
        ax.set_title(title, fontsize=10)
        ax.set_xticks(P)
        ax.set_yscale("log")  # the methods span two orders of magnitude
        ax.grid(alpha=0.3, which="both")
    axes[0].legend(fontsize=8)
    fig.suptitle(f"Fig. 7: mean over {ev['mse_obs']['ip'].shape[0]} held-out interactions (band: 25-75 %)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def plot_fig8(ev, test, cfg, path, percent=60):
    """Fig. 8: true (blue) vs predicted (red) high-five points at ``percent`` observed."""
    import matplotlib.pyplot as plt

    j = list(cfg.percents).index(percent)
    pg = ev["pred_goals"]["ip"][:, j]
    fig, ax = plt.subplots(figsize=(8.4, 4.8))
    _goal_box_patches(ax)
    for t, p in zip(test.goals, pg):
        ax.plot([t[0], p[0]], [t[1], p[1]], color="0.6", lw=0.8)
    ax.plot(*test.goals.T, "o", mfc="none", mec="tab:blue", ms=8, mew=1.5, label="true goal")
    dist = ev["goal_err"]["ip"][:, j]
    ax.plot(*pg.T, "o", mfc="none", mec="tab:red", ms=8, mew=1.5,
            label=f"predicted, {METHOD_LABELS['ip']}: {100 * np.mean(dist):.1f} cm")
    for name, mk, col in (("ip_likelihood", "x", "tab:orange"), ("ip_default", "+", "tab:green"),
                          ("nn", "^", "tab:purple"), ("prior", "s", "0.35")):
        pgm = ev["pred_goals"].get(name)
        if pgm is not None and not np.all(np.isnan(pgm)):
            dl = ev["goal_err"][name][:, j]
            style = dict(mfc="none", mec=col) if mk in "^s" else dict(color=col)
            ax.plot(*pgm[:, j].T, mk, ms=7, mew=1.5, **style,
                    label=f"{'' if name == 'prior' else 'predicted, '}{METHOD_LABELS[name]}: "
                          f"{100 * np.mean(dl):.1f} cm")
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(f"Fig. 8: goals at {percent} % observed (FK of inferred goal joint angles)", fontsize=9)
    ax.legend(fontsize=7.5, loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


#: Panels of the animation: (key of the ``models`` argument of :func:`animate`, name, details, colour).
ANIMATION_PANELS = (
    ("default", "library defaults", "positions, CV σ², likelihood phase", "tab:green"),
    ("paper", "the paper's IP", "forcing values, DTW phase", "tab:red"),
)


def _interp_rows(s, grid, Y):
    """Rows of ``Y`` (on the normalised-time ``grid``) at ``s`` (a scalar, clipped to [0, 1])."""
    return interp_columns(min(max(float(s), 0.0), 1.0), grid, Y)


def animation_states(models, test, idx, cfg, n_frames=None, n_samples=8):
    """What :func:`animate` draws, frame by frame: batch predictions from the growing observation.

    Observed frames: ``k = 3 .. T`` (evenly spread, the last one ``T``); for every model and frame,
    ``model.predict(d[:k, :2])`` (the same call as the Fig. 7 evaluation), the robot arm at the posterior
    mean at the estimated phase, ``n_samples`` posterior samples (same random draws in every frame) and
    the predicted hand path.  Then a few *hold* frames: the human has stopped and the robot completes its
    predicted response from the estimated phase to the end (``s = 1``) with the last prediction.  The
    robot hand--goal distance is that of the drawn robot hand (forward kinematics) from the true
    high-five point; in the last frame it is the distance of the end of the predicted response.

    Returns
    -------
    states : list of dict
        One per frame: ``k`` (frames seen), ``hold`` (bool) and, per model key, ``phase``, ``s_robot``
        (where on the predicted response the robot is), ``q`` (robot joint angles), ``hand``, ``dist``
        (m), ``path`` (predicted hand path from ``s_robot`` to the end), ``cloud`` (sampled hand paths)
        and ``end`` (predicted end of the hand).
    """
    ca = test.controlled_arm
    d = test.demos[idx]
    T = len(d)
    n_frames = int(cfg.gif_frames if n_frames is None else n_frames)
    n_hold = max(2, n_frames // 8)
    ks = np.unique(np.linspace(3, T, max(2, n_frames - n_hold)).round().astype(int))
    grid = np.linspace(0.0, 1.0, cfg.n_points)
    goal = np.asarray(test.goals[idx], dtype=float)
    states = []
    last = {}
    for k in ks:
        st = {"k": int(k), "hold": False}
        for key, model in models.items():
            pred = model.predict(d[:k, :2])
            traj = pred.trajectory(cfg.n_points)
            S = pred.samples(n_samples, cfg.n_points, random_state=cfg.seed) if n_samples else None
            last[key] = (pred.phase, traj, S)
            st[key] = _panel_state(ca, goal, grid, pred.phase, pred.phase, traj, S)
        states.append(st)
    for j in range(1, n_hold + 1):  # the human has stopped; the robot finishes its predicted response
        st = {"k": T, "hold": True}
        for key, (ph, traj, S) in last.items():
            st[key] = _panel_state(ca, goal, grid, ph, ph + (1.0 - ph) * j / n_hold, traj, S)
        states.append(st)
    return states


def _panel_state(ca, goal, grid, phase, s_robot, traj, S):
    q = _interp_rows(s_robot, grid, traj[:, 2:])
    hand = ca.hand(q)
    fut = grid >= s_robot - 1e-12
    hp = ca.hand(traj[:, 2:])
    return {
        "phase": float(phase), "s_robot": float(s_robot), "q": q, "hand": hand,
        "dist": float(np.linalg.norm(hand - goal)),
        "path": np.vstack([hand, hp[fut]]), "end": hp[-1],
        "cloud": None if S is None else ca.hand(S[:, fut, 2:]),
    }


def animate(models, test, idx, cfg, path, fps=15, n_samples=8):
    """GIF: the library's defaults beside the paper's IP on one held-out simulated high five.

    Each panel replays the observed (human) arm of test interaction ``idx``; the controlled (robot) arm
    follows the posterior-mean response of that panel's model at its estimated phase, predicted from the
    frames seen so far; the faint cloud is ``n_samples`` posterior samples of the robot's hand path (their
    spread is the model's predictive uncertainty), the dashed curve the mean path still to come.  After
    the human's last frame the robot completes its predicted response (see :func:`animation_states`).

    Parameters
    ----------
    models : dict
        ``{"default": fitted model, "paper": fitted model}`` (keys of :data:`ANIMATION_PANELS`; a missing
        key drops its panel).
    test : HighFiveData
    idx : int
        Test interaction shown.
    cfg : HighFiveConfig
        ``gif_frames`` (frames of the GIF), ``n_points``, ``seed``.
    path : str or Path
        Where the GIF is written.

    Returns
    -------
    dict
        ``test_index``, ``n_frames`` and, per panel key, the numbers of the last frame: ``phase`` (estimated
        with all frames seen), ``true_phase`` (1), ``distance_m`` (robot hand at the end of its predicted
        response to the true high-five point), ``distance_at_true_phase_m`` (the same with the model conditioned
        at the true phase instead of its estimate) and ``label``.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D

    panels = [p for p in ANIMATION_PANELS if p[0] in models]
    if not panels:
        raise ValueError(f"models must contain some of {[p[0] for p in ANIMATION_PANELS]}, got {list(models)}")
    states = animation_states({p[0]: models[p[0]] for p in panels}, test, idx, cfg, n_samples=n_samples)
    oa, ca = test.observed_arm, test.controlled_arm
    d = test.demos[idx]
    T = len(d)
    obs_hand = oa.hand(d[:, :2])
    goal = test.goals[idx]

    fig = Figure(figsize=(3.95 * len(panels), 4.6), dpi=100)  # every text >= 8.5 pt = 11.8 px at 100 dpi
    canvas = FigureCanvasAgg(fig)
    axes = fig.subplots(1, len(panels), squeeze=False)
    art = {}
    for ax, (key, name, details, col) in zip(axes[0], panels):
        _setup_axes(ax, f"{name}\n({details})")
        ax.set_xlim(-0.2, 1.8)
        ax.set_ylim(-1.35, 0.95)
        ax.plot(*goal, "o", mfc="none", mec="k", ms=11, mew=1.5, zorder=6)
        cloud = [ax.plot([], [], color=col, lw=0.6, alpha=0.3)[0] for _ in range(n_samples)]
        (trace,) = ax.plot([], [], color="tab:blue", lw=1)
        obs_line = _draw_arm(ax, oa, d[0, :2], color="tab:blue")
        ctrl_line = _draw_arm(ax, ca, ca.rest, color=col)
        (path_line,) = ax.plot([], [], "--", color=col, lw=1.2)
        (end_pt,) = ax.plot([], [], "x", color=col, ms=9, mew=2)
        txt = ax.text(0.02, 0.98, "", transform=ax.transAxes, va="top", fontsize=8.5)
        art[key] = (cloud, trace, obs_line, ctrl_line, path_line, end_pt, txt)
    handles = [Line2D([], [], ls="", marker="o", mfc="none", mec="k", ms=9, mew=1.5, label="true high-five point"),
               Line2D([], [], color="tab:blue", lw=3, marker="o", ms=5, label="human (replayed; its hand's path)")]
    handles += [Line2D([], [], color=col, lw=3, marker="o", ms=5, label=f"robot, {name}: predicted mean")
                for _, name, _, col in panels]
    handles += [Line2D([], [], color="0.3", ls="--", lw=1.2, label="predicted hand path to come (x: its end)"),
                Line2D([], [], color="0.3", lw=0.6, alpha=0.4, label=f"{n_samples} posterior samples of it")]
    fig.legend(handles=handles, loc="lower center", ncol=2, fontsize=8.5, frameon=False)
    fig.subplots_adjust(left=0.07, right=0.99, top=0.9, bottom=0.25, wspace=0.18)

    def draw(st):
        k = st["k"]
        po = oa.forward_kinematics(d[k - 1, :2])
        for key, *_ in panels:
            cloud, trace, obs_line, ctrl_line, path_line, end_pt, txt = art[key]
            ps = st[key]
            obs_line.set_data(po[:, 0], po[:, 1])
            trace.set_data(obs_hand[:k, 0], obs_hand[:k, 1])
            pc = ca.forward_kinematics(ps["q"])
            ctrl_line.set_data(pc[:, 0], pc[:, 1])
            path_line.set_data(ps["path"][:, 0], ps["path"][:, 1])
            end_pt.set_data([ps["end"][0]], [ps["end"][1]])
            for i, line in enumerate(cloud):
                c = ps["cloud"][i] if ps["cloud"] is not None else np.empty((0, 2))
                line.set_data(c[:, 0], c[:, 1])
            note = "human stopped: robot completes its response" if st["hold"] else ""
            txt.set_text(f"seen {100 * k / T:.0f} %: phase {ps['phase']:.2f} (true {(k - 1) / (T - 1):.2f})\n"
                         f"robot hand–goal distance {100 * ps['dist']:.1f} cm\n{note}")

    # the static part (axes, titles, legend) is rendered once; each frame redraws only what moves
    dynamic = [a for v in art.values() for a in (*v[0], *v[1:])]
    _write_gif(fig, canvas, dynamic, states, draw, path, fps)
    final = states[-1]
    out = {"test_index": int(idx), "n_frames": len(states)}
    for key, name, details, _ in panels:
        at_true = models[key].predict(d[:, :2], phase=1.0).trajectory(cfg.n_points)  # what the phase estimate costs
        out[key] = {"label": f"{name} ({details})", "phase": final[key]["phase"], "true_phase": 1.0,
                    "distance_m": final[key]["dist"],
                    "distance_at_true_phase_m": float(np.linalg.norm(ca.hand(at_true[-1, 2:]) - goal))}
    return out


def _write_gif(fig, canvas, dynamic, states, draw, path, fps):
    """Write one GIF frame per state: the figure without the ``dynamic`` artists is rendered once, then per
    frame it is restored, ``draw(state)`` updates the artists and only they are drawn (blitting)."""
    from PIL import Image  # a dependency of matplotlib

    for a in dynamic:
        a.set_animated(True)
    canvas.draw()
    background = canvas.copy_from_bbox(fig.bbox)
    frames = []
    for st in states:
        canvas.restore_region(background)
        draw(st)
        for a in dynamic:
            fig.draw_artist(a)
        frames.append(Image.fromarray(np.asarray(canvas.buffer_rgba())[..., :3].copy()))
    frames[0].save(str(path), save_all=True, append_images=frames[1:], duration=int(round(1000 / fps)), loop=0)

"""Figures of the simulated high-five experiments (paper Sec. IV, Fig. 5-8) and the animation.

Drawn by :func:`interprim.experiments.highfive.run_highfive` (matplotlib: the ``plot`` extra).
"""

from __future__ import annotations

import numpy as np

from .highfive_common import METHOD_LABELS, METHODS, _goal_spread, _n_observed

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


def plot_fig6(model, test, idx, cfg, path, percents=(40, 60)):
    """Fig. 6: posterior samples of the controlled agent's task-space trajectory; returns goal spreads (m)."""
    import matplotlib.pyplot as plt

    oa, ca = test.observed_arm, test.controlled_arm
    d = test.demos[idx]
    fig, axes = plt.subplots(1, len(percents), figsize=(5.2 * len(percents), 4.8), sharey=True)
    spreads = []
    for ax, p in zip(np.atleast_1d(axes), percents):
        k = _n_observed(len(d), p)
        pred = model.predict(d[:k, :2])
        S = pred.samples(cfg.n_samples, cfg.n_points, random_state=cfg.seed)
        spread, ends = _goal_spread(S[:, :, 2:], ca)
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
    for ax, key, title in zip(axes, ("mse_obs", "mse_ctrl"), ("observed agent (prediction)", "controlled agent (inferred response)")):
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
    for name, mk, col in (("ip_likelihood", "x", "tab:orange"), ("ip_default", "+", "tab:green")):
        pgm = ev["pred_goals"].get(name)
        if pgm is not None and not np.all(np.isnan(pgm)):
            dl = ev["goal_err"][name][:, j]
            ax.plot(*pgm[:, j].T, mk, color=col, ms=7, mew=1.5,
                    label=f"predicted, {METHOD_LABELS[name]}: {100 * np.mean(dl):.1f} cm")
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(f"Fig. 8: goals at {percent} % observed (FK of inferred goal joint angles)", fontsize=9)
    ax.legend(fontsize=7.5, loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def animate(model, test, idx, cfg, path, fps=15):
    """GIF: the observed arm replays a test interaction; the controlled arm follows the IP's online response.

    The controlled arm is driven by ``model.stream()``: after every observed frame the
    prediction is updated, and the arm tracks the posterior-mean response at the
    estimated phase (first-order tracking, time constant ~3 frames).  The dashed red
    curve is the currently predicted hand path, the red cross the predicted goal.
    """
    import matplotlib.pyplot as plt
    from matplotlib.animation import PillowWriter

    oa, ca = test.observed_arm, test.controlled_arm
    d = test.demos[idx]
    T = len(d)
    n_hold = max(3, T // 10)
    stream = model.stream()
    q_ctrl = ca.rest.copy()
    states = []
    s_grid = np.linspace(0.0, 1.0, cfg.n_points)
    pred = None
    for t in range(T + n_hold):
        if t < T:
            try:  # the mean is enough here; skip the posterior covariance where the core allows it
                pred = stream.update(d[t, :2], need_cov=False)
            except TypeError:
                pred = stream.update(d[t, :2])
        traj = pred.trajectory(cfg.n_points)
        target = np.array([np.interp(min(pred.phase, 1.0) if t < T else 1.0, s_grid, traj[:, c]) for c in range(2, 5)])
        q_ctrl = q_ctrl + 0.35 * (target - q_ctrl)
        states.append((min(t, T - 1), q_ctrl.copy(), ca.hand(traj[:, 2:]), ca.hand(pred.goal[2:]), pred.phase))
    sel = np.unique(np.linspace(0, len(states) - 1, max(2, cfg.gif_frames)).round().astype(int))

    fig, ax = plt.subplots(figsize=(4.4, 4.4))
    _setup_axes(ax)
    ax.set_title("IP controls the right arm online", fontsize=9)
    ax.plot(*test.goals[idx], "o", mfc="none", mec="k", ms=10, label="true high-five point")
    obs_line = _draw_arm(ax, oa, d[0, :2], color="tab:blue", label="observed (replayed)")
    ctrl_line = _draw_arm(ax, ca, ca.rest, color="tab:green", label="controlled (IP)")
    (trace,) = ax.plot([], [], color="tab:blue", lw=1)
    (path_line,) = ax.plot([], [], "--", color="tab:red", lw=1, label="predicted hand path")
    (goal_pt,) = ax.plot([], [], "x", color="tab:red", ms=9, mew=2)
    txt = ax.text(0.02, 0.97, "", transform=ax.transAxes, va="top", fontsize=8)
    ax.legend(loc="lower center", fontsize=6.5)
    fig.tight_layout()
    obs_hand = oa.hand(d[:, :2])

    def draw(f):
        t, qc, hp, g, ph = states[sel[f]]
        po = oa.forward_kinematics(d[t, :2])
        pc = ca.forward_kinematics(qc)
        obs_line.set_data(po[:, 0], po[:, 1])
        ctrl_line.set_data(pc[:, 0], pc[:, 1])
        trace.set_data(obs_hand[: t + 1, 0], obs_hand[: t + 1, 1])
        path_line.set_data(hp[:, 0], hp[:, 1])
        goal_pt.set_data([g[0]], [g[1]])
        txt.set_text(f"seen {100 * (t + 1) / T:3.0f} %   estimated phase {ph:.2f}")
        return obs_line, ctrl_line, trace, path_line, goal_pt, txt

    writer = PillowWriter(fps=fps)
    with writer.saving(fig, str(path), dpi=72):  # one render per frame
        for f in range(len(sel)):
            draw(f)
            writer.grab_frame()
    plt.close(fig)



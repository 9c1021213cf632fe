"""Figures of the evaluation (matplotlib, Agg backend): error and recognition curves, predicted
hand trajectories with their uncertainty band, and a 3-D animation of both skeletons."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..model_selection.prefixes import observed_frames

__all__ = ["evaluation_figures", "error_curves", "recognition_curves", "trajectory_figure", "skeleton_animation"]

_STYLE = {
    "ip-forcing": ("C0", "-"), "ip-position": ("C1", "-"), "ip-forcing+pca": ("C0", "--"),
    "ip-position+pca": ("C1", "--"), "ip-paper": ("C7", ":"), "ip-forcing-dtw": ("C0", ":"),
    "ip-position-dtw": ("C1", ":"), "ip-forcing-oracle": ("C0", "-."), "ip-position-oracle": ("C1", "-."),
    "iprompt": ("C2", "-"), "nn": ("C3", "-"), "prior": ("k", "-"),
}
DEFAULT_CURVE_METHODS = ("ip-forcing", "ip-position", "ip-forcing+pca", "ip-position+pca", "ip-paper", "iprompt",
                         "nn", "prior")


def _plt():
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    return plt


def error_curves(summary, path, metric="rmse_ctrl", methods=DEFAULT_CURVE_METHODS, ylabel=None):
    """One panel per task: ``metric`` versus % observed for every method."""
    plt = _plt()
    tasks = list(summary["metrics"])
    n = len(tasks)
    cols = min(3, n)
    rows = int(np.ceil(n / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.2 * rows), squeeze=False)
    for ax, t in zip(axes.flat, tasks):
        for m in methods:
            md = summary["metrics"][t].get(m)
            if not md or metric not in md:
                continue
            fr = sorted(float(f) for f in md[metric])
            v = [md[metric][f] if f in md[metric] else md[metric][str(f)] for f in fr]
            c, ls = _STYLE.get(m, (None, "-"))
            ax.plot(np.array(fr) * 100, v, color=c, ls=ls, marker=".", label=m)
        ax.set_title(t, fontsize=9)
        ax.set_xlabel("% observed")
        ax.set_ylabel(ylabel or metric)
        ax.grid(alpha=0.3)
    for ax in list(axes.flat)[n:]:
        ax.axis("off")
    axes.flat[0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)


def recognition_curves(summary, path):
    """Recognition accuracy versus % observed per interaction (and over all)."""
    plt = _plt()
    rec = summary.get("recognition") or {}
    fig, ax = plt.subplots(figsize=(5.5, 3.6))
    for t, fr in rec.items():
        f = sorted(float(x) for x in fr)
        ax.plot(np.array(f) * 100, [fr[x] if x in fr else fr[str(x)] for x in f], marker=".",
                lw=3 if t == "all" else 1.2, color="k" if t == "all" else None, label=t)
    ax.axhline(1.0 / max(len(rec) - 1, 1), color="gray", ls=":", lw=1, label="chance")
    ax.set_xlabel("% observed")
    ax.set_ylabel("recognition accuracy")
    ax.set_ylim(0, 1.02)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)


def trajectory_figure(model, test, observed_dofs, controlled_dofs, path, fractions=(0.4, 0.6, 0.8), title="",
                      labels=("x", "y", "z"), n=100):
    """Agent 2's true and predicted hand coordinates at several fractions observed, with the 90 % band."""
    from ..core.preprocessing import time_normalise

    plt = _plt()
    truth = time_normalise(test, n)
    s = np.linspace(0, 1, n)
    k = len(controlled_dofs)
    fig, axes = plt.subplots(k, len(fractions), figsize=(3.6 * len(fractions), 2.2 * k), squeeze=False,
                             sharex=True)
    T = test.shape[0]
    for j, p in enumerate(fractions):
        M = observed_frames(T, p)
        pred = model.predict(test[:M, observed_dofs])
        Y, S = pred.trajectory(n), pred.std(n)
        for i, c in enumerate(controlled_dofs):
            ax = axes[i, j]
            ax.fill_between(s, Y[:, c] - 1.645 * S[:, c], Y[:, c] + 1.645 * S[:, c], color="C0", alpha=0.2,
                            lw=0, label="90 % interval")
            ax.plot(s, truth[:, c], "k", lw=1.5, label="true")
            ax.plot(s, Y[:, c], "C0", lw=1.5, label="predicted")
            ax.axvline((M - 1) / (T - 1), color="gray", ls=":", lw=1)
            ax.axvline(pred.normalised_time, color="C3", ls="--", lw=1, label="estimated phase")
            if j == 0:
                ax.set_ylabel(f"hand {labels[i % len(labels)]} (m)")
            if i == 0:
                ax.set_title(f"{int(p * 100)} % observed", fontsize=9)
            if i == k - 1:
                ax.set_xlabel("normalised time")
    axes[0, 0].legend(fontsize=6)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)


_BONES = [(0, 1), (1, 2), (2, 3), (1, 4), (4, 5), (5, 6), (1, 7), (7, 8), (8, 9)]


def skeleton_animation(model, action, demo_index, path, data_path=None, dt=0.05, n_frames=40, fps=8):
    """3-D GIF: both NuiSI skeletons (true) and the robot hand predicted from the growing observation.

    Agent 2 is drawn rotated by 180 degrees about the vertical and shifted so that the two right
    hands meet at the moment of contact (each agent is recorded in its own torso frame).
    ``model`` observes agent 1's upper body and controls agent 2's right hand.
    """
    from matplotlib.animation import FuncAnimation, PillowWriter

    from ..datasets import JOINT_GROUPS, NUISI_JOINTS, load_nuisi

    plt = _plt()
    d = load_nuisi(data_path, action=action, observed="all", controlled="all", dt=dt, demos=[demo_index])
    x = d.demos[0]
    T = x.shape[0]
    a1 = x[:, :30].reshape(T, 10, 3)
    a2 = x[:, 30:].reshape(T, 10, 3)
    R = np.diag([-1.0, -1.0, 1.0])
    k = int(np.argmax(np.linalg.norm(a2[:, 9] - a2[0, 9], axis=1)))
    off = a1[k, 9] - a2[k, 9] @ R.T
    off[2] = 0.0
    a2w = a2 @ R.T + off
    obs_idx = [NUISI_JOINTS.index(j) for j in JOINT_GROUPS["upper_body"]]
    o = a1[:, obs_idx, :].reshape(T, -1)
    frames = np.unique(np.linspace(3, T, n_frames).astype(int))
    allp = np.concatenate([a1.reshape(-1, 3), a2w.reshape(-1, 3)])
    lims = [(float(allp[:, i].min()) - 0.1, float(allp[:, i].max()) + 0.1) for i in range(3)]
    fig = plt.figure(figsize=(5, 4.2))
    ax = fig.add_subplot(111, projection="3d")

    def draw(M):
        ax.cla()
        pred = model.predict(o[:M])
        s_now = pred.normalised_time
        Y = pred.trajectory(60)
        ctrl = model.controlled_dofs_
        hand = Y[:, ctrl] @ R.T + off
        t = M - 1
        for (i, j) in _BONES:
            ax.plot(*zip(a1[t, i], a1[t, j]), color="C0", lw=2)
            ax.plot(*zip(a2w[t, i], a2w[t, j]), color="C7", lw=2)
        sgrid = np.linspace(0, 1, 60)
        fut = sgrid >= s_now
        ax.plot(*hand[fut].T, color="C3", lw=1.5, ls="--")
        kk = int(np.clip(np.searchsorted(sgrid, s_now), 0, 59))
        ax.scatter(*hand[kk], color="C3", s=60, alpha=0.9)
        ax.scatter(*a2w[t, 9], color="k", s=15)
        ax.set_xlim(*lims[0])
        ax.set_ylim(*lims[1])
        ax.set_zlim(*lims[2])
        ax.set_box_aspect(tuple(b - a for a, b in lims))
        ax.set_title(f"{action}: {100 * M / T:.0f} % of agent 1 seen\n"
                     "blue: human, grey: partner (black dot: its hand), red: predicted robot hand", fontsize=8)
        ax.view_init(elev=15, azim=-60)
        return []

    anim = FuncAnimation(fig, draw, frames=frames, blit=False)
    anim.save(str(path), writer=PillowWriter(fps=fps))
    plt.close(fig)
    return Path(path)


def evaluation_figures(results, summary, cfg, out_dir, datasets, traj_method="ip-position", animate=True):
    """All figures of an evaluation run; returns the paths written."""
    from .sweep import load_task, make_estimator, task_names

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = [error_curves(summary, out / "errors_controlled.png", "rmse_ctrl", ylabel="controlled RMSE"),
             error_curves(summary, out / "errors_observed.png", "rmse_obs", ylabel="observed RMSE"),
             error_curves(summary, out / "phase_error.png", "phase_err",
                          methods=("ip-forcing", "ip-forcing-dtw", "ip-position", "ip-position-dtw", "iprompt",
                                   "nn"), ylabel="|phase error|")]
    if summary.get("recognition"):
        paths.append(recognition_curves(summary, out / "recognition.png"))
    for ds in datasets:
        for tk in task_names(ds):
            t = load_task(ds, tk, cfg)
            ctrl = [i for i in range(t.demos[0].shape[1]) if i not in set(t.observed_dofs)]
            if not ctrl:
                continue
            model = make_estimator(traj_method, t.observed_dofs, cfg).fit(t.demos[1:], dt=t.dt)
            name = t.name.replace("/", "_")
            paths.append(trajectory_figure(model, t.demos[0], t.observed_dofs, ctrl, out / f"trajectory_{name}.png",
                                           title=f"{t.name}: held-out demo 0, {traj_method}"))
            if animate and ds == "nuisi" and tk == "highfive1":
                paths.append(skeleton_animation(model, tk, 0, out / "highfive_animation.gif",
                                                data_path=cfg.data_path, dt=cfg.nuisi_dt))
    return paths

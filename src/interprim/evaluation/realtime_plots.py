"""Figures of the real-time protocol on one held-out interaction: both people, the prediction made after
every frame with its 90 % band, and the clock baseline (:mod:`interprim.evaluation.realtime`).

Every number drawn or returned comes from :func:`~interprim.evaluation.realtime.realtime_fold`: the
animation and the strip draw its traced records (``trace=True``), and the summary numbers are
:func:`~interprim.evaluation.realtime.summarise_realtime` of its records on the protocol's frames.
matplotlib (the ``plot`` extra) is imported when a figure is drawn.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..core.cv import DEFAULT_HORIZON
from ..model_selection.prefixes import observed_frames
from .realtime import Z90, RealTimeConfig, realtime_fold, summarise_realtime

__all__ = ["realtime_interaction_figure", "nuisi_realtime_figure", "NUISI_FIGURE_METHODS"]

_COLOURS = ("C0", "C2", "C1", "C4")


def _geometry(test, observed_dofs, point_dim, facing):
    """Observed points ``(T, n_o, d)``, partner points in the display frame ``(T, n_c, d)`` and the map
    ``x -> x R + off`` that puts the partner's coordinates into that frame.

    Each agent is recorded in its own frame (NuiSI: x forward, y to the left, z up).  With ``facing`` the
    partner is turned by 180 degrees about the vertical (the last coordinate) and shifted horizontally so
    that the observed agent's last point (its hand) and the partner's last point meet at the partner's
    "contact" frame (its last point furthest from where it started).  A rigid map: distances are kept.
    """
    T = test.shape[0]
    obs = [int(i) for i in observed_dofs]
    ctrl = [i for i in range(test.shape[1]) if i not in set(obs)]
    if len(obs) % point_dim or len(ctrl) % point_dim or not ctrl:
        raise ValueError(f"observed ({len(obs)}) and controlled ({len(ctrl)}) columns must be whole points of "
                         f"{point_dim} coordinates, and some columns must be controlled")
    P_o = test[:, obs].reshape(T, -1, point_dim)
    P_c = test[:, ctrl].reshape(T, -1, point_dim)
    R = np.eye(point_dim)
    off = np.zeros(point_dim)
    if facing:
        R[np.arange(point_dim - 1), np.arange(point_dim - 1)] = -1.0
        hand = P_c[:, -1]
        kc = int(np.argmax(np.linalg.norm(hand - hand[0], axis=1)))
        off = P_o[kc, -1] - hand[kc] @ R
        off[-1] = 0.0
    return obs, ctrl, P_o, P_c @ R + off, R, off


def _to_display(Y, R, off, point_dim):
    """``(H, n_c * d)`` partner columns -> ``(H, n_c, d)`` display coordinates."""
    return Y.reshape(Y.shape[0], -1, point_dim) @ R + off


def realtime_interaction_figure(models, train, test, observed_dofs, dt: float, gif_path=None, png_path=None, *,
                                horizon: float = DEFAULT_HORIZON, point_dim: int = 3, view=(0, 2), facing: bool = True,
                                n_frames: int = 60, fps: int = 5, dpi: int = 85, snapshots=(0.3, 0.5, 0.7, 0.9),
                                title: str = "", axis_labels=("forward [m]", "up [m]"),
                                unit: tuple = ("cm", 100.0), prefix=None) -> dict:
    """Animation (GIF) and static strip (PNG) of real-time prediction on one held-out demonstration.

    After each observed frame ``k`` every model predicts the controlled agent's next ``horizon`` seconds,
    placed in time by its own estimate of the phase and the speed (the real-time protocol of
    :mod:`interprim.evaluation.realtime`); the figure shows, in a 2-D view (``view``: which two coordinates
    of each point):

    * the observed agent's points at frame ``k`` (joined in column order, e.g. shoulder-elbow-hand) and the
      path of its last point so far;
    * the controlled agent's true points: the path so far, now, and the true next ``horizon`` seconds (black);
    * the prediction (colour) with its pointwise 90 % band (ellipses, ``mean +- 1.645 std`` per coordinate);
    * the clock baseline (grey): the mean training demonstration played at the mean duration.

    Parameters
    ----------
    models : dict
        ``{label: fitted estimator}`` (``predict(partial)`` with ``trajectory``, ``std`` and timing), fitted
        on ``train`` only (``test`` held out).  One panel (GIF) or row (PNG) each.
    train : list of ndarray
        The training demonstrations (the clock baseline is their mean).
    test : ndarray, shape (T, D)
        The held-out demonstration.
    observed_dofs : sequence of int
        Columns of the observed agent; the others are the controlled agent's.  Both are points of
        ``point_dim`` coordinates (the last coordinate is vertical).
    dt : float
        Seconds per frame.
    gif_path, png_path : str or Path, optional
        Where to write the animation (one frame per evaluated ``k``: ``k = 3 .. T``, at most ``n_frames``,
        evenly spread) and the strip (one row per model: the ``snapshots`` fractions seen, then the error
        over the next ``horizon`` seconds against the fraction seen, with the clock's).
    fps, dpi : int
        Frames per second (real time at 20 Hz is 20; the default plays 4x slower) and resolution of the GIF.
    facing : bool
        Turn the controlled agent to face the observed one (see :func:`_geometry`), for agents recorded in
        their own frames.
    unit : (str, float)
        Unit of the errors printed on the figure and its factor from data units (default centimetres).
    prefix : callable, optional
        ``prefix(k)``: the observed columns of the first ``k`` frames as a robot had them (a causal prefix of
        an interpolated recording, :class:`~interprim.model_selection.prefixes.Prefixes`); default the first ``k``
        rows of ``test``.

    Returns
    -------
    dict
        ``T``, ``dt``, ``horizon_s``, ``n_frames`` (of the GIF), ``files`` (``{"gif": path, "png": path}``) and
        ``models``: per model label, the protocol's summary on this demonstration (frames seen from 20 to 90 %,
        :func:`~interprim.evaluation.realtime.summarise_realtime`): ``rt_ctrl`` (RMSE of the controlled agent over the
        next ``horizon`` s, data units), ``clock_rt_ctrl``, ``rt_ctrl_vs_clock``, ``phase_err``, ``clock_phase_err``,
        ``cov_ctrl`` (coverage of the 90 % band) and ``z_ctrl`` (RMS error / RMS std).
    """
    test = np.asarray(test, dtype=np.float64)
    train = [np.asarray(d, dtype=np.float64) for d in train]
    if not models:
        raise ValueError("models must name at least one fitted estimator")
    if len(view) != 2 or not all(0 <= int(v) < point_dim for v in view):
        raise ValueError(f"view must name two of the {point_dim} coordinates of a point, got {view!r}")
    T = test.shape[0]
    if T < 4:
        raise ValueError(f"the held-out demonstration has {T} frames; at least 4 are needed")
    obs, ctrl, P_o, P_c, R, off = _geometry(test, observed_dofs, point_dim, facing)
    cfg = RealTimeConfig(horizon=horizon, point_dim=point_dim)
    out = {"T": T, "dt": float(dt), "horizon_s": float(horizon), "files": {}, "models": {}}
    ks = np.unique(np.linspace(3, T, max(2, min(int(n_frames), T - 2))).round().astype(int))
    snap_k = [observed_frames(T, f) for f in snapshots]
    all_k = sorted(set(ks.tolist()) | set(snap_k))
    traces = {}
    for label, model in models.items():
        recs = realtime_fold(model, train, test, obs, dt, cfg, name=label, fitted=True,
                             prefix=prefix)  # the protocol's frames
        summ = summarise_realtime(recs)
        m, c = summ[label], summ["clock"]
        out["models"][label] = {"rt_ctrl": m["rt_ctrl"], "clock_rt_ctrl": c["rt_ctrl"],
                                "rt_ctrl_vs_clock": m["rt_ctrl_vs_clock"],
                      "phase_err": m["phase_err"], "clock_phase_err": c["phase_err"], "cov_ctrl": m["cov_ctrl"],
                      "z_ctrl": m["z_ctrl"], "n_evaluated": m["n"]}
        tr = realtime_fold(model, train, test, obs, dt, cfg, name=label, fitted=True, frames=all_k, trace=True,
                           prefix=prefix)
        traces[label] = {k: {r["method"]: r for r in tr if r["k"] == k} for k in all_k}
    if gif_path is None and png_path is None:
        out["n_frames"] = 0
        return out
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    a, b = (int(v) for v in view)
    pts = np.concatenate([P_o.reshape(-1, point_dim), P_c.reshape(-1, point_dim)])
    lims = [(float(pts[:, i].min()) - 0.12, float(pts[:, i].max()) + 0.12) for i in (a, b)]
    sc, un = unit[1], unit[0]
    labels = list(models)

    def panel(ax, label, k, colour):
        ax.cla()
        r = traces[label][k]
        rec, clock = r[label], r["clock"]
        t = k - 1
        ax.plot(P_o[t, :, a], P_o[t, :, b], "-o", color="tab:blue", lw=2.5, ms=4)
        ax.plot(P_o[: t + 1, -1, a], P_o[: t + 1, -1, b], color="tab:blue", lw=0.8, alpha=0.7)
        ax.plot(P_c[: t + 1, -1, a], P_c[: t + 1, -1, b], color="0.45", lw=0.8)
        truth = _to_display(rec["truth"][:, ctrl], R, off, point_dim)[:, -1]
        ax.plot(truth[:, a], truth[:, b], ":", color="k", lw=1.5)
        ax.plot(P_c[t, -1, a], P_c[t, -1, b], "o", color="k", ms=6)
        cl = _to_display(clock["mean"][:, ctrl], R, off, point_dim)[:, -1]
        ax.plot(cl[:, a], cl[:, b], "--", color="0.55", lw=1.5, marker=".")
        mu = _to_display(rec["mean"][:, ctrl], R, off, point_dim)[:, -1]
        if rec["std"] is not None:
            from matplotlib.patches import Ellipse

            sd = rec["std"][:, ctrl].reshape(-1, len(ctrl) // point_dim, point_dim)[:, -1]  # |R| = 1 per axis
            for h in range(mu.shape[0]):
                ax.add_patch(Ellipse((mu[h, a], mu[h, b]), 2 * Z90 * sd[h, a], 2 * Z90 * sd[h, b], fc=colour,
                                     alpha=0.15, lw=0))
        ax.plot(mu[:, a], mu[:, b], "-", color=colour, lw=2, marker=".")
        ax.set_xlim(*lims[0])
        ax.set_ylim(*lims[1])
        ax.set_aspect("equal")
        ax.set_xlabel(axis_labels[0], fontsize=7)
        ax.set_ylabel(axis_labels[1], fontsize=7)
        ax.tick_params(labelsize=6)
        ax.set_title(f"{label}\nseen {100 * k / T:.0f} % ({(k - 1) * dt:.2f} s), phase {rec['phase']:.2f} "
                     f"(true {rec['phase_true']:.2f})\nerror next {horizon:g} s: {sc * rec['rt_ctrl']:.1f} {un} "
                     f"(clock {sc * clock['rt_ctrl']:.1f} {un})", fontsize=7)

    def legend(fig, ncol):
        from matplotlib.lines import Line2D
        from matplotlib.patches import Patch

        h = [Line2D([], [], color="tab:blue", lw=2.5, marker="o", ms=4,
                    label="observed person's right arm (path of the hand)"),
             Line2D([], [], color="0.45", lw=0.8, label="partner's right hand so far"),
             Line2D([], [], color="k", marker="o", ls="", ms=6, label="partner's hand now"),
             Line2D([], [], color="k", ls=":", lw=1.5, label=f"partner's hand, true next {horizon:g} s"),
             Line2D([], [], color="0.55", ls="--", marker=".", lw=1.5, label=f"clock baseline, next {horizon:g} s")]
        for j, label in enumerate(labels):
            c = _COLOURS[j % len(_COLOURS)]
            h.append(Line2D([], [], color=c, lw=2, marker=".", label=f"{label}: prediction, next {horizon:g} s"))
            h.append(Patch(fc=c, alpha=0.3, label=f"{label}: 90 % band"))
        fig.legend(handles=h, loc="lower center", ncol=ncol, fontsize=6, frameon=False)

    if gif_path is not None:
        from matplotlib.animation import PillowWriter

        fig, axes = plt.subplots(1, len(labels), figsize=(3.7 * len(labels), 4.6), squeeze=False)
        legend(fig, 2)
        if title:
            fig.suptitle(title, fontsize=8)
        writer = PillowWriter(fps=fps)
        with writer.saving(fig, str(gif_path), dpi=dpi):
            for i, k in enumerate(ks):
                for j, label in enumerate(labels):
                    panel(axes[0, j], label, int(k), _COLOURS[j % len(_COLOURS)])
                if i == 0:  # one layout for every frame
                    fig.tight_layout(rect=(0, 0.2, 1, 1))
                writer.grab_frame()
        plt.close(fig)
        out["files"]["gif"] = str(gif_path)
    out["n_frames"] = int(len(ks)) if gif_path is not None else 0
    if png_path is not None:
        ncol = len(snap_k) + 1
        fig, axes = plt.subplots(len(labels), ncol, figsize=(2.7 * ncol, 2.9 * len(labels) + 0.4), squeeze=False)
        for i, label in enumerate(labels):
            colour = _COLOURS[i % len(_COLOURS)]
            for j, k in enumerate(snap_k):
                panel(axes[i, j], label, k, colour)
            ax = axes[i, -1]
            f = np.array([k / T for k in all_k])
            for meth, col, ls, name in ((label, colour, "-", label), ("clock", "0.55", "--", "clock")):
                ax.plot(100 * f, [sc * traces[label][k][meth]["rt_ctrl"] for k in all_k], ls, color=col, marker=".",
                        ms=3, label=name)
            ax.axvspan(100 * cfg.start, 100 * cfg.stop, color="0.9", zorder=0, label="protocol frames")
            s = out["models"][label]
            ax.set_title(f"error over the next {horizon:g} s\n20-90 %: {sc * s['rt_ctrl']:.1f} {un} vs clock "
                         f"{sc * s['clock_rt_ctrl']:.1f} {un} ({s['rt_ctrl_vs_clock']:.2f}x)", fontsize=7)
            ax.set_xlabel("% seen", fontsize=7)
            ax.set_ylabel(f"RMSE [{un}]", fontsize=7)
            ax.tick_params(labelsize=6)
            ax.grid(alpha=0.3)
            ax.legend(fontsize=5.5)
        if title:
            fig.suptitle(title, fontsize=9)
        legend(fig, 5)
        fig.tight_layout(rect=(0, 0.45 / fig.get_figheight(), 1, 1))
        fig.savefig(png_path, dpi=90)
        plt.close(fig)
        out["files"]["png"] = str(png_path)
    return out


#: The two models of :func:`nuisi_realtime_figure`: the library's defaults and the paper's method exactly
#: (forcing observation, open-end DTW phase, the noise from the fit residual).  Until 2026-11-26 the second row
#: was the learned phase, which the defaults' ``phase_method="cv"`` now picks on these recordings.
NUISI_FIGURE_METHODS = {"library defaults": {},
                        "the paper exactly": {"observation": "forcing", "sigma2": "residual", "phase_method": "dtw"}}


def nuisi_realtime_figure(action: str = "highfive1", demo: int = 0, out_dir=".", data_path=None, dt: float = 0.05,
                          n_frames: int = 60, gif: bool = True, png: bool = True, methods=None,
                          development_only: bool = True) -> dict:
    """:func:`realtime_interaction_figure` for one NuiSI recording, held out (leave-one-out).

    Agent 1's right shoulder, elbow and hand are observed (9 columns), agent 2's right hand is predicted
    (:func:`interprim.datasets.load_nuisi` with ``observed="right_arm", controlled="right_hand"``).  The
    models (:data:`NUISI_FIGURE_METHODS`: ``InteractionPrimitive`` with its defaults, and as in the paper) are
    fitted on the other recordings of ``action``; with ``development_only``
    (default) only on the development recordings (the first two thirds: the untouched hold-out of
    :data:`interprim.evaluation.nested.HOLDOUT` is neither fitted on nor shown), and ``demo`` must be one of
    them.  The held-out recording is seen through causal prefixes (the raw samples recorded by each frame's
    time).  Writes
    ``nuisi_<action>_<demo>_realtime.gif`` / ``.png`` to ``out_dir`` (unless ``gif``/``png`` is False) and
    returns the figure's numbers (metres) with ``action``, ``demo`` and ``n_train``.
    """
    from ..datasets import load_nuisi
    from ..model_selection.prefixes import Prefixes
    from ..models.primitive.estimator import InteractionPrimitive
    from .nested import split_holdout

    ds = load_nuisi(data_path, action=action, observed="right_arm", controlled="right_hand", dt=dt)
    if development_only:
        n_all = len(ds.demos)
        ds = ds.take(split_holdout(n_all)[0])
        if not 0 <= int(demo) < len(ds.demos):
            raise ValueError(f"{action} has {len(ds.demos)} development recordings (the last {n_all - len(ds.demos)} "
                             f"of {n_all} are the untouched hold-out); demo must be in 0..{len(ds.demos) - 1}, got "
                             f"{demo} (development_only=False to use them all)")
    if not 0 <= int(demo) < len(ds.demos):
        raise ValueError(f"{action} has {len(ds.demos)} recordings; demo must be in 0..{len(ds.demos) - 1}, got {demo}")
    test = ds.demos[int(demo)]
    assert ds.observed_dofs is not None and ds.dt is not None  # load_nuisi sets both
    prefixes = Prefixes(ds, ds.observed_dofs)
    train = [d for i, d in enumerate(ds.demos) if i != int(demo)]
    obs = list(ds.observed_dofs)
    models = {label: InteractionPrimitive(observed_dofs=obs, **kw).fit(train, dt=ds.dt)
              for label, kw in (methods or NUISI_FIGURE_METHODS).items()}
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    stem = out / f"nuisi_{action}_{ds.labels[int(demo)]}_realtime"
    res = realtime_interaction_figure(
        models, train, test, obs, ds.dt, gif_path=stem.with_suffix(".gif") if gif else None,
        png_path=stem.with_suffix(".png") if png else None, n_frames=n_frames,
        title=f"NuiSI {action}, recording {ds.labels[int(demo)]} held out (models fitted on the other {len(train)})",
        prefix=lambda k: prefixes(int(demo), k))
    res.update(action=action, demo=int(demo), n_train=len(train))
    return res

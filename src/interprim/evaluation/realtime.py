"""Evaluation protocols in seconds, not in normalised time: real-time prediction, phase, calibration.

The paper's Fig. 7 compares predictions with the truth on a normalised-time grid, which hides every
timing error: a method that predicts the right shape at the wrong speed looks perfect.  A robot needs
the partner's positions *in seconds from now*.  This module measures that, for any estimator with the
small interface of :mod:`interprim.models.demonstrations` (``fit(demos, dt)``, ``predict(partial)`` returning an
object with ``trajectory(n)``, ``std(n)`` and, when it estimates timing, ``phase`` and ``duration``),
on any set of demonstrations (built-in data or a user's own recordings).

Protocols (per held-out demonstration of ``T`` frames at ``dt``; leave-one-out or k-fold):

* **Real time.** After each observed frame ``k`` (the first ``k`` frames seen, ``k/T`` from ``start`` to
  ``stop``, default 20 ... 90 %), predict the controlled agent's positions at the next frames up to
  ``horizon`` seconds ahead (default 0.25 s), placed in time by the method's own estimate of the phase
  ``s`` (fraction of the movement at frame ``k``) and of the duration ``D``: the position at ``t`` seconds
  after frame ``k`` is the prediction at normalised time ``s + t / D``.  Error: root mean square of the
  point errors over the horizon frames.
* **Phase.** ``|s - (k - 1) / (T - 1)|`` for the method's phase, and for the clock.
* **Calibration.** Over the same horizon frames, both agents: the fraction of true coordinates inside the
  pointwise 90 % predictive band ``mean +- 1.645 std`` (coverage) and RMS error / RMS predicted std
  (1 = calibrated; > 1 over-confident).

Baselines, always on the same splits:

* ``clock``: the mean of the time-normalised training demonstrations, played from the first frame at the
  mean training duration (what a robot without any perception of timing would do);
* ``oracle-duration``: the same mean stretched to the true duration of the held-out demonstration (not
  available online: a reference that shows how much of the error is timing, not a lower bound).

A method without a ``duration`` but with a ``phase`` (e.g. nearest neighbour) is placed in time at the
speed implied by its phase (elapsed time / phase); a method with neither (the prior mean) is played by the
clock.
"""

from __future__ import annotations

import numpy as np

from ..core.cv import DEFAULT_HORIZON
from ..model_selection.metrics import Z90
from ..model_selection.realtime import (
    ALL_METHODS_FROM,
    MIN_DEMONSTRATIONS,
    RealTimeConfig,
    folds,
    mean_demo,
    realtime_fold,
    realtime_sweep,
    summarise_realtime,
    whole_movement_fold,
)
from ..models.registry import default_methods
from .nested import WHOLE_RIVALS, beaten_by, standard_error_ratio, yardstick_markdown

__all__ = ["RealTimeConfig", "mean_demo", "realtime_fold", "whole_movement_fold", "realtime_sweep",
           "summarise_realtime", "summarise_with_rest", "REST_KEYS", "default_methods", "verdict", "nested_verdict",
           "choose_method", "markdown_table", "forward_markdown", "save_report", "folds", "Z90", "MIN_DEMONSTRATIONS",
           "ALL_METHODS_FROM"]

def verdict(summary, method: str = "ip", threshold: float = 0.03) -> str:
    """One plain sentence: does conditioning on the human help the robot's real-time prediction here?

    Compares ``method``'s real-time error of the controlled agent with the clock's (the mean played at the
    mean duration) and the prior mean's; ``threshold`` is the relative gain below which the answer is "no".
    """
    m = summary.get(method)
    if m is None or "rt_ctrl_vs_clock" not in m:
        return f"no verdict: {method!r} or the clock is missing from the results"
    r = m["rt_ctrl_vs_clock"]
    ph = m.get("phase_err_vs_clock", float("nan"))
    timing = (f"its timing is {100 * (1 - ph):.0f} % closer to the truth than the clock's" if ph < 1 - threshold
              else "its timing is no better than the clock's")
    if "phase_err_vs_clock_why" in m:
        timing = f"its timing cannot be compared with the clock's ({m['phase_err_vs_clock_why']})"
    if r <= 1 - threshold:
        return (f"conditioning on the human improves the robot's real-time prediction by {100 * (1 - r):.0f} % "
                f"over the clock (RMSE {m['rt_ctrl']:.4g} vs {summary['clock']['rt_ctrl']:.4g}); {timing}.")
    if r < 1 + threshold:
        return (f"does not help on this data: the model does no better than replaying the mean at the mean "
                f"speed (real-time RMSE {r:.2f}x the clock's); {timing}.")
    return (f"hurts on this data: the model's real-time prediction is {100 * (r - 1):.0f} % worse than replaying "
            f"the mean at the mean speed; {timing}. Use the mean (or more demonstrations).")


#: The rest-of-the-movement figures :func:`summarise_with_rest` adds to a method's summary (``rest_`` + each).
REST_KEYS = ("rt_ctrl", "cov_ctrl", "cov_obs", "rt_ctrl_vs_clock", "rt_ctrl_vs_oracle")


def summarise_with_rest(records) -> dict:
    """:func:`summarise_realtime` of the real-time and whole-movement records, with each method's figures over the
    rest of the movement in seconds (the records with ``"protocol": "rest"``) added as ``rest_`` + each of
    :data:`REST_KEYS`: its error and its 90 % band's coverage, each agent, and the error ÷ the clock's and ÷ the
    mean at the true duration's."""
    summary = summarise_realtime([r for r in records if r.get("protocol") != "rest"])
    rest = summarise_realtime([dict(r, protocol=None) for r in records if r.get("protocol") == "rest"])
    for m, v in rest.items():
        summary.setdefault(m, {}).update({f"rest_{k}": v[k] for k in REST_KEYS if k in v})
    return summary


def markdown_table(summary) -> str:
    """The summary as a Markdown table (one row per method)."""
    cols = [("rt_ctrl", "real-time RMSE, controlled", 4), ("rt_ctrl_vs_clock", "x clock", 2),
            ("rt_ctrl_vs_oracle", "x oracle-duration", 2),
            ("rest_rt_ctrl_vs_clock", "rest of the movement, controlled, x clock", 2),
            ("rest_rt_ctrl_vs_oracle", "x oracle-duration", 2),
            ("rest_cov_ctrl", "90 % band over the rest, controlled", 2), ("phase_err", "phase error", 3),
            ("phase_err_vs_clock", "x clock", 2), ("cov_ctrl", "90 % band coverage, controlled", 2),
            ("cov_obs", "coverage, observed", 2), ("z_ctrl", "RMSE / std, controlled", 2),
            ("z_obs", "RMSE / std, observed", 2), ("wm_ctrl", "whole movement RMSE, controlled", 4),
            ("wm_ctrl_vs_prior", "x prior", 2)]
    lines = ["| method | " + " | ".join(c[1] for c in cols) + " |", "|---" * (len(cols) + 1) + "|"]
    order = [m for m in ("clock", "oracle-duration") if m in summary] + [m for m in summary
                                                                          if m not in ("clock", "oracle-duration")]
    for m in order:
        v = summary[m]
        cells = []
        for key, _, dg in cols:
            x = v.get(key, float("nan"))
            cells.append("—" if not np.isfinite(x) else f"{x:.{dg}f}")
        lines.append(f"| {m} | " + " | ".join(cells) + " |")
    why = next((v["phase_err_vs_clock_why"] for v in summary.values() if "phase_err_vs_clock_why" in v), None)
    if why:
        lines += ["", f"Phase error x clock: not given, {why}."]
    return "\n".join(lines)


def choose_method(make_estimators, demos, observed_dofs, dt: float, cfg=None, k: int = 3,
                  metric: str = "rt_ctrl") -> tuple:
    """The method with the smallest cross-validated error on ``demos`` (training demonstrations only).

    Parameters
    ----------
    make_estimators : dict
        ``{name: factory}`` of the candidate methods (see :func:`~interprim.evaluation.realtime.realtime_sweep`).
    demos : sequence of ndarray, Demonstrations or Prefixes
        The training demonstrations (causal prefixes when their raw samples are known).
    observed_dofs, dt, cfg
        As in :func:`~interprim.evaluation.realtime.realtime_sweep` (``cfg`` default: every 3rd frame).
    k : int
        Inner folds.
    metric : str
        ``"rt_ctrl"`` (real time, the controlled agent) or ``"wm_ctrl"`` (whole movement at 60 %).

    Returns
    -------
    (str, dict)
        The chosen name and ``{name: mean inner error}`` (``inf`` for a method that cannot be fitted on an
        inner training fold, e.g. with too few demonstrations).
    """
    cfg = cfg or RealTimeConfig(stride=3)
    whole = (0.6,) if metric.startswith("wm") else None
    scores = {}
    for name, factory in make_estimators.items():
        try:
            recs = realtime_sweep({name: factory}, demos, observed_dofs, dt, cfg, k=k, whole_movement=whole)
        except ValueError:  # e.g. too few demonstrations in an inner training fold for this method
            scores[name] = float("inf")
            continue
        scores[name] = float(summarise_realtime(recs).get(name, {}).get(metric, np.inf))
    if not np.isfinite(min(scores.values())):
        return next(iter(make_estimators)), scores
    return min(scores, key=lambda m: (scores[m], list(make_estimators).index(m))), scores


BASELINES = ("nn", "prior", "clock")

#: How each method of :func:`default_methods` is fitted outside the evaluation.
def _fit_commands() -> dict:
    """``{method: the interprim fit command that fits it}`` (``auto``: the blend; a family: the registry's options)."""
    from ..models.registry import FAMILIES

    out = {"auto": "interprim fit {data} --observed {observed} -o model.npz"}
    for name, fam in FAMILIES.items():
        if fam.fit_args:
            note = f" ({fam.fit_note})" if fam.fit_note else ""
            out[name] = f"interprim fit {{data}} --observed {{observed}} {fam.fit_args} -o model.npz{note}"
    return out


FIT_COMMANDS = _fit_commands()


def nested_verdict(summary, records, method: str = "chosen", threshold: float = 0.03, data: str = "DEMOS",
                   observed: str = "COLS") -> str:
    """The verdict of an evaluation whose choice was made inside the training folds (nested).

    Says which method the inner cross-validation chose (per outer fold), how the chosen model compares with the
    clock and with the mean stretched to the true duration (a reference that knows the
    true duration; not a lower bound), names the best method
    among all rows and says plainly when a baseline beats the chosen model by more than one standard error, and
    gives the command that fits the chosen method.  Of the default blend (``auto``) it gives the same figures, the
    baseline that beats it in real time, and every method of :data:`~interprim.evaluation.nested.WHOLE_RIVALS` that
    beats it on the whole movement by more than one standard error (:func:`~interprim.evaluation.nested.beaten_by`).
    """
    m = summary.get(method)
    if m is None or "rt_ctrl_vs_clock" not in m:
        return verdict(summary, next((x for x in ("ip", "learned") if x in summary), "ip"), threshold)
    picks: dict = {}
    for r in records:
        if r["method"] == method and r.get("protocol") != "whole":
            picks.setdefault(r["chosen"], set()).add(r["demo"])
    order = sorted(picks, key=lambda c: -len(picks[c]))
    n_demo = sum(len(v) for v in picks.values())
    chosen = ", ".join(f"{c} ({len(picks[c])} of {n_demo} held-out demonstrations)" for c in order)
    r = m["rt_ctrl_vs_clock"]
    parts = [f"chosen inside the training folds: {chosen}."]
    ro = m.get("rt_ctrl_vs_oracle", float("nan"))
    parts.append(f"Real time: {r:.2f}x the clock's error and {ro:.2f}x the mean stretched to the true duration "
                 f"(a reference that knows the true duration, which no online method does; not a lower bound: it can "
                 f"be worse than the clock).")
    online = [x for x in summary if x not in ("oracle-duration", "oracle", method) and "rt_ctrl" in summary[x]]
    best = min(online, key=lambda x: summary[x]["rt_ctrl"]) if online else None
    if best is not None:
        rb, se = standard_error_ratio(records, best if best != "clock" else "clock", method)
        if best in BASELINES and np.isfinite(rb) and rb < 1 - (se if np.isfinite(se) else 0):
            parts.append(f"A baseline beats it: {best} has {rb:.2f}x (± {se:.2f}) the chosen model's real-time "
                         f"error; use {best} on this data.")
        else:
            parts.append(f"Best method: {best} ({summary[best]['rt_ctrl_vs_clock']:.2f}x the clock).")
    if r <= 1 - threshold:
        parts.append(f"Conditioning on the human helps: {100 * (1 - r):.0f} % less real-time error than the clock.")
    elif r < 1 + threshold:
        parts.append("It does not help on this data: no better than the mean at the mean speed.")
    else:
        parts.append(f"It hurts on this data: {100 * (r - 1):.0f} % worse than the mean at the mean speed.")
    w = m.get("wm_ctrl_vs_prior")
    if w is not None and np.isfinite(w):
        parts.append(f"Whole movement: {w:.2f}x the mean demonstration's error.")
    parts += _rest_sentences(summary, records, method, "the chosen model")
    a = summary.get("auto")
    if a is not None and "rt_ctrl_vs_clock" in a:  # what interprim fit makes by default, fitted inside the folds
        ra, se = standard_error_ratio(records, "auto", method)
        parts.append(f"The blend that 'interprim fit' makes by default (auto): {a['rt_ctrl_vs_clock']:.2f}x the clock "
                     f"and {a.get('rt_ctrl_vs_oracle', float('nan')):.2f}x the mean at the true duration in real "
                     f"time ({ra:.2f}x ± {se:.2f} the chosen family's error)"
                     + (f", {a['wm_ctrl_vs_prior']:.2f}x the mean demonstration on the whole movement."
                        if np.isfinite(a.get("wm_ctrl_vs_prior", np.nan)) else "."))
        online = [x for x in summary if x in BASELINES and "rt_ctrl" in summary[x]]
        if online:
            b = min(online, key=lambda x: summary[x]["rt_ctrl"])
            rb, seb = standard_error_ratio(records, b, "auto")
            if np.isfinite(rb) and rb < 1 - (seb if np.isfinite(seb) else 0):
                parts.append(f"A baseline beats the blend: {b} has {rb:.2f}x (± {seb:.2f}) its real-time error.")
        parts += _rest_sentences(summary, records, "auto", "the blend")
        rivals = [x for x in WHOLE_RIVALS if "wm_ctrl" in summary.get(x, {})]
        whole = beaten_by(records, "auto", rivals, key="wm_ctrl")
        if whole:  # the paper's measure: the blend's choices are made in seconds, which can cost it here
            parts.append("On the whole movement (the paper's measure, in normalised time), more than a standard error "
                         f"better than the blend ({len(rivals)} compared): "
                         + "; ".join(f"{x} ({r:.2f}x ± {se:.2f} its error)" for x, r, se in whole) + ".")
    if order and a is not None and "rt_ctrl_vs_clock" in a:
        parts.append("To fit the blend: " + FIT_COMMANDS["auto"].format(data=data, observed=observed)
                     + "; the chosen family alone: "
                     + FIT_COMMANDS.get(order[0], order[0]).format(data=data, observed=observed))
    elif order:
        parts.append("To fit it: " + FIT_COMMANDS.get(order[0], order[0]).format(data=data, observed=observed))
    return " ".join(parts)


def _rest_sentences(summary, records, method: str, who: str) -> list:
    """What the verdict says of ``method`` over the rest of the movement in seconds (the records with ``"protocol":
    "rest"``, :func:`summarise_with_rest`): its error ÷ the clock's and ÷ the mean at the true duration's, its 90 %
    band's coverage there, and the clock named when it beats ``method`` by more than one standard error."""
    m = summary.get(method, {})
    r = m.get("rest_rt_ctrl_vs_clock")
    if r is None or not np.isfinite(r):
        return []
    cov = m.get("rest_cov_ctrl", float("nan"))
    band = (f"; its 90 % band covers {cov:.0%} of the controlled agent's frames there" if np.isfinite(cov)
            else " (it gives no band)")
    out = [f"Over the rest of the movement in seconds, {who} has {r:.2f}x the clock's error and "
           f"{m.get('rest_rt_ctrl_vs_oracle', float('nan')):.2f}x the mean at the true duration's{band}."]
    rb, se = standard_error_ratio(records, "clock", method, protocol="rest")
    if np.isfinite(rb) and rb < 1 - (se if np.isfinite(se) else 0):
        out.append(f"The clock beats {who} there: {rb:.2f}x (± {se:.2f}) its error over the rest of the movement.")
    return out


def forward_markdown(forward) -> str:
    """The forward check (:func:`interprim.assessment.forward_check`) as a markdown section: every method's error
    ÷ each yardstick's reference on the latest recordings, ± one standard error over them."""
    return yardstick_markdown(forward["table"], title=(
        f"Forward in recording order: the latest {len(forward['latest'])} recordings predicted by models fitted on "
        "the earlier ones (± one standard error over the latest recordings)"))


def save_report(records, summary, sentence, out_dir, title: str = "", horizon: float = DEFAULT_HORIZON, notes=(),
                unit: str = "data units", forward=None) -> list:
    """Write ``realtime.json`` (records + summary), ``report.md`` (table + verdict) and, with matplotlib,
    ``realtime.png`` (real-time error of the controlled agent against the fraction seen, per method).
    ``notes``: lines added to the report (e.g. methods left out); ``unit``: the controlled columns' unit, for the
    figure's y-axis; ``forward``: the forward check (:func:`interprim.assessment.forward_check`), written to
    ``realtime.json`` (``"forward"``) and as a section of ``report.md``."""
    import json
    from pathlib import Path

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = [out / "realtime.json", out / "report.md"]
    doc = {"summary": summary, "verdict": sentence, "records": records, "notes": list(notes)}
    if forward is not None:
        doc["forward"] = {"latest": forward["latest"], "verdict": " ".join(forward["sentences"]),
                          "records": forward["records"],
                          "table": {k: {m: list(v) for m, v in t.items()} for k, t in forward["table"].items()}}
    paths[0].write_text(json.dumps(doc, indent=1))
    section = "" if forward is None else (f"\n{forward_markdown(forward)}\n\n**Forward check:** "
                                          f"{' '.join(forward['sentences'])}\n")
    paths[1].write_text((f"# {title}\n\n" if title else "") + markdown_table(summary) + f"\n\n**Verdict:** {sentence}\n"
                        + section + "".join(f"\nNote: {n}\n" for n in notes))
    try:
        import matplotlib

        matplotlib.use("Agg", force=False)
        import matplotlib.pyplot as plt
    except ImportError:  # plotting is optional
        return paths
    fig, ax = plt.subplots(figsize=(6, 3.6))
    bins = np.linspace(0.2, 0.9, 8)
    mids = 0.5 * (bins[:-1] + bins[1:])
    curves = {}
    for m in summary:
        rs = [r for r in records if r["method"] == m and "rt_ctrl" in r and r.get("protocol") is None]
        if not rs:
            continue
        f = np.array([r["fraction"] for r in rs])
        e = np.array([r["rt_ctrl"] for r in rs])
        idx = np.clip(np.digitize(f, bins) - 1, 0, len(bins) - 2)
        curves[m] = np.array([e[idx == i].mean() if np.any(idx == i) else np.nan for i in range(len(mids))])
    drawn: list = []
    for m, y in curves.items():
        # a curve equal (to 0.1 %) to one drawn before (the prior mean is played by the clock) would hide under it:
        # say so in its label and draw it dotted with open markers, so that both stay visible
        same = next((o for o in drawn if np.allclose(y, curves[o], rtol=1e-3, atol=1e-12, equal_nan=True)), None)
        style: dict = dict(marker="o", ms=3, ls="--" if m in ("clock", "oracle-duration") else "-")
        if same is not None:
            style = dict(marker="s", ms=6, mfc="none", ls=":", lw=2.5)
        ax.plot(mids, y, label=m if same is None else f"{m} (= {same})", zorder=3 if same is None else 2, **style)
        drawn.append(m)
    ax.set_xlabel("fraction of the movement seen")
    ax.set_ylabel(f"RMSE over the next {horizon:g} s ({unit})")
    ax.legend(fontsize=7)
    ax.set_title(f"controlled agent: {title}" if title else "real-time prediction of the controlled agent",
                 fontsize=9)
    fig.tight_layout()
    fig.savefig(out / "realtime.png", dpi=110)
    plt.close(fig)
    return paths + [out / "realtime.png"]


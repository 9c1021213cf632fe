"""Leave-one-out evaluation of Interaction Primitives and their peers ("% observed" sweeps, Fig. 7).

Protocol: for every task (one NuiSI
interaction, the synthetic set, ...) and every demonstration ``j``: fit each
method on the other demonstrations, observe the first ``p`` % of demonstration
``j``'s observed agent (:func:`~interprim.model_selection.prefixes.observed_frames`) (``p`` = 10, 20, ..., 100), predict
the whole interaction and compare it with the truth on a common normalised-time grid.

Metrics per (task, method, held-out demo, fraction):

- ``rmse_ctrl`` / ``rmse_obs``: root mean square of the point error of the
  controlled agent's (robot's: agent 2's right hand) / observed agent's
  trajectory over the whole movement, in data units (metres on NuiSI); with
  ``point_dim = 3`` the error of a point is its 3-D Euclidean distance.
- ``final_err``: error of the controlled agent at the end of the movement;
  ``contact_err``: at the moment the true controlled point is furthest from
  its start (where the high-five or handshake happens).
- ``coverage``: fraction of the controlled agent's true coordinates inside the
  method's pointwise 90 % predictive interval (``mean +- 1.645 std``).
- ``phase`` / ``phase_true``: estimated and true fraction seen.

Methods (:data:`METHODS`, rows of :data:`interprim.models.registry.FAMILIES`): ``ip-forcing`` and
``ip-position`` (this library with
``sigma2="cv"`` and ``phase_method="likelihood"``, conditioning on forcing
values, Eq. 15, or on positions), ``ip-paper`` (the paper exactly: forcing,
DTW phase, ``sigma2="residual"``), ``*-dtw`` variants (same but DTW phase),
``iprompt`` (:class:`~interprim.models.promp.InteractionProMP`), ``nn``
(:class:`~interprim.models.demonstrations.NearestNeighbour`) and ``prior``
(:class:`~interprim.models.demonstrations.PriorMean`); a ``+pca`` suffix projects each
agent on ``pca_components`` principal components first (paper Sec. IV).

Recognition (:func:`recognition_fold`): one model per interaction; the held-out
demonstration's prefix is scored by every model (:mod:`interprim.models.recognition`).

Sweeps run as independent tasks through joblib (``backend="loky"`` on local
cores, or ``"dask"`` for a Dask cluster through joblib's Dask backend); see
:func:`run_sweep`.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from functools import lru_cache

import numpy as np

from ..core.preprocessing import time_normalise
from ..model_selection.metrics import Z90, point_rms
from ..model_selection.prefixes import observed_frames

__all__ = ["EvalConfig", "METHODS", "METHOD_NEEDS", "FRACTIONS", "task_names", "save_results", "recognition_table",
           "make_estimator", "evaluate_fold", "recognition_fold", "run_sweep", "summarise", "markdown_tables"]

FRACTIONS = tuple(round(0.1 * k, 1) for k in range(1, 11))
METHODS = ("ip-forcing", "ip-position", "ip-paper", "iprompt", "nn", "prior")
#: optional modules a method needs (the ``bench`` extra), beyond the core
METHOD_NEEDS = {"iprompt": ("movement_primitives", "gmr")}
#: phase variants evaluated from the same fitted IP model (``ip-forcing`` -> ``ip-forcing-dtw``, ...)
PHASE_VARIANTS = ("likelihood", "dtw", "oracle")
NUISI_ACTIONS = ("highfive1", "handshake2", "fistbump2", "clapfist2", "rocket1", "wave1")


@dataclass(frozen=True)
class EvalConfig:
    """Settings of an evaluation (hashable, so that workers can cache loaded data and models).

    Parameters
    ----------
    n_basis : int
        Basis functions per DoF of the IP models (NuiSI demos have only 12-24 real frames).
    smoothing_window : int or None
        Savitzky-Golay window of the IP models (frames at the loader's ``dt``).
    pca_components : int
        Components per agent of the ``+pca`` variants.
    promp_weights : int
        Basis functions per DoF of the Interaction ProMP.
    n_out : int
        Points of the normalised-time grid on which errors are computed.
    nuisi_dt : float
        Resampling interval of the NuiSI loader (s).
    development_only : bool
        NuiSI: use only the development recordings (the first two thirds of each interaction;
        :data:`interprim.evaluation.nested.HOLDOUT`), leaving the untouched hold-out out of every fit and test.
    data_path : str or None
        NuiSI file or data folder (default: the loaders' default).
    """

    n_basis: int = 20
    smoothing_window: int | None = 7
    pca_components: int = 6
    promp_weights: int = 10
    n_out: int = 100
    nuisi_dt: float = 0.05
    data_path: str | None = None
    development_only: bool = False
    fractions: tuple = FRACTIONS
    recognition_fractions: tuple = (0.2, 0.4, 0.6, 0.8)
    recognition_covariance: str = "ridge"
    recognition_noise: object = 1e-4


@dataclass
class Task:
    """One data set to evaluate on: demonstrations, which columns are observed, units."""

    name: str
    demos: list
    observed_dofs: list
    dt: float
    point_dim: int = 1
    columns: list = field(default_factory=list)
    # Prefixes: causal observed prefixes (None: the first frames of the arrays)
    prefixes: Callable[[int, int], np.ndarray] | None = None

    def prefix(self, j: int, k: int):
        """The first ``k`` observed frames of demonstration ``j`` as a robot had them (causal)."""
        if self.prefixes is None:
            return self.demos[j][:k, self.observed_dofs]
        return self.prefixes(j, k)


@lru_cache(maxsize=64)
def load_task(dataset: str, name: str, cfg: EvalConfig) -> Task:
    """The demonstrations, observed columns and sampling of one task of a data set (``nuisi``: one action, with
    causal prefixes; the built-in synthetic and simulated sets; the handwritten characters)."""
    if dataset == "nuisi":
        from ..datasets import load_nuisi
        from ..model_selection.prefixes import Prefixes

        d = load_nuisi(cfg.data_path, action=name, observed="upper_body", controlled="right_hand", dt=cfg.nuisi_dt)
        if cfg.development_only:
            from .nested import split_holdout

            d = d.take(split_holdout(len(d))[0])
        assert d.observed_dofs is not None and d.dt is not None  # load_nuisi sets both
        return Task(f"nuisi/{name}", list(d.demos), list(d.observed_dofs), float(d.dt), 3, list(d.columns),
                    Prefixes(d, d.observed_dofs))
    if dataset == "synthetic":
        from ..synthetic import two_agent_demos

        return Task("synthetic", two_agent_demos(30, seed=0), [0, 1], 0.01, 1, ["o1", "o2", "c1", "c2", "c3"])
    if dataset == "synthetic-noisy":
        from ..synthetic import two_agent_demos

        return Task("synthetic-noisy", two_agent_demos(30, seed=0, noise=0.02), [0, 1], 0.01, 1,
                    ["o1", "o2", "c1", "c2", "c3"])
    if dataset == "highfive-sim":
        from ..sim import generate_highfive

        data = generate_highfive(30, seed=0, progress=False)
        return Task("highfive-sim", list(data.demos), list(data.observed_dofs), float(data.dt), 1)
    if dataset == "characters":
        from ..datasets import load_character_trajectories

        d = load_character_trajectories(None, letters=name, max_per_letter=30)[name]
        return Task(f"characters/{name}", [np.asarray(x)[:, :2] for x in d.demos], [0, 1], float(d.dt or 0.005), 2)
    raise ValueError(f"unknown data set {dataset!r}; expected nuisi, synthetic, synthetic-noisy, highfive-sim, "
                     "characters")


def task_names(dataset: str) -> list:
    """The tasks of a data set (NuiSI: its six interactions)."""
    if dataset == "nuisi":
        return list(NUISI_ACTIONS)
    if dataset == "characters":
        return ["a", "b", "c", "e", "s"]
    return [dataset]


def make_estimator(method: str, observed_dofs, cfg: EvalConfig):
    """An unfitted estimator for a method name of :data:`METHODS` (optionally with a ``+pca`` suffix): a family
    of :mod:`interprim.models.registry` with this sweep's settings (``ip-*``: the Interaction Primitive with the
    observation model and phase named)."""
    from ..models import registry

    base, _, suffix = method.partition("+")
    pca = cfg.pca_components if suffix == "pca" else None
    if base in ("ip-forcing", "ip-position", "ip-paper", "ip-forcing-dtw", "ip-position-dtw"):
        # the registry's rows (ip-paper: the paper exactly); '-dtw': the same row with the paper's DTW phase
        row = base[:-len("-dtw")] if base.endswith("-dtw") else base
        settings = registry.Settings(tuple(observed_dofs), n_basis=cfg.n_basis, smoothing_window=cfg.smoothing_window,
                                     phase_method="dtw" if base.endswith("-dtw") else None)
        return registry.family(row).build(settings).set_params(pca_components=pca)
    if base == "iprompt":
        return registry.family("iprompt").cls(observed_dofs, n_weights=cfg.promp_weights)
    if base in ("nn", "prior"):
        return registry.family(base).build(registry.Settings(tuple(observed_dofs)))
    raise ValueError(f"unknown method {method!r}; expected one of {METHODS} (optionally with '+pca')")


def evaluate_fold(dataset: str, task: str, method: str, j: int, cfg: EvalConfig = EvalConfig()) -> list:
    """Fit ``method`` on all demonstrations of a task but ``j``; predict ``j`` at every fraction.

    Returns one record (dict) per fraction (see the module docstring for the metrics).
    """
    from ..core.blas import single_thread

    t = load_task(dataset, task, cfg)
    demos = t.demos
    train = [d for i, d in enumerate(demos) if i != j]
    test = demos[j]
    obs = t.observed_dofs
    ctrl = [i for i in range(test.shape[1]) if i not in set(obs)]
    n = cfg.n_out
    truth = time_normalise(test, n)
    base, plus, suffix = method.partition("+")
    variants: list[tuple[str, str | None]] = [(method, None)]
    if base in ("ip-forcing", "ip-position"):
        # one fit, three ways to get the phase: likelihood (the method), the paper's DTW, the true phase
        variants = [(f"{base}{'' if v == 'likelihood' else '-' + v}{plus}{suffix}", v) for v in PHASE_VARIANTS]
    with single_thread():
        est = make_estimator(method, obs, cfg).fit(train, dt=t.dt)
        selection = getattr(est, "selection_", None)
        out = []
        T = test.shape[0]
        for (name, variant), p in ((v, p) for v in variants for p in cfg.fractions):
            M = observed_frames(T, p)
            if variant == "oracle":
                pred = est.predict(t.prefix(j, M), phase=max((M - 1) / (T - 1), 1e-3))
            else:
                if variant is not None:
                    est.phase_method = variant
                pred = est.predict(t.prefix(j, M))
            Y = pred.trajectory(n)
            S = pred.std(n)
            err = Y - truth
            rec = {
                "dataset": dataset, "task": t.name, "method": name, "demo": int(j), "fraction": float(p),
                "n_observed": M, "phase_true": (M - 1) / (T - 1), "phase": float(pred.phase),
                "rmse_obs": point_rms(err[:, obs], t.point_dim),
                "log_likelihood": float(pred.log_likelihood),
            }
            if ctrl:
                ec = err[:, ctrl]
                start = truth[0, ctrl]
                k = int(np.argmax(np.linalg.norm(truth[:, ctrl] - start, axis=1)))
                rec.update({
                    "rmse_ctrl": point_rms(ec, t.point_dim),
                    "final_err": float(np.linalg.norm(ec[-1])),
                    "contact_err": float(np.linalg.norm(ec[k])),
                    "coverage": (float(np.mean(np.abs(ec) <= Z90 * S[:, ctrl] + 1e-12)) if S is not None
                                 else float("nan")),
                })
            if selection is not None and p == cfg.fractions[0]:
                keys = ("sigma2", "shrinkage", "cross_shrinkage", "phase_sigma2", "cv_error", "cv_error_prior")
                rec["selection"] = {k2: selection[k2] for k2 in keys if k2 in selection}
            out.append(rec)
    return out


@lru_cache(maxsize=32)
def _recognition_model(dataset: str, task: str, cfg: EvalConfig, leave_out: int):
    from ..models.primitive.estimator import InteractionPrimitive

    t = load_task(dataset, task, cfg)
    demos = [d for i, d in enumerate(t.demos) if i != leave_out]
    # recognition uses the prior and the phase noise only (chosen in fit), not the conditioning sigma2
    return InteractionPrimitive(observed_dofs=t.observed_dofs, n_basis=cfg.n_basis,
                                smoothing_window=cfg.smoothing_window, sigma2=1.0,
                                covariance=cfg.recognition_covariance,
                                phase_method="likelihood").fit(demos, dt=t.dt)


def recognition_fold(dataset: str, task: str, j: int, cfg: EvalConfig = EvalConfig()) -> list:
    """Recognise held-out demonstration ``j`` of ``task`` among all tasks of the data set, per fraction.

    The task's own model is fitted without ``j``; the other tasks' models on all their demonstrations.
    """
    from ..core.blas import single_thread
    from ..models.recognition import Recogniser

    names = task_names(dataset)
    with single_thread():
        models = {nm: _recognition_model(dataset, nm, cfg, j if nm == task else -1) for nm in names}
        rec = Recogniser(models, noise=cfg.recognition_noise)
        tk = load_task(dataset, task, cfg)
        T = tk.demos[j].shape[0]
        out = []
        for p in cfg.recognition_fractions:
            M = observed_frames(T, p)
            r = rec.recognise(tk.prefix(j, M))
            out.append({"dataset": dataset, "task": task, "demo": int(j), "fraction": float(p),
                        "predicted": r.label, "correct": bool(r.label == task),
                        "probabilities": {k: float(v) for k, v in r.probabilities.items()}})
    return out


def _jobs(datasets, methods, cfg, recognition: bool, max_demos=None):
    jobs = []
    for ds in datasets:
        for tk in task_names(ds):
            n = len(load_task(ds, tk, cfg).demos)
            idx = range(n) if max_demos is None else np.unique(np.linspace(0, n - 1, min(max_demos, n)).astype(int))
            for j in idx:
                for m in methods:
                    jobs.append(("fold", ds, tk, m, int(j)))
                if recognition and ds == "nuisi":
                    jobs.append(("recog", ds, tk, None, int(j)))
    # longest jobs first for better load balance
    jobs.sort(key=lambda x: (x[0] == "recog", not str(x[3]).startswith("ip"), "pca" in str(x[3])))
    return jobs


def _run_job(job, cfg):
    kind, ds, tk, m, j = job
    if kind == "fold":
        return kind, evaluate_fold(ds, tk, m, j, cfg)
    return kind, recognition_fold(ds, tk, j, cfg)


def run_sweep(datasets=("nuisi",), methods=METHODS, cfg: EvalConfig = EvalConfig(), n_jobs: int = 1,
              backend: str = "loky", recognition: bool = True, max_demos=None, progress: bool = True,
              scheduler: str | None = None):
    """Run the evaluation sweep (data sets x tasks x held-out demos x methods) in parallel.

    Parameters
    ----------
    datasets, methods : sequence of str
    cfg : EvalConfig
    n_jobs : int
        Parallel workers (joblib); ``-1`` for all cores.
    backend : {"loky", "threading", "dask"}
        joblib backend; ``"dask"`` needs ``dask[distributed]`` and connects to
        ``scheduler`` (an address) or starts a ``LocalCluster``.
    recognition : bool
        Also run the recognition sweep (NuiSI).
    max_demos : int, optional
        Hold out only this many demonstrations per task (a quick run).
    progress : bool
        Show a tqdm progress bar.

    Returns
    -------
    dict
        ``{"folds": [records], "recognition": [records]}``.
    """
    from joblib import Parallel, delayed, parallel_config

    jobs = _jobs(datasets, methods, cfg, recognition, max_demos)
    client = cluster = None
    if backend == "dask":
        try:
            from dask.distributed import Client, LocalCluster
        except ImportError as exc:  # pragma: no cover
            raise ImportError("backend='dask' needs the optional extra: pip install 'interprim[dask]'") from exc
        cluster = None if scheduler else LocalCluster(n_workers=max(1, n_jobs if n_jobs > 0 else 2),
                                                      threads_per_worker=1, processes=True, dashboard_address=None)
        client = Client(scheduler or cluster)
    folds: list = []
    recog: list = []
    try:
        with parallel_config(backend=backend, n_jobs=n_jobs, inner_max_num_threads=1 if backend == "loky" else None):
            gen = Parallel(return_as="generator_unordered")(delayed(_run_job)(jb, cfg) for jb in jobs)
            if progress:
                from tqdm.auto import tqdm

                gen = tqdm(gen, total=len(jobs), desc="evaluate", unit="fold")
            for kind, recs in gen:
                (folds if kind == "fold" else recog).extend(recs)
    finally:
        if client is not None:
            client.close()
            if cluster is not None:  # the cluster started here: its worker processes end with the sweep
                cluster.close()
    return {"folds": folds, "recognition": recog, "config": asdict(cfg)}


def _agg(vals):
    v = np.asarray([x for x in vals if x is not None and np.isfinite(x)], dtype=np.float64)
    return float(v.mean()) if v.size else float("nan")


def summarise(results) -> dict:
    """Means over held-out demonstrations: ``{task: {method: {metric: {fraction: value}}}}`` and recognition."""
    table: dict = {}
    for r in results["folds"]:
        d = table.setdefault(r["task"], {}).setdefault(r["method"], {})
        for k in ("rmse_ctrl", "rmse_obs", "final_err", "contact_err", "coverage"):
            if k in r:
                d.setdefault(k, {}).setdefault(r["fraction"], []).append(r[k])
        d.setdefault("phase_err", {}).setdefault(r["fraction"], []).append(abs(r["phase"] - r["phase_true"]))
    out = {t: {m: {k: {f: _agg(v) for f, v in sorted(fr.items())} for k, fr in md.items()} for m, md in tm.items()}
           for t, tm in table.items()}
    rec: dict = {}
    for r in results.get("recognition", []):
        rec.setdefault(r["task"], {}).setdefault(r["fraction"], []).append(float(r["correct"]))
    rec_s = {t: {f: _agg(v) for f, v in sorted(fr.items())} for t, fr in rec.items()}
    if rec:
        allf: dict = {}
        for fr in rec.values():
            for f, v in fr.items():
                allf.setdefault(f, []).extend(v)
        rec_s["all"] = {f: _agg(v) for f, v in sorted(allf.items())}
    sel: dict = {}
    for r in results["folds"]:
        if "selection" in r:
            sel.setdefault(r["task"], {}).setdefault(r["method"], []).append(r["selection"])
    sel_s = {t: {m: {k: float(np.median([s[k] for s in v if k in s])) for k in v[0]} for m, v in tm.items()}
             for t, tm in sel.items()}
    return {"metrics": out, "recognition": rec_s, "selection": sel_s}


def _fmt(x, digits=3):
    return "–" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{x:.{digits}f}"


def markdown_tables(summary, fractions=(0.4, 0.6, 0.8), metric: str = "rmse_ctrl") -> str:
    """Markdown tables: per task, ``metric`` by method at the given fractions, plus recognition."""
    lines = []
    titles = {"rmse_ctrl": "controlled agent (agent 2 hand) RMSE", "rmse_obs": "observed agent RMSE",
              "final_err": "final controlled position error", "contact_err": "controlled error at contact",
              "coverage": "coverage of the 90 % interval (controlled)", "phase_err": "absolute phase error"}
    lines.append(f"### {titles.get(metric, metric)}\n")
    head = "| task | method | " + " | ".join(f"{int(round(f * 100))} %" for f in fractions) + " |"
    lines += [head, "|" + "---|" * (len(fractions) + 2)]
    for t, tm in summary["metrics"].items():
        for m, md in tm.items():
            if metric not in md:
                continue
            vals = [md[metric].get(f, md[metric].get(str(f), float("nan"))) for f in fractions]
            lines.append(f"| {t} | {m} | " + " | ".join(_fmt(v) for v in vals) + " |")
    return "\n".join(lines) + "\n"


def recognition_table(summary, fractions=(0.2, 0.4, 0.6, 0.8, 1.0)) -> str:
    """Markdown table of the recognition accuracy per interaction (and ``all``) at the given fractions;
    an empty string when the summary has no recognition results."""
    rec = summary.get("recognition", {})
    if not rec:
        return ""
    lines = ["### recognition accuracy (leave-one-out)\n",
             "| interaction | " + " | ".join(f"{int(round(f * 100))} %" for f in fractions) + " |",
             "|" + "---|" * (len(fractions) + 1)]
    for t, fr in rec.items():
        lines.append(f"| {t} | " + " | ".join(_fmt(fr.get(f, float("nan")), 2) for f in fractions) + " |")
    return "\n".join(lines) + "\n"


def save_results(results, summary, out_dir) -> list:
    """Write ``results.json``, ``summary.json`` and ``tables.md`` to ``out_dir``; returns the paths."""
    from pathlib import Path

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    (out / "results.json").write_text(json.dumps(results, indent=1, default=float))
    (out / "summary.json").write_text(json.dumps(summary, indent=1, default=float))
    md = ["# interprim evaluation\n", "Leave-one-out; means over held-out demonstrations.\n"]
    for metric in ("rmse_ctrl", "rmse_obs", "final_err", "contact_err", "coverage", "phase_err"):
        md.append(markdown_tables(summary, metric=metric))
    md.append(recognition_table(summary))
    (out / "tables.md").write_text("\n".join(md))
    paths += [out / "results.json", out / "summary.json", out / "tables.md"]
    return paths

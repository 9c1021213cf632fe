"""``interprim evaluate``: leave-one-out sweeps of IPs and their peers (tables, JSON, figures).

Top-level imports are light; the work happens in :mod:`interprim.evaluation.sweep`.
"""

from __future__ import annotations

DEFAULT_METHODS = "ip-forcing,ip-position,ip-forcing+pca,ip-position+pca,ip-paper,iprompt,nn,prior"


def add_parser(subparsers):
    p = subparsers.add_parser(
        "evaluate",
        help="leave-one-out evaluation of IPs and peers (RMSE vs %% observed, recognition, figures)",
        description=(
            "Leave-one-out over the demonstrations of each task: observe 10-100 %% of the observed agent, "
            "predict the controlled agent (NuiSI: agent 2's right hand) and the observed agent's completion. "
            "Methods: ip-forcing / ip-position (sigma2 by cross-validation, likelihood phase; '-dtw' and "
            "'-oracle' phase variants are reported from the same fits), ip-paper (the paper exactly), iprompt "
            "(Interaction ProMP from movement-primitives + gmr), nn (nearest demonstration under DTW), prior "
            "(mean demonstration); '+pca' projects each agent on principal components first. Writes "
            "tables.md, summary.json, results.json and figures to --out."
        ),
    )
    p.add_argument("--data", default="nuisi",
                   help="comma-separated data sets: nuisi, synthetic, synthetic-noisy, highfive-sim, characters "
                        "(default nuisi)")
    p.add_argument("--data-path", default=None, help="NuiSI file or data folder (default: ../shared/data)")
    p.add_argument("--methods", default=DEFAULT_METHODS, help=f"comma-separated methods (default {DEFAULT_METHODS})")
    p.add_argument("--jobs", type=int, default=1, help="parallel workers (-1: all cores)")
    p.add_argument("--backend", default="loky", choices=["loky", "threading", "dask"],
                   help="joblib backend; dask needs 'interprim[dask]' and uses --scheduler or a LocalCluster")
    p.add_argument("--scheduler", default=None, help="Dask scheduler address (with --backend dask)")
    p.add_argument("--out", default="evaluation", help="output folder (default ./evaluation)")
    p.add_argument("--quick", action="store_true",
                   help="hold out only 4 demonstrations per task and observe 20/40/60/80/100 %%")
    p.add_argument("--no-recognition", action="store_true", help="skip the recognition sweep")
    p.add_argument("--no-figures", action="store_true", help="skip the figures")
    p.add_argument("--pca", type=int, default=6, help="principal components per agent of '+pca' methods")
    p.add_argument("--n-basis", type=int, default=20, help="basis functions per DoF of the IP models")
    p.add_argument("--fractions", default=None,
                   help="comma-separated observed fractions (default 0.1,0.2,...,1.0)")
    p.set_defaults(func=run)
    return p


def run(args) -> int:
    from dataclasses import replace

    from ..evaluation import EvalConfig, recognition_table, run_sweep, save_results, summarise

    cfg = EvalConfig(data_path=args.data_path, pca_components=args.pca, n_basis=args.n_basis)
    if args.fractions:
        cfg = replace(cfg, fractions=tuple(float(f) for f in args.fractions.split(",") if f.strip()))
    if args.quick:
        cfg = replace(cfg, fractions=(0.2, 0.4, 0.6, 0.8, 1.0), recognition_fractions=(0.2, 0.4, 0.6))
    datasets = [d.strip() for d in args.data.split(",") if d.strip()]
    methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    res = run_sweep(datasets, methods, cfg, n_jobs=args.jobs, backend=args.backend,
                    recognition=not args.no_recognition, max_demos=4 if args.quick else None,
                    scheduler=args.scheduler)
    summary = summarise(res)
    paths = save_results(res, summary, args.out)
    if not args.no_figures:
        from ..evaluation.plots import evaluation_figures

        paths += evaluation_figures(res, summary, cfg, args.out, datasets)
    from ..evaluation import markdown_tables

    print(markdown_tables(summary))
    print(recognition_table(summary))
    for p in paths:
        print(f"wrote {p}")
    return 0

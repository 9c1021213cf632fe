"""``interprim evaluate``: leave-one-out sweeps of IPs and their peers (tables, JSON, figures).

Top-level imports are light; the work happens in :mod:`interprim.evaluation.sweep`.
"""

from __future__ import annotations

from ..core.cv import DEFAULT_HORIZON

DEFAULT_METHODS = "ip-forcing,ip-position,ip-forcing+pca,ip-position+pca,ip-paper,iprompt,nn,prior"
#: the methods of ``--data FILE`` (:func:`interprim.evaluation.realtime.default_methods`)
USER_METHODS = "ip,learned,ip-paper,nn,prior"


def add_parser(subparsers):
    from ._common import MAX_NAN_GAP_HELP

    p = subparsers.add_parser(
        "evaluate",
        help="leave-one-out evaluation of IPs and peers (RMSE vs %% observed, recognition, figures)",
        description=(
            "Leave-one-out over the demonstrations of each task: observe 10-100 % of the observed agent, "
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
                        "(default nuisi); or YOUR recordings: a CSV/NPZ file or a folder of them (with --observed), "
                        "evaluated by the real-time, rest-of-the-movement, phase, calibration and whole-movement "
                        "protocols")
    p.add_argument("--observed", default=None,
                   help="with --data FILE: the observed agent's columns (names or 0-based indices, comma-separated; "
                        "default: the file's '# observed:' entry)")
    p.add_argument("--controlled", default=None,
                   help="with --data FILE: the controlled agent's columns (names, indices or patterns); columns named "
                        "in neither --observed nor --controlled are dropped")
    p.add_argument("--resample", type=float, default=None, metavar="DT",
                   help="with --data FILE: resample the demonstrations to this interval (s) (needed for irregular "
                        "time stamps; ROS bags: the grid both agents are interpolated onto)")
    p.add_argument("--max-nan-gap", type=int, default=None,
                   help="with --data FILE: " + MAX_NAN_GAP_HELP)
    p.add_argument("--folds", type=int, default=None,
                   help="with --data FILE: k-fold cross-validation (default: leave-one-out)")
    p.add_argument("--horizon", type=float, default=DEFAULT_HORIZON,
                   help=f"with --data FILE: seconds ahead predicted after each observed frame (default "
                   f"{DEFAULT_HORIZON}; the printed 'interprim fit' command fits for it)")
    p.add_argument("--dt", type=float, default=None,
                   help="with --data FILE: sampling interval in seconds of files without time stamps")
    p.add_argument("--smoothing-window", type=int, default=None,
                   help="with --data FILE: Savitzky-Golay window (frames) of the IP models (noisy recordings)")
    p.add_argument("--data-path", default=None, help="NuiSI file or data folder (default: ../shared/data)")
    p.add_argument("--methods", default=None,
                   help=f"comma-separated methods (built-in data: default {DEFAULT_METHODS}; with --data FILE: "
                        f"some of {USER_METHODS}, default all)")
    p.add_argument("--jobs", type=int, default=1, help="parallel workers (-1: all cores)")
    p.add_argument("--backend", default="loky", choices=["loky", "threading", "dask"],
                   help="joblib backend; dask needs 'interprim[dask]' and uses --scheduler or a LocalCluster")
    p.add_argument("--scheduler", default=None, help="Dask scheduler address (with --backend dask)")
    p.add_argument("--out", default="evaluation", help="output folder (default ./evaluation)")
    p.add_argument("--quick", action="store_true",
                   help="hold out only 4 demonstrations per task and observe 20/40/60/80/100 %%")
    p.add_argument("--no-recognition", action="store_true", help="skip the recognition sweep")
    p.add_argument("--development-only", action="store_true",
                   help="NuiSI: use only the development recordings (the first two thirds of each interaction), "
                        "leaving the hold-out untouched")
    p.add_argument("--no-figures", action="store_true", help="skip the figures")
    p.add_argument("--no-forward", action="store_true",
                   help="with --data FILE: skip the forward check (the latest third of the recordings predicted by "
                        "models fitted on the earlier two thirds; run from 6 recordings)")
    p.add_argument("--pca", type=int, default=6, help="principal components per agent of '+pca' methods")
    p.add_argument("--n-basis", type=int, default=20, help="basis functions per DoF of the IP models")
    p.add_argument("--fractions", default=None,
                   help="comma-separated observed fractions (default 0.1,0.2,...,1.0)")
    from ._common import add_recording_args

    add_recording_args(p, what="--data")
    p.set_defaults(func=run)
    return p


DATA_SETS = ("nuisi", "synthetic", "synthetic-noisy", "highfive-sim", "characters")


def _check_names(datasets, methods, cfg):
    """One-line errors (naming the flag) for unknown --data / --methods, before any work starts."""
    from ..core.errors import InterprimError
    from ..evaluation import make_estimator

    bad = [d for d in datasets if d not in DATA_SETS] or ([] if datasets else ["''"])
    if bad:
        raise InterprimError(
            f"--data {','.join(bad)}: not a built-in data set; expected {', '.join(DATA_SETS)}, or the path of "
            "your own CSV/NPZ file or folder (with --observed)"
        )
    for m in methods:
        try:
            make_estimator(m, [0], cfg)
        except ValueError:
            raise InterprimError(f"--methods: unknown method {m!r}; expected comma-separated names such as "
                                 f"{DEFAULT_METHODS}") from None


def _available(methods) -> list:
    """``methods`` without those whose peer packages are not installed, each left out with a note on stderr."""
    import sys

    from .._optional import install_hint, missing
    from ..evaluation.sweep import METHOD_NEEDS

    keep = []
    for m in methods:
        gone = missing(*METHOD_NEEDS.get(m.partition("+")[0], ()))
        if gone:
            print(f"note: skipping {m}: it needs {', '.join(gone)} ({install_hint(gone)})", file=sys.stderr)
        else:
            keep.append(m)
    if not keep:
        from ..core.errors import MissingExtraError

        raise MissingExtraError(f"--methods: none of {', '.join(methods)} can run without its peer packages")
    return keep


def _is_user_data(data: str) -> bool:
    from pathlib import Path

    suffixes = (".csv", ".npz", ".c3d", ".bvh", ".bag", ".db3", ".mcap")
    return data.strip() not in DATA_SETS and (Path(data).exists() or data.lower().endswith(suffixes))


def run_user_data(args) -> int:
    """``--data FILE``: every protocol of :mod:`interprim.evaluation.realtime` on the user's own demonstrations."""
    import sys
    from pathlib import Path

    from ..assessment import evaluate_demonstrations
    from ..core.errors import InterprimError
    from ..evaluation.realtime import (
        ALL_METHODS_FROM,
        MIN_DEMONSTRATIONS,
        RealTimeConfig,
        default_methods,
        forward_markdown,
        markdown_table,
        save_report,
    )

    if not Path(args.data).exists():
        raise InterprimError(f"--data {args.data}: no such file or folder")
    if getattr(args, "development_only", False):
        raise InterprimError("--development-only holds out the built-in NuiSI hold-out; with --data FILE keep your own "
                             "hold-out recordings out of the file instead")
    from ._common import SPLIT_HINT, agent_columns, print_notes, read_demonstrations, split_cols

    ds = read_demonstrations(args.data, args)  # as 'interprim fit' reads it: irregular stamps at their median
    print_notes(ds, "evaluate", file=sys.stderr)
    ds, obs = agent_columns(ds, split_cols([args.observed]), split_cols([args.controlled]), args.data)
    if len(ds.demos) < MIN_DEMONSTRATIONS:
        raise InterprimError(f"--data {args.data}: {len(ds.demos)} demonstration(s); the evaluation needs at least "
                             f"{MIN_DEMONSTRATIONS} (every method runs from {ALL_METHODS_FROM}, leave-one-out). "
                             + SPLIT_HINT)
    if args.folds is not None and args.folds < 2:
        raise InterprimError(f"--folds {args.folds}: needs at least 2 folds")
    methods = None
    if args.methods is not None:
        methods = [m.strip() for m in args.methods.split(",") if m.strip()]
        known = list(default_methods(obs))
        if not methods or any(m not in known for m in methods):
            raise InterprimError(f"--methods {args.methods}: with --data FILE the methods are some of "
                                 f"{','.join(known)}")
    cfg = RealTimeConfig(horizon=float(args.horizon))
    notes = []
    # the printed 'interprim fit' command reads the data as this evaluation did: the file, every data option, and
    # the observed (and controlled) columns actually used, also when they came from the file's '# observed:' line
    from ._common import data_flags, shell_words

    ctrl_flag = ["--controlled", ",".join(ds.columns[i] for i in range(ds.n_dofs) if i not in set(obs))] \
        if args.controlled else []
    horizon_flag = [] if float(args.horizon) == DEFAULT_HORIZON else ["--horizon", f"{float(args.horizon):g}"]
    fit_data = shell_words([args.data] + data_flags(args) + ctrl_flag + horizon_flag)
    fit_observed = shell_words([",".join(ds.columns[i] for i in obs)])

    def note(line):
        notes.append(line)
        print(f"note: {line}", file=sys.stderr)

    try:
        recs, summary, sentence = evaluate_demonstrations(ds, obs, float(ds.dt), k=args.folds, cfg=cfg,
                                                          smoothing_window=args.smoothing_window,
                                                          n_basis=args.n_basis, methods=methods, progress=True,
                                                          log=note, data=fit_data, observed=fit_observed)
    except InterprimError:
        raise
    except (ValueError, TypeError) as exc:  # e.g. too few demonstrations left in a training fold
        raise InterprimError(f"cannot evaluate --data {args.data}: {exc}") from None
    forward = None
    if not args.no_forward:
        from ..assessment import FORWARD_FROM, forward_check

        if len(ds.demos) < FORWARD_FROM:
            note(f"forward check left out: it predicts the latest third of the recordings from the earlier two "
                 f"thirds and needs at least {FORWARD_FROM} recordings, got {len(ds.demos)}")
        else:
            forward = forward_check(ds, obs, float(ds.dt), cfg=cfg, smoothing_window=args.smoothing_window,
                                    n_basis=args.n_basis, methods=methods,
                                    log=lambda line: print(line, file=sys.stderr, flush=True))
    from ._common import moved, output_when_done

    with output_when_done(args.out, folder=True) as tmp:  # the report appears whole, or not at all
        paths = save_report(recs, summary, sentence, tmp, title=f"{args.data}: {len(ds.demos)} demonstrations",
                            horizon=float(args.horizon), notes=notes, forward=forward)
    paths = moved(paths, tmp, args.out)
    print(markdown_table(summary))
    if forward is not None:
        print("\n" + forward_markdown(forward))
    print(f"\nverdict: {sentence}")
    if forward is not None:
        print(f"\nforward check: {' '.join(forward['sentences'])}")
    for p in paths:
        print(f"wrote {p}")
    return 0


def _fractions(text: str) -> tuple:
    """``--fractions`` as numbers in (0, 1], or a one-line error naming the flag."""
    from ._common import CommandError

    out = []
    for f in (f.strip() for f in text.split(",")):
        if not f:
            continue
        try:
            v = float(f)
        except ValueError:
            raise CommandError(f"--fractions {text}: {f!r} is not a number (comma-separated fractions in (0, 1])") \
                from None
        if not 0 < v <= 1:
            raise CommandError(f"--fractions {text}: {f} is not in (0, 1] (the fraction of a movement observed)")
        out.append(v)
    if not out:
        raise CommandError(f"--fractions {text!r}: no fraction given")
    return tuple(out)


def run(args) -> int:
    from dataclasses import replace

    from ._common import check_output, positive_number

    positive_number(args.horizon, "--horizon")
    positive_number(args.dt, "--dt")
    positive_number(args.resample, "--resample")
    fractions = _fractions(args.fractions) if args.fractions else None
    check_output(args.out, "--out", folder=True)
    if _is_user_data(args.data):
        return run_user_data(args)

    from ..evaluation import EvalConfig, recognition_table, run_sweep, save_results, summarise

    cfg = EvalConfig(data_path=args.data_path, pca_components=args.pca, n_basis=args.n_basis,
                     development_only=args.development_only)
    if fractions is not None:
        cfg = replace(cfg, fractions=fractions)
    if args.quick:
        cfg = replace(cfg, fractions=(0.2, 0.4, 0.6, 0.8, 1.0), recognition_fractions=(0.2, 0.4, 0.6))
    datasets = [d.strip() for d in args.data.split(",") if d.strip()]
    methods = [m.strip() for m in (args.methods or DEFAULT_METHODS).split(",") if m.strip()]
    _check_names(datasets, methods, cfg)
    from .._optional import require

    require(("joblib", "tqdm"), "the sweep", extra="experiments")
    methods = _available(methods)
    res = run_sweep(datasets, methods, cfg, n_jobs=args.jobs, backend=args.backend,
                    recognition=not args.no_recognition, max_demos=4 if args.quick else None,
                    scheduler=args.scheduler)
    summary = summarise(res)
    from ._common import moved, output_when_done

    with output_when_done(args.out, folder=True) as tmp:  # the results appear whole, or not at all
        paths = save_results(res, summary, tmp)
        if not args.no_figures:
            from ..evaluation.plots import evaluation_figures

            paths += evaluation_figures(res, summary, cfg, tmp, datasets)
    paths = moved(paths, tmp, args.out)
    from ..evaluation import markdown_tables

    print(markdown_tables(summary))
    print(recognition_table(summary))
    for p in paths:
        print(f"wrote {p}")
    return 0

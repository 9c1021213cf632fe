"""Sub-commands ``fit``, ``predict`` and ``handwriting`` of the ``interprim`` command line.

Only :mod:`argparse` is imported at module level; numpy, the core and matplotlib are imported
inside the command functions, so ``interprim --help`` stays fast.  File formats are described
in ``docs/data-formats.md``.
"""

from __future__ import annotations

import argparse

from .errors import DataFileError, InterprimError

__all__ = ["add_parser", "CommandError"]


class CommandError(InterprimError, ValueError):
    """A command-line argument is invalid or a step of a command failed (reported in one line)."""


_FIT_EPILOG = """\
DEMOS is a CSV file (header of column names, a 'time' column in seconds, optionally a 'demo'
column splitting several demonstrations), a folder of such files, or an NPZ archive with
demo_000, demo_001, ... (T, D) arrays, time_000, ... and 'columns' (see docs/data-formats.md).

examples:
  interprim fit demos.csv --observed hand_x,hand_y,hand_z -o model.npz
  interprim fit recordings/ --observed 0,1,2 --n-basis 15 --smoothing-window 7 -o model.npz
"""

_PREDICT_EPILOG = """\
PARTIAL holds the frames of the observed agent seen so far (CSV or NPZ, one demonstration, same
column names as the training data; other columns are ignored; without a 'time' column the frames
are taken at the model's sampling interval).

OUT (.csv or .npz) gets the prediction of the whole movement on a normalised-time grid:
  phase            fraction of the movement already observed (DTW, paper Eq. 8-9, or the
                   model's phase_method)
  s, time          normalised time 0..1 and seconds since the start (s * estimated duration)
  mean_<col>       posterior mean of every DoF (observed and controlled)
  std_<col>        pointwise posterior standard deviation
  sample<k>_<col>  with --samples K: K trajectories drawn from the posterior
CSV files start with '#' comment lines holding phase, speed, duration and log-likelihood.

example:
  interprim predict model.npz first_half.csv -o prediction.csv --samples 10
"""


def add_parser(subparsers) -> None:
    """Register ``fit``, ``predict`` and ``handwriting`` with an ``argparse`` sub-parser set."""
    fmt = argparse.RawDescriptionHelpFormatter

    p = subparsers.add_parser(
        "fit",
        help="learn an Interaction Primitive from demonstration files",
        description="Learn an Interaction Primitive from demonstrations of two agents (or one) and save it.",
        epilog=_FIT_EPILOG,
        formatter_class=fmt,
    )
    p.add_argument("demos", metavar="DEMOS", help="CSV file, NPZ file or folder of demonstrations")
    p.add_argument(
        "--observed",
        action="append",
        metavar="COLS",
        help="the observed agent's (human's) columns: names or 0-based indices, comma-separated "
        "(repeatable). All other columns are the controlled agent (robot); naming every column "
        "gives a single-agent model. Default: the file's '# observed:' entry",
    )
    p.add_argument("-o", "--output", required=True, metavar="MODEL", help="model file to write (.npz)")
    p.add_argument("--columns", metavar="COLS", help="use only these columns (names or indices, comma-separated)")
    p.add_argument("--n-basis", type=int, default=20, help="Gaussian basis functions per DoF (default 20)")
    p.add_argument(
        "--observation",
        choices=("forcing", "position"),
        default=None,
        help="condition on forcing terms (paper Eq. 15) or on positions (default: the model's)",
    )
    p.add_argument(
        "--covariance", choices=("shrinkage", "ridge", "empirical"), default=None, help="covariance regularisation"
    )
    p.add_argument(
        "--sigma2",
        type=_sigma2,
        default=None,
        help="observation noise variance: a number, 'auto' or 'cv' (cross-validated) (default: the model's)",
    )
    p.add_argument(
        "--phase-method",
        choices=("dtw", "likelihood"),
        default=None,
        help="phase estimation: open-end DTW (paper Eq. 5-9) or likelihood (default: the model's)",
    )
    p.add_argument(
        "--input-noise",
        type=float,
        default=None,
        metavar="STD",
        help="standard deviation (data units) of noise in the online input that the demonstrations lack "
        "(sensor noise); makes predictions robust to it",
    )
    p.add_argument(
        "--smoothing-window", type=int, default=None, help="Savitzky-Golay window in frames for derivatives (odd)"
    )
    p.add_argument("--pca", type=int, default=None, metavar="K", help="project each agent onto K principal components")
    p.add_argument("--dt", type=float, default=None, help="sampling interval (s) for files without time stamps")
    p.add_argument(
        "--resample", type=float, default=None, metavar="DT", help="resample the demonstrations to this interval (s)"
    )
    p.add_argument("--max-nan-gap", type=int, default=0, help="fill interior gaps of up to this many missing frames")
    p.set_defaults(func=cmd_fit)

    p = subparsers.add_parser(
        "predict",
        help="predict both agents' movements from a partial observation",
        description="Predict the rest of the interaction (both agents) from the observed agent's first frames.",
        epilog=_PREDICT_EPILOG,
        formatter_class=fmt,
    )
    p.add_argument("model", metavar="MODEL", help="model file written by 'interprim fit'")
    p.add_argument("partial", metavar="PARTIAL", help="CSV or NPZ with the observed agent's frames so far")
    p.add_argument("-o", "--output", required=True, metavar="OUT", help="output file (.csv or .npz)")
    p.add_argument("--samples", type=int, default=0, metavar="K", help="also write K posterior samples")
    p.add_argument("--n-points", type=int, default=100, help="points of the normalised-time grid (default 100)")
    p.add_argument("--seed", type=int, default=0, help="random seed of the samples (default 0)")
    p.add_argument("--dt", type=float, default=None, help="sampling interval (s) of PARTIAL if it has no time column")
    p.set_defaults(func=cmd_predict)

    p = subparsers.add_parser(
        "handwriting",
        help="handwriting completion experiment (paper Fig. 3-4) on real letters",
        description=(
            "Learn one single-agent model per letter of the UCI Character Trajectories and per LASA shape, "
            "observe 20-80% of held-out samples, complete them, and report the error with the prior-mean and "
            "nearest-neighbour baselines (report.md, results.json and figures in --out)."
        ),
        formatter_class=fmt,
    )
    p.add_argument("--out", default="handwriting-results", help="output folder (default ./handwriting-results)")
    p.add_argument("--letters", default=None, help="letters to use, e.g. 'abc' (default all 20)")
    p.add_argument("--max-per-letter", type=int, default=30, help="samples per letter (default 30; 0 = all)")
    p.add_argument("--folds", type=int, default=5, help="cross-validation folds per letter (default 5)")
    p.add_argument(
        "--shapes",
        default=None,
        help="LASA shapes, comma-separated, or 'none' (default: GShape,Angle,Sshape,WShape,NShape,Snake; "
        'needs pip install "interprim[lasa]")',
    )
    p.add_argument("--n-basis", type=int, default=20, help="basis functions per DoF (default 20)")
    p.add_argument(
        "--observations",
        default="forcing,position",
        help="IP observation models to compare, comma-separated (default forcing,position)",
    )
    p.add_argument(
        "--no-true-phase", action="store_true", help="skip the diagnostic IP given the true phase"
    )
    p.add_argument(
        "--beyond-paper",
        action="store_true",
        help="also evaluate an IP with phase by likelihood and cross-validated sigma2 (several times slower)",
    )
    p.add_argument("--seed", type=int, default=0, help="seed of the folds (default 0)")
    p.add_argument("--data", default=None, metavar="PATH", help="trajectories_train.mat (default: the data folder)")
    p.add_argument("--no-figures", action="store_true", help="skip the figures")
    p.set_defaults(func=cmd_handwriting)


# ----------------------------------------------------------------------------- helpers
def _sigma2(text):
    if text in ("auto", "cv"):
        return text
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive number, 'auto' or 'cv', got {text!r}") from None
    if not v > 0:
        raise argparse.ArgumentTypeError(f"must be positive, got {text!r}")
    return v


def _split_cols(values):
    out = []
    for v in values or []:
        out.extend(s.strip() for s in v.split(",") if s.strip())
    return out


def _positive(value, name):
    if value is not None and not value > 0:
        raise CommandError(f"{name} must be positive, got {value!r}")
    return value


def _model_columns(model):
    """Column names of the demonstrations a model was fitted on (``None`` if it was fitted without names)."""
    return getattr(model, "columns_", None)


# ----------------------------------------------------------------------------- fit
def cmd_fit(args) -> int:
    """``interprim fit``: load demonstrations, fit an InteractionPrimitive, save it."""
    from pathlib import Path

    import interprim as ip
    from interprim.datasets import load_demonstrations
    from interprim.datasets._base import select_columns

    _positive(args.n_basis, "--n-basis")
    _positive(args.dt, "--dt")
    _positive(args.resample, "--resample")
    ds = load_demonstrations(
        args.demos,
        columns=args.columns,
        dt=args.dt,
        resample_dt=args.resample,
        max_nan_gap=args.max_nan_gap,
    )
    observed = _split_cols(args.observed)
    if observed:
        obs = select_columns(ds.columns, observed, where=f"--observed (columns of {args.demos})")
    elif ds.observed_dofs:
        obs = list(ds.observed_dofs)
    else:
        raise CommandError(
            f"--observed is required: name the observed agent's columns among {', '.join(ds.columns)}"
        )
    if len(ds) < 2:
        raise CommandError(f"{args.demos} holds {len(ds)} demonstration; at least 2 are needed to learn a distribution")
    kwargs = {"n_basis": args.n_basis}
    for key, val in (
        ("observation", args.observation),
        ("covariance", args.covariance),
        ("sigma2", args.sigma2),
        ("phase_method", args.phase_method),
        ("input_noise", args.input_noise),
        ("smoothing_window", args.smoothing_window),
        ("pca_components", args.pca),
    ):
        if val is not None:
            kwargs[key] = val
    try:
        model = ip.InteractionPrimitive(observed_dofs=obs, **kwargs)
        model.fit(ds)  # its dt or time stamps, and its column names (stored in the model file)
    except InterprimError:
        raise
    except (ValueError, TypeError) as exc:
        raise CommandError(f"cannot fit the model to {args.demos}: {exc}") from None
    out = Path(args.output)
    if out.parent and not out.parent.exists():
        out.parent.mkdir(parents=True, exist_ok=True)
    model.save(out)
    obs_names = [ds.columns[i] for i in model.observed_dofs_]
    ctrl_names = [ds.columns[i] for i in model.controlled_dofs_]
    print(
        f"fitted {len(ds)} demonstrations, {ds.n_dofs} columns, dt={model.dt_:.4g} s, "
        f"mean duration {model.mean_duration_:.3g} s\n"
        f"  observed:   {', '.join(obs_names)}\n"
        f"  controlled: {', '.join(ctrl_names) or '(none: single-agent model)'}\n"
        f"saved {out}"
    )
    return 0


# ----------------------------------------------------------------------------- predict
def cmd_predict(args) -> int:
    """``interprim predict``: condition a saved model on a partial observation and write the prediction."""
    from pathlib import Path

    import numpy as np

    import interprim as ip
    from interprim.datasets import load_demonstrations

    out = Path(args.output)
    suffix = out.suffix.lower()
    if suffix not in (".csv", ".npz"):
        raise CommandError(f"-o {args.output}: the output must end in .csv or .npz")
    if args.samples < 0:
        raise CommandError(f"--samples must be >= 0, got {args.samples}")
    if args.n_points < 2:
        raise CommandError(f"--n-points must be >= 2, got {args.n_points}")
    _positive(args.dt, "--dt")
    if not Path(args.model).exists():
        raise FileNotFoundError(f"model file not found: {args.model}")
    model = ip.InteractionPrimitive.load(args.model)
    columns = _model_columns(model) or [f"dof_{j}" for j in range(model.n_dofs_)]
    obs_names = [columns[i] for i in model.observed_dofs_]
    part = load_demonstrations(args.partial, dt=args.dt or model.dt_, min_frames=1)
    if len(part) != 1:
        raise CommandError(f"{args.partial} holds {len(part)} demonstrations; give the frames of one movement")
    missing = [c for c in obs_names if c not in part.columns]
    if not missing:
        idx = [part.columns.index(c) for c in obs_names]
    elif len(part.columns) == len(obs_names) and all(c.startswith("dof_") for c in part.columns):
        idx = list(range(len(obs_names)))  # unnamed columns, taken in order
    else:
        raise DataFileError(
            f"{args.partial}: missing observed column(s) {missing}; the model observes "
            f"{', '.join(obs_names)} and the file has {', '.join(part.columns)}"
        )
    frames = part.demos[0][:, idx]
    t = part.times[0]
    try:
        if frames.shape[0] > 1 and (part.dt is None or abs(part.dt - model.dt_) > 1e-9 * model.dt_):
            pred = model.predict(frames, times=t - t[0])
        else:
            pred = model.predict(frames)
    except InterprimError:
        raise
    except (ValueError, TypeError) as exc:
        raise CommandError(f"cannot predict from {args.partial}: {exc}") from None
    n = int(args.n_points)
    s = np.linspace(0.0, 1.0, n)
    mean = np.asarray(pred.trajectory(n))
    std = np.asarray(pred.std(n))
    samples = np.asarray(pred.samples(args.samples, n, random_state=args.seed)) if args.samples else None
    scalars = {
        "phase": float(pred.phase),
        "speed": float(pred.speed),
        "duration": float(pred.duration),
        "log_likelihood": float(pred.log_likelihood),
    }
    if out.parent and not out.parent.exists():
        out.parent.mkdir(parents=True, exist_ok=True)
    if suffix == ".npz":
        arrays = dict(
            s=s,
            time=s * scalars["duration"],
            mean=mean,
            std=std,
            columns=np.array(columns, dtype=str),
            observed=np.array(obs_names, dtype=str),
            **{k: np.float64(v) for k, v in scalars.items()},
        )
        if samples is not None:
            arrays["samples"] = samples
        np.savez(out, **arrays)
    else:
        header = ["phase", "s", "time"] + [f"mean_{c}" for c in columns] + [f"std_{c}" for c in columns]
        blocks = [np.full(n, scalars["phase"]), s, s * scalars["duration"], *mean.T, *std.T]
        if samples is not None:
            for k in range(samples.shape[0]):
                header += [f"sample{k}_{c}" for c in columns]
                blocks += list(samples[k].T)
        table = np.column_stack(blocks)
        with open(out, "w", encoding="utf-8") as fh:
            fh.write("# interprim prediction (columns: see docs/data-formats.md)\n")
            for k, v in scalars.items():
                fh.write(f"# {k}: {v!r}\n")
            fh.write(f"# observed_columns: {', '.join(obs_names)}\n")
            fh.write(",".join(header) + "\n")
            for row in table:
                fh.write(",".join(repr(float(v)) for v in row) + "\n")
    print(
        f"phase {scalars['phase']:.3f} (of the movement seen), speed {scalars['speed']:.3f}, "
        f"duration {scalars['duration']:.3g} s, {frames.shape[0]} frames observed\nwrote {out}"
    )
    return 0


# ----------------------------------------------------------------------------- handwriting
def cmd_handwriting(args) -> int:
    """``interprim handwriting``: run :func:`interprim.experiments.handwriting.run_handwriting`."""
    from interprim.experiments.handwriting import BEYOND_PAPER, DEFAULT_LASA_SHAPES, run_handwriting, summary_lines

    if args.shapes is None:
        shapes = DEFAULT_LASA_SHAPES
    elif args.shapes.strip().lower() in ("none", ""):
        shapes = ()
    else:
        shapes = tuple(s.strip() for s in args.shapes.split(",") if s.strip())
    if shapes:
        try:
            from interprim.datasets import lasa_shapes

            known = lasa_shapes()
        except ImportError as exc:
            raise CommandError(f"{exc}; or pass --shapes none") from None
        bad = [s for s in shapes if s not in known]
        if bad:
            raise CommandError(f"unknown LASA shape(s) {bad}; available: {', '.join(known)}")
    if args.folds < 2:
        raise CommandError(f"--folds must be >= 2, got {args.folds}")
    observations = [o.strip() for o in args.observations.split(",") if o.strip()]
    bad = [o for o in observations if o not in ("forcing", "position")]
    if bad or not observations:
        raise CommandError(f"--observations must list 'forcing' and/or 'position', got {args.observations!r}")
    try:
        res = run_handwriting(
            args.out,
            letters=args.letters,
            max_per_letter=args.max_per_letter or None,
            n_folds=args.folds,
            lasa_shapes=shapes,
            n_basis=args.n_basis,
            observations=observations,
            true_phase=not args.no_true_phase,
            extra_variants=BEYOND_PAPER if args.beyond_paper else None,
            seed=args.seed,
            data_path=args.data,
            figures=not args.no_figures,
        )
    except InterprimError:
        raise
    except ValueError as exc:
        raise CommandError(str(exc)) from None
    print("\n".join(summary_lines(res)))
    print(f"wrote {args.out}/report.md, results.json" + (", figures" if not args.no_figures else "") + f" ({res['seconds']} s)")
    return 0

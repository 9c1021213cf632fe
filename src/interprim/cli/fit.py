"""``interprim fit``: learn a model of the interaction from demonstration files and save it.

By default (``--model auto``) the model is chosen on the demonstrations themselves
(:class:`~interprim.models.auto.AutoInteraction`: the Interaction Primitive, the learned interaction, the
kernel-weighted and the nearest demonstration and the mean, compared on held-out folds and blended);
``--model ip`` fits the Interaction Primitive alone, with every option of the paper's model.

Only :mod:`argparse` is imported at module level; numpy and the core are imported
inside the command function, so ``interprim --help`` stays fast.  File formats are
described in ``docs/data-formats.md``.
"""

from __future__ import annotations

import argparse
import math
from typing import Any

from ..core.cv import DEFAULT_HORIZON
from ..core.errors import InterprimError
from ._common import (
    MAX_NAN_GAP_HELP,
    SPLIT_HINT,
    CommandError,
    add_recording_args,
    agent_columns,
    check_output,
    output_when_done,
    positive_number,
    print_notes,
    read_demonstrations,
    split_cols,
)

__all__ = ["add_parser", "CommandError"]

_FIT_EPILOG = """\
DEMOS is a CSV file (header of column names, a 'time' column in seconds, optionally a 'demo'
column splitting several demonstrations), a folder of such files, or an NPZ archive with
demo_000, demo_001, ... (T, D) arrays, time_000, ... and 'columns' (see docs/data-formats.md).
It may also be a recording: a folder of C3D files (markers <marker>_x/_y/_z in metres; needs
pip install 'interprim[mocap]'), Qualisys TSV or OptiTrack Motive CSV exports, or BVH files (one
demonstration per file), or a ROS bag (.bag, .db3, .mcap or a rosbag2 folder; needs
pip install 'interprim[ros]') with --topics. One continuous take (any of these, CSV and NPZ too) is
cut into demonstrations with --split-gap, --split-repetitions, --split-frames (C3D/TSV: --split-events).
Marker gaps up to 0.1 s are filled; markers seen in under half the frames are left out (one warning).
--observed and --controlled take names, 0-based indices or shell patterns ('A:*', 'RHand_?').

examples:
  interprim fit demos.csv --observed hand_x,hand_y,hand_z -o model.npz                 (model chosen on the data)
  interprim fit demos.csv --observed hand_x,hand_y,hand_z --model ip -o model.npz      (Interaction Primitive)
  interprim fit recordings/ --observed 0,1,2 --n-basis 15 --smoothing-window 7 -o model.npz
  interprim fit takes/ --observed 'A:RHand_*' --controlled 'B:RHand_*' -o model.npz   (folder of .c3d)
  interprim fit handovers.bag --topics /human/wrist,/robot/joint_states --split-gap 1.0 -o model.npz
"""


def add_parser(subparsers) -> None:
    """Register ``fit`` with an ``argparse`` sub-parser set."""
    fmt = argparse.RawDescriptionHelpFormatter

    p = subparsers.add_parser(
        "fit",
        help="learn a model of the interaction from demonstration files (chosen on them by default)",
        description="Learn a model of the interaction from demonstrations of two agents (or one) and save it. "
        "By default the model is chosen on the demonstrations (--model auto).",
        epilog=_FIT_EPILOG,
        formatter_class=fmt,
    )
    p.add_argument("demos", metavar="DEMOS", help="CSV, NPZ, C3D, BVH file, ROS bag, or a folder of demonstrations")
    p.add_argument(
        "--observed",
        action="append",
        metavar="COLS",
        help="the observed agent's (human's) columns: names or 0-based indices, comma-separated "
        "(repeatable). All other columns are the controlled agent (robot); naming every column "
        "gives a single-agent model. Default: the file's '# observed:' entry (ROS bags: the first of --topics)",
    )
    p.add_argument(
        "--controlled",
        action="append",
        metavar="COLS",
        help="the controlled agent's (robot's) columns, as for --observed (repeatable). Given, the columns "
        "named in neither --observed nor --controlled are dropped; without --observed, every column not "
        "named here is observed",
    )
    p.add_argument("-o", "--output", required=True, metavar="MODEL", help="model file to write (.npz)")
    p.add_argument("--columns", metavar="COLS", help="use only these columns (names or indices, comma-separated)")
    p.add_argument(
        "--model",
        choices=MODELS,
        default="auto",
        help="auto (default): compare the Interaction Primitive, the learned interaction, the kernel-weighted and "
        "the nearest demonstration and the mean on held-out folds of the demonstrations (real-time error --horizon s "
        "ahead) and blend them with cross-validated weights; or one model alone: ip (the Interaction Primitive; "
        "the options below marked 'ip' apply to it), learned, kernel, nn, prior",
    )
    p.add_argument(
        "--horizon", type=float, default=None, metavar="SECONDS",
        help=f"seconds ahead of the real-time band: --model auto scores its candidates and fits its first weights "
        f"for it, the kernel model is tuned for it (default {DEFAULT_HORIZON}; --model ip predicts the whole "
        f"movement and has no horizon)",
    )
    p.add_argument(
        "--frame-budget", type=_frame_budget, default=None, metavar="X",
        help="--model auto: the most a streamed frame, and a predict call, may cost, as a multiple of the "
        "Interaction Primitive's on the same data, or --frame-budget-floor (--predict-budget-floor) milliseconds "
        "if that is more (default 3; 'none': no bound); families that do not fit are left out, and the summary "
        "says which",
    )
    p.add_argument(
        "--frame-budget-floor", type=_milliseconds, default=None, metavar="MS",
        help="--model auto: milliseconds a streamed frame may always cost, however cheap the Interaction "
        "Primitive's frame is on the data (default 1; 0: the budget is the multiple alone)",
    )
    p.add_argument(
        "--predict-budget-floor", type=_milliseconds_or_none, default=None, metavar="MS",
        help="--model auto: the same for a predict call from half the movement (default 2; 'none': a predict is "
        "not bounded, for a robot that only streams)",
    )
    p.add_argument(
        "--max-prefixes", type=_max_prefixes, default=None, metavar="N",
        help="--model auto: score at most N prefixes of each held-out demonstration when comparing the families (a "
        "long demonstration is scored every k-th frame, so the fit's time does not grow with the sampling rate; "
        "default 24; 'none': every third frame, however many)",
    )
    p.add_argument("--n-basis", type=int, default=20, help="Gaussian basis functions per DoF (default 20)")
    p.add_argument(
        "--observation",
        choices=("forcing", "position"),
        default=None,
        help="condition on forcing terms (paper Eq. 15) or on positions (default: the model's) (ip)",
    )
    p.add_argument(
        "--covariance", choices=("shrinkage", "ridge", "empirical"), default=None, help="covariance regularisation (ip)"
    )
    p.add_argument(
        "--sigma2",
        type=_sigma2,
        default=None,
        help="observation noise variance: a number, 'residual' (from the fit's residual) or 'cv' (cross-validated) "
        "(default: the model's) (ip)",
    )
    p.add_argument(
        "--phase-method",
        choices=("dtw", "likelihood", "learned", "cv"),
        default=None,
        help="phase estimation: cv (default: whichever of likelihood and learned has the smaller held-out phase "
        "error on the demonstrations), likelihood (marginal likelihood of the observed prefix), learned "
        "(regressed on the demonstrations' own prefixes) or dtw (the paper's open-end DTW, Eq. 5-9) (ip)",
    )
    p.add_argument(
        "--calibrate",
        type=_calibrate,
        default=None,
        metavar="{with-cv,on,off}",
        help="scale the predictive std to held-out errors of the demonstrations: with-cv (default: when sigma2 is "
        "cross-validated and there are at least 6 demonstrations), on or off (ip)",
    )
    p.add_argument(
        "--input-noise",
        type=float,
        default=None,
        metavar="STD",
        help="standard deviation (data units) of noise in the online input that the demonstrations lack "
        "(sensor noise); makes predictions robust to it (ip)",
    )
    p.add_argument(
        "--smoothing-window", type=int, default=None, help="Savitzky-Golay window in frames for derivatives (odd)"
    )
    p.add_argument("--pca", type=int, default=None, metavar="K",
                   help="project each agent onto K principal components (ip)")
    p.add_argument("--dt", type=float, default=None, help="sampling interval (s) for files without time stamps")
    p.add_argument(
        "--resample", type=float, default=None, metavar="DT",
        help="resample the demonstrations to this interval (s); ROS bags: the uniform grid both agents are "
        "interpolated onto"
    )
    p.add_argument(
        "--max-nan-gap", type=int, default=None, help=MAX_NAN_GAP_HELP,
    )
    add_recording_args(p)
    p.set_defaults(func=cmd_fit)


def _models():
    from ..models.registry import FAMILIES

    return ("auto",) + tuple(n for n, f in FAMILIES.items() if f.cli)


MODELS = _models()
#: options that configure the Interaction Primitive alone (--model ip)
IP_ONLY = (("observation", "--observation"), ("covariance", "--covariance"), ("sigma2", "--sigma2"),
           ("phase_method", "--phase-method"), ("input_noise", "--input-noise"), ("pca", "--pca"),
           ("calibrate", "--calibrate"))


def _positive_or_none(convert, expected):
    """An argparse type: ``'none'`` (kept as the string: no bound) or a finite value of ``convert`` above 0."""
    def parse(text):
        if text.strip().lower() == "none":
            return "none"
        try:
            value = convert(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {expected} or 'none', got {text!r}") from None
        if not 0 < value < float("inf"):  # NaN fails too
            raise argparse.ArgumentTypeError(f"expected {expected} or 'none', got {text!r}")
        return value
    return parse


_frame_budget = _positive_or_none(float, "a positive number")
_max_prefixes = _positive_or_none(int, "a whole number of prefixes >= 1")


def _milliseconds(text):
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of milliseconds >= 0, got {text!r}") from None
    if not (value >= 0 and value < float("inf")):
        raise argparse.ArgumentTypeError(f"expected a number of milliseconds >= 0, got {text!r}")
    return value


def _milliseconds_or_none(text):
    """:func:`_milliseconds`, or ``'none'`` (kept as the string: no bound)."""
    if text.strip().lower() == "none":
        return "none"
    try:
        return _milliseconds(text)
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(f"expected a number of milliseconds >= 0 or 'none', got {text!r}") from None


def _sigma2(text):
    if text in ("residual", "cv"):
        return text
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive number, 'residual' or 'cv', got {text!r}") from None
    if not (v > 0 and math.isfinite(v)):
        raise argparse.ArgumentTypeError(f"must be positive and finite, got {text!r}")
    return v


def _calibrate(text):
    choices = {"with-cv": "with-cv", "on": True, "off": False}
    if text not in choices:
        raise argparse.ArgumentTypeError(f"expected with-cv, on or off, got {text!r}")
    return choices[text]


def cmd_fit(args) -> int:
    """``interprim fit``: load demonstrations, fit the model (chosen on them by default), save it."""
    import interprim as ip

    positive_number(args.n_basis, "--n-basis")
    positive_number(args.horizon, "--horizon")
    check_output(args.output, "-o", inputs=(args.demos,), suffixes=(".npz",))
    ds = read_demonstrations(args.demos, args, columns=args.columns)  # as 'interprim evaluate --data' reads it
    print_notes(ds, "fit")
    n_read = ds.n_dofs
    ds, obs = agent_columns(ds, split_cols(args.observed), split_cols(args.controlled), args.demos)
    if len(ds) < 2:
        raise CommandError(f"{args.demos} holds {len(ds)} demonstration; at least 2 are needed to learn a "
                           "distribution. " + SPLIT_HINT)
    for flag, value in (("--frame-budget", args.frame_budget), ("--frame-budget-floor", args.frame_budget_floor),
                        ("--predict-budget-floor", args.predict_budget_floor), ("--max-prefixes", args.max_prefixes)):
        if args.model != "auto" and value is not None:
            raise CommandError(f"{flag} sets how --model auto compares and blends the families; --model "
                               f"{args.model} is one family alone (drop {flag}, or use --model auto)")
    if args.model != "ip":
        given = [flag for key, flag in IP_ONLY if getattr(args, key) is not None]
        if given:
            raise CommandError(f"{', '.join(given)} configure(s) the Interaction Primitive alone: add --model ip "
                               f"(--model {args.model} compares or fits other models at their defaults)")
        return _fit_other(args, ds, obs, n_read)
    kwargs = {"n_basis": args.n_basis}
    for key, val in (
        ("observation", args.observation),
        ("covariance", args.covariance),
        ("sigma2", args.sigma2),
        ("phase_method", args.phase_method),
        ("input_noise", args.input_noise),
        ("calibrate", args.calibrate),
        ("smoothing_window", args.smoothing_window),
        ("pca_components", args.pca),
    ):
        if val is not None:
            kwargs[key] = val
    model = ip.InteractionPrimitive(observed_dofs=obs, **kwargs)
    # its dt or time stamps, and its column names (stored in the model file)
    fit_seconds, out = _fit_and_save(model, lambda: model.fit(ds), args)
    obs_names = [ds.columns[i] for i in model.observed_dofs_]
    ctrl_names = [ds.columns[i] for i in model.controlled_dofs_]
    print(
        f"fitted {len(ds)} demonstrations, {ds.n_dofs} columns, dt={model.dt_:.4g} s, "
        f"mean duration {model.mean_duration_:.3g} s\n"
        f"  observed:   {', '.join(obs_names)}\n"
        f"  controlled: {', '.join(ctrl_names) or '(none: single-agent model)'}\n"
        + (f"  dropped:    {n_read - ds.n_dofs} columns named in neither --observed nor --controlled\n"
           if ds.n_dofs < n_read else "")
        + "chosen (model.summary(), model.selection_):\n" + "\n".join(model.summary().splitlines()[1:]) + "\n"
        + f"fit in {fit_seconds:.1f} s; saved {out}"
    )
    return 0




def _fit_other(args, ds, obs, n_read) -> int:
    """``--model auto`` (the model chosen on the data) or one of the other families alone."""
    from interprim.models.auto import AutoInteraction

    if args.model == "auto" and len(ds) < 3:
        raise CommandError(f"{args.demos} holds {len(ds)} demonstrations; --model auto compares models on held-out "
                           "folds and needs at least 3 (or use --model ip). " + SPLIT_HINT)
    budget: dict[str, Any] = {}  # not given: the library's default budget; "none": no budget
    if args.frame_budget is not None:
        budget["frame_budget"] = None if args.frame_budget == "none" else float(args.frame_budget)
    if args.frame_budget_floor is not None:
        budget["frame_budget_floor"] = float(args.frame_budget_floor) / 1e3
    if args.predict_budget_floor is not None:
        budget["predict_budget_floor"] = (None if args.predict_budget_floor == "none"
                                          else float(args.predict_budget_floor) / 1e3)
    if args.max_prefixes is not None:
        budget["max_prefixes"] = None if args.max_prefixes == "none" else int(args.max_prefixes)
    auto = AutoInteraction(obs, candidates=AutoInteraction.CANDIDATES if args.model == "auto" else (args.model,),
                           n_basis=args.n_basis, smoothing_window=args.smoothing_window, progress=True,
                           horizon=DEFAULT_HORIZON if args.horizon is None else float(args.horizon), **budget)
    model = auto
    fit_seconds, out = _fit_and_save(model, lambda: auto.fit(ds, dt=ds.dt), args)  # one family alone: no comparison
    ctrl = [i for i in range(ds.n_dofs) if i not in set(obs)]
    what = model.summary()
    unit = _unit(ds, ctrl)
    if unit and "error" in what:
        what += f"\n  (errors in {unit}: the unit of the controlled columns, as the file states it)"
    resampled = "" if ds.dt is not None else " (irregular time stamps resampled at their median interval)"
    print(
        f"fitted {len(ds)} demonstrations, {ds.n_dofs} columns, dt={model.dt_:.4g} s{resampled}, mean duration "
        f"{model.mean_duration_:.3g} s\n"
        f"  observed:   {', '.join(ds.columns[i] for i in obs)}\n"
        f"  controlled: {', '.join(ds.columns[i] for i in ctrl) or '(none: single-agent model)'}\n"
        + (f"  dropped:    {n_read - ds.n_dofs} columns named in neither --observed nor --controlled\n"
           if ds.n_dofs < n_read else "")
        + what + "\n"
        + f"fit in {fit_seconds:.1f} s; saved {out}"
    )
    return 0


def _unit(ds, cols) -> str:
    """The one unit the file states for the columns ``cols`` (empty when it states none, or several)."""
    units = getattr(ds, "units", None)
    if not units or not cols:
        return ""
    got = {units[i] for i in cols}
    return got.pop() if len(got) == 1 and None not in got and "" not in got else ""


def _fit_and_save(model, fit, args):
    """Run ``fit()`` (bad data: a one-line error naming the file), save ``model`` to ``-o``; ``(seconds, path)``."""
    import time
    from pathlib import Path

    try:
        t0 = time.perf_counter()
        fit()
        fit_seconds = time.perf_counter() - t0
    except InterprimError:
        raise
    except (ValueError, TypeError) as exc:
        raise CommandError(f"cannot fit the model to {args.demos}: {exc}") from None
    out = Path(args.output)
    with output_when_done(out) as tmp:  # a failed save leaves no model file (nor a temporary one)
        model.save(tmp)
    return fit_seconds, out

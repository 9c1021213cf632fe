"""``interprim predict``: predict both agents' movements from a partial observation of the observed agent.

Only :mod:`argparse` is imported at module level; numpy and the core are imported
inside the command function, so ``interprim --help`` stays fast.
"""

from __future__ import annotations

import argparse

from ..core.errors import DataFileError, InterprimError
from ._common import (
    MAX_NAN_GAP_HELP,
    CommandError,
    add_recording_args,
    check_output,
    output_when_done,
    positive_number,
    recording_options,
)

__all__ = ["add_parser"]

_PREDICT_EPILOG = """\
PARTIAL holds the frames of the observed agent seen so far (CSV or NPZ, one demonstration, same
column names as the training data; other columns are ignored; without a 'time' column the frames
are taken at the model's sampling interval). It may also be a recording: a C3D or BVH file, or a
ROS bag with --topics naming the observed agent's topic (and, optionally, the controlled one).

OUT (.csv or .npz) gets the prediction of the whole movement on a normalised-time grid:
  phase            fraction of the movement already observed (DTW, paper Eq. 8-9, or the
                   model's phase_method)
  s, time          normalised time 0..1 and seconds since the start (s * estimated duration)
  mean_<col>       posterior mean of every DoF (observed and controlled)
  std_<col>        pointwise posterior standard deviation
  sample<k>_<col>  with --samples K: K trajectories drawn from the posterior
CSV files start with '#' comment lines holding phase, speed, duration, the log-likelihood and input
distance when the model gives them, and out_of_range / duration_out_of_range as true or false.

example:
  interprim predict model.npz first_half.csv -o prediction.csv --samples 10
"""


#: the largest --n-points and --samples, and values (points x columns x (samples + 2)) of one prediction file
MAX_POINTS = 100_000
MAX_SAMPLES = 10_000
MAX_VALUES = 50_000_000


def add_parser(subparsers) -> None:
    """Register ``predict`` with an ``argparse`` sub-parser set."""
    fmt = argparse.RawDescriptionHelpFormatter

    p = subparsers.add_parser(
        "predict",
        help="predict both agents' movements from a partial observation",
        description="Predict the rest of the interaction (both agents) from the observed agent's first frames.",
        epilog=_PREDICT_EPILOG,
        formatter_class=fmt,
    )
    p.add_argument("model", metavar="MODEL", help="model file written by 'interprim fit' (any model)")
    p.add_argument("partial", metavar="PARTIAL", help="CSV or NPZ with the observed agent's frames so far")
    p.add_argument("-o", "--output", required=True, metavar="OUT", help="output file (.csv or .npz)")
    p.add_argument("--samples", type=int, default=0, metavar="K", help="also write K posterior samples")
    p.add_argument("--n-points", type=int, default=100, help="points of the normalised-time grid (default 100)")
    p.add_argument("--seed", type=int, default=0, help="random seed of the samples (default 0)")
    p.add_argument("--dt", type=float, default=None, help="sampling interval (s) of PARTIAL if it has no time column")
    p.add_argument("--observe-fraction", type=float, default=None, metavar="F",
                   help="observe only the first F (0 < F <= 1) of PARTIAL's frames, e.g. 0.6 for the first 60 %% of a "
                        "whole recording")
    p.add_argument("--max-nan-gap", type=int, default=None, help="PARTIAL: " + MAX_NAN_GAP_HELP)
    add_recording_args(p, what="PARTIAL")
    p.set_defaults(func=cmd_predict)


def _model_columns(model):
    """Column names of the demonstrations a model was fitted on (``None`` if it was fitted without names)."""
    return getattr(model, "columns_", None)


def cmd_predict(args) -> int:
    """``interprim predict``: condition a saved model on a partial observation and write the prediction."""
    import warnings
    from pathlib import Path

    import numpy as np

    import interprim as ip
    from interprim.core.errors import OutOfRangeWarning
    from interprim.datasets import load_demonstrations

    out = Path(args.output)
    suffix = out.suffix.lower()
    check_output(out, "-o", inputs=(args.model, args.partial), suffixes=(".csv", ".npz"))
    if not 0 <= args.samples <= MAX_SAMPLES:
        raise CommandError(f"--samples must be in 0..{MAX_SAMPLES}, got {args.samples}")
    if not 2 <= args.n_points <= MAX_POINTS:
        raise CommandError(f"--n-points must be in 2..{MAX_POINTS}, got {args.n_points}")
    positive_number(args.dt, "--dt")
    if args.observe_fraction is not None and not 0 < args.observe_fraction <= 1:
        raise CommandError(f"--observe-fraction must be in (0, 1], got {args.observe_fraction!r}")
    if not Path(args.model).exists():
        raise FileNotFoundError(f"model file not found: {args.model}")
    model = ip.load_any(args.model)  # whatever 'interprim fit' saved (the model chosen on the data by default)
    if (args.samples + 2) * args.n_points * model.n_dofs_ > MAX_VALUES:  # mean, std and the samples, written whole
        raise CommandError(f"--samples {args.samples} x --n-points {args.n_points} x {model.n_dofs_} columns is more "
                           f"than the {MAX_VALUES:.0e} values a prediction file may hold")
    columns = _model_columns(model) or [f"dof_{j}" for j in range(model.n_dofs_)]
    obs_names = [columns[i] for i in model.observed_dofs_]
    part = load_demonstrations(args.partial, dt=args.dt or model.dt_, min_frames=1, max_nan_gap=args.max_nan_gap,
                               **recording_options(args))
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
    if args.observe_fraction is not None:  # the first F of the recording: ceil(F * T) frames, at least one
        n_obs = max(1, int(np.ceil(args.observe_fraction * frames.shape[0] - 1e-9)))
        frames, t = frames[:n_obs], t[:n_obs]
    from interprim.datasets._base import sampling

    try:
        with warnings.catch_warnings():  # said once, in the command's own WARNING line below
            warnings.simplefilter("ignore", OutOfRangeWarning)
            # frames on the model's grid up to rounding (the rule of every command) are taken as they are
            if frames.shape[0] > 1 and not sampling([t], dt=model.dt_).uniform:
                if isinstance(model, ip.InteractionPrimitive):
                    pred = model.predict(frames, times=t - t[0])
                else:  # models of frames on their own grid: the observed frames resampled onto it (causal)
                    from interprim.core.preprocessing import resample_uniform

                    pred = model.predict(resample_uniform(frames, t, dt=model.dt_)[0])
            else:
                pred = model.predict(frames)
    except InterprimError:
        raise
    except (ValueError, TypeError) as exc:
        raise CommandError(f"cannot predict from {args.partial}: {exc}") from None
    n = int(args.n_points)
    s = np.linspace(0.0, 1.0, n)
    mean = np.asarray(pred.trajectory(n))
    sd = pred.std(n)
    std = np.full_like(mean, np.nan) if sd is None else np.asarray(sd)  # NaN: the model gives no uncertainty
    # (a phase may be NaN: a model that does not estimate one, as the mean demonstration, says so)
    bad = [what for what, v in (("duration", pred.duration), ("mean", mean), ("std", std if sd is not None else 0.0))
           if not np.all(np.isfinite(v))]
    if bad:  # nothing a robot could use: said, and no file written
        raise CommandError(f"the prediction from {args.partial} is not finite ({', '.join(bad)}): values beyond "
                           "the floating-point range in the model or the frames? (input distance "
                           f"{float(getattr(pred, 'input_distance', float('nan'))):.3g} standard deviations)")
    samples = np.asarray(pred.samples(args.samples, n, random_state=args.seed)) if args.samples else None
    scalars = {
        "phase": float(pred.phase),
        "speed": float(pred.speed),
        "duration": float(pred.duration),
        "log_likelihood": float(pred.log_likelihood),
        "input_distance": float(getattr(pred, "input_distance", float("nan"))),
        "out_of_range": bool(getattr(pred, "out_of_range", False)),
        "duration_out_of_range": bool(getattr(pred, "duration_out_of_range", False)),
    }
    with output_when_done(out) as tmp:  # written whole, or not at all
        _write_prediction(tmp, suffix, s, mean, std, columns, obs_names, scalars, samples)
    print(
        f"phase {scalars['phase']:.3f} (of the movement seen), speed {scalars['speed']:.3f}, "
        f"duration {scalars['duration']:.3g} s, {frames.shape[0]} frames observed\nwrote {out}"
    )
    if scalars["duration_out_of_range"] and not scalars["out_of_range"]:  # else the input warning below says it
        from interprim.core.input_range import DURATION_FACTOR, duration_range

        lo, hi = duration_range(model) or (float("nan"), float("nan"))
        print(f"WARNING: the predicted duration {scalars['duration']:.3g} s is far outside the demonstrated ones "
              f"({lo:.3g}-{hi:.3g} s; flagged beyond {DURATION_FACTOR:g}x): the predicted timing does not follow the "
              "demonstrations.")
    if scalars["out_of_range"]:
        print(f"WARNING: the observed frames are {scalars['input_distance']:.3g} standard deviations from the "
              "training demonstrations: wrong units, column order or frame of reference? The prediction "
              "extrapolates.")
    return 0


def _write_prediction(out, suffix, s, mean, std, columns, obs_names, scalars, samples):
    """The prediction as an ``.npz`` archive or a CSV table (docs/data-formats.md)."""
    import numpy as np

    n = s.shape[0]
    if suffix == ".npz":
        arrays = dict(
            s=s,
            time=s * scalars["duration"],
            mean=mean,
            std=std,
            columns=np.array(columns, dtype=str),
            observed=np.array(obs_names, dtype=str),
            **{k: (np.bool_(v) if isinstance(v, bool) else np.float64(v)) for k, v in scalars.items()},
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
                if isinstance(v, bool):
                    fh.write(f"# {k}: {'true' if v else 'false'}\n")
                elif np.isfinite(v):
                    fh.write(f"# {k}: {v!r}\n")
                # a value the model does not give (NaN: no likelihood, no input range) is left out
            fh.write(f"# observed_columns: {', '.join(obs_names)}\n")
            fh.write(",".join(header) + "\n")
            for row in table:
                fh.write(",".join(repr(float(v)) for v in row) + "\n")



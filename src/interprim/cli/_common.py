"""What the sub-commands of the ``interprim`` command line share: their error type and argument checks."""

from __future__ import annotations

import contextlib

from ..core.errors import InterprimError

__all__ = ["CommandError", "output_when_done", "check_output"]


class CommandError(InterprimError, ValueError):
    """A command-line argument is invalid or a step of a command failed (reported in one line)."""


@contextlib.contextmanager
def output_when_done(path, *, folder: bool = False):
    """Write a command's output only if the command succeeds.

    Yields a temporary path in the same folder as ``path`` (a hidden name, same suffix); the command writes
    there.  When the block ends without an exception the file is moved onto ``path`` with ``os.replace``
    (atomic on one file system), or, for ``folder=True``, each file written into the temporary folder is moved
    into ``path`` (created if needed; files already in it that the command did not write are kept).  When the
    block raises (an error, Ctrl-C), the temporary file or folder is removed and ``path`` is left as it was.
    """
    import os
    import shutil
    import tempfile
    from pathlib import Path

    final = Path(path)
    parent = final.parent if str(final.parent) else Path(".")
    parent.mkdir(parents=True, exist_ok=True)
    if folder:
        tmp = Path(tempfile.mkdtemp(prefix=f".{final.name}.", suffix=".tmp", dir=parent))
    else:
        fd, name = tempfile.mkstemp(prefix=f".{final.stem}.", suffix=".tmp" + final.suffix, dir=parent)
        os.close(fd)
        tmp = Path(name)
    try:
        yield tmp
        if folder:
            final.mkdir(parents=True, exist_ok=True)
            for src in sorted(tmp.rglob("*")):
                if src.is_dir():
                    continue
                dst = final / src.relative_to(tmp)
                dst.parent.mkdir(parents=True, exist_ok=True)
                os.replace(src, dst)
        else:
            os.replace(tmp, final)
    finally:
        if folder:
            shutil.rmtree(tmp, ignore_errors=True)
        elif tmp.exists():
            tmp.unlink()


def moved(paths, tmp, final) -> list:
    """``paths`` written under the temporary folder ``tmp`` as they are named once moved into ``final``."""
    from pathlib import Path

    out = []
    for p in paths:
        try:
            out.append(Path(final) / Path(p).relative_to(tmp))
        except ValueError:
            out.append(p)
    return out


def split_cols(values):
    out = []
    for v in values or []:
        if v is None:
            continue
        out.extend(s.strip() for s in v.split(",") if s.strip())
    return out


def positive_number(value, name):
    """``value`` (None passes), refused unless a positive finite number."""
    import math

    if value is not None and not (value > 0 and math.isfinite(value)):
        raise CommandError(f"{name} must be a positive finite number, got {value!r}")
    return value


def check_output(path, flag: str, *, inputs=(), folder: bool = False, suffixes=None) -> None:
    """Refuse, before any work, an output the command could not write or that would destroy an input.

    ``path`` (given with ``flag``): a file, or a folder with ``folder=True``.  Refused: a suffix not in
    ``suffixes``; a folder output that exists as a file, or a file output that exists as a folder; a path under
    an existing file (a file cannot hold a folder); an output that is one of ``inputs`` (the same file, however
    named: the input would be replaced by the output)."""
    import os
    from pathlib import Path

    out = Path(path)
    if suffixes is not None and out.suffix.lower() not in suffixes:
        raise CommandError(f"{flag} {path}: the output must end in {' or '.join(suffixes)}")
    if out.exists():
        if folder and not out.is_dir():
            raise CommandError(f"{flag} {path}: exists and is not a folder (the output is a folder)")
        if not folder and out.is_dir():
            raise CommandError(f"{flag} {path}: is a folder (the output is a file)")
    for parent in out.absolute().parents:
        if parent.exists():
            if not parent.is_dir():
                raise CommandError(f"{flag} {path}: {parent} is a file, not a folder")
            break
    if out.exists() and not folder:
        for given in inputs:
            if given is not None and Path(given).exists() and os.path.samefile(out, given):
                raise CommandError(f"{flag} {path}: is the input {given}; the output would replace it (choose "
                                   "another name)")


# ----------------------------------------------------------------------------- recordings
MAX_NAN_GAP_HELP = ("fill interior gaps of up to this many missing frames by linear interpolation (default: none for "
                    "CSV, NPZ, BVH and ROS bags; 0.1 s of frames for marker files: C3D, TSV, Motive CSV)")
RECORDING_HELP = (
    "recordings and takes: motion capture (.c3d, Qualisys .tsv, OptiTrack Motive .csv, .bvh), ROS bags (.bag, "
    ".db3, .mcap, rosbag2 folder), and CSV/NPZ takes to split; see docs/data-formats.md"
)


def add_recording_args(p, what="DEMOS") -> None:
    """The options of the motion-capture and ROS-bag readers (``load_demonstrations``), as one argument group."""
    g = p.add_argument_group(RECORDING_HELP)
    g.add_argument("--topics", metavar="OBS,CTRL",
                   help=f"ROS bag {what}: the observed and the controlled agent's topic (JointState, PoseStamped, "
                        "PointStamped, TransformStamped, Odometry, PoseWithCovarianceStamped), tf frame (tf:FRAME; "
                        "tf2_msgs/TFMessage or ROS 1 tf/tfMessage) or numeric fields of any message "
                        "(/turtle1/pose:x,y), comma-separated; required for bags. "
                        "The controlled stream is interpolated onto the observed stream's time stamps "
                        "(with --resample DT: both onto a uniform grid)")
    g.add_argument("--split-topic", metavar="TOPIC",
                   help="ROS bag: a topic whose messages (e.g. std_msgs/Empty) mark the start of each demonstration")
    g.add_argument("--split-gap", type=float, metavar="SECONDS",
                   help="a pause longer than SECONDS starts a new demonstration: ROS bag, no message in either "
                        "stream; a take (CSV, NPZ, C3D, BVH, TSV), every column slower than 5%% of the take's "
                        "95th-percentile speed, or a value missing")
    g.add_argument("--split-events", nargs="?", const="*", default=None, metavar="LABELS",
                   help="C3D, Qualisys TSV: each of the file's events (or only those labelled LABELS, "
                        "comma-separated) starts a demonstration lasting until the next; the piece after the last "
                        "event is not a whole cycle and is left out (see --keep-partial)")
    g.add_argument("--keep-partial", action="store_true",
                   help="with --split-events: also keep the piece after the last event")
    g.add_argument("--split-frames", metavar="A-B,C-D",
                   help="the demonstrations as frame ranges (inclusive; C3D/TSV/Motive frames as the capture numbers "
                        "them, BVH frames and CSV/NPZ rows from 0)")
    g.add_argument("--split-repetitions", nargs="?", const=True, default=None, metavar="PERIOD",
                   help="cut a continuous take (CSV, NPZ, C3D, BVH, TSV: walking, hopping, repeated serves) into the "
                        "repetitions of its movement; the period is found from the take (or give it in seconds)")
    g.add_argument("--trim", action="store_true",
                   help="drop the leading and trailing frames of each demonstration in which a marker or value is "
                        "missing")
    g.add_argument("--min-marker-coverage", type=float, default=None, metavar="SHARE",
                   help="marker files (C3D, TSV, Motive CSV): leave out the markers seen in fewer than this share of "
                        "the frames (default 0.5; 0 keeps all; markers named with --markers are always kept)")
    g.add_argument("--orientation", action="store_true",
                   help="ROS bag: also read the orientation quaternion of poses and tf frames (_qx, _qy, _qz, _qw)")
    g.add_argument("--joints", metavar="J1,J2",
                   help="BVH: joints to keep; ROS JointState: joints to read (default all)")
    g.add_argument("--markers", metavar="M1,M2",
                   help="C3D, TSV, Motive CSV: markers to keep (default: all seen in at least --min-marker-coverage "
                        "of the frames)")
    g.add_argument("--bvh-mode", choices=("positions", "angles"), default=None,
                   help="BVH: joint world positions <joint>_x/_y/_z by forward kinematics (default) or joint angles "
                        "<joint>_<channel> in radians")
    g.add_argument("--length-unit", metavar="UNIT", choices=("mm", "cm", "m", "in", "ft"),
                   help="BVH: the file's length unit (positions are converted to metres); C3D, TSV, Motive CSV: "
                        "overrides the file's unit (marker positions are always converted to metres)")
    g.add_argument("--end-sites", action="store_true", help="BVH positions: also the End Site points (<joint>_end_x)")
    c = p.add_argument_group("CSV files (also rostopic echo -p and ros2 bag / PlotJuggler CSV exports)")
    c.add_argument("--time-column", metavar="NAME",
                   help="CSV: the column of time stamps (default 'time', else the first of %%time, __time, timestamp, "
                        "Time, field.header.stamp, header.stamp)")
    c.add_argument("--time-unit", choices=("s", "ms", "us", "ns"), default=None,
                   help="CSV: the time column's unit (default: seconds for 'time'; for another column nanoseconds "
                        "when its values are whole numbers more than 1000 apart, as ROS stamps, else seconds)")


def recording_options(args) -> dict:
    """The keyword arguments of ``load_demonstrations`` given by :func:`add_recording_args` flags."""
    positive_number(args.split_gap, "--split-gap")
    return dict(
        topics=args.topics or None,  # parsed by the bag reader ('/a/pose:x,y,/b/pose:x,y' has field lists)
        split_topic=args.split_topic,
        split_gap=args.split_gap,
        trim=bool(args.trim),
        split_events=(True if args.split_events == "*" else split_cols([args.split_events]))
        if args.split_events is not None else None,
        split_frames=args.split_frames,
        split_repetitions=_repetitions(getattr(args, "split_repetitions", None)),
        orientation=bool(args.orientation),
        joints=split_cols([args.joints]) if args.joints else None,
        markers=split_cols([args.markers]) if args.markers else None,
        bvh_mode=args.bvh_mode,
        length_unit=args.length_unit,
        end_sites=bool(args.end_sites),
        time_column=getattr(args, "time_column", None),
        time_unit=getattr(args, "time_unit", None),
        min_marker_coverage=getattr(args, "min_marker_coverage", None),
        keep_partial=bool(getattr(args, "keep_partial", False)),
    )


#: (attribute, flag, default) of every option that changes which data a command reads or how it is fitted, shared
#: by ``evaluate`` and ``fit``: :func:`data_flags`.
DATA_OPTIONS = (
    ("dt", "--dt", None), ("resample", "--resample", None), ("max_nan_gap", "--max-nan-gap", None),
    ("topics", "--topics", None), ("split_topic", "--split-topic", None), ("split_gap", "--split-gap", None),
    ("split_events", "--split-events", None), ("split_frames", "--split-frames", None), ("trim", "--trim", False),
    ("orientation", "--orientation", False), ("joints", "--joints", None), ("markers", "--markers", None),
    ("bvh_mode", "--bvh-mode", None), ("length_unit", "--length-unit", None), ("end_sites", "--end-sites", False),
    ("time_column", "--time-column", None), ("time_unit", "--time-unit", None),
    ("split_repetitions", "--split-repetitions", None), ("min_marker_coverage", "--min-marker-coverage", None),
    ("keep_partial", "--keep-partial", False),
    ("smoothing_window", "--smoothing-window", None), ("n_basis", "--n-basis", 20),
)


def data_flags(args) -> list:
    """The command-line flags (a list of words) that make another command read the data as ``args`` did."""
    words = []
    for attr, flag, default in DATA_OPTIONS:
        value = getattr(args, attr, default)
        if value is None or value == default:
            continue
        if value is True:
            words.append(flag)
        elif flag == "--split-events" and value == "*":
            words.append(flag)  # every event (nargs='?' without a value)
        else:
            words += [flag, str(value)]
    return words


def shell_words(words) -> str:
    """``words`` as one shell command line (each quoted when it needs to be)."""
    import shlex

    return " ".join(shlex.quote(str(w)) for w in words)


def _repetitions(text):
    if text is None or text is True:
        return text
    try:
        value = float(text)
    except ValueError:
        raise CommandError(f"--split-repetitions takes a period in seconds or nothing (found from the take), "
                           f"got {text!r}") from None
    return positive_number(value, "--split-repetitions")


#: what a command says when a file holds one demonstration (a continuous recording): how to cut it
SPLIT_HINT = ("If it is one continuous recording, cut it with --split-gap SECONDS (pauses), --split-repetitions (a "
              "repeated movement) or --split-frames A-B,C-D (C3D and TSV files with events: --split-events)")


def read_demonstrations(path, args, *, columns=None, flag="--resample"):
    """The demonstrations of ``path`` as every command reads them (``fit FILE``, ``evaluate --data FILE``,
    ``serve --replay``): the data options of ``args``; irregular time stamps without ``--resample`` resampled at
    their median interval (the rule of the models' ``fit``), said in one note."""
    from ..datasets import load_demonstrations
    from ..datasets._base import sampling
    from ..datasets.files import median_interval, resampled

    resample = getattr(args, "resample", None)
    positive_number(resample, flag)
    positive_number(getattr(args, "dt", None), "--dt")
    ds = load_demonstrations(path, columns=columns, dt=getattr(args, "dt", None), resample_dt=resample,
                             max_nan_gap=getattr(args, "max_nan_gap", None), **recording_options(args))
    if ds.dt is None and len(ds) and all(len(t) > 1 for t in ds.times):
        why = sampling(ds.times).describe(ds.labels)
        dt = median_interval(ds.times)
        ds = resampled(ds, dt)
        ds.notes = list(ds.notes) + [f"{why}; resampled at their median interval {dt:.6g} s (as {flag} {dt:.6g}); "
                                     f"give {flag} DT to choose the interval"]
    return ds


def as_flags(text: str, command: str | None) -> str:
    """``text`` with the Python argument names of ``command`` written as its flags (``keep_partial=True`` as
    ``--keep-partial``), as its errors are printed."""
    if not command:
        return text
    from . import build_parser, flag_names

    return flag_names(build_parser(), command, _Text(text))


class _Text(Exception):
    multiline = True


def print_notes(ds, command: str | None = None, file=None) -> None:
    """What the reader decided for the user to know (``Demonstrations.notes``), one line each, with the flags of
    ``command``."""
    for note in getattr(ds, "notes", ()) or ():
        print(f"note: {as_flags(note, command)}", file=file)


def expand_columns(columns, names, flag: str) -> list:
    """Column names for ``names`` (names, 0-based indices or shell patterns such as ``A:*`` or ``RHand_?``)."""
    import fnmatch

    out = []
    for n in names:
        if n in columns or n.lstrip("-").isdigit() or not any(ch in n for ch in "*?["):
            out.append(n)
            continue
        hits = [c for c in columns if fnmatch.fnmatchcase(c, n)]
        if not hits:
            raise CommandError(f"{flag}: the pattern {n!r} matches no column; the columns are: {', '.join(columns)}")
        out.extend(h for h in hits if h not in out)
    return out


def agent_columns(ds, observed, controlled, source: str):
    """The set restricted to the two agents' columns, and the observed columns' indices in it.

    ``observed``/``controlled`` are lists from ``--observed``/``--controlled`` (may be empty).  Without
    ``--observed`` the file's own entry is used (CSV ``# observed:``, the first ROS topic); without
    ``--controlled`` every other column is controlled; with it, columns named in neither are dropped.
    """
    from ..datasets._base import select_columns

    obs_names = expand_columns(ds.columns, observed, "--observed")
    ctrl_names = expand_columns(ds.columns, controlled, "--controlled")
    if obs_names:
        obs = select_columns(ds.columns, obs_names, where=f"--observed (columns of {source})")
    elif ds.observed_dofs:
        obs = list(ds.observed_dofs)
    elif ctrl_names:
        obs = None
    else:
        raise CommandError(f"--observed is required: name the observed agent's columns among {', '.join(ds.columns)}")
    if not ctrl_names:
        return ds, obs
    ctrl = select_columns(ds.columns, ctrl_names, where=f"--controlled (columns of {source})")
    if obs is None:
        obs = [i for i in range(ds.n_dofs) if i not in set(ctrl)]
        if not obs:
            raise CommandError("--controlled names every column; name the observed agent's columns with --observed")
    both = sorted(set(obs) & set(ctrl))
    if both:
        raise CommandError(f"--observed and --controlled both name {', '.join(ds.columns[i] for i in both)}")
    keep = sorted(set(obs) | set(ctrl))
    sub = ds.select([ds.columns[i] for i in keep])
    sub.observed_dofs = None
    return sub, [keep.index(i) for i in obs]

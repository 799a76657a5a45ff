"""The argument parser of `cosim`: one sub-command each for run, info, bench,
sweep, plot and verify, each bound to its ``_cmd_NAME`` in
:mod:`cosim.cli.commands`."""
from __future__ import annotations

import argparse
import re

from cosim import __version__
from cosim.cli.commands import (_cmd_bench, _cmd_info, _cmd_plot, _cmd_run, _cmd_sweep,
                                _cmd_verify)

__all__ = ["build_parser"]


#: a number as an option takes it: ASCII digits in the usual syntax (float() also
#: reads `٥` and `1_0`), or inf or nan, which the caller refuses by name
_NUMBER = re.compile(r"\s*[+-]?(?:(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?"
                     r"|inf|infinity|nan)\s*", re.ASCII | re.IGNORECASE)


def _floats(text: str) -> list[float]:
    try:
        parts = [x for x in text.split(",") if x.strip()]
        if not all(_NUMBER.fullmatch(x) for x in parts):
            raise ValueError(text)
        return [float(x) for x in parts]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected numbers separated by commas, got "
                                         f"{_shown(repr(text))}")


def _steps(text: str) -> list[float]:
    """`--steps`: one or more finite step sizes > 0 [s], checked before any run."""
    import math
    steps = _floats(text)
    if not steps:
        raise argparse.ArgumentTypeError(f"expected one or more step sizes [s] separated by "
                                         f"commas, got {_shown(repr(text))}")
    bad = [x for x in steps if not (math.isfinite(x) and x > 0)]
    if bad:
        raise argparse.ArgumentTypeError(f"each step must be a finite number of seconds > 0, "
                                         f"got {bad[0]!r}")
    return steps


def _schemes(text: str) -> list[str]:
    """`--schemes`: one or more names (each checked against the known schemes before any
    run, :func:`cosim.cli.bench_command._check_scheme`)."""
    names = [x.strip() for x in text.split(",") if x.strip()]
    if not names:
        raise argparse.ArgumentTypeError(f"expected one or more scheme names separated by "
                                         f"commas, got {_shown(repr(text))}")
    return names


def _shown(text: str) -> str:
    from cosim.errors import shown
    return shown(text)


def _accuracy(text: str) -> float:
    from cosim.scene.checks import parse_accuracy
    try:
        return parse_accuracy(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc))


def _spread(text: str) -> int:
    from cosim.studies.roundoff import OFFSETS
    most = len(OFFSETS) + 1
    try:
        k = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number of copies, got {text!r}")
    if not 1 <= k <= most:
        raise argparse.ArgumentTypeError(
            f"must be from 1 to {most} (the scene and one copy per round-off offset; "
            f"1 runs the scene alone), got {k}")
    return k


def _frames(text: str) -> int:
    try:
        k = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number of frames, got {text!r}")
    if k < 2:
        raise argparse.ArgumentTypeError(f"must be at least 2 (the first and the last "
                                         f"sample), got {k}")
    return k


def _magnify(text: str) -> float:
    import math
    try:
        x = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}")
    if not (math.isfinite(x) and x > 0):
        raise argparse.ArgumentTypeError(f"must be a finite number > 0, got {text!r}")
    return x


#: what a SCENE argument may be
_SCENE_HELP = ("scene file (TOML), or the name of a scene cosim ships (spring_drop, "
               "three_mass, ...: `cosim info --list`); a file that exists wins")


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="cosim", description="Co-simulation of impacts between "
                                "robots and vibrating structures.")
    p.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = p.add_subparsers(dest="command", required=True)
    r = sub.add_parser("run", help="run a scene, print a summary, write summary.json and "
                                   "series.npz")
    r.add_argument("scene", help=_SCENE_HELP)
    r.add_argument("--variant", help="apply the scene's [variants.NAME] table")
    r.add_argument("--scheme", help="coupling scheme (monolithic, jacobi, gauss_seidel, "
                                    "implicit)")
    r.add_argument("--set", action="append", metavar="KEY=VALUE",
                   help="override a scene value (after the variant); repeatable")
    r.add_argument("--out", help="output directory (default: a new folder "
                                 "runs/SCENE[-VARIANT][-SCHEME], SCHEME when it is not the "
                                 "scene's own; runs/NAME-2, -3, ... when taken)")
    r.add_argument("--overwrite", action="store_true",
                   help="replace a run that the output directory already holds (without "
                        "--out: the default folder itself, not a new one)")
    r.add_argument("--no-estimate", action="store_true",
                   help="skip the error estimate (two companion runs, at 0.71 and 1.41 times the "
                        "step, together about 2.1 times the run's macro steps; none where "
                        "nothing could be read; summary key `accuracy`)")
    r.add_argument("--accuracy", type=_accuracy, metavar="X",
                   help="choose the scheme and steps expected to meet a relative accuracy X "
                        "(1%%, 0.5 %%, 0.01) of the strike's peak and exit velocity at the "
                        "least CPU, check the run's estimate and refine once (default: the "
                        "scene's scheme.accuracy); exit 3 when it is not met")
    r.add_argument("--yes", action="store_true",
                   help="with --accuracy: run a refinement counted at more than 10 times the "
                        "first run's steps (not run without it)")
    r.add_argument("--quiet", action="store_true",
                   help="no progress line (it shows only on a terminal, after a second)")
    r.set_defaults(func=_cmd_run)
    i = sub.add_parser("info", help="what a run will meet: DOFs, frequencies, stable steps, "
                                    "variants; without a scene, the scenes cosim ships")
    i.add_argument("scene", nargs="?", help=_SCENE_HELP + "; left out, the shipped scenes "
                                                         "are listed")
    i.add_argument("--list", action="store_true",
                   help="list the scenes cosim ships, one line each (as without a scene)")
    i.add_argument("--variant", help="apply the scene's [variants.NAME] table (default: the "
                                     "scene's default_variant)")
    i.add_argument("--set", action="append", metavar="KEY=VALUE",
                   help="override a scene value (after the variant); repeatable")
    i.add_argument("--json", action="store_true", help="print JSON instead of text")
    i.add_argument("--accuracy", type=_accuracy, metavar="X",
                   help="choose, without running, the scheme and steps that meet relative "
                        "accuracy X (1%%, 0.5 %%, 0.01) of the strike's peak and exit velocity "
                        "at the least predicted CPU (default: the scene's scheme.accuracy)")
    i.add_argument("--run-fmu", action="store_true",
                   help="load and run the scene's FMUs (their native code, as `cosim run` "
                        "does) to evaluate what only they tell: a port mass they report "
                        "when they run, and where each contact first closes. Without it "
                        "an FMU is read from its modelDescription.xml alone and none of "
                        "its code runs")
    i.set_defaults(func=_cmd_info)
    bn = sub.add_parser("bench", help="work-precision: error against CPU time over schemes "
                                      "and steps, against a cached monolithic reference")
    bn.add_argument("scene", help=_SCENE_HELP)
    bn.add_argument("--variant", help="apply the scene's [variants.NAME] table (default: the "
                                      "scene's default_variant)")
    bn.add_argument("--schemes", type=_schemes,
                    help="co-simulation schemes, comma separated (default: the scene's "
                         "own, if it is one, gauss_seidel and implicit)")
    bn.add_argument("--steps", type=_steps, help="step sizes [s], comma separated (default "
                                                  "1e-4,5e-5,2e-5,1e-5)")
    bn.add_argument("--contact", help="contact whose peak penetration and count are compared "
                                      "(default: the scene's only contact, else its only "
                                      "contact of a multibody on a structure)")
    bn.add_argument("--joint", help="SUBSYSTEM/JOINT whose rate at the last release is "
                                    "compared (default: the joint of the body that carries "
                                    "the contact's point)")
    bn.add_argument("--set", action="append", metavar="KEY=VALUE",
                    help="override a scene value in every run (after the variant); "
                         "repeatable")
    bn.add_argument("--spread", type=_spread, default=3, metavar="K",
                    help="run each row on the scene and K-1 copies whose initial state is "
                         "moved by a few ulps; report the median and worst error (default 3; "
                         "1: one run)")
    bn.add_argument("--out", help="output directory (default runs/SCENE[-VARIANT]-bench)")
    bn.set_defaults(func=_cmd_bench)
    sw = sub.add_parser("sweep", help="a parameter study: every combination of variants "
                                      "and values, on a process pool or a Dask cluster; one "
                                      "table")
    sw.add_argument("scene", nargs="?", help=_SCENE_HELP + "; not with --study")
    sw.add_argument("--study", help="a study file, or the name of one cosim ships "
                                    "(fig8_stiffness, fig11_chain_mass)")
    sw.add_argument("--variants", help="variants, comma separated (default: the scene's)")
    sw.add_argument("--set", action="append", metavar="KEY=V1,V2,...",
                    help="values of a scene key (TOML; commas inside [] and quotes stay); "
                         "repeatable: every combination runs")
    sw.add_argument("--scheme", help="coupling scheme of every point")
    sw.add_argument("--accuracy", type=_accuracy, metavar="X",
                    help="run every point with the scheme and steps the model chooses for a "
                         "relative accuracy X (1%%, 0.01); not checked by a companion run")
    sw.add_argument("--workers", type=int, help="local processes (default: the CPUs; 1 runs "
                                                "here); with --scheduler local, Dask workers")
    sw.add_argument("--scheduler", metavar="ADDRESS",
                    help="run on a Dask distributed cluster (tcp://host:8786), or `local` to "
                         "start one here; needs the dask extra")
    sw.add_argument("--out", help="sweep directory (default runs/SCENE-sweep or runs/STUDY)")
    sw.add_argument("--timeout", type=float, metavar="SECONDS",
                    help="most wall-clock seconds a point may run; a point past it is "
                         "stopped and recorded with status `timeout` (a study's `timeout` "
                         "key otherwise)")
    sw.add_argument("--retry-failed", action="store_true",
                    help="run the points that failed or were refused before again")
    sw.add_argument("--contact", help="contact whose regime is classified and drawn (default: "
                                      "the scene's only contact, else its only contact of a "
                                      "multibody on a structure)")
    sw.add_argument("--joint", help="SUBSYSTEM/JOINT of the striker (default: the joint of the "
                                    "body that carries the contact's point)")
    sw.add_argument("--yes", action="store_true",
                    help="run a grid of more than 10000 points (refused without it)")
    sw.add_argument("--no-plot", action="store_true", help="write the table only")
    sw.add_argument("--quiet", action="store_true", help="no progress")
    sw.set_defaults(func=_cmd_sweep)
    pl = sub.add_parser("plot", help="draw a run directory (finished or interrupted): "
                                     "penetrations, forces, velocities, energy")
    pl.add_argument("run_dir", help="directory written by `cosim run`")
    pl.add_argument("--format", choices=("png", "svg", "pdf"), default="png",
                    help="figure format (default png)")
    pl.add_argument("--animate", action="store_true",
                    help="also write an animation of the robot and the structure (MP4 with "
                         "ffmpeg where matplotlib finds it, else GIF with Pillow); needs the "
                         "run's scene.toml")
    pl.add_argument("--frames", type=_frames, default=200,
                    help="most frames in the animation, at least 2 (default 200)")
    pl.add_argument("--magnify", type=_magnify, default=1.0,
                    help="scale of the structures' deflection in the animation, a finite "
                         "number > 0 (default 1)")
    pl.add_argument("--out", help="output directory (default RUN_DIR)")
    pl.add_argument("--quiet", action="store_true",
                    help="no progress bar for the animation (it shows only on a terminal)")
    pl.set_defaults(func=_cmd_plot)
    v = sub.add_parser("verify", help="run the verification cases, or check what holds on "
                                      "any scene (SCENE); exit 1 if any check fails")
    v.add_argument("scene", nargs="?",
                   help=_SCENE_HELP + "; checks its energy ledger, its scheme against the "
                        "monolithic reference within the run's estimate, its contact counts "
                        "under round-off and the estimate's order (without it: the "
                        "verification cases)")
    v.add_argument("--variant", help="apply the scene's [variants.NAME] table")
    v.add_argument("--scheme", help="coupling scheme of the run checked")
    v.add_argument("--set", action="append", metavar="KEY=VALUE",
                   help="override a scene value (after the variant); repeatable")
    v.add_argument("--cases", help="folder of the scene files (default: the cases cosim "
                                   "ships, from any folder): spring_drop.toml's analytic "
                                   "checks if it is there, the checks of SCENE on every "
                                   "other scene file there")
    v.add_argument("--hard", action="store_true",
                   help="also run the hard-case matrix (three_mass f1000 and ms0.01, every "
                        "scheme and placement of C, steps up to ten times the stability limit)")
    v.set_defaults(func=_cmd_verify)
    return p

"""How the cost of a run grows with the size of the structure.

Two families of scenes, made from the shipped ones by overrides (no scene
file is written):

- ``beam_modal`` and ``beam_full``: beam_impact (CASES.md section 6) with
  16 to 1024 elements; ``beam_modal`` keeps the scene's modal reduction
  (``modes = { cutoff_hz = 20000 }``), ``beam_full`` drops the ``modes``
  table, so that every mode of the FE model is kept (``fem.modes`` with
  neither a count nor a cutoff: dense ``eigh``, no reduction).
- ``chain``: three_mass f100 (CASES.md section 5) with a chain of 3 to 300
  equal masses (0.15 kg) and springs (1.6e5 N/m), every mode kept (the
  chain's default), lifted so that its top rests at y = 0.

Each run starts the robot in the state it has at ``T_START`` = 0.095 s, just
before C strikes (taken once per scene from a run of the original scene:
until C touches, the robot does not feel the structure, which rests in its
static equilibrium), and runs ``--window`` seconds (0.03 s: C's contacts on
the beam and the chain's contact train fit in it).  So the time measured is
the impact, where a structure's cost lies, not the flight.

Per run the CSV has the build CPU (assembly, modes, static start:
``Scene.build``), the CPU of ``cosim.simulate`` (process time around it,
build included), the solve's CPU (the summary's ``cpu_time_s``), the part of
it spent in the structure's steps, and their ratios to the simulated time
and to the macro steps.  The slopes are least-squares fits of log cost on
log size (:func:`loglog_slope`), over all sizes and over the larger half.

BLAS runs on one thread (``--blas-threads`` to change): on a shared machine
threaded LAPACK calls on small matrices cost more CPU in waiting than in
arithmetic, which would hide how the algorithm grows.

Run from the project root::

    python benchmarks/size_scaling.py [--quick] [--out DIR] [--png FILE]

(the picture needs the `plot` extra).  It prints the machine it ran on.
``python benchmarks/size_scaling.py --table CSV`` prints the Markdown table of
a run's CSV as docs/performance.md shows it; the published run is in
``benchmarks/results/size_scaling``.
"""
from __future__ import annotations

import argparse
import os
import sys

if __name__ == "__main__":   # before numpy is imported anywhere
    _threads = "1"
    if "--blas-threads" in sys.argv:
        _threads = sys.argv[sys.argv.index("--blas-threads") + 1]
    for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[_v] = _threads

import csv
import math
import platform
import time
import warnings
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
CASES = ROOT / "cases"

#: the robot's state is taken at this time, just before C strikes [s]
T_START = 0.095
#: simulated window after ``T_START`` [s]
WINDOW = 0.03

SIZES = {"beam_modal": (16, 32, 64, 128, 256, 512, 1024),
         "beam_full": (16, 32, 64, 128, 256, 512, 1024),
         "chain": (3, 6, 12, 25, 50, 100, 200, 300)}
QUICK_SIZES = {"beam_modal": (16, 32), "beam_full": (16, 32), "chain": (3, 6)}

#: the chain's masses [kg] and springs [N/m] (three_mass's m_s and c_ref)
CHAIN_MASS, CHAIN_STIFFNESS = 0.15, 1.6e5
GRAVITY = 9.81

#: robot joints and the bodies they carry, as in both scenes
JOINTS = {"x": "slider_x", "y": "slider_y", "body": "main", "arm": "arm"}

#: columns of the CSV, in order
COLUMNS = ("series", "size", "dofs", "modes", "omega_max", "window_s", "macro_steps",
           "cpu_build_s", "cpu_simulate_s", "cpu_solve_s", "cpu_structure_s",
           "cpu_per_sim_s", "cpu_per_step_s", "structure_cpu_per_step_s", "contacts_C",
           "peak_C", "status")


@dataclass(frozen=True)
class Point:
    """One run: a series at one size (see :data:`COLUMNS`)."""

    series: str
    size: int
    dofs: int
    modes: int
    omega_max: float
    window_s: float
    macro_steps: int
    cpu_build_s: float
    cpu_simulate_s: float
    cpu_solve_s: float
    cpu_structure_s: float
    cpu_per_sim_s: float
    cpu_per_step_s: float
    structure_cpu_per_step_s: float
    contacts_C: int
    peak_C: float
    status: str


def loglog_slope(size, cost, tail: int | None = None) -> tuple[float, float]:
    """Exponent ``p`` of ``cost ~ c size**p``: least squares of log cost on
    log size.

    Parameters
    ----------
    size, cost : sequences of positive float
        Problem sizes and what they cost (any unit).
    tail : int, optional
        Fit only the ``tail`` largest sizes (at least 2).  A cost with a
        constant part (overhead that does not grow) bends the full-range
        fit below the exponent the large sizes follow; the tail sees past it.

    Returns
    -------
    slope, intercept : float
        ``log cost = intercept + slope * log size`` (natural logarithms).

    Raises
    ------
    ValueError
        With fewer than two points, sizes that are not distinct, or a size or
        cost that is not finite and positive.
    """
    x = np.asarray(size, float).ravel()
    y = np.asarray(cost, float).ravel()
    if x.shape != y.shape:
        raise ValueError(f"`size` and `cost` must have the same length, got {x.size} and "
                         f"{y.size}")
    if not (np.all(np.isfinite(x)) and np.all(x > 0) and np.all(np.isfinite(y))
            and np.all(y > 0)):
        raise ValueError("`size` and `cost` must be finite and > 0 for a log-log fit")
    order = np.argsort(x)
    x, y = x[order], y[order]
    if tail is not None:
        if tail < 2:
            raise ValueError(f"`tail` must be >= 2, got {tail}")
        x, y = x[-tail:], y[-tail:]
    if x.size < 2 or np.unique(x).size < 2:
        raise ValueError(f"a slope needs at least two distinct sizes, got {x.tolist()}")
    slope, intercept = np.polyfit(np.log(x), np.log(y), 1)
    return float(slope), float(intercept)


# ------------------------------------------------------------------ scenes
def _robot_overrides(state: dict) -> list:
    ov = []
    for joint, body in JOINTS.items():
        for key in ("q", "dq"):
            ov.append((["subsystems", "robot", "bodies", body, "joint", f"{key}0"],
                       float(state[joint][key])))
    return ov


def _scene_file(series: str) -> tuple[Path, str | None]:
    return ((CASES / "three_mass.toml", "f100") if series == "chain"
            else (CASES / "beam_impact.toml", None))


def robot_state(series: str, t_start: float = T_START) -> dict:
    """The robot's joints ``{name: {q, dq}}`` at ``t_start`` in the original
    scene of a series (C has not touched yet, so the structure plays no part)."""
    from cosim import load_scene, simulate
    path, variant = _scene_file(series)
    res = simulate(load_scene(path, variant, [f"t_end={t_start!r}"]), estimate=False)
    if res.summary["contacts"]["C"]["count"]:
        raise ValueError(f"C touched before `t_start` = {t_start} s in {path.name}; start "
                         f"earlier")
    return res.summary["final_state"]["robot"]


def overrides(series: str, size: int, robot: dict, window: float) -> list:
    """Overrides making the scene of ``series`` at ``size``, the robot
    starting in state ``robot``, run for ``window`` seconds."""
    ov = _robot_overrides(robot) + [(["t_end"], float(window))]
    if series == "chain":
        n = int(size)
        # static sag of the top mass: sum over the n springs below it of the
        # weight they carry, g m (1 + 2 + ... + n) / k
        sag = GRAVITY * CHAIN_MASS * n * (n + 1) / (2.0 * CHAIN_STIFFNESS)
        ov += [(["subsystems", "chain", "masses"], [CHAIN_MASS] * n),
               (["subsystems", "chain", "stiffnesses"], [CHAIN_STIFFNESS] * n),
               (["subsystems", "chain", "origin"], [0.4733, sag])]
    else:
        ov.append((["subsystems", "beam", "elements"], int(size)))
        if series == "beam_full":
            # no `modes` table: every mode is kept.  The structure's RK4
            # `contact_step` is checked against the fastest kept mode when the
            # system is built, though the closed-form contact steps of this
            # scene never use it; set it small enough to pass.
            ov += [(["subsystems", "beam", "modes"], {}),
                   (["subsystems", "beam", "integrator", "contact_step"], 1e-15)]
    return ov


class _StructureClock:
    """Process time spent in :meth:`StructureSubsystem._step_impl` (patched
    on the class for the duration of a ``with`` block).  The run goes through
    the Python macro loop (``COSIM_DRIVER=python``), which calls the step it
    times; the compiled loop steps the structure's kernel itself."""

    def __enter__(self):
        self.driver = os.environ.get("COSIM_DRIVER")
        os.environ["COSIM_DRIVER"] = "python"
        from cosim.sides.fem import StructureSubsystem
        self.cls, self.orig, self.total = StructureSubsystem, StructureSubsystem._step_impl, 0.0
        clock = self

        def timed(sub, *args, **kwargs):
            t0 = time.process_time()
            try:
                return clock.orig(sub, *args, **kwargs)
            finally:
                clock.total += time.process_time() - t0

        self.cls._step_impl = timed
        return self

    def __exit__(self, *exc):
        self.cls._step_impl = self.orig
        if self.driver is None:
            os.environ.pop("COSIM_DRIVER", None)
        else:
            os.environ["COSIM_DRIVER"] = self.driver


def run_point(series: str, size: int, robot: dict, window: float = WINDOW) -> Point:
    """Build and run one scene of a series; CPU as process time."""
    from cosim import load_scene, simulate
    from cosim.sides.fem import StructureSubsystem
    path, variant = _scene_file(series)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = load_scene(path, variant, overrides(series, size, robot, window))
        t0 = time.process_time()
        system, _ = scene.build()
        cpu_build = time.process_time() - t0
    sub = next(s for s in system.subsystems if isinstance(s, StructureSubsystem))
    with _StructureClock() as clock:
        t0 = time.process_time()
        res = simulate(scene, estimate=False)
        cpu_sim = time.process_time() - t0
    s = res.summary
    solve, steps = float(s["cpu_time_s"]), int(s["macro_steps"])
    c = s["contacts"]["C"]
    return Point(series, int(size), int(sub.structure.n_dof), int(sub.n_modes),
                 float(np.max(sub.omega)), float(window), steps, cpu_build, cpu_sim, solve,
                 clock.total, solve / window, solve / max(steps, 1),
                 clock.total / max(steps, 1), int(c["count"]), float(c["peak_penetration"]),
                 s["status"])


def run_series(series: str, sizes, window: float = WINDOW, budget: float = math.inf,
               robot: dict | None = None, echo=None) -> list[Point]:
    """Run a series over ``sizes`` (ascending); stop after a run whose
    ``simulate`` CPU exceeds ``budget`` seconds, as larger ones cost more."""
    from cosim.errors import SimulationError
    from cosim.scene.load import SceneError
    robot = robot_state(series) if robot is None else robot
    points = []
    for n in sizes:
        try:
            p = run_point(series, n, robot, window)
        except (SceneError, SimulationError, ValueError) as exc:
            nan = math.nan
            p = Point(series, int(n), 0, 0, nan, float(window), 0, nan, nan, nan, nan, nan, nan,
                      nan, 0, nan, f"error: {exc}")
        points.append(p)
        if echo:
            echo(p)
        if p.cpu_simulate_s > budget:
            if echo and n != sizes[-1]:
                echo(f"{series}: stopped after size {n} ({p.cpu_simulate_s:.1f} s CPU > "
                     f"budget {budget:g} s)")
            break
    return points


def read_csv(path) -> list[Point]:
    """Points of a CSV written by :func:`write_csv`."""
    types = {f: t for f, t in Point.__annotations__.items()}
    with Path(path).open() as fh:
        return [Point(**{k: (v if types[k] == "str" else
                             int(v) if types[k] == "int" else float(v))
                         for k, v in row.items()}) for row in csv.DictReader(fh)]


def write_csv(points, path) -> Path:
    from cosim.io.rundir import atomic_write

    def write(fh):
        w = csv.DictWriter(fh, fieldnames=COLUMNS)
        w.writeheader()
        for p in points:
            w.writerow(asdict(p))
    return atomic_write(Path(path), write, "w")


SLOPE_METRICS = ("cpu_per_sim_s", "cpu_per_step_s", "structure_cpu_per_step_s", "cpu_build_s")


def slopes(points) -> dict:
    """``{series: {metric: (slope over all sizes, slope over the larger half)}}``."""
    out = {}
    for series in dict.fromkeys(p.series for p in points):
        pts = [p for p in points if p.series == series and p.status == "finished"]
        if len(pts) < 2:
            continue
        size = [p.size for p in pts]
        out[series] = {}
        for m in SLOPE_METRICS:
            cost = [getattr(p, m) for p in pts]
            tail = max(2, (len(pts) + 1) // 2)
            out[series][m] = (loglog_slope(size, cost)[0], loglog_slope(size, cost, tail)[0])
    return out


_UNITS = {"chain": "masses"}


def table(points) -> str:
    """The Markdown table of a run's points as docs/performance.md shows it:
    per series its sizes and kept modes (first … last), the CPU per simulated
    second, the slopes of log CPU per step on log size (whole run and the
    structure's steps; all sizes / larger half) and the build CPU."""
    fits = slopes(points)
    lines = ["| series | sizes | kept modes | CPU per simulated second [s] | slope per step, "
             "whole run | slope per step, structure's steps | build [ms] |",
             "|---|---|---|---|---|---|---|"]
    for series, fit in fits.items():
        pts = [q for q in points if q.series == series and q.status == "finished"]
        a, b = pts[0], pts[-1]
        lines.append(
            f"| `{series}` | {a.size} … {b.size} {_UNITS.get(series, 'elements')} "
            f"| {a.modes} … {b.modes} | {a.cpu_per_sim_s:.1f} … {b.cpu_per_sim_s:.1f} "
            f"| {fit['cpu_per_step_s'][0]:.2f} / {fit['cpu_per_step_s'][1]:.2f} "
            f"| {fit['structure_cpu_per_step_s'][0]:.2f} / "
            f"{fit['structure_cpu_per_step_s'][1]:.2f} "
            f"| {1e3 * a.cpu_build_s:.0f} … {1e3 * b.cpu_build_s:.0f} |")
    return "\n".join(lines)


def plot(points, path) -> Path:
    """Log-log picture: CPU per simulated second (solid) and the structure's
    share of it (dashed) against size, one panel for the beam, one for the
    chain."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 2, figsize=(10, 4.2), sharey=True, constrained_layout=True)
    style = {"beam_modal": ("C0", "modal (cutoff 20 kHz)"),
             "beam_full": ("C3", "all modes"), "chain": ("C2", "chain")}
    fits = slopes(points)
    for ax, group, xlabel in ((axes[0], ("beam_modal", "beam_full"), "beam elements"),
                              (axes[1], ("chain",), "chain masses")):
        for series in group:
            pts = [p for p in points if p.series == series and p.status == "finished"]
            if not pts:
                continue
            color, label = style[series]
            n = [p.size for p in pts]
            slope = fits.get(series, {}).get("cpu_per_sim_s", (math.nan, math.nan))[1]
            ax.loglog(n, [p.cpu_per_sim_s for p in pts], "o-", color=color,
                      label=f"{label}: whole run (slope {slope:.2f}, larger half)")
            ax.loglog(n, [p.cpu_structure_s / p.window_s for p in pts], "s--", color=color,
                      alpha=0.7, label=f"{label}: structure's steps")
        ax.set_xlabel(xlabel)
        ax.set_ylabel("CPU per simulated second [s/s]")
        ax.grid(True, which="both", alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=8, loc="upper left")
    top = max((p.cpu_per_sim_s for p in points if p.status == "finished"), default=1.0)
    axes[0].set_ylim(top=20.0 * top)          # room for the legends above the data
    axes[0].set_title("beam_impact: C's two contacts")
    axes[1].set_title("three_mass f100: C's contact train")
    from cosim.io.rundir import atomic_write
    path = atomic_write(Path(path), lambda fh: fig.savefig(fh, dpi=110, format="png"), "wb")
    plt.close(fig)
    return path


def machine() -> str:
    threads = os.environ.get("OPENBLAS_NUM_THREADS", "default")
    return (f"machine: {platform.machine()} {platform.processor() or ''}".rstrip()
            + f", {os.cpu_count()} cores, Python {platform.python_version()}, numpy "
            f"{np.__version__}, {platform.system()} {platform.release()}, BLAS threads "
            f"{threads}")


def _echo(p):
    if isinstance(p, str):
        print(p, flush=True)
        return
    if p.status.startswith("error"):
        print(f"{p.series:<11}{p.size:>6}  {p.status}", flush=True)
        return
    print(f"{p.series:<11}{p.size:>6}{p.dofs:>6}{p.modes:>6}{p.omega_max:>10.3g}"
          f"{p.macro_steps:>6}{p.cpu_build_s:>9.3f}{p.cpu_simulate_s:>9.3f}"
          f"{p.cpu_solve_s:>9.3f}{p.cpu_structure_s:>9.3f}{p.cpu_per_step_s * 1e3:>9.3f}"
          f"{p.contacts_C:>4}  {p.status}", flush=True)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="two small sizes per series")
    ap.add_argument("--series", default="beam_modal,beam_full,chain")
    ap.add_argument("--window", type=float, default=WINDOW, help="simulated time [s]")
    ap.add_argument("--budget", type=float, default=120.0,
                    help="stop a series after a run costing more CPU than this [s]")
    ap.add_argument("--out", default="runs/size-scaling", help="directory of the CSV")
    ap.add_argument("--png", default=None, help="picture (default OUT/size_scaling.png)")
    ap.add_argument("--blas-threads", default="1", help="BLAS threads (set before numpy loads)")
    ap.add_argument("--sizes", action="append", default=[], metavar="SERIES=N,N,...",
                    help="sizes of one series (repeatable)")
    ap.add_argument("--from-csv", default=None, metavar="CSV",
                    help="no runs: slopes and picture of an earlier CSV")
    ap.add_argument("--table", default=None, metavar="CSV",
                    help="no runs: the Markdown table of an earlier CSV")
    args = ap.parse_args(argv)
    if args.table:
        print(table(read_csv(args.table)))
        return 0
    if args.from_csv:
        points = read_csv(args.from_csv)
        _report(points, args.png or Path(args.from_csv).with_suffix(".png"))
        return 0
    sizes = dict(QUICK_SIZES if args.quick else SIZES)
    for item in args.sizes:
        name, _, values = item.partition("=")
        if name not in SIZES or not values:
            ap.error(f"--sizes must read SERIES=N,N,... with SERIES in {sorted(SIZES)}, "
                     f"got {item!r}")
        sizes[name] = tuple(sorted(int(v) for v in values.split(",")))
    print(machine())
    print(f"window {args.window} s from t = {T_START} s; CPU in s; per step in ms")
    print(f"{'series':<11}{'size':>6}{'dofs':>6}{'modes':>6}{'w_max':>10}{'steps':>6}"
          f"{'build':>9}{'simul.':>9}{'solve':>9}{'struct.':>9}{'ms/step':>9}{'C':>4}")
    points = []
    for series in args.series.split(","):
        points += run_series(series, sizes[series], args.window, args.budget, echo=_echo)
    out = Path(args.out)
    print(f"CSV: {write_csv(points, out / 'size_scaling.csv')}")
    _report(points, args.png or out / "size_scaling.png")
    return 0


def _report(points, png):
    print("log-log slopes (all sizes / larger half):")
    for series, fit in slopes(points).items():
        print(f"  {series:<11}" + "  ".join(f"{m} {a:.2f} / {b:.2f}" for m, (a, b)
                                             in fit.items()))
    try:
        print(f"plot: {plot(points, png)}")
    except ImportError:
        print("plot: skipped (matplotlib missing: pip install '.[plot]')")


if __name__ == "__main__":
    sys.exit(main())

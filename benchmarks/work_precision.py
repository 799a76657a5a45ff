"""The work-precision study of three_mass f100 (the README's picture):
``cosim bench`` over Gauss-Seidel, Jacobi and implicit at five step sizes,
the paper's RK45 and the monolithic scheme at four tolerances, each row on
the scene and four copies moved by round-off (``--spread 5``).

Run from the project root: ``python benchmarks/work_precision.py [--out DIR]``
(needs the `plot` extra for the picture).  The table it prints starts with
the machine it ran on.

``python benchmarks/work_precision.py --table DIR`` prints the Markdown table
of a finished study (``DIR/bench.csv`` and ``DIR/reference.json``) as
docs/performance.md shows it; the published run is in
``benchmarks/results/work_precision_three_mass_f100``.
"""
import json
import math
import sys
from pathlib import Path

#: the scene and four round-off copies (+1, -1, +2, -2 ulps) per row
SPREAD = 5
#: the scene's own scheme and step in contact (marked "default" in the table)
DEFAULT = ("gauss_seidel", 3e-5)
#: the study's arguments after ``cosim``
ARGS = ["bench", "cases/three_mass.toml", "--variant", "f100", "--schemes",
        "gauss_seidel,jacobi,implicit", "--steps", "8e-5,4e-5,3e-5,2e-5,1e-5",
        "--spread", str(SPREAD)]

HEADER = ("| run | step in contact | rtol | CPU [s], median | C's peak, median / worst "
          "| C's contacts | exit velocity, median / worst | energy, median / worst |\n"
          "|---|---|---|---|---|---|---|---|")


def _e(x: float) -> str:
    """``x`` with two digits, the exponent without its zero: 1.6e-4."""
    m, e = f"{x:.1e}".split("e")
    return f"{m}e{int(e)}"


def _band(med: float, worst: float, bold: bool = True) -> str:
    """``median / worst``; a worst above 1 % in bold when ``bold``."""
    worst_text = _e(worst)
    if bold and worst > 0.01:
        worst_text = f"**{worst_text}**"
    return f"{_e(med)} / {worst_text}"


def table(rows, ref: dict) -> str:
    """The Markdown table of a study's rows (:class:`cosim.studies.bench.BenchRow`):
    medians and worst copies; a worst peak or exit-velocity error above 1 %
    and a contact count other than the reference's in bold; a row whose
    copies did not all finish says how many did."""
    lines = [HEADER]
    for r in rows:
        cells = [f"`{r.label}`" + (" (default)" if (r.scheme, r.macro_step) == DEFAULT else ""),
                 "" if math.isnan(r.macro_step) else f"{r.macro_step * 1e6:.0f} µs",
                 "" if math.isnan(r.tolerance) else _e(r.tolerance).replace("1.0e", "1e"),
                 f"{r.cpu_time_s:.2f}"]
        if r.status != "finished":
            cells += [f"{r.status}: {r.finished} of {r.copies} copies finished", "", "", ""]
        else:
            lo, hi = int(r.count_min), int(r.count_max)
            counts = str(lo) if lo == hi else f"{lo}-{hi}"
            if lo != ref["count"] or hi != ref["count"]:
                counts = f"**{counts}**"
            cells += [_band(r.err_peak, r.err_peak_worst), counts,
                      _band(r.err_exit_velocity, r.err_exit_velocity_worst),
                      _band(r.err_energy, r.err_energy_worst, bold=False)]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def published(folder):
    """The rows and reference of a finished study."""
    from cosim.studies.bench import read_csv
    folder = Path(folder)
    return read_csv(folder / "bench.csv"), json.loads((folder / "reference.json").read_text())


if __name__ == "__main__":
    if "--table" in sys.argv:
        rows, ref = published(sys.argv[sys.argv.index("--table") + 1])
        print(table(rows, ref))
        sys.exit(0)
    from cosim.cli import main
    out = sys.argv[sys.argv.index("--out") + 1] if "--out" in sys.argv else "runs/work-precision"
    sys.exit(main(ARGS + ["--out", out]))

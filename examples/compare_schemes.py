"""One scene under several coupling schemes, compared with the monolithic reference.

Runs ``cases/three_mass.toml``, variant ``f100`` (the arm strikes a three-mass chain through
a stiff spring and rebounds in a train of contacts), once per scheme, and compares C's
contact intervals, peak force and CPU time with those of ``monolithic``, which stacks every
subsystem into one ODE. C's law is linear, so its peak force is its stiffness times its peak
penetration, which each run locates between its samples.

The figure ``docs/_static/examples/compare_schemes.png`` was made by::

    python examples/compare_schemes.py
"""
import argparse
import json
from pathlib import Path

from matplotlib.figure import Figure

import cosim
from cosim.io.rundir import atomic_write

SCENE = Path(__file__).resolve().parents[1] / "cases" / "three_mass.toml"
SCHEMES = ["monolithic", "jacobi", "gauss_seidel", "implicit"]


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--t-end", type=float, default=0.13,
                        help="end time [s] (C strikes at 0.103 s)")
    parser.add_argument("--out", type=Path, default=Path("runs/examples/compare_schemes"))
    args = parser.parse_args(argv)

    rows = {}
    for name in SCHEMES:
        scene = cosim.load_scene(SCENE, "f100", [f"t_end={args.t_end}"], scheme=name)
        result = cosim.simulate(scene, estimate=False)   # its CPU, not its error
        c = result.summary["contacts"]["C"]
        k = scene.data["contacts"]["C"]["law"]["contact_stiffness"]
        rows[name] = {"intervals": c["intervals"], "peak_force": k * c["peak_penetration"],
                      "cpu_time_s": result.summary["cpu_time_s"]}
    ref = rows["monolithic"]
    print(f"{'scheme':<14}{'contacts':>9}{'peak force [N]':>16}{'vs ref':>9}{'CPU [s]':>9}")
    for name, r in rows.items():
        r["peak_error"] = r["peak_force"] / ref["peak_force"] - 1.0
        print(f"{name:<14}{len(r['intervals']):>9}{r['peak_force']:>16.1f}"
              f"{r['peak_error']:>+9.2%}{r['cpu_time_s']:>9.2f}")
    atomic_write(args.out / "compare_schemes.json", lambda fh: json.dump(rows, fh, indent=1), "w")

    fig = Figure(figsize=(8, 5), dpi=100, layout="constrained")
    ax_t, ax_p = fig.subplots(1, 2, width_ratios=[2.2, 1])
    for i, (name, r) in enumerate(rows.items()):
        spans = [(1e3 * a, 1e3 * (b - a)) for a, b in r["intervals"]]
        ax_t.broken_barh(spans, (i - 0.35, 0.7), color=f"C{i}")
    ax_t.set_yticks(range(len(rows)),
                    [f"{n}\n{r['cpu_time_s']:.2f} s CPU" for n, r in rows.items()])
    ax_t.invert_yaxis()
    ax_t.set_xlabel("time [ms]")
    ax_t.set_title("contact intervals of C")
    ax_p.barh(range(len(rows)), [100 * r["peak_error"] for r in rows.values()],
              color=[f"C{i}" for i in range(len(rows))])
    ax_p.set_yticks(range(len(rows)), [])
    ax_p.invert_yaxis()
    ax_p.axvline(0.0, color="k", lw=0.8)
    ax_p.set_xlabel("peak force vs monolithic [%]")
    ax_p.set_title("peak force of C")
    atomic_write(args.out / "compare_schemes.png",
                 lambda fh: fig.savefig(fh, format="png"), "wb")
    print(f"wrote {args.out / 'compare_schemes.png'}")


if __name__ == "__main__":
    main()

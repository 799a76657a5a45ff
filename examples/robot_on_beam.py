"""A robot arm strikes a steel beam: the contact force and the beam's deflection where it is struck.

Runs the shipped scene ``cases/beam_impact.toml`` (a 12 kg robot whose arm hits a simply
supported 1 m steel beam at 0.45 m from its left support) and plots the contact force of C
and the beam's deflection at the struck point. The deflection is evaluated between the nodes
with the beam's own shape functions (``fem.Beam(...).assemble().point_operator``) from the
nodal values that ``series`` holds as ``q/beam/w1``, ``q/beam/t1``, ...

Before C strikes, the beam rests at its static sag under its own weight; the script prints
that sag next to the closed form ``q s (L^3 - 2 L s^2 + s^3) / (24 E I)``.

The figure ``docs/_static/examples/robot_on_beam.png`` was made by::

    python examples/robot_on_beam.py
"""
import argparse
import json
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

import cosim
from cosim.io.rundir import atomic_write
import fem

SCENE = Path(__file__).resolve().parents[1] / "cases" / "beam_impact.toml"


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--t-end", type=float, default=0.13,
                        help="end time [s] (C strikes at 0.103 s)")
    parser.add_argument("--out", type=Path, default=Path("runs/examples/robot_on_beam"))
    args = parser.parse_args(argv)

    scene = cosim.load_scene(SCENE, overrides=[f"t_end={args.t_end}"])
    result = cosim.simulate(scene, estimate=False)   # no error estimate read here
    t, force = result.series["t"], result.series["force/C"]

    # the beam as the scene declares it, to evaluate w between the nodes
    b = scene.data["subsystems"]["beam"]
    section = fem.rectangular_section(**b["section"])
    beam = fem.Beam(b["length"], b["youngs_modulus"], section.second_moment, b["density"],
                    section.area, b["elements"], b["left"], b["right"]).assemble()
    s = b["points"]["under_C"]
    dofs, weights = beam.point_operator(s)
    w = weights @ np.array([result.series[f"q/beam/{beam.dof_names[i]}"] for i in dofs])

    L, EI = b["length"], b["youngs_modulus"] * section.second_moment
    q = b["density"] * section.area * scene.data["effects"]["gravity"]   # weight [N/m]
    sag = -q * s * (L**3 - 2 * L * s**2 + s**3) / (24 * EI)       # static sag at s [m]
    intervals = result.summary["contacts"]["C"]["intervals"]
    print(f"C's contacts: {intervals}")
    print(f"peak force {force.max():.0f} N, lowest deflection {w.min() * 1e3:.3f} mm")
    print(f"sag at rest {w[0] * 1e3:.4f} mm, closed form {sag * 1e3:.4f} mm")
    summary = {"sag": float(w[0]), "sag_closed_form": sag, "intervals": intervals,
               "peak_force": float(force.max()), "lowest_deflection": float(w.min())}
    atomic_write(args.out / "robot_on_beam.json", lambda fh: json.dump(summary, fh, indent=1), "w")

    fig = Figure(figsize=(8, 5), dpi=100, layout="constrained")
    ax_f, ax_w = fig.subplots(2, 1, sharex=True)
    ax_f.plot(t * 1e3, force, color="C3")
    ax_f.set_ylabel("contact force at C [N]")
    ax_w.plot(t * 1e3, w * 1e3, color="C0", label="beam under C")
    ax_w.axhline(sag * 1e3, color="0.5", ls=":", label="static sag (closed form)")
    for t_on, t_off in intervals:
        for ax in (ax_f, ax_w):
            ax.axvspan(t_on * 1e3, t_off * 1e3, color="C3", alpha=0.12, lw=0)
    ax_w.set_ylabel("deflection at 0.45 m [mm]")
    ax_w.set_xlabel("time [ms]")
    ax_w.legend(loc="lower left")
    ax_f.set_xlim(max(0.0, (intervals[0][0] - 0.005) * 1e3) if intervals else 0.0, t[-1] * 1e3)
    atomic_write(args.out / "robot_on_beam.png",
                 lambda fh: fig.savefig(fh, format="png"), "wb")
    print(f"wrote {args.out / 'robot_on_beam.png'}")


if __name__ == "__main__":
    main()

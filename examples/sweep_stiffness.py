"""Sweep a contact stiffness: peak force and contact time against k, with their closed forms.

Runs ``cases/spring_drop.toml`` (a 1 kg mass at 1 m/s against a wall through a linear
penalty spring) once per stiffness, each run a plain ``cosim.run_scene`` with an override of
``contacts.wall.law.contact_stiffness``, as ``cosim run --set`` does. The undamped spring
gives closed forms to compare with: the contact lasts ``pi sqrt(m/k)`` and the force peaks at
``v0 sqrt(k m)``. A contact still closed at ``--t-end`` is left out.
(``cosim sweep cases/spring_drop.toml --set contacts.wall.law.contact_stiffness=1e5,1e6``
runs the same points on a process pool and writes one table.)

The figure ``docs/_static/examples/sweep_stiffness.png`` was made by::

    python examples/sweep_stiffness.py
"""
import argparse
import json
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

import cosim
from cosim.io.rundir import atomic_write

SCENE = Path(__file__).resolve().parents[1] / "cases" / "spring_drop.toml"
MASS, SPEED = 1.0, 1.0                     # [kg], [m/s]: the scene's body and its approach


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--t-end", type=float, default=0.02, help="end time [s] (touch at 10 ms)")
    parser.add_argument("--out", type=Path, default=Path("runs/examples/sweep_stiffness"))
    args = parser.parse_args(argv)

    stiffness = np.geomspace(1e5, 1e8, 7)                           # [N/m]
    peak_force, contact_time = np.full(7, np.nan), np.full(7, np.nan)
    for i, k in enumerate(stiffness):
        result = cosim.run_scene(SCENE, overrides=[f"t_end={args.t_end}",
                                                        f"contacts.wall.law.contact_stiffness={k}"],
                                 estimate=False)
        wall = result.summary["contacts"]["wall"]
        if wall["count"] == 1 and wall["intervals"][0][1] < args.t_end:     # touched and left
            peak_force[i] = k * wall["peak_penetration"]    # linear law: f = k d
            contact_time[i] = wall["in_touch_time"]
    exact_force, exact_time = SPEED * np.sqrt(stiffness * MASS), np.pi * np.sqrt(MASS / stiffness)
    for row in zip(stiffness, peak_force, exact_force, contact_time * 1e3, exact_time * 1e3):
        print("k = {:8.3g} N/m   peak {:9.2f} N (exact {:9.2f})   contact {:7.4f} ms "
              "(exact {:7.4f})".format(*row))
    atomic_write(args.out / "sweep_stiffness.json", lambda fh: fh.write(json.dumps(
        {"stiffness": stiffness.tolist(), "peak_force": peak_force.tolist(),
         "contact_time": contact_time.tolist(), "exact_force": exact_force.tolist(),
         "exact_time": exact_time.tolist()}, indent=1)), "w")

    fig = Figure(figsize=(8, 5), dpi=100, layout="constrained")
    ax_f, ax_t = fig.subplots(1, 2)
    ax_f.loglog(stiffness, exact_force, color="0.6", label=r"$v_0\sqrt{km}$")
    ax_f.loglog(stiffness, peak_force, "o", color="C3", label="cosim")
    ax_f.set_ylabel("peak contact force [N]")
    ax_t.loglog(stiffness, exact_time * 1e3, color="0.6", label=r"$\pi\sqrt{m/k}$")
    ax_t.loglog(stiffness, contact_time * 1e3, "o", color="C0", label="cosim")
    ax_t.set_ylabel("contact time [ms]")
    for ax in (ax_f, ax_t):
        ax.set_xlabel("contact stiffness k [N/m]")
        ax.legend()
    atomic_write(args.out / "sweep_stiffness.png",
                 lambda fh: fig.savefig(fh, format="png"), "wb")
    print(f"wrote {args.out / 'sweep_stiffness.png'}")


if __name__ == "__main__":
    main()

"""Wall time of a parameter sweep against the single run's solve (target:
200 points of three_mass f10 on 2 workers within 1.3 x points x single-run
solve / workers, the sweep's own cost at most 30 % above the solves').

Run from the project root::

    python benchmarks/sweep_wall.py [--points 200] [--workers 2] [--out DIR]

It measures the solve CPU of one run of the point scene (best of 3), then runs
the sweep on a local process pool (``cosim.studies.sweep``: one run directory per
point and ``sweep.csv`` under ``--out``, default ``runs/sweep-wall``, which is
replaced) and prints its wall time beside the bound.  The points vary the arm's
initial rate over a band around the scene's -20 rad/s, so every point strikes
the chain.
"""
import argparse
import os
import platform
import shutil
import time
import warnings

import numpy as np

import cosim
from cosim.studies.sweep import sweep

SCENE = "cases/three_mass.toml"
VARIANT = "f10"
KEY = "subsystems.robot.bodies.arm.joint.dq0"
#: the bound's factor over the points' solves shared among the workers
FACTOR = 1.3


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--points", type=int, default=200)
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--out", default="runs/sweep-wall")
    args = p.parse_args()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        single = min(cosim.simulate(cosim.load_scene(SCENE, VARIANT),
                                    estimate=False).summary["cpu_time_s"] for _ in range(3))
    values = [float(v) for v in np.round(np.linspace(-21.0, -19.0, args.points), 6)]
    shutil.rmtree(args.out, ignore_errors=True)
    wall0 = time.perf_counter()
    rows = sweep(SCENE, variants=[VARIANT], grid={KEY: values}, workers=args.workers,
                 out=args.out)
    wall = time.perf_counter() - wall0
    bound = FACTOR * args.points * single / args.workers
    done = sum(r.get("status") == "finished" for r in rows)
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, Python "
          f"{platform.python_version()}; load average {os.getloadavg()[0]:.2f}")
    print(f"single run solve (best of 3): {single:.3f} s CPU")
    print(f"sweep: {args.points} points ({done} finished) on {args.workers} workers: "
          f"{wall:.2f} s wall; bound {FACTOR:g} x points x single / workers = {bound:.2f} s; "
          f"ratio {wall / bound:.2f}")


if __name__ == "__main__":
    main()

"""CPU of three_mass's solve with the compiled macro loop and with the Python
loop over the same compiled sides, and the share of the run spent inside the
compiled loop's calls.

Run from the project root::

    python benchmarks/macro_loop.py [--repeat N] [--variants f10,f100,f1000]

Per variant it prints the best of ``--repeat`` solves (the summary's
``cpu_time_s``) with each loop (``COSIM_DRIVER``, see
:mod:`cosim.core.schemes.driver`), their ratio, the macro steps, and from
the scheme's ``loop_stats`` the CPU inside the compiled loop's calls over
the CPU of the whole run (the rest is the run's set-up and the recorder
taking the loop's blocks of samples, :mod:`cosim.core.schemes.driven_block`).
"""
import argparse
import os
import platform
import warnings

import cosim
from cosim.core.recorder import Recorder
from cosim.scene.build import build_system


def _scene(variant):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return cosim.load_scene("cases/three_mass.toml", variant)


def solve_cpu(variant, loop, repeat):
    """Best ``cpu_time_s`` of ``repeat`` runs with ``loop``, and the summary."""
    os.environ["COSIM_DRIVER"] = loop
    best, summary = None, None
    for _ in range(repeat):
        summary = cosim.simulate(_scene(variant), estimate=False).summary
        best = summary["cpu_time_s"] if best is None else min(best, summary["cpu_time_s"])
    return best, summary


def compiled_share(variant, repeat):
    """``loop_stats`` of the run whose compiled share is the largest of ``repeat``."""
    os.environ["COSIM_DRIVER"] = "compiled"
    best = None
    for _ in range(repeat):
        scene = _scene(variant)
        system, sch = build_system(scene)
        sch.run(system, scene.t_end, Recorder(system, scene.name, sch.name, scene.t_end))
        st = sch.loop_stats
        if best is None or st["run_cpu_s"] < best["run_cpu_s"]:
            best = st
    return best


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeat", type=int, default=5)
    p.add_argument("--variants", default="f10,f100,f1000")
    args = p.parse_args()
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, Python "
          f"{platform.python_version()}, {platform.system()} {platform.release()}; "
          f"load average {os.getloadavg()[0]:.2f}")
    print(f"{'variant':<9}{'steps':>7}{'python loop [s]':>17}{'compiled loop [s]':>19}"
          f"{'ratio':>8}{'in compiled loop':>18}")
    for v in [x for x in args.variants.split(",") if x]:
        py, _ = solve_cpu(v, "python", args.repeat)
        co, summary = solve_cpu(v, "compiled", args.repeat)
        st = compiled_share(v, args.repeat)
        assert st["loop"] == "compiled", st["refusal"]
        share = st["compiled_cpu_s"] / st["run_cpu_s"]
        print(f"{v:<9}{summary['macro_steps']:>7}{py:>17.4f}{co:>19.4f}{py / co:>8.2f}"
              f"{share:>17.0%}", flush=True)


if __name__ == "__main__":
    main()

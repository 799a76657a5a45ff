"""The share of the solve inside the sampled path's side calls, and the solve
CPU, of the scenes whose contacts all have rigid partners.

Run from the project root::

    python benchmarks/sampled_path.py [--repeat N] [--scenes a,b:variant,...]

Each scene runs ``--repeat`` times in this process (after one run that
loads what a first run loads) as ``cosim run`` runs it (guard, edges,
recorder); per scene it prints the median and the range of the scheme's
``loop_stats``: ``compiled_cpu_s / run_cpu_s`` (the CPU inside the side's
``sample_steps`` calls less the recorder's blocks they called back, over the
whole of the scheme's ``run``), ``run_cpu_s`` and the summary's
``cpu_time_s``, and the kernel's returns to Python (the recorder's blocks).

What the counter counts: everything inside the side's call.  For an RK4
side that is the compiled kernel (a rigid law's impact, resolved in Python,
is called from inside it); for an adaptive method (manipulator_wall's
DOP853) it is the numpy integrator of :mod:`cosim.core.embedded_rk` calling
the compiled right-hand side, so the share overstates the compiled code
there.  ``perf record`` over the solve alone (``perf report --sort dso``:
the samples in the project's ``.so`` files) says what runs compiled.
"""
import argparse
import os
import platform
import statistics
import warnings

import cosim
from cosim.core.schemes import base, sampled

SCENES = "ground_multicontact,manipulator_wall:mu0.03,ground_multicontact_strike"


def measure(name, variant, repeat):
    """``(shares, run_cpu, cpu_time, blocks, stats)`` of ``repeat`` runs."""
    got, blocks = [], []
    run, call = base.CoSimulationScheme.run, sampled._Emitter.__call__

    def keep(self, *args, **kw):
        try:
            return run(self, *args, **kw)
        finally:
            got.append(self.loop_stats)

    def count(self, *args, **kw):
        blocks[-1] += 1
        return call(self, *args, **kw)

    def scene():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return cosim.load_scene(f"cases/{name}.toml", variant)

    base.CoSimulationScheme.run, sampled._Emitter.__call__ = keep, count
    try:
        blocks.append(0)
        cosim.simulate(scene(), estimate=False)          # what a first run loads
        shares, runs, cpus = [], [], []
        blocks[:] = []
        for _ in range(repeat):
            blocks.append(0)
            res = cosim.simulate(scene(), estimate=False)
            st = got[-1]
            shares.append(st["compiled_cpu_s"] / st["run_cpu_s"])
            runs.append(st["run_cpu_s"])
            cpus.append(res.summary["cpu_time_s"])
    finally:
        base.CoSimulationScheme.run, sampled._Emitter.__call__ = run, call
    return shares, runs, cpus, blocks, st


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeat", type=int, default=15)
    p.add_argument("--scenes", default=SCENES, help="names, each with :variant or not")
    args = p.parse_args()
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, Python "
          f"{platform.python_version()}; load average {os.getloadavg()[0]:.2f}")

    def spread(xs, f):
        return f"{f(statistics.median(xs))} [{f(min(xs))}, {f(max(xs))}]"
    pct = "{:.1%}".format
    ms = "{:.2f}".format
    for item in args.scenes.split(","):
        name, _, variant = item.partition(":")
        shares, runs, cpus, blocks, st = measure(name, variant or None, args.repeat)
        assert st["loop"] == "sampled", st
        print(f"{item}: {st['macro_steps']} macro steps in {statistics.median(blocks):.0f} "
              f"returns of the side; compiled share {spread(shares, pct)}; run CPU "
              f"{spread([r * 1e3 for r in runs], ms)} ms; cpu_time_s "
              f"{spread([c * 1e3 for c in cpus], ms)} ms", flush=True)


if __name__ == "__main__":
    main()

"""CPU of the monolithic reference (``--scheme monolithic``): its right-hand
side in compiled code (``cosim.core._stacked``) against the Python one
(``COSIM_KERNEL=numpy``), from one run.

Run from the project root::

    python benchmarks/monolithic.py [--repeat N] [--kernels compiled,numpy] [--profile]

One row per scene: the best ``cpu_time_s`` of ``--repeat`` runs with each
kernel, and each contact's count (the two must agree).  The first run of a
process also pays for importing scipy's integrators (some 0.3 s of CPU);
``--repeat 2`` or more shows the runs without it.  ``--profile`` prints,
per scene and kernel, the right-hand-side and event evaluations and the
functions that took most time (cProfile) in one further run.
"""
import argparse
import cProfile
import os
import platform
import pstats
import warnings

import cosim

#: (scene, variant, overrides)
RUNS = [("three_mass", "f100", ()),
        ("three_mass", "f1", ()),
        ("manipulator_wall", "mu0.03", ()),
        ("beam_impact", None, ()),
        ("spring_drop", None, ())]


def run(name, variant, overrides, kernel):
    os.environ["COSIM_KERNEL"] = kernel
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = cosim.load_scene(f"cases/{name}.toml", variant, list(overrides), "monolithic")
    return cosim.simulate(scene, estimate=False).summary


def profile(name, variant, overrides, kernel, lines=15):
    import cosim.core.schemes.monolithic as mono
    seen = []
    real = mono._compiled_rhs

    def keep(system, active):
        seen.append(real(system, active))
        return seen[-1]

    mono._compiled_rhs = keep
    prof = cProfile.Profile()
    try:
        prof.enable()
        summary = run(name, variant, overrides, kernel)
        prof.disable()
    finally:
        mono._compiled_rhs = real
    stacked = seen[-1] if seen else None
    stats = pstats.Stats(prof)
    print(f"--- {name} {variant or '-'} {kernel}: cpu_time_s {summary['cpu_time_s']:.3f} "
          f"(under the profiler)"
          + (f", compiled rhs calls {stacked.n_rhs}, event evaluations {stacked.n_events}"
             if stacked is not None else ", Python right-hand side"))
    stats.sort_stats("tottime").print_stats(lines)


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeat", type=int, default=1)
    p.add_argument("--kernels", default="compiled,numpy")
    p.add_argument("--only", default="", help="comma-separated scene names")
    p.add_argument("--profile", action="store_true")
    args = p.parse_args()
    kernels = [k for k in args.kernels.split(",") if k]
    only = {s for s in args.only.split(",") if s}
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, Python "
          f"{platform.python_version()}; load average {os.getloadavg()[0]:.2f}")
    print(f"{'scene':<18}{'variant':<9}" + "".join(f"{k + ' CPU [s]':>18}" for k in kernels)
          + "  contacts")
    for name, variant, over in RUNS:
        if only and name not in only:
            continue
        cells, counts = [], []
        for k in kernels:
            best = None
            for _ in range(args.repeat):
                s = run(name, variant, over, k)
                best = s["cpu_time_s"] if best is None else min(best, s["cpu_time_s"])
            cells.append(f"{best:>18.3f}")
            counts.append({c: v["count"] for c, v in s["contacts"].items()})
        same = all(c == counts[0] for c in counts)
        print(f"{name:<18}{variant or '-':<9}{''.join(cells)}  {counts[0]}"
              + ("" if same else f" DIFFER: {counts}"), flush=True)
        if args.profile:
            for k in kernels:
                profile(name, variant, over, k)


if __name__ == "__main__":
    main()

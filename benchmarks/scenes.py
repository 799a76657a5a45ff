"""CPU of every shipped scene under its default scheme (the README's
performance table), and of three_mass f100 under the monolithic reference.

Run from the project root: ``python benchmarks/scenes.py``.  It prints the
machine it ran on; each time is the process CPU of the run itself (the
``cpu_time_s`` of its summary), the best of ``--repeat`` runs.
"""
import argparse
import os
import platform
import warnings

import cosim

RUNS = [("spring_drop", None, None), ("manipulator_wall", "mu0.03", None),
        ("manipulator_wall", "mu0.03", "monolithic"), ("rod_impact", None, None),
        ("ground_multicontact", None, None), ("three_mass", "f100", None),
        ("three_mass", "f100", "monolithic"), ("beam_impact", None, None)]


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeat", type=int, default=1)
    args = p.parse_args()
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, Python "
          f"{platform.python_version()}, {platform.system()} {platform.release()}")
    print(f"{'scene':<22}{'variant':<9}{'scheme':<14}{'simulated [s]':>14}{'CPU [s]':>9}")
    for name, variant, scheme in RUNS:
        best = None
        for _ in range(args.repeat):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                scene = cosim.load_scene(f"cases/{name}.toml", variant, scheme=scheme)
            res = cosim.simulate(scene)
            cpu = res.summary["cpu_time_s"]
            best = cpu if best is None else min(best, cpu)
        print(f"{name:<22}{variant or '-':<9}{res.summary['scheme']:<14}"
              f"{res.summary['t_end']:>14.3g}{best:>9.2f}")


if __name__ == "__main__":
    main()

"""CPU of the shipped scenes with the compiled kernel and with the numpy
reference, from one run (the README's scenes table).

Run from the project root::

    python benchmarks/scenes.py [--repeat N] [--kernels compiled,numpy] [--only NAME,...]
                                [--first-run] [--out DIR]

It prints the machine, then one row per run: the process CPU of the solve
(the ``cpu_time_s`` of its summary), the best of ``--repeat`` runs, with each
kernel (``COSIM_KERNEL``, see :mod:`cosim.sides.kernel`), their ratio, and the target
of the row where there is one.  Both kernels run in the same process, one
after the other, so the ratio holds whatever the machine's speed.  With
``--out DIR`` it writes the same as ``DIR/scenes.json`` (through cosim's
checked writer); ``--table DIR`` prints the Markdown table of such a run as
docs/performance.md shows it (the published run is in
``benchmarks/results/scenes``).

``--first-run`` adds, beside each warm best (the runs above, in this one
process), the solve CPU of a run that is the first of its process: ``python
-m cosim.cli run`` in a fresh interpreter (``--no-estimate``), its
``cpu_time_s`` read from the ``summary.json`` it writes, the best of
``--repeat`` such processes (at least 2: bytecode is cached as users have
it, ``PYTHONDONTWRITEBYTECODE`` dropped, so the first process may pay for
compiling what a later one reads).  The warm runs then write their folders
too (temporary ones), so that both do a run's whole work (its series spooled
to disk).  A one-time cost inside the solve (an import, a first call) shows as
their ratio, ``first/warm``.  Both run
OpenBLAS on one thread, as `cosim run` does, unless the user set a count.
"""
import argparse
import datetime
import json
import os
import platform
import subprocess
import sys
import tempfile
import warnings

if __name__ == "__main__":
    # the warm runs in this process run as `cosim run` does: OpenBLAS on one
    # thread unless the user chose a count (cosim.cli.one_blas_thread_by_default),
    # set before numpy loads
    from cosim.cli import one_blas_thread_by_default
    one_blas_thread_by_default()

import cosim

#: (scene, variant, scheme, overrides, target CPU [s] or None)
RUNS = [("spring_drop", None, None, (), 0.02),
        ("manipulator_wall", "mu0.03", None, (), None),
        ("manipulator_wall", "mu0.03", "monolithic", (), None),
        ("rod_impact", None, None, (), None),
        ("ground_multicontact", None, None, (), 0.15),
        ("three_mass", "f100", None, (), None),
        ("three_mass", "f100", "monolithic", (), 1.0),
        ("beam_impact", None, None, (), None),
        ("beam_impact", None, "monolithic", (), None),
        ("beam_impact", None, None, ("t_end=10",), 2.0),
        ("brachiation", None, None, (), 0.3),
        ("brachiation", None, "monolithic", (), None)]


def solve_cpu(name, variant, scheme, overrides, kernel, repeat, write=False):
    """Best ``cpu_time_s`` of ``repeat`` runs with ``kernel``, and the summary;
    with ``write``, each run writes its folder (a temporary one) as `cosim run`
    does."""
    os.environ["COSIM_KERNEL"] = kernel
    best, summary = None, None
    for _ in range(repeat):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            scene = cosim.load_scene(f"cases/{name}.toml", variant, overrides=overrides,
                                     scheme=scheme)
        with tempfile.TemporaryDirectory() as tmp:
            out = os.path.join(tmp, "run") if write else None
            summary = cosim.simulate(scene, estimate=False, out=out).summary
        cpu = summary["cpu_time_s"]
        best = cpu if best is None else min(best, cpu)
    return best, summary


def first_cpu(name, variant, scheme, overrides, kernel, repeat):
    """Best ``cpu_time_s`` of ``repeat`` (at least 2) runs, each the first of
    a fresh ``python -m cosim.cli run`` process."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env["COSIM_KERNEL"] = kernel
    argv = [sys.executable, "-m", "cosim.cli", "run", f"cases/{name}.toml", "--quiet",
            "--no-estimate"]
    if variant:
        argv += ["--variant", variant]
    if scheme:
        argv += ["--scheme", scheme]
    for o in overrides:
        argv += ["--set", o]
    best = None
    for _ in range(max(2, repeat)):
        with tempfile.TemporaryDirectory() as tmp:
            out = os.path.join(tmp, "run")
            subprocess.run(argv + ["--out", out], env=env, check=True,
                           stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            with open(os.path.join(out, "summary.json"), encoding="utf-8") as fh:
                cpu = json.load(fh)["cpu_time_s"]
        best = cpu if best is None else min(best, cpu)
    return best


def _label(r) -> str:
    text = r["scene"] + (f" {r['variant']}" if r["variant"] else "")
    text += f", `{r['scheme']}`"
    if r["overrides"]:
        text += " " + " ".join(f"`--set {o}`" for o in r["overrides"])
    return text


def table(data: dict) -> str:
    """The Markdown table of a run's ``scenes.json`` (its first kernel)."""
    k = data["kernels"][0]
    first = data.get("first_run", False)    # and the first run of a fresh process, beside
    lines = [f"| scene, scheme | simulated [s] | {k} CPU [s] | "
             + ("first run [s] | first / warm | " if first else "") + "target [s] | met |",
             "|---|---|---|" + ("---|---|" if first else "") + "---|---|"]
    for r in data["rows"]:
        cpu = r["cpu_s"][k]
        target = "-" if r["target_s"] is None else f"{r['target_s']:g}"
        met = "-" if r["target_s"] is None else ("yes" if cpu <= r["target_s"] else "**no**")
        f1 = r["first_cpu_s"][k] if first else None
        cells = f" {f1:.4f} | {f1 / cpu:.2f} |" if first else ""
        lines.append(f"| {_label(r)} | {r['t_end']:g} | {cpu:.4f} |{cells} {target} | {met} |")
    return "\n".join(lines)


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeat", type=int, default=1)
    p.add_argument("--kernels", default="compiled,numpy",
                   help="comma-separated: compiled, numpy (default both)")
    p.add_argument("--only", default="", help="comma-separated scene names")
    p.add_argument("--out", default=None, help="write DIR/scenes.json")
    p.add_argument("--table", metavar="DIR", help="print the table of a finished run")
    p.add_argument("--first-run", action="store_true",
                   help="also each run as the first of a fresh process (first kernel only)")
    args = p.parse_args()
    if args.table:
        with open(os.path.join(args.table, "scenes.json"), encoding="utf-8") as fh:
            print(table(json.load(fh)))
        return
    kernels = [k for k in args.kernels.split(",") if k]
    only = {s for s in args.only.split(",") if s}
    machine = (f"{platform.machine()}, {os.cpu_count()} cores, Python "
               f"{platform.python_version()}, {platform.system()} {platform.release()}")
    data = {"machine": machine, "date": datetime.date.today().isoformat(),
            "load_average": os.getloadavg()[0], "repeat": args.repeat, "kernels": kernels,
            "first_run": args.first_run, "rows": []}
    print(f"machine: {machine}; load average {data['load_average']:.2f}")
    head = "".join(f"{k + ' CPU [s]':>18}" for k in kernels)
    if args.first_run:
        head += f"{'first CPU [s]':>15}{'first/warm':>12}"
    print(f"{'scene':<22}{'variant':<9}{'scheme':<14}{'simulated [s]':>14}{head}"
          f"{'ratio':>8}{'target [s]':>12}")
    for name, variant, scheme, over, target in RUNS:
        if only and name not in only:
            continue
        cpus, summary = [], None
        for k in kernels:
            cpu, summary = solve_cpu(name, variant, scheme, over, k, args.repeat,
                                     write=args.first_run)
            cpus.append(cpu)
        ratio = f"{cpus[0] / cpus[1]:8.3f}" if len(cpus) == 2 else f"{'':8}"
        cells = "".join(f"{c:>18.{4 if args.first_run else 3}f}" for c in cpus)
        first = None
        if args.first_run:
            first = first_cpu(name, variant, scheme, over, kernels[0], args.repeat)
            cells += f"{first:>15.4f}{first / cpus[0]:>12.2f}"
        tgt = f"{target:>12.2f}" if target is not None else f"{'-':>12}"
        print(f"{name:<22}{variant or '-':<9}{summary['scheme']:<14}"
              f"{summary['t_end']:>14.3g}{cells}{ratio}{tgt}", flush=True)
        data["rows"].append({"scene": name, "variant": variant, "scheme": summary["scheme"],
                             "overrides": list(over), "t_end": summary["t_end"],
                             "cpu_s": dict(zip(kernels, cpus)), "target_s": target,
                             **({"first_cpu_s": {kernels[0]: first}} if args.first_run else {})})
    if args.out:
        from cosim.io.rundir import OutputFolder
        with OutputFolder(args.out) as folder:
            folder.write("scenes.json", lambda fh: json.dump(data, fh, indent=1), "w")
        print(f"wrote {args.out}/scenes.json")


if __name__ == "__main__":
    main()

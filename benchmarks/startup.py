"""Start-up of `cosim run`: what importing cosim's own modules and reading and
building the scene cost, as ratios to numpy's own import in the same process.

Run from the project root: ``python benchmarks/startup.py [--repeat 5] [--out DIR]``
(``--out DIR`` writes the figures as ``DIR/startup.json`` through cosim's
checked writer; ``--table DIR`` prints the Markdown table of such a run as
docs/performance.md shows it; the published run is in
``benchmarks/results/startup``).  A
loaded, shared machine makes absolute times noisy; a ratio to numpy, measured in
the same process, travels better between machines and loads.  Each figure is
the best of ``--repeat`` fresh processes, after one that is not counted:
bytecode is cached as users have it (``PYTHONDONTWRITEBYTECODE`` is dropped from
the environment of the runs, and the first run writes the caches).

- *imports*: ``python -X importtime -m cosim.cli run SCENE ...`` as a user types
  it; the self times of every module are summed by top-level package: ours
  (``cosim``, ``multibody``, ``fem``, ``couplers``, each and together), numpy,
  and the rest (the standard library and other packages, whoever asked for them).
  "best sum" is the best of the runs' sums; "sum of bests" sums each module's
  best run, which filters out more of a loaded machine's noise.
- *in process*: in other fresh processes, wall (``time.perf_counter``) and CPU
  (``time.process_time``, which a loaded machine inflates far less) around
  ``import numpy``, ``import cosim.scene.run, cosim.scene.load`` (what the command line
  imports before it reads the scene), ``import cosim.sides._multibody_step`` (the
  compiled kernel, which `cosim run` imports through ``importlib``, out of
  ``-X importtime``'s sight), :func:`cosim.load_scene` and
  :func:`cosim.scene.build.build_system` (with the modules they import where first
  needed); then, in processes that import everything else the run imports
  (numpy, the standard library) before the clock starts, our modules alone, and
  load and build alone.
"""
import argparse
import datetime
import json
import math
import os
import platform
import re
import subprocess
import sys
import tempfile

OURS = ("cosim", "multibody", "fem", "couplers")
_LINE = re.compile(r"import time:\s+(\d+) \|\s+(\d+) \|\s*(\S+)")

TIMING = """
import json, sys, time
scene_path, variant, mode, preload = sys.argv[1], sys.argv[2] or None, sys.argv[3], sys.argv[4:]
out = {}
def clock():
    return time.perf_counter(), time.process_time()
def lap(key, start):
    now = clock()
    out[key] = [now[0] - start[0], now[1] - start[1]]
if mode == "cold":                   # as `cosim run` goes
    t = clock()
    import numpy
    lap("numpy", t)
    t = clock()
    import cosim.scene.run, cosim.scene.load
    lap("import", t)
    t = clock()
    try:                             # the compiled kernel, timed on its own
        import cosim.sides._multibody_step
    except ImportError:
        pass
    lap("extension", t)
else:                                # the rest first: our modules, then load and build, alone
    for name in preload:
        try:
            __import__(name)
        except ImportError:
            pass
    t = clock()
    import cosim.scene.run, cosim.scene.load
    for name in mode.split(","):
        __import__(name)
    lap("ours", t)
t = clock()
scene = cosim.load_scene(scene_path, variant)
lap("load", t)
t = clock()
from cosim.scene.build import build_system
build_system(scene)
lap("build", t)
print(json.dumps(out))
"""
MODULES = """
import sys
before = set(sys.modules)
import cosim
cosim.load_scene(sys.argv[1], sys.argv[2] or None).build()
new = sorted(set(sys.modules) - before)
print(",".join(m for m in new if m.split(".")[0] in OURS))
print(*(m for m in new if m.split(".")[0] not in OURS))
"""
#: the runs' environment: bytecode cached as users have it
ENV = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}


def group(module: str) -> str:
    top = module.split(".")[0]
    return top if top in OURS or top == "numpy" else "other"


GROUPS = (*OURS, "ours", "numpy", "other", "all")
#: key of numpy's cumulative import time (itself and what it imports first)
NUMPY_CUMULATIVE = "<numpy cumulative>"


def group_sums(self_times: dict[str, float]) -> dict[str, float]:
    """Self times [s] summed per package group."""
    sums = dict.fromkeys(GROUPS, 0.0)
    sums[NUMPY_CUMULATIVE] = self_times.get(NUMPY_CUMULATIVE, math.nan)
    for module, t in self_times.items():
        if module == NUMPY_CUMULATIVE:
            continue
        g = group(module)
        sums[g] += t
        if g in OURS:
            sums["ours"] += t
        sums["all"] += t
    return sums


def import_times(scene: str, variant: str | None, out: str) -> dict[str, float]:
    """Self import time [s] of each module, from one ``-X importtime`` run
    (without the error estimate, which comes after the run, not at start-up)."""
    argv = [sys.executable, "-X", "importtime", "-m", "cosim.cli", "run", scene, "--out", out,
            "--overwrite", "--quiet", "--no-estimate"]
    if variant:
        argv += ["--variant", variant]
    proc = subprocess.run(argv, capture_output=True, text=True, env=ENV)
    if proc.returncode != 0:
        raise RuntimeError(f"`cosim run` exited with {proc.returncode}:\n{proc.stderr[-2000:]}")
    times = {}
    for line in proc.stderr.splitlines():
        m = _LINE.match(line)
        if m:
            times[m[3]] = int(m[1]) * 1e-6
            if m[3] == "numpy":           # with the standard library it pulls in
                times[NUMPY_CUMULATIVE] = int(m[2]) * 1e-6
    return times


def _run(script: str, *argv: str) -> str:
    proc = subprocess.run([sys.executable, "-c", script, *argv], capture_output=True,
                          text=True, env=ENV)
    if proc.returncode != 0:
        raise RuntimeError(f"the timing process exited with {proc.returncode}:\n"
                           f"{proc.stderr[-2000:]}")
    return proc.stdout


def scene_times(scene: str, variant: str | None, ours: str = "", others=()) -> dict:
    """Times ``[wall, CPU]`` [s] from one fresh process.  Without ``ours``:
    ``import numpy``, ``import cosim.scene.run, cosim.scene.load``, the kernel's import,
    then ``load_scene`` and ``build_system`` with the imports they trigger.
    With ``ours`` (comma-separated) and ``others``: ``others`` imported before
    the clock starts, then our modules alone, then load and build alone."""
    return json.loads(_run(TIMING, scene, variant or "", ours or "cold", *others))


def best(runs: list[dict]) -> dict:
    """Per key, the least value (per clock where a value is ``[wall, CPU]``)."""
    def least(values):
        if isinstance(values[0], list):
            return [min(v[i] for v in values) for i in range(len(values[0]))]
        return min(values)
    return {k: least([r[k] for r in runs]) for k in runs[0]}


def table(data: dict) -> str:
    """The Markdown table of a run's ``startup.json``."""
    n, per, cpu = data["modules"], data["self_sum_of_bests_s"], data["cpu_s"]
    ratio = cpu["ours"] / cpu["numpy"]
    rows = [(f"our modules imported (`{'`, `'.join(OURS)}`)",
             f"{n['all']} ({', '.join(str(n[p]) for p in OURS)})"),
            ("their import, CPU, alone", f"{1e3 * cpu['ours']:.1f} ms"),
            (f"... as a ratio to numpy's import (CPU, {1e3 * cpu['numpy']:.0f} ms)",
             f"{ratio:.2f}"),
            ("`-X importtime` self times, sum of per-module bests: "
             + " / ".join(f"`{p}`" for p in OURS),
             " / ".join(f"{1e3 * per[p]:.1f}" for p in OURS) + " ms"),
            ("... ours together, as a ratio to numpy's self times",
             f"{per['ours'] / per['numpy']:.2f}"),
            ("scene read and build alone, CPU (ratio)",
             f"{1e3 * cpu['scene']:.1f} ms ({cpu['scene'] / cpu['numpy']:.2f})")]
    lines = [f"| {data['scene']} | measured |", "|---|---|"]
    return "\n".join(lines + [f"| {a} | {b} |" for a, b in rows])


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scene", default="cases/three_mass.toml")
    p.add_argument("--variant", default="f100")
    p.add_argument("--repeat", type=int, default=5)
    p.add_argument("--out", default=None, help="write DIR/startup.json")
    p.add_argument("--table", metavar="DIR", help="print the table of a finished run")
    args = p.parse_args(argv)
    if args.table:
        with open(os.path.join(args.table, "startup.json"), encoding="utf-8") as fh:
            print(table(json.load(fh)))
        return
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, Python "
          f"{platform.python_version()}, {platform.system()} {platform.release()}, load average "
          f"{os.getloadavg()[0]:.1f}")
    with tempfile.TemporaryDirectory() as tmp:
        runs = [import_times(args.scene, args.variant, tmp) for _ in range(args.repeat + 1)][1:]
    imp = best([group_sums(r) for r in runs])
    per_module = group_sums({m: min(r.get(m, math.inf) for r in runs) for m in runs[0]})
    cold = best([scene_times(args.scene, args.variant) for _ in range(args.repeat + 1)][1:])
    ours, others = _run(MODULES.replace("OURS", repr(OURS)), args.scene,
                        args.variant or "").splitlines()
    alone = best([scene_times(args.scene, args.variant, ours, others.split())
                  for _ in range(args.repeat)])
    print(f"`cosim run {args.scene} --variant {args.variant}`, best of {args.repeat}")
    print(f"{'self import time of':<24}{'best sum [ms]':>14}{'/ numpy':>9}"
          f"{'sum of bests [ms]':>19}{'/ numpy':>9}")
    labels = {"ours": "  ours together", "other": "other (stdlib, ...)", "all": "everything"}
    for g in GROUPS:
        print(f"{labels.get(g, g):<24}{1e3 * imp[g]:>14.1f}{imp[g] / imp['numpy']:>9.2f}"
              f"{1e3 * per_module[g]:>19.1f}{per_module[g] / per_module['numpy']:>9.2f}")
    loaded = [m for m in runs[0] if group(m) in OURS]
    print(f"our modules imported: {len(loaded)} (" + ", ".join(
        f"{p} {sum(group(m) == p for m in loaded)}" for p in OURS) + ")")
    numpy_own = set(_run("import sys, numpy; print(*sys.modules)").split())
    beyond = {m: min(r.get(m, math.inf) for r in runs) for m in runs[0]
              if group(m) == "other" and m not in numpy_own and m != NUMPY_CUMULATIVE}
    print(f"other modules that numpy does not import itself: {len(beyond)}, "
          f"{1e3 * sum(beyond.values()):.1f} ms (sum of bests; largest: " + ", ".join(
              f"{m} {1e3 * t:.1f}" for m, t in sorted(beyond.items(), key=lambda kv: -kv[1])[:4])
          + ")")
    cum, ours_best = imp[NUMPY_CUMULATIVE], per_module["ours"]
    print(f"numpy with what it imports (cumulative): {1e3 * cum:.1f} ms; ours (sum of bests) "
          f"/ that = {ours_best / cum:.2f}")
    print(f"{'in process':<34}{'wall [ms]':>10}{'/ numpy':>9}{'CPU [ms]':>10}{'/ numpy':>9}")
    rows = [("import numpy", cold["numpy"]),
            ("import cosim.scene.run, cosim.scene.load", cold["import"]),
            ("import cosim.sides._multibody_step", cold["extension"]),
            ("load_scene, with its imports", cold["load"]),
            ("build_system, with its imports", cold["build"]),
            ("our modules alone", alone["ours"]),
            ("load_scene alone", alone["load"]),
            ("build_system alone", alone["build"]),
            ("scene read and build alone", [a + b for a, b in zip(alone["load"], alone["build"])])]
    for label, (wall, cpu) in rows:
        print(f"{label:<34}{1e3 * wall:>10.1f}{wall / cold['numpy'][0]:>9.2f}"
              f"{1e3 * cpu:>10.1f}{cpu / cold['numpy'][1]:>9.2f}")
    if args.out:
        from cosim.io.rundir import OutputFolder
        data = {"machine": f"{platform.machine()}, {os.cpu_count()} cores, Python "
                           f"{platform.python_version()}, {platform.system()} {platform.release()}",
                "date": datetime.date.today().isoformat(), "load_average": os.getloadavg()[0],
                "repeat": args.repeat,
                "scene": args.scene.rsplit("/", 1)[-1].removesuffix(".toml")
                + (f" {args.variant}" if args.variant else ""),
                "modules": {"all": len(loaded),
                            **{p: sum(group(m) == p for m in loaded) for p in OURS}},
                "self_best_sum_s": imp, "self_sum_of_bests_s": per_module,
                "cpu_s": {"numpy": cold["numpy"][1], "ours": alone["ours"][1],
                          "scene": alone["load"][1] + alone["build"][1]},
                "in_process": {label: v for label, v in rows}}
        with OutputFolder(args.out) as folder:
            folder.write("startup.json", lambda fh: json.dump(data, fh, indent=1), "w")
        print(f"wrote {args.out}/startup.json")


if __name__ == "__main__":
    main()

"""Start-up of `cosim run`: what importing cosim's own modules and reading and
building the scene cost, as ratios to numpy's own import in the same process.

Run from the project root: ``python benchmarks/startup.py [--repeat 5]``.  A
loaded, shared machine makes absolute times noisy; a ratio to numpy, measured in
the same process, travels better between machines and loads.  Each figure is
the best of ``--repeat`` fresh processes, after one that is not counted:
bytecode is cached as users have it (``PYTHONDONTWRITEBYTECODE`` is dropped from
the environment of the runs, and the first run writes the caches).

- *imports*: ``python -X importtime -m cosim.cli run SCENE ...`` as a user types
  it; the self times of every module are summed by top-level package: ours
  (``cosim``, ``multibody``, ``fem``, ``couplers``, each and together), numpy,
  and the rest (the standard library and other packages, whoever asked for them).
- *scene*: in another fresh process, ``time.perf_counter`` around ``import
  numpy``, then around :func:`cosim.load_scene` and
  :func:`cosim.build.build_system` as ``cosim run`` calls them (after ``import
  cosim.run`` and ``cosim.scene``, as the command line does); the first call
  pays for the modules it loads where first needed, and a second call shows the
  rest.
"""
import argparse
import os
import platform
import re
import subprocess
import sys
import tempfile

OURS = ("cosim", "multibody", "fem", "couplers")
_LINE = re.compile(r"import time:\s+(\d+) \|\s+(\d+) \|\s*(\S+)")

TIMING = """
import sys, time
t0 = time.perf_counter()
import numpy
t1 = time.perf_counter()
import cosim.run, cosim.scene
t2 = time.perf_counter()
scene = cosim.load_scene(sys.argv[1], sys.argv[2] or None)
t3 = time.perf_counter()
from cosim.build import build_system
build_system(scene)
t4 = time.perf_counter()
scene = cosim.load_scene(sys.argv[1], sys.argv[2] or None)
t5 = time.perf_counter()
build_system(scene)
t6 = time.perf_counter()
print(t1 - t0, t2 - t1, t3 - t2, t4 - t3, t5 - t4, t6 - t5)
"""
TIMING_KEYS = ("numpy", "import", "load", "build", "load_again", "build_again")
#: the runs' environment: bytecode cached as users have it
ENV = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}


def import_times(scene: str, variant: str | None, out: str) -> dict[str, float]:
    """Self import times [s] summed per group, from one ``-X importtime`` run."""
    argv = [sys.executable, "-X", "importtime", "-m", "cosim.cli", "run", scene, "--out", out,
            "--overwrite", "--quiet"]
    if variant:
        argv += ["--variant", variant]
    proc = subprocess.run(argv, capture_output=True, text=True, env=ENV)
    if proc.returncode != 0:
        raise RuntimeError(f"`cosim run` exited with {proc.returncode}:\n{proc.stderr[-2000:]}")
    sums = dict.fromkeys((*OURS, "ours", "numpy", "other", "all"), 0.0)
    for line in proc.stderr.splitlines():
        m = _LINE.match(line)
        if not m:
            continue
        self_s = int(m[1]) * 1e-6
        top = m[3].split(".")[0]
        group = top if top in OURS or top == "numpy" else "other"
        sums[group] += self_s
        if top in OURS:
            sums["ours"] += self_s
        sums["all"] += self_s
    return sums


def scene_times(scene: str, variant: str | None) -> dict[str, float]:
    """``import numpy``, ``import cosim.run, cosim.scene``, load and build
    (first and second call) [s], from one fresh process."""
    proc = subprocess.run([sys.executable, "-c", TIMING, scene, variant or ""],
                          capture_output=True, text=True, env=ENV)
    if proc.returncode != 0:
        raise RuntimeError(f"the timing process exited with {proc.returncode}:\n"
                           f"{proc.stderr[-2000:]}")
    return dict(zip(TIMING_KEYS, map(float, proc.stdout.split())))


def best(runs: list[dict]) -> dict[str, float]:
    return {k: min(r[k] for r in runs) for k in runs[0]}


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scene", default="cases/three_mass.toml")
    p.add_argument("--variant", default="f100")
    p.add_argument("--repeat", type=int, default=5)
    args = p.parse_args(argv)
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, Python "
          f"{platform.python_version()}, {platform.system()} {platform.release()}, load average "
          f"{os.getloadavg()[0]:.1f}")
    with tempfile.TemporaryDirectory() as tmp:
        runs = [import_times(args.scene, args.variant, tmp) for _ in range(args.repeat + 1)]
    imp = best(runs[1:])
    sc = best([scene_times(args.scene, args.variant) for _ in range(args.repeat + 1)][1:])
    print(f"`cosim run {args.scene} --variant {args.variant}`, best of {args.repeat}")
    print(f"{'self import time of':<34}{'[ms]':>8}{'/ numpy':>9}")
    for group in (*OURS, "ours", "numpy", "other", "all"):
        label = {"ours": "  ours together", "other": "other (stdlib, ...)",
                 "all": "everything"}.get(group, group)
        print(f"{label:<34}{1e3 * imp[group]:>8.1f}{imp[group] / imp['numpy']:>9.2f}")
    print(f"{'in process (perf_counter)':<34}{'[ms]':>8}{'/ numpy':>9}")
    labels = {"numpy": "import numpy", "import": "import cosim.run, cosim.scene",
              "load": "load_scene", "build": "build_system (with its imports)",
              "load_again": "load_scene, second call", "build_again": "build_system, second call"}
    for key in TIMING_KEYS:
        print(f"{labels[key]:<34}{1e3 * sc[key]:>8.1f}{sc[key] / sc['numpy']:>9.2f}")
    first = sc["load"] + sc["build"]
    print(f"{'scene read and build, first call':<34}{1e3 * first:>8.1f}{first / sc['numpy']:>9.2f}")


if __name__ == "__main__":
    main()

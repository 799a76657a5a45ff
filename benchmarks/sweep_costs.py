"""What the chain-mass sweep of docs/sweeps.md costs, one way after another,
from one run (the page's paragraph "Measured ...").

Run from the project root::

    python benchmarks/sweep_costs.py [--out DIR]

It runs ``cosim sweep cases/three_mass.toml --variants ms0.05,...,ms6.4`` as
a user types it, each in a fresh process whose CPU (user + sys, children
included: ``os.wait4``) is read from the kernel: on one process
(``--workers 1``), on a pool of two (``--workers 2``), on a local Dask
cluster (``--scheduler local``, needs the ``dask`` extra; left out without
it), and again into the pool's folder, which reads the points back; it
records whether the three tables (``sweep.csv``) are the same but for
``cpu_time_s`` (``tables_identical``).  Beside
them: the sum of the runs' own ``cpu_time_s`` (from ``sweep.csv``) and the
CPU of importing what a pool's process imports
(``python -c "import cosim.studies.sweep, cosim.scene.run"``, best of 3).
With ``--out DIR`` it writes ``DIR/sweep_costs.json`` through cosim's checked
writer; the published run is in ``benchmarks/results/sweep_costs``.
"""
import argparse
import csv
import datetime
import json
import os
import platform
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
VARIANTS = "ms0.05,ms0.1,ms0.2,ms0.4,ms0.8,ms1.6,ms3.2,ms6.4"


def _cpu(argv, env) -> float:
    """CPU [s] (user + sys, the process and its children) of ``argv``."""
    proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            env=env, cwd=ROOT)
    _, status, usage = os.wait4(proc.pid, 0)
    code = os.waitstatus_to_exitcode(status)
    if code != 0:
        raise RuntimeError(f"{' '.join(argv)} exited {code}")
    return usage.ru_utime + usage.ru_stime


def _table(path) -> list[dict]:
    """``sweep.csv``'s rows without ``cpu_time_s`` (the machine's)."""
    with open(path, newline="") as fh:
        return [{k: v for k, v in r.items() if k != "cpu_time_s"} for r in csv.DictReader(fh)]


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default=None, help="write DIR/sweep_costs.json")
    args = p.parse_args()
    env = dict(os.environ)
    src = str(ROOT / "src")
    env["PYTHONPATH"] = src + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    sweep = [sys.executable, "-m", "cosim.cli", "sweep", "cases/three_mass.toml",
             "--variants", VARIANTS, "--no-plot"]
    data = {"machine": f"{platform.machine()}, {os.cpu_count()} cores, Python "
                       f"{platform.python_version()}, {platform.system()} {platform.release()}",
            "date": datetime.date.today().isoformat(), "load_average": os.getloadavg()[0],
            "points": len(VARIANTS.split(",")), "cpu_s": {}}
    cpu = data["cpu_s"]
    with tempfile.TemporaryDirectory() as tmp:
        cpu["one_process"] = _cpu(sweep + ["--workers", "1", "--out", f"{tmp}/one"], env)
        cpu["pool_2"] = _cpu(sweep + ["--workers", "2", "--out", f"{tmp}/pool"], env)
        with open(f"{tmp}/pool/sweep.csv", newline="") as fh:
            rows = list(csv.DictReader(fh))
        cpu["runs"] = sum(float(r["cpu_time_s"]) for r in rows)
        data["finished"] = sum(r["status"] == "finished" for r in rows)
        try:
            import dask.distributed  # noqa: F401
            cpu["dask_local"] = _cpu(sweep + ["--workers", "2", "--scheduler", "local",
                                              "--out", f"{tmp}/dask"], env)
        except ImportError:
            cpu["dask_local"] = None
        tables = [_table(f"{tmp}/{d}/sweep.csv") for d in ("one", "pool", "dask")
                  if os.path.exists(f"{tmp}/{d}/sweep.csv")]
        data["tables_identical"] = all(t == tables[0] for t in tables[1:])
        data["tables_compared"] = len(tables)
        cpu["read_back"] = _cpu(sweep + ["--workers", "2", "--out", f"{tmp}/pool"], env)
    cpu["import"] = min(_cpu([sys.executable, "-c", "import cosim.studies.sweep, "
                                                    "cosim.scene.run"], env) for _ in range(3))
    print(json.dumps(data, indent=1))
    if args.out:
        from cosim.io.rundir import OutputFolder
        with OutputFolder(args.out) as folder:
            folder.write("sweep_costs.json", lambda fh: json.dump(data, fh, indent=1), "w")
        print(f"wrote {args.out}/sweep_costs.json")


if __name__ == "__main__":
    main()

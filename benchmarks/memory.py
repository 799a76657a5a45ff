"""Peak memory of a run against its simulated length (beam_impact, 1 s and 10 s).

Run from the project root: ``python benchmarks/memory.py [--out DIR]``.
Each run is a fresh process; its peak resident set size comes from
``os.wait4`` (the kernel's ``ru_maxrss`` of that child alone).  Three ways of
running:

- ``cosim run --out DIR --no-estimate``: the series are streamed to disk in
  chunks, so the peak does not grow with the simulated time;
- ``cosim run --out DIR``: the same, and then the error estimate's companion
  run, whose series stay in memory (it is compared with the run's samples), so
  the peak grows with the simulated time;
- ``cosim.simulate(scene)`` without an output directory: the series stay in
  memory (the Python API's default), so the peak grows with the samples kept.

It prints the machine it ran on, and per run the simulated time, the samples
written, the size of ``series.npz``, the process CPU and the peak RSS; with
``--out DIR`` it writes the same as ``DIR/memory.json`` (through cosim's
checked writer).  ``--table DIR`` prints the Markdown table of such a run as
docs/performance.md shows it (the published run is in
``benchmarks/results/memory``).
"""
import argparse
import datetime
import json
import os
import platform
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
SCENE = ROOT / "cases" / "beam_impact.toml"

_IN_MEMORY = """
import sys, warnings
import cosim
scene = cosim.load_scene(sys.argv[1], overrides=[f"t_end={sys.argv[2]}"])
res = cosim.simulate(scene, estimate=False)
print(len(res.t))
"""


def _measure(cmd, env) -> tuple[float, float, str]:
    """Run ``cmd``; return its peak RSS [MiB], CPU (user + sys) [s] and stdout."""
    with tempfile.TemporaryFile("w+") as out:
        proc = subprocess.Popen(cmd, stdout=out, stderr=subprocess.DEVNULL, env=env, cwd=ROOT)
        _, status, usage = os.wait4(proc.pid, 0)
        proc.returncode = os.waitstatus_to_exitcode(status)
        if proc.returncode != 0:
            raise RuntimeError(f"{' '.join(map(str, cmd))} exited {proc.returncode}")
        out.seek(0)
        text = out.read()
    scale = 1024 if sys.platform != "darwin" else 1      # ru_maxrss: KB on Linux
    return usage.ru_maxrss * scale / 2**20, usage.ru_utime + usage.ru_stime, text


MODES = {"streamed": "`cosim run --out --no-estimate` (series streamed)",
         "estimate": "`cosim run --out` (streamed, then the estimate's companion in memory)",
         "memory": "`cosim.simulate` (series in memory)"}


def table(data: dict) -> str:
    """The Markdown table of a run's ``memory.json``."""
    lines = ["| beam_impact | simulated [s] | samples | `series.npz` [MiB] | CPU [s] "
             "| peak RSS [MiB] |", "|---|---|---|---|---|---|"]
    for r in data["rows"]:
        size = "" if r["series_mib"] is None else f"{r['series_mib']:.1f}"
        lines.append(f"| {MODES[r['mode']]} | {r['t_end']:g} | {r['samples']} | {size} "
                     f"| {r['cpu_s']:.1f} | {r['peak_rss_mib']:.1f} |")
    return "\n".join(lines)


def _streamed(t_end, env, estimate: bool) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "run"
        rss, cpu, _ = _measure([sys.executable, "-m", "cosim.cli", "run", str(SCENE),
                                "--set", f"t_end={t_end}", "--out", str(out), "--quiet"]
                               + ([] if estimate else ["--no-estimate"]), env)
        with zipfile.ZipFile(out / "series.npz") as zf:
            size = sum(i.file_size for i in zf.infolist())
        with np.load(out / "series.npz") as npz:
            n = len(npz["t"])
    return {"mode": "estimate" if estimate else "streamed", "t_end": t_end, "samples": n,
            "series_mib": size / 2**20, "cpu_s": cpu, "peak_rss_mib": rss}


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--t-end", type=float, nargs="+", default=[1.0, 10.0],
                   help="simulated times [s] (default 1 10)")
    p.add_argument("--no-memory-mode", action="store_true",
                   help="skip the in-memory runs (cosim.simulate without an output directory)")
    p.add_argument("--out", default=None, help="write DIR/memory.json")
    p.add_argument("--table", metavar="DIR", help="print the table of a finished run")
    args = p.parse_args()
    if args.table:
        print(table(json.loads((Path(args.table) / "memory.json").read_text())))
        return
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1")
    src = str(ROOT / "src")
    env["PYTHONPATH"] = src + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    machine = (f"{platform.machine()} {platform.processor() or ''}".rstrip()
               + f", {os.cpu_count()} cores, Python {platform.python_version()}, "
               f"{platform.system()} {platform.release()}, numpy {np.__version__}")
    data = {"machine": machine, "date": datetime.date.today().isoformat(),
            "load_average": os.getloadavg()[0], "scene": "cases/beam_impact.toml",
            "blas_threads": 1, "rows": []}
    print(f"machine: {machine}")
    print(f"scene: {SCENE.relative_to(ROOT)} (default scheme)")
    print(f"{'mode':<26}{'simulated [s]':>14}{'samples':>9}{'series.npz [MiB]':>17}"
          f"{'CPU [s]':>9}{'peak RSS [MiB]':>15}")
    for t_end in args.t_end:
        rows = [_streamed(t_end, env, False), _streamed(t_end, env, True)]
        if not args.no_memory_mode:
            rss, cpu, text = _measure([sys.executable, "-c", _IN_MEMORY, str(SCENE),
                                       str(t_end)], env)
            rows.append({"mode": "memory", "t_end": t_end, "samples": int(text.split()[-1]),
                         "series_mib": None, "cpu_s": cpu, "peak_rss_mib": rss})
        for r in rows:
            size = "-" if r["series_mib"] is None else f"{r['series_mib']:.2f}"
            print(f"{r['mode']:<26}{t_end:>14.3g}{r['samples']:>9}{size:>17}"
                  f"{r['cpu_s']:>9.1f}{r['peak_rss_mib']:>15.1f}", flush=True)
        data["rows"] += rows
    data["rows"].sort(key=lambda r: (list(MODES).index(r["mode"]), r["t_end"]))
    if args.out:
        from cosim.io.rundir import OutputFolder
        with OutputFolder(args.out) as folder:
            folder.write("memory.json", lambda fh: json.dump(data, fh, indent=1), "w")
        print(f"wrote {args.out}/memory.json")


if __name__ == "__main__":
    main()

"""Peak memory of a run against its simulated length (beam_impact, 1 s and 10 s).

Run from the project root: ``python benchmarks/memory.py``.  Each run is a
fresh process; its peak resident set size comes from ``os.wait4`` (the
kernel's ``ru_maxrss`` of that child alone).  Two ways of running:

- ``cosim run --out DIR``: the series are streamed to disk in chunks, so the
  peak should not grow with the simulated time;
- ``cosim.simulate(scene)`` without an output directory: the series stay in
  memory (the Python API's default), so the peak grows with the samples kept.

It prints the machine it ran on, and per run the simulated time, the samples
written, the size of ``series.npz``, the process CPU and the peak RSS.
"""
import argparse
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


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--t-end", type=float, nargs="+", default=[1.0, 10.0],
                   help="simulated times [s] (default 1 10)")
    p.add_argument("--no-memory-mode", action="store_true",
                   help="skip the in-memory runs (cosim.simulate without an output directory)")
    args = p.parse_args()
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1")
    src = str(ROOT / "src")
    env["PYTHONPATH"] = src + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    print(f"machine: {platform.machine()} {platform.processor() or ''}".rstrip()
          + f", {os.cpu_count()} cores, Python {platform.python_version()}, "
          f"{platform.system()} {platform.release()}, numpy {np.__version__}")
    print(f"scene: {SCENE.relative_to(ROOT)} (default scheme)")
    print(f"{'mode':<26}{'simulated [s]':>14}{'samples':>9}{'series.npz [MiB]':>17}"
          f"{'CPU [s]':>9}{'peak RSS [MiB]':>15}")
    for t_end in args.t_end:
        with tempfile.TemporaryDirectory() as tmp:
            out = Path(tmp) / "run"
            rss, cpu, _ = _measure([sys.executable, "-m", "cosim.cli", "run", str(SCENE),
                                    "--set", f"t_end={t_end}", "--out", str(out), "--quiet"],
                                   env)
            with zipfile.ZipFile(out / "series.npz") as zf:
                size = sum(i.file_size for i in zf.infolist())
            with np.load(out / "series.npz") as npz:
                n = len(npz["t"])
        print(f"{'cosim run --out (streamed)':<26}{t_end:>14.3g}{n:>9}{size / 2**20:>17.2f}"
              f"{cpu:>9.1f}{rss:>15.1f}", flush=True)
        if not args.no_memory_mode:
            rss, cpu, text = _measure([sys.executable, "-c", _IN_MEMORY, str(SCENE),
                                       str(t_end)], env)
            print(f"{'simulate() in memory':<26}{t_end:>14.3g}{int(text.split()[-1]):>9}"
                  f"{'-':>17}{cpu:>9.1f}{rss:>15.1f}", flush=True)


if __name__ == "__main__":
    main()

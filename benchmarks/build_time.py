"""What compiling cosim's extensions costs (the README's install paragraph).

Run from the project root: ``python benchmarks/build_time.py [--out DIR]``.
It copies the sources (``src/`` without built files, ``setup.py``,
``pyproject.toml``, ``MANIFEST.in``, ``README.md``) to a temporary folder and
runs ``python setup.py build_ext --inplace`` there, as ``pip install`` builds
them (Cython, then one C compiler per core), in a fresh process whose CPU
(user + sys, the compilers included: ``os.wait4``) and wall time it prints
with the number of extensions built.  With ``--out DIR`` it writes
``DIR/build.json`` through cosim's checked writer; the published run is in
``benchmarks/results/compile``.  The checkout's own built files are not touched.
"""
import argparse
import datetime
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
FILES = ("setup.py", "pyproject.toml", "MANIFEST.in", "README.md")


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default=None, help="write DIR/build.json")
    args = p.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        shutil.copytree(ROOT / "src", Path(tmp) / "src",
                        ignore=shutil.ignore_patterns("*.so", "*.c", "__pycache__", "*.egg-info"))
        for name in FILES:
            shutil.copy2(ROOT / name, Path(tmp) / name)
        pyx = sorted(str(q.relative_to(tmp)) for q in Path(tmp, "src").rglob("*.pyx"))
        start = time.perf_counter()
        proc = subprocess.Popen([sys.executable, "setup.py", "build_ext", "--inplace"], cwd=tmp,
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - start
        if os.waitstatus_to_exitcode(status) != 0:
            raise RuntimeError("setup.py build_ext failed")
        built = sorted(str(q.relative_to(tmp)) for q in Path(tmp, "src").rglob("*.so"))
    data = {"machine": f"{platform.machine()}, {os.cpu_count()} cores, Python "
                       f"{platform.python_version()}, {platform.system()} {platform.release()}",
            "date": datetime.date.today().isoformat(), "load_average": os.getloadavg()[0],
            "pyx": pyx, "built": built, "cpu_s": usage.ru_utime + usage.ru_stime,
            "wall_s": wall}
    print(json.dumps(data, indent=1))
    if args.out:
        from cosim.io.rundir import OutputFolder
        with OutputFolder(args.out) as folder:
            folder.write("build.json", lambda fh: json.dump(data, fh, indent=1), "w")
        print(f"wrote {args.out}/build.json")


if __name__ == "__main__":
    main()

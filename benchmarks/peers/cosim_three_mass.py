"""Scene 5 (three_mass) as cosim runs it: exactly ``cosim run`` in this process.

Run: ``python benchmarks/peers/cosim_three_mass.py --out DIR [--variant f100]
[--t-end T] [-- EXTRA ...]``.  Everything after ``--`` goes to ``cosim run``
unchanged (``--scheme monolithic --set scheme.monolithic.method="RK45" ...``
gives the paper's method).  After the run's own summary it prints one JSON
line: the CPU time of the solve alone (``cpu_time_s`` of ``summary.json``,
``time.process_time`` around the scheme's run) and the run directory, which
holds ``summary.json`` and ``series.npz``.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    extra = []
    if "--" in argv:
        i = argv.index("--")
        argv, extra = argv[:i], argv[i + 1:]
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default=str(Path(__file__).resolve().parents[2] / "cases"
                                           / "three_mass.toml"))
    ap.add_argument("--variant", default="f100")
    ap.add_argument("--t-end", type=float, default=None, help="[s] (default: the scene's)")
    ap.add_argument("--out", required=True)
    a = ap.parse_args(argv)

    from cosim.cli import console

    args = ["run", a.scene, "--variant", a.variant, "--out", a.out, "--quiet", "--overwrite"]
    if a.t_end:
        args += ["--set", f"t_end={a.t_end!r}"]
    # the `cosim` command's own entry, which ends the process as the command does
    code = console(args + extra)
    summary = Path(a.out) / "summary.json"
    s = json.loads(summary.read_text()) if summary.exists() else {}
    print(json.dumps({"peer": "cosim", "success": code == 0 and s.get("status") == "finished",
                      "solve_cpu_s": s.get("cpu_time_s"), "steps": s.get("macro_steps"),
                      "t_end": s.get("t_end"), "scheme": s.get("scheme"), "run_dir": a.out}))
    return code


if __name__ == "__main__":
    sys.exit(main())

"""Scene 5 side by side: cosim, Exudyn, MuJoCo and the paper's RK45, from one run.

Run from the project root::

    python benchmarks/peers/run.py [--repeat N] [--quick]
                                   [--peers cosim,exudyn,mujoco,paper_rk45] [--out DIR]

It prints the machine, then one row per peer on three_mass f100 (m_s =
0.15 kg, 0.25 s):

- ``solve_cpu_s``: CPU of the solve alone, measured inside the peer's own
  process (``time.process_time`` around the solver call);
- ``process_cpu_s``: CPU of the whole process, user + sys of the child
  (``resource.getrusage(RUSAGE_CHILDREN)`` before and after), interpreter
  start, imports, model building and writing the series included;

each the best of ``--repeat`` runs (default 5; bytecode is cached as users
have it, the first run writing the caches), and the three errors of C
against the bench's reference (:func:`cosim.studies.bench.reference`, the fine
monolithic DOP853 run, cached in ``runs/.bench-cache``): the count of C's
contacts (absolute difference), C's peak penetration (relative; at the
run's own samples, and between them on the cubic Hermite interpolant of
the penetration and its rate) and the arm joint's exit velocity at C's last
release (relative).  A run meets the 1 % criterion when the count is exact
and both peak errors and the exit-velocity error are within 1 %.

The peers are small scripts run as subprocesses, each printing a JSON line:

- ``cosim``: ``cosim run cases/three_mass.toml --variant f100`` with the
  scene's default scheme (``cosim_three_mass.py``);
- ``paper_rk45``: the same command with the monolithic scheme under the
  Dormand-Prince 5(4) pair (RK45; cosim's own, :mod:`cosim.core.embedded_rk`,
  since issue 39; scipy's before), max step 1e-4 s, rtol 1e-4, atol 1e-6 (the bench's ``paper_rk45``
  row, :data:`cosim.studies.bench.PAPER_RK45`);
- ``exudyn``: this directory's own Exudyn model (``exudyn_three_mass.py``),
  which needs ``pip install ".[peers]"``; it is left out, with a note, when
  exudyn is not installed;
- ``mujoco``: this directory's own MuJoCo model (``mujoco_three_mass.py``),
  semi-implicit Euler at 2.5e-5 s by MuJoCo's rollout; the same extra, the
  same note when mujoco is not installed.

``--spread N`` adds N runs of the Exudyn model per largest step of
``--exudyn-steps``, the robot lifted by k x 1e-15 m (k = 0 .. N-1): the
physics is the same, the adaptive step sequence is not, and the table shows
how far the errors move with it.

``--mujoco-steps H1,H2,...`` runs the MuJoCo model once at each fixed step
h of the list with each integrator of ``--mujoco-integrators`` (default
Euler and RK4) and tabulates its errors and solve CPU (the best of
``--repeat`` runs), and marks the cheapest setting that meets 1 % with
every smaller step of its integrator too (:func:`cheapest`): how the MuJoCo
row's setting was chosen.

``--quick`` ends every run and the reference at 0.106 s (C's first two
contacts) and repeats once: a check that everything runs, not a benchmark.
The table goes to ``DIR/peers.csv``, ``DIR/peers.md`` and ``DIR/peers.json``
(default ``runs/peers``).
"""
from __future__ import annotations

import argparse
import csv
import json
import math
import os
import platform
import resource
import subprocess
import sys
import tempfile
import tomllib
from pathlib import Path

import numpy as np

from cosim.io.rundir import OutputFolder

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
SCENE = ROOT / "cases" / "three_mass.toml"
VARIANT = "f100"
CONTACT = "C"
JOINT = "robot/arm"
#: end time of ``--quick`` [s]: C's first two contacts, both released
QUICK_T_END = 0.106
PEERS = ("cosim", "exudyn", "mujoco", "paper_rk45")
#: the peers that are our own models in another package, the package's name
PACKAGES = {"exudyn": "exudyn", "mujoco": "mujoco"}
#: the round-off-sized lift of the robot between the Exudyn runs of ``--spread`` [m]
LIFT = 1e-15
COLUMNS = ("peer", "method", "solve_cpu_s", "process_cpu_s", "repeat", "steps", "count",
           "err_count", "err_peak_steps", "err_peak_interp", "err_exit_velocity", "meets_1pc",
           "status")


# --- metrics of a series -----------------------------------------------------------------

def intervals(t, penetration) -> list[list[float]]:
    """Contact intervals [s] of a penetration series sampled at a run's own
    steps: where it is positive, each edge placed where the straight line
    between the two samples around it crosses zero.  A contact open at the
    first sample starts there; one open at the last ends there."""
    t, p = np.asarray(t, float), np.asarray(penetration, float)
    inside = p > 0
    out, start = [], (t[0] if inside[0] else None)
    for i in np.flatnonzero(inside[1:] != inside[:-1]):
        tc = t[i] + (t[i + 1] - t[i]) * p[i] / (p[i] - p[i + 1])
        if inside[i + 1]:
            start = tc
        else:
            out.append([float(start), float(tc)])
            start = None
    if start is not None:
        out.append([float(start), float(t[-1])])
    return out


def hermite_peak(t, penetration, rate) -> float:
    """Largest penetration [m] on the cubic Hermite interpolant of the
    penetration and its rate between consecutive samples (0 if it never
    penetrates)."""
    from cosim.core.recorder import hermite_cubic_max

    t, p, v = (np.asarray(a, float) for a in (t, penetration, rate))
    peak = max(float(p.max()), 0.0)
    for i in np.flatnonzero((p[:-1] > 0) | (p[1:] > 0)):
        if v[i] > 0 >= v[i + 1] and t[i + 1] > t[i]:
            peak = max(peak, hermite_cubic_max(p[i], v[i], p[i + 1], v[i + 1],
                                               t[i + 1] - t[i])[0])
    return peak


def series_metrics(s) -> dict:
    """C's count, peak penetration (at the samples and interpolated) and the
    arm's exit velocity, from a series with ``t``, ``gap/C``,
    ``gap_rate/C`` and ``dq/robot/arm`` (an Exudyn run's)."""
    from cosim.studies.metrics import exit_velocity

    t = s["t"]
    p, v = -np.asarray(s[f"gap/{CONTACT}"]), -np.asarray(s[f"gap_rate/{CONTACT}"])
    iv = intervals(t, p)
    ev = math.nan
    if iv and iv[-1][1] < t[-1]:
        ev = exit_velocity(t, s[f"dq/{JOINT}"], iv[-1][1])
    return {"count": len(iv), "peak_steps": max(float(p.max()), 0.0),
            "peak": hermite_peak(t, p, v), "exit_velocity": ev}


def run_dir_metrics(run_dir) -> dict:
    """The same from a cosim run directory: count, intervals and the
    (interpolated or located) peak from ``summary.json``, the peak at the
    recorded samples from ``series.npz``, the exit velocity as
    :func:`cosim.studies.metrics.impact_metrics` takes it."""
    from cosim.studies.metrics import exit_velocity

    run_dir = Path(run_dir)
    c = json.loads((run_dir / "summary.json").read_text())["contacts"][CONTACT]
    with np.load(run_dir / "series.npz") as z:
        t, gap, dq = z["t"], z[f"gap/{CONTACT}"], z[f"dq/{JOINT}"]
    ev = math.nan
    if c["intervals"] and c["intervals"][-1][1] < t[-1]:
        ev = exit_velocity(t, dq, c["intervals"][-1][1])
    return {"count": int(c["count"]), "peak_steps": max(float(-gap.min()), 0.0),
            "peak": float(c["peak_penetration"]), "exit_velocity": ev}


def errors(m: dict, ref: dict) -> dict:
    """Errors of a run's metrics against the reference's."""
    def rel(value, key):
        return abs(value - ref[key]) / abs(ref[key]) if ref[key] else math.nan
    e = {"err_count": abs(m["count"] - ref["count"]),
         "err_peak_steps": rel(m["peak_steps"], "peak"),
         "err_peak_interp": rel(m["peak"], "peak"),
         "err_exit_velocity": rel(m["exit_velocity"], "exit_velocity")}
    e["meets_1pc"] = bool(e["err_count"] == 0 and max(e["err_peak_steps"], e["err_peak_interp"],
                                                      e["err_exit_velocity"]) <= 0.01)
    return e


# --- running the peers --------------------------------------------------------------------

def machine() -> dict:
    """What the numbers were measured on."""
    model = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    versions = {}
    for mod in ("numpy", "scipy", "exudyn", "mujoco"):
        try:
            versions[mod] = __import__(mod).__version__
        except ImportError:
            pass
    load = os.getloadavg() if hasattr(os, "getloadavg") else None
    return {"cpu": model, "cores": os.cpu_count(), "system": platform.platform(),
            "python": platform.python_version(), "versions": versions,
            "load_average_1min": None if load is None else round(load[0], 2)}


def paper_args() -> list[str]:
    """``cosim run`` options of the paper's method (the bench's row)."""
    from cosim.studies.bench import PAPER_RK45

    out = ["--scheme", "monolithic"]
    for k, v in PAPER_RK45.items():
        out += ["--set", f"scheme.monolithic.{k}={json.dumps(v)}"]
    return out


def command(peer: str, out: Path, t_end: float | None, extra=()) -> list[str]:
    end = ["--t-end", repr(t_end)] if t_end else []
    if peer in PACKAGES:
        return [sys.executable, str(HERE / f"{peer}_three_mass.py"), "--scene", str(SCENE),
                "--variant", VARIANT, "--out", str(out)] + end + list(extra)
    cmd = [sys.executable, str(HERE / "cosim_three_mass.py"), "--scene", str(SCENE),
           "--variant", VARIANT, "--out", str(out)] + end
    return cmd + (["--"] + paper_args() if peer == "paper_rk45" else [])


def run_once(cmd: list[str]) -> tuple[dict, float]:
    """Run a peer; its JSON line and the CPU (user + sys) of its process."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    # bytecode cached as users have it (as benchmarks/startup.py runs): with
    # PYTHONDONTWRITEBYTECODE set, a peer whose cache is stale would compile its
    # modules again in every run and be charged for it; the first run writes the caches
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("{")]
    if not lines:
        raise RuntimeError(f"`{' '.join(cmd)}` printed no JSON line (exit {proc.returncode}):\n"
                           f"{proc.stderr[-2000:]}")
    return json.loads(lines[-1]), cpu


def method(peer: str, info: dict) -> str:
    """A row's method, from its peer's JSON line."""
    if peer == "cosim":
        return f"cosim run ({info.get('scheme')})"
    if peer == "exudyn":
        return f"Exudyn {info.get('version')} TrapezoidalIndex2"
    if peer == "mujoco":
        h = info.get("step")
        return (f"MuJoCo {info.get('version')} {info.get('integrator')}"
                + ("" if h is None else f", h = {h:g} s"))
    return "cosim monolithic, RK45"


def measure(peer: str, work: Path, repeat: int, t_end: float | None, ref: dict) -> dict:
    """Best-of-``repeat`` CPU of a peer and the errors of its (last) run."""
    out = work / peer
    solve, whole, info = [], [], {}
    for _ in range(repeat):
        info, cpu = run_once(command(peer, out, t_end))
        whole.append(cpu)
        if info.get("solve_cpu_s") is not None:
            solve.append(float(info["solve_cpu_s"]))
    row = {"peer": peer, "method": method(peer, info),
           "solve_cpu_s": min(solve) if solve else math.nan, "process_cpu_s": min(whole),
           "repeat": repeat,
           # the monolithic scheme reports its segments between events, not RK45's steps
           "steps": None if peer == "paper_rk45" else info.get("steps"),
           "status": "finished" if info.get("success") else "failed"}
    nan = {k: math.nan for k in ("err_count", "err_peak_steps", "err_peak_interp",
                                 "err_exit_velocity")}
    if not info.get("success"):
        return {**row, "count": math.nan, **nan, "meets_1pc": False}
    if peer in PACKAGES:
        with np.load(info["series"]) as z:
            m = series_metrics({k: z[k] for k in z.files})
    else:
        m = run_dir_metrics(info["run_dir"])
    return {**row, "count": m["count"], **errors(m, ref)}


def spread(work: Path, steps, n: int, t_end: float | None, ref: dict,
           lift: float = LIFT) -> list[dict]:
    """How much the Exudyn run owes to its step sequence: ``n`` runs per
    largest step h, the robot lifted by 0, ``lift``, 2 ``lift``, ... [m]
    (round-off: the physics does not change, the adaptive steps do)."""
    out = []
    for h in steps:
        runs = []
        for k in range(n):
            info, _ = run_once(command("exudyn", work / "spread", t_end,
                                       ["--step", repr(h), "--lift", repr(k * lift)]))
            if not info.get("success"):
                runs.append(None)
                continue
            with np.load(info["series"]) as z:
                m = series_metrics({key: z[key] for key in z.files})
            runs.append({"solve_cpu_s": info["solve_cpu_s"], "steps": info["steps"],
                         **errors(m, ref)})
        ok = [r for r in runs if r is not None]
        ev = [r["err_exit_velocity"] for r in ok]
        pk = [max(r["err_peak_steps"], r["err_peak_interp"]) for r in ok]
        out.append({"step": h, "runs": n, "failed": n - len(ok),
                    "meets_1pc": sum(r["meets_1pc"] for r in ok),
                    "count_exact": sum(r["err_count"] == 0 for r in ok),
                    "err_exit_velocity_median": float(np.median(ev)) if ev else math.nan,
                    "err_exit_velocity_max": max(ev, default=math.nan),
                    "err_peak_max": max(pk, default=math.nan),
                    "solve_cpu_s_median": float(np.median([r["solve_cpu_s"] for r in ok]))
                    if ok else math.nan,
                    "steps_median": float(np.median([r["steps"] for r in ok])) if ok
                    else math.nan})
    return out


def mujoco_sweep(work: Path, steps, integrators, repeat: int, t_end: float | None,
                 ref: dict) -> list[dict]:
    """The MuJoCo model at each fixed step h of ``steps`` with each of
    ``integrators``: its errors and solve CPU (the best of ``repeat`` runs),
    the setting :func:`cheapest` picks marked ``cheapest``."""
    out = []
    for integrator in integrators:
        for h in steps:
            cpu, info = [], {}
            for _ in range(repeat):
                info, _ = run_once(command("mujoco", work / "sweep", t_end,
                                           ["--step", repr(h), "--integrator", integrator]))
                cpu.append(float(info["solve_cpu_s"]))
            row = {"integrator": integrator, "step": info["step"], "steps": info["steps"],
                   "solve_cpu_s": min(cpu), "repeat": repeat, "cheapest": False}
            if info.get("success"):
                with np.load(info["series"]) as z:
                    m = series_metrics({k: z[k] for k in z.files})
                row.update(count=m["count"], **errors(m, ref))
            else:
                row.update(count=math.nan, err_count=math.nan, err_peak_steps=math.nan,
                           err_peak_interp=math.nan, err_exit_velocity=math.nan,
                           meets_1pc=False)
            out.append(row)
    best = cheapest(out)
    if best is not None:
        best["cheapest"] = True
    return out


def cheapest(rows: list[dict]) -> dict | None:
    """The cheapest (least solve CPU) of the settings that meet 1 % with
    every smaller step of their integrator too: C's count hangs on grazing
    re-contacts, so a step that meets 1 % while a smaller one misses it got
    there by luck and would not survive a change of the scene or the step
    list (None if no setting qualifies)."""
    safe = []
    for integrator in dict.fromkeys(r["integrator"] for r in rows):
        for r in sorted((r for r in rows if r["integrator"] == integrator),
                        key=lambda r: r["step"]):
            if not r["meets_1pc"]:
                break
            safe.append(r)
    return min(safe, key=lambda r: r["solve_cpu_s"], default=None)


def _fmt(v, pct=False) -> str:
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, float):
        if math.isnan(v):
            return "—"
        return f"{100 * v:.2f} %" if pct else f"{v:.3g}"
    return "" if v is None else str(v)


def markdown(rows: list[dict], mach: dict, ref: dict, t_end: float, spreads=(),
             sweep=()) -> str:
    """The table as markdown, with the machine and the reference."""
    head = (f"three_mass {VARIANT}, {t_end:g} s; machine: {mach['cpu']}, {mach['cores']} cores, "
            f"Python {mach['python']}, " + ", ".join(f"{k} {v}" for k, v in
                                                      mach["versions"].items())
            + f"; load average {mach['load_average_1min']}.  Reference (monolithic DOP853, "
            f"rtol 1e-11): C closes {ref['count']} times, peak {ref['peak']:.6g} m, exit "
            f"velocity {ref['exit_velocity']:.6g} rad/s.")
    lines = [head, "",
             "| peer | solve CPU [s] | whole process CPU [s] | steps | C's contacts | "
             "peak error (samples / interpolated) | exit velocity error | within 1 % |",
             "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['method']} | {_fmt(r['solve_cpu_s'])} | {_fmt(r['process_cpu_s'])} "
                     f"| {_fmt(r['steps'])} | {_fmt(r['count'])} | "
                     f"{_fmt(r['err_peak_steps'], True)} / {_fmt(r['err_peak_interp'], True)} | "
                     f"{_fmt(r['err_exit_velocity'], True)} | {_fmt(r['meets_1pc'])} |")
    lines.append("")
    lines.append(f"CPU: best of {rows[0]['repeat'] if rows else 0} runs each.")
    if spreads:
        lines += ["", f"Exudyn's step sequence: {spreads[0]['runs']} runs per largest step h, "
                  f"the robot lifted by k x {LIFT:g} m (k = 0, 1, ...):", "",
                  "| h [s] | runs within 1 % | C's count exact | exit velocity error "
                  "(median / max) | peak error (max) | solve CPU (median) [s] | steps "
                  "(median) |", "|---|---|---|---|---|---|---|"]
        for r in spreads:
            lines.append(f"| {r['step']:g} | {r['meets_1pc']} of {r['runs']} | "
                         f"{r['count_exact']} of {r['runs']} | "
                         f"{_fmt(r['err_exit_velocity_median'], True)} / "
                         f"{_fmt(r['err_exit_velocity_max'], True)} | "
                         f"{_fmt(r['err_peak_max'], True)} | {_fmt(r['solve_cpu_s_median'])} | "
                         f"{r['steps_median']:.0f} |")
    if sweep:
        lines += ["", "MuJoCo's integrators and fixed steps h (solve CPU: best of "
                  f"{sweep[0]['repeat']} runs; * the cheapest within 1 % with every smaller "
                  "step of its integrator):", "",
                  "| integrator | h [s] | steps | solve CPU [s] | C's contacts | peak error "
                  "(samples / interpolated) | exit velocity error | within 1 % |",
                  "|---|---|---|---|---|---|---|---|"]
        for r in sweep:
            lines.append(f"| {r['integrator']} | {r['step']:g} | {r['steps']} | "
                         f"{_fmt(r['solve_cpu_s'])}{' *' if r['cheapest'] else ''} | "
                         f"{_fmt(r['count'])} | {_fmt(r['err_peak_steps'], True)} / "
                         f"{_fmt(r['err_peak_interp'], True)} | "
                         f"{_fmt(r['err_exit_velocity'], True)} | {_fmt(r['meets_1pc'])} |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5, help="runs per peer; the best CPU counts")
    ap.add_argument("--quick", action="store_true",
                    help=f"end at {QUICK_T_END} s and repeat once: a check, not a benchmark")
    ap.add_argument("--peers", default=",".join(PEERS), help="comma-separated subset of "
                    + ", ".join(PEERS))
    ap.add_argument("--out", default=str(ROOT / "runs" / "peers"))
    ap.add_argument("--spread", type=int, default=0, metavar="N",
                    help=f"also run the Exudyn model N times per step of --exudyn-steps, the "
                    f"robot lifted by k x {LIFT:g} m: how much its errors owe to its steps")
    ap.add_argument("--exudyn-steps", default="5e-4",
                    help="largest steps h [s] of --spread, comma-separated (default 5e-4)")
    ap.add_argument("--mujoco-steps", default="",
                    help="fixed steps h [s], comma-separated: also run the MuJoCo model at each "
                    "with each integrator of --mujoco-integrators and tabulate its errors")
    ap.add_argument("--mujoco-integrators", default="Euler,RK4",
                    help="MuJoCo integrators of --mujoco-steps, comma-separated "
                    "(default Euler,RK4)")
    ap.add_argument("--cache-dir", default=str(ROOT / "runs" / ".bench-cache"),
                    help="where the reference is cached")
    a = ap.parse_args(argv)
    peers = [p.strip() for p in a.peers.split(",") if p.strip()]
    unknown = set(peers) - set(PEERS)
    if unknown:
        ap.error(f"unknown peers {sorted(unknown)}; known: {', '.join(PEERS)}")
    if a.repeat < 1:
        ap.error(f"`--repeat` must be >= 1, got {a.repeat}")
    mach = machine()
    print("machine: " + json.dumps(mach))
    for peer, package in PACKAGES.items():
        if package not in mach["versions"] and (peer in peers or (peer == "mujoco"
                                                                  and a.mujoco_steps)):
            print(f"{package} is not installed (pip install \".[peers]\"): its row is left out")
            if peer in peers:
                peers.remove(peer)
    t_end = QUICK_T_END if a.quick else None
    repeat = 1 if a.quick else a.repeat

    from cosim.studies.bench import reference

    ref = reference(SCENE, VARIANT, CONTACT, JOINT,
                    overrides=[f"t_end={t_end!r}"] if t_end else (), cache_dir=a.cache_dir)
    t_show = t_end or float(tomllib.loads(SCENE.read_text())["t_end"])
    print(f"reference: C closes {ref['count']} times, peak {ref['peak']:.6g} m, "
          f"exit velocity {ref['exit_velocity']:.6g} rad/s")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for peer in peers:
            row = measure(peer, Path(tmp), repeat, t_end, ref)
            rows.append(row)
            print(json.dumps(row))
        spreads = []
        if a.spread and "exudyn" in peers:
            steps = [float(v) for v in a.exudyn_steps.split(",") if v.strip()]
            spreads = spread(Path(tmp), steps, a.spread, t_end, ref)
            for r in spreads:
                print(json.dumps(r))
        sweep = []
        if a.mujoco_steps and "mujoco" in mach["versions"]:
            sweep = mujoco_sweep(Path(tmp), [float(v) for v in a.mujoco_steps.split(",")
                                             if v.strip()],
                                 [v.strip() for v in a.mujoco_integrators.split(",") if v.strip()],
                                 repeat, t_end, ref)
            for r in sweep:
                print(json.dumps(r))
    out = Path(a.out)

    def write_rows(fh):
        w = csv.DictWriter(fh, fieldnames=COLUMNS)
        w.writeheader()
        for r in rows:
            w.writerow({k: r.get(k) for k in COLUMNS})
    md = markdown(rows, mach, ref, t_show, spreads, sweep)
    report = {"machine": mach, "reference": ref, "t_end": t_show, "rows": rows,
              "exudyn_spread": spreads, "mujoco_steps": sweep}
    with OutputFolder(out) as folder:       # the checked writer every cosim output uses
        folder.write("peers.csv", write_rows, "w")
        folder.write("peers.md", lambda fh: fh.write(md), "w")
        folder.write("peers.json", lambda fh: json.dump(report, fh, indent=1), "w")
    print()
    print(md, end="")
    print(f"wrote {out / 'peers.csv'}, {out / 'peers.md'} and {out / 'peers.json'}")
    return 0 if all(r["status"] == "finished" for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())

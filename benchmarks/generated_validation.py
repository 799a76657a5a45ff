"""Validate the run's error estimate, `--accuracy` requests and `cosim info`'s
stable steps on generated scenes (:mod:`cosim.studies.generate`), which no
one tuned.

For each of ``--n`` scenes of ``--seed`` (written as ``scenes/NAME.toml``
into ``--out``):

a. **the estimate, the request and their cost**: what
   ``benchmarks/accuracy_validation.py`` does on each shipped scene
   (:func:`accuracy_validation.validate_case`, one repeat): the scene's own
   run and its estimate, ``cosim run --accuracy 1%`` without its folder, and
   the bench rows it is priced against, each against the fine monolithic
   reference (:func:`cosim.studies.bench.reference`: DOP853, rtol 1e-11);
   judged and totalled by that script's rules (its ``totals`` and targets).
b. **the stable step**: ``cosim info``'s printed largest stable macro step
   of each explicit scheme (an exchanged contact) or the host's largest
   stable integrator step (a hosted contact), with the kind info prints
   (``runs`` or ``necessary bound only``; an integrator step is printed
   without one and is held as a step that runs), and a run at 0.9 times it:
   finished, stopped by the guard, or refused (and why).  A step printed as
   ``runs`` (or unmarked) that does not finish fails the claim; a necessary
   bound only does not.

Run from the project root::

    python benchmarks/generated_validation.py --n 40 --out benchmarks/results/generated_validation
    python benchmarks/generated_validation.py --quick --out DIR   # 6 scenes
    python benchmarks/generated_validation.py --table DIR         # tables again, totals recounted

It writes ``DIR/validation.json`` (after each scene) and ``DIR/README.md`` (the
machine, the date, the tables and totals) through cosim's checked writer.
"""
from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import re
import subprocess
import sys
import time
import warnings
from pathlib import Path

#: the accuracy asked (X)
ACCURACY = 0.01
#: estimate over actual within [1 / AGREE, AGREE] agrees
AGREE = 3.0
#: the fraction of the printed stable step the check runs at
STEP_FRACTION = 0.9
QUANTITIES = ("peak", "exit_velocity")
CONTACT = "strike"


def _quiet():
    ctx = warnings.catch_warnings()
    ctx.__enter__()
    warnings.simplefilter("ignore")
    return ctx


def _av():
    """benchmarks/accuracy_validation.py, beside this script."""
    import importlib.util
    path = Path(__file__).with_name("accuracy_validation.py")
    if "accuracy_validation" not in sys.modules:
        spec = importlib.util.spec_from_file_location("accuracy_validation", path)
        mod = importlib.util.module_from_spec(spec)
        sys.modules["accuracy_validation"] = mod
        spec.loader.exec_module(mod)
    return sys.modules["accuracy_validation"]


def judge(est, act, x: float = ACCURACY):
    """Whether an estimate agrees with the actual error (None: nothing to
    judge): :func:`accuracy_validation.agrees`."""
    return _av().agrees(est, act, x)


_NUMBER = r"([0-9.eE+-]+|not limited)(?: \((runs|necessary bound only)\))?"


def info_steps(path) -> dict:
    """``cosim info``'s printed largest stable steps: ``macro`` (scheme ->
    step or None) and ``integrator`` (method -> step or None)."""
    proc = subprocess.run([sys.executable, "-m", "cosim.cli", "info", str(path)],
                          capture_output=True, text=True, timeout=600)
    out = {"macro": {}, "integrator": {}, "kind": {}, "host": None,
           "exit_code": proc.returncode}
    for line in proc.stdout.splitlines():
        for key, head in (("macro", "largest stable macro step [s]:"),
                          ("integrator", "largest stable integrator step [s]:")):
            if head in line:
                for name, v, kind in re.findall(r"(\w+) " + _NUMBER, line.split(":", 1)[1]):
                    out[key][name] = None if v == "not limited" else float(v)
                    if key == "macro" and kind:
                        out["kind"][name] = kind
        m = re.search(r"\(embedded in (\w+)\)", line)
        if m:
            out["host"] = m.group(1)
    return out


def step_checks(path, info: dict, scene_data: dict) -> list[dict]:
    """Runs at STEP_FRACTION times each printed stable step: finished,
    stopped (by the guard) or refused (the pre-flight check or the build)."""
    from cosim.errors import SimulationError, UnsafeStepError
    from cosim.scene.checks import SceneError
    from cosim.scene.load import load_scene
    from cosim.scene.run import simulate
    checks = []
    macro = scene_data["scheme"]["macro_step"]
    for scheme, h in info["macro"].items():
        if h is None:
            continue
        h9 = STEP_FRACTION * h
        checks.append({"what": f"{scheme} macro step", "stable_step": h, "scheme": scheme,
                       "kind": info.get("kind", {}).get(scheme, "unmarked"),
                       "set": [f"scheme.contact_step={h9!r}",
                               f"scheme.macro_step={max(macro, h9)!r}"]})
    for method, h in info["integrator"].items():
        if h is None or info["host"] is None:
            continue
        key = ("subsystems.robot.integrator.max_step" if info["host"] == "robot"
               else "subsystems.target.integrator.contact_step")
        checks.append({"what": f"{info['host']} {method} step", "stable_step": h, "scheme": None,
                       "kind": "unmarked",
                       "set": [f"{key}={STEP_FRACTION * h!r}"]})
    for c in checks:
        ctx = _quiet()
        try:
            res = simulate(load_scene(path, None, c["set"], c["scheme"]))
            c["status"] = res.status
            c["message"] = "" if res.success else res.message
        except (UnsafeStepError, SceneError) as exc:
            c["status"], c["message"] = "refused", str(exc)
        except SimulationError as exc:  # an iteration that did not converge, say
            c["status"], c["message"] = "failed", f"{type(exc).__name__}: {exc}"
        finally:
            ctx.__exit__(None, None, None)
    return checks


def validate(path, cache, request: bool = True) -> dict:
    """One generated scene: the shipped scenes' validation (not with
    ``request`` False: ``--quick``), then info's stable steps run at 0.9x."""
    import tomllib
    data = tomllib.loads(Path(path).read_text())
    c = data["contacts"][CONTACT]
    case = {"scene": Path(path).stem, "description": data["description"],
            "scheme": data["scheme"]["name"], "placement": c["placement"],
            "law": c["law"]["type"], "structure": data["subsystems"]["target"]["type"]}
    if request:
        t0 = time.process_time()
        try:
            case["validation"] = _av().validate_case(str(path), None, CONTACT, cache, 1)
        except Exception as exc:    # one scene's failure does not end the batch: it is said
            case["validation"] = None
            case["error"] = f"{type(exc).__name__}: {exc}"
        case["cpu_s"] = time.process_time() - t0
    else:
        case["validation"] = None
    info = info_steps(path)
    case["info"] = info
    case["at_0.9"] = step_checks(path, info, data)
    return case


def step_fails(s: dict) -> bool:
    """A step info calls one that runs (or prints unmarked) that a run at
    0.9x does not finish."""
    return s["kind"] != "necessary bound only" and s["status"] != "finished"


def totals(cases: list[dict]) -> dict:
    """The shipped scenes' totals over the validated scenes, the scenes that
    could not be validated, and the stable-step checks."""
    done = [c["validation"] for c in cases if c.get("validation")]
    steps = [s for c in cases for s in c["at_0.9"]]
    out = _av().totals(done) if done else {}
    return {**out, "scenes": len(cases), "validated": len(done),
            "errors": sum("error" in c for c in cases),
            "step_checks": len(steps),
            "step_runs": sum(s["kind"] != "necessary bound only" for s in steps),
            "step_runs_finished": sum(s["kind"] != "necessary bound only"
                                      and s["status"] == "finished" for s in steps),
            "step_bound_stopped": sum(s["kind"] == "necessary bound only"
                                      and s["status"] != "finished" for s in steps),
            "step_bound": sum(s["kind"] == "necessary bound only" for s in steps),
            "integrator_steps": sum(s["scheme"] is None for s in steps),
            "integrator_finished": sum(s["scheme"] is None and s["status"] == "finished"
                                       for s in steps)}


def _steps(c) -> str:
    if not c["at_0.9"]:
        return "not limited"
    tag = {"runs": "", "unmarked": "", "necessary bound only": " (bound)"}
    return "; ".join(f"{s['what']} {s['stable_step']:.3g}{tag[s['kind']]}: {s['status']}"
                     + (" ✗" if step_fails(s) else "") for s in c["at_0.9"])


def table(data: dict) -> str:
    av = _av()
    lines = ["| scene | structure, law, placement, scheme | peak: est / actual | "
             "exit: est / actual | 1 %: choice | 1 %: peak | 1 %: exit | 1 % met, outcome | "
             "CPU: own / whole over cheapest | info's stable step: run at 0.9x |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for c in data["cases"]:
        v = c.get("validation")
        head = (f"| {c['scene']} | {c['structure']}, {c['law']}, {c['placement']}, "
                f"{c['scheme']} |")
        if v is None:
            why = c.get("error", "not validated (--quick)")
            lines.append(f"{head} {why} | - | - | - | - | - | - | {_steps(c)} |")
            continue
        d, r = v["default"]["pairs"], v["request"]
        ch = f"{r['scheme']} {r['step']:.3g}" + (" (refined)" if r["refined"] else "")
        lines.append(f"{head} {av._pair(d['peak'])} | {av._pair(d['exit_velocity'])} | {ch} | "
                     f"{av._pair(r['pairs']['peak'])} | "
                     f"{av._pair(r['pairs']['exit_velocity'])} | "
                     f"{'yes' if r['met'] else '**no**'}, {r['outcome']} | "
                     f"{av._x(v['own_ratio'])} / {av._x(v['cpu_ratio'])} | {_steps(c)} |")
    return "\n".join(lines)


def totals_text(data: dict) -> str:
    t = data["totals"]
    out = f"{t['validated']} of {t['scenes']} scenes validated"
    if t["errors"]:
        out += f" ({t['errors']} stopped: said in the table)"
    out += "."
    if t["validated"]:
        out += (f" {t['pairs']} pairs with an actual error ({t['small']} of them below "
                f"X/100, {t['without_estimate']} without an estimate, {t['bounds']} bounds); "
                f"{t['under']} under-estimated past 3x.")
    out += (f" Runs at {STEP_FRACTION}x cosim info's stable step: {t['step_runs_finished']} "
            f"of the {t['step_runs']} steps printed as ones that run (or unmarked) finished "
            f"(the integrator steps, unmarked: {t['integrator_finished']} of "
            f"{t['integrator_steps']}); "
            f"{t['step_bound_stopped']} of the {t['step_bound']} printed as a necessary bound "
            f"only were stopped or refused.")
    out += "\n\n" + (_av().verdicts_text(t, t["validated"]) + "\n" if t["validated"] else "")
    out += (f"- every printed step that runs runs at {STEP_FRACTION}x: "
            f"{t['step_runs_finished']} of {t['step_runs']}, "
            f"**{'met' if t['step_runs_finished'] == t['step_runs'] else 'NOT met'}**")
    return out


def _cpu() -> float:
    """CPU time of this process and its children (`cosim info`) [s]."""
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


def _machine() -> str:
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{cpu}, Python {platform.python_version()}"


def readme(data: dict) -> str:
    return (f"# Validation on generated scenes\n\n`python benchmarks/generated_validation.py "
            f"{data['argv']}`: {data['n']} scenes of seed {data['seed']} "
            f"(`cosim.studies.generate`), run on {data['machine']}, {data['date']}; "
            f"{data['cpu_s']:.0f} s of CPU in all.\n\n{LEGEND}\n\n{table(data)}\n\n"
            f"{totals_text(data)}\n")


LEGEND = (f"Each pair is the estimated / actual relative error (against the monolithic "
          f"reference, DOP853 at rtol 1e-11) of the strike's peak penetration or of the tip "
          f"joint's exit velocity at the strike's last release (≤: the estimate is a bound at "
          f"order 1, its order not confirmed): ✓ when the estimate lies within {AGREE:g}x of "
          f"the actual error, or, where the actual error is below X/100 (X = {ACCURACY:.0%}), "
          f"when the estimate says below X/10; n/r: no estimate. \"1 %\" is `cosim run "
          f"--accuracy 1%` (its choice, its estimate and the actual error; met: both actual "
          f"errors within 1 % and the reference's contact count; the outcome it printed). CPU: "
          f"the request's own run (choice, run, refinement) and the request whole (with its "
          f"estimates) over the cheapest bench row that meets 1 % (process time, one run each, "
          f"each command timed as a new process would run it, the assemblies and modes kept "
          f"by another forgotten, on a shared 2-core machine: noisy). The last column runs "
          f"each stable step `cosim info` prints at {STEP_FRACTION}x: finished, failed (stopped by the run guard) or "
          f"refused (by the pre-flight check or the build); (bound): printed as a necessary "
          f"bound only; ✗: a step printed as one that runs that did not finish.")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, default=40, help="how many scenes")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default="runs/generated-validation")
    ap.add_argument("--cache", default=None, help="the references' cache folder")
    ap.add_argument("--quick", action="store_true",
                    help="6 scenes (unless --n), the stable steps alone")
    ap.add_argument("--table", metavar="DIR",
                    help="print (and rewrite DIR/README.md) the tables of a finished run, "
                         "its totals recounted")
    args = ap.parse_args(argv)
    from cosim.io.rundir import OutputFolder
    if args.table:
        data = json.loads((Path(args.table) / "validation.json").read_text())
        data["totals"] = totals(data["cases"])      # counted again by these rules
        text = readme(data)
        with OutputFolder(args.table) as folder:
            folder.write("validation.json", lambda fh: json.dump(data, fh, indent=1), "w")
            folder.write("README.md", lambda fh: fh.write(text), "w")
        print(text)
        return 0
    from cosim.studies.generate import write_scenes
    given = argv if argv is not None else sys.argv[1:]
    n = 6 if args.quick and "--n" not in given else args.n
    data = {"machine": _machine(), "date": datetime.datetime.now(datetime.timezone.utc)
            .strftime("%Y-%m-%d %H:%M UTC"), "argv": " ".join(given), "n": n,
            "seed": args.seed, "accuracy": ACCURACY, "cases": [], "cpu_s": 0.0}
    t0 = _cpu()
    with OutputFolder(args.out) as folder:
        paths = write_scenes(folder.path / "scenes", n, args.seed)
        with OutputFolder(folder.path / "scenes") as scenes:     # a former run's, gone
            for old in sorted(scenes.path.glob("*.toml")):
                if old not in paths:
                    scenes.remove(old.name)
        for path in paths:
            case = validate(path, args.cache, request=not args.quick)
            data["cases"].append(case)
            data["cpu_s"] = _cpu() - t0
            data["totals"] = totals(data["cases"])
            folder.write("validation.json", lambda fh: json.dump(data, fh, indent=1), "w")
            v = case.get("validation")
            print(f"{case['scene']}: " + (case.get("error", "-") if v is None else
                  f"met {v['request']['met']} {v['request']['outcome']}") +
                  f", {_steps(case)}", flush=True)
        folder.write("README.md", lambda fh: fh.write(readme(data)), "w")
    print(readme(data))
    return 0


if __name__ == "__main__":
    sys.exit(main())

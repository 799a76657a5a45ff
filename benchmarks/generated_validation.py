"""Validate the run's error estimate, `--accuracy` requests and `cosim info`'s
stable steps on generated scenes (:mod:`cosim.studies.generate`), which no
one tuned.

For each of ``--n`` scenes of ``--seed`` (written as ``scenes/NAME.toml``
into ``--out``):

a. **the estimate**: the scene's own run, its error estimated by the
   companion run (:func:`cosim.studies.estimate.estimate_errors`), against
   the fine monolithic reference (:func:`cosim.studies.bench.reference`:
   DOP853, rtol 1e-11): the relative errors of the strike's peak penetration
   and of the tip joint's exit velocity at its last release.  A pair
   *agrees* when the estimate lies within [1/3, 3] times the actual error;
   where the actual error is below X/100 (X the accuracy asked, 1 %), the
   ratio means nothing and the pair agrees when the estimate says below X/10.
b. **the request** (not with ``--quick``): ``cosim run --accuracy 1%``
   without its folder (:class:`cosim.cli.accuracy.Request`: the choice, the
   run, its estimate, one refinement where the estimate misses): its
   estimated and actual errors (judged as in a) and whether 1 % is met.
c. **the stable step**: ``cosim info``'s printed largest stable macro step
   of each explicit scheme (an exchanged contact) or the host's largest
   stable integrator step (a hosted contact), and a run at 0.9 times it:
   finished, stopped by the guard, or refused (and why).

Run from the project root::

    python benchmarks/generated_validation.py --n 40 --out benchmarks/results/generated_validation
    python benchmarks/generated_validation.py --quick --out DIR   # 6 scenes, no requests
    python benchmarks/generated_validation.py --table DIR         # a finished run's tables again

It writes ``DIR/validation.json`` (after each scene) and ``DIR/README.md`` (the
machine, the date, the tables and totals) through cosim's checked writer.
"""
from __future__ import annotations

import argparse
import datetime
import json
import math
import os
import platform
import re
import subprocess
import sys
import time
import warnings
from pathlib import Path
from types import SimpleNamespace

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


def judge(est, act, x: float = ACCURACY):
    """Whether an estimate agrees with the actual error (None: nothing to
    judge).  Below x/100 the actual error is judged on the estimate saying
    below x/10 alone."""
    if est is None or act is None:
        return None
    if act < x / 100:
        return est < x / 10
    if est == 0.0:
        return False
    return 1.0 / AGREE <= est / act <= AGREE


def _finite(v):
    return float(v) if v is not None and math.isfinite(v) else None


def estimated(acc: dict, joint: str) -> dict:
    """The estimate's relative errors: quantity -> (error or None, why)."""
    if CONTACT not in acc.get("contacts", {}):
        why = "; ".join(acc.get("why") or ["no companion"])
        return {q: (None, why) for q in QUANTITIES}
    entries = {"peak": acc["contacts"][CONTACT]["peak_penetration"],
               "exit_velocity": acc["exit"].get(joint, {"why": f"no joint {joint}"})}
    return {q: (e.get("relative_error"), e.get("why", "")) for q, e in entries.items()}


def actual(res, joint: str, ref: dict) -> dict:
    from cosim.studies.metrics import impact_metrics, relative_errors
    m = impact_metrics(res, CONTACT, joint)
    if ref is None:                 # the reference failed: nothing to compare with
        return {"peak": None, "exit_velocity": None, "count": m["count"]}
    e = relative_errors(m, ref)
    return {"peak": _finite(e["peak"]), "exit_velocity": _finite(e["exit_velocity"]),
            "count": m["count"]}


def pairs(est: dict, act: dict) -> dict:
    return {q: {"estimated": est[q][0], "why": est[q][1], "actual": act[q],
                "agrees": judge(est[q][0], act[q])} for q in QUANTITIES}


def own_run(path, joint, ref) -> dict:
    """The scene's run and its estimate, against the reference."""
    from cosim.scene.load import load_scene
    from cosim.scene.run import simulate
    from cosim.studies.estimate import estimate_errors
    ctx = _quiet()
    try:
        scene = load_scene(path)
        t0 = time.process_time()
        try:
            res = simulate(scene)
        except Exception as exc:        # a scene the generator got wrong: said, not fatal
            return {"status": "error", "message": f"{type(exc).__name__}: {exc}",
                    "cpu_s": time.process_time() - t0}
        t1 = time.process_time()
        if not res.success:
            return {"status": res.status, "message": res.message, "cpu_s": t1 - t0}
        acc = estimate_errors(scene, res, contact=CONTACT)
        t2 = time.process_time()
    finally:
        ctx.__exit__(None, None, None)
    act = actual(res, joint, ref)
    return {"status": res.status, "cpu_s": t1 - t0, "estimate_cpu_s": t2 - t1,
            "companion": acc["companion"].get("status"), "count": act["count"],
            "pairs": pairs(estimated(acc, joint), act)}


def request_run(path, joint, ref) -> dict:
    """``cosim run --accuracy 1%`` without its folder."""
    from cosim.cli.accuracy import Request
    from cosim.scene.load import load_scene
    from cosim.scene.run import simulate
    from cosim.studies.estimate import estimate_errors
    args = SimpleNamespace(scene=str(path), variant=None, set=[], scheme=None,
                           accuracy=ACCURACY, no_estimate=False)
    ctx = _quiet()
    t0 = time.process_time()
    try:
        req = Request.make(args, load_scene(path))
        req.run = simulate
        res = simulate(req.scene)
        if not res.success:
            return {"status": res.status, "message": res.message,
                    "cpu_s": time.process_time() - t0}
        res.summary["accuracy"] = estimate_errors(req.scene, res, contact=req.contact)
        res = req.check(res)
    except Exception as exc:        # a refusal (SceneError) or a failed refinement
        return {"status": "refused", "message": f"{type(exc).__name__}: {exc}",
                "cpu_s": time.process_time() - t0}
    finally:
        ctx.__exit__(None, None, None)
    r = res.summary["accuracy"]["request"]
    act = actual(res, joint, ref)
    met = (all(act[q] is not None and act[q] <= ACCURACY for q in QUANTITIES)
           if ref is not None else None)
    return {"status": res.status, "cpu_s": time.process_time() - t0, "scheme": r["scheme"],
            "step": r["step"], "refined": r["refined"], "count": act["count"],
            "met": met and act["count"] == ref["count"] if ref is not None else None,
            "pairs": pairs(estimated(res.summary["accuracy"], joint), act)}


_NUMBER = r"([0-9.eE+-]+|not limited)"


def info_steps(path) -> dict:
    """``cosim info``'s printed largest stable steps: ``macro`` (scheme ->
    step or None) and ``integrator`` (method -> step or None)."""
    proc = subprocess.run([sys.executable, "-m", "cosim.cli", "info", str(path)],
                          capture_output=True, text=True, timeout=600)
    out = {"macro": {}, "integrator": {}, "host": None, "exit_code": proc.returncode}
    for line in proc.stdout.splitlines():
        for key, head in (("macro", "largest stable macro step [s]:"),
                          ("integrator", "largest stable integrator step [s]:")):
            if head in line:
                for name, v in re.findall(r"(\w+) " + _NUMBER, line.split(":", 1)[1]):
                    out[key][name] = None if v == "not limited" else float(v)
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
                       "set": [f"scheme.contact_step={h9!r}",
                               f"scheme.macro_step={max(macro, h9)!r}"]})
    for method, h in info["integrator"].items():
        if h is None or info["host"] is None:
            continue
        key = ("subsystems.robot.integrator.max_step" if info["host"] == "robot"
               else "subsystems.target.integrator.contact_step")
        checks.append({"what": f"{info['host']} {method} step", "stable_step": h, "scheme": None,
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


def validate(path, cache, request: bool) -> dict:
    import tomllib
    from cosim.studies.bench import reference
    from cosim.studies.strike import find_strike
    data = tomllib.loads(Path(path).read_text())
    ctx = _quiet()
    contact, joint = find_strike(path)
    t0 = time.process_time()
    try:
        ref = reference(path, None, contact, joint, cache_dir=cache)
        case_ref = {k: ref[k] for k in ("count", "peak", "exit_velocity")}
    except Exception as exc:        # one scene's failed reference does not end the batch
        ref, case_ref = None, {"count": None, "error": f"{type(exc).__name__}: {exc}"}
    finally:
        ctx.__exit__(None, None, None)
    case_ref["cpu_s"] = time.process_time() - t0
    c = data["contacts"][CONTACT]
    case = {"scene": Path(path).stem, "description": data["description"],
            "scheme": data["scheme"]["name"], "placement": c["placement"],
            "law": c["law"]["type"], "structure": data["subsystems"]["target"]["type"],
            "joint": joint, "reference": case_ref}
    case["run"] = own_run(path, joint, ref)
    case["request"] = request_run(path, joint, ref) if request else None
    info = info_steps(path)
    case["info"] = info
    case["at_0.9"] = step_checks(path, info, data)
    return case


def totals(cases: list[dict]) -> dict:
    def tally(runs):
        ps = [p for r in runs if r and "pairs" in r for p in r["pairs"].values()]
        judged = [p for p in ps if p["agrees"] is not None]
        return {"pairs": len(ps), "judged": len(judged), "agree": sum(p["agrees"] for p in judged),
                "small": sum(p["actual"] is not None and p["actual"] < ACCURACY / 100
                             for p in judged),
                "no_estimate": sum(p["estimated"] is None for p in ps)}
    reqs = [c["request"] for c in cases if c["request"]]
    unreferenced = sum(c["reference"]["count"] is None for c in cases)
    steps = [s for c in cases for s in c["at_0.9"]]
    return {"scenes": len(cases), "unreferenced": unreferenced,
            "finished": sum(c["run"]["status"] == "finished" for c in cases),
            "estimate": tally([c["run"] for c in cases]), "request": tally(reqs),
            "requests": len(reqs), "met": sum(bool(r.get("met")) for r in reqs),
            "step_checks": len(steps),
            "step_finished": sum(s["status"] == "finished" for s in steps),
            "step_stopped": sum(s["status"] not in ("finished", "refused") for s in steps),
            "step_refused": sum(s["status"] == "refused" for s in steps)}


def _pct(x) -> str:
    return "-" if x is None else f"{100 * x:.2g} %"


def _pair(p) -> str:
    if p["estimated"] is None:
        return f"n/e / {_pct(p['actual'])}"
    mark = "" if p["agrees"] is None else " ✓" if p["agrees"] else " ✗"
    return f"{_pct(p['estimated'])} / {_pct(p['actual'])}{mark}"


def _steps(c) -> str:
    if not c["at_0.9"]:
        return "not limited"
    return "; ".join(f"{s['what']} {s['stable_step']:.3g}: {s['status']}" for s in c["at_0.9"])


def table(data: dict) -> str:
    lines = ["| scene | structure, law, placement, scheme | contacts (ref) | "
             "peak: est / actual | exit: est / actual | 1 %: choice | 1 %: peak | 1 %: exit | "
             "1 % met | info's stable step: run at 0.9x |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for c in data["cases"]:
        r, q = c["run"], c["request"]
        rc = "no reference" if c["reference"]["count"] is None else c["reference"]["count"]
        if "pairs" in r:
            pk, ex = _pair(r["pairs"]["peak"]), _pair(r["pairs"]["exit_velocity"])
            cnt = f"{r['count']} ({rc})"
        else:
            pk = ex = "-"
            cnt = f"{r['status']} ({rc})"
        if q is None:
            qc = qp = qe = qm = "-"
        elif "pairs" in q:
            qc = f"{q['scheme']} {q['step']:.3g}" + (" (refined)" if q["refined"] else "")
            qp, qe = _pair(q["pairs"]["peak"]), _pair(q["pairs"]["exit_velocity"])
            qm = "-" if q["met"] is None else "yes" if q["met"] else "**no**"
        else:
            qc, qp, qe, qm = q["status"], "-", "-", "-"
        lines.append(f"| {c['scene']} | {c['structure']}, {c['law']}, {c['placement']}, "
                     f"{c['scheme']} | {cnt} | {pk} | {ex} | {qc} | {qp} | {qe} | {qm} | "
                     f"{_steps(c)} |")
    return "\n".join(lines)


def totals_text(data: dict) -> str:
    t = data["totals"]
    e, r = t["estimate"], t["request"]
    out = (f"{t['finished']} of {t['scenes']} scenes finished"
           + (f" ({t['unreferenced']} without a reference: it failed)" if t.get("unreferenced")
              else "") + f". Estimate: {e['agree']} of "
           f"{e['judged']} pairs agree ({e['small']} of them below X/100 = "
           f"{ACCURACY / 100:.0e}, judged on the estimate below X/10), {e['no_estimate']} of "
           f"{e['pairs']} without an estimate.")
    if t["requests"]:
        out += (f" Requests at 1 %: met on {t['met']} of {t['requests']}; their estimates "
                f"agree on {r['agree']} of {r['judged']} pairs.")
    out += (f" Runs at {STEP_FRACTION}x cosim info's stable step: {t['step_finished']} of "
            f"{t['step_checks']} finished, {t['step_stopped']} stopped, {t['step_refused']} "
            f"refused.")
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
          f"joint's exit velocity at the strike's last release: ✓ when the estimate lies within "
          f"{AGREE:g}x of the actual error, or, where the actual error is below X/100 "
          f"(X = {ACCURACY:.0%}), when the estimate says below X/10; n/e: no estimate. "
          f"\"1 %\" is `cosim run --accuracy 1%` (its choice, its estimate and the actual "
          f"error, met: both actual errors within 1 % and the reference's contact count). The "
          f"last column runs each stable step `cosim info` prints at {STEP_FRACTION}x: "
          f"finished, failed (stopped by the run guard) or refused (by the pre-flight check "
          f"or the build).")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, default=40, help="how many scenes")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default="runs/generated-validation")
    ap.add_argument("--cache", default=None, help="the references' cache folder")
    ap.add_argument("--quick", action="store_true",
                    help="6 scenes (unless --n), no --accuracy requests")
    ap.add_argument("--table", metavar="DIR",
                    help="print (and rewrite DIR/README.md) the tables of a finished run")
    args = ap.parse_args(argv)
    from cosim.io.rundir import OutputFolder
    if args.table:
        text = readme(json.loads((Path(args.table) / "validation.json").read_text()))
        with OutputFolder(args.table) as folder:
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
            print(f"{case['scene']}: {case['run']['status']}, "
                  f"{_steps(case)}", flush=True)
        folder.write("README.md", lambda fh: fh.write(readme(data)), "w")
    print(readme(data))
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Validate accuracy on request against the bench's fine reference.

For each scene of :data:`CASES` (the scenes the accuracy model was fitted
on, :mod:`benchmarks.accuracy_model`, brachiation included) two runs are
compared with the fine monolithic reference of
:func:`cosim.studies.bench.reference`:

- the scene's default run (its own scheme and steps), its error estimated
  by the companion run (:func:`cosim.studies.estimate.estimate_errors`);
- the run ``cosim run --accuracy 1%`` keeps (:class:`cosim.cli.accuracy.Request`:
  the model's choice, its estimate, one refinement where the estimate
  misses).

a. **estimate against actual**: for the strike contact's peak penetration
   and the strike joint's exit velocity at the contact's last release, the
   estimated relative error (or why there is none) against the actual one
   (the run against the reference).  A pair *agrees* when estimate over
   actual lies within [1/3, 3], or both lie below :data:`ROUNDOFF`.
b. **1 % met**: the kept run's actual peak and exit-velocity errors are at
   most 1 %; and its CPU (the choice, the run, its companion(s), the
   refinement and its companion: process time) over that of the cheapest
   bench row that meets 1 % on both with the reference's count (Gauss-Seidel,
   Jacobi and implicit at :data:`STEP_FACTORS` times the chosen step; the
   scene loaded and run, process time), each the median of ``--repeat``.
c. **the estimate's cost**: the default run's estimate (its companion and
   what it reads) over the run itself, both process time, against
   :data:`ESTIMATE_TARGET`.

Run from the project root::

    python benchmarks/accuracy_validation.py [--out DIR] [--cache DIR] [--repeat N]
    python benchmarks/accuracy_validation.py --table DIR    # the table of a finished run

It writes ``DIR/validation.json`` through cosim's checked writer and prints
the Markdown table and totals of docs/accuracy.md ("Accuracy on request:
validation").  The published run is in
``benchmarks/results/accuracy_validation``.
"""
from __future__ import annotations

import argparse
import json
import math
import platform
import statistics
import sys
import time
import warnings
from pathlib import Path
from types import SimpleNamespace

#: (scene, variant, contact) validated; contact None: the scene's strike
CASES = [("three_mass", "f1", None), ("three_mass", "f10", None),
         ("three_mass", "f100", None), ("three_mass", "f1000", None),
         ("beam_impact", None, None), ("ground_multicontact", "kA1e6", "C"),
         ("spring_drop", "undamped", None), ("brachiation", None, "gripper1")]

#: the accuracy asked
ACCURACY = 0.01

#: estimate over actual within [1 / AGREE, AGREE] agrees
AGREE = 3.0

#: both below this: round-off, agreement whatever the ratio
ROUNDOFF = 1e-8

#: the bench rows' steps, as factors of the step the request chose
STEP_FACTORS = (2.0, 1.4, 1.0, 0.7, 0.5)

#: the bench rows' schemes
SCHEMES = ("gauss_seidel", "jacobi", "implicit")

#: the CPU ratio the issue aims at
CPU_TARGET = 1.5
#: the estimate's CPU over the run's it should stay within
ESTIMATE_TARGET = 0.3

QUANTITIES = ("peak", "exit_velocity")

#: the stages of a request's CPU: the choice (two loads and the model), the
#: run, its companion at 4x, the check (a companion at 2x where the counts
#: differ, the refinement and its companion)
STAGES = ("plan", "run", "estimate", "check")


def _quiet():
    ctx = warnings.catch_warnings()
    ctx.__enter__()
    warnings.simplefilter("ignore")
    return ctx


def estimated(acc: dict, contact: str, joint: str) -> dict:
    """The estimate's relative errors of the contact's peak and the joint's
    exit velocity: quantity -> ``{"error": float or None, "why": str}``."""
    out = {}
    if contact not in acc.get("contacts", {}):      # no companion ran
        why = "; ".join(acc.get("why") or ["the estimate is not reliable"])
        return {q: {"error": None, "why": why} for q in QUANTITIES}
    # each quantity by its own verdict, as a request judges it (another contact's
    # estimate that the companion cannot see does not decide these)
    entries = {"peak": acc["contacts"][contact]["peak_penetration"],
               "exit_velocity": acc["exit"].get(joint, {"why": f"no joint {joint}"})}
    for q, e in entries.items():
        err = e.get("relative_error")
        out[q] = {"error": err, "why": "" if err is not None else
                  e.get("why", "not estimated")}
    return out


def actual(res, contact: str, joint: str, ref: dict) -> dict:
    """The run's relative errors against the reference, and its count."""
    from cosim.studies.metrics import impact_metrics, relative_errors
    m = impact_metrics(res, contact, joint)
    e = relative_errors(m, ref)
    return {"peak": _finite(e["peak"]), "exit_velocity": _finite(e["exit_velocity"]),
            "count": m["count"], "count_ref": ref["count"]}


def _finite(x):
    return float(x) if x is not None and math.isfinite(x) else None


def agrees(est, act) -> bool | None:
    """Whether an estimate agrees with the actual error (None: no estimate
    or no actual error to compare)."""
    if est is None or act is None:
        return None
    if est < ROUNDOFF and act < ROUNDOFF:
        return True
    if est == 0.0 or act == 0.0:
        return False
    return 1.0 / AGREE <= est / act <= AGREE


def _pairs(est: dict, act: dict) -> dict:
    return {q: {"estimated": est[q]["error"], "why": est[q]["why"], "actual": act[q],
                "agrees": agrees(est[q]["error"], act[q])} for q in QUANTITIES}


def default_run(name, variant, contact, joint, ref) -> dict:
    """The scene's own run, estimated, against the reference."""
    from cosim.scene.load import load_scene
    from cosim.scene.run import simulate
    from cosim.studies.estimate import estimate_errors
    ctx = _quiet()
    try:
        scene = load_scene(name, variant)
        t0 = time.process_time()
        res = simulate(scene)
        t1 = time.process_time()
        acc = estimate_errors(scene, res, contact=contact)     # the exit at the strike's release
        t2 = time.process_time()
        cpu = t2 - t0
    finally:
        ctx.__exit__(None, None, None)
    act = actual(res, contact, joint, ref)
    return {"scheme": scene.scheme, "cpu_s": cpu,
            "stages_s": {"run": t1 - t0, "estimate": t2 - t1},
            "companion": acc["companion"].get("status"), "count": act["count"],
            "exit_at": acc.get("exit", {}).get("at"), "factor": acc["factor"],
            "coarsened": sorted(acc.get("coarsened") or {}),
            "pairs": _pairs(estimated(acc, contact, joint), act)}


def request_run(name, variant, contact, joint, ref, accuracy=ACCURACY):
    """``cosim run --accuracy`` without its folder: the choice, the run,
    its estimate and the one refinement; returns (record, chosen step)."""
    from cosim.cli.accuracy import Request
    from cosim.scene.load import load_scene
    from cosim.scene.run import simulate
    from cosim.studies.estimate import estimate_errors
    import tempfile

    from cosim.io.rundir import OutputFolder
    args = SimpleNamespace(scene=name, variant=variant, set=[], scheme=None,
                           accuracy=accuracy, no_estimate=False, yes=True)
    ctx = _quiet()
    where = tempfile.TemporaryDirectory()
    try:
        out = Path(where.name) / "run"
        t = [time.process_time()]
        req = Request.make(args, load_scene(name, variant))
        req.run = lambda sc, to: simulate(sc, out=to, overwrite=True)
        first = req.choice.step
        t.append(time.process_time())
        res = simulate(req.scene, out=out)
        t.append(time.process_time())
        res.summary["accuracy"] = estimate_errors(req.scene, res, contact=req.contact)
        t.append(time.process_time())
        with OutputFolder(out) as folder:      # the refinement runs beside it, then replaces it
            res = req.check(res, folder)
        t.append(time.process_time())
    finally:
        ctx.__exit__(None, None, None)
    r = res.summary["accuracy"]["request"]
    act = actual(res, contact, joint, ref)
    met = all(act[q] is not None and act[q] <= accuracy for q in QUANTITIES)
    return {"scheme": r["scheme"], "overrides": r["overrides"], "step": r["step"],
            "first_step": first, "refined": r["refined"],
            "request_estimate": r["estimated_error"], "request_met": r["met"],
            "unchecked": r["unchecked"], "cpu_s": t[-1] - t[0],
            "stages_s": {k: b - a for k, a, b in zip(STAGES, t, t[1:])},
            "exit_at": res.summary["accuracy"].get("exit", {}).get("at"),
            "factor": res.summary["accuracy"]["factor"], "knob": req.choice.knob.key,
            "coarsened": sorted(res.summary["accuracy"].get("coarsened") or {}),
            "count": act["count"],
            "count_ref": act["count_ref"], "met": met and act["count"] == act["count_ref"],
            "pairs": _pairs(estimated(res.summary["accuracy"], contact, joint), act)}, req.choice


def bench_rows(name, variant, contact, joint, ref, choice, accuracy=ACCURACY) -> list[dict]:
    """Gauss-Seidel, Jacobi and implicit at :data:`STEP_FACTORS` times the
    chosen step (the knob the model turns): each run's errors, count and
    CPU (loading and running the scene, process time)."""
    from cosim.errors import UnsafeStepError
    from cosim.scene.checks import SceneError
    from cosim.scene.load import load_scene
    from cosim.scene.run import simulate
    k = choice.knob
    base = choice.step if choice.scheme != "monolithic" else k.value
    rows = []
    for scheme in SCHEMES:
        for f in STEP_FACTORS:
            h = float(f"{base * f:.3g}")
            row = {"scheme": scheme, "step": h, "factor": f}
            ctx = _quiet()
            try:
                t0 = time.process_time()
                res = simulate(load_scene(name, variant, k.overrides(h), scheme))
                row["cpu_s"] = time.process_time() - t0
            except (UnsafeStepError, SceneError):
                rows.append({**row, "status": "refused"})
                continue
            finally:
                ctx.__exit__(None, None, None)
            row["status"] = "finished" if res.success else res.status
            if res.success:
                act = actual(res, contact, joint, ref)
                row.update(act)
                row["meets"] = (act["count"] == act["count_ref"] and all(
                    act[q] is not None and act[q] <= accuracy for q in QUANTITIES))
            rows.append(row)
    return rows


def _median_cpu(fn, repeat: int):
    """``fn()`` run ``repeat`` times: its first result, with ``cpu_s`` the
    median over the runs."""
    runs = [fn() for _ in range(repeat)]
    first = runs[0]
    rec = first[0] if isinstance(first, tuple) else first
    recs = [r[0] if isinstance(r, tuple) else r for r in runs]
    rec["cpu_s"] = statistics.median(r["cpu_s"] for r in recs)
    if "stages_s" in rec:
        rec["stages_s"] = {k: statistics.median(r["stages_s"][k] for r in recs)
                           for k in rec["stages_s"]}
    return first


def validate_case(name, variant, contact, cache, repeat: int = 1) -> dict:
    """One scene: its default run, its request at 1 % and the bench rows."""
    from cosim.scene.load import load_scene
    from cosim.studies.bench import reference
    from cosim.studies.choose import knob
    from cosim.studies.strike import find_strike
    ctx = _quiet()
    try:
        scene = load_scene(name, variant)
        contact, joint = find_strike(scene, knob(scene, contact).contact)
        ref = reference(name, variant, contact, joint, cache_dir=cache)
    finally:
        ctx.__exit__(None, None, None)
    case = {"scene": name, "variant": variant, "contact": contact, "joint": joint,
            "reference": {k: ref[k] for k in ("count", "peak", "exit_velocity")}}
    case["default"] = _median_cpu(lambda: default_run(name, variant, contact, joint, ref),
                                  repeat)
    case["request"], choice = _median_cpu(
        lambda: request_run(name, variant, contact, joint, ref), repeat)
    rows = [bench_rows(name, variant, contact, joint, ref, choice) for _ in range(repeat)]
    for i, row in enumerate(rows[0]):
        if "cpu_s" in row:
            row["cpu_s"] = statistics.median(r[i]["cpu_s"] for r in rows)
    case["bench"] = rows[0]
    ok = [r for r in rows[0] if r.get("meets")]
    best = min(ok, key=lambda r: r["cpu_s"]) if ok else None
    case["cheapest"] = best
    case["cpu_ratio"] = case["request"]["cpu_s"] / best["cpu_s"] if best else None
    at = [r for r in rows[0] if r["scheme"] == case["request"]["scheme"] and r["factor"] == 1.0
          and "cpu_s" in r]
    # the chosen step run as a bench row, over the cheapest: what the model's margin costs
    case["choice_over_cheapest"] = at[0]["cpu_s"] / best["cpu_s"] if best and at else None
    return case


def totals(cases: list[dict]) -> dict:
    """Pairs that agree, pairs with an estimate, pairs without; cases that
    meet 1 %; CPU ratios."""
    pairs = [p for c in cases for run in ("default", "request")
             for p in c[run]["pairs"].values()]
    judged = [p for p in pairs if p["agrees"] is not None]
    ratios = [c["cpu_ratio"] for c in cases if c["cpu_ratio"] is not None]
    return {"pairs": len(pairs), "with_estimate": len(judged),
            "agree": sum(p["agrees"] for p in judged),
            "without_estimate": sum(p["estimated"] is None for p in pairs),
            "met": sum(c["request"]["met"] for c in cases), "cases": len(cases),
            "cpu_within_target": sum(r <= CPU_TARGET for r in ratios),
            "cpu_ratio_max": max(ratios) if ratios else None,
            "cpu_ratio_median": statistics.median(ratios) if ratios else None,
            "no_bench_row": sum(c["cpu_ratio"] is None for c in cases),
            "estimate_within_target": sum(estimate_share(c["default"]) <= ESTIMATE_TARGET
                                          for c in cases),
            "estimate_share_median": statistics.median(estimate_share(c["default"])
                                                       for c in cases)}


def _pct(x) -> str:
    return "-" if x is None else f"{100 * x:.2g} %"


def _pair(p) -> str:
    if p["estimated"] is None:
        return f"n/r / {_pct(p['actual'])}"
    mark = "" if p["agrees"] is None else " ✓" if p["agrees"] else " ✗"
    return f"{_pct(p['estimated'])} / {_pct(p['actual'])}{mark}"


def case_label(c: dict) -> str:
    return c["scene"] + (f" {c['variant']}" if c["variant"] else "")


def table(data: dict) -> str:
    """The Markdown tables of docs/accuracy.md."""
    lines = ["| scene | default: peak est / actual | default: exit est / actual | "
             "1 %: choice | 1 %: peak est / actual | 1 %: exit est / actual | 1 % met | "
             "CPU [s]: 1 % / cheapest row | ratio |",
             "|---|---|---|---|---|---|---|---|---|"]
    for c in data["cases"]:
        d, r, b = c["default"]["pairs"], c["request"], c["cheapest"]
        ch = f"{r['scheme']} {r['step']:.3g}" + (" (refined)" if r["refined"] else "")
        cheap = f"{b['scheme']} {b['step']:.3g}: {b['cpu_s']:.3g}" if b else "none meets 1 %"
        lines.append(
            f"| {case_label(c)} | {_pair(d['peak'])} | {_pair(d['exit_velocity'])} | {ch} | "
            f"{_pair(r['pairs']['peak'])} | {_pair(r['pairs']['exit_velocity'])} | "
            f"{'yes' if r['met'] else '**no**'} | {r['cpu_s']:.3g} / {cheap} | "
            f"{'-' if c['cpu_ratio'] is None else format(c['cpu_ratio'], '.2g')} |")
    lines += ["", "| scene | estimate's exit velocity read at | request CPU [s]: "
              + " / ".join(STAGES) + " | chosen step as a bench row / cheapest | "
              "default: companion factor, estimate / run CPU |",
              "|---|---|---|---|---|"]
    for c in data["cases"]:
        r, d = c["request"], c["default"]
        st = " / ".join(f"{r['stages_s'][k]:.2g}" for k in STAGES)
        x = c["choice_over_cheapest"]
        share = estimate_share(d)
        own = (f"{d['factor']:g}x, {share:.2f}" if d.get("companion") != "not run" else
               f"not run, {share:.2f}")
        lines.append(f"| {case_label(c)} | {r['exit_at'] or '-'} | {st} | "
                     f"{'-' if x is None else format(x, '.2g')} | {own} |")
    return "\n".join(lines)


def estimate_share(run: dict) -> float:
    """The estimate's CPU over the run's (the default run's stages)."""
    return run["stages_s"]["estimate"] / run["stages_s"]["run"]


def totals_text(data: dict) -> str:
    """The totals in one line."""
    t = data["totals"]
    lines = [f"Agree within {AGREE:g}x: {t['agree']} of {t['with_estimate']} pairs with "
              f"an estimate ({t['without_estimate']} of {t['pairs']} without one). 1 % met on "
              f"{t['met']} of {t['cases']}. CPU within {CPU_TARGET}x of the cheapest bench row "
              f"on {t['cpu_within_target']} of {t['cases'] - t['no_bench_row']} (median "
              f"{t['cpu_ratio_median']:.2g}x, worst {t['cpu_ratio_max']:.2g}x). The default "
              f"run's estimate within {ESTIMATE_TARGET:.0%} of its CPU on "
              f"{t['estimate_within_target']} of {t['cases']} (median "
              f"{t['estimate_share_median']:.2f})."]
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default="runs/accuracy-validation")
    ap.add_argument("--cache", default="runs/.bench-cache")
    ap.add_argument("--repeat", type=int, default=3, help="CPU: the median of this many runs")
    ap.add_argument("--table", metavar="DIR", help="print the table of a finished run")
    args = ap.parse_args(argv)
    if args.table:
        data = json.loads((Path(args.table) / "validation.json").read_text())
        print(table(data) + "\n\n" + totals_text(data))
        return 0
    from cosim.io.rundir import OutputFolder
    data = {"machine": f"{platform.machine()}, Python {platform.python_version()}",
            "accuracy": ACCURACY, "repeat": args.repeat, "cases": []}
    with OutputFolder(args.out) as folder:
        for name, variant, contact in CASES:
            c = validate_case(name, variant, contact, args.cache, args.repeat)
            data["cases"].append(c)
            print(f"{case_label(c)}: request {c['request']['scheme']} {c['request']['step']:.3g}"
                  f" met {c['request']['met']} ratio {c['cpu_ratio']}", flush=True)
            data["totals"] = totals(data["cases"])
            folder.write("validation.json", lambda fh: json.dump(data, fh, indent=1), "w")
    print(table(data) + "\n\n" + totals_text(data))
    return 0


if __name__ == "__main__":
    sys.exit(main())

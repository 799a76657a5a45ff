"""Validate accuracy on request against the bench's fine reference.

For each scene of :data:`CASES` (the scenes the accuracy model was fitted
on, :mod:`benchmarks.accuracy_model`, brachiation included) two runs are
compared with the fine monolithic reference of
:func:`cosim.studies.bench.reference`:

- the scene's default run (its own scheme and steps), its error estimated
  by its companions (:func:`cosim.studies.estimate.estimate_errors`);
- the run ``cosim run --accuracy 1%`` keeps (:class:`cosim.cli.accuracy.Request`:
  the model's choice, its estimate, one refinement where the estimate
  misses).

The issue's targets, each counted met / total in :func:`totals`:

a. **estimate against actual** (:data:`PAIR_TARGET` of the pairs): for the
   strike contact's peak penetration and the strike joint's exit velocity at
   the contact's last release, the estimated relative error (or why there is
   none) against the actual one (the run against the reference).  A pair
   *agrees* when estimate over actual lies within [1/3, 3]; where the actual
   error is below X/100 (X the accuracy asked) the ratio means nothing and the
   pair agrees when the estimate says below X/10.  A pair without an estimate
   does not agree.
b. **X met** (:data:`MET_TARGET` of the scenes): the kept run's actual peak
   and exit-velocity errors are at most X with the reference's contact count;
   **honest** (every scene): the request is met, or its outcome
   (``accuracy.request.outcome``) says ``not met`` or ``unchecked``.
c. **its cost**: against the cheapest bench row that meets X on both with the
   reference's count (Gauss-Seidel, Jacobi and implicit at
   :data:`STEP_FACTORS` times the chosen step; the scene loaded and run,
   process time): the request's own run (the choice, the run and a
   refinement's run: process time) at most :data:`CPU_TARGET` times it, and
   the request whole (with its estimates) at most :data:`ESTIMATE_TARGET`
   times it, each the median of ``--repeat``; each command timed as a new
   process would run it (:func:`fresh`: the assemblies and modes another
   kept are forgotten first).

Run from the project root::

    python benchmarks/accuracy_validation.py [--out DIR] [--cache DIR] [--repeat N]
    python benchmarks/accuracy_validation.py --table DIR    # the table of a finished run

It writes ``DIR/validation.json`` through cosim's checked writer and prints
the tables and totals of docs/accuracy.md; the published run is in
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

#: an actual error below X / SMALL is judged on the estimate saying below X / 10
SMALL = 100.0

#: the share of the pairs that should agree, and of the scenes that should meet X
PAIR_TARGET = MET_TARGET = 0.9

#: the bench rows' steps, as factors of the step the request chose
STEP_FACTORS = (2.0, 1.4, 1.0, 0.7, 0.5)

#: the bench rows' schemes
SCHEMES = ("gauss_seidel", "jacobi", "implicit")

#: the request's own run over the cheapest bench row that meets X
CPU_TARGET = 1.5
#: the request with its estimates over the cheapest bench row that meets X
ESTIMATE_TARGET = 3.0

QUANTITIES = ("peak", "exit_velocity")

#: the stages of a request's CPU: the choice (two loads and the model), the
#: run, its estimate (two companions), the check (a companion where the counts
#: differ, the refinement and its estimate)
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
                  e.get("why", "not estimated"), "kind": e.get("kind"), "order": e.get("order")}
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


def agrees(est, act, x: float = ACCURACY) -> bool | None:
    """Whether an estimate agrees with the actual error (None: no estimate
    or no actual error to compare).  Below ``x / SMALL`` the actual error is
    judged on the estimate saying below ``x / 10`` alone."""
    if est is None or act is None:
        return None
    if act < x / SMALL:
        return est < x / 10
    if est == 0.0:
        return False
    return 1.0 / AGREE <= est / act <= AGREE


def _pairs(est: dict, act: dict) -> dict:
    return {q: {"estimated": est[q]["error"], "why": est[q]["why"], "actual": act[q],
                "kind": est[q].get("kind"), "order": est[q].get("order"),
                "agrees": agrees(est[q]["error"], act[q])} for q in QUANTITIES}


def fresh() -> None:
    """Forget what a process keeps between builds (the assembled structures,
    :func:`cosim.scene.build.clear_assembled`, and their modes), so that each
    timed command (the default run, the request, each bench row) pays its
    builds as a new `cosim run` would: none is timed with another's
    assemblies kept."""
    from cosim.scene.build import clear_assembled
    from fem.modal import clear_solved
    clear_assembled()
    clear_solved()


def default_run(name, variant, contact, joint, ref) -> dict:
    """The scene's own run, estimated, against the reference."""
    from cosim.scene.load import load_scene
    from cosim.scene.run import simulate
    from cosim.studies.estimate import estimate_errors
    ctx = _quiet()
    try:
        fresh()
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
        fresh()
        t = [time.process_time()]
        req = Request.make(args, load_scene(name, variant))
        refined_s = []

        def timed(sc, to):
            t0 = time.process_time()
            try:
                return simulate(sc, out=to, overwrite=True)
            finally:
                refined_s.append(time.process_time() - t0)
        req.run = timed
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
            "outcome": r["outcome"], "note": r.get("note"),
            "unchecked": r["unchecked"], "cpu_s": t[-1] - t[0],
            "own_cpu_s": t[2] - t[0] + sum(refined_s),
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
                fresh()
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
    for k in ("cpu_s", "own_cpu_s"):
        if k in rec:
            rec[k] = statistics.median(r[k] for r in recs)
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
    case["own_ratio"] = case["request"]["own_cpu_s"] / best["cpu_s"] if best else None
    at = [r for r in rows[0] if r["scheme"] == case["request"]["scheme"] and r["factor"] == 1.0
          and "cpu_s" in r]
    # the chosen step run as a bench row, over the cheapest: what the model's margin costs
    case["choice_over_cheapest"] = at[0]["cpu_s"] / best["cpu_s"] if best and at else None
    return case


def honest(r: dict) -> bool:
    """A request is honest when it is met, or says ``not met`` or
    ``unchecked``."""
    return bool(r["met"]) or r.get("outcome") in ("not met", "unchecked")


def pair_totals(pairs: list[dict]) -> dict:
    """Pairs with an actual error, those that agree, those with no estimate,
    those judged below X/100."""
    judged = [p for p in pairs if p["actual"] is not None]
    return {"pairs": len(judged), "agree": sum(bool(p["agrees"]) for p in judged),
            "without_estimate": sum(p["estimated"] is None for p in judged),
            "small": sum(p["actual"] < ACCURACY / SMALL for p in judged),
            "bounds": sum(p.get("kind") == "bound" for p in judged),
            "under": sum(p["estimated"] is not None and p["agrees"] is False
                         and p["estimated"] < p["actual"] for p in judged)}


def cpu_totals(own: list, whole: list) -> dict:
    """The CPU ratios (None: no bench row meets X) against their targets."""
    out = {}
    for key, rs, target in (("own", own, CPU_TARGET), ("whole", whole, ESTIMATE_TARGET)):
        rs = [r for r in rs if r is not None]
        out |= {"cpu_cases": len(rs), f"{key}_within": sum(r <= target for r in rs),
                f"{key}_median": statistics.median(rs) if rs else None,
                f"{key}_max": max(rs) if rs else None}
    return out


def totals(cases: list[dict]) -> dict:
    """Per target, met / total: the pairs that agree, the scenes that meet
    X, the honest requests, the CPU ratios within their targets."""
    pairs = [p for c in cases for run in ("default", "request")
             for p in c[run]["pairs"].values()]
    return {**pair_totals(pairs), "met": sum(c["request"]["met"] for c in cases),
            "cases": len(cases), "honest": sum(honest(c["request"]) for c in cases),
            **cpu_totals([c["own_ratio"] for c in cases], [c["cpu_ratio"] for c in cases])}


def verdicts(t: dict, scenes: int) -> dict:
    """Each target: (met, total, whether the target holds)."""
    return {"agree": (t["agree"], t["pairs"], t["agree"] >= PAIR_TARGET * t["pairs"]),
            "met": (t["met"], scenes, t["met"] >= MET_TARGET * scenes),
            "honest": (t["honest"], scenes, t["honest"] == scenes),
            "own_cpu": (t["own_within"], t["cpu_cases"], t["own_within"] == t["cpu_cases"]),
            "whole_cpu": (t["whole_within"], t["cpu_cases"],
                          t["whole_within"] == t["cpu_cases"])}


def verdicts_text(t: dict, scenes: int) -> str:
    """The targets, one line each: met / total and the verdict."""
    v = verdicts(t, scenes)
    what = {"agree": f"estimate within {AGREE:g}x (or below X/10 where the actual error is "
                     f"below X/100) on at least {100 * PAIR_TARGET:.0f} % of the pairs",
            "met": f"the request met on at least {100 * MET_TARGET:.0f} % of the scenes",
            "honest": "the request met or reported not met / unchecked on every scene",
            "own_cpu": f"the request's own run within {CPU_TARGET:g}x of the cheapest bench "
                       f"row that meets X (median {_x(t['own_median'])}, worst "
                       f"{_x(t['own_max'])})",
            "whole_cpu": f"the request with its estimates within {ESTIMATE_TARGET:g}x of it "
                         f"(median {_x(t['whole_median'])}, worst {_x(t['whole_max'])})"}
    return "\n".join(f"- {what[k]}: {a} of {b}, **{'met' if ok else 'NOT met'}**"
                      for k, (a, b, ok) in v.items())


#: the summary table's rows: target key -> what it holds
SUMMARY_ROWS = {"agree": "the estimate within 3x (below X/10 under X/100), ≥ 90 % of pairs",
                "met": "`--accuracy 1%` met, on ≥ 90 % of the scenes",
                "honest": "met, or said not met / unchecked, on every scene",
                "own_cpu": "the request's own run within 1.5x of the cheapest row that meets 1 %",
                "whole_cpu": "the request with its estimates within 3x of that row"}

#: the same, short: the columns of the summary across
SUMMARY_SHORT = {"agree": "estimate within 3x (≥ 90 %)", "met": "1 % met (≥ 90 %)",
                 "honest": "met or said not (all)", "own_cpu": "own run ≤ 1.5x (all)",
                 "whole_cpu": "with estimates ≤ 3x (all)"}


def _cell(t: dict, n: int, key: str) -> str:
    a, b, ok = verdicts(t, n)[key]
    return f"{a} of {b}: {'met' if ok else '**NOT met**'}"


def summary_table(runs: list[tuple[str, dict, int]], across: bool = False,
                  head: str = "run") -> str:
    """The targets against each run (its heading, totals and scenes), met /
    total and the verdict: a row per target (docs/accuracy.md), or with
    ``across`` a row per run (docs/performance.md), ``head`` the first
    column's heading."""
    if across:
        return "\n".join([f"| {head} | " + " | ".join(SUMMARY_SHORT.values()) + " |",
                          "|---|" + "---|" * len(SUMMARY_SHORT)] +
                         [f"| {h} | " + " | ".join(_cell(t, n, k) for k in SUMMARY_SHORT) + " |"
                          for h, t, n in runs])
    lines = ["| target | " + " | ".join(h for h, _, _ in runs) + " |",
             "|---|" + "---|" * len(runs)]
    for key, what in SUMMARY_ROWS.items():
        lines.append(f"| {what} | " + " | ".join(_cell(t, n, key) for _, t, n in runs) + " |")
    return "\n".join(lines)


def _x(r) -> str:
    return "-" if r is None else f"{r:.2g}x"


def _pct(x) -> str:
    return "-" if x is None else f"{100 * x:.2g} %"


def _pair(p) -> str:
    if p["estimated"] is None:
        return f"n/r / {_pct(p['actual'])}"
    mark = "" if p["agrees"] is None else " ✓" if p["agrees"] else " ✗"
    bound = "≤" if p.get("kind") == "bound" else ""
    return f"{bound}{_pct(p['estimated'])} / {_pct(p['actual'])}{mark}"


def case_label(c: dict) -> str:
    return c["scene"] + (f" {c['variant']}" if c["variant"] else "")


def table(data: dict) -> str:
    """The Markdown tables of docs/accuracy.md."""
    lines = ["| scene | default: peak est / actual | default: exit est / actual | "
             "1 %: choice | 1 %: peak est / actual | 1 %: exit est / actual | 1 % met | "
             "outcome | CPU [s]: own run / whole / cheapest row | ratios |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for c in data["cases"]:
        d, r, b = c["default"]["pairs"], c["request"], c["cheapest"]
        ch = f"{r['scheme']} {r['step']:.3g}" + (" (refined)" if r["refined"] else "")
        cheap = f"{b['scheme']} {b['step']:.3g}: {b['cpu_s']:.3g}" if b else "none meets 1 %"
        lines.append(
            f"| {case_label(c)} | {_pair(d['peak'])} | {_pair(d['exit_velocity'])} | {ch} | "
            f"{_pair(r['pairs']['peak'])} | {_pair(r['pairs']['exit_velocity'])} | "
            f"{'yes' if r['met'] else '**no**'} | {r['outcome']} | "
            f"{r['own_cpu_s']:.3g} / {r['cpu_s']:.3g} / {cheap} | "
            f"{_x(c['own_ratio'])} / {_x(c['cpu_ratio'])} |")
    lines += ["", "| scene | request CPU [s]: " + " / ".join(STAGES) + " | chosen step as "
              "a bench row / cheapest | default: estimate / run CPU |", "|---|---|---|---|"]
    for c in data["cases"]:
        r, d = c["request"], c["default"]
        st = " / ".join(f"{r['stages_s'][k]:.2g}" for k in STAGES)
        x = c["choice_over_cheapest"]
        own = (f"{estimate_share(d):.2f}" if d.get("companion") != "not run" else
               f"not run, {estimate_share(d):.2f}")
        lines.append(f"| {case_label(c)} | {st} | {'-' if x is None else format(x, '.2g')} | "
                     f"{own} |")
    return "\n".join(lines)


def estimate_share(run: dict) -> float:
    """The estimate's CPU over the run's (the default run's stages)."""
    return run["stages_s"]["estimate"] / run["stages_s"]["run"]


def totals_text(data: dict) -> str:
    """The totals against each target, one line each."""
    t = data["totals"]
    return (f"{t['pairs']} pairs with an actual error ({t['small']} of them below X/100, "
            f"{t['without_estimate']} without an estimate, {t['bounds']} bounds); "
            f"{t['under']} under-estimated past {AGREE:g}x.\n\n"
            + verdicts_text(t, t["cases"]))


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

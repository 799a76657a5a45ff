"""`cosim bench`'s "co-simulation / monolithic CPU" on every shipped scene and
variant and on generated scenes: does a co-simulation that meets the bench's
accuracy ever cost more than integrating the scene as one system?

For each shipped scene (``cases/*.toml``) and each of its variants (the
scene alone too where it has no ``default_variant``), and for ``--n``
scenes of ``--seed`` drawn by :mod:`cosim.studies.generate` (written as
``scenes/NAME.toml`` into ``--out``), it runs what ``cosim bench SCENE
[--variant V]`` runs, with its defaults (:func:`cosim.studies.bench.run_bench`:
the scene's own scheme and ``implicit`` at four steps, the monolithic scheme
at four tolerances, the paper's RK45, each row on the scene and two
round-off copies), in this process, OpenBLAS on one thread as `cosim` runs
it.  From the rows it takes what the bench prints
(:func:`cosim.studies.bench.cheapest_within` at 1 %): the cheapest
co-simulation and the cheapest monolithic row whose every copy meets 1 %,
their solve CPU (median over the copies) and their ratio, judged against the
target: at most 1.  The two CPUs come from runs in one process a few seconds
apart, so their ratio holds better than either time on a shared machine;
the load average is kept beside each row.

For the chosen co-simulation it runs that row once more to say which macro
loop took it (:attr:`cosim.core.schemes.base.CoSimulationScheme.loop_stats`:
``compiled`` or ``python`` and why, the macro steps, the share of the run
inside the compiled loop's calls) and its CPU per macro step.

Where the bench refuses a scene (no single strike to compare, no joint), the
row says why, as `cosim bench` would; for the scenes in :data:`CONTACTS` it
also runs the bench with the contact named (``--contact``).

Run from the project root::

    python benchmarks/bench_ratio.py [--n 6] [--seed 0] [--spread 3] [--only NAME,...]
                                     [--no-shipped] [--out DIR]
    python benchmarks/bench_ratio.py --table DIR      # the table of a finished run again

It writes ``DIR/bench_ratio.json`` (after each scene) and ``DIR/README.md``
(the machine, the date, the load, the table) through cosim's checked writer.
"""
from __future__ import annotations

import argparse
import datetime
import json
import math
import os
import platform
import sys
import time
import warnings
from pathlib import Path

if __name__ == "__main__":
    # as `cosim bench` runs: OpenBLAS on one thread unless the user chose a
    # count (cosim.cli.one_blas_thread_by_default), set before numpy loads
    from cosim.cli import one_blas_thread_by_default
    one_blas_thread_by_default()

#: the accuracy `cosim bench` judges its cheapest rows by
ACCURACY = 0.01
#: the target: co-simulation CPU over monolithic CPU at most this
TARGET = 1.0
#: shipped scenes the bench refuses without ``--contact`` (no contact joins a
#: multibody to a structure), and the strike a user would name there
CONTACTS = {"ground_multicontact": "C", "ground_multicontact_strike": "C"}


def shipped_cases(only=()) -> list[tuple[str, str, str | None]]:
    """(name, path relative to the project root, variant) of each shipped
    scene and variant `cosim bench` can be asked for: every variant, and the
    scene without one where it names no ``default_variant``."""
    from cosim.scene.shipped import scene_variants, shipped_scenes
    out = []
    for name, path in shipped_scenes().items():
        if only and name not in only:
            continue
        variants, default = scene_variants(path)
        rel = f"cases/{path.name}"
        if not variants or default is None:
            out.append((name, rel, None))
        out += [(name, rel, v) for v in variants]
    return out


def _quiet():
    ctx = warnings.catch_warnings()
    ctx.__enter__()
    warnings.simplefilter("ignore")
    return ctx


def _plain(text: str) -> str:
    """``text`` without this machine's path of the project (a message that
    names a scene file)."""
    root = str(Path.cwd().resolve())
    return text.replace(root + os.sep, "").replace(root, ".")


def verdict(ratio) -> str:
    """``yes`` (ratio at most :data:`TARGET`), ``no``, or ``-`` (no ratio:
    no co-simulation or no monolithic row met the accuracy)."""
    if ratio is None or (isinstance(ratio, float) and math.isnan(ratio)):
        return "-"
    return "yes" if ratio <= TARGET else "no"


def _row_dict(r) -> dict:
    from dataclasses import asdict
    return {k: (None if isinstance(v, float) and math.isnan(v) else v)
            for k, v in asdict(r).items()}


def _overrides(path, variant, row, schemes=None) -> tuple[list[str], str]:
    """The ``--set`` overrides and the scheme that make bench row ``row``
    (as :func:`cosim.studies.bench.run_bench` built it)."""
    from cosim.scene.load import load_scene
    from cosim.studies.bench import _runs
    scene = load_scene(path, variant)
    for scheme, label, step, tol, ov in _runs(scene, schemes):
        if scheme == row.scheme and label == row.label and step == row.macro_step:
            return ov, scheme
    raise LookupError(f"no bench row {row.label} at {row.macro_step}")


def loop_of(path, variant, ov, scheme) -> dict:
    """One run of a bench row: its macro loop (``loop``, ``refusal``), macro
    steps, solve CPU and the share of it inside the compiled loop's calls."""
    from cosim.core.guard import Guard
    from cosim.core.recorder import Recorder
    from cosim.scene.build import build_system
    from cosim.scene.load import load_scene
    ctx = _quiet()
    try:
        scene = load_scene(path, variant, list(ov), scheme)
        system, sch = build_system(scene)
        rec = Recorder(system, scene.name, sch.name, scene.t_end, every=scene.output_every,
                       auto_edges=[c not in system.embedded for c in range(system.n_contacts)],
                       guard=Guard(system, scene.guard))
        sch.prepare(system, scene.t_end, rec)   # as cosim.scene.run.simulate, before the clock
        rec.prepare()
        t0 = time.process_time()
        sch.run(system, scene.t_end, rec)
        cpu = time.process_time() - t0
    finally:
        ctx.__exit__(None, None, None)
    st = dict(getattr(sch, "loop_stats", None) or {})
    steps = st.get("macro_steps") or getattr(sch, "n_windows", 0)
    out = {"loop": st.get("loop", "-"), "refusal": st.get("refusal"), "macro_steps": steps,
           "cpu_s": cpu, "us_per_step": 1e6 * cpu / steps if steps else None}
    if st.get("run_cpu_s"):
        out["compiled_share"] = st["compiled_cpu_s"] / st["run_cpu_s"]
    return out


def bench_case(name, path, variant, contact=None, spread=3, cache=None, origin="shipped",
               schemes=None):
    """One scene and variant: the bench's cheapest rows within 1 % and their
    ratio, or why the bench does not apply (``schemes``: the bench's
    ``--schemes``; None: its default)."""
    from cosim.errors import SimulationError
    from cosim.scene.checks import SceneError
    from cosim.studies.bench import cheapest_within, run_bench
    case = {"scene": name, "variant": variant, "origin": origin, "contact": contact,
            "load_before": os.getloadavg()[0]}
    t0 = time.process_time()
    ctx = _quiet()
    try:
        ref, rows = run_bench(path, variant, schemes, contact=contact, cache_dir=cache,
                              spread=spread)
    except (SceneError, SimulationError, ValueError) as exc:
        case["refused"] = _plain(f"{type(exc).__name__}: {exc}")
        return case
    except Exception as exc:     # a run that raised: said, and the batch goes on
        case["error"] = _plain(f"{type(exc).__name__}: {exc}")
        return case
    finally:
        ctx.__exit__(None, None, None)
        case["bench_cpu_s"] = time.process_time() - t0
        case["load_after"] = os.getloadavg()[0]
    best = cheapest_within(rows, ACCURACY)
    case["reference"] = {k: ref[k] for k in ("count", "peak", "exit_velocity", "cpu_time_s")}
    case["rows"] = [_row_dict(r) for r in rows]
    for kind in ("cosim", "monolithic"):
        r = best[kind]
        case[kind] = None if r is None else {"label": r.label, "step": _row_dict(r)["macro_step"],
                                             "rtol": _row_dict(r)["tolerance"],
                                             "cpu_s": r.cpu_time_s}
    ratio = best["ratio_monolithic"]
    case["ratio"] = None if math.isnan(ratio) else ratio
    case["verdict"] = verdict(case["ratio"])
    if best["cosim"] is not None:
        try:
            ov, scheme = _overrides(path, variant, best["cosim"], schemes)
            case["cosim_loop"] = loop_of(path, variant, ov, scheme)
        except (LookupError, SceneError, SimulationError) as exc:
            case["cosim_loop"] = {"loop": "-", "refusal": _plain(str(exc))}
    return case


def _num(x, spec) -> str:
    return "-" if x is None else format(x, spec)


def _choice(c) -> str:
    if c is None:
        return "none within 1 %"
    if c["step"] is not None:
        return f"{c['label']} {c['step'] * 1e6:g} µs"
    return f"{c['label']} rtol {c['rtol']:.0e}"


def _loop(c) -> str:
    lp = c.get("cosim_loop")
    if not lp:
        return "-"
    text = lp["loop"]
    if lp.get("compiled_share") is not None and lp["loop"] == "compiled":
        text += f" ({lp['compiled_share']:.0%} inside)"
    if lp.get("refusal"):
        text += f": {lp['refusal']}"
    if lp.get("us_per_step") is not None:
        text += f"; {lp['macro_steps']} steps, {lp['us_per_step']:.0f} µs each"
    return text.replace("|", "/")


def _why(c) -> str:
    """Why a row has no ratio."""
    if "refused" in c:
        return "bench does not apply: " + c["refused"].split(": ", 1)[-1].replace("|", "/")
    if "error" in c:
        return "bench stopped: " + c["error"].replace("|", "/")
    if c["cosim"] is None:
        return "no co-simulation row meets 1 %"
    return "no monolithic row meets 1 %"


HEAD = ("| scene | variant | cheapest co-simulation within 1 % | its CPU [s] | "
        "cheapest monolithic within 1 % | its CPU [s] | co-sim / mono | ≤ 1 | "
        "co-simulation's loop | load |")


def table(data: dict) -> str:
    """The Markdown table of a run's ``bench_ratio.json``."""
    lines = [HEAD, "|" + "---|" * HEAD.count(" | ") + "---|"]
    for c in data["cases"]:
        variant = (c["variant"] or "-") + (f" (`--contact {c['contact']}`)" if c["contact"]
                                           else "")
        load = f"{c['load_before']:.1f}"
        if "refused" in c or "error" in c:
            lines.append(f"| {c['scene']} | {variant} | {_why(c)} | - | - | - | - | - | - "
                         f"| {load} |")
            continue
        v = c["verdict"] if c["verdict"] != "no" else "**no**"
        ratio = _num(c["ratio"], ".2f") if c["ratio"] is not None else _why(c)
        co, mo = c["cosim"], c["monolithic"]
        lines.append(f"| {c['scene']} | {variant} | {_choice(co)} | "
                     f"{_num(co and co['cpu_s'], '.4f')} | {_choice(mo)} | "
                     f"{_num(mo and mo['cpu_s'], '.4f')} | {ratio} | {v} | {_loop(c)} | "
                     f"{load} |")
    return "\n".join(lines)


def totals(data: dict) -> dict:
    cases = data["cases"]
    return {"cases": len(cases), "refused": sum("refused" in c for c in cases),
            "errors": sum("error" in c for c in cases),
            "ratios": sum(c.get("ratio") is not None for c in cases),
            "met": sum(c.get("verdict") == "yes" for c in cases),
            "over": sum(c.get("verdict") == "no" for c in cases),
            "no_ratio": sum("refused" not in c and "error" not in c and c.get("ratio") is None
                            for c in cases)}


def readme(data: dict) -> str:
    t = totals(data)
    what = [w for w, there in (
        ("the shipped scenes", any(c["origin"] == "shipped" for c in data["cases"])),
        (f"{data['n']} generated scenes of seed {data['seed']}", data["n"] > 0)) if there]
    schemes = (f", the bench's `--schemes {data['schemes']}`" if data.get("schemes")
               else "")
    return (f"# co-simulation / monolithic CPU of `cosim bench`\n\n"
            f"`python benchmarks/bench_ratio.py {data['argv']}`: {' and '.join(what)}"
            f"{schemes}, each row on the scene and "
            f"{data['spread'] - 1} round-off copies, run on {data['machine']}, {data['date']}; "
            f"{data['cpu_s']:.0f} s of CPU in all, load average {data['load_start']:.1f} at "
            f"the start (a shared machine: the load column is the 1-minute load average as "
            f"each scene's bench began).\n\n"
            f"Each ratio is the bench's \"co-simulation / monolithic CPU\": the median solve "
            f"CPU of the cheapest co-simulation row whose every copy meets 1 % (the "
            f"reference's contact count, peak and exit velocity within 1 %) over that of the "
            f"cheapest monolithic row that does; target at most {TARGET:g}. The loop column "
            f"is one more run of the chosen co-simulation: the macro loop that took it "
            f"(and why not the compiled one), its macro steps and CPU per step.\n\n"
            f"{table(data)}\n\n"
            f"{t['cases']} scenes and variants: {t['refused']} refused by the bench, "
            + (f"{t['errors']} stopped by an error, " if t.get("errors") else "") +
            f"{t['no_ratio']} without a ratio, {t['ratios']} with one: {t['met']} at most "
            f"{TARGET:g}, {t['over']} over.\n")


def _machine() -> str:
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{cpu}, {os.cpu_count()} cores, Python {platform.python_version()}"


def _write(folder, data) -> None:
    folder.write("bench_ratio.json", lambda fh: json.dump(data, fh, indent=1), "w")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, default=6, help="how many generated scenes (default 6: "
                    "the first 6 cover every category of the generator)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--spread", type=int, default=3, help="the bench's --spread (default 3)")
    ap.add_argument("--only", default="", help="comma-separated scene names (shipped or "
                    "generated)")
    ap.add_argument("--schemes", default=None, help="the bench's --schemes, comma-separated "
                    "(default: the bench's own: the scene's scheme, gauss_seidel and implicit)")
    ap.add_argument("--no-shipped", action="store_true", help="the generated scenes alone")
    ap.add_argument("--out", default="runs/bench-ratio")
    ap.add_argument("--cache", default="runs/.bench-cache", help="the references' cache")
    ap.add_argument("--table", metavar="DIR", help="print (and rewrite DIR/README.md) the "
                    "table of a finished run")
    args = ap.parse_args(argv)
    from cosim.io.rundir import OutputFolder
    if args.table:
        data = json.loads((Path(args.table) / "bench_ratio.json").read_text())
        with OutputFolder(args.table) as folder:
            folder.write("README.md", lambda fh: fh.write(readme(data)), "w")
        print(readme(data))
        return 0
    if args.n < 0:
        ap.error(f"--n must be >= 0, got {args.n}")
    given = argv if argv is not None else sys.argv[1:]
    data = {"machine": _machine(), "date": datetime.datetime.now(datetime.timezone.utc)
            .strftime("%Y-%m-%d %H:%M UTC"), "argv": " ".join(given), "n": args.n,
            "seed": args.seed, "spread": args.spread, "accuracy": ACCURACY,
            "schemes": args.schemes,
            "load_start": os.getloadavg()[0], "cases": [], "cpu_s": 0.0}
    t0 = time.process_time()
    only = {s for s in args.only.split(",") if s}
    print(f"machine: {data['machine']}; load average {data['load_start']:.2f}", flush=True)
    with OutputFolder(args.out) as folder:
        todo = [] if args.no_shipped else [(n, p, v, None) for n, p, v in shipped_cases(only)]
        if args.n:
            from cosim.studies.generate import write_scenes
            paths = write_scenes(folder.path / "scenes", args.n, args.seed)
            with OutputFolder(folder.path / "scenes") as scenes:     # a former run's, gone
                for old in sorted(scenes.path.glob("*.toml")):
                    if old not in paths:
                        scenes.remove(old.name)
            todo += [(p.stem, str(p), None, "generated") for p in paths
                     if not only or p.stem in only]
        schemes = [x for x in args.schemes.split(",") if x] if args.schemes else None
        for name, path, variant, origin in todo:
            tries = [None] + ([CONTACTS[name]] if name in CONTACTS else [])
            for contact in tries:
                case = bench_case(name, path, variant, contact, args.spread, args.cache,
                                  origin or "shipped", schemes)
                data["cases"].append(case)
                data["cpu_s"] = time.process_time() - t0
                _write(folder, data)
                print(table({"cases": [case]}).splitlines()[-1], flush=True)
        data["load_end"] = os.getloadavg()[0]
        _write(folder, data)
        folder.write("README.md", lambda fh: fh.write(readme(data)), "w")
    print(readme(data))
    return 0


if __name__ == "__main__":
    sys.exit(main())

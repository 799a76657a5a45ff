"""The sub-commands of `cosim`: each ``_cmd_NAME(args)`` runs one and returns
its exit status (the parser in :mod:`cosim.cli.parser` names them)."""
from __future__ import annotations

import sys
from pathlib import Path

from cosim.cli.signals import _StopOnSignals, _stop_code
from cosim.cli.terminal import _frame_progress, _progress_line

__all__: list[str] = []


def _units(scene):
    """``units(SUBSYSTEM, NAME) -> (" m", " m/s")``: the units of a final
    state's q and dq, as the scene declares them: a prismatic joint's metres,
    a revolute joint's radians; a structure's rotation DOFs (``t0``, ``t1``,
    ... of a beam) in radians, its other DOFs (displacements) in metres; an
    FMU's coordinates without (their units are the FMU's)."""
    import re

    kinds = {}
    for spec in scene.subsystems:
        if spec.type == "multibody":
            kinds[spec.name] = {j.name: j.kind for j in spec.joints}
        elif spec.type not in ("fmu", "rigid"):
            kinds[spec.name] = "structure"

    def units(sub, name):
        kind = kinds.get(sub)
        if kind == "structure":
            kind = "revolute" if re.fullmatch(r"t\d+", name) else "prismatic"
        elif isinstance(kind, dict):
            kind = kind.get(name)
        return {"revolute": (" rad", " rad/s"), "prismatic": (" m", " m/s")}.get(kind, ("", ""))
    return units


def _print_summary(s: dict, out: Path | None, units=None) -> None:
    """The run's summary on the terminal.  ``units`` (:func:`_units`) puts
    the units after the final state's values."""
    e = s["energy"]
    print(f"scene {s['scene']}  scheme {s['scheme']}  status {s['status']}")
    print(f"  t_end {s['t_end']:.6g} s  cpu {s['cpu_time_s']:.3g} s  macro steps "
          f"{s['macro_steps']}  iterations {s['iterations']}")
    for name, c in s["contacts"].items():
        first = c["intervals"][0] if c["intervals"] else None
        span = f"first [{first[0]:.6g}, {first[1]:.6g}] s" if first else "never touched"
        print(f"  contact {name}: {c['count']} interval(s), {span}, peak penetration "
              f"{c['peak_penetration']:.4g} m, impulse {c['impulse']:.4g} N s")
        if c["count"] > 1:
            t0, t1 = c["intervals"][0][0], c["intervals"][-1][1]
            print(f"    first touch {t0:.6g} s, last release {t1:.6g} s (span {t1 - t0:.6g} s, "
                  f"in touch {c['in_touch_time']:.6g} s)")
    supplied = e.get("supplied", 0.0)
    expected = e["initial"] + supplied - e["dissipated"]
    print(f"  energy: initial {e['initial']:.6g} J + supplied {supplied:.6g} J - dissipated "
          f"{e['dissipated']:.6g} J = {expected:.6g} J; final {e['final']:.6g} J (drift "
          f"{e['final'] - expected:.3g} J at the end, at most {e['max_abs_drift']:.3g} J)")
    for w in s.get("warnings", []):
        print(f"  warning: {w['message']}")
    for imp in s["impacts"]:
        vn, vt = imp["normal_velocity"], imp["tangential_velocity"]
        slip = " -> ".join(m for _, _, m in imp["slip_history"]) or "frictionless"
        print(f"  impact {imp['contact']} at t = {imp['time']:.6g} s: normal impulse "
              f"{imp['normal_impulse']:.5g} N s (compression {imp['compression_impulse']:.5g}), "
              f"tangential {imp['tangential_impulse']:.5g} N s")
        print(f"    contact velocity normal {vn[0]:.5g} -> {vn[1]:.5g} m/s, tangential "
              f"{vt[0]:.5g} -> {vt[1]:.5g} m/s; slip: {slip}"
              + (f" ({imp['slip_end']})" if imp["slip_end"] else ""))
        after = ", ".join(f"{k} {v:.5g}" for k, v in imp["dq_after"].items())
        print(f"    joint velocities after [rad/s]: {after}")
    for sw in s.get("switches", []):
        print(f"  switch {sw['contact']} at t = {sw['time']:.6g} s: {sw['from']} -> {sw['to']}")
    if s["final_state"]:
        print("  final state (q, and its rate dq):")
    for sub, joints in s["final_state"].items():
        if len(joints) > 12:
            print(f"    {sub}: {len(joints)} DOFs (in summary.json)")
            continue
        for j, v in joints.items():
            q, dq = units(sub, j) if units is not None else ("", "")
            print(f"    {sub}/{j}: q = {v['q']:.6g}{q}, dq = {v['dq']:.6g}{dq}")
    if "accuracy" in s:
        from cosim.studies.estimate import accuracy_text
        print(f"  {accuracy_text(s['accuracy'])}")
        if "request" in s["accuracy"]:
            from cosim.studies.accurate import request_text
            print("\n".join(f"  {line}" for line in request_text(s["accuracy"]["request"])))
    if s["message"] and s["status"] == "finished":
        print(f"  message: {s['message']}")      # a run that did not finish says it once, below
    if out is not None:
        print(f"  wrote {out / 'summary.json'}, {out / 'series.npz'} and {out / 'scene.toml'}")


def _estimate(scene, res, out, request=None):
    """:func:`cosim.cli.accuracy.estimate_and_check`."""
    from cosim.cli.accuracy import estimate_and_check
    return estimate_and_check(scene, res, out, request)


def _outcome(summary: dict) -> int:
    """:func:`cosim.cli.accuracy.exit_status` of a run asked for an
    accuracy; 0 for any other (which imports nothing more)."""
    if summary.get("accuracy", {}).get("request") is None:
        return 0
    from cosim.cli.accuracy import exit_status
    return exit_status(summary)


def _default_name(scene) -> str:
    """``SCENE[-VARIANT][-SCHEME]`` (:func:`cosim.io.rundir.run_folder_name`):
    the scheme named when it is not the one the scene (with its variant)
    gives, whether `--scheme` or `--set scheme.name=` chose it."""
    import re

    from cosim.core.result import written_by_a_run
    from cosim.io.rundir import name_problem, run_folder_name
    from cosim.scene.read import read_scene

    own, _ = read_scene(scene.path, scene.variant)
    table = own.get("scheme")
    own_scheme = table.get("name") if isinstance(table, dict) else None
    scheme = scene.scheme if scene.scheme != own_scheme else None
    run = Path(scene.path).resolve().parent.name
    if written_by_a_run(scene.path) and name_problem(run) is None:
        # a run's scene.toml again: named after that run (its variant is in its name)
        return run_folder_name(re.sub(r"-\d+$", "", run), None, scheme)
    return run_folder_name(scene.name, scene.variant, scheme)


def _cmd_run(args) -> int:
    with _StopOnSignals():
        return _run(args)


def _run(args) -> int:
    from cosim.errors import PluginError
    from cosim.io.rundir import fresh_folder
    from cosim.scene.run import RunInterrupted, simulate
    from cosim.scene.load import load_scene

    scene = load_scene(args.scene, args.variant, args.set or (), args.scheme)
    request = None
    table = scene.data.get("scheme")
    if args.accuracy is not None or isinstance(table, dict) and "accuracy" in table:
        from cosim.cli.accuracy import Request
        request = Request.make(args, scene)      # the scene with the steps chosen for it
        scene = request.scene
    made = None                 # a default folder, new: removed again if the run is refused
    if args.out:
        out = Path(args.out)
    elif args.overwrite:                # the default folder itself, its run replaced
        out = Path("runs") / _default_name(scene)
    else:                               # a new folder: a run again never meets the one before
        out = made = fresh_folder("runs", _default_name(scene))
    progress = _progress_line(args.quiet)
    code, crash = None, None
    if request is not None:
        request.run = lambda sc, where: simulate(sc, progress=_progress_line(args.quiet),
                                                 out=where, overwrite=True)
    try:
        res = simulate(scene, progress=progress, out=out, overwrite=args.overwrite)
    except RunInterrupted as exc:
        res, code = exc.result, _stop_code(exc.__cause__)
    except Exception as exc:
        res = getattr(exc, "partial_result", None)
        if res is None:
            raise
        code, crash = 1, exc
    finally:
        if progress is not None:
            progress.close()
        if made is not None and made.is_dir() and not any(made.iterdir()):
            made.rmdir()
    if res.status == "finished" and (request is not None or scene.estimate
                                     and not args.no_estimate):
        try:
            res = _estimate(scene, res, out, request)
        except RunInterrupted as exc:      # the run is kept as it finished, without estimate
            code = _stop_code(exc.__cause__)
        if request is not None and request.stopped is not None:
            code = _stop_code(request.stopped)       # the refinement's: the first run kept
    _print_summary(res.summary, out, _units(scene))
    for name in scene.export:
        print(f"  wrote {out / (name + '.xdmf')} (open in ParaView)")
    if res.status != "finished":
        message = res.message.rstrip()
        print(f"error: the run did not finish ({res.status}): {message}"
              f"{'' if message.endswith('.') else '.'} Its series and summary up to "
              f"t = {res.summary['t_end']:.6g} s are in {out}", file=sys.stderr)
    if isinstance(crash, PluginError):  # an installed plug-in failed, said above: not cosim
        return 2
    if crash is not None:
        import traceback
        traceback.print_exception(crash, file=sys.stderr)
        print("error: this is a bug of cosim, not of the scene: please report it with the "
              "scene file and the lines above", file=sys.stderr)
    if code is not None:
        return code
    if not res.success:
        return 1
    return _outcome(res.summary)


def _cmd_verify(args) -> int:
    from cosim.studies.verify import run_checks

    if args.scene is not None:
        if args.cases is not None or args.hard:
            return _usage("--cases and --hard run the verification cases: give them "
                          "without a SCENE")
        from cosim.scene.load import load_scene
        from cosim.studies.verify_scene import scene_checks
        scene = load_scene(args.scene, args.variant, args.set or (), args.scheme)
        return _report(scene_checks(scene))
    if args.variant or args.set or args.scheme:
        return _usage("--variant, --set and --scheme apply to a SCENE: give one")
    cases = args.cases
    if cases is None:                   # the scenes cosim ships, from any folder
        from cosim.scene.shipped import shipped_folder
        cases = shipped_folder("cases") or "cases"
        return _report(run_checks(cases, hard=args.hard))
    from cosim.studies.verify import folder_checks
    return _report(folder_checks(cases, hard=args.hard))


def _usage(message: str) -> int:
    print(f"error: cosim verify: {message}", file=sys.stderr)
    return 2


def _report(checks) -> int:
    """Print one line per check (PASS, FAIL or SKIP) and the tally; exit 1
    if any failed."""
    failed = skipped = 0
    for check in checks:
        failed += not check.passed
        skipped += check.skipped
        word = "SKIP" if check.skipped else "PASS" if check.passed else "FAIL"
        print(f"{word}  {check.name}: {check.detail}", flush=True)
    tail = f" ({skipped} skipped)" if skipped else ""
    print(f"{'all checks passed' if not failed else f'{failed} check(s) failed'}{tail}")
    return 1 if failed else 0


def _fmt(v):
    if v is None:
        return "not limited"
    return f"{v:.4g}" if isinstance(v, float) else str(v)


def _cmd_info(args) -> int:
    from cosim.io.strict_json import dumps
    from cosim.scene.info import scene_info
    from cosim.scene.load import load_scene

    if args.list or args.scene is None:
        return _list_scenes(args)
    scene = load_scene(args.scene, args.variant, args.set or ())
    info = scene_info(scene, run_fmu=args.run_fmu)
    table = scene.data.get("scheme")
    if args.accuracy is not None or isinstance(table, dict) and "accuracy" in table:
        from cosim.studies.accurate import asked
        accuracy, source = asked(scene, args.accuracy)
        from cosim.studies.choose import choose
        info["accuracy"] = {"from": source, **choose(scene, accuracy, source=source).as_dict()}
    if args.json:
        print(dumps(info, indent=2))        # strict: a value not finite as null, noted
        return 0
    print(f"scene {info['scene']}" + (f"  variant {info['variant']}" if info["variant"] else "")
          + f"  scheme {info['scheme']}  t_end {info['t_end']:g} s")
    _print_variants(info)
    work = info["work"]
    print(f"  work: {work['bound']} {work['steps']:.3g} integrator steps ({work['how']})")
    for name, s in info["subsystems"].items():
        line = f"  subsystem {name}: {s['type']}, {s['dofs']} DOF"
        if "modes_kept" in s:
            line += f" ({s['modes_kept']} modes kept, {s['modes_dropped']} dropped)"
        if "natural_frequencies_hz" in s:
            line += ", lowest frequencies [Hz] " + ", ".join(
                f"{f:.4g}" for f in s["natural_frequencies_hz"][:6])
        print(line)
        for r in s.get("mode_rule", ()):      # a plane body's modes against a contact
            print(f"    modes to {r['kept_to_hz']:.4g} Hz: {r['ratio']:.3g} x contact "
                  f"{r['contact']}'s {r['frequency_hz']:.4g} Hz ({r['verdict']}; 10 x or more "
                  f"wanted), static correction {'on' if r['static_correction'] else 'off'}"
                  + (f", dropped modes {r['dropped_share']:.2g} of its compliance (1e-2 or "
                     f"less wanted)" if "dropped_share" in r else ""))
        if "fmu" in s:                  # an FMU side: its variables (cosim.scene.info.fmu_info)
            f = s["fmu"]                # (its texts escaped and capped there)
            print(f"    model {f['model_name']}"
                  + (f", generated by {f['generation_tool']}" if f["generation_tool"] else "")
                  + (f": {f['description']}" if f["description"] else ""))
            for pname, pm in f["port_mass"].items():
                mass = "unknown until the FMU runs" if pm["kg"] is None else f"{pm['kg']:.4g} kg"
                print(f"    port {pname}: mass {mass}"
                      + (f" (output {pm['variable']})" if pm["variable"] else ""))
            print(f"    FMU {f['file']} (FMI {f['fmi_version']}), get/set state "
                  f"{'yes' if f['can_get_set_state'] else 'no'}, variables:")
            for v in f["variables"]:
                start = "" if v["start"] is None else f" = {v['start']}"
                unit = f" [{v['unit']}]" if v["unit"] else ""
                print(f"      {v['name']}{start}{unit}: {v['causality']} {v['variability']} "
                      f"{v['type']}" + (f", {v['description']}" if v["description"] else ""))
    for w in info.get("warnings", []):
        print(f"  warning: {w['message']}")
    for name, c in info["contacts"].items():
        where = c["placement"] + (f" in {c['host']}" if "host" in c else "")
        print(f"  contact {name}: {c['law']} ({where}) between {c['between'][0]} and "
              f"{c['between'][1]}")
        pose = c.get("pose")
        if pose is not None:
            where = (f"at its first touch, t = {pose['t']:.6g} s" if pose["at"] == "first touch"
                     else f"at the initial pose ({pose['why']})")
        if c.get("frequency_hz") is not None:
            print(f"    reduced mass {c['reduced_mass']:.4g} kg, frequency {c['frequency_hz']:.4g}"
                  f" Hz, contact time {c['contact_time_s']:.4g} s, {where}")
            if "initial_pose" in c:
                p0 = c["initial_pose"]
                print(f"    at the initial pose: reduced mass {p0['reduced_mass']:.4g} kg, "
                      f"frequency {p0['frequency_hz']:.4g} Hz, contact time "
                      f"{p0['contact_time_s']:.4g} s (the stable steps below are judged there)")
            kinds = c.get("max_macro_step_kind", {})
            print("    largest stable macro step [s]: " + ", ".join(
                f"{k} {_fmt(v)}" + (f" ({kinds[k]})" if kinds.get(k) else "")
                for k, v in c["max_macro_step_s"].items()))
            for k, why in c.get("max_macro_step_why", {}).items():
                print(f"    {k}: necessary bound only, not a step known to run: {why}")
            if "max_integrator_step_s" in c:
                print("    largest stable integrator step [s]: " + ", ".join(
                    f"{k} {_fmt(v)}" for k, v in c["max_integrator_step_s"].items()))
            if "sampling_interval_s" in c:
                print(f"    output sampling every {c['sampling_interval_s']:.4g} s: "
                      f"{c['samples_per_contact']:.3g} samples per contact")
            if "sampling_note" in c:
                print(f"    note: {c['sampling_note']}")
        elif "not_evaluated" in c:      # what only an FMU's code could tell
            print(f"    not evaluated: {c['not_evaluated']}")
        elif pose is not None:          # a nonlinear law without a linearisation
            print(f"    reduced mass {c['reduced_mass']:.4g} kg, {where}")
    if any("fmu" in s for s in info["subsystems"].values()):
        print("  FMU code " + ("run (--run-fmu)" if info["fmu_code_run"] else
                               "not run: read from modelDescription.xml alone "
                               "(--run-fmu runs it)"))
    if "accuracy" in info:
        _print_accuracy(info["accuracy"])
    return 0


def _print_accuracy(a: dict) -> None:
    """The choice of :func:`cosim.studies.choose.choose`, as ``cosim info`` prints it."""
    print(f"  accuracy {a['accuracy'] * 100:.3g} % ({a['from']}): scheme {a['scheme']} "
          + " ".join(f"--set {o}" for o in a["overrides"]))
    err = a["predicted_error"]
    print(f"    predicted error: peak {err['peak'] * 100:.2g} %, exit velocity "
          f"{err['exit_velocity'] * 100:.2g} %; work {a['work_steps']:.3g} integrator steps, "
          f"about {a['predicted_cpu_s']:.2g} s of CPU")
    print(f"    why: {a['why']}")
    if a.get("caveat"):
        print(f"    note: {a['caveat']}")


def _print_variants(info: dict) -> None:
    """The scene's variants, one line each with the keys it sets."""
    from cosim.io.tomlwrite import value_text

    variants = info["variants"]
    if not variants:
        return
    default = info["default_variant"]
    print(f"  variants ({len(variants)}; --variant NAME"
          + (f", default {default}" if default else "") + "):")
    for name, sets in variants.items():
        what = "; ".join(f"{k} = {value_text(v)}" for k, v in sets.items()) or "the scene as written"
        print(f"    {name}{' (run here)' if name == info['variant'] else ''}: {what}")


def _list_scenes(args) -> int:
    """`cosim info` without a scene, or `--list`: the scenes cosim ships."""
    from cosim.io.strict_json import dumps
    from cosim.scene.shipped import shipped_list

    if args.variant or args.set or args.run_fmu:
        print("error: --variant, --set and --run-fmu need a SCENE", file=sys.stderr)
        return 2
    scenes = shipped_list()
    if args.json:
        print(dumps(scenes, indent=2))
        return 0
    width = max((len(s["name"]) for s in scenes), default=0)
    print(f"{len(scenes)} scenes ship with cosim (`cosim run NAME`, `cosim info NAME` for "
          f"one; the variants in brackets, the default first):")
    for s in scenes:
        names = s["variants"]
        if s["default_variant"] in names:
            names = [s["default_variant"]] + [v for v in names if v != s["default_variant"]]
        print(f"  {s['name']:<{width}}  {s['description']}"
              + (f" [{', '.join(names)}]" if names else ""))
    return 0


def _cmd_bench(args) -> int:
    """`cosim bench`, in :mod:`cosim.cli.bench_command` (loaded when run)."""
    from cosim.cli.bench_command import _cmd_bench as bench
    return bench(args)


def _cmd_plot(args) -> int:
    try:
        from cosim import plot
    except ImportError as exc:
        if (exc.name or "").split(".")[0] != "matplotlib":
            raise
        print('error: `cosim plot` needs matplotlib: pip install "cosim[plot]"', file=sys.stderr)
        return 2
    try:
        run = plot.load_run(args.run_dir)
        paths = plot.plot_run(run, args.out, args.format)
        if args.animate:
            bar = _frame_progress(args.quiet)
            try:
                paths.append(plot.animate_run(run, args.out, max_frames=args.frames,
                                              magnify=args.magnify, progress=bar))
            finally:
                if bar is not None:
                    bar.close()
    except plot.PlotError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if run.incomplete:
        print(f"incomplete run: {run.incomplete}")
    if run.not_finite:
        from cosim.errors import shown
        print(f"note: {len(run.not_finite)} series hold values that are not finite, left out "
              f"of the lines drawn: {shown(', '.join(run.not_finite))}")
    for path in paths:
        print(f"wrote {path}")
    return 0


def _cmd_sweep(args) -> int:
    """`cosim sweep`, in :mod:`cosim.cli.sweep_command` (loaded when run)."""
    from cosim.cli.sweep_command import _cmd_sweep as sweep
    return sweep(args)

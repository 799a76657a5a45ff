"""`cosim bench`: the scene, its strike and the options checked before any
run, the bench's folder held from its first row to its figure, the table
printed row by row (:mod:`cosim.studies.bench` does the work)."""
from __future__ import annotations

import contextlib
import sys
from pathlib import Path

__all__: list[str] = []


def _machine() -> str:
    import os
    import platform
    return (f"{platform.machine()} {platform.processor() or ''}".strip()
            + f", {os.cpu_count()} cores, Python {platform.python_version()}, "
            f"{platform.system()} {platform.release()}")


def _check_scheme(name: str, option: str) -> None:
    """Refuse, before any work, a scheme name no scheme (shipped or an
    installed plug-in) has: a ValueError naming ``option``
    and the schemes known."""
    from cosim.core.plugins import provide
    from cosim.core.schemes import COUPLING_SCHEMES
    from cosim.errors import shown
    provide(COUPLING_SCHEMES, "cosim.schemes", name)        # an installed plug-in
    if name not in COUPLING_SCHEMES:
        raise ValueError(f"{option}: no scheme is named {shown(repr(name))}; the schemes are "
                         f"{sorted(COUPLING_SCHEMES)}")


def _cmd_bench(args) -> int:
    from cosim.io.rundir import OutputFolder
    from cosim.scene.shipped import scene_file
    from cosim.studies.strike import find_strike

    args.scene = scene_file(args.scene)     # a path, or the name of a shipped scene
    try:
        for scheme in args.schemes or ():
            _check_scheme(scheme, "--schemes")
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    # the contact and joint compared, as `cosim sweep` chooses them: checked
    # (and a scene that leaves no single choice refused, naming its contacts)
    # before a folder is made or anything runs
    args.contact, args.joint = find_strike(args.scene, args.contact, args.joint,
                                           variant=args.variant)
    from cosim.scene.load import load_scene
    load_scene(args.scene, args.variant, args.set or ())     # --set, read before any run
    out = Path(args.out) if args.out else Path("runs") / (
        Path(args.scene).stem + (f"-{args.variant}" if args.variant else "") + "-bench")
    # the folder is opened (a link or a file at its place refused) and locked
    # before anything runs, and held until the last file is written
    folder = OutputFolder(out).open()
    wrote = False
    try:
        wrote = _bench(args, folder)
    finally:
        folder.close()
        if folder.created and not wrote:      # made for a bench that wrote nothing
            with contextlib.suppress(OSError):
                out.rmdir()
    return 0


def _bench(args, folder) -> bool:
    """The bench of :func:`_cmd_bench` into the open, locked ``folder``;
    whether it wrote its files."""
    import math

    from cosim.studies.bench import cheapest_within, run_bench, write_csv, write_reference
    from cosim.studies.bench_plot import plot

    out = folder.path
    spread = args.spread
    from cosim.errors import shown
    print(f"bench {shown(str(args.scene), 500)}"
          + (f" --variant {args.variant}" if args.variant else "")
          + f" on {_machine()}")
    print(f"contact {args.contact}, exit velocity of joint {args.joint}")
    print(f"each row: the scene and {spread - 1} round-off copies; errors median / worst, "
          f"contact counts min-max, CPU median" if spread > 1 else "each row: one run")
    print(f"{'scheme':<14}{'step [s]':>10}{'rtol':>9}{'CPU [s]':>9}{'peak':>20}{'contacts':>9}"
          f"{'exit vel.':>20}{'energy':>20}  status")

    def fmt(x, spec):
        width = int(spec.split(".")[0])
        return "-".rjust(width) if isinstance(x, float) and math.isnan(x) else format(x, spec)

    def band(med, worst):
        if math.isnan(med):
            return "-".rjust(20)
        return (f"{med:.2e} / {worst:.2e}" if spread > 1 else f"{med:.2e}").rjust(20)

    def show(r):
        counts = ("-" if math.isnan(r.count_min) else f"{r.count_min:.0f}"
                  if r.count_min == r.count_max else f"{r.count_min:.0f}-{r.count_max:.0f}")
        print(f"{r.label:<14}{fmt(r.macro_step, '10.1e')}{fmt(r.tolerance, '9.0e')}"
              f"{fmt(r.cpu_time_s, '9.2f')}{band(r.err_peak, r.err_peak_worst)}{counts:>9}"
              f"{band(r.err_exit_velocity, r.err_exit_velocity_worst)}"
              f"{band(r.err_energy, r.err_energy_worst)}  {r.status}", flush=True)

    ref, rows = run_bench(args.scene, args.variant, args.schemes, args.steps, args.contact,
                          args.joint, args.set or (), cache_dir=Path("runs") / ".bench-cache",
                          progress=show, spread=spread)
    print(f"reference (monolithic DOP853, rtol 1e-11, one run): {ref['count']} contacts of "
          f"{args.contact}, peak {ref['peak']:.6g} m, exit velocity {ref['exit_velocity']:.6g}, "
          f"CPU {ref['cpu_time_s']:.2f} s")
    zero = [what for key, what in (("peak", "peak"), ("exit_velocity", "exit velocity"))
            if ref[key] == 0]
    if zero:            # a rigid contact's peak: no relative error to give
        print(f"note: the reference's {' and '.join(zero)} is 0: no relative error; a row's "
              f"error is 0 where its value is 0 too, else `-`")
    best = cheapest_within(rows, 0.01)
    print("cheapest within 1 % (exact count; peak and exit velocity within 1 %"
          + (", every copy" if spread > 1 else "") + "):")
    for kind in ("cosim", "monolithic", "paper_rk45"):
        r = best[kind]
        print(f"  {kind:<11}" + ("none" if r is None else
                                 f"{r.label} {fmt(r.macro_step, '1.1e').strip()} "
                                 f"{fmt(r.tolerance, '1.0e').strip()}: {r.cpu_time_s:.2f} s"))
    if best["cosim"] is not None:
        print(f"  co-simulation / monolithic CPU {best['ratio_monolithic']:.2f}, "
              f"/ paper_rk45 CPU {best['ratio_paper_rk45']:.2f}")
    write_csv(rows, "bench.csv", folder)
    write_reference(ref, "reference.json", folder)
    print(f"wrote {out / 'bench.csv'} and {out / 'reference.json'}")
    try:
        plot(rows, "bench.png", title=f"{Path(args.scene).stem} {args.variant or ''}",
             folder=folder)
        print(f"wrote {out / 'bench.png'}")
    except ImportError:
        print('no plot: matplotlib is not installed (pip install "cosim[plot]")',
              file=sys.stderr)
    return True

"""What a plane body costs: its set-up (read, assemble, modes, a cached
re-run) at about 8k, 33k and 130k DOF, and its step against the 1-D beam's
with the same number of modes.

Set-up: the clamped steel strip 1 m x 0.1 m (plane stress, P2 triangles, the
left edge fixed) on 100 x 10, 200 x 20 and 400 x 40 squares each cut in two,
written as a Gmsh 2.2 file.  Per size, wall and CPU (process time) of

- *read*: :func:`fem.plane.read_mesh` (meshio and every check of the file);
- *assemble*: :meth:`fem.plane.Plane.assemble` (scikit-fem, ``M`` and ``K``);
- *factor*: the sparse LU of ``K`` the eigen-solve inverts with (timed on
  its own, then again inside *modes*);
- *modes*: :func:`fem.modes` for the lowest 20 and 50 modes (scipy's
  ``eigsh`` in shift-invert about 0, on one OpenBLAS thread as cosim runs it:
  :mod:`fem.blas_threads`; the decompositions kept in the process are
  forgotten first), with the number of solves ARPACK asked for; then the 50
  modes again with OpenBLAS's threads as the machine gives them
  (``COSIM_BLAS_THREADS=keep``), and on one thread once more, side by side;
- *cached re-run*: a second run's whole set-up with the modal cache filled
  by the first (:func:`fem.plane.cache.cached_modes`): read, assemble and
  the cache entry read back.

Step: beam_impact (the 1-D beam, 32 elements, C's point held in place as
a plane body's is: ``contacts.C.follow = false``) and its 2-D twin
beam_impact_2d (the same beam meshed in the plane, 100 x 2 x 2 P2
triangles), both with ``modes = { count = N }``, run whole; per macro step,
the CPU of the run's solve (the summary's ``cpu_time_s``, compiled loop)
and of the structure's own steps (``StructureSubsystem._step_impl`` timed
in the Python loop), best of ``--repeat`` runs.

BLAS runs on the threads the machine gives it (targets are for 2 cores):
``--blas-threads`` sets them before numpy loads.  The machine is shared, so
the load average is written with the run.

Run from the project root::

    python benchmarks/plane_setup.py [--quick] [--repeat 3] [--out DIR]

``--out DIR`` writes ``DIR/plane_setup.json`` through cosim's checked
writer; ``python benchmarks/plane_setup.py --table DIR`` prints the Markdown
tables of such a run as docs/performance.md shows them; the published run is
in ``benchmarks/results/plane_setup``.
"""
from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import sys

if __name__ == "__main__" and "--blas-threads" in sys.argv:   # before numpy loads
    for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[_v] = sys.argv[sys.argv.index("--blas-threads") + 1]

import tempfile
import time
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: label -> squares along and across the strip
SIZES = {"8k": (100, 10), "33k": (200, 20), "130k": (400, 40)}
QUICK = {"8k": (100, 10)}
MODES = (20, 50)
#: the mode counts of the step comparison (the 1-D beam of 32 elements has 64 DOFs)
STEP_MODES = (16, 48)
STRIP = dict(thickness=0.01, youngs_modulus=210e9, poisson_ratio=0.3, density=7850.0,
             model="plane_stress", element="P2", fixed=("left",))


def _clock():
    return time.perf_counter(), time.process_time()


def _since(t0) -> list:
    w, c = _clock()
    return [w - t0[0], c - t0[1]]


def write_strip(path, nx: int, ny: int) -> Path:
    """The strip 1 m x 0.1 m on ``nx`` x ``ny`` squares as a Gmsh 2.2 file."""
    sys.path.insert(0, str(ROOT / "tests"))
    try:
        from plane_files import write_msh
    finally:
        sys.path.pop(0)
    from fem.plane import rectangle
    return Path(write_msh(str(path), rectangle(1.0, 0.1, nx, ny), name="strip"))


class _CountingSolves:
    """Counts the solves of the shift-invert operator (ARPACK's matvecs)."""

    def __enter__(self):
        import fem.modal as modal
        self.modal, self.orig, self.n, self.factor = modal, modal._elastic_solver, 0, 0.0
        clock = self

        def counted(structure):
            t0 = time.perf_counter()
            solve = clock.orig(structure)
            clock.factor += time.perf_counter() - t0

            def wrapped(b):
                clock.n += 1
                return solve(b)
            return wrapped

        modal._elastic_solver = counted
        return self

    def __exit__(self, *exc):
        self.modal._elastic_solver = self.orig


def setup_point(label: str, nx: int, ny: int, folder: Path, threads: bool = True) -> dict:
    """The set-up figures of one strip size (``threads``: the 50 modes again
    with OpenBLAS's threads kept, and on one thread once more)."""
    from cosim.io.rundir import OutputFolder
    from fem.modal import _elastic_solver, clear_solved, modes
    from fem.plane import Plane
    from fem.plane.cache import cached_modes

    path = write_strip(folder / f"strip_{label}.msh", nx, ny)
    out = {"label": label, "squares": [nx, ny]}
    plane = Plane(mesh=str(path), **STRIP)
    t0 = _clock()
    mesh = plane.read()
    out["read"] = _since(t0)
    t0 = _clock()
    s = plane.assemble(mesh)
    out["assemble"] = _since(t0)
    out["dofs"] = int(s.n_dof)
    t0 = _clock()
    _elastic_solver(s)
    out["factor"] = _since(t0)
    for m in MODES:
        clear_solved()
        with _CountingSolves() as count:
            t0 = _clock()
            basis = modes(s, n_modes=m)
            out[f"modes{m}"] = _since(t0)
        out[f"modes{m}_solves"] = count.n
        out[f"modes{m}_factor_wall"] = count.factor
        out[f"modes{m}_top_hz"] = float(basis.frequencies_hz[-1])
    # the same 50 modes with OpenBLAS's threads as the machine gives them
    # (COSIM_BLAS_THREADS=keep), then on one thread again: the two side by
    # side under the same load
    for key, keep in (("modes50_keep", True), ("modes50_again", False)) if threads else ():
        clear_solved()
        os.environ["COSIM_BLAS_THREADS"] = "keep" if keep else ""
        try:
            t0 = _clock()
            modes(s, n_modes=MODES[-1])
            out[key] = _since(t0)
        finally:
            os.environ.pop("COSIM_BLAS_THREADS", None)
    out["f1_hz"] = float(basis.frequencies_hz[0])
    # the cache: filled by a first run (50 modes), then a second run's set-up
    m = MODES[-1]
    with OutputFolder(folder / f"cache_{label}", lock=False) as cache:
        clear_solved()
        _, hit = cached_modes(s, cache, n_modes=m)
        assert not hit
        clear_solved()
        t0 = _clock()
        again = Plane(mesh=str(path), **STRIP)
        s2 = again.assemble(again.read())
        basis2, hit = cached_modes(s2, cache, n_modes=m)
        out["cached_rerun"] = _since(t0)
        if not hit:
            raise RuntimeError("the second run missed the modal cache")
    return out


def _StructureClock():
    """size_scaling's clock of the structure's own steps (the Python macro
    loop, with ``StructureSubsystem._step_impl`` timed), loaded from the
    script beside this one."""
    import importlib.util
    path = Path(__file__).with_name("size_scaling.py")
    spec = importlib.util.spec_from_file_location("size_scaling_bench", path)
    mod = sys.modules.get(spec.name)
    if mod is None:
        mod = importlib.util.module_from_spec(spec)
        sys.modules[spec.name] = mod        # its dataclasses look their module up
        spec.loader.exec_module(mod)
    return mod._StructureClock()


def _scene(which: str, n_modes: int, cache: Path):
    import cosim
    if which == "beam":
        # C's point held where it first touches, as a plane body's port is
        return cosim.load_scene(ROOT / "cases" / "beam_impact.toml",
                                overrides=[f"subsystems.beam.modes={{count={n_modes}}}",
                                           "contacts.C.follow=false"])
    return cosim.load_scene(ROOT / "cases" / "beam_impact_2d.toml", overrides=[
        f"subsystems.beam.modes={{count={n_modes}, static_correction=true, "
        f"cache={json.dumps(str(cache))}}}"])


def step_point(which: str, n_modes: int, repeat: int, cache: Path) -> dict:
    """Per macro step: the solve's CPU (compiled loop) and the structure's
    steps' CPU (Python loop), best of ``repeat`` runs."""
    import cosim
    solve, struct, steps = [], [], 0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = _scene(which, n_modes, cache)
        cosim.simulate(scene, estimate=False)          # not counted: caches, first calls
        for _ in range(repeat):
            res = cosim.simulate(scene, estimate=False)
            steps = int(res.summary["macro_steps"])
            solve.append(float(res.summary["cpu_time_s"]) / steps)
        for _ in range(repeat):
            with _StructureClock() as clock:
                res = cosim.simulate(scene, estimate=False)
            struct.append(clock.total / int(res.summary["macro_steps"]))
        system, _ = scene.build()
    sub = next(s for s in system.subsystems if s.name == "beam")
    c = res.summary["contacts"]["C"]
    return {"structure": which, "modes": int(sub.n_modes), "dofs": int(sub.structure.n_dof),
            "macro_steps": steps, "solve_per_step_s": min(solve),
            "structure_per_step_s": min(struct), "contacts_C": int(c["count"])}


def _ms(pair) -> str:
    return f"{1e3 * pair[0]:.0f}" if pair[0] >= 0.1 else f"{1e3 * pair[0]:.1f}"


def table(data: dict) -> str:
    """The Markdown tables of a run's ``plane_setup.json``: set-up (wall [ms])
    and step cost."""
    lines = ["| DOFs | read | assemble | factor | 20 modes (solves) | 50 modes (solves) "
             "| 50 modes, BLAS threads kept / one again | cached re-run |",
             "|---|---|---|---|---|---|---|---|"]
    for p in data["setup"]:
        lines.append(f"| {p['dofs']} | {_ms(p['read'])} | {_ms(p['assemble'])} "
                     f"| {_ms(p['factor'])} | {_ms(p['modes20'])} ({p['modes20_solves']}) "
                     f"| {_ms(p['modes50'])} ({p['modes50_solves']}) "
                     f"| {_ms(p['modes50_keep'])} / {_ms(p['modes50_again'])} "
                     f"| {_ms(p['cached_rerun'])} |")
    lines += ["", "| modes | beam: solve / structure [us per step] | plane: solve / structure "
              "[us per step] | ratio solve / structure |", "|---|---|---|---|"]
    by = {(p["structure"], p["modes"]): p for p in data["step"]}
    for m in sorted({p["modes"] for p in data["step"]}):
        b, q = by[("beam", m)], by[("plane", m)]
        lines.append(f"| {m} | {1e6 * b['solve_per_step_s']:.1f} / "
                     f"{1e6 * b['structure_per_step_s']:.1f} | {1e6 * q['solve_per_step_s']:.1f}"
                     f" / {1e6 * q['structure_per_step_s']:.1f} | "
                     f"{q['solve_per_step_s'] / b['solve_per_step_s']:.2f} / "
                     f"{q['structure_per_step_s'] / b['structure_per_step_s']:.2f} |")
    return "\n".join(lines)


def machine() -> str:
    threads = os.environ.get("OPENBLAS_NUM_THREADS", "default")
    return (f"{platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}, "
            f"{platform.system()} {platform.release()}, BLAS threads {threads}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="the smallest size only")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--out", default=None, help="write DIR/plane_setup.json")
    ap.add_argument("--table", metavar="DIR", help="print the tables of a finished run")
    ap.add_argument("--blas-threads", default=None, help="BLAS threads (set before numpy)")
    ap.add_argument("--skip-step", action="store_true", help="set-up only")
    args = ap.parse_args(argv)
    if args.table:
        with open(os.path.join(args.table, "plane_setup.json"), encoding="utf-8") as fh:
            print(table(json.load(fh)))
        return 0
    load = [os.getloadavg()[0]]
    print(f"machine: {machine()}, load average {load[0]:.1f}", flush=True)
    data = {"machine": machine(), "date": datetime.date.today().isoformat(), "setup": [],
            "step": [], "repeat": args.repeat}
    with tempfile.TemporaryDirectory() as tmp:
        for label, (nx, ny) in (QUICK if args.quick else SIZES).items():
            p = setup_point(label, nx, ny, Path(tmp))
            load.append(os.getloadavg()[0])
            data["setup"].append(p)
            print(f"{p['dofs']:>7} DOFs: read {p['read'][0]:.2f} s, assemble "
                  f"{p['assemble'][0]:.2f} s, factor {p['factor'][0]:.2f} s, 20 modes "
                  f"{p['modes20'][0]:.2f} s ({p['modes20_solves']} solves), 50 modes "
                  f"{p['modes50'][0]:.2f} s ({p['modes50_solves']} solves, CPU "
                  f"{p['modes50'][1]:.2f} s; threads kept {p['modes50_keep'][0]:.2f} s, one "
                  f"again {p['modes50_again'][0]:.2f} s), cached re-run "
                  f"{p['cached_rerun'][0]:.2f} s; "
                  f"load {load[-1]:.1f}", flush=True)
        if not args.skip_step:
            for m in STEP_MODES:
                for which in ("beam", "plane"):
                    p = step_point(which, m, args.repeat, Path(tmp) / "step_cache")
                    data["step"].append(p)
                    print(f"{which:<6}{p['modes']:>4} modes ({p['dofs']} DOFs): solve "
                          f"{1e6 * p['solve_per_step_s']:.1f} us/step, structure "
                          f"{1e6 * p['structure_per_step_s']:.1f} us/step over "
                          f"{p['macro_steps']} steps, C {p['contacts_C']}", flush=True)
            load.append(os.getloadavg()[0])
    data["load_average"] = load
    if not args.skip_step:
        print(table(data))
    if args.out:
        from cosim.io.rundir import OutputFolder
        with OutputFolder(args.out) as folder:
            folder.write("plane_setup.json", lambda fh: json.dump(data, fh, indent=1), "w")
        print(f"wrote {args.out}/plane_setup.json")
    return 0


if __name__ == "__main__":
    sys.exit(main())

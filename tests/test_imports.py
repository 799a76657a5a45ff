"""Start-up: a command imports only what its scene needs (issues 12 and 17).

Each case runs the command line in a fresh interpreter and reads back the set
of modules it loaded: a behaviour, not a timing.  scikit-fem, meshio,
matplotlib and dask are heavy and optional; scipy's submodules load where
first used, so a chain or a rigid ground needs none of scipy.  Our own modules
that a scene may not use (joint effects, rigid impacts, grasp and friction,
the mesh-based structures, the structural integrators, the monolithic and
implicit schemes, plots, sweeps, benchmarks, export, verification) load where
first needed too; ``benchmarks/startup.py`` measures what that saves.
"""
import importlib
import json
import re
import subprocess
import sys

import pytest

from conftest import CASES, ROOT

OURS = ("cosim", "multibody", "fem", "couplers")
#: our modules that a scene which does not use them must not load
ON_DEMAND = ("multibody.effects", "multibody.impact", "couplers.connection", "cosim.core.connection_modes",
             "fem.beam", "fem.rod", "fem.integrators", "cosim.core.schemes.monolithic",
             "cosim.core.schemes.implicit", "cosim.plot", "cosim.studies.sweep", "cosim.studies.bench",
             "cosim.io.export", "cosim.studies.verify", "cosim.scene.info", "cosim.studies.analytic", "cosim.studies.metrics")

HEAVY = ("skfem", "meshio", "matplotlib", "dask", "distributed")

SCRIPT = """
import atexit, json, sys
out = sys.argv[1]
def dump():
    with open(out, "w") as fh:
        json.dump(sorted(sys.modules), fh)
atexit.register(dump)
from cosim.cli import main
sys.exit(main(sys.argv[2:]))
"""


def loaded(tmp_path, *argv):
    out = tmp_path / "modules.json"
    proc = subprocess.run([sys.executable, "-c", SCRIPT, str(out), *argv], cwd=ROOT,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode in (0, 1), proc.stderr
    return set(json.loads(out.read_text()))


def packages(mods, names):
    return sorted(m for m in mods if m.split(".")[0] in names)


def test_help_imports_nothing_heavy(tmp_path):
    mods = loaded(tmp_path, "--help")
    assert not packages(mods, HEAVY + ("scipy",))


@pytest.mark.parametrize("scene,variant", [("spring_drop", None), ("three_mass", "f1")])
def test_rigid_ground_and_chain_scenes_need_no_scipy(tmp_path, scene, variant):
    argv = ["run", str(CASES / f"{scene}.toml"), "--out", str(tmp_path / "run"), "--quiet",
            "--set", "t_end=0.01"]
    if variant:
        argv += ["--variant", variant]
    mods = loaded(tmp_path, *argv)
    assert "cosim.scene.run" in mods
    if scene == "three_mass":
        assert "fem.chain" in mods          # the chain was built, without scipy
    assert not packages(mods, HEAVY + ("scipy",)), packages(mods, HEAVY + ("scipy",))


def test_scipy_loads_where_first_used(tmp_path):
    """The monolithic scheme integrates with scipy's solve_ivp for the
    methods cosim has no pair of its own for (RK23 here): scipy.integrate is
    loaded then, and still nothing of the structures' or the plots'
    packages.  (Its default, DOP853, needs no scipy: test_monolithic_solver.)"""
    mods = loaded(tmp_path, "run", str(CASES / "spring_drop.toml"), "--scheme", "monolithic",
                  "--set", 'scheme.method="RK23"', "--out", str(tmp_path / "run"), "--quiet")
    assert "scipy.integrate" in mods
    assert not packages(mods, HEAVY)


def test_a_beam_scene_loads_scikit_fem_but_not_meshio_or_plots(tmp_path):
    mods = loaded(tmp_path, "run", str(CASES / "beam_impact.toml"), "--out",
                  str(tmp_path / "run"), "--quiet", "--set", "t_end=0.002")
    assert "skfem" in mods
    assert not packages(mods, ("meshio", "matplotlib", "dask", "distributed"))


def test_help_imports_none_of_the_run(tmp_path):
    mods = loaded(tmp_path, "--help")
    ours = [m for m in packages(mods, OURS) if not m.startswith("cosim.cli.")]
    assert ours == ["cosim", "cosim.cli", "cosim.errors"]
    # the command line's own modules, and none that a sub-command loads
    assert {m for m in mods if m.startswith("cosim.cli.")} == {
        "cosim.cli.commands", "cosim.cli.parser", "cosim.cli.signals", "cosim.cli.terminal"}


def run_argv(tmp_path, scene, variant=None, t_end="0.01", *extra):
    argv = ["run", str(CASES / f"{scene}.toml"), "--out", str(tmp_path / "run"), "--quiet",
            "--set", f"t_end={t_end}", *extra]
    return argv + (["--variant", variant] if variant else [])


def test_a_rigid_ground_scene_loads_none_of_the_modules_it_does_not_use(tmp_path):
    """spring_drop: a mass, a wall, a linear law, Gauss-Seidel: no structure
    package, no effects, impacts, connections or other schemes."""
    mods = loaded(tmp_path, *run_argv(tmp_path, "spring_drop"))
    assert "cosim.scene.run" in mods and "cosim.core.schemes.explicit" in mods
    assert [m for m in ON_DEMAND if m in mods] == []
    assert packages(mods, ("fem",)) == []


def test_a_chain_scene_loads_only_what_it_steps_with(tmp_path):
    """three_mass: the chain is stepped by ``fem.integrators.ExactModal`` and
    the file has a ``[scheme.monolithic]`` table, which is validated against
    that scheme's options; nothing else on demand is loaded."""
    mods = loaded(tmp_path, *run_argv(tmp_path, "three_mass", "f100"))
    assert {"fem.chain", "fem.integrators", "cosim.core.schemes.monolithic"} <= mods
    needed = ("fem.integrators", "cosim.core.schemes.monolithic")
    assert [m for m in ON_DEMAND if m in mods and m not in needed] == []


@pytest.mark.parametrize("scene,variant,extra,needs", [
    ("spring_drop", None, ("--scheme", "implicit"), {"cosim.core.schemes.implicit"}),
    ("manipulator_wall", "mu0.03", ("--set", "contacts.tip.law.restitution=0.5"),
     {"multibody.impact"}),
    ("brachiation", None, (), {"multibody.effects", "couplers.connection", "cosim.core.connection_modes",
                               "fem.beam"}),
])
def test_a_module_on_demand_loads_where_the_scene_uses_it(tmp_path, scene, variant, extra, needs):
    """The other side of the coin: a scene with an implicit scheme, a rigid
    impact, a drive, a grasp and a cable loads what steps them (and runs)."""
    t_end = "0.45" if scene == "manipulator_wall" else "0.002"   # the wall is struck at 0.39 s
    mods = loaded(tmp_path, *run_argv(tmp_path, scene, variant, t_end, *extra))
    assert needs <= mods, sorted(needs - mods)
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["status"] == "finished"
    if scene == "manipulator_wall":
        assert summary["impacts"], "the rigid impact was meant to happen"


def test_the_compiled_kernel_loads_only_with_a_multibody_side(tmp_path):
    """``cosim.sides._multibody_step`` steps trees: a rod against a rigid wall and
    ``cosim --help`` do not import it; ``cosim run`` of a tree does."""
    assert "cosim.sides._multibody_step" not in loaded(tmp_path, *run_argv(tmp_path, "rod_impact",
                                                                     None, "1e-5"))
    assert "cosim.sides._multibody_step" not in loaded(tmp_path, "--help")
    try:
        importlib.import_module("cosim.sides._multibody_step")
    except ImportError:
        pytest.skip("the compiled kernel is not built here (tests/test_kernel.py fails then)")
    assert "cosim.sides._multibody_step" in loaded(tmp_path, *run_argv(tmp_path, "spring_drop",
                                                                 None, "1e-4", "--overwrite"))


@pytest.mark.parametrize("package", OURS)
def test_every_public_name_imports_as_before(package):
    """Names loaded on first use are still there: ``from PACKAGE import NAME``
    for every name of ``__all__``, each defined in the package's submodule."""
    code = (f"import {package}\n"
            f"for name in {package}.__all__:\n"
            f"    exec(f'from {package} import {{name}}')\n"
            f"    assert name in dir({package}), name\n"
            f"print(len({package}.__all__))")
    proc = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert int(proc.stdout) >= 15
    mod = importlib.import_module(package)
    with pytest.raises(AttributeError, match=f"module '{package}' has no attribute 'no_such_name'"):
        getattr(mod, "no_such_name")


def test_cosim_submodules_load_on_attribute_access():
    code = ("import sys, cosim\n"
            "assert 'cosim.scene.run' not in sys.modules\n"
            "assert cosim.simulate.__module__ == 'cosim.api'\n"
            "assert 'cosim.studies' not in sys.modules\n"
            "assert cosim.studies.__name__ == 'cosim.studies'\n"
            "assert cosim.plot.__name__ == 'cosim.plot'\n")
    proc = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr


def test_the_scheme_registry_imports_a_scheme_on_lookup_only():
    code = ("import sys\n"
            "from cosim.core.schemes import COUPLING_SCHEMES, get_scheme\n"
            "names = sorted(COUPLING_SCHEMES)\n"
            "assert 'implicit' in COUPLING_SCHEMES and len(COUPLING_SCHEMES) == 4\n"
            "assert 'cosim.core.schemes.implicit' not in sys.modules\n"
            "cls = get_scheme('implicit')\n"
            "assert 'cosim.core.schemes.implicit' in sys.modules\n"
            "print(' '.join(names), cls.__name__)")
    proc = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.split() == ["gauss_seidel", "implicit", "jacobi", "monolithic", "Implicit"]


def test_the_scheme_registry_is_a_registry_as_before():
    """Each name resolves to the class of that name; a user's own class
    registers and resolves as in a dict; unknown names list the valid ones."""
    from cosim.core.schemes import COUPLING_SCHEMES, GaussSeidel, Implicit, Monolithic, get_scheme
    assert list(COUPLING_SCHEMES) == ["monolithic", "jacobi", "gauss_seidel", "implicit"]
    assert {n: c.name for n, c in COUPLING_SCHEMES.items()} == {n: n for n in COUPLING_SCHEMES}
    assert COUPLING_SCHEMES["monolithic"] is Monolithic
    assert COUPLING_SCHEMES["implicit"] is Implicit

    class Mine(GaussSeidel):
        name = "mine"

    COUPLING_SCHEMES["mine"] = Mine
    try:
        assert get_scheme("mine") is Mine and "mine" in COUPLING_SCHEMES
    finally:
        del COUPLING_SCHEMES["mine"]
    assert "mine" not in COUPLING_SCHEMES
    with pytest.raises(ValueError, match=r"unknown coupling scheme 'mine'; valid coupling "
                                         r"schemes are \['gauss_seidel', 'implicit', 'jacobi', "
                                         r"'monolithic'\]"):
        get_scheme("mine")


# ----------------------------------------------------------------------------
# Cheaper definitions, same models: a law or integrator class that adds no field
# to its base is not decorated again (a frozen dataclass's methods are generated
# with one `exec` each at import); what the decorator gave it must be unchanged.

def _declared_fields(cls) -> list[str]:
    """The non-ClassVar annotations along the MRO: what the fields must be."""
    names = []
    for klass in reversed(cls.__mro__):
        for name, annotation in vars(klass).get("__annotations__", {}).items():
            if "ClassVar" not in str(annotation) and name not in names:
                names.append(name)
    return names


def _models():
    from cosim.core.ode import INTEGRATORS
    from test_laws import EXAMPLES
    changes = {"linear": ("contact_stiffness", 2e6), "kelvin_voigt": ("contact_damping", 1.0),
               "rigid": ("restitution", 0.3), "hertz": ("exponent", 1.25),
               "hunt_crossley": ("hysteresis_damping", 0.25),
               "lankarani_nikravesh": ("restitution", 0.7), "flores": ("impact_speed", 3.0)}
    out = [(law, *changes[name]) for name, law in EXAMPLES.items()]
    out += [(INTEGRATORS["rk4"](max_step=1e-3), "max_step", 2e-3)]
    out += [(cls(), "rtol", 1e-6) for name, cls in INTEGRATORS.items() if name != "rk4"]
    return out


@pytest.mark.parametrize("model,key,other", _models(), ids=lambda v: type(v).__name__
                         if not isinstance(v, (str, float)) else "")
def test_registered_models_are_the_frozen_dataclasses_they_were(model, key, other):
    import dataclasses
    cls = type(model)
    assert dataclasses.is_dataclass(cls)
    assert [f.name for f in dataclasses.fields(cls)] == _declared_fields(cls)
    twin = dataclasses.replace(model)
    assert twin is not model and twin == model and hash(twin) == hash(model)
    changed = dataclasses.replace(model, **{key: other})
    assert type(changed) is cls and changed != model and getattr(changed, key) == other
    assert repr(model).startswith(f"{cls.__qualname__}({dataclasses.fields(cls)[0].name}=")
    with pytest.raises(dataclasses.FrozenInstanceError):
        setattr(model, key, other)
    with pytest.raises(ValueError, match=f"`{key}`"):   # __post_init__ still validates
        dataclasses.replace(model, **{key: -1.0})


def test_models_of_two_classes_with_the_same_fields_differ():
    from couplers import FloresLaw, LankaraniNikraveshLaw
    from cosim.core.ode import INTEGRATORS
    assert LankaraniNikraveshLaw(1e9, 1.5, 0.5, 2.0) != FloresLaw(1e9, 1.5, 0.5, 2.0)
    assert INTEGRATORS["rk45"]() != INTEGRATORS["dop853"]() == INTEGRATORS["dop853"]()


def test_a_simulation_result_compares_by_identity():
    """It holds arrays: the generated == could only raise; now a result equals
    itself alone and hashes (it is still frozen)."""
    import dataclasses

    import numpy as np

    from cosim import SimulationResult
    make = lambda: SimulationResult(np.arange(3.0), {}, {}, (), 1, 0, 0, "finished", "", True)  # noqa: E731
    a, b = make(), make()
    assert a == a and a != b and len({a, b}) == 2
    with pytest.raises(dataclasses.FrozenInstanceError):
        a.status = "failed"


def test_the_startup_benchmark_runs_and_reports_every_group(tmp_path):
    """``benchmarks/startup.py`` (a measurement, not a timed test): it runs,
    finds our modules and numpy in ``-X importtime``'s output and prints a
    row per group and per in-process step, each a time and a ratio (in
    process: wall and CPU)."""
    proc = subprocess.run([sys.executable, "benchmarks/startup.py", "--repeat", "1"], cwd=ROOT,
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    rows = {}
    for line in proc.stdout.splitlines():
        m = re.match(r"\s*(\S.*?)\s{2,}(\d+\.\d+)\s+(\d+\.\d+)", line)
        if m:
            rows[m[1]] = [float(m[2]), float(m[3])]
    for label in ("cosim", "multibody", "fem", "couplers", "ours together", "numpy",
                  "import numpy", "our modules alone", "load_scene alone", "build_system alone",
                  "scene read and build alone"):
        assert label in rows, (label, proc.stdout)
    assert rows["cosim"][0] > 0 and rows["numpy"][1] == 1.0
    assert rows["import numpy"][1] == 1.0 and rows["load_scene alone"][0] > 0


def test_a_run_imports_no_cryptographic_modules(tmp_path):
    """The run folder's temporary names are random bytes from ``os.urandom``
    (what ``secrets.token_hex`` reads): ``secrets`` would load ``hmac`` and
    OpenSSL's hashes into every run."""
    mods = loaded(tmp_path, "run", str(CASES / "three_mass.toml"), "--variant", "f100", "--out",
                  str(tmp_path / "run"), "--quiet", "--set", "t_end=0.01")
    assert "cosim.io.rundir" in mods
    assert not {"secrets", "hmac"} & mods


def test_an_explicit_adaptive_side_needs_no_scipy(tmp_path):
    """manipulator_wall's robot integrates with DOP853 and locates its
    impact as an event: cosim's own Runge-Kutta pairs (issue 39), so the
    whole run, its accuracy estimate included, loads nothing of scipy (whose
    integrate package cost half a second inside the first solve)."""
    mods = loaded(tmp_path, "run", str(CASES / "manipulator_wall.toml"), "--variant", "mu0.03",
                  "--out", str(tmp_path / "run"), "--quiet")
    assert "cosim.core.embedded_rk" in mods and "multibody.impact" in mods
    assert not packages(mods, ("scipy",)), packages(mods, ("scipy",))

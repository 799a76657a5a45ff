"""Plug-ins: a contact law, scheme or integrator that an installed package
declares under cosim's entry points, usable by name from the command line.

examples/custom_law/ is such a package: it is pip-installed here (no
dependencies, no build isolation, into a temporary folder put on the path),
and its scene runs through `cosim run`, `cosim sweep` (a pool of spawned
processes, which find the plug-in themselves) and `cosim info`.  Broken
plug-ins (a name clash, an import that fails, the wrong class) are made as
bare ``.dist-info`` folders, which is all that Python's metadata reads.
"""
import json
import subprocess
import sys

import pytest

from conftest import ROOT
from plugin_tools import bare_dist, child_env, pip_install, run_cosim
from cosim.studies.analytic import hertz_contact

PACKAGE = ROOT / "examples" / "custom_law"
SCENE = PACKAGE / "scene.toml"


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    """examples/custom_law installed by pip into a folder of its own."""
    return pip_install(PACKAGE, tmp_path_factory.mktemp("plugin"), "sphere_law.py")


def test_cosim_run_finds_the_installed_law(installed, tmp_path):
    proc = run_cosim(["run", SCENE, "--out", tmp_path / "run", "--quiet"], child_env(installed), tmp_path)
    assert proc.returncode == 0, proc.stderr
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    wall = summary["contacts"]["wall"]
    # the sphere's Hertz constant, K = (4/3) E / (1 - nu^2) sqrt(R), and the closed form
    k = 4 / 3 * 1e7 / (1 - 0.49 ** 2) * 0.05 ** 0.5
    t_c, d_max = hertz_contact(1.0, k, 1.0, 1.5)
    assert wall["count"] == 1
    # RK4 at 10 us, touch and release located (examples/custom_law.py measures 2.5e-9)
    assert wall["in_touch_time"] == pytest.approx(t_c, rel=1e-6)
    assert wall["peak_penetration"] == pytest.approx(d_max, rel=1e-6)
    assert summary["final_state"]["body"]["x"]["dq"] == pytest.approx(1.0, rel=1e-6)


def test_cosim_info_names_the_installed_law(installed, tmp_path):
    proc = run_cosim(["info", SCENE], child_env(installed), tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert "contact wall: sphere_on_flat (" in proc.stdout
    proc = run_cosim(["info", SCENE, "--json"], child_env(installed), tmp_path)
    assert json.loads(proc.stdout)["contacts"]["wall"]["law"] == "sphere_on_flat"


def test_cosim_sweep_workers_find_the_installed_law(installed, tmp_path):
    """Two points on a pool of two spawned processes: each worker reads the
    scene and finds the plug-in on its own."""
    proc = run_cosim(["sweep", SCENE, "--set", "contacts.wall.law.radius=0.05,0.2",
                   "--workers", "2", "--out", tmp_path / "sweep", "--no-plot", "--quiet"],
                  child_env(installed), tmp_path, timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "2 of 2 point(s) finished" in proc.stdout + proc.stderr
    points = sorted((tmp_path / "sweep").rglob("summary.json"))
    assert len(points) == 2
    times = sorted(json.loads(p.read_text())["contacts"]["wall"]["in_touch_time"]
                   for p in points)
    # t_c ~ K^(-2/5) ~ R^(-1/5): the larger sphere is stiffer, its contact shorter by 4^(1/5)
    assert times[1] / times[0] == pytest.approx(4 ** 0.2, rel=1e-5)


def test_cosim_sweep_dask_workers_find_the_installed_law(installed, tmp_path):
    """The same on a local Dask cluster: its worker processes find the plug-in."""
    pytest.importorskip("distributed")
    pytest.importorskip("cryptography")            # else the local workers are threads
    env = child_env(installed)
    env["TMPDIR"] = str(tmp_path / "tmp")
    (tmp_path / "tmp").mkdir()
    proc = run_cosim(["sweep", SCENE, "--set", "contacts.wall.law.radius=0.05,0.2",
                   "--scheduler", "local", "--workers", "1", "--out", tmp_path / "sweep",
                   "--no-plot", "--quiet"], env, tmp_path, timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "2 of 2 point(s) finished" in proc.stdout + proc.stderr
    points = sorted((tmp_path / "sweep").rglob("summary.json"))
    times = sorted(json.loads(p.read_text())["contacts"]["wall"]["in_touch_time"]
                   for p in points)
    assert times[1] / times[0] == pytest.approx(4 ** 0.2, rel=1e-5)


def test_without_the_package_the_name_is_unknown(tmp_path):
    proc = run_cosim(["run", SCENE, "--out", tmp_path / "run"], child_env(), tmp_path)
    assert proc.returncode == 2
    assert "`contacts.wall.law.type` must be one of" in proc.stderr
    assert "got 'sphere_on_flat'" in proc.stderr


def test_a_plugin_named_like_a_built_in_is_never_loaded(tmp_path):
    """A plug-in named `hertz` may not replace the built-in: it is never
    imported, and blocks no other name (tests/test_plugin_misbehaviour.py
    has the rest of a clash)."""
    site = bare_dist(tmp_path / "site", "shadow-hertz", "cosim.laws", {"hertz": "shadow:Law"},
                 "shadow", "raise SystemExit('imported')\n")
    scene = tmp_path / "scene.toml"
    scene.write_text(SCENE.read_text().replace('law = { type = "sphere_on_flat"',
                                               'law = { type = "flat_sphere"'))
    proc = run_cosim(["run", scene, "--out", tmp_path / "run"], child_env(site), tmp_path)
    assert proc.returncode == 2, proc.stderr
    assert "`contacts.wall.law.type` must be one of ['flores', 'hertz'," in proc.stderr
    assert "got 'flat_sphere'" in proc.stderr and "shadow" not in proc.stderr, proc.stderr
    assert "imported" not in proc.stderr                         # never imported


def test_a_plugin_that_fails_to_import_names_its_distribution(tmp_path):
    site = bare_dist(tmp_path / "site", "broken-law", "cosim.laws",
                 {"sphere_on_flat": "broken_law:SphereOnFlat"}, "broken_law",
                 "import a_module_that_is_not_there\n")
    proc = run_cosim(["run", SCENE, "--out", tmp_path / "run"], child_env(site), tmp_path)
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr == ("error: the plug-in distribution `broken-law` 1.0, entry point "
                           "`sphere_on_flat = broken_law:SphereOnFlat` in group `cosim.laws` "
                           "cannot be imported: ModuleNotFoundError: No module named "
                           "'a_module_that_is_not_there'\n")
    assert not (tmp_path / "run").exists()


def test_a_plugin_of_the_wrong_kind_or_name_is_refused(tmp_path):
    code = """
        from cosim.core.ode import RK4
        class NotALaw:
            name = "sphere_on_flat"
        class Stepper(RK4):
            name = "other_name"
        """
    site = bare_dist(tmp_path / "site", "odd-plugins", "cosim.laws",
                 {"sphere_on_flat": "odd:NotALaw"}, "odd", code)
    proc = run_cosim(["run", SCENE, "--out", tmp_path / "a"], child_env(site), tmp_path)
    assert proc.returncode == 2
    assert "loads <class 'odd.NotALaw'>, which is not a subclass of couplers.law_base." \
           "ContactLaw" in proc.stderr, proc.stderr
    site2 = bare_dist(tmp_path / "site2", "odd-stepper", "cosim.integrators",
                  {"my_rk4": "odd:Stepper"})
    scene = tmp_path / "scene.toml"
    scene.write_text(SCENE.read_text().replace('method = "rk4"', 'method = "my_rk4"'))
    proc = run_cosim(["run", scene, "--out", tmp_path / "b"], child_env(site2, site), tmp_path)
    assert proc.returncode == 2
    assert "loads Stepper, whose `name` is 'other_name', not 'my_rk4'" in proc.stderr, \
        proc.stderr


def test_plugin_scheme_and_integrator_by_name(tmp_path):
    """A scheme and a robot's integrator from a plug-in, in one scene, by name."""
    code = """
        from cosim.core.ode import RK4
        from cosim.core.schemes import GaussSeidel
        class MyRK4(RK4):
            name = "my_rk4"
        class MyGaussSeidel(GaussSeidel):
            name = "my_gauss_seidel"
        """
    site = bare_dist(tmp_path / "site", "my-steppers", "cosim.integrators",
                 {"my_rk4": "mine:MyRK4"}, "mine", code)
    bare_dist(tmp_path / "site", "my-schemes", "cosim.schemes",
          {"my_gauss_seidel": "mine:MyGaussSeidel"})
    scene = tmp_path / "scene.toml"
    text = (ROOT / "cases" / "spring_drop.toml").read_text()
    scene.write_text(text.replace('method = "rk4"', 'method = "my_rk4"')
                     .replace('name = "gauss_seidel"', 'name = "my_gauss_seidel"'))
    proc = run_cosim(["run", scene, "--out", tmp_path / "run", "--quiet"], child_env(site), tmp_path)
    assert proc.returncode == 0, proc.stderr
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["scheme"] == "my_gauss_seidel"
    # the same steps as the built-ins they subclass: the undamped closed form, pi ms
    assert summary["contacts"]["wall"]["in_touch_time"] == pytest.approx(3.14159265e-3,
                                                                         rel=1e-6)
    # and `--scheme` names one on the command line too
    proc = run_cosim(["run", ROOT / "cases" / "spring_drop.toml", "--scheme", "my_gauss_seidel",
                   "--out", tmp_path / "run2", "--quiet"], child_env(site), tmp_path)
    assert proc.returncode == 0, proc.stderr
    # a sweep's spawned workers build the scene's scheme and integrator by name: they
    # find the plug-ins themselves
    proc = run_cosim(["sweep", scene, "--set", "t_end=0.015,0.02", "--workers", "2",
                   "--out", tmp_path / "sweep", "--no-plot", "--quiet"], child_env(site), tmp_path,
                  timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "2 of 2 point(s) finished" in proc.stdout + proc.stderr


def test_plugin_structure_integrator_by_name(tmp_path):
    """A structure's integrator from a plug-in (Newmark's average acceleration
    under another name) steps three_mass's chain as the built-in does."""
    code = """
        from fem.newmark import Newmark
        class MyNewmark(Newmark):
            name = "my_newmark"
        """
    site = bare_dist(tmp_path / "site", "my-newmark", "cosim.integrators",
                 {"my_newmark": "mine_fem:MyNewmark"}, "mine_fem", code)
    runs = {}
    for method in ("newmark", "my_newmark"):
        over = ["--set", f'subsystems.chain.integrator.method="{method}"', "--set", "t_end=0.12"]
        out = tmp_path / method
        proc = run_cosim(["run", ROOT / "cases" / "three_mass.toml", "--variant", "f100", *over,
                       "--out", out, "--quiet", "--no-estimate"], child_env(site), tmp_path)
        assert proc.returncode == 0, proc.stderr
        runs[method] = json.loads((out / "summary.json").read_text())
    # the same class under two names: the same steps, bit for bit
    assert runs["my_newmark"]["contacts"] == runs["newmark"]["contacts"]


def test_built_in_names_read_no_plugin_metadata(tmp_path):
    """A scene of built-in names imports no plug-in and reads no package
    metadata (start-up): a plug-in that would fail on import stays unread."""
    site = bare_dist(tmp_path / "site", "loud", "cosim.laws", {"loud": "loud:Law"}, "loud",
                 "raise SystemExit('imported')\n")
    code = ("import sys; from cosim import cli; "
            f"rc = cli.main(['run', {str(ROOT / 'cases' / 'spring_drop.toml')!r}, "
            f"'--out', {str(tmp_path / 'o')!r}, '--quiet']); "
            "print(sorted(m for m in sys.modules if m in ('importlib.metadata', 'loud'))); "
            "sys.exit(rc)")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          env=child_env(site), cwd=tmp_path, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip().splitlines()[-1] == "[]"


def test_the_plugins_page_shows_what_the_commands_print(installed, tmp_path):
    """docs/plugins.md: the run's output as printed (its CPU time aside, the
    machine's), the info line, and the contact time it quotes."""
    import re

    page = (ROOT / "docs" / "plugins.md").read_text(encoding="utf-8")
    shown = page.split("$ cosim run examples/custom_law/scene.toml --out runs/sphere_drop\n")[1]
    shown = shown.split("$ cosim info")[0].splitlines()
    proc = run_cosim(["run", SCENE, "--out", "runs/sphere_drop"], child_env(installed), tmp_path)
    assert proc.returncode == 0, proc.stderr
    cpu = re.compile(r"cpu \S+ s")
    assert [cpu.sub("cpu _ s", ln) for ln in proc.stdout.splitlines()] == \
        [cpu.sub("cpu _ s", ln) for ln in shown]
    info = run_cosim(["info", SCENE], child_env(installed), tmp_path).stdout
    assert "  contact wall: sphere_on_flat (embedded) between body and wall\n" in info
    assert "  contact wall: sphere_on_flat (embedded) between body and wall" in page
    summary = json.loads((tmp_path / "runs" / "sphere_drop" / "summary.json").read_text())
    assert "The contact lasts 7.4153 ms" in page
    assert f"{summary['contacts']['wall']['in_touch_time'] * 1e3:.5g}" == "7.4153"

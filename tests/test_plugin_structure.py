"""A structure an installed package declares (entry point ``cosim.structures``),
usable by name in a scene: examples/custom_structure/, a string on an
elastic foundation.

The model is checked against closed forms (its frequencies are the string's
shifted by the foundation; its static deflection converges at second order
to the continuous one); with no foundation a run of it is the built-in
string's run.  Through the command line: `cosim run`, `cosim info`,
`cosim sweep` on a pool, a key reference, bad keys and bad plug-ins.
"""
import json
import math
import subprocess
import sys

import numpy as np
import pytest

from conftest import ROOT
from plugin_tools import bare_dist, child_env, pip_install, run_cosim

PACKAGE = ROOT / "examples" / "custom_structure"
SCENE = PACKAGE / "scene.toml"


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    """examples/custom_structure installed by pip into a folder of its own."""
    return pip_install(PACKAGE, tmp_path_factory.mktemp("plugin"), "foundation_string.py")


@pytest.fixture
def model_class(monkeypatch):
    """The example's class, imported from the example's folder (no install)."""
    monkeypatch.syspath_prepend(str(PACKAGE))
    monkeypatch.delitem(sys.modules, "foundation_string", raising=False)
    from foundation_string import FoundationString
    return FoundationString


def _model(cls, **kw):
    args = dict(length=2.0, tension=1000.0, density=7850.0, area=1e-4,
                foundation_stiffness=1e5, elements=40)
    args.update(kw)
    return cls(**args)


def test_frequencies_are_the_strings_shifted_by_the_foundation(model_class):
    """omega_n^2 = omega_string,n^2 + k_f / (rho A), exactly for the
    discrete models too (K adds a multiple of M): equal to round-off."""
    import fem
    shifted = _model(model_class).assemble()
    plain = _model(model_class, foundation_stiffness=0.0).assemble()
    w_f = fem.natural_frequencies(shifted, 10) * 2 * np.pi
    w_0 = fem.natural_frequencies(plain, 10) * 2 * np.pi
    expected = np.sqrt(w_0 ** 2 + 1e5 / (7850.0 * 1e-4))
    np.testing.assert_allclose(w_f, expected, rtol=1e-10)
    # and the plain one is cosim's own string's closed form (P1, consistent mass)
    h, c = 2.0 / 40, math.sqrt(1000.0 / 0.785)
    k = np.arange(1, 11) * np.pi / 2.0
    w_string = c / h * np.sqrt(6 * (1 - np.cos(k * h)) / (2 + np.cos(k * h)))
    np.testing.assert_allclose(w_0, w_string, rtol=1e-10)


def test_static_deflection_converges_at_second_order(model_class):
    """A point load P at mid-span: w = P tanh(lambda L/2) / (2 T lambda),
    lambda = sqrt(k_f / T), approached at O(h^2)."""
    lam = math.sqrt(1e5 / 1000.0)
    exact = 10.0 * math.tanh(lam * 1.0) / (2 * 1000.0 * lam)
    errors = []
    for n in (40, 80, 160):
        s = _model(model_class, elements=n).assemble()
        u = s.static_displacement(s.point_load(1.0, 10.0))
        dofs, weights = s.point_operator(1.0)
        errors.append(abs(weights @ u[dofs] - exact) / exact)
    orders = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert errors[-1] < 1e-3
    np.testing.assert_allclose(orders, 2.0, atol=0.1)


def test_cosim_run_with_the_installed_structure(installed, tmp_path):
    proc = run_cosim(["run", SCENE, "--out", tmp_path / "run"], child_env(installed), tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert "string: 39 DOFs" in proc.stdout
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    c = summary["contacts"]["C"]
    assert summary["status"] == "finished"
    assert c["count"] == 1
    # the mass leaves upwards with most of its speed (the string rings on)
    assert 0.9 < summary["final_state"]["body"]["y"]["dq"] < 1.0


def test_without_a_foundation_the_run_is_the_built_in_strings(installed, tmp_path):
    """foundation_stiffness = 0: the plug-in's matrices are the string's,
    so the two runs agree to round-off (not bit for bit: K + 0 M is a sum)."""
    text = SCENE.read_text()
    plugin = tmp_path / "plugin.toml"
    plugin.write_text(text.replace("foundation_stiffness = 1e5", "foundation_stiffness = 0.0"))
    built_in = tmp_path / "built_in.toml"
    built_in.write_text(text.replace('type = "foundation_string"', 'type = "string"')
                        .replace("foundation_stiffness = 1e5    # [N/m^2]\n", ""))
    out = {}
    for scene in (plugin, built_in):
        proc = run_cosim(["run", scene, "--out", tmp_path / scene.stem, "--quiet",
                          "--no-estimate"], child_env(installed), tmp_path)
        assert proc.returncode == 0, proc.stderr
        out[scene.stem] = json.loads((tmp_path / scene.stem / "summary.json").read_text())
    a, b = out["plugin"]["contacts"]["C"], out["built_in"]["contacts"]["C"]
    assert a["count"] == b["count"] == 1
    for key in ("peak_penetration", "impulse", "in_touch_time"):
        assert a[key] == pytest.approx(b[key], rel=1e-9), key
    assert out["plugin"]["final_state"]["body"]["y"]["dq"] == pytest.approx(
        out["built_in"]["final_state"]["body"]["y"]["dq"], rel=1e-9)


def test_cosim_info_and_the_key_reference_name_it(installed, tmp_path):
    proc = run_cosim(["info", SCENE, "--json"], child_env(installed), tmp_path)
    assert proc.returncode == 0, proc.stderr
    string = json.loads(proc.stdout)["subsystems"]["string"]
    assert (string["type"], string["dofs"], string["modes_kept"]) == ("StructureSubsystem", 39, 20)
    # the lowest frequency: the discrete string's (P1, 40 elements) shifted by the foundation
    h, c = 2.0 / 40, math.sqrt(1000.0 / 0.785)
    w_string = c / h * math.sqrt(6 * (1 - math.cos(math.pi / 2 * h)) / (2 + math.cos(math.pi / 2 * h)))
    f1 = math.sqrt(w_string ** 2 + 1e5 / 0.785) / (2 * math.pi)
    assert string["natural_frequencies_hz"][0] == pytest.approx(f1, rel=1e-9)
    code = ("from cosim.core.plugins import find; from cosim.scene.keys import section;"
            "find('cosim.structures', 'foundation_string');"
            "s = section('structure.foundation_string');"
            "import json; print(json.dumps([(k.name, k.unit, k.check) for k in s.keys]))")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          env=child_env(installed), cwd=tmp_path, timeout=120)
    assert proc.returncode == 0, proc.stderr
    keys = {k[0]: tuple(k[1:]) for k in json.loads(proc.stdout)}
    assert keys["foundation_stiffness"] == ("N/m^2", ">= 0")
    assert keys["elements"] == ("", "an integer in [2, 100000]")
    assert keys["axis"][1] == "two finite numbers, not both 0"
    # the keys every structure shares come after the model's own
    assert {"points", "modes", "integrator", "static_equilibrium"} <= set(keys)


def test_cosim_sweep_workers_find_the_installed_structure(installed, tmp_path):
    proc = run_cosim(["sweep", SCENE, "--set",
                      "subsystems.string.foundation_stiffness=0.0,1e5", "--set", "t_end=0.03",
                      "--workers", "2", "--out", tmp_path / "sweep", "--no-plot", "--quiet"],
                     child_env(installed), tmp_path, timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "2 of 2 point(s) finished" in proc.stdout + proc.stderr
    times = sorted(json.loads(p.read_text())["contacts"]["C"]["in_touch_time"]
                   for p in (tmp_path / "sweep").rglob("summary.json"))
    assert len(times) == 2
    assert times[0] < times[1]          # the foundation stiffens the string: a shorter contact


@pytest.mark.parametrize("edit, key, message", [
    (("foundation_stiffness = 1e5", "foundation_stiffness = -1.0"),
     "subsystems.string.foundation_stiffness", "must be >= 0 N/m^2, got -1"),
    (("elements = 40", "elements = 1"), "subsystems.string.elements", "must be >= 2, got 1"),
    (("tension = 1000.0        # [N]\n", ""), "subsystems.string.tension",
     "is required but missing"),
    (("elements = 40", "elements = 40\nsection = { width = 0.01 }"), "subsystems.string.section",
     "is not a known key"),
    (("points = { middle = 1.0 }", "points = { middle = 2.5 }"),
     "subsystems.string.points.middle", "must be a material coordinate in [0, 2] m"),
    (('law = { type = "linear"', 'follow = true\nlaw = { type = "linear"'), "contacts.C.follow",
     "which an installed package declares; a contact follows the built-in"),
])
def test_bad_keys_of_a_plugin_structure_name_the_key(installed, tmp_path, edit, key, message):
    scene = tmp_path / "scene.toml"
    text = SCENE.read_text()
    assert edit[0] in text
    scene.write_text(text.replace(edit[0], edit[1]))
    proc = run_cosim(["run", scene, "--out", tmp_path / "run"], child_env(installed), tmp_path)
    assert proc.returncode == 2, proc.stderr
    assert f"`{key}`" in proc.stderr and message in proc.stderr, proc.stderr
    assert not (tmp_path / "run").exists()


def test_without_the_package_the_type_is_unknown(tmp_path):
    proc = run_cosim(["run", SCENE, "--out", tmp_path / "run"], child_env(), tmp_path)
    assert proc.returncode == 2
    assert "`subsystems.string.type` must be one of" in proc.stderr
    assert "got 'foundation_string'" in proc.stderr


def test_bad_plugin_structures_are_refused(tmp_path):
    """Named like a built-in (never imported, blocking no other name), a field
    no scene value gives, a class that is not a StructureModel."""
    site = bare_dist(tmp_path / "a", "shadow-string", "cosim.structures",
                     {"string": "shadow:S"}, "shadow", "raise SystemExit('imported')\n")
    scene = tmp_path / "scene.toml"
    scene.write_text(SCENE.read_text().replace('"foundation_string"', '"other_string"'))
    proc = run_cosim(["run", scene, "--out", tmp_path / "r1"], child_env(site), tmp_path)
    assert proc.returncode == 2
    # never loaded, and blocking no other name: `other_string` is unknown, as without it
    assert "`subsystems.string.type` must be one of" in proc.stderr, proc.stderr
    assert "got 'other_string'" in proc.stderr and "shadow" not in proc.stderr
    assert "imported" not in proc.stderr
    code = """
        from dataclasses import dataclass
        from typing import ClassVar
        import fem
        @dataclass(frozen=True)
        class Odd(fem.StructureModel):
            length: float
            table: dict
            name: ClassVar[str] = "foundation_string"
            def dof_bound(self): return 3
            def assemble(self): raise AssertionError
        class NotAModel:
            name = "foundation_string"
        """
    for folder, target, message in (
            ("b", "odd:Odd", "has a field `table: <class 'dict'>` that no scene value gives"),
            ("c", "odd:NotAModel", "which is not a subclass of fem.structure_model.StructureModel")):
        site = bare_dist(tmp_path / folder, f"odd-{folder}", "cosim.structures",
                         {"foundation_string": target}, "odd", code)
        proc = run_cosim(["run", SCENE, "--out", tmp_path / folder / "run"], child_env(site),
                         tmp_path)
        assert proc.returncode == 2
        assert message in proc.stderr, proc.stderr
        assert not (tmp_path / folder / "run").exists()


def test_the_plugins_page_shows_what_the_commands_print(installed, tmp_path):
    """docs/plugins.md's structure section: the run's output as printed (its
    CPU time aside), the info line and the frequencies it quotes."""
    import re

    page = (ROOT / "docs" / "plugins.md").read_text(encoding="utf-8")
    command = "$ cosim run examples/custom_structure/scene.toml --out runs/string_on_foundation\n"
    shown = page.split(command)[1].split("$ cosim info")[0].splitlines()
    proc = run_cosim(["run", SCENE, "--out", "runs/string_on_foundation"], child_env(installed),
                     tmp_path)
    assert proc.returncode == 0, proc.stderr
    cpu = re.compile(r"cpu \S+ s")
    assert [cpu.sub("cpu _ s", ln) for ln in proc.stdout.splitlines()] == \
        [cpu.sub("cpu _ s", ln) for ln in shown]
    info = run_cosim(["info", SCENE], child_env(installed), tmp_path).stdout
    line = next(ln for ln in info.splitlines() if ln.startswith("  subsystem string:"))
    assert line in page
    h, c = 2.0 / 40, math.sqrt(1000.0 / 0.785)
    w_string = c / h * math.sqrt(6 * (1 - math.cos(math.pi / 2 * h)) / (2 + math.cos(math.pi / 2 * h)))
    w_found = math.sqrt(1e5 / 0.785)
    quoted = (f"{math.hypot(w_string, w_found) / (2 * math.pi):.3g} Hz, is the 40-element "
              f"string's {w_string / (2 * math.pi):.4g} Hz shifted by the foundation's\n"
              f"sqrt(k_f / (rho A)) / (2 pi) = {w_found / (2 * math.pi):.3g} Hz")
    assert quoted in page, quoted

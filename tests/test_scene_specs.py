"""The loader hands the builder frozen, typed specs; the scheme is resolved
in one place; the loader and the builder do not import each other."""
from __future__ import annotations

import ast
import dataclasses
import re
import warnings
from pathlib import Path

import pytest

from cosim.scene import specs
from cosim.scene.checks import MAX_STEPS, SceneError
from cosim.scene.keys import DEFAULT_MULTIBODY_STEP
from cosim.scene.load import load_scene

ROOT = Path(__file__).resolve().parents[1]
SCENE = ROOT / "src" / "cosim" / "scene"
CASES = ROOT / "cases"
SPRING_DROP = CASES / "spring_drop.toml"


def test_the_loader_hands_frozen_typed_specs():
    s = load_scene(CASES / "beam_impact.toml")
    kinds = {type(sub) for sub in s.subsystems}
    assert kinds <= {specs.MultibodySpec, specs.RigidSpec, specs.StructureSpec}
    assert specs.StructureSpec in kinds and specs.MultibodySpec in kinds
    assert all(type(c) is specs.ContactSpec for c in s.contacts)
    robot = next(sub for sub in s.subsystems if isinstance(sub, specs.MultibodySpec))
    assert all(type(b) is specs.BodySpec for b in robot.bodies)
    assert all(type(j) is specs.JointSpec for j in robot.joints)
    beam = next(sub for sub in s.subsystems if isinstance(sub, specs.StructureSpec))
    assert beam.type == "beam" and beam.modes == {"n_modes": beam.n_modes,
                                                  "cutoff_hz": beam.cutoff_hz}
    with pytest.raises(dataclasses.FrozenInstanceError):
        s.contacts[0].placement = "coupler"
    with pytest.raises(dataclasses.FrozenInstanceError):
        robot.bodies[0].mass = 2.0
    # read by key too, as the dictionaries they replace were
    assert s.contacts[0]["law"] is s.contacts[0].law
    assert robot["joints"][0]["dq0"] == robot.joints[0].dq0
    with pytest.raises(KeyError):
        robot["nope"]


def test_a_spec_holds_si_values_of_the_file():
    s = load_scene(SPRING_DROP)
    body, wall = s.subsystems
    assert body.type == "multibody" and wall.type == "rigid"
    assert body.max_step == 1e-5 and body.integrator == "rk4"
    assert body.bodies[0].mass == 1.0 and body.joints[0].kind == "prismatic"
    assert body.joints[0].q0 == 0.01 and body.joints[0].dq0 == -1.0
    assert wall.points == {"surface": (0.0, 0.0)}
    c = s.contacts[0]
    assert (c.a, c.b, c.normal, c.placement) == (("body", "tip"), ("wall", "surface"),
                                                 (1.0, 0.0), "embedded")
    assert c.law.contact_stiffness == 1e6


def _imports(path: Path) -> set[str]:
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module:
            out.add(node.module)
            out |= {f"{node.module}.{a.name}" for a in node.names}
    return {m for m in out if m.startswith("cosim.scene.")}


def _scene_modules():
    return {f"cosim.scene.{p.stem}": p for p in SCENE.glob("*.py") if p.stem != "__init__"}


def test_load_and_build_do_not_import_each_other():
    """Not at the top, not inside a function."""
    assert not any(m.startswith("cosim.scene.build") for m in _imports(SCENE / "load.py"))
    assert not any(m.startswith("cosim.scene.load") for m in _imports(SCENE / "build.py"))
    # the builder reads the specs it is handed: of the scene package it
    # needs only the scene error and, for a cutoff that keeps no mode, the
    # plausibility judgments (a leaf: they import nothing of cosim)
    # (and the FMU side's and the plane body's builders, and a circle contact's
    # rules, which import neither the loader nor the builder)
    assert {m for m in _imports(SCENE / "build.py")
            if not m.startswith(("cosim.scene.fmu_build", "cosim.scene.plane_build",
                                 "cosim.scene.circle_rules"))} \
        <= {"cosim.scene.checks", "cosim.scene.checks.SceneError", "cosim.scene.plausible",
            "cosim.scene.plausible.HIGH_HZ", "cosim.scene.plausible.section_problem"}
    assert not any(m.startswith("cosim") for m in _imports(SCENE / "plausible.py"))
    for builder in ("fmu_build.py", "plane_build.py", "circle_rules.py"):
        assert not any(m.startswith(("cosim.scene.load", "cosim.scene.build"))
                       for m in _imports(SCENE / builder))


def test_the_scene_modules_import_no_circle():
    mods = _scene_modules()
    edges = {m: {d for d in mods if any(i == d or i.startswith(d + ".")
                                         for i in _imports(p))} - {m}
             for m, p in mods.items()}
    state = {}

    def visit(m, trail):
        if state.get(m) == "done":
            return
        assert state.get(m) != "open", f"import circle: {' -> '.join(trail + [m])}"
        state[m] = "open"
        for d in sorted(edges[m]):
            visit(d, trail + [m])
        state[m] = "done"

    for m in sorted(mods):
        visit(m, [])


def test_no_module_of_the_scene_package_is_over_500_lines():
    long = {p.name: n for p in SCENE.glob("*.py")
            if (n := len(p.read_text().splitlines())) > 500}
    assert not long, long


# ------------------------------------------------------- the scheme, once
def test_the_scheme_is_resolved_in_one_place():
    """The messages of the choice live in specs.resolve_scheme alone, and no
    bare default step is left in the builder."""
    texts = {p.name: p.read_text() for p in SCENE.glob("*.py")}
    for phrase in ("ignores the options", "is required by scheme"):
        assert [n for n, t in texts.items() if phrase in t] == ["specs.py"], phrase
    assert "1e-4" not in texts["build.py"] and "warnings" not in texts["build.py"]


def test_resolve_scheme_drops_ignored_options_with_one_warning():
    with pytest.warns(UserWarning) as caught:
        spec = specs.resolve_scheme("monolithic", {"macro_step": 1e-4, "rtol": 1e-8,
                                                   "max_iterations": 3},
                                    {"monolithic": {"atol": 1e-9}}, file="s.toml", t_end=1.0)
    assert len(caught) == 1
    assert str(caught[0].message) == ("s.toml: scheme `monolithic` ignores the options "
                                      "['macro_step', 'max_iterations']")
    assert spec == specs.SchemeSpec("monolithic", {"rtol": 1e-8, "atol": 1e-9},
                                    DEFAULT_MULTIBODY_STEP)
    assert spec.macro_step is None


def test_resolve_scheme_checks_the_macro_step():
    with pytest.raises(SceneError, match=re.escape("`scheme.macro_step` is required by "
                                                   "scheme `jacobi` [s]")):
        specs.resolve_scheme("jacobi", {}, {}, file="s.toml", t_end=1.0)
    with pytest.raises(SceneError, match=re.escape("`scheme.macro_step` is 1e-12 s: the run "
                                                   "would take at most 1e+13 integrator steps "
                                                   "(1e+13 macro steps of 1e-12 s")
                       + ".*" + re.escape(f"more than the {MAX_STEPS:.3g} a run may take")):
        specs.resolve_scheme("jacobi", {"macro_step": 1e-12}, {}, file="s.toml", t_end=10.0)
    with pytest.raises(SceneError, match=re.escape("`scheme.name` ")):
        specs.resolve_scheme("nope", {}, {}, file="s.toml", t_end=1.0)


@pytest.mark.parametrize("macro_step,expected", [(1e-5, 1e-5), (1e-3, DEFAULT_MULTIBODY_STEP)])
def test_the_default_multibody_step_is_the_shorter_of_macro_step_and_its_default(
        macro_step, expected):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        spec = specs.resolve_scheme("jacobi", {"macro_step": macro_step}, {},
                                    file="s.toml", t_end=1.0)
    assert spec.default_step == expected
    s = load_scene(SPRING_DROP, overrides=["subsystems.body.integrator={}",
                                           f"scheme.macro_step={macro_step}"])
    system, _ = s.build()
    assert system.subsystems[0].integrator.max_step == expected


def test_a_scheme_table_applies_when_its_scheme_runs():
    s = load_scene(SPRING_DROP, overrides=["scheme.monolithic.rtol=1e-6"])
    assert s.scheme_options == {"macro_step": 1e-4}
    assert s.scheme_tables == {"monolithic": {"rtol": 1e-6}}
    with warnings.catch_warnings():         # another scheme chosen: no warning
        warnings.simplefilter("error")
        spec = s.scheme_spec("monolithic")
    assert spec.options == {"rtol": 1e-6}
    _, sch = s.build("implicit")
    assert sch.macro_step == 1e-4

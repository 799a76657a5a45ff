"""One validators module per package, and ``bool`` is never a number.

Each package keeps its parameter rules in one module (``couplers.checks``,
``fem.checks``, ``multibody.checks``, ``cosim.scene.checks``); the models
call it, so ``True`` is refused everywhere with a message that names the
parameter, instead of passing as 1.
"""
from __future__ import annotations

import re
from pathlib import Path

import pytest

import couplers
import fem
import multibody
from couplers.checks import positive as couplers_positive
from fem.checks import positive as fem_positive, vector
from multibody.checks import finite, vec2

SRC = Path(__file__).resolve().parents[1] / "src"
CASES = Path(__file__).resolve().parents[1] / "cases"


def test_couplers_refuse_true_as_a_number():
    with pytest.raises(TypeError, match=re.escape("`contact_stiffness` must be a number "
                                                  "[N/m], got True")):
        couplers.LinearLaw(contact_stiffness=True)
    with pytest.raises(TypeError, match=re.escape("`stiffness` must be a number [N/m], "
                                                  "got True")):
        couplers.Grasp(stiffness=True, damping=0.0, tangential_stiffness=0.0,
                       tangential_damping=0.0)
    with pytest.raises(TypeError, match=re.escape("`k` must be a number [N/m], got False")):
        couplers_positive(False, "k", "N/m", allow_zero=True)
    assert couplers_positive(2, "k", "N/m") == 2.0


def test_fem_refuses_true_as_a_number():
    with pytest.raises(TypeError, match=re.escape("`length` must be a number [m], got True")):
        fem.Rod(length=True, youngs_modulus=1.0, density=1.0, area=1.0, n_elements=2)
    with pytest.raises(TypeError, match=re.escape("`origin` must be a 2-vector of numbers, "
                                                  "got (True, 0.0)")):
        vector((True, 0.0), "origin", unit=False)
    with pytest.raises(TypeError, match=re.escape("`x` must be a number [m], got True")):
        fem_positive(True, "x", "m")


def test_multibody_refuses_true_as_a_number():
    with pytest.raises(ValueError, match=re.escape("`stiffness` must be a finite number, "
                                                   "got True")):
        multibody.JointSpring(joint=0, stiffness=True)
    with pytest.raises(ValueError, match=re.escape("`b.com` must be two finite numbers [m], "
                                                   "got (True, 0.0)")):
        multibody.Body("b", 1.0, 0.0, (True, 0.0), {})
    with pytest.raises(ValueError, match=re.escape("`p` must be two finite numbers [m]")):
        vec2([0.0, False], "p")
    assert finite(3, "x") == 3.0


@pytest.mark.parametrize("package", ["couplers", "fem", "multibody"])
def test_no_private_check_crosses_a_module(package):
    """A private helper imported from a sibling module is what the checks
    module replaces: no ``from .x import _name`` of a validator is left."""
    found = []
    for path in sorted((SRC / package).glob("*.py")):
        for line in path.read_text().splitlines():
            m = re.match(r"from \.\w+ import (.*)", line.strip())
            if m and re.search(r"\b_(positive|count|vector|choice|real|finite|nonneg|vec2|"
                               r"unit_interval)\b", m.group(1)):
                found.append(f"{path.name}: {line.strip()}")
    assert not found, found


def test_the_scene_loader_refuses_true_as_a_number():
    from cosim.scene.checks import SceneError
    from cosim.scene.load import load_scene
    scene = CASES / "spring_drop.toml"
    for key, text in (("contacts.wall.law.contact_stiffness", "must be a number, got a "
                                                              "boolean True"),
                      ("subsystems.body.bodies.mass.mass", "must be a number [kg], got a "
                                                           "boolean True"),
                      ("contacts.wall.normal", "must be an array of two numbers [1], got "
                                               "[True, 0.0]")):
        value = "[true, 0.0]" if key.endswith("normal") else "true"
        with pytest.raises(SceneError, match=re.escape(f"`{key}` {text}")):
            load_scene(scene, overrides=[f"{key}={value}"])

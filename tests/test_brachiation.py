"""CASES.md section 7: a brachiation robot hands over from one gripper to the
other on a tensioned cable (``cases/brachiation.toml``).

One run of the scene's default co-simulation (``implicit``, 1 ms steps) and one
of its ``rigid_cable`` variant are shared by the tests that read them.
"""
import math
import re
import subprocess
import sys

import numpy as np
import pytest

import cosim
from conftest import CASES, ROOT
from cosim.build import build_system
from cosim.scene import SceneError

SCENE = CASES / "brachiation.toml"
G = 9.81
ROBOT_MASS = 3.0                # two links of 1.5 kg
K_GRASP = 1e5                   # [N/m] both grasps, normal and tangential
C_GRASP = 100.0                 # [N s/m]
H = 1e-3                        # the scene's macro step [s]


def simulate(variant=None, overrides=(), scheme=None):
    res = cosim.simulate(cosim.load_scene(SCENE, variant, list(overrides), scheme))
    assert res.status == "finished", res.message
    return res


# ----------------------------------------------------------- the static start
@pytest.mark.parametrize("override,message", [
    ("subsystems.cable.static_equilibrium=false",
     r"`subsystems\.cable\.static_loads` are point loads of the static state; they need "
     r"`static_equilibrium = true`"),
    ("subsystems.cable.static_loads={ g3 = -1.0 }",
     r"`subsystems\.cable\.static_loads\.g3` names no point of this structure; its points "
     r"are \['g1', 'g2'\]"),
])
def test_static_loads_are_checked(override, message):
    with pytest.raises(SceneError, match=re.escape(str(SCENE)) + ".*" + message):
        cosim.load_scene(SCENE, overrides=[override])


def test_robot_hanging_at_rest_leaves_the_cable_at_rest():
    """The robot hangs straight down from gripper 1 (elbow reference still 0
    until 0.2 s): the cable starts in static equilibrium under its weight and
    the robot's (``static_loads``), the grasp spring stretched by m g / k.
    Nothing moves.  Without the robot's weight in the static state the cable
    would drop by about 14 mm at gripper 1 and ring."""
    weight = ROBOT_MASS * G
    base = ["t_end=0.15", "subsystems.robot.bodies.link1.joint.q0=-1.5707963267948966",
            f"subsystems.cable.static_loads={{ g1 = {-weight!r} }}"]
    system, _ = build_system(cosim.load_scene(SCENE, overrides=base))
    cable = system.subsystems[[s.name for s in system.subsystems].index("cable")]
    y_cable = float(cable.outputs(0.0, cable.x)[0][0, 1])
    y0 = y_cable - 0.005 - weight / K_GRASP          # offset: the rope's radius
    r = simulate(overrides=base + [f"subsystems.robot.bodies.frame_y.joint.q0={y0!r}"])
    w = r.series["q/cable/w32"]                      # node 32 is x = 1.6 m
    # measured: 1.4e-11 m and 2.6e-7 N (the kept modes carry the static
    # state exactly); with `static_loads = { g1 = 0.0 }`, 26 mm and 28 N
    assert np.max(np.abs(w - w[0])) < 1e-9
    assert np.max(np.abs(r.series["force/gripper1"] + weight)) < 1e-6 * weight

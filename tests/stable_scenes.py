"""Scenes written for the stable-step tests: a pendulum or a two-link arm
strikes a cable, a string, a beam, a rod or a chain through a linear,
Kelvin-Voigt or Hertz law, exchanged by the scheme or hosted by one side.

Every striker hangs from a pivot at (0.5, 0.3) m and reaches 0.5 m; it
starts with its tip 5 mm above the struck point, falling at about 1.5 m/s,
so the first contact comes within a few milliseconds and ``t_end`` can stay
short.  The pendulum is the 1 kg pendulum on a tensioned cable of issue 36.
"""
from __future__ import annotations

import math

#: the tip's starting angle: 5 mm above y = 0 for a 0.5 m reach from y = 0.3 m
Q0 = math.asin((0.005 - 0.3) / 0.5)
#: where the tip starts along x [m]
X_TIP = 0.5 + 0.5 * math.cos(Q0)

STRIKERS = {
    "pendulum": f"""
[subsystems.arm]
type = "multibody"
integrator = {{ method = "rk4", max_step = 1e-5 }}

[subsystems.arm.bodies.bob]
mass = 1.0
inertia = 0.0
com = [0.5, 0.0]
points = {{ tip = [0.5, 0.0] }}
joint = {{ name = "q", type = "revolute", parent = "ground", offset = [0.5, 0.3], q0 = {Q0!r}, dq0 = -3.0 }}
""",
    "arm2": f"""
[subsystems.arm]
type = "multibody"
integrator = {{ method = "rk4", max_step = 1e-5 }}

[subsystems.arm.bodies.upper]
mass = 0.6
inertia = 0.0045
com = [0.15, 0.0]
joint = {{ name = "shoulder", type = "revolute", parent = "ground", offset = [0.5, 0.3], q0 = {Q0!r}, dq0 = -3.0 }}

[subsystems.arm.bodies.fore]
mass = 0.4
inertia = 0.00133
com = [0.1, 0.0]
points = {{ tip = [0.2, 0.0] }}
joint = {{ name = "elbow", type = "revolute", parent = "upper", offset = [0.3, 0.0], q0 = 0.0 }}
""",
}

STRUCTURES = {
    "cable": """
[subsystems.wire]
type = "cable"
length = 2.0
youngs_modulus = 100e9
density = 7850.0
section = { diameter = 0.01 }
tension = 2000.0
elements = 40
left = "pinned"
right = "pinned"
direction = [0.0, 1.0]
points = { hit = %(s)r }
modes = { cutoff_hz = 2000.0 }
""",
    "string": """
[subsystems.wire]
type = "string"
length = 2.0
density = 7850.0
area = 7.85e-5
tension = 2000.0
elements = 40
direction = [0.0, 1.0]
points = { hit = %(s)r }
modes = { cutoff_hz = 2000.0 }
""",
    "beam": """
[subsystems.wire]
type = "beam"
length = 1.5
youngs_modulus = 210e9
density = 7850.0
section = { width = 0.04, height = 0.01 }
elements = 24
left = "pinned"
right = "pinned"
direction = [0.0, 1.0]
points = { hit = %(s)r }
modes = { cutoff_hz = 5000.0 }
""",
    "rod": """
[subsystems.wire]
type = "rod"
length = 0.5
youngs_modulus = 70e9
density = 2700.0
area = 1e-4
elements = 20
left = "free"
right = "fixed"
origin = [%(x)r, 0.0]
axis = [0.0, -1.0]
points = { hit = 0.0 }
modes = { cutoff_hz = 30000.0 }
""",
    "chain": """
[subsystems.wire]
type = "chain"
masses = [0.15, 0.15, 0.15]
stiffnesses = [1.6e5, 1.6e5, 1.6e5]
spacing = 0.05
origin = [%(x)r, 0.0]
direction = [0.0, 1.0]
points = { hit = 0 }
""",
}

LAWS = {
    "linear": '{ type = "linear", contact_stiffness = %(k)r }',
    "kelvin_voigt": '{ type = "kelvin_voigt", contact_stiffness = %(k)r, contact_damping = %(c)r }',
    "hertz": ('{ type = "hertz", contact_stiffness = %(k)r, exponent = 1.5, '
              'reference_penetration = 1e-4 }'),
}


def scene_text(striker="pendulum", structure="cable", law="kelvin_voigt", placement="coupler",
               k=1e4, c=22.0, t_end=0.02, scheme="jacobi", step=1e-5) -> str:
    """A scene file's text (module docstring); ``placement`` is
    ``"coupler"``, ``"host_arm"`` or ``"host_structure"``."""
    place = {"coupler": 'placement = "coupler"',
             "host_arm": 'placement = "embedded"\nhost = "arm"',
             "host_structure": 'placement = "embedded"\nhost = "wire"'}[placement]
    return (f'name = "strike_{striker}_{structure}_{law}_{placement}"\n'
            f"t_end = {t_end!r}\n\n[scheme]\nname = \"{scheme}\"\nmacro_step = {step!r}\n\n"
            "[effects]\ngravity = 9.81\n"
            + STRIKERS[striker]
            + STRUCTURES[structure] % {"s": X_TIP, "x": X_TIP}
            + "\n[contacts.hit]\na = \"arm.tip\"\nb = \"wire.hit\"\nnormal = [0.0, 1.0]\n"
            + place + "\nlaw = " + LAWS[law] % {"k": k, "c": c} + "\n")


#: (striker, structure, law, placement, k, c): the varied scenes of the sweep
VARIED = [
    ("pendulum", "cable", "kelvin_voigt", "coupler", 1e4, 22.0),
    ("pendulum", "cable", "kelvin_voigt", "coupler", 1e7, 22.0),
    ("pendulum", "cable", "kelvin_voigt", "host_arm", 1e4, 22.0),
    ("arm2", "cable", "linear", "coupler", 1e5, 0.0),
    ("pendulum", "string", "kelvin_voigt", "coupler", 1e5, 30.0),
    ("arm2", "string", "linear", "host_structure", 1e5, 0.0),
    ("pendulum", "beam", "kelvin_voigt", "coupler", 1e6, 100.0),
    ("arm2", "beam", "hertz", "coupler", 1e6, 0.0),
    ("pendulum", "rod", "linear", "coupler", 1e6, 0.0),
    ("pendulum", "chain", "kelvin_voigt", "coupler", 1e6, 50.0),
    ("arm2", "chain", "hertz", "host_arm", 1e6, 0.0),
]


def write(tmp_path, *args, **kw):
    """Write :func:`scene_text` to a file in ``tmp_path``; its path."""
    text = scene_text(*args, **kw)
    name = text.split('"')[1]
    p = tmp_path / f"{name}.toml"
    p.write_text(text)
    return p

"""Every shipped scene and variant carries CASES.md's numbers.

The table below is written from CASES.md by hand, every number in full
(``16e6``, never a rounded ``2e+07``).  Each row is one scene with one variant;
the test loads that scene through :func:`cosim.load_scene`, so the variant and
its overrides are applied as a user gets them, and compares every physical
parameter the loaded scene holds (masses, inertias, lengths, points, joint
axes, initial states, gravity, contact laws and normals, chain, beam, rod and
cable data) with the row.  A parameter the scene holds and the row does not
name, or the other way round, fails too, and so does a variant that has no
row.  Derived initial states are computed here from CASES.md's formulas, e.g.
the body's height 0.1 - (m3 + m4) g / (kA + kB), and must agree to a few ulps.

The two scenes of plane bodies (beam_impact_2d, beam_with_holes) are
examples beyond CASES.md: their rows hold section 6's robot, contact and
steel, and the scene files' meshes and sections.

Where CASES.md leaves a value to the project (marked "assumed" there or in
the scene file's comments), the row holds the scene file's value with a
comment saying so; changing it is then a decision, made here too.
"""
import math
import tomllib
from pathlib import Path

import pytest

import cosim
from conftest import CASES

G = 9.81                                    # [m/s^2] CASES.md: gravity along -y
GRAVITY = (0.0, -G)


def linear(k):
    return ("linear", {"contact_stiffness": k})


# ---------------------------------------------------------------- section 1
def spring_drop(law):
    return {
        "gravity": None,
        "body.mass.mass": 1.0, "body.mass.inertia": 0.0, "body.mass.com": (0.0, 0.0),
        "body.mass.point.tip": (0.0, 0.0),
        "body.x.kind": "prismatic", "body.x.parent": "ground", "body.x.offset": (0.0, 0.0),
        "body.x.axis": (1.0, 0.0), "body.x.q0": 0.01, "body.x.dq0": -1.0,
        "body.x.effects": "[]",
        "wall.point.surface": (0.0, 0.0),
        "contact.wall.ports": (("body", "tip"), ("wall", "surface")),
        "contact.wall.normal": (1.0, 0.0), "contact.wall.offset": 0.0,
        "contact.wall.law": law, "contact.wall.connection": None,
    }


# ---------------------------------------------------------------- section 2
ROD_IMPACT = {
    "gravity": None,
    "rod.type": "rod", "rod.length": 1.0, "rod.youngs_modulus": 210e9, "rod.density": 7850.0,
    "rod.area": 1e-4, "rod.left": "free", "rod.right": "free", "rod.origin": (0.0, 0.0),
    "rod.axis": (1.0, 0.0), "rod.initial_velocity": -1.0, "rod.static_equilibrium": False,
    "rod.static_loads": {}, "rod.ports": {"end": 0.0}, "rod.rayleigh": None,
    "wall.point.surface": (0.0, 0.0),
    "contact.wall.ports": (("rod", "end"), ("wall", "surface")),
    "contact.wall.normal": (1.0, 0.0), "contact.wall.offset": 0.0,
    "contact.wall.law": linear(1e10), "contact.wall.connection": None,
}


# ---------------------------------------------------------------- section 3
def manipulator_wall(law):
    row = {"gravity": None, "t_end": 0.561,          # the pose is reported at 0.561 s
           "wall.point.line": (-0.254463, 0.0),      # x_w
           "contact.tip.ports": (("robot", "tip"), ("wall", "line")),
           "contact.tip.normal": (1.0, 0.0), "contact.tip.offset": 0.0,
           "contact.tip.law": law, "contact.tip.connection": None}
    for i in range(1, 11):
        link, joint = f"link{i}", f"q{i}"
        row |= {f"robot.{link}.mass": 0.3341, f"robot.{link}.inertia": 0.0011388,
                f"robot.{link}.com": (0.085, 0.0),                 # mid-link (assumed)
                f"robot.{joint}.kind": "revolute",
                f"robot.{joint}.parent": "ground" if i == 1 else f"link{i - 1}",
                f"robot.{joint}.offset": (0.0, 0.0) if i == 1 else (0.17, 0.0),
                f"robot.{joint}.q0": -0.25, f"robot.{joint}.dq0": -0.2,
                f"robot.{joint}.effects": "[]"}
    row["robot.link10.point.tip"] = (0.17, 0.0)
    return row


def rigid(friction):
    # Poisson restitution R = 0.5 (assumed)
    return ("rigid", {"restitution": 0.5, "friction": friction})


# ---------------------------------------------------------------- section 4
def robot(k_a, q4):
    """Body #3 on T1/T2/R3 with arm #4, resting on A and B pressed equally."""
    k_b = 1e6
    d0 = (10.0 + 2.0) * G / (k_a + k_b)
    row = {"gravity": GRAVITY}
    for frame, joint, parent, axis in (("slider_x", "x", "ground", (1.0, 0.0)),
                                       ("slider_y", "y", "slider_x", (0.0, 1.0))):
        row |= {f"robot.{frame}.mass": 0.0, f"robot.{frame}.inertia": 0.0,
                f"robot.{frame}.com": (0.0, 0.0), f"robot.{joint}.kind": "prismatic",
                f"robot.{joint}.parent": parent, f"robot.{joint}.offset": (0.0, 0.0),
                f"robot.{joint}.axis": axis, f"robot.{joint}.dq0": 0.0,
                f"robot.{joint}.effects": "[]"}
    row |= {
        "robot.x.q0": 0.0, "robot.y.q0": 0.1 - d0,
        "robot.main.mass": 10.0, "robot.main.inertia": 0.1, "robot.main.com": (0.0, 0.0),
        "robot.main.point.A": (-0.2, -0.1), "robot.main.point.B": (0.2, -0.1),   # (assumed)
        "robot.body.kind": "revolute", "robot.body.parent": "slider_y",
        "robot.body.offset": (0.0, 0.0), "robot.body.q0": 0.0, "robot.body.dq0": 0.0,
        "robot.body.effects": "[]",
        "robot.arm.mass": 2.0, "robot.arm.inertia": 0.043, "robot.arm.com": (0.2, -0.08),
        "robot.arm.point.C": (0.3, -0.2),
        "robot.arm.kind": "revolute", "robot.arm.parent": "main",
        "robot.arm.offset": (0.15, 0.1), "robot.arm.q0": q4, "robot.arm.dq0": -20.0,
        "robot.arm.effects": "[]",
        "ground.point.surface": (0.0, 0.0),
    }
    for name, k in (("A", k_a), ("B", k_b)):
        row |= {f"contact.{name}.ports": (("robot", name), ("ground", "surface")),
                f"contact.{name}.normal": (0.0, 1.0), f"contact.{name}.offset": 0.0,
                f"contact.{name}.law": linear(k), f"contact.{name}.connection": None}
    return row


def ground_multicontact(k_a, q4):
    return robot(k_a, q4) | {
        "contact.C.ports": (("robot", "C"), ("ground", "surface")),
        "contact.C.normal": (0.0, 1.0), "contact.C.offset": 0.0,
        "contact.C.law": linear(1e6), "contact.C.connection": None}


# ---------------------------------------------------------------- section 5
C_REF = 1.6e5


def three_mass(f, m_s=0.15):
    return robot(1e6, 2.0) | {
        "chain.type": "chain", "chain.masses": (m_s, m_s, m_s),
        "chain.stiffnesses": (C_REF, C_REF, C_REF), "chain.ground_below": True,
        "chain.direction": (0.0, 1.0), "chain.rayleigh": None,
        # the top at rest level with the ground in static equilibrium: the
        # reference is lifted by the top mass's static sag (3 + 2 + 1) m_s g / c_ref
        "chain.origin.y": 6.0 * m_s * G / C_REF,
        "chain.static_equilibrium": True, "chain.static_loads": {},
        "chain.initial_velocity": 0.0, "chain.ports": {"top": 0.0},
        "contact.C.ports": (("robot", "C"), ("chain", "top")),
        "contact.C.normal": (0.0, 1.0), "contact.C.offset": 0.0,
        "contact.C.law": linear(f * C_REF), "contact.C.connection": None}


# ---------------------------------------------------------------- section 6
BEAM_IMPACT = robot(1e6, 2.0) | {
    "beam.type": "beam", "beam.length": 1.0, "beam.youngs_modulus": 210e9,
    "beam.density": 7850.0, "beam.area": 0.04 * 0.01,
    "beam.second_moment": 0.04 * 0.01 ** 3 / 12.0, "beam.tension": 0.0,
    "beam.left": "pinned", "beam.right": "pinned", "beam.rayleigh": None,
    "beam.axis": (1.0, 0.0), "beam.direction": (0.0, 1.0),
    "beam.origin.y": 0.0,                       # its top surface (supports) at y = 0
    "beam.static_equilibrium": True, "beam.static_loads": {}, "beam.initial_velocity": 0.0,
    "beam.ports": {"under_C": 0.45},            # struck 0.45 m from the left support (assumed)
    "contact.C.ports": (("robot", "C"), ("beam", "under_C")),
    "contact.C.normal": (0.0, 1.0), "contact.C.offset": 0.0,
    "contact.C.law": linear(1.6e6), "contact.C.connection": None,
}


# ------------------------------------------- beyond CASES.md: plane bodies
def plane_beam(mesh, thickness):
    """Section 6's robot and contact C striking a beam meshed in the plane:
    steel as section 6's beam (E, rho), plane stress with nu = 0.3, P2, its
    top face at y = 0, pinned as the 1-D beam (u_y = 0 on the end faces,
    u_x = 0 at the left one's mid-height), struck 0.45 m along the top;
    the mesh and its section are the scene file's (assumed)."""
    return robot(1e6, 2.0) | {
        "beam.type": "plane", "beam.mesh": mesh, "beam.scale": 1.0,
        "beam.model": "plane_stress", "beam.thickness": thickness,
        "beam.youngs_modulus": 210e9, "beam.poisson_ratio": 0.3, "beam.density": 7850.0,
        "beam.element": "P2", "beam.fixed": (), "beam.fixed_x": ("pin",),
        "beam.fixed_y": ("left", "right"), "beam.origin": (0.0233, 0.0), "beam.angle": 0.0,
        "beam.rayleigh": None, "beam.static_equilibrium": True, "beam.static_loads": {},
        "beam.initial_velocity": (0.0, 0.0), "beam.ports": {"under_C": ("top", 0.45)},
        "beam.modes": {"n_modes": None, "cutoff_hz": 20000.0}, "beam.static_correction": True,
        "contact.C.ports": (("robot", "C"), ("beam", "under_C")),
        "contact.C.normal": (0.0, 1.0), "contact.C.offset": 0.0,
        "contact.C.law": linear(1.6e6), "contact.C.connection": None,
    }


# ---------------------------------------------------------------- section 7
def grasp(close, release):
    # stiff bilateral springs (assumed in the scene file: 1e5 N/m, 100 N s/m)
    return {"stiffness": 1e5, "damping": 100.0, "tangential_stiffness": 1e5,
            "tangential_damping": 100.0, "friction": None, "close": close, "release": release}


def brachiation(rigid_cable):
    m, l = 1.5, 0.5                              # links (assumed): 0.5 m, 1.5 kg
    row = {"gravity": GRAVITY}
    for frame, joint, parent, axis, q0 in (("frame_x", "x", "ground", (1.0, 0.0), 1.6),
                                           # the cable's static height at g1, less the
                                           # rope's radius and the grasp's stretch (file)
                                           ("frame_y", "y", "frame_x", (0.0, 1.0), -0.015946)):
        row |= {f"robot.{frame}.mass": 0.0, f"robot.{frame}.inertia": 0.0,
                f"robot.{frame}.com": (0.0, 0.0), f"robot.{joint}.kind": "prismatic",
                f"robot.{joint}.parent": parent, f"robot.{joint}.offset": (0.0, 0.0),
                f"robot.{joint}.axis": axis, f"robot.{joint}.q0": q0,
                f"robot.{joint}.dq0": 0.0, f"robot.{joint}.effects": "[]"}
    row |= {
        "robot.link1.mass": m, "robot.link1.inertia": m * l ** 2 / 12.0,
        "robot.link1.com": (l / 2, 0.0), "robot.link1.point.g1": (0.0, 0.0),
        "robot.link2.mass": m, "robot.link2.inertia": m * l ** 2 / 12.0,
        "robot.link2.com": (l / 2, 0.0), "robot.link2.point.g2": (l, 0.0),
        "robot.shoulder.kind": "revolute", "robot.shoulder.parent": "frame_y",
        "robot.shoulder.offset": (0.0, 0.0),
        "robot.shoulder.q0": -math.pi / 2 - 1.0,     # hanging, swung back 1 rad (assumed)
        "robot.shoulder.dq0": 0.0, "robot.shoulder.effects": "[]",
        "robot.elbow.kind": "revolute", "robot.elbow.parent": "link1",
        "robot.elbow.offset": (l, 0.0), "robot.elbow.q0": 0.0, "robot.elbow.dq0": 0.0,
        # PD swing to 2 asin(0.4 / 0.5) over 0.2 ... 0.7 s (assumed in the scene file)
        "robot.elbow.effects": "[PDTracking(joint=3, kp=100.0, kd=5.0, reference=MinimumJerk("
                               "start=0.0, end=1.287, t_start=0.2, t_end=0.7), max_torque=inf)]",
    }
    for name in ("g1", "g2"):
        contact = f"gripper{name[1]}"
        row |= {f"contact.{contact}.ports": (("robot", name), ("cable", name)),
                f"contact.{contact}.normal": (0.0, -1.0),
                f"contact.{contact}.offset": 0.005,             # the rope's radius
                f"contact.{contact}.law": linear(1e5)}
    row["contact.gripper1.connection"] = grasp(("start", None, None, 0.0),
                                               ("after", None, "gripper2.grasp", 0.05))
    row["contact.gripper2.connection"] = grasp(("touch", None, None, 0.0), None)
    if rigid_cable:
        # the flexible cable's static heights at t = 0 (scene file), same ports
        row["cable.point.g1"] = (1.6, -0.0108303)
        row["cable.point.g2"] = (2.4, -0.00943132)
        return row
    d = 0.01                                     # rope diameter
    return row | {
        "cable.type": "cable", "cable.length": 4.0, "cable.youngs_modulus": 100e9,
        "cable.density": 7850.0, "cable.area": math.pi * d ** 2 / 4,
        "cable.second_moment": math.pi * d ** 4 / 64, "cable.tension": 2000.0,
        "cable.left": "pinned", "cable.right": "pinned", "cable.rayleigh": None,
        "cable.axis": (1.0, 0.0), "cable.direction": (0.0, 1.0), "cable.origin.y": 0.0,
        "cable.static_equilibrium": True, "cable.initial_velocity": 0.0,
        "cable.static_loads": {"g1": -11.568},   # gripper 1's pull at t = 0 (scene file)
        "cable.ports": {"g1": 1.6, "g2": 2.4},   # 0.8 m apart
    }


ROWS = {
    ("spring_drop", "undamped"): spring_drop(linear(1e6)),
    ("spring_drop", "kelvin_voigt"): spring_drop(
        ("kelvin_voigt", {"contact_stiffness": 1e6, "contact_damping": 200.0})),
    ("rod_impact", None): ROD_IMPACT,
    ("manipulator_wall", "mu0"): manipulator_wall(rigid(0.0)),
    ("manipulator_wall", "mu0.03"): manipulator_wall(rigid(0.03)),
    ("manipulator_wall", "mu0.15"): manipulator_wall(rigid(0.15)),
    ("manipulator_wall", "mu0.35"): manipulator_wall(rigid(0.35)),
    # penalty: stiffness (assumed), the dashpot giving restitution 0.5 (scene file)
    ("manipulator_wall", "penalty"): manipulator_wall(
        ("kelvin_voigt", {"contact_stiffness": 1e6, "contact_damping": 596.0})),
    ("ground_multicontact", "kA1e6"): ground_multicontact(1e6, 2.0),
    ("ground_multicontact", "kA4e6"): ground_multicontact(4e6, 2.0),
    ("ground_multicontact", "kA16e6"): ground_multicontact(16e6, 2.0),
    ("ground_multicontact_strike", "kA1e6"): ground_multicontact(1e6, 0.05),
    ("ground_multicontact_strike", "kA4e6"): ground_multicontact(4e6, 0.05),
    ("ground_multicontact_strike", "kA16e6"): ground_multicontact(16e6, 0.05),
    ("three_mass", "f1"): three_mass(1.0),
    ("three_mass", "f2"): three_mass(2.0),
    ("three_mass", "f4"): three_mass(4.0),
    ("three_mass", "f10"): three_mass(10.0),
    ("three_mass", "f100"): three_mass(100.0),
    ("three_mass", "f1000"): three_mass(1000.0),
    ("three_mass", "ms0.01"): three_mass(100.0, 0.01),
    **{("three_mass", f"ms{m}"): three_mass(10.0, m)
       for m in (0.05, 0.1, 0.2, 0.4, 0.8, 1.6, 3.2, 6.4)},
    ("beam_impact", None): BEAM_IMPACT,
    # section 6's beam (40 mm thick, 10 mm high) meshed in the plane
    ("beam_impact_2d", None): plane_beam("beam_2d.msh", 0.04),
    # a deeper beam with seven holes, 10 mm thick (an example: its mesh, beam_with_holes.geo)
    ("beam_with_holes", None): plane_beam("beam_with_holes.msh", 0.01),
    ("brachiation", None): brachiation(rigid_cable=False),
    ("brachiation", "rigid_cable"): brachiation(rigid_cable=True),
}


# ------------------------------------------------------------ the scene's side
def _multibody(sub) -> dict:
    out, n = {}, sub["name"]
    bodies = sub["bodies"]
    for b in bodies:
        out |= {f"{n}.{b['name']}.mass": b["mass"], f"{n}.{b['name']}.inertia": b["inertia"],
                f"{n}.{b['name']}.com": tuple(b["com"])}
        out |= {f"{n}.{b['name']}.point.{p}": tuple(xy) for p, xy in b["points"].items()}
    for j in sub["joints"]:
        key = f"{n}.{j['name']}"
        out |= {f"{key}.kind": j["kind"],
                f"{key}.parent": "ground" if j["parent"] < 0 else bodies[j["parent"]]["name"],
                f"{key}.offset": tuple(j["offset"]), f"{key}.q0": j["q0"],
                f"{key}.dq0": j["dq0"], f"{key}.effects": repr(list(j["effects"]))}
        if j["kind"] == "prismatic":
            out[f"{key}.axis"] = tuple(j["axis"])
    return out


def _structure(sub) -> dict:
    n, model = sub["name"], sub["model"]
    out = {f"{n}.type": sub["type"], f"{n}.static_equilibrium": sub["static_equilibrium"],
           f"{n}.static_loads": dict(sub["static_loads"]),
           f"{n}.initial_velocity": sub["initial_velocity"], f"{n}.ports": dict(sub["ports"]),
           f"{n}.rayleigh": model.rayleigh}
    if sub["type"] == "plane":
        out |= {f"{n}.mesh": Path(model.mesh).name, f"{n}.origin": tuple(model.origin),
                f"{n}.modes": sub["modes"], f"{n}.static_correction": sub["static_correction"]}
        out |= {f"{n}.{k}": getattr(model, k) for k in (
            "scale", "model", "thickness", "youngs_modulus", "poisson_ratio", "density",
            "element", "fixed", "fixed_x", "fixed_y", "angle")}
        return out
    if sub["type"] == "chain":
        out |= {f"{n}.masses": tuple(model.masses), f"{n}.stiffnesses": tuple(model.stiffnesses),
                f"{n}.ground_below": model.ground_below, f"{n}.direction": tuple(model.direction),
                f"{n}.origin.y": model.origin[1]}   # x: where it stands, drawing only
        return out
    out |= {f"{n}.{k}": getattr(model, k) for k in ("length", "youngs_modulus", "density",
                                                    "area", "left", "right")}
    out[f"{n}.axis"] = tuple(model.axis)
    if sub["type"] == "rod":
        out[f"{n}.origin"] = tuple(model.origin)
        return out
    out |= {f"{n}.second_moment": model.second_moment, f"{n}.tension": model.tension,
            f"{n}.direction": tuple(model.direction),
            # x places the support under the struck point; y is the surface's height
            f"{n}.origin.y": model.origin[1]}
    return out


def _law(law):
    return (type(law).__name__.removesuffix("Law").replace("KelvinVoigt", "kelvin_voigt").lower(),
            dict(vars(law)))


def _connection(conn):
    if conn is None:
        return None
    trig = (lambda t: None if t is None else (t.kind, t.time, t.event, t.delay))
    return {**vars(conn.grasp), "friction": conn.friction,
            "close": trig(conn.close), "release": trig(conn.release)}


def parameters(scene) -> dict:
    """Every physical parameter of a loaded scene, by a flat name."""
    out = {"gravity": scene.gravity, "t_end": scene.t_end}
    for sub in scene.subsystems:
        if sub["type"] == "multibody":
            out |= _multibody(sub)
        elif sub["type"] == "rigid":
            out |= {f"{sub['name']}.point.{p}": tuple(xy) for p, xy in sub["points"].items()}
        else:
            out |= _structure(sub)
    for c in scene.contacts:
        key = f"contact.{c['name']}"
        out |= {f"{key}.ports": (tuple(c["a"]), tuple(c["b"])),
                f"{key}.normal": tuple(c["normal"]), f"{key}.offset": c["offset"],
                f"{key}.law": _law(c["law"]), f"{key}.connection": _connection(c["connection"])}
    return out


def same(found, expected) -> bool:
    """Equal, numbers to a few ulps (a rounded number, off by 1e-13, fails)."""
    if isinstance(expected, float) or isinstance(found, float):
        if not isinstance(found, (int, float)) or isinstance(found, bool):
            return False
        return abs(found - expected) <= 4 * math.ulp(max(abs(found), abs(expected)))
    if isinstance(expected, (tuple, list)):
        return (isinstance(found, (tuple, list)) and len(found) == len(expected)
                and all(same(f, e) for f, e in zip(found, expected)))
    if isinstance(expected, dict):
        return (isinstance(found, dict) and found.keys() == expected.keys()
                and all(same(found[k], expected[k]) for k in expected))
    return found == expected


def _shipped():
    rows = []
    for path in sorted(CASES.glob("*.toml")):
        data = tomllib.loads(path.read_text())
        if "default_variant" not in data:        # the file as it is, without a variant
            rows.append((path.stem, None))
        rows += [(path.stem, v) for v in sorted(data.get("variants", {}))]
    return rows


def test_every_shipped_scene_and_variant_has_a_row():
    assert sorted(ROWS, key=str) == sorted(_shipped(), key=str)


@pytest.mark.parametrize("scene,variant", sorted(ROWS, key=str), ids=str)
def test_scene_carries_the_numbers_of_cases_md(scene, variant):
    found = parameters(cosim.load_scene(CASES / f"{scene}.toml", variant))
    row = ROWS[scene, variant]
    if "t_end" not in row:                       # CASES.md gives it for one scene only
        del found["t_end"]
    assert sorted(found) == sorted(row), (set(found) ^ set(row))
    wrong = {k: (found[k], row[k]) for k in row if not same(found[k], row[k])}
    assert not wrong, f"{scene} {variant}: (scene's value, CASES.md's) {wrong}"


def test_a_rounded_stiffness_fails_the_table():
    """The slip this test exists for: kA16e6 written as 2e+07."""
    found = parameters(cosim.load_scene(CASES / "ground_multicontact_strike.toml", "kA16e6",
                                        overrides=["contacts.A.law.contact_stiffness=2e+07"]))
    assert not same(found["contact.A.law"], ROWS["ground_multicontact_strike", "kA16e6"]
                    ["contact.A.law"])
    # and so does a height rounded to 13 digits
    found = parameters(cosim.load_scene(
        CASES / "ground_multicontact_strike.toml", "kA16e6",
        overrides=["subsystems.robot.bodies.slider_y.joint.q0=0.0999930752941"]))
    assert not same(found["robot.y.q0"], ROWS["ground_multicontact_strike", "kA16e6"]
                    ["robot.y.q0"])

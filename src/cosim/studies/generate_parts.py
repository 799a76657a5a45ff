"""The parts a generated scene is drawn from (:mod:`cosim.studies.generate`):
a planar robot of 1 to 4 links, a structure, a contact law and the scheme's
steps, each in a physically sensible range.

Every function takes the scene's own :class:`numpy.random.Generator`, so a
scene depends on its seed and index alone.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["LAWS", "STRUCTURES", "PLACEMENTS", "SCHEMES", "JOINT_KINDS", "draw_robot", "aim",
           "robot_kinematics", "scale_robot", "robot_table", "draw_structure", "law_table",
           "POWER_EXPONENT", "MAX_JOINT_RATE"]

#: the shipped penalty laws (the `rigid` law is left out: it is an impulse
#: resolved inside a moving side against a rigid side, and every generated
#: contact joins a robot to a structure that moves)
LAWS = ("linear", "kelvin_voigt", "hertz", "hunt_crossley", "lankarani_nikravesh", "flores")
#: the built-in structures
STRUCTURES = ("chain", "beam", "cable", "string", "rod")
#: hosted by one side (`embedded`) or exchanged by the scheme (`coupler`)
PLACEMENTS = ("embedded", "coupler")
#: the co-simulation schemes (the monolithic one is the reference)
SCHEMES = ("jacobi", "gauss_seidel", "implicit")
JOINT_KINDS = ("revolute", "prismatic")

#: exponent of the power laws (Hertz's spheres)
POWER_EXPONENT = 1.5
#: [rad/s] the fastest revolute joint a generated robot starts with
MAX_JOINT_RATE = 40.0


def _log_uniform(rng, lo: float, hi: float) -> float:
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


def draw_robot(rng, n_links: int, first_kind: str) -> list[dict]:
    """Links of a serial robot: each a slender bar of mass ``mass`` [kg] and
    length ``length`` [m] on a revolute or prismatic joint (the first joint's
    kind given, the others drawn), in a drawn pose.  Joint rates are left at
    zero: :func:`robot_kinematics` aims them."""
    links = []
    for i in range(n_links):
        kind = first_kind if i == 0 else str(rng.choice(JOINT_KINDS))
        link = {"kind": kind, "mass": _log_uniform(rng, 0.2, 2.0),
                "length": float(rng.uniform(0.15, 0.45)), "axis": (1.0, 0.0), "angle": 0.0}
        if kind == "revolute":
            link["q0"] = float(rng.uniform(-math.pi, math.pi))
        else:
            a = float(rng.uniform(-math.pi, math.pi))
            link["axis"] = (math.cos(a), math.sin(a))
            link["angle"] = float(rng.uniform(-math.pi, math.pi))
            link["q0"] = float(rng.uniform(-0.05, 0.05))
        links.append(link)
    return links


def _tree(links):
    from multibody import Body, Joint, TreeModel
    bodies, joints = [], []
    for i, ln in enumerate(links):
        m, L = ln["mass"], ln["length"]
        bodies.append(Body(f"link{i + 1}", m, m * L * L / 12.0, (L / 2, 0.0),
                           {"tip": (L, 0.0)} if i == len(links) - 1 else {}))
        joints.append(Joint(f"q{i + 1}", ln["kind"], i - 1,
                            (0.0, 0.0) if i == 0 else (links[i - 1]["length"], 0.0),
                            ln["axis"], ln["angle"]))
    return TreeModel(bodies, joints)


def robot_kinematics(links, dq) -> dict:
    """The tip's position, velocity and velocity-product acceleration, and
    the mobility ``n^T J M^-1 J^T`` (2 x 2) of the tip, from cosim's own
    tree (:class:`multibody.TreeModel`)."""
    tree = _tree(links)
    q = np.array([ln["q0"] for ln in links])
    dq = np.asarray(dq, float)
    fr = tree.frames(q, dq)
    pk = tree.points(fr, dq, np.array([len(links) - 1]), np.array([[links[-1]["length"], 0.0]]))
    J = pk.jacobian[0]
    mob = J @ np.linalg.solve(tree.mass_matrix(q), J.T)
    return {"position": pk.position[0], "velocity": pk.velocity[0],
            "acceleration": pk.accel_bias[0], "jacobian": J, "mobility": mob}


def aim(rng, links, speed: float, tilt: float):
    """Joint rates whose tip moves at ``speed`` [m/s] along ``-n``, where the
    unit normal ``n`` is the tip's drawn direction of motion, reversed and
    turned by ``tilt`` [rad] (an oblique strike).  Returns (dq, n, kinematics);
    draws again while a revolute rate would exceed :data:`MAX_JOINT_RATE`."""
    sd = np.array([4.0 if ln["kind"] == "revolute" else 0.4 for ln in links])
    rev = np.array([ln["kind"] == "revolute" for ln in links])
    for _ in range(100):
        dq = rng.normal(0.0, 1.0, len(links)) * sd
        v = robot_kinematics(links, dq)["velocity"]
        vn = float(np.hypot(*v))
        if vn < 1e-3 * float(np.abs(dq).max()):
            continue
        u = -v / vn
        c, s = math.cos(tilt), math.sin(tilt)
        n = np.array([c * u[0] - s * u[1], s * u[0] + c * u[1]])
        dq = dq * speed / (vn * c)             # n . v = -speed
        if not rev.any() or np.abs(dq[rev]).max() <= MAX_JOINT_RATE:
            return dq, n, robot_kinematics(links, dq)
    raise RuntimeError("no joint rates found for the drawn robot")     # pragma: no cover


def scale_robot(links, factor: float) -> list[dict]:
    """The robot with every mass (and so every inertia) times ``factor``."""
    return [{**ln, "mass": ln["mass"] * factor} for ln in links]


def robot_table(links, dq, integrator: dict) -> dict:
    """``[subsystems.robot]`` of the scene: RK4 with the steps of
    ``integrator`` (``max_step``, ``free_step``)."""
    bodies = {}
    for i, ln in enumerate(links):
        L, m = ln["length"], ln["mass"]
        joint = {"name": f"q{i + 1}", "type": ln["kind"],
                 "parent": "ground" if i == 0 else f"link{i}"}
        if i:
            joint["offset"] = [links[i - 1]["length"], 0.0]
        if ln["kind"] == "prismatic":
            joint["axis"] = list(ln["axis"])
            joint["angle"] = ln["angle"]
        joint["q0"], joint["dq0"] = ln["q0"], float(dq[i])
        body = {"mass": m, "inertia": m * L * L / 12.0, "com": [L / 2, 0.0]}
        if i == len(links) - 1:
            body["points"] = {"tip": [L, 0.0]}
        body["joint"] = joint
        bodies[f"link{i + 1}"] = body
    return {"type": "multibody", "integrator": {"method": "rk4", **integrator},
            "bodies": bodies}


_BEAM_ENDS = (("pinned", "pinned"), ("clamped", "clamped"), ("clamped", "pinned"),
              ("clamped", "free"))


def draw_structure(rng, kind: str, gravity: bool) -> tuple[dict, str]:
    """A structure table of type ``kind`` with its origin at [0, 0], axis
    [1, 0] and direction [0, 1] (:mod:`cosim.studies.generate` turns and
    places it), its port ``hit``, and a few kept modes so that the
    monolithic reference stays affordable.  Returns (table, note)."""
    static = gravity and kind != "rod"     # a free rod has no static state under load
    if kind == "chain":
        n = int(rng.integers(1, 5))
        t = {"type": "chain", "masses": [_log_uniform(rng, 0.1, 2.0) for _ in range(n)],
             "stiffnesses": [_log_uniform(rng, 2e4, 5e5) for _ in range(n)],
             "spacing": 0.05, "points": {"hit": 0}}
        note = f"{n} masses"
    elif kind in ("beam", "cable"):
        L = float(rng.uniform(0.5, 2.0))
        ends = _BEAM_ENDS[int(rng.integers(len(_BEAM_ENDS)))] if kind == "beam" else (
            "pinned", "pinned")
        s = L * float(rng.uniform(0.6, 0.95) if ends[1] == "free" else rng.uniform(0.2, 0.8))
        steel = bool(rng.integers(2))
        t = {"type": kind, "length": L, "youngs_modulus": 210e9 if steel else 70e9,
             "density": 7850.0 if steel else 2700.0, "elements": int(rng.integers(8, 17)),
             "left": ends[0], "right": ends[1], "points": {"hit": s},
             "modes": {"count": int(rng.integers(3, 9))}}
        if kind == "beam":
            t["section"] = {"width": float(rng.uniform(0.02, 0.08)),
                            "height": float(rng.uniform(0.006, 0.02))}
            note = f"{ends[0]}-{ends[1]}"
        else:
            t["section"] = {"diameter": float(rng.uniform(0.005, 0.015))}
            t["tension"] = _log_uniform(rng, 500.0, 5000.0)
            note = f"tension {t['tension']:.0f} N"
    elif kind == "string":
        L = float(rng.uniform(0.5, 1.5))
        t = {"type": "string", "length": L, "density": 7850.0, "elements": int(rng.integers(8, 17)),
             "tension": _log_uniform(rng, 500.0, 5000.0), "area": _log_uniform(rng, 2e-5, 1e-4),
             "points": {"hit": L * float(rng.uniform(0.2, 0.8))},
             "modes": {"count": int(rng.integers(3, 8))}}
        note = f"tension {t['tension']:.0f} N"
    elif kind == "rod":
        steel = bool(rng.integers(2))
        right = "free" if rng.integers(2) else "fixed"
        t = {"type": "rod", "length": float(rng.uniform(0.2, 1.0)),
             "youngs_modulus": 210e9 if steel else 70e9, "density": 7850.0 if steel else 2700.0,
             "area": _log_uniform(rng, 1e-4, 1e-3), "elements": int(rng.integers(8, 17)),
             "left": "free", "right": right, "points": {"hit": 0.0},
             "modes": {"count": int(rng.integers(3, 8))}}
        note = f"free-{right}"
    else:
        raise ValueError(f"no structure kind {kind!r}; kinds are {STRUCTURES}")
    if static:
        t["static_equilibrium"] = True
    return t, note


def law_table(rng, law: str, m_red: float, omega: float, speed: float) -> dict:
    """The contact law ``law`` for a reduced mass ``m_red`` [kg] met at
    ``speed`` [m/s]: linear laws of stiffness ``m_red omega^2``; the power
    laws (exponent :data:`POWER_EXPONENT`) store the impact's energy at the
    linear law's peak ``d = speed / omega`` and are linearised there
    (``reference_penetration``), so that the pre-flight check and ``cosim
    info`` can judge them."""
    k = m_red * omega * omega
    if law == "linear":
        return {"type": "linear", "contact_stiffness": k}
    if law == "kelvin_voigt":
        zeta = float(rng.uniform(0.05, 0.4))
        return {"type": "kelvin_voigt", "contact_stiffness": k,
                "contact_damping": 2.0 * zeta * math.sqrt(k * m_red)}
    e = POWER_EXPONENT
    d = speed / omega
    t = {"type": law, "contact_stiffness": (e + 1.0) / 2.0 * k / d ** (e - 1.0), "exponent": e,
         "reference_penetration": d}
    if law == "hunt_crossley":
        t["hysteresis_damping"] = float(rng.uniform(0.05, 0.4)) / speed
    elif law == "lankarani_nikravesh":      # reaches its asked restitution above 0.79
        t.update(restitution=float(rng.uniform(0.8, 0.95)), impact_speed=speed)
    elif law == "flores":     # below 0.6 its linearisation is overdamped (see the module)
        t.update(restitution=float(rng.uniform(0.6, 0.95)), impact_speed=speed)
    elif law != "hertz":
        raise ValueError(f"no law {law!r}; laws are {LAWS}")
    return t

"""Scene 5 (three_mass) as the peers' own models read it: the numbers from
``cases/three_mass.toml`` that the Exudyn and the MuJoCo model are built
from, and the chain's static equilibrium.  Plain Python and numpy, so that
the mapping is tested without either peer package installed.
"""
from __future__ import annotations

import math
import tomllib
from pathlib import Path

import numpy as np

#: the contact laws the peers' models reproduce: a unilateral linear spring,
#: with a viscous damper in parallel for ``kelvin_voigt`` (the force clipped at 0)
LAWS = ("linear", "kelvin_voigt")


def merge(base: dict, over: dict) -> dict:
    """``base`` with ``over``'s keys applied, tables merged key by key."""
    out = dict(base)
    for k, v in over.items():
        out[k] = merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else v
    return out


def scene_numbers(path, variant: str | None = None) -> dict:
    """The numbers of scene 5 that the peers' models need, read from its file.

    Parameters
    ----------
    path : str or Path
        ``cases/three_mass.toml``.
    variant : str, optional
        A variant's overrides are applied first (default: the file's own).

    Returns
    -------
    dict
        ``gravity`` [m/s^2], ``t_end`` [s], ``y0`` (the body's height) [m],
        ``body`` and ``arm`` (``mass`` [kg], ``inertia`` [kg m^2]),
        ``A``, ``B`` (body frame) and ``joint`` (body frame), ``com`` and
        ``C`` (arm frame, from the joint) [m], ``q_arm``, ``dq_arm``
        [rad, rad/s], ``chain_masses`` [kg], ``chain_stiffnesses`` [N/m],
        ``chain_origin`` and ``chain_origin_y`` [m], ``k`` {contact:
        stiffness [N/m]}, ``damping`` {contact: damping [N s/m]}.

    Raises
    ------
    ValueError
        Where the scene leaves what the models map: a joint other than the
        arm's not starting at rest at 0 (the body's height aside), a body
        mass centre off its joint, a contact law other than :data:`LAWS`.
    """
    data = tomllib.loads(Path(path).read_text())
    variant = variant or data.get("default_variant")
    if variant:
        data = merge(data, data["variants"][variant])
    b = data["subsystems"]["robot"]["bodies"]
    main, arm = b["main"], b["arm"]
    chain = data["subsystems"]["chain"]
    for name, body in (("x", b["slider_x"]), ("body", main)):
        j = body["joint"]
        if j.get("q0", 0.0) or j.get("dq0", 0.0):
            raise ValueError(f"{path}: the peers' models start joint `{name}` at rest at 0, "
                             f"the scene gives q0 = {j.get('q0', 0.0)}, "
                             f"dq0 = {j.get('dq0', 0.0)}")
    if b["slider_y"]["joint"].get("dq0", 0.0):
        raise ValueError(f"{path}: the peers' models start joint `y` at rest, the scene gives "
                         f"dq0 = {b['slider_y']['joint']['dq0']}")
    if any(main.get("com", [0.0, 0.0])):
        raise ValueError(f"{path}: `subsystems.robot.bodies.main.com` must be [0, 0] (the "
                         f"body turns about its mass centre), got {main['com']}")
    laws = {}
    for c in "ABC":
        law = data["contacts"][c]["law"]
        if law.get("type") not in LAWS:
            raise ValueError(f"{path}: `contacts.{c}.law.type` must be one of {LAWS} for the "
                             f"peers' models, got {law.get('type')!r}")
        laws[c] = law
    return {
        "gravity": float(data["effects"]["gravity"]),
        "t_end": float(data["t_end"]),
        "y0": float(b["slider_y"]["joint"]["q0"]),
        "body": {"mass": float(main["mass"]), "inertia": float(main["inertia"])},
        "arm": {"mass": float(arm["mass"]), "inertia": float(arm["inertia"])},
        "A": [float(v) for v in main["points"]["A"]],
        "B": [float(v) for v in main["points"]["B"]],
        "joint": [float(v) for v in arm["joint"]["offset"]],
        "com": [float(v) for v in arm["com"]],
        "C": [float(v) for v in arm["points"]["C"]],
        "q_arm": float(arm["joint"].get("q0", 0.0)),
        "dq_arm": float(arm["joint"].get("dq0", 0.0)),
        "chain_masses": [float(v) for v in chain["masses"]],
        "chain_stiffnesses": [float(v) for v in chain["stiffnesses"]],
        "chain_origin": [float(v) for v in chain["origin"]],
        "chain_origin_y": float(chain["origin"][1]),
        "k": {c: float(law["contact_stiffness"]) for c, law in laws.items()},
        "damping": {c: float(law.get("contact_damping", 0.0)) if law["type"] == "kelvin_voigt"
                    else 0.0 for c, law in laws.items()},
    }


def rot(phi: float, v) -> np.ndarray:
    """The plane vector ``v`` turned by ``phi`` [rad]."""
    c, s = math.cos(phi), math.sin(phi)
    return np.array([c * v[0] - s * v[1], s * v[0] + c * v[1]])


def chain_equilibrium(masses, stiffnesses, gravity: float) -> list[float]:
    """Static displacements [m] (top first) of a hanging chain of masses on
    springs, the last spring to the ground, under gravity along -y: spring i
    carries the weight of masses 0..i."""
    u, below = [], 0.0
    for i in reversed(range(len(masses))):
        below -= gravity * sum(masses[:i + 1]) / stiffnesses[i]
        u.append(below)
    return u[::-1]

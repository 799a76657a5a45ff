"""Scenes no one chose by hand: a robot strikes a structure, drawn at random
but reproducible from a seed.

Each scene holds one robot (``robot``: 1 to 4 slender links on revolute
and prismatic joints, its last link's ``tip`` the striking point), one
structure (``target``: a chain, beam, cable, string or rod) and one contact
``strike`` from ``robot.tip`` to ``target.hit`` with one of the shipped
penalty laws, hosted by one side (``embedded``, the lighter by default) or
exchanged by the scheme (``coupler``), under ``jacobi``, ``gauss_seidel``
or ``implicit``.  The categories (structure, law, placement, scheme, the
number of links and the first joint's kind) are dealt from shuffled decks,
so that the first ``n`` scenes hold each structure at least ``n // 5``
times, each law ``n // 6`` times and so on (the first 6 already cover every
category); each deck has its own stream, so the first ``k`` of ``n`` scenes
are the ``k`` scenes of :func:`scenes` ``(k)``.

How a scene is drawn (:func:`draw`), from its own generator
``numpy.random.default_rng([seed, index])``:

1. the robot's links, pose and joint rates: its tip moves at 0.3 to 2 m/s
   along ``-n``, the contact normal, turned 0 to 0.5 rad off the tip's path
   (an oblique strike);
2. the structure, turned so that its field moves along ``n`` (a rod: its
   axis along ``-n``, struck at its free end ``s = 0``), with 3 to 8 modes
   kept; built once (a probe, through the loader) for its port's mobility,
   static compliance and position in its static state under gravity;
3. the robot's masses, scaled so that its mobility at the tip makes it 0.2
   to 5 times as heavy as the structure's port (less where the pair would
   push on for longer than :data:`MAX_PUSH`);
4. the law: a contact time of 1 to 4 ms at the reduced mass (the power laws
   linearised at the linear law's peak penetration, see
   :func:`cosim.studies.generate_parts.law_table`);
5. the structure placed so that the tip meets the port 0.5 to 4 ms after the
   start (shorter where the tip's path curves), the scheme's steps (contact
   steps of a 20th to an 80th of the contact time, four times shorter at
   extrapolation order 0, whose error is first order; an exchanged contact
   under an explicit scheme at 0.3 to 0.9 of the pre-flight check's largest
   safe step, at extrapolation order 1 or 2), and ``t_end`` long enough for
   the contact, the push and every rebound to end, at most :data:`MAX_T_END`.

What is left out by design, and why: the `rigid` law (an impulse resolved
inside a moving side against a rigid side, and every generated contact
strikes a structure that moves); an exchanged contact at extrapolation order
0 under an explicit scheme (the pre-flight check allows it only at about a
500th of the contact time: a run of hundreds of thousands of steps, not a
scene that runs in a second); static equilibrium for a rod (a free rod has
none under an axial load); a Flores law asked for a restitution below 0.6
(linearised at the reference penetration its damping ratio exceeds 1, and
the pre-flight check's model of one contact, which steps a half period of
the damped motion, then has none and gives no safe step).
"""
from __future__ import annotations

import math
import os
import tempfile
import warnings
from pathlib import Path

import numpy as np

from cosim.io.rundir import OutputFolder
from cosim.io.tomlwrite import dumps
from cosim.studies.generate_parts import (JOINT_KINDS, LAWS, PLACEMENTS, SCHEMES, STRUCTURES,
                                          aim, draw_robot, draw_structure, law_table,
                                          robot_kinematics, robot_table, scale_robot)

__all__ = ["scenes", "draw", "write_scenes", "categories", "LAWS", "STRUCTURES", "PLACEMENTS",
           "SCHEMES", "JOINT_KINDS", "LINKS", "MAX_T_END", "MAX_PUSH"]

#: the number of links a robot may have
LINKS = (1, 2, 3, 4)
#: [s] the longest run a generated scene asks for
MAX_T_END = 0.06
#: [s] the longest the robot may push the structure before it leaves: the
#: half period of the robot's mass on the structure's static stiffness
MAX_PUSH = 0.02
#: omega h of a host's RK4 steps while the contact it hosts is closed
HOST_STEP = 0.3
#: the decks the categories are dealt from, in the order of their streams
DECKS = {"structure": STRUCTURES, "law": LAWS, "placement": PLACEMENTS, "scheme": SCHEMES,
         "links": LINKS, "first_joint": JOINT_KINDS}


def categories(n: int, seed: int = 0) -> list[dict]:
    """The categories of the first ``n`` scenes: each deck shuffled anew
    from its own stream whenever it runs out."""
    out = [{} for _ in range(n)]
    for k, (key, deck) in enumerate(DECKS.items()):
        rng = np.random.default_rng([seed, 1_000_003, k])
        dealt: list = []
        while len(dealt) < n:
            dealt += [deck[i] for i in rng.permutation(len(deck))]
        for i in range(n):
            out[i][key] = dealt[i]
    return out


def _log_uniform(rng, lo: float, hi: float) -> float:
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


def _turned(table: dict, n: np.ndarray) -> dict:
    """The structure turned so that its field moves along ``n``."""
    t = dict(table)
    if t["type"] == "rod":
        t["axis"] = [float(-n[0]), float(-n[1])]
    else:
        t["direction"] = [float(n[0]), float(n[1])]
        if t["type"] != "chain":
            t["axis"] = [float(-n[1]), float(n[0])]
    return t


def _probe(table: dict, n: np.ndarray, gravity: float | None) -> dict:
    """Build the structure alone, at the origin, through the loader: its
    port's mobility along ``n`` [1/kg], static compliance along ``n`` [m/N]
    (its elastic modes), position in the initial (static) state [m] and
    highest kept frequency [Hz]."""
    from cosim.scene.load import load_scene
    data = {"name": "probe", "t_end": 1.0, "scheme": {"name": "gauss_seidel", "macro_step": 1e-3},
            "subsystems": {"target": {**table, "origin": [0.0, 0.0]}}}
    if gravity:
        data["effects"] = {"gravity": gravity}
    with tempfile.TemporaryDirectory() as tmp, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        # by its real path: a system's temporary folder may lie below a link
        # (/tmp -> /private/tmp), which the writer refuses
        with OutputFolder(os.path.realpath(tmp), lock=False) as folder:
            path = folder.write("probe.toml", lambda fh: fh.write(dumps(data)), "w")
        system, _ = load_scene(path).build()
    sub = system.subsystems[0]
    port = list(sub.port_names).index("hit")
    pos = sub.outputs(sub.t, sub.x)[0][port]
    # the port's row of the mass-normalised modes (what port_mobility sums)
    row, omega = sub.port_participation(port, n), np.asarray(sub.omega, float)
    elastic = omega > 1e-6 * omega.max()
    return {"mobility": sub.port_mobility(port, n), "position": np.asarray(pos, float),
            "compliance": float(np.sum((row[elastic] / omega[elastic]) ** 2)),
            "f_max": float(omega.max() / (2 * math.pi))}


def _linearised(law: dict) -> tuple[float, float]:
    """The law's linearised stiffness [N/m] and damping [N s/m], as the
    checks read them (:attr:`couplers.laws.ContactLaw.stiffness`)."""
    from couplers.laws import CONTACT_LAWS
    params = {k: v for k, v in law.items() if k != "type"}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        lw = CONTACT_LAWS[law["type"]](**params)
    return lw.stiffness, lw.damping


def _safe_step(law: dict, m_red: float, order: int) -> float:
    """The pre-flight check's largest safe step for the law's linearisation
    at the reduced mass (no rigid partner: the force is extrapolated), searched
    below ten contact times as `cosim info` searches it."""
    from cosim.core import preflight
    k, c = _linearised(law)
    h = preflight.largest_safe_step(m_red, k, c, 10 * math.pi / math.sqrt(k / m_red), order,
                                    0.01, False)
    if not h > 0:
        raise RuntimeError(f"generator bug: no safe step for law {law} at {m_red} kg")
    return h


def _safe_below(law: dict, m_red: float, order: int, h: float) -> float:
    """``h``, rounded down to 3 digits, or a shorter step the pre-flight
    check passes: the energy one contact gains is not monotonic in the step
    (the steps per contact are a whole number), so a step below a safe one
    need not be safe."""
    from cosim.core import preflight
    k, c = _linearised(law)
    for _ in range(10):
        h = _sig_down(h)
        if preflight.is_safe(m_red, k, c, h, order, 0.01, False):
            return h
        h = preflight.largest_safe_step(m_red, k, c, h, order, 0.01, False)
    raise RuntimeError(f"generator bug: no safe step below {h} s for law {law}")


def _sig_down(x: float, digits: int = 3) -> float:
    """``x`` rounded down to ``digits`` significant digits."""
    exp = math.floor(math.log10(x)) - digits + 1
    return float(f"{math.floor(x / 10.0 ** exp * (1 + 1e-12))}e{exp}")


def _sig(x: float, digits: int = 4) -> float:
    return float(f"{x:.{digits}g}")


def draw(index: int, seed: int = 0, cats: dict | None = None) -> tuple[str, dict]:
    """Scene ``index`` of seed ``seed``: (name, scene table).  ``cats`` are its
    categories (:func:`categories`; computed when left out)."""
    if cats is None:
        cats = categories(index + 1, seed)[index]
    rng = np.random.default_rng([seed, index])
    kind, law, placement, scheme = (cats["structure"], cats["law"], cats["placement"],
                                    cats["scheme"])
    gravity = 9.81 if rng.integers(2) else None
    # 1. the robot, aimed
    links = draw_robot(rng, cats["links"], cats["first_joint"])
    speed = _log_uniform(rng, 0.3, 2.0)
    dq, n, kin = aim(rng, links, speed, float(rng.uniform(-0.5, 0.5)))
    # 2. the structure, turned along n and probed
    table, note = draw_structure(rng, kind, gravity is not None)
    table = _turned(table, n)
    probe = _probe(table, n, gravity)
    m_port = 1.0 / probe["mobility"]
    # 3. the robot's mass against the port's
    m_robot = _log_uniform(rng, 0.2, 5.0) * m_port
    if probe["compliance"] > 0:
        m_robot = min(m_robot, max((MAX_PUSH / math.pi) ** 2 / probe["compliance"] - m_port,
                                   0.2 * m_port))
    mob_r = float(n @ kin["mobility"] @ n)
    links = scale_robot(links, m_robot * mob_r)
    mob_r = float(n @ robot_kinematics(links, dq)["mobility"] @ n)
    m_red = 1.0 / (mob_r + probe["mobility"])
    # 4. the law
    t_c = _log_uniform(rng, 1e-3, 4e-3)
    omega = math.pi / t_c
    law_t = law_table(rng, law, m_red, omega, speed)
    # 5. placement, steps, end time
    t_s = _log_uniform(rng, 0.5e-3, 4e-3)
    accel = float(np.hypot(*kin["acceleration"]))
    if accel > 0:
        t_s = min(t_s, 0.2 * speed / accel)
    gap = speed * t_s
    hit = kin["position"] - gap * n
    table["origin"] = [float(x) for x in hit - probe["position"]]
    explicit = scheme != "implicit"
    order = (int(rng.integers(1, 3)) if placement == "coupler" and explicit
             else int(rng.integers(0, 2)) if explicit else 1)
    # a held force (order 0) errs at first order: four times the steps
    h_c = t_c / _log_uniform(rng, 20.0, 80.0) / (4.0 if order == 0 else 1.0)
    if placement == "coupler" and explicit:
        h_c = min(h_c, float(rng.uniform(0.3, 0.9)) * _safe_step(law_t, m_red, order))
        h_c = _safe_below(law_t, m_red, order, h_c)
    else:
        h_c = _sig(h_c, 3)
    macro = _sig(max(_log_uniform(rng, 2e-4, 1e-3), h_c), 3)
    sch = {"name": scheme, "macro_step": macro, "contact_step": h_c,
           "extrapolation_order": order}
    if scheme == "gauss_seidel":
        sch["sequence"] = ["target", "robot"] if rng.integers(2) else ["robot", "target"]
    if scheme == "implicit":
        sch["tolerance"] = 1e-6 if rng.integers(2) else 1e-8
        sch["acceleration"] = "iqn_ils" if rng.integers(2) else "aitken"
    push = (math.pi * math.sqrt((m_robot + m_port) * probe["compliance"])
            if probe["compliance"] > 0 else 0.0)
    t_end = min(MAX_T_END, t_s + 1.5 * max(push, t_c) + 4 * t_c)
    # a host's RK4 resolves the spring against a prescribed point (the build
    # checks omega h <= sqrt(2), omega from the host's own port mobility):
    # steps at omega h <= HOST_STEP, and a 40th (robot), a 200th (structure)
    # of the contact time
    k_lin = _linearised(law_t)[0]
    w_s = max(math.sqrt(k_lin * probe["mobility"]), 2 * math.pi * probe["f_max"])
    table["integrator"] = {"contact_step": _sig(min(t_c / 200, HOST_STEP / w_s), 3)}
    rk4 = {"max_step": _sig(min(1e-4, t_c / 40, HOST_STEP / math.sqrt(k_lin * mob_r)), 3)}
    if rk4["max_step"] < 1e-4:
        rk4["free_step"] = 1e-4            # while the robot hosts nothing closed
    name = f"gen{seed}-{index:03d}"
    joints = "+".join("R" if ln["kind"] == "revolute" else "P" for ln in links)
    data = {"name": name,
            "description": (f"generated (seed {seed}, scene {index}): {len(links)}-link robot "
                            f"({joints}) strikes a {kind} ({note}) at {speed:.2f} m/s, {law} "
                            f"law, {placement}, {scheme}"),
            "t_end": _sig(t_end, 3), "scheme": sch}
    if gravity:
        data["effects"] = {"gravity": gravity}
    data["subsystems"] = {"robot": robot_table(links, dq, rk4),
                          "target": table}
    data["contacts"] = {"strike": {"a": "robot.tip", "b": "target.hit",
                                   "normal": [float(n[0]), float(n[1])], "law": law_t,
                                   "placement": placement}}
    return name, data


def scenes(n: int, seed: int = 0, *, text: bool = True) -> list[tuple[str, str | dict]]:
    """``n`` generated scenes of seed ``seed``: (name, TOML text), or (name,
    table) with ``text=False``.  The same seed gives the same scenes."""
    if n < 0:
        raise ValueError(f"`n` must be >= 0, got {n!r}")
    out = []
    for i, cats in enumerate(categories(n, seed)):
        name, data = draw(i, seed, cats)
        out.append((name, dumps(data) if text else data))
    return out


def write_scenes(folder, n: int, seed: int = 0) -> list[Path]:
    """Write :func:`scenes` as ``NAME.toml`` into ``folder`` (made when
    missing) through cosim's checked writer; returns their paths."""
    paths = []
    with OutputFolder(folder) as out:
        for name, text in scenes(n, seed):
            paths.append(out.write(f"{name}.toml", lambda fh, t=text: fh.write(t), "w"))
    return paths

"""Scene 5 (three_mass) as an Exudyn model: the peer the README compares with.

The numbers come from the scene file itself (``cases/three_mass.toml`` with a
variant applied), so the two models cannot drift apart; the structure is the
one CASES.md sections 4-5 describe, written in Exudyn's own terms:

- the main body (#3) and the arm (#4) are two free planar rigid bodies
  (``NodeRigidBody2D`` + ``ObjectRigidBody2D``, three absolute coordinates
  each, mass centre at the node) joined by a revolute joint
  (``ObjectJointRevolute2D``, one Lagrange multiplier pair): redundant
  coordinates, where cosim uses the four joint coordinates x, y, body, arm;
- the chain is three 1-D masses (``Node1D`` + ``Mass1D``) on coordinate
  springs (``CoordinateSpringDamper``), the last one to the ground, started
  in static equilibrium under gravity;
- each contact is Exudyn's own unilateral penalty element on a coordinate
  gap (``ObjectContactCoordinate``, linear, undamped, its open/closed state
  in a ``NodeGenericData``): A and B between the foot's height and the
  ground, C between the arm tip's height and the top mass's.  A point's
  height is a coordinate marker (``MarkerBodiesRelativeTranslationCoordinate``
  from the ground body along y), so the gap is ``y_C - y_top`` wherever the
  body drifts sideways, as the scene says;
- gravity as constant loads on the mass centres and the chain's coordinates.

It is solved by the implicit trapezoidal rule with index-2 constraints
(``TrapezoidalIndex2``), h = 5e-4 s, adaptive steps, discontinuous
(active-set) iterations with tolerance 1, and the contact elements'
recommended step size, which cuts a step at a contact switch.  Exudyn's
default smallest step (1e-8 s) stops the run at a grazing switch of C near
t = 0.105 s (the recommended step shrinks below it), so the smallest step is
lowered to 1e-12 s; nothing else is tuned.

Run: ``python benchmarks/peers/exudyn_three_mass.py [--variant f100]
[--t-end T] [--step H] [--lift DY] [--out DIR]``.  It prints one JSON line: the CPU time of the
solve alone (``time.process_time`` around ``SolveDynamic``), the number of
steps, and where the series went.  ``DIR/series.npz`` holds, at every
accepted step, ``t``, ``gap/C`` [m] (negative in contact) and its rate
``gap_rate/C`` [m/s], and the robot's joint coordinates in cosim's names
(``q/robot/x``, ``y``, ``body``, ``arm`` and their ``dq/...``), so that
cosim's metrics read it as they read a cosim run.  Needs ``pip install
".[peers]"`` (exudyn 1.13.6).
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

# the scene's numbers, shared with the MuJoCo model (this directory is on the
# path when the script runs, and the tests put it there)
from three_mass_scene import chain_equilibrium, rot, scene_numbers  # noqa: F401

#: the step and settings of the comparison
STEP = 5e-4                 # [s] largest step
MIN_STEP = 1e-12            # [s] smallest step the adaptive control may take
DISCONTINUOUS_TOLERANCE = 1.0


def build(exu, n: dict, t_end: float, step: float = STEP, lift: float = 0.0):
    """The Exudyn system of scene 5 and its simulation settings.

    Parameters
    ----------
    exu : module
        ``exudyn``.
    n : dict
        :func:`scene_numbers`.
    t_end : float
        [s]
    step : float
        Largest step h [s].
    lift : float
        Raise the robot's initial height by this much [m] (a round-off-sized
        lift, 1e-15 m, shows how much the run depends on its step sequence).

    Returns
    -------
    tuple
        ``(mbs, settings, sensors, geometry)``; ``sensors`` maps names to
        sensor numbers that store coordinates and their rates at every step.
    """
    if any(n["damping"].values()):
        raise ValueError(f"the Exudyn model's contacts are undamped, the scene gives "
                         f"{n['damping']} N s/m")
    from exudyn.itemInterface import (CoordinateSpringDamper, LoadCoordinate, LoadForceVector,
                                      MarkerBodiesRelativeTranslationCoordinate,
                                      MarkerBodyPosition, MarkerNodeCoordinate, Mass1D,
                                      Node1D, NodeGenericData, NodePointGround,
                                      NodeRigidBody2D, ObjectContactCoordinate, ObjectGround,
                                      ObjectJointRevolute2D, ObjectRigidBody2D, SensorNode)

    g = n["gravity"]
    n = {**n, "y0": n["y0"] + lift}
    sc = exu.SystemContainer()
    mbs = sc.AddSystem()
    # main body: mass centre on R3, at rest, horizontal
    body_node = mbs.AddNode(NodeRigidBody2D(referenceCoordinates=[0.0, n["y0"], 0.0]))
    body = mbs.AddObject(ObjectRigidBody2D(nodeNumber=body_node, **n["body"]))
    # arm: its node at its mass centre, rotated by q_arm, turning at dq_arm
    joint_point = np.array([0.0, n["y0"]]) + np.array(n["joint"])
    r_com = rot(n["q_arm"], n["com"])
    com = joint_point + r_com
    w = n["dq_arm"]
    arm_node = mbs.AddNode(NodeRigidBody2D(
        referenceCoordinates=[com[0], com[1], n["q_arm"]],
        initialVelocities=[-w * r_com[1], w * r_com[0], w]))
    arm = mbs.AddObject(ObjectRigidBody2D(nodeNumber=arm_node, **n["arm"]))
    c_local = [n["C"][0] - n["com"][0], n["C"][1] - n["com"][1], 0.0]
    mbs.AddObject(ObjectJointRevolute2D(markerNumbers=[
        mbs.AddMarker(MarkerBodyPosition(bodyNumber=body, localPosition=n["joint"] + [0.0])),
        mbs.AddMarker(MarkerBodyPosition(bodyNumber=arm,
                                         localPosition=[-n["com"][0], -n["com"][1], 0.0]))]))
    for obj, mass in ((body, n["body"]["mass"]), (arm, n["arm"]["mass"])):
        mk = mbs.AddMarker(MarkerBodyPosition(bodyNumber=obj, localPosition=[0.0, 0.0, 0.0]))
        mbs.AddLoad(LoadForceVector(markerNumber=mk, loadVector=[0.0, -mass * g, 0.0]))

    ground = mbs.AddObject(ObjectGround())
    ground_coord = mbs.AddMarker(MarkerNodeCoordinate(nodeNumber=mbs.AddNode(NodePointGround()),
                                                      coordinate=0))

    def height(obj, local):
        """A coordinate marker: the height of a body point above y = 0."""
        return mbs.AddMarker(MarkerBodiesRelativeTranslationCoordinate(
            bodyNumbers=[ground, obj], localPosition0=[0.0, 0.0, 0.0],
            localPosition1=list(local), axis0=[0.0, 1.0, 0.0]))

    def contact(lower, upper, k, offset, gap0):
        # gap = upper - lower - offset; force k * (-gap) while gap < 0
        state = mbs.AddNode(NodeGenericData(initialCoordinates=[gap0],
                                            numberOfDataCoordinates=1))
        mbs.AddObject(ObjectContactCoordinate(markerNumbers=[lower, upper], nodeNumber=state,
                                              contactStiffness=k, contactDamping=0.0,
                                              offset=offset))

    for name in ("A", "B"):
        contact(ground_coord, height(body, n[name] + [0.0]), n["k"][name], 0.0,
                n["y0"] + n[name][1])

    u0 = chain_equilibrium(n["chain_masses"], n["chain_stiffnesses"], g)
    chain_nodes, chain_coords = [], []
    for m, u in zip(n["chain_masses"], u0):
        nd = mbs.AddNode(Node1D(referenceCoordinates=[0.0], initialCoordinates=[u]))
        mbs.AddObject(Mass1D(nodeNumber=nd, mass=m))
        mk = mbs.AddMarker(MarkerNodeCoordinate(nodeNumber=nd, coordinate=0))
        mbs.AddLoad(LoadCoordinate(markerNumber=mk, load=-m * g))
        chain_nodes.append(nd)
        chain_coords.append(mk)
    for i, k in enumerate(n["chain_stiffnesses"]):
        below = chain_coords[i + 1] if i + 1 < len(chain_coords) else ground_coord
        mbs.AddObject(CoordinateSpringDamper(markerNumbers=[below, chain_coords[i]],
                                             stiffness=k, damping=0.0))
    # the top mass's height is origin_y + its displacement
    y_c0 = com[1] + rot(n["q_arm"], c_local)[1]
    contact(chain_coords[0], height(arm, c_local), n["k"]["C"], n["chain_origin_y"],
            y_c0 - n["chain_origin_y"] - u0[0])

    ovt = exu.OutputVariableType
    sensors = {}
    for name, nd in (("body", body_node), ("arm", arm_node), ("top", chain_nodes[0])):
        for kind, ov in (("q", ovt.Coordinates), ("dq", ovt.Coordinates_t)):
            sensors[f"{kind}/{name}"] = mbs.AddSensor(SensorNode(
                nodeNumber=nd, outputVariableType=ov, storeInternal=True, writeToFile=False))
    mbs.Assemble()

    s = exu.SimulationSettings()
    ti = s.timeIntegration
    ti.endTime = t_end
    ti.numberOfSteps = max(1, round(t_end / step))
    ti.adaptiveStep = True
    ti.minimumStepSize = MIN_STEP
    ti.discontinuous.iterationTolerance = DISCONTINUOUS_TOLERANCE
    ti.discontinuous.useRecommendedStepSize = True
    ti.verboseMode = 0
    s.solution.file.write = False           # the series goes to series.npz
    s.solution.sensors.writePeriod = 0.0     # every step
    s.show.statistics = False
    s.show.computationTime = False
    geometry = {"system_container": sc,      # keeps the system alive with the caller
                "body_ref": [0.0, n["y0"], 0.0], "arm_ref": [com[0], com[1], n["q_arm"]],
                "c_local": c_local[:2], "top_origin_y": n["chain_origin_y"]}
    return mbs, s, sensors, geometry


def series(mbs, sensors, geometry) -> dict:
    """The stored sensor data as cosim-named arrays at every accepted step."""
    d = {k: mbs.GetSensorStoredData(v) for k, v in sensors.items()}
    t = d["q/body"][:, 0]
    body = d["q/body"][:, 1:4] + geometry["body_ref"]
    arm = d["q/arm"][:, 1:4] + geometry["arm_ref"]
    dbody, darm = d["dq/body"][:, 1:4], d["dq/arm"][:, 1:4]
    cx, cy = geometry["c_local"]
    phi = arm[:, 2]
    rx = np.cos(phi) * cx - np.sin(phi) * cy
    ry = np.sin(phi) * cx + np.cos(phi) * cy
    y_c = arm[:, 1] + ry
    v_c = darm[:, 1] + darm[:, 2] * rx
    y_top = geometry["top_origin_y"] + d["q/top"][:, 1]
    v_top = d["dq/top"][:, 1]
    return {
        "t": t, "gap/C": y_c - y_top, "gap_rate/C": v_c - v_top,
        "q/robot/x": body[:, 0], "q/robot/y": body[:, 1], "q/robot/body": body[:, 2],
        "q/robot/arm": arm[:, 2] - body[:, 2],
        "dq/robot/x": dbody[:, 0], "dq/robot/y": dbody[:, 1], "dq/robot/body": dbody[:, 2],
        "dq/robot/arm": darm[:, 2] - dbody[:, 2],
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default=str(Path(__file__).resolve().parents[2] / "cases"
                                           / "three_mass.toml"))
    ap.add_argument("--variant", default="f100")
    ap.add_argument("--t-end", type=float, default=None, help="[s] (default: the scene's)")
    ap.add_argument("--out", default=None, help="directory for series.npz")
    ap.add_argument("--step", type=float, default=STEP, help=f"largest step [s] (default {STEP})")
    ap.add_argument("--lift", type=float, default=0.0,
                    help="raise the robot's initial height by this much [m] (default 0)")
    a = ap.parse_args(argv)
    import exudyn as exu

    n = scene_numbers(a.scene, a.variant)
    t_end = a.t_end or n["t_end"]
    mbs, settings, sensors, geometry = build(exu, n, t_end, a.step, a.lift)
    cpu0 = time.process_time()
    try:
        ok = exu.SolveDynamic(mbs, settings,
                              solverType=exu.DynamicSolverType.TrapezoidalIndex2)
    except exu.SolverError:
        ok = False
    cpu = time.process_time() - cpu0
    s = series(mbs, sensors, geometry)
    path = None
    if a.out:
        from cosim.io.rundir import OutputFolder

        with OutputFolder(a.out) as folder:     # the checked writer every cosim output uses
            path = folder.write("series.npz", lambda fh: np.savez(fh, **s))
    print(json.dumps({"peer": "exudyn", "version": exu.__version__, "success": bool(ok),
                      "solve_cpu_s": cpu, "steps": int(len(s["t"]) - 1), "t_end": t_end,
                      "step": a.step, "lift": a.lift,
                      "series": None if path is None else str(path)}))
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())

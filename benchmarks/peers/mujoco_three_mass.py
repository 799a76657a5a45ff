"""Scene 5 (three_mass) as a MuJoCo model: the second peer of ``run.py``.

The numbers come from the scene file itself (``cases/three_mass.toml`` with a
variant applied, read by ``three_mass_scene.py`` as for the Exudyn model);
the structure is the one CASES.md sections 4-5 describe, in MuJoCo's terms
(MJCF written by :func:`mjcf`):

- the robot is a tree in cosim's own joint coordinates: the main body (#3)
  carries three joints, slides ``x`` and ``y`` and the hinge ``body`` about
  its mass centre; the arm (#4) is its child, the hinge ``arm`` at the
  joint offset, its mass centre at ``com``.  The plane is MuJoCo's x-y plane,
  hinges about z, gravity along -y (``<option gravity>``);
- the chain is three bodies on slides along y, each in the world, started in
  static equilibrium; its springs are exact linear springs: the ground
  spring the bottom slide's joint stiffness, the two between masses fixed
  tendons (length = the difference of the two slides) with a stiffness;
- MuJoCo's own contacts are switched off (``<flag contact="disable">``): its
  soft constraints are not a penalty spring of a given stiffness (their
  force goes through the impedance ``solimp`` and the constraint's effective
  mass), so the scene's law would only be approximated.  Each contact is instead an
  actuator that is a linear spring by construction: a ``<general>`` actuator
  on the contact point's site with a ``refsite`` (the ground's origin for A
  and B, the top mass for C) and gear (0, 1, 0), so that its length is the
  gap along y in the reference's frame (``y_C - y_top`` wherever the body
  drifts sideways, as the scene says); gain 0 and the affine bias
  ``0 - k gap - c gap_rate`` make its force the penalty spring (and damper,
  for a Kelvin-Voigt law), and the force range [0, inf) makes it unilateral.
  The actuator's force acts along the same direction on both bodies: the
  exact, undamped (for ``linear``) contact force of the scene.

It is integrated by MuJoCo's semi-implicit Euler (velocity first, then the
position with the new velocity) at a fixed step, h = 2.5e-5 s by default,
the cheapest setting ``run.py --mujoco-steps`` found to meet the 1 %
criterion; the run is MuJoCo's C rollout (``mujoco.rollout``, one thread),
which steps without returning to Python.

Run: ``python benchmarks/peers/mujoco_three_mass.py [--variant f100] [--t-end T]
[--step H] [--integrator Euler|RK4|implicit|implicitfast] [--out DIR]``.
It prints one JSON line: the CPU time of the solve alone
(``time.process_time`` around the rollout), the number of steps, and where
the series went.  ``DIR/series.npz`` holds, at every step, ``t``, ``gap/C``
[m] (negative in contact) and its rate ``gap_rate/C`` [m/s], and the
robot's joint coordinates in cosim's names (``q/robot/x``, ``y``, ``body``,
``arm`` and their ``dq/...``), as the Exudyn model's.  Needs ``pip install
".[peers]"`` (mujoco 4.0.0).
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

# the scene's numbers, shared with the Exudyn model (this directory is on the
# path when the script runs, and the tests put it there)
from three_mass_scene import chain_equilibrium, scene_numbers

#: the cheapest setting found to meet the 1 % criterion on f100 (see run.py --mujoco-steps)
STEP = 2.5e-5               # [s]
INTEGRATOR = "Euler"
INTEGRATORS = ("Euler", "RK4", "implicit", "implicitfast")
#: the robot's joints, then the chain's slides (top first): the model's qpos and qvel order
JOINTS = ("x", "y", "body", "arm", "m1", "m2", "m3")
#: the actuators' force limit [N]: unilateral, no upper bound met in practice
FORCE_MAX = 1e30


def _v(*values) -> str:
    """Numbers as MJCF text, each exactly (``repr`` round-trips a float)."""
    return " ".join(repr(float(v)) for v in values)


def steps(t_end: float, step: float) -> tuple[int, float]:
    """The number of fixed steps to ``t_end`` and their length [s]: the
    largest step not above ``step`` that ends exactly there."""
    if not step > 0:
        raise ValueError(f"`--step` must be > 0 s, got {step}")
    n = max(1, math.ceil(t_end / step * (1 - 1e-12)))
    return n, t_end / n


def mjcf(n: dict, step: float = STEP, integrator: str = INTEGRATOR) -> str:
    """The MJCF text of scene 5.

    Parameters
    ----------
    n : dict
        :func:`three_mass_scene.scene_numbers`.
    step : float
        The fixed step [s].
    integrator : str
        One of :data:`INTEGRATORS`.

    Returns
    -------
    str
        The model; its joints are :data:`JOINTS` in that order, its
        actuators ``A``, ``B``, ``C`` the contacts.
    """
    if integrator not in INTEGRATORS:
        raise ValueError(f"`integrator` must be one of {INTEGRATORS}, got {integrator!r}")
    body, arm = n["body"], n["arm"]
    # the hinges turn about z only: the other two principal moments are set
    # equal to it so that the triangle inequality holds; no joint uses them
    ib, ia = body["inertia"], arm["inertia"]
    origin = n["chain_origin"]
    chain = []
    for i, m in enumerate(n["chain_masses"], start=1):
        # the chain moves vertically only: its bodies' rotary inertia is never used
        stiff = (f' stiffness="{_v(n["chain_stiffnesses"][-1])}" springref="0"'
                 if i == len(n["chain_masses"]) else "")
        site = '\n      <site name="top"/>' if i == 1 else ""
        chain.append(f'''    <body name="m{i}" pos="{_v(origin[0], origin[1], 0)}">
      <joint name="m{i}" type="slide" axis="0 1 0"{stiff}/>
      <inertial pos="0 0 0" mass="{_v(m)}" diaginertia="1e-6 1e-6 1e-6"/>{site}
    </body>''')
    tendons = []
    for i, k in enumerate(n["chain_stiffnesses"][:-1], start=1):
        tendons.append(f'''    <fixed name="m{i}-m{i + 1}" stiffness="{_v(k)}" springlength="0">
      <joint joint="m{i}" coef="1"/>
      <joint joint="m{i + 1}" coef="-1"/>
    </fixed>''')
    actuators = []
    for c, ref in (("A", "ground"), ("B", "ground"), ("C", "top")):
        actuators.append(
            f'    <general name="{c}" site="{c}" refsite="{ref}" gear="0 1 0 0 0 0" '
            f'gaintype="fixed" gainprm="0" biastype="affine" '
            f'biasprm="{_v(0, -n["k"][c], -n["damping"][c])}" '
            f'forcelimited="true" forcerange="{_v(0, FORCE_MAX)}"/>')
    nl = "\n"
    return f'''<mujoco model="three_mass">
  <compiler angle="radian" autolimits="true"/>
  <option timestep="{_v(step)}" integrator="{integrator}" gravity="{_v(0, -n["gravity"], 0)}">
    <flag contact="disable"/>
  </option>
  <worldbody>
    <site name="ground" pos="0 0 0"/>
    <body name="main" pos="0 0 0">
      <joint name="x" type="slide" axis="1 0 0"/>
      <joint name="y" type="slide" axis="0 1 0"/>
      <joint name="body" type="hinge" axis="0 0 1"/>
      <inertial pos="0 0 0" mass="{_v(body["mass"])}" diaginertia="{_v(ib, ib, ib)}"/>
      <site name="A" pos="{_v(*n["A"], 0)}"/>
      <site name="B" pos="{_v(*n["B"], 0)}"/>
      <body name="arm" pos="{_v(*n["joint"], 0)}">
        <joint name="arm" type="hinge" axis="0 0 1"/>
        <inertial pos="{_v(*n["com"], 0)}" mass="{_v(arm["mass"])}" diaginertia="{_v(ia, ia, ia)}"/>
        <site name="C" pos="{_v(*n["C"], 0)}"/>
      </body>
    </body>
{nl.join(chain)}
  </worldbody>
  <tendon>
{nl.join(tendons)}
  </tendon>
  <actuator>
{nl.join(actuators)}
  </actuator>
</mujoco>
'''


def initial_state(n: dict, lift: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """``qpos`` and ``qvel`` at t = 0, in the order of :data:`JOINTS`: the
    robot at the scene's height (raised by ``lift`` [m]) and arm angle and
    rate, the chain in static equilibrium and at rest."""
    u = chain_equilibrium(n["chain_masses"], n["chain_stiffnesses"], n["gravity"])
    qpos = np.array([0.0, n["y0"] + lift, 0.0, n["q_arm"], *u])
    qvel = np.array([0.0, 0.0, 0.0, n["dq_arm"], 0.0, 0.0, 0.0])
    return qpos, qvel


def series(n: dict, t, qpos, qvel) -> dict:
    """cosim-named arrays of a run: the joint coordinates as they are, C's
    gap ``y_C - y_top`` [m] and its rate [m/s] from the joint coordinates
    (the same kinematics as the model's C actuator length)."""
    t, q, dq = np.asarray(t, float), np.asarray(qpos, float), np.asarray(qvel, float)
    jx, jy = n["joint"]
    cx, cy = n["C"]
    tb, phi = q[:, 2], q[:, 2] + q[:, 3]
    wb, wphi = dq[:, 2], dq[:, 2] + dq[:, 3]
    y_c = q[:, 1] + np.sin(tb) * jx + np.cos(tb) * jy + np.sin(phi) * cx + np.cos(phi) * cy
    v_c = (dq[:, 1] + wb * (np.cos(tb) * jx - np.sin(tb) * jy)
           + wphi * (np.cos(phi) * cx - np.sin(phi) * cy))
    out = {"t": t, "gap/C": y_c - (n["chain_origin_y"] + q[:, 4]), "gap_rate/C": v_c - dq[:, 4]}
    for i, j in enumerate(JOINTS[:4]):
        out[f"q/robot/{j}"] = q[:, i]
        out[f"dq/robot/{j}"] = dq[:, i]
    return out


def solve(mujoco, n: dict, t_end: float, step: float = STEP, integrator: str = INTEGRATOR,
          lift: float = 0.0) -> dict:
    """Run the model to ``t_end`` by MuJoCo's rollout.

    Returns
    -------
    dict
        ``t`` [s], ``qpos``, ``qvel`` (one row per step, t = 0 first),
        ``solve_cpu_s`` (``time.process_time`` around the rollout alone),
        ``steps`` and ``step`` [s] (the fixed step, ending at ``t_end``).
    """
    from mujoco import rollout

    nstep, h = steps(t_end, step)
    model = mujoco.MjModel.from_xml_string(mjcf(n, h, integrator))
    data = mujoco.MjData(model)
    data.qpos[:], data.qvel[:] = initial_state(n, lift)
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    x0 = np.empty(mujoco.mj_stateSize(model, spec))
    mujoco.mj_getState(model, data, x0, spec)
    cpu0 = time.process_time()
    state, _ = rollout.rollout(model, data, x0, nstep=nstep)
    cpu = time.process_time() - cpu0
    # the full physics state starts with time, qpos and qvel, in that order
    x = np.vstack([x0, state[0]])
    nq, nv = model.nq, model.nv
    return {"t": x[:, 0], "qpos": x[:, 1:1 + nq], "qvel": x[:, 1 + nq:1 + nq + nv],
            "solve_cpu_s": cpu, "steps": nstep, "step": h}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default=str(Path(__file__).resolve().parents[2] / "cases"
                                           / "three_mass.toml"))
    ap.add_argument("--variant", default="f100")
    ap.add_argument("--t-end", type=float, default=None, help="[s] (default: the scene's)")
    ap.add_argument("--out", default=None, help="directory for series.npz")
    ap.add_argument("--step", type=float, default=STEP, help=f"fixed step [s] (default {STEP})")
    ap.add_argument("--integrator", default=INTEGRATOR, choices=INTEGRATORS,
                    help=f"MuJoCo's integrator (default {INTEGRATOR})")
    ap.add_argument("--lift", type=float, default=0.0,
                    help="raise the robot's initial height by this much [m] (default 0)")
    a = ap.parse_args(argv)
    import mujoco

    n = scene_numbers(a.scene, a.variant)
    t_end = a.t_end or n["t_end"]
    r = solve(mujoco, n, t_end, a.step, a.integrator, a.lift)
    s = series(n, r["t"], r["qpos"], r["qvel"])
    # MuJoCo resets a run whose accelerations blow up, and the clock with it
    ok = bool(np.all(np.isfinite(r["qpos"])) and np.all(np.diff(r["t"]) > 0)
              and math.isclose(r["t"][-1], t_end, rel_tol=1e-9))
    path = None
    if a.out:
        from cosim.io.rundir import OutputFolder

        with OutputFolder(a.out) as folder:     # the checked writer every cosim output uses
            path = folder.write("series.npz", lambda fh: np.savez(fh, **s))
    print(json.dumps({"peer": "mujoco", "version": mujoco.__version__, "success": ok,
                      "solve_cpu_s": r["solve_cpu_s"], "steps": r["steps"], "t_end": t_end,
                      "step": r["step"], "integrator": a.integrator, "lift": a.lift,
                      "series": None if path is None else str(path)}))
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())

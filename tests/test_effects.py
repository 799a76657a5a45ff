"""Joint springs, dampers and drives: torques, trajectories and the energy ledger."""
import warnings

import numpy as np
import pytest

import cosim
from multibody import (JointDamper, JointEffects, JointSpring, MinimumJerk, PDTracking,
                       Sinusoid, Table)

PENDULUM = """
t_end = {t_end}
[scheme]
name = "gauss_seidel"
macro_step = 1e-3
[effects]
gravity = 9.81
[subsystems.arm]
type = "multibody"
integrator = {{ method = "rk4", max_step = 1e-3 }}
[subsystems.arm.bodies.link]
mass = 1.0
inertia = 0.0208333
com = [0.25, 0.0]
points = {{ tip = [0.5, 0.0] }}
[subsystems.arm.bodies.link.joint]
name = "q"
type = "revolute"
q0 = -1.2
dq0 = 0.5
{effects}
"""

EFFECTS = """spring = { stiffness = 2.0, rest = 0.1 }
damper = { damping = 0.05 }
drive = { type = "pd", kp = 3.0, kd = 0.2, reference = { type = "sinusoid", amplitude = 0.2, frequency = 1.0 } }"""


def scene(tmp_path, effects=EFFECTS, t_end=2.0, **kw):
    p = tmp_path / "pendulum.toml"
    p.write_text(PENDULUM.format(effects=effects, t_end=t_end))
    with warnings.catch_warnings():          # switching to monolithic drops macro_step
        warnings.simplefilter("ignore")
        return cosim.load_scene(p, **kw)


@pytest.mark.parametrize("scheme", ["monolithic", "gauss_seidel"])
def test_energy_ledger_closes_with_spring_damper_and_drive(tmp_path, scheme):
    """E + dissipated - supplied stays at E0: RK4 at 1e-3 s on a ~1 Hz pendulum
    keeps it within 1e-8 J; the monolithic reference within 1e-9 J."""
    res = cosim.simulate(scene(tmp_path, scheme=scheme))
    e = res.summary["energy"]
    assert e["dissipated"] > 1e-3 and abs(e["supplied"]) > 1e-3
    assert abs(e["initial"] + e["supplied"] - e["dissipated"] - e["final"]) < 1e-8
    assert e["max_abs_drift"] < 1e-8


def test_cosimulation_matches_monolithic(tmp_path):
    ref = cosim.simulate(scene(tmp_path, scheme="monolithic")).summary["final_state"]["arm"]["q"]
    got = cosim.simulate(scene(tmp_path)).summary["final_state"]["arm"]["q"]
    assert got["q"] == pytest.approx(ref["q"], abs=1e-9)
    assert got["dq"] == pytest.approx(ref["dq"], abs=1e-8)


def test_undeclared_effects_are_not_built(tmp_path):
    sys_, _ = scene(tmp_path, effects="").build()
    assert sys_.subsystems[0].effects is None


def test_pd_tracking_follows_a_minimum_jerk_reference(tmp_path):
    """Stiff PD (kp = 400, kd = 40) under gravity: once the reference rests,
    the steady error is at most m g l_c / kp = 9.81 * 0.25 / 400 = 6e-3 rad."""
    eff = ('drive = { type = "pd", kp = 400.0, kd = 40.0, reference = { type = '
           '"minimum_jerk", start = -1.2, end = 0.8, t_start = 0.2, t_end = 1.2 } }')
    res = cosim.simulate(scene(tmp_path, eff, t_end=2.0, overrides=["subsystems.arm.bodies."
                                                                     "link.joint.dq0=0.0"]))
    q = res.summary["final_state"]["arm"]["q"]["q"]
    assert q == pytest.approx(0.8, abs=9.81 * 0.25 / 400)


@pytest.mark.parametrize("traj", [
    Table((0.0, 1.0, 3.0), (0.0, 2.0, -1.0)),
    MinimumJerk(-0.3, 1.1, 0.5, 2.0),
    Sinusoid(0.4, 1.5, 0.3, 0.1)])
def test_trajectory_rate_is_its_derivative(traj):
    for t in (0.3, 0.9, 1.7, 2.4):
        eps = 1e-6
        assert traj.rate(t) == pytest.approx((traj(t + eps) - traj(t - eps)) / (2 * eps),
                                             rel=1e-5, abs=1e-8)


def test_minimum_jerk_ends_at_rest():
    mj = MinimumJerk(1.0, 3.0, 0.0, 2.0)
    assert mj(0.0) == 1.0 and mj(2.0) == 3.0 and mj(5.0) == 3.0
    assert mj.rate(0.0) == 0.0 and mj.rate(2.0) == 0.0
    assert mj(1.0) == pytest.approx(2.0)


def test_effects_torque_and_energy():
    eff = JointEffects(2, [JointSpring(0, 5.0, 0.2), JointDamper(1, 0.5),
                           PDTracking(1, 2.0, 0.1, Table((0.0,), (1.0,)), max_torque=1.0)])
    q, dq = np.array([0.7, 0.0]), np.array([0.0, 2.0])
    tau = eff.torque(0.0, q, dq)
    assert tau[0] == pytest.approx(-5.0 * 0.5)
    # PD: 2 (1 - 0) + 0.1 (0 - 2) = 1.8, saturated at 1; damper -1
    assert tau[1] == pytest.approx(1.0 - 1.0)
    assert eff.potential(q) == pytest.approx(0.5 * 5 * 0.25)
    diss, sup = eff.rates(0.0, q, dq)
    assert diss == pytest.approx(0.5 * 4) and sup == pytest.approx(1.0 * 2)


@pytest.mark.parametrize("text,match", [
    ('spring = { stiffness = -1.0 }', r"`subsystems\.arm\.bodies\.link\.joint\.spring\.stiffness` "
                                      r"must be >= 0"),
    ('drive = { type = "pid" }', r"`subsystems\.arm\.bodies\.link\.joint\.drive\.type` must be one of"),
    ('drive = { type = "table", times = [0.0, 0.0], torques = [1.0, 2.0] }',
     r"`subsystems\.arm\.bodies\.link\.joint\.drive\.times\[1\]` must be greater than the "
     r"time before it, 0\.0 \(times increase strictly\), got 0\.0$"),
    ('drive = { type = "pd", kp = 1.0, kd = 1.0, reference = { type = "minimum_jerk", start = 0.0,'
     ' end = 1.0, t_start = 1.0, t_end = 0.5 } }',
     r"`subsystems\.arm\.bodies\.link\.joint\.drive\.reference\.t_end` must be > "
     r"`t_start`, got 0\.5 <= 1\.0"),
])
def test_effect_errors_name_the_key(tmp_path, text, match):
    with pytest.raises(cosim.SceneError, match=match):
        scene(tmp_path, text)

"""Macro-step control: small steps only around coupler contacts, never a
contact stepped over blindly (rolled back and landed on its onset).

These runs keep 0.13's steps (``land_onsets = false``): they hold what the
controller does on its own (uniform contact steps, a long step landed on the
onset it crossed); landing every contact step on its onsets is held in
tests/test_land_onsets.py."""
import math
import warnings

import numpy as np
import pytest

import cosim
from conftest import CASES

W = 1000.0
BASE = ['contacts.wall.placement="coupler"']


def run(scheme, *ov, order=1, unsafe=True, land=False):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        # the runs study long steps on purpose: the run guard is off
        extra = ["scheme.accept_unsafe_step=true", "guard.energy_check=false"] \
            if unsafe and scheme != "implicit" else []
        scene = cosim.load_scene(CASES / "spring_drop.toml", overrides=BASE + extra + [
            f"scheme.extrapolation_order={order}", *ov,
            *([] if land or scheme == "monolithic" else ["scheme.land_onsets=false"])],
            scheme=scheme)
    res = cosim.simulate(scene, estimate=False)
    assert res.success, res.message
    return res


@pytest.mark.parametrize("scheme", ["jacobi", "gauss_seidel", "implicit"])
def test_controlled_steps_match_uniform_fine_steps_with_far_fewer_windows(scheme):
    """Free flight in 1 ms steps, contact in 12.5 us steps: the same answer
    as 12.5 us throughout (the same forces in contact; free flight is exact)."""
    fine = run(scheme, "scheme.macro_step=1.25e-5")
    ctrl = run(scheme, "scheme.macro_step=1e-3", "scheme.contact_step=1.25e-5")
    fa = fine.summary["final_state"]["body"]["x"]
    fb = ctrl.summary["final_state"]["body"]["x"]
    assert fb["dq"] == pytest.approx(fa["dq"], rel=1e-9)
    assert fb["q"] == pytest.approx(fa["q"], rel=1e-9)
    assert ctrl.n_windows < fine.n_windows / 4
    assert fine.summary["contacts"]["wall"]["intervals"][0] == pytest.approx(
        ctrl.summary["contacts"]["wall"]["intervals"][0], abs=1e-12)


def test_unpredicted_onset_is_rolled_back_and_landed_on():
    """A constant 2000 N push toward the wall: a first 5 ms step would carry the
    body through it (x0 = 1 cm); the linear prediction misses the touch-down,
    the step is rejected and the next one ends at the onset, x0 = a t^2 / 2.
    Landing on the onset is at least as accurate as uniform fine steps, whose
    grid straddles it (errors against the monolithic reference)."""
    push = ['subsystems.body.bodies.mass.joint.drive={type="constant", torque=-2000.0}',
            "subsystems.body.bodies.mass.joint.dq0=0.0"]
    ref = run("monolithic", *push).summary["final_state"]["body"]["x"]["dq"]
    fine = run("implicit", "scheme.macro_step=1.25e-5", *push)
    ctrl = run("implicit", "scheme.macro_step=5e-3", "scheme.contact_step=1.25e-5", *push)
    assert ctrl.n_rejected >= 1
    on_c = ctrl.summary["contacts"]["wall"]["intervals"][0][0]
    assert on_c == pytest.approx(math.sqrt(2 * 0.01 / 2000.0), abs=1e-9)
    err_fine = abs(fine.summary["final_state"]["body"]["x"]["dq"] - ref)
    err_ctrl = abs(ctrl.summary["final_state"]["body"]["x"]["dq"] - ref)
    # both carry the contact phase's second-order error (omega H = 0.0125 at
    # an approach of 6.3 m/s, two impacts): observed 1.25e-3 of the speed
    assert err_ctrl <= err_fine * (1 + 1e-9) and err_ctrl < 2e-3 * abs(ref), (err_ctrl,
                                                                              err_fine)


def test_extrapolation_of_an_open_contact_never_pulls():
    """Linear extrapolation after release would carry the falling force on
    into tension over the next (80 times longer) step; it is held at zero, and
    the rebound keeps the second-order bound of the uniform steps."""
    res = run("jacobi", "scheme.macro_step=1e-3", "scheme.contact_step=1.25e-5")
    assert res.series["force/wall"].min() >= 0.0
    v = res.summary["final_state"]["body"]["x"]["dq"]
    assert v == pytest.approx(1.0, abs=0.25 * (W * 1.25e-5) ** 2)


def test_preflight_judges_the_contact_step():
    with pytest.raises(cosim.UnsafeStepError, match=r"macro step 2e-05 s is too large"):
        run("jacobi", "scheme.macro_step=1e-3", "scheme.contact_step=2e-5", order=0,
            unsafe=False)


@pytest.mark.parametrize("scheme", ["jacobi", "gauss_seidel", "implicit"])
@pytest.mark.parametrize("push,v0", [(500.0, -0.5), (2000.0, 0.5), (8000.0, 0.0)])
def test_onset_is_landed_on_for_any_push_and_approach_speed(scheme, push, v0):
    """A constant push F towards the wall from x0 = 1 cm at speed v0 (< 0:
    towards it): touch-down at t_on = (v0 + sqrt(v0^2 + 2 a x0)) / a,
    a = F / m, free motion before it.  With 5 ms long steps and 12.5 us
    contact steps the onset is located to 1e-9 s (observed 3.4e-11 or
    better), no force acts before it, and the first sample in contact is
    one contact step after touch-down: its penetration is at most
    v_on * contact_step (no step carries the body through the wall with
    the force still at zero)."""
    a = push / 1.0
    t_on = (v0 + math.sqrt(v0 * v0 + 2 * a * 0.01)) / a
    v_on = math.sqrt(v0 * v0 + 2 * a * 0.01)
    res = run(scheme, "scheme.macro_step=5e-3", "scheme.contact_step=1.25e-5",
              f"subsystems.body.bodies.mass.joint.drive={{type=\"constant\", torque={-push}}}",
              f"subsystems.body.bodies.mass.joint.dq0={v0}", "t_end=0.01")
    on = res.summary["contacts"]["wall"]["intervals"][0][0]
    assert on == pytest.approx(t_on, abs=1e-9), (on, t_on)
    t, gap, force = res.series["t"], res.series["gap/wall"], res.series["force/wall"]
    assert np.all(force[t < t_on - 1e-9] == 0.0)
    first = np.flatnonzero(gap < 0)[0]
    assert -gap[first] <= v_on * 1.25e-5, (t[first], -gap[first], v_on * 1.25e-5)


@pytest.mark.parametrize("scheme", ["jacobi", "gauss_seidel", "implicit"])
def test_a_shorter_approach_horizon_saves_the_approach_steps_only(scheme):
    """``approach_horizon`` sets how far ahead a predicted onset shortens the
    step: free flight is exact here, so a horizon of 0.1 ms instead of the
    1.5 ms macro step gives the same answer in fewer macro steps (the
    onset, at 10 ms, falls inside a long step: rolled back and landed on)."""
    steps = ("scheme.macro_step=1.5e-3", "scheme.contact_step=1.25e-5")
    wide = run(scheme, *steps)
    near = run(scheme, *steps, "scheme.approach_horizon=1e-4")
    fa = wide.summary["final_state"]["body"]["x"]
    fb = near.summary["final_state"]["body"]["x"]
    assert fb["dq"] == pytest.approx(fa["dq"], rel=1e-9)
    assert fb["q"] == pytest.approx(fa["q"], rel=1e-9)
    assert np.allclose(near.summary["contacts"]["wall"]["intervals"],
                       wide.summary["contacts"]["wall"]["intervals"], rtol=0, atol=1e-12)
    # the 1 ms before the onset was 80 steps of 12.5 us; now one rolled back
    assert near.n_windows <= wide.n_windows - 60
    assert near.n_rejected >= 1


@pytest.mark.parametrize("ulps", [0, 2, -2])
def test_approach_horizon_on_a_train_of_impacts_changes_only_free_flight(ulps):
    """three_mass f100 (C closes 9 times): a 0.5 ms horizon takes the approach
    in fewer steps; C's count is the same and its peak and the arm's exit
    rate move by less than 1e-4 relative (the robot's RK4 sub-steps in free
    flight are split differently; measured 1e-5, against the scene's own
    error of 1e-3 against the bench's reference)."""
    from cosim.studies.metrics import impact_metrics
    from cosim.studies.roundoff import perturbed
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = perturbed(cosim.load_scene(CASES / "three_mass.toml", variant="f100"), ulps)
        near_scene = perturbed(cosim.load_scene(CASES / "three_mass.toml", variant="f100",
                                                overrides=["scheme.approach_horizon=5e-4"]),
                               ulps)
    wide, near = cosim.simulate(scene, estimate=False), cosim.simulate(near_scene, estimate=False)
    mw, mn = (impact_metrics(r, "C", "robot/arm") for r in (wide, near))
    assert mn["count"] == mw["count"] == 9
    assert mn["peak"] == pytest.approx(mw["peak"], rel=1e-4)
    assert mn["exit_velocity"] == pytest.approx(mw["exit_velocity"], rel=1e-4)
    assert near.n_windows <= wide.n_windows - 15

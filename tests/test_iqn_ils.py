"""Interface quasi-Newton (IQN-ILS) acceleration of the implicit scheme,
against Aitken relaxation: the same answer, fewer iterations when several
coupler contacts are closed at once."""
import functools
import re
import warnings

import numpy as np
import pytest

import cosim
from cosim.scene.load import SceneError
from cosim.core.schemes import Implicit
from conftest import CASES

# A bar (on a vertical slider, free to tilt) pressed by a constant 500 N onto
# two feet on springs (1e5 N/m each).  The two contacts are coupler contacts
# of different stiffness (1e6 and 1e7 N/m), so the interface residual has two
# directions that answer a force change very differently.  The run starts
# near the static equilibrium (250 N on each foot) and a downward kick of
# 0.1 m/s makes it vibrate; both contacts stay closed throughout.
PRESSED = """
name = "two_point_press"
description = "A bar pressed onto two sprung feet: two coupler contacts closed at once"
t_end = 0.004

[scheme]
name = "implicit"
macro_step = 1e-4

[subsystems.plate]
type = "multibody"
integrator = { method = "rk4", max_step = 1e-5 }

[subsystems.plate.bodies.slider]
mass = 1.0

[subsystems.plate.bodies.slider.joint]
name = "y"
type = "prismatic"
parent = "ground"
axis = [0.0, 1.0]
q0 = -2.6375e-3
dq0 = -0.1
drive = { type = "constant", torque = -500.0 }

[subsystems.plate.bodies.bar]
mass = 0.5
inertia = 0.002
points = { L = [-0.1, 0.0], R = [0.1, 0.0] }
joint = { name = "tilt", type = "revolute", parent = "slider", q0 = 1.125e-3 }

[subsystems.feet]
type = "multibody"
integrator = { method = "rk4", max_step = 1e-5 }

[subsystems.feet.bodies.left]
mass = 0.2
points = { P = [0.0, 0.0] }

[subsystems.feet.bodies.left.joint]
name = "yl"
type = "prismatic"
parent = "ground"
offset = [-0.1, 0.0]
axis = [0.0, 1.0]
q0 = -2.5e-3
spring = { stiffness = 1e5 }

[subsystems.feet.bodies.right]
mass = 0.2
points = { Q = [0.0, 0.0] }

[subsystems.feet.bodies.right.joint]
name = "yr"
type = "prismatic"
parent = "ground"
offset = [0.1, 0.0]
axis = [0.0, 1.0]
q0 = -2.5e-3
spring = { stiffness = 1e5 }

[contacts.left]
a = "plate.L"
b = "feet.P"
normal = [0.0, 1.0]
law = { type = "linear", contact_stiffness = 1e6 }

[contacts.right]
a = "plate.R"
b = "feet.Q"
normal = [0.0, 1.0]
law = { type = "linear", contact_stiffness = 1e7 }

# the bar lands tilting: the contacts close and open at different times
[variants.landing]
subsystems.plate.bodies.slider.joint.q0 = 0.001
subsystems.plate.bodies.slider.joint.dq0 = -1.0
subsystems.plate.bodies.slider.joint.drive.torque = 0.0
subsystems.plate.bodies.bar.joint.q0 = 0.0
subsystems.plate.bodies.bar.joint.dq0 = 2.0
subsystems.feet.bodies.left.joint.q0 = 0.0
subsystems.feet.bodies.right.joint.q0 = 0.0
"""


@pytest.fixture(scope="module")
def pressed(tmp_path_factory):
    path = tmp_path_factory.mktemp("iqn") / "two_point_press.toml"
    path.write_text(PRESSED)
    return path


@functools.lru_cache(maxsize=None)      # several tests compare the same runs
def run(path, *overrides, variant=None, acceleration="aitken", reuse=0, tolerance=1e-8):
    ov = [f'scheme.acceleration="{acceleration}"', f"scheme.tolerance={tolerance}", *overrides]
    if acceleration == "iqn_ils":
        ov.append(f"scheme.reuse={reuse}")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = cosim.load_scene(path, variant, ov, "implicit")
    res = cosim.simulate(scene)
    assert res.success, res.message
    return res


def final_state(res):
    """Joint coordinates and rates of every subsystem, (2, n_joints)."""
    return np.array([(joint["q"], joint["dq"]) for sub in res.summary["final_state"].values()
                     for joint in sub.values()]).T


def assert_close(res, ref, rtol):
    """Coordinates and rates each within ``rtol`` of the largest of their
    kind (a tilt near zero has no relative error of its own)."""
    x, x_ref = final_state(res), final_state(ref)
    err = np.abs(x - x_ref).max(axis=1) / np.abs(x_ref).max(axis=1)
    assert np.all(err <= rtol), err


def test_one_contact_is_the_secant_method_like_aitken():
    """With one coupler contact the residual is a scalar: IQN-ILS and Aitken
    are both the secant method after one relaxed pass, so they agree to
    rounding and take the same iterations (measured 266 each over 200
    steps)."""
    drop = CASES / "spring_drop.toml"
    coupler = 'contacts.wall.placement="coupler"'
    a = run(drop, coupler)
    q = run(drop, coupler, acceleration="iqn_ils")
    assert a.summary["contacts"]["wall"]["count"] == 1
    assert a.n_iterations > a.n_windows           # the contact steps did iterate
    assert_close(q, a, 1e-8)
    assert abs(q.n_iterations - a.n_iterations) <= 0.02 * a.n_iterations


@pytest.mark.parametrize("variant,reuse", [(None, 0), (None, 2), ("landing", 0),
                                           ("landing", 2)])
def test_iqn_ils_converges_to_the_answer_of_aitken(pressed, variant, reuse):
    """Two coupler contacts, closed throughout or closing and opening at
    different times (where reused secants must be dropped).  Reference:
    Aitken converged to 1e-12.  Run to the default tolerance 1e-8, the
    largest error measured was 2.5e-8 (Aitken, landing, rates; IQN-ILS
    6e-9); run to 1e-6 instead, Aitken is off by 2.8e-6 (pressed) and
    5.1e-7 (landing), IQN-ILS with reuse by 2.5e-7 (landing), so the bound
    1e-7 tells a converged step from one accepted early."""
    ref = run(pressed, variant=variant, tolerance=1e-12)
    if variant == "landing":
        iv = {k: c["intervals"] for k, c in ref.summary["contacts"].items()}
        assert len(iv["right"]) == 2 and iv["left"][0][0] < iv["right"][0][0], iv
    assert_close(run(pressed, variant=variant), ref, 1e-7)
    assert_close(run(pressed, variant=variant, acceleration="iqn_ils", reuse=reuse), ref, 1e-7)


def test_iqn_ils_needs_fewer_iterations_with_several_contacts(pressed):
    """40 macro steps with both contacts closed: Aitken took 268 iterations,
    IQN-ILS 160 (4 a step: a relaxed pass, one secant, then the two-column
    model of the nearly linear interface, then the check), ratio 0.60."""
    a = run(pressed, variant=None)
    q = run(pressed, variant=None, acceleration="iqn_ils", reuse=0)
    assert a.n_windows == q.n_windows == 40
    assert q.n_iterations < 0.7 * a.n_iterations, (q.n_iterations, a.n_iterations)


def test_reused_secants_save_further_iterations(pressed):
    """Smooth, closed contacts: the secants of the previous step model the
    next one's interface well.  Measured 160 iterations without reuse, 118
    with reuse = 1, 90 with reuse = 2 (ratio 0.56); with two contacts at most
    two columns are used, so reuse > 2 changes nothing here."""
    q0 = run(pressed, variant=None, acceleration="iqn_ils", reuse=0)
    q2 = run(pressed, variant=None, acceleration="iqn_ils", reuse=2)
    assert q2.n_iterations < 0.7 * q0.n_iterations, (q2.n_iterations, q0.n_iterations)


def test_unknown_acceleration_is_refused_by_the_scene_loader():
    with pytest.raises(SceneError, match=re.escape(
            "`scheme.acceleration` must be one of ['aitken', 'iqn_ils'], got 'newton'")):
        cosim.load_scene(CASES / "spring_drop.toml", None,
                         ['scheme.acceleration="newton"'], "implicit")


@pytest.mark.parametrize("key,value,rule", [
    ("acceleration", "newton", "one of ['aitken', 'iqn_ils']"),
    ("reuse", -1, ">= 0 (macro steps)"),
    ("filter_tolerance", 0.0, "in (0, 1)"),
])
def test_bad_acceleration_options_are_refused_by_the_scheme(key, value, rule):
    with pytest.raises(ValueError, match=re.escape(
            f"`{key}` of scheme `implicit` must be {rule}, got {value!r}")):
        Implicit(macro_step=1e-4, **{key: value})


def test_acceleration_must_be_a_string():
    with pytest.raises(SceneError, match=re.escape(
            "`scheme.acceleration` must be a string, got an integer 1")):
        cosim.load_scene(CASES / "spring_drop.toml", None, ["scheme.acceleration=1"],
                         "implicit")


def test_iqn_options_without_iqn_ils_warn():
    with pytest.warns(UserWarning, match=re.escape(
            "scheme `implicit` with `acceleration` 'aitken' ignores the options ['reuse']")):
        Implicit(macro_step=1e-4, reuse=2)

"""The subsystem protocol, the stepper, extrapolation and the recorder's helpers."""
import math

import numpy as np
import pytest

from couplers import LinearLaw, PointContact
from cosim import RK4, StepInput
from cosim.sides.multibody import MultibodySubsystem
from cosim.core.recorder import hermite_cubic_max
from cosim.core.schemes import extrapolation_coeffs
from multibody import Body, Joint, TreeModel


def slider(mass=2.0, q0=0.0, dq0=0.0, max_step=1e-3):
    model = TreeModel([Body("b", mass, 0.0, points={"p": (0.0, 0.0)})],
                      [Joint("x", "prismatic", axis=(1.0, 0.0))])
    return MultibodySubsystem("s", model, [q0], [dq0], {"p": (0, (0.0, 0.0))},
                              integrator=RK4(max_step=max_step))


def const_force(t0, h, fx):
    return StepInput(t0, h, np.array([[[fx, 0.0]]]))


def test_step_owns_time_status_and_counters():
    s = slider()
    s.step(0.0, 0.1, const_force(0.0, 0.1, 4.0))
    assert s.t == pytest.approx(0.1) and s.n_steps == 1 and s.status == "running"
    # exact under a constant force: x = F t^2 / (2 m)
    assert s.x[0] == pytest.approx(4.0 * 0.01 / 4.0, rel=1e-12)
    with pytest.raises(RuntimeError, match=r"is at t = 0\.1.* from t = 0\.5"):
        s.step(0.5, 0.1)
    with pytest.raises(ValueError, match=r"`h` must be > 0 s, got -0\.1"):
        s.step(0.1, -0.1)


def test_failure_marks_status_and_stops_stepping():
    s = slider()

    class Bad(StepInput):
        def __call__(self, t):
            raise FloatingPointError("boom")
    inp = Bad(0.0, 0.1, np.zeros((1, 1, 2)))
    with pytest.raises(FloatingPointError):
        s.step(0.0, 0.1, inp)
    assert s.status == "failed"
    with pytest.raises(RuntimeError, match="is failed"):
        s.step(0.0, 0.1)


def test_rollback_repeats_bit_identically():
    s = slider(q0=0.3, dq0=-1.0)
    s.embed_contact(PointContact("w", LinearLaw(1e5), (1.0, 0.0)), 0, 1.0, (0.0, 0.0))
    s.step(0.0, 0.2, const_force(0.0, 0.2, 0.5))
    saved = s.get_state()
    s.step(0.2, 0.3, const_force(0.2, 0.3, -0.7))
    first = (s.x.copy(), s.aux.copy(), s.t, s.n_steps)
    s.set_state(saved)
    assert s.t == 0.2 and s.n_steps == 1
    s.step(0.2, 0.3, const_force(0.2, 0.3, -0.7))
    assert np.array_equal(s.x, first[0]) and np.array_equal(s.aux, first[1])
    assert (s.t, s.n_steps) == first[2:]


def test_step_input_polynomial():
    c = np.array([[[1.0, 2.0]], [[3.0, 0.0]], [[-1.0, 4.0]]])
    u = StepInput(1.0, 0.5, c)
    s = 0.3 / 0.5
    assert np.allclose(u(1.3), c[0] + c[1] * s + c[2] * s * s)


@pytest.mark.parametrize("order", [0, 1, 2])
def test_extrapolation_is_exact_for_polynomials_of_its_order(order):
    p = np.poly1d([0.7, -2.0, 3.0][2 - order:])      # degree == order
    hist = [np.array([p(-2.0)]), np.array([p(-1.0)]), np.array([p(0.0)])]
    co = extrapolation_coeffs(hist, order)
    for s in (0.25, 1.0):
        assert sum(co[j, 0] * s ** j for j in range(len(co))) == pytest.approx(p(s))
    # the last step may be shorter: ratio 0.5 puts s = 1 at half a step
    co = extrapolation_coeffs(hist, order, ratio=0.5)
    assert sum(co[j, 0] for j in range(len(co))) == pytest.approx(p(0.5))


def test_extrapolation_falls_back_when_history_is_short():
    co = extrapolation_coeffs([np.array([2.0])], 2)
    assert co.shape == (1, 1) and co[0, 0] == 2.0


def test_rk4_converges_at_fourth_order():
    """Harmonic oscillator to t = 3, 3 refinements, polyfit slope of the state error."""
    f = lambda t, y: np.array([y[1], -y[0]])
    hs = np.array([0.2, 0.1, 0.05, 0.025])
    exact = np.array([math.cos(3.0), -math.sin(3.0)])
    errs = [np.linalg.norm(RK4(max_step=h).integrate(f, 0.0, np.array([1.0, 0.0]), 3.0) - exact)
            for h in hs]
    slope = np.polyfit(np.log(hs), np.log(errs), 1)[0]
    assert abs(slope - 4) < 0.1, f"observed order {slope:.2f}"
    assert errs[-1] < 1e-7


def test_rk4_locates_a_switch_and_restarts_there():
    """A mass falls at -1 m/s from x = 0.05 onto a spring floor (k/m = 1e4):
    touch at t = 0.05 s exactly; with the switch located inside the sub-step,
    the rebound is exact to RK4's error even with a coarse grid whose points
    straddle the touch."""
    w2 = 1e4
    f = lambda t, y: np.array([y[1], -w2 * min(y[0], 0.0)])
    sw = lambda t, y: np.array([-y[0]])
    log = []
    y = RK4(max_step=7e-4).integrate(f, 0.0, np.array([0.05, -1.0]), 0.2, sw,
                                     lambda t, j, on, y: log.append((t, on)))
    t_c = math.pi / math.sqrt(w2)
    assert [on for _, on in log] == [True, False]
    assert log[0][0] == pytest.approx(0.05, abs=1e-12)
    assert log[1][0] == pytest.approx(0.05 + t_c, rel=1e-6)
    assert y[1] == pytest.approx(1.0, rel=1e-6)
    assert y[0] == pytest.approx(0.2 - 0.05 - t_c, rel=1e-6)


def test_hermite_cubic_max():
    # d(t) = t (1 - t) on [0, 1]: max 1/4 at 1/2, given values and slopes at the ends
    value, where = hermite_cubic_max(0.0, 1.0, 0.0, -1.0, 1.0)
    assert value == pytest.approx(0.25) and where == pytest.approx(0.5)
    # monotone: the end is the max
    assert hermite_cubic_max(0.0, 1.0, 1.0, 1.0, 1.0)[0] == pytest.approx(1.0)


def test_port_mobility_of_a_slider_is_one_over_mass():
    s = slider(mass=4.0)
    assert s.port_mobility(0, (1.0, 0.0)) == pytest.approx(0.25)
    assert s.port_mobility(0, (0.0, 1.0)) == pytest.approx(0.0)

"""The embedded Runge-Kutta pairs of cosim.core.embedded_rk (issue 39): their
orders, their dense output, their error control, their agreement with
scipy's solve_ivp and their event location.

The problems have closed-form solutions: ``y' = 1 + y^2`` (``y = tan(t +
c)``, nonlinear, every derivative non-zero away from the origin), the
harmonic oscillator and the free fall.
"""
import math

import numpy as np
import pytest

from cosim.core.embedded_rk import PAIRS, Events, locate_root, single_step, solve

#: the pairs, the order of the solution they carry, of their dense output
ORDERS = {"RK45": (5, 4), "DOP853": (8, 7)}
#: step sizes over which each pair's local error is far above round-off and
#: in its asymptotic range (DOP853's at h = 0.05 is already 1e-16)
STEPS = {"RK45": [0.2, 0.1, 0.05, 0.025], "DOP853": [0.4, 0.2, 0.1]}


def tan_rhs(t, y):
    return 1.0 + y * y


def oscillator(t, y):
    return np.array([y[1], -y[0]])


def slopes(h, err):
    return np.diff(np.log(err)) / np.diff(np.log(h))


@pytest.mark.parametrize("name", list(PAIRS))
def test_tableau_is_consistent(name):
    """Each stage's node is its row sum, the weights sum to 1 and the
    error weights to 0 (a typo in a coefficient breaks one of these)."""
    p = PAIRS[name]
    rows = [i for i in range(1, len(p.c)) if i != p.stages]   # stage `stages` is f(t+h, y1)
    assert np.abs(p.a[rows].sum(axis=1) - p.c[rows]).max() < 8 * np.finfo(float).eps
    assert abs(p.b.sum() - 1.0) < 8 * np.finfo(float).eps
    assert abs(p.e.sum()) < 8 * np.finfo(float).eps


@pytest.mark.parametrize("name", list(PAIRS))
def test_fixed_step_local_order(name):
    """One step from the exact state: the local error falls as h^(p+1),
    p = 5 and 8; the dense output's at mid-step as h^(q+1), q = 4 and 7."""
    p, q = ORDERS[name]
    t0 = 0.3
    h = np.array(STEPS[name])
    end, mid = [], []
    for hk in h:
        y1, dense = single_step(name, tan_rhs, t0, [math.tan(t0)], hk)
        end.append(abs(y1[0] - math.tan(t0 + hk)))
        mid.append(abs(dense(0.5)[0] - math.tan(t0 + 0.5 * hk)))
    assert np.all(slopes(h, end) > p + 1 - 0.5), slopes(h, end)
    assert np.all(slopes(h, end) < p + 1 + 1.0), slopes(h, end)
    assert np.all(slopes(h, mid) > q + 1 - 0.5), slopes(h, mid)


@pytest.mark.parametrize("name", list(PAIRS))
def test_dense_output_meets_the_ends(name):
    """The dense output is the step's start at s = 0 and its end at s = 1
    (to round-off: it is a sum of differences)."""
    y0 = np.array([1.0, 0.3])
    y1, dense = single_step(name, oscillator, 0.0, y0, 0.4)
    assert np.abs(dense(0.0) - y0).max() < 4 * np.finfo(float).eps
    assert np.abs(dense(1.0) - y1).max() < 16 * np.finfo(float).eps


@pytest.mark.parametrize("name", list(PAIRS))
def test_global_error_is_proportional_to_the_tolerance(name):
    """Error per step controlled with the lower-order estimate, the global
    error of the oscillator after three periods scales as the tolerance
    (slope 1 on a log-log plot) and stays within a small multiple of it."""
    tols = 10.0 ** -np.arange(5, 11)
    err = []
    for tol in tols:
        r = solve(name, oscillator, 0.0, [1.0, 0.0], 20.0, rtol=tol, atol=tol)
        assert r.status == 0 and r.t == 20.0
        err.append(abs(r.y[0] - math.cos(20.0)))
    slope = np.polyfit(np.log(tols), np.log(err), 1)[0]
    assert 0.8 < slope < 1.2, slope
    assert np.all(np.array(err) < 20 * tols), np.array(err) / tols


@pytest.mark.parametrize("name", list(PAIRS))
def test_output_times_read_the_dense_output(name):
    """Outputs between the steps are as accurate as the steps themselves."""
    te = np.linspace(0.0, 10.0, 41)
    r = solve(name, oscillator, 0.0, [1.0, 0.0], 10.0, rtol=1e-9, atol=1e-9, t_eval=te)
    assert r.y_eval.shape == (40, 2)           # the last (the end itself) is r.y
    assert np.abs(r.y_eval[:, 0] - np.cos(te[:-1])).max() < 20e-9


@pytest.mark.parametrize("name", list(PAIRS))
@pytest.mark.parametrize("tol", [1e-6, 1e-9])
def test_agrees_with_scipy_within_the_tolerance(name, tol):
    """Lotka-Volterra and van der Pol: ours and scipy's solve_ivp (same
    method, same tolerances; independent codes, so not bit for bit) are each
    within 20 rtol of a tight reference at the end, hence within 40 rtol of
    each other (measured: within 10 rtol)."""
    from scipy.integrate import solve_ivp

    problems = [(lambda t, y: np.array([1.5 * y[0] - y[0] * y[1], -3 * y[1] + y[0] * y[1]]),
                 [10.0, 5.0]),
                (lambda t, y: np.array([y[1], 2.0 * (1 - y[0] ** 2) * y[1] - y[0]]), [2.0, 0.0])]
    for fun, y0 in problems:
        ours = solve(name, fun, 0.0, y0, 10.0, rtol=tol, atol=tol * 1e-3).y
        theirs = solve_ivp(fun, (0.0, 10.0), y0, method=name, rtol=tol, atol=tol * 1e-3).y[:, -1]
        ref = solve_ivp(fun, (0.0, 10.0), y0, method="DOP853", rtol=1e-13, atol=1e-13).y[:, -1]
        scale = np.abs(ref).max()
        assert np.abs(ours - ref).max() < 20 * tol * scale
        assert np.abs(ours - theirs).max() < 40 * tol * scale


@pytest.mark.parametrize("name", list(PAIRS))
@pytest.mark.parametrize("height", [2.0, 0.37])
def test_free_fall_hits_the_ground_on_time(name, height):
    """A parabola is integrated exactly by both pairs, their dense outputs
    too: the located impact is sqrt(2 H / g) to the root finder's
    tolerance (4 eps t), the state there at rest on the ground."""
    g = 9.81
    ground = Events(lambda t, y: np.array([y[0]]), np.array([-1.0]), np.array([True]))
    r = solve(name, lambda t, y: np.array([y[1], -g]), 0.0, [height, 0.0], 5.0,
              rtol=1e-8, atol=1e-10, events=ground)
    t_hit = math.sqrt(2 * height / g)
    assert r.status == 1
    assert abs(r.t - t_hit) < 16 * np.finfo(float).eps * t_hit
    assert r.t_events[0] == [r.t]
    assert abs(r.y[0]) < 1e-13 and r.y[1] == pytest.approx(-g * t_hit, rel=1e-13)


@pytest.mark.parametrize("name", list(PAIRS))
def test_terminal_event_takes_only_its_direction(name):
    """x = cos t crosses zero falling at pi/2 and rising at 3 pi/2: a rising
    terminal event stops at 3 pi/2, a falling one at pi/2, each within the
    tolerance of the solution (a zero located on the dense output)."""
    for direction, t_root in ((1.0, 1.5 * math.pi), (-1.0, 0.5 * math.pi)):
        ev = Events(lambda t, y: y[:1], np.array([direction]), np.array([True]))
        r = solve(name, oscillator, 0.0, [1.0, 0.0], 10.0, rtol=1e-10, atol=1e-10, events=ev)
        assert r.status == 1
        assert abs(r.t - t_root) < 1e-8
        assert np.sign(r.y[1]) == direction          # moving the way it crossed


@pytest.mark.parametrize("name", list(PAIRS))
def test_non_terminal_events_of_either_direction(name):
    """Non-terminal, both directions: every zero of cos t in (0, 9), each
    once, and the integration goes on to the end."""
    ev = Events(lambda t, y: np.array([y[0], y[1]]), np.array([0.0, -1.0]),
                np.array([False, False]))
    r = solve(name, oscillator, 0.0, [1.0, 0.0], 9.0, rtol=1e-10, atol=1e-10, events=ev)
    assert r.status == 0 and r.t == 9.0
    np.testing.assert_allclose(r.t_events[0], [0.5 * math.pi, 1.5 * math.pi, 2.5 * math.pi],
                               atol=1e-8)
    # y' = -sin t starts at zero (no crossing), rises through it at pi and
    # falls through it at 2 pi: only the fall counts
    np.testing.assert_allclose(r.t_events[1], [2 * math.pi], atol=1e-8)
    for t, y in zip(r.t_events[0], r.y_events[0]):
        assert abs(y[0]) < 1e-8 and abs(y[1] + math.sin(t)) < 1e-8


def test_max_step_bounds_every_step():
    """max_step forces at least (t1 - t0) / max_step steps on a problem the
    error control would cross in a few (a line)."""
    calls = []

    def line(t, y):
        calls.append(t)
        return np.ones(1)

    r = solve("RK45", line, 0.0, [0.0], 1.0, rtol=1e-3, atol=1e-3, max_step=0.01)
    assert r.y[0] == pytest.approx(1.0, abs=1e-13)
    assert r.nfev >= 6 * 100                      # 6 evaluations a step, 100 steps at least
    assert np.all(np.diff(sorted(set(calls))) <= 0.01 + 1e-15)


@pytest.mark.parametrize("root", [0.1, 0.5, 0.999])
def test_root_finder_returns_the_crossing_side(root):
    """The returned time is on the far side of the root (where the sign has
    changed), within the tolerance, for a steep and a flat function."""
    for fun in (lambda t: math.tanh(50 * (t - root)), lambda t: (t - root) ** 3):
        t = locate_root(fun, 0.0, fun(0.0), 1.0, fun(1.0), 1e-13)
        assert fun(t) >= 0.0 and abs(t - root) <= 1e-13


def test_failure_is_reported_not_raised():
    """A solution that blows up (y' = y^2, y(0) = 1, pole at t = 1) ends
    with status -1 and a message, short of the end."""
    r = solve("DOP853", lambda t, y: y * y, 0.0, [1.0], 2.0, rtol=1e-8, atol=1e-8)
    assert r.status == -1 and "step size" in r.message
    assert r.t == pytest.approx(1.0, abs=1e-3)


@pytest.mark.parametrize("name", list(PAIRS))
def test_a_right_hand_side_turning_nan_fails_where_it_turns(name):
    """NaN from t = 0.5 on: every step over it is rejected (a NaN error is
    not below 1) until the step falls below the spacing of the numbers; at
    t = 0 already, the starting step is NaN: both end with status -1."""
    r = solve(name, lambda t, y: y if t < 0.5 else y * np.nan, 0.0, [1.0], 1.0,
              rtol=1e-8, atol=1e-8)
    assert r.status == -1 and r.t == pytest.approx(0.5, abs=1e-12)
    assert np.isfinite(r.y).all()
    r = solve(name, lambda t, y: y * np.nan, 0.0, [1.0], 1.0, rtol=1e-8, atol=1e-8)
    assert r.status == -1 and r.t == 0.0


def test_an_empty_interval_returns_the_start():
    r = solve("DOP853", lambda t, y: -y, 1.0, [2.0], 1.0, rtol=1e-8, atol=1e-8)
    assert r.status == 0 and r.t == 1.0 and r.y.tolist() == [2.0] and r.nfev == 1


def test_a_terminal_event_zero_at_the_start_counts_on_the_side_its_direction_leaves():
    """``g = y`` with ``y(0) = 0`` and ``y' = 1``: a rising terminal event
    (the start counts as negative) is found at once, a falling one (the
    start counts as positive) is not; ``y' = -1`` the other way round.  A
    contact that touches where the run starts and goes on closing is not
    lost (the monolithic scheme's rod_impact).  Non-terminal: see
    test_non_terminal_events_of_either_direction."""
    for slope, direction, found in ((1.0, 1.0, True), (1.0, -1.0, False),
                                    (-1.0, -1.0, True), (-1.0, 1.0, False)):
        ev = Events(lambda t, y: np.array([y[0]]), [direction], [True])
        res = solve("DOP853", lambda t, y: np.array([slope]), 0.0, [0.0], 1.0,
                    rtol=1e-10, atol=1e-12, events=ev)
        assert (res.status == 1) is found, (slope, direction)
        if found:
            assert 0.0 < res.t < 1e-12 and res.y[0] * slope >= 0.0
        else:
            assert res.t == 1.0

"""The monolithic scheme's solver (issue 39): ``DOP853`` (the default) and
``RK45`` run on cosim's own embedded pairs (:mod:`cosim.core.embedded_rk`),
the other methods on scipy's ``solve_ivp``.

The own pairs are held to closed forms (spring_drop's contact interval
``pi sqrt(m/k)`` and exit velocity, undamped and with the clipped
Kelvin-Voigt law) and to scipy's solver for the same method on a scene of
many contact switches and peaks (three_mass).  The bounds follow from the
tolerance: each step's local error is held below ``rtol`` of the state, and
a run of a few hundred steps and a few dozen located events accumulates
some hundreds of them at most.
"""
import warnings

import numpy as np
import pytest

import cosim
from analytic import kelvin_voigt_clipped, linear_contact
from conftest import CASES
from cosim.core.schemes import monolithic
from test_imports import loaded, packages

M, K, C_KV, V0 = 1.0, 1e6, 200.0, 1.0
RTOL = 1e-10                  # the scheme's default
#: the relative error a tolerance ``rtol`` allows the run's quantities
ALLOWED = 100 * RTOL


def simulate(scene, variant, method, *, scipy=False, monkeypatch=None):
    """Run ``scene`` monolithic with ``method``; with ``scipy`` on scipy's
    ``solve_ivp`` for that method (the own pairs withdrawn)."""
    if scipy:
        monkeypatch.setattr(monolithic, "_PAIRS", ())
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sc = cosim.load_scene(CASES / f"{scene}.toml", variant,
                              [f'scheme.method="{method}"'], "monolithic")
        res = cosim.simulate(sc, estimate=False)
    assert res.success, res.message
    return res


@pytest.mark.parametrize("method", ["DOP853", "RK45"])
@pytest.mark.parametrize("variant", ["undamped", "kelvin_voigt"])
def test_own_pairs_meet_the_spring_drop_closed_form(method, variant):
    res = simulate("spring_drop", variant, method)
    c = res.summary["contacts"]["wall"]
    (t_on, t_off), = c["intervals"]
    t_ref, e_ref = ((linear_contact(M, K), 1.0) if variant == "undamped"
                    else kelvin_voigt_clipped(M, K, C_KV))
    v = res.summary["final_state"]["body"]["x"]["dq"]
    assert abs((t_off - t_on) / t_ref - 1) < ALLOWED
    assert abs(v / (e_ref * V0) - 1) < ALLOWED


@pytest.mark.parametrize("method", ["DOP853", "RK45", "RK23"])
def test_a_contact_touching_at_the_start_closes_at_once(method):
    """spring_drop started at the wall (penetration exactly zero, moving in):
    the contact closes at t = 0 and lasts pi sqrt(m/k), whichever solver
    runs (the own pairs take a switch that starts on its boundary as on the
    side it leaves, as scipy's solve_ivp does)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sc = cosim.load_scene(CASES / "spring_drop.toml", "undamped",
                              [f'scheme.method="{method}"',
                               "subsystems.body.bodies.mass.joint.q0=0.0"], "monolithic")
        res = cosim.simulate(sc, estimate=False)
    c = res.summary["contacts"]["wall"]
    (t_on, t_off), = c["intervals"]
    assert t_on < 1e-12
    allowed = ALLOWED if method != "RK23" else 1e3 * ALLOWED   # scipy's RK23: rtol 1e-10
    assert abs((t_off - t_on) / linear_contact(M, K) - 1) < allowed
    assert abs(res.summary["final_state"]["body"]["x"]["dq"] / V0 - 1) < allowed


def test_own_dop853_agrees_with_scipys(monkeypatch):
    """three_mass (rtol 1e-9 in its file): 15 contact intervals, their
    switches and peaks located on the dense output.  Each solution is
    within some hundreds of rtol of the exact one, so of each other."""
    own = simulate("three_mass", "f100", "DOP853")
    ref = simulate("three_mass", "f100", "DOP853", scipy=True, monkeypatch=monkeypatch)
    bound = 1000 * 1e-9
    for name, c in own.summary["contacts"].items():
        r = ref.summary["contacts"][name]
        assert c["impulse"] == pytest.approx(r["impulse"], rel=bound)
        assert c["peak_penetration"] == pytest.approx(r["peak_penetration"], rel=bound)
    for side, joints in own.summary["final_state"].items():
        for j, s in joints.items():
            r = ref.summary["final_state"][side][j]
            scale = max(abs(r["dq"]), 1.0)              # m/s, rad/s
            assert abs(s["dq"] - r["dq"]) <= bound * scale, (side, j)
            assert abs(s["q"] - r["q"]) <= bound * max(abs(r["q"]), 1e-2), (side, j)


def test_a_monolithic_dop853_run_imports_no_scipy_integrate(tmp_path):
    """The first monolithic run of a process pays for no scipy.integrate
    import: three_mass (a chain, a robot, compiled faces) needs no scipy."""
    mods = loaded(tmp_path, "run", str(CASES / "three_mass.toml"), "--variant", "f100",
                  "--scheme", "monolithic", "--no-estimate", "--out", str(tmp_path / "run"),
                  "--quiet")
    assert "cosim.core.schemes.monolithic" in mods and "cosim.core.embedded_rk" in mods
    assert not packages(mods, ("scipy",)), packages(mods, ("scipy",))



@pytest.mark.parametrize("method", ["DOP853", "RK23"])
def test_a_solver_failure_comes_back_as_status_and_message(method):
    """A right-hand side that turns non-finite: the segment stops with
    status -1 and a message saying where, on the own pair and on scipy's
    (``Monolithic.run`` raises it as a CouplingError naming the time)."""
    def rhs(t, y):
        return np.array([np.nan if t > 0.5 else 1.0])

    segment = monolithic.Monolithic(method=method)._segment_solver(rhs, 1.0)
    sol = segment(0.0, np.zeros(1), lambda t, y: np.empty(0), np.empty(0), np.empty(0, bool),
                  np.empty(0))
    assert sol.status == -1 and sol.message
    assert 0.0 < sol.t <= 0.5 + 1e-9

"""The compiled embedded pairs (``cosim.sides._embedded_rk``) against their
numpy reference, :func:`cosim.core.embedded_rk.solve`.

Both run the same algorithm in the same order of arithmetic; they differ only
where numpy sums in another order than the compiled loops (BLAS's vector
kernels in ``A @ y``, ``a @ K``, ``einsum``), i.e. by an ulp or so per
operation.  Never bit for bit, so:

- on a linear ODE (harmonic oscillator, ``y' = A y``), with the same steps
  (asserted: the same number of right-hand-side evaluations), the two
  solutions, output samples and event times differ by at most ``1e-13``: a
  few hundred steps, each rounding otherwise by a few ulps of values of
  order 1, under a rotation that does not amplify them;
- both pairs converge at their order on it (the compiled pair alone);
- on manipulator_wall with a rigid wall (mu0 .. mu0.35, and mu0.03 with
  RK45 instead of DOP853) the compiled side
  takes the same steps as the reference (the same count of evaluations of
  the tree's right-hand side, which counts accepted, rejected and dense
  output stages), the same impacts and switches, for the scene and its
  copies moved by +-1 and +-2 ulps; impact times agree within 1e-12 s and
  the final joint states within ``1e-10`` (the robot's rtol): the ulp-level
  differences grow through 0.45 s of chain dynamics and an impact, and
  measured stay below 3e-11 relative, 5e-12 absolute;
- the penalty variant's stiff contact makes the step-size controller
  sensitive to round-off: the reference alone, moved by one ulp, takes
  1489 to 2088 evaluations and its release time moves by 1e-12 s, its
  final state by 2e-9.  There the compiled side must give the same contact
  and switch counts, the same touch time within 1e-12 s (the same steps up
  to it), and a release time and final state as close to the reference as
  the reference's own ulp copies are to it, with a margin of 5:
  5e-12 s and 1e-8.
"""
from __future__ import annotations

import math
import sys
import warnings

import numpy as np
import pytest

from conftest import CASES

import cosim
import cosim.sides.multibody_kernel as mk
from cosim.core.embedded_rk import Events, solve
from cosim.core.schemes import sampled
from cosim.sides.kernel import kernel_choice
from cosim.sides.multibody import MultibodySubsystem
from cosim.studies.roundoff import spread

if kernel_choice() == "numpy":
    pytest.skip("the compiled kernels are not chosen (COSIM_KERNEL=numpy)",
                allow_module_level=True)
# built wherever the compiled kernels are chosen: a missing module is an error, not a skip
import cosim.sides._embedded_rk as rk  # noqa: E402

PAIRS = ["RK45", "DOP853"]
ORDERS = {"RK45": 5, "DOP853": 8}
A = np.array([[0.0, 1.0], [-1.0, 0.0]])       # x'' = -x: x = cos t from (1, 0)


@pytest.mark.parametrize("name", PAIRS)
@pytest.mark.parametrize("terminal", [False, True])
def test_linear_ode_same_as_the_reference(name, terminal):
    """Oscillator with events ``x`` (falling, terminal or not) and ``v``
    (both ways), 41 output times: same evaluations, status, event counts;
    times and states within 1e-13."""
    C = np.eye(2)
    direction, term = [-1.0, 0.0], [terminal, False]
    te = np.linspace(0.05, 9.95, 41)
    ref = solve(name, lambda t, y: A @ y, 0.0, [1.0, 0.0], 10.0, rtol=1e-9, atol=1e-12,
                events=Events(lambda t, y: C @ y, direction, term), t_eval=te)
    t, y, status, _, t_ev, y_ev, y_out, nfev = rk.solve_linear(
        name, A, C, direction, term, 0.0, [1.0, 0.0], 10.0, rtol=1e-9, atol=1e-12, t_eval=te)
    assert (status, nfev) == (ref.status, ref.nfev)
    assert status == (1 if terminal else 0)
    assert abs(t - ref.t) <= 1e-13
    assert np.abs(y - ref.y).max() <= 1e-13
    assert y_out.shape == ref.y_eval.shape and len(y_out) >= 7
    assert np.abs(y_out - ref.y_eval).max() <= 1e-13
    for j in range(2):
        assert len(t_ev[j]) == len(ref.t_events[j])
        assert np.abs(np.subtract(t_ev[j], ref.t_events[j])).max(initial=0) <= 1e-13
        assert np.abs(np.subtract(y_ev[j], ref.y_events[j])).max(initial=0) <= 1e-13
    # x falls through zero at pi/2 (and 5 pi/2 when it goes on): located on
    # the dense output, within the solution's own error
    assert t_ev[0][0] == pytest.approx(math.pi / 2, abs=1e-8)
    assert len(t_ev[0]) == (1 if terminal else 2)


@pytest.mark.parametrize("name", PAIRS)
def test_linear_ode_order_of_accuracy(name):
    """With tolerances that accept every step, the steps are ``max_step``
    (after a short start) and the error at t = 4 falls as h^p, p = 5 and 8."""
    p = ORDERS[name]
    hs = np.array([0.4, 0.2, 0.1] if name == "DOP853" else [0.2, 0.1, 0.05, 0.025])
    err = []
    for h in hs:
        t, y, status, *_ = rk.solve_linear(name, A, np.zeros((0, 2)), [], [], 0.0, [1.0, 0.0],
                                           4.0, rtol=1e3, atol=1e3, max_step=h)
        assert status == 0 and t == 4.0
        err.append(math.hypot(y[0] - math.cos(4.0), y[1] + math.sin(4.0)))
    slopes = np.diff(np.log(err)) / np.diff(np.log(hs))
    assert np.all(slopes > p - 0.5) and np.all(slopes < p + 1.0), slopes


def test_an_unknown_pair_is_refused():
    with pytest.raises(ValueError, match="unknown pair 'RK23'"):
        rk.solve_linear("RK23", A, np.zeros((0, 2)), [], [], 0.0, [1.0, 0.0], 1.0,
                        rtol=1e-6, atol=1e-6)


# ------------------------------------------------------------ manipulator_wall
def _run(monkeypatch, scene, compiled: bool):
    """The run with the compiled pairs or the reference over the same compiled
    right-hand side: its outcome and the sides' right-hand-side evaluations."""
    monkeypatch.setattr(mk, "COMPILED_PAIRS", compiled)
    sides = []
    build = MultibodySubsystem._build_kernel

    def keep(self):
        sides.append(self)
        return build(self)
    monkeypatch.setattr(MultibodySubsystem, "_build_kernel", keep)
    res = cosim.simulate(scene, estimate=False)
    assert res.success, res.message
    kernels = [s._kernel for s in sides if s._kernel]
    assert kernels
    assert all((s._rk[1] is not None) == compiled for s in sides if s._kernel)
    s = res.summary
    tip = s["contacts"]["tip"]
    return {"n_rhs": sum(k.n_rhs for k in kernels),
            "impacts": [i["time"] for i in s["impacts"]],
            "intervals": np.ravel(tip["intervals"]), "count": tip["count"],
            "switches": len(s["switches"]),
            "state": np.array([[v["q"], v["dq"]] for v in s["final_state"]["robot"].values()])}


def _copies(variant, overrides=()):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = cosim.load_scene(CASES / "manipulator_wall.toml", variant,
                                 ["t_end=0.45", *overrides])
        return list(spread(scene, 5))


#: the robot's RK45 at its default tolerances instead of the scene's DOP853
RK45 = ("subsystems.robot.integrator.method=rk45", "subsystems.robot.integrator.rtol=1e-8",
        "subsystems.robot.integrator.atol=1e-10")


@pytest.mark.parametrize("variant, overrides", [
    ("mu0", ()), ("mu0.03", ()), ("mu0.15", ()), ("mu0.35", ()), ("mu0.03", RK45)],
    ids=["mu0", "mu0.03", "mu0.15", "mu0.35", "mu0.03-rk45"])
@pytest.mark.parametrize("path", [True, False], ids=["sampled", "loop"])
def test_manipulator_wall_rigid_same_steps(monkeypatch, variant, overrides, path):
    """Same evaluations, impacts and switches for the scene and its +-1,
    +-2 ulp copies; impact times within 1e-12 s, states within 1e-10; on the
    sampled path and in the macro loop (the stepper's ``integrate``)."""
    monkeypatch.setattr(sampled, "ENABLED", path)
    for scene in _copies(variant, overrides):
        ref = _run(monkeypatch, scene, False)
        fast = _run(monkeypatch, scene, True)
        assert fast["n_rhs"] == ref["n_rhs"] > 100
        assert len(fast["impacts"]) == len(ref["impacts"]) == 1
        assert (fast["count"], fast["switches"]) == (ref["count"], ref["switches"])
        assert abs(fast["impacts"][0] - ref["impacts"][0]) <= 1e-12
        assert np.abs(fast["intervals"] - ref["intervals"]).max() <= 1e-12
        np.testing.assert_allclose(fast["state"], ref["state"], rtol=1e-10, atol=1e-10)


def test_manipulator_wall_penalty_within_the_references_own_spread(monkeypatch):
    """The stiff penalty contact: counts equal for every copy; the touch within
    1e-12 s, the release within 5e-12 s, the state within 1e-8 (see the
    module's docstring for the reference's own spread)."""
    for scene in _copies("penalty"):
        ref = _run(monkeypatch, scene, False)
        fast = _run(monkeypatch, scene, True)
        assert (fast["count"], fast["switches"]) == (ref["count"], ref["switches"])
        assert fast["count"] == 1 and len(fast["intervals"]) == 2
        assert abs(fast["intervals"][0] - ref["intervals"][0]) <= 1e-12
        assert abs(fast["intervals"][1] - ref["intervals"][1]) <= 5e-12
        np.testing.assert_allclose(fast["state"], ref["state"], rtol=0, atol=1e-8)



def test_no_python_call_per_step(monkeypatch):
    """Per accepted step no Python function runs: the compiled side's run
    calls about as many Python functions at rtol 1e-13 as at 1e-8 (within
    a few: the watched maxima located, each probed in Python, may differ),
    though it takes about 25 more steps, 300 more evaluations of the tree's
    right-hand side; the reference's calls grow with its steps (by 450)."""
    loose = ("subsystems.robot.integrator.rtol=1e-8", "subsystems.robot.integrator.atol=1e-10")
    tight = ("subsystems.robot.integrator.rtol=1e-13", "subsystems.robot.integrator.atol=1e-15")
    n = [0]

    def count(frame, event, arg):
        if event == "call":
            n[0] += 1

    def calls(compiled, overrides):
        scene = _copies("mu0.03", overrides)[0]
        _run(monkeypatch, scene, compiled)          # one-time imports and caches
        n[0] = 0
        sys.setprofile(count)
        try:
            out = _run(monkeypatch, scene, compiled)
        finally:
            sys.setprofile(None)
        return n[0], out["n_rhs"]

    (fast, rhs), (fast_t, rhs_t) = calls(True, loose), calls(True, tight)
    assert rhs_t > rhs + 200, (rhs, rhs_t)
    assert abs(fast_t - fast) <= 6, (fast, fast_t)
    (ref, _), (ref_t, _) = calls(False, loose), calls(False, tight)
    assert ref_t > ref + 200 and ref > fast, (ref, ref_t, fast)

"""Integrators of the multibody subsystem on the free ten-link chain
(CASES.md section 3's robot, faster: dq from -2 to 2 rad/s, no wall)."""
import numpy as np
import pytest

from cosim.bodies import MultibodySubsystem
from cosim.integrators import INTEGRATORS
from multibody import Body, Joint, TreeModel

L = 0.17
T_END, H = 1.0, 0.05


def chain(stepper):
    tree = TreeModel([Body(f"l{i}", 0.3341, 0.0011388, (L / 2, 0.0)) for i in range(10)],
                     [Joint(f"q{i}", "revolute", i - 1, (0.0, 0.0) if i == 0 else (L, 0.0))
                      for i in range(10)])
    return MultibodySubsystem("robot", tree, np.full(10, -0.25), np.linspace(-2, 2, 10), {},
                              None, stepper)


def run(stepper):
    s = chain(stepper)
    e0, drift = s.energy(), 0.0
    for k in range(round(T_END / H)):
        s.step(k * H, H)
        assert s.t == pytest.approx((k + 1) * H, abs=1e-15)     # lands on the boundary
        drift = max(drift, abs(s.energy() - e0))
    return s.x.copy(), drift / e0


@pytest.fixture(scope="module")
def reference():
    return run(INTEGRATORS["dop853"](rtol=1e-13, atol=1e-14))[0]


def test_every_registered_integrator_is_covered():
    assert set(INTEGRATORS) == {"rk4", "rk45", "dop853", "radau", "bdf"}


def test_rk4_is_fourth_order_on_the_chain(reference):
    """Sub-steps 4, 2, 1, 0.5 ms; observed slope 4.08, errors 4e-2 .. 8e-6."""
    hs = np.array([4e-3, 2e-3, 1e-3, 5e-4])
    errs = [np.linalg.norm(run(INTEGRATORS["rk4"](max_step=h))[0] - reference) for h in hs]
    slope = np.polyfit(np.log(hs), np.log(errs), 1)[0]
    assert abs(slope - 4) < 0.15, f"observed order {slope:.2f}"
    assert errs[-1] < 2e-5


# (method, options, bound on max |E - E0| / E0 over 1 s); observed values in comments
DRIFT = [
    ("rk4", {"max_step": 1e-3}, 1e-6),                    # 2.3e-7
    ("rk45", {"rtol": 1e-9, "atol": 1e-12}, 1e-9),        # 1.5e-10
    ("dop853", {"rtol": 1e-10, "atol": 1e-12}, 1e-10),    # 8.8e-12
    ("radau", {"rtol": 1e-8, "atol": 1e-11}, 1e-9),       # ~1e-10
    ("bdf", {"rtol": 1e-9, "atol": 1e-12}, 1e-7),         # 1.1e-8
]


@pytest.mark.parametrize("name,opts,bound", DRIFT, ids=[d[0] for d in DRIFT])
def test_energy_drift_of_the_free_chain(name, opts, bound):
    _, drift = run(INTEGRATORS[name](**opts))
    assert drift < bound, f"{name}: relative drift {drift:.2e}"


@pytest.mark.parametrize("name", ["rk45", "dop853", "radau", "bdf"])
def test_adaptive_error_follows_the_tolerance(name, reference):
    """Three orders of magnitude in rtol buy at least two in the error."""
    loose = np.linalg.norm(run(INTEGRATORS[name](rtol=1e-5, atol=1e-8))[0] - reference)
    tight = np.linalg.norm(run(INTEGRATORS[name](rtol=1e-8, atol=1e-11))[0] - reference)
    assert tight < 1e-2 * loose, (loose, tight)


@pytest.mark.parametrize("name,opts,match", [
    ("rk4", {"max_step": 0.0}, r"`max_step` must be > 0 s, got 0\.0"),
    ("rk45", {"rtol": -1.0}, r"`rtol` must be > 0, got -1\.0"),
    ("radau", {"max_step": -1.0}, r"`max_step` must be > 0 s"),
])
def test_options_are_checked(name, opts, match):
    with pytest.raises(ValueError, match=match):
        INTEGRATORS[name](**opts)

"""Integrators of the multibody subsystem on the free ten-link chain
(CASES.md section 3's robot, faster: dq from -2 to 2 rad/s, no wall)."""
import numpy as np
import pytest

from cosim.sides.multibody import MultibodySubsystem
from cosim.core.ode import INTEGRATORS
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


# -- free_step: long sub-steps while every contact is open ----------------------------
K_WALL, V_IN = 1e6, 1.0


def _wall(counter):
    """A unit mass flying at -1 m/s from x = 0.01 m onto a spring wall at x = 0
    (closed where x < 0): touch at 10 ms, contact for pi/1000 s, exit at +1 m/s."""
    def f(t, y):
        counter[0] += 1
        return np.array([y[1], K_WALL * max(-y[0], 0.0)])

    def switch(t, y):
        return np.array([-y[0]])
    return f, switch


@pytest.mark.parametrize("coarse", [False, True])
def test_free_step_keeps_contacts_at_max_step(coarse):
    from cosim.core.ode import RK4
    calls = [0]
    f, switch = _wall(calls)
    t_touch, t_c = 0.01, np.pi / np.sqrt(K_WALL)
    t1 = t_touch + t_c + 2e-3
    y = RK4(max_step=1e-5, free_step=1e-3).integrate(f, 0.0, np.array([0.01, -V_IN]), t1,
                                                      switch, coarse=coarse)
    # after the contact: free flight at +1 m/s from x = 0 at t_touch + t_c
    assert y[1] == pytest.approx(V_IN, abs=1e-9)
    assert y[0] == pytest.approx(V_IN * (t1 - t_touch - t_c), abs=1e-10)
    fine_calls = 4 * round(t1 / 1e-5)
    if coarse:   # 10 coarse sub-steps to the touch instead of 1000 fine ones
        assert calls[0] < fine_calls - 3000
    else:
        assert calls[0] >= fine_calls


def test_free_step_is_a_scene_option_of_rk4_only(tmp_path):
    import cosim
    from conftest import CASES
    scene = cosim.load_scene(CASES / "spring_drop.toml", None,
                             ["subsystems.body.integrator.free_step=1e-3",
                              "scheme.macro_step=2e-3"])
    res = cosim.simulate(scene, estimate=False)
    (t_on, t_off), = res.summary["contacts"]["wall"]["intervals"]
    assert t_off - t_on == pytest.approx(np.pi / 1e3, rel=1e-6)
    assert res.summary["final_state"]["body"]["x"]["dq"] == pytest.approx(1.0, rel=1e-6)
    with pytest.raises(cosim.SceneError, match="free_step"):
        cosim.load_scene(CASES / "spring_drop.toml", None,
                         ['subsystems.body.integrator.method="rk45"',
                          "subsystems.body.integrator.free_step=1e-3"])
    with pytest.raises(cosim.SceneError, match="free_step"):
        cosim.load_scene(CASES / "spring_drop.toml", None,
                         ["subsystems.body.integrator.free_step=-1.0"])


def test_substep_peaks_is_the_maximum_of_the_cubic_hermite():
    """The per-sub-step peak against the cubic Hermite sampled densely, over
    random sub-steps (rates of both signs, near-quadratic cubics included):
    where the rate falls from positive to negative, the interpolant's maximum;
    elsewhere the end value (the start is the previous sub-step's end).
    Entries already above stay."""
    from cosim.core.ode import substep_peaks

    rng = np.random.default_rng(19)
    s = np.linspace(0.0, 1.0, 200001)
    for _ in range(300):
        d0, d1 = rng.normal(size=2)
        h = 10.0 ** rng.uniform(-6, 0)
        v0, v1 = rng.normal(size=2) / h
        if rng.random() < 0.2:              # c3 = 0: the derivative is linear
            v1 = 2.0 * (d1 - d0) / h - v0
        p = (d0 * (2 * s**3 - 3 * s**2 + 1) + h * v0 * (s**3 - 2 * s**2 + s)
             + d1 * (-2 * s**3 + 3 * s**2) + h * v1 * (s**3 - s**2))
        peak = np.array([-np.inf, 1e9])
        substep_peaks(peak, [d0, d0], [v0, v0], [d1, d1], [v1, v1], h)
        expected = p.max() if v0 > 0 > v1 else d1
        assert peak[0] == pytest.approx(expected, rel=1e-9, abs=1e-9 * abs(d1 - d0)), \
            (d0, v0, d1, v1, h)
        assert peak[1] == 1e9

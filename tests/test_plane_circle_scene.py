"""The circle contact in a scene (a contact's ``radius``): a point mass with
a circle of 10 mm strikes the clamped strip (the plane body hosts the
spread penalty, Gauss-Seidel hands the force vector to the mass).  The
ledger closes (its residual, the coupling error, is small beside the
contact's stored energy and falls as the macro step squared), a loaded
circle rolled over a corner closes it too while the force turns, the run
agrees with the stand-alone strike of tests/test_plane_circle_strike.py,
the compiled loop refuses it with its reason, and what a circle cannot run
with is refused at its key."""
import json
import math

import numpy as np
import pytest

import cosim
from documented import Claim, assert_printed, assert_reproduced
from fem.plane import rectangle
from plane_files import write_msh
from cosim.scene.load import SceneError
from test_plane_circle_strike import _peak_and_duration, _strike, _strip

S, CMD = "docs/structures.md", "pytest tests/test_plane_circle_scene.py"
R, H = 0.01, 0.04

SCENE = """\
name = "circle_strike"
t_end = {t_end}

[scheme]
name = "gauss_seidel"
macro_step = {step}
sequence = ["strip", "ball"]
{effects}
[subsystems.strip]
type = "plane"
mesh = "strip.msh"
thickness = 0.01
youngs_modulus = 210e9
poisson_ratio = 0.3
density = 7850.0
supports = {{ fixed = {fixed} }}
points = {{ top = {{ boundary = "top", s = 0.2 }} }}
modes = {{ count = {modes} }}
integrator = {{ contact_step = {contact_step} }}

[subsystems.ball]
type = "multibody"
integrator = {{ method = "rk4", max_step = {step} }}
{bodies}
[contacts.hit]
a = "ball.centre"
b = "strip.top"
normal = [0.0, 1.0]
radius = {radius}
law = {{ type = "linear", contact_stiffness = 1e12 }}
"""

#: the mass falling on mid-span at 1 m/s, free along y only
DROP = f"""
[subsystems.ball.bodies.ball]
mass = 0.2
inertia = 1e-5
points = {{ centre = [0.0, 0.0] }}
joint = {{ name = "y", type = "prismatic", parent = "ground", axis = [0.0, 1.0], offset = [0.2, {H / 2 + R + 1e-6!r}], dq0 = -1.0 }}
"""
#: a carriage (0.1 kg, along x at 3 m/s) carrying the ball (0.2 kg, along
#: y), pressed into the top face 5 mm before the corner by a joint spring
#: (1e4 N/m stretched by 0.1 m: 1 kN)
ROLL = f"""
[subsystems.ball.bodies.carriage]
mass = 0.1
inertia = 1e-5
points = {{ o = [0.0, 0.0] }}
joint = {{ name = "x", type = "prismatic", parent = "ground", axis = [1.0, 0.0], offset = [0.395, 0.0], dq0 = 3.0 }}

[subsystems.ball.bodies.ball]
mass = 0.2
inertia = 1e-5
points = {{ centre = [0.0, 0.0] }}
joint = {{ name = "y", type = "prismatic", parent = "carriage", axis = [0.0, 1.0], offset = [0.0, {H / 2 + R - 5e-5!r}], spring = {{ stiffness = 1e4, rest = -0.1 }} }}
"""


def _scene(path, step=1e-6, t_end=3.5e-4, contact_step=2e-7, modes=20,
           fixed='["left", "right"]', bodies=DROP, effects="", radius=R, **replace):
    write_msh(path / "strip.msh", rectangle(0.4, H, 40, 4), name="strip")
    text = SCENE.format(t_end=t_end, step=step, contact_step=contact_step, modes=modes,
                        fixed=fixed, bodies=bodies, effects=effects, radius=radius)
    for old, new in replace.items():
        assert old in text, old
        text = text.replace(old, new)
    (path / "s.toml").write_text(text)
    return path / "s.toml"


def _circle(system):
    strip = system.subsystems[system.names.index("strip")]
    return strip, strip.circles[0].circle


def _replay(res, system, centre0):
    """The stored energy and the force on the circle at every sample, from
    the recorded modes and centre (the circle's own functions)."""
    strip, cc = _circle(system)
    q = np.column_stack([res.series[f"q/strip/mode{i + 1}"] for i in range(strip.n_modes)])
    x = res.series["q/ball/x"] if "q/ball/x" in res.series else np.zeros(len(q))
    c = np.column_stack([centre0[0] + x, centre0[1] + res.series["q/ball/y"]])
    out = [cc.evaluate(qi, ci) for qi, ci in zip(q, c)]
    return np.array([e for e, _, _ in out]), np.array([f for _, _, f in out])


@pytest.fixture(scope="module")
def strikes(tmp_path_factory):
    """The strike at macro steps of 2 and 1 us: result, system."""
    out = {}
    for step in (2e-6, 1e-6):
        path = _scene(tmp_path_factory.mktemp(f"strike{step:g}"), step=step)
        scene = cosim.load_scene(path)
        out[step] = cosim.simulate(scene, estimate=False), scene.build()[0]
    return out


def test_a_circle_strike_closes_the_ledger(strikes):
    """The energy of mass, modes and the circle's penalty (its V(q, c) booked
    as the contact's stored energy) drifts by the coupling error alone: small
    beside the largest stored energy, falling as the macro step squared, and
    the contact's own ledger (work on both sides plus stored) closes at the
    release."""
    drift = {}
    for step, (res, system) in strikes.items():
        assert res.status == "finished", res.message
        stored, _ = _replay(res, system, (0.2, H / 2 + R + 1e-6))
        c = res.summary["contacts"]["hit"]
        assert c["count"] == 1 and c["stored"] == 0.0           # released
        assert stored.max() > 0.5 * res.summary["energy"]["initial"]   # the penalty took most
        drift[step] = res.summary["energy"]["max_abs_drift"] / stored.max()
        assert abs(c["coupling_error"]) < drift[step] * stored.max()
    assert drift[1e-6] < 5e-5, drift
    assert drift[2e-6] / drift[1e-6] > 3.5, drift               # second order in the step
    for printed, value, measured in (("1.9e-5 of the largest stored energy", 1.9e-5, drift[1e-6]),
                                     ("7.4e-5 at 2 µs", 7.4e-5, drift[2e-6])):
        claim = Claim(S, printed, CMD, value, abs=0.05e-5 if value < 5e-5 else 0.05e-4)
        assert_printed(claim)
        assert_reproduced(claim, measured)


def test_the_scene_strike_agrees_with_the_stand_alone_strike(strikes):
    """The same strike integrated with mass and modes together (DOP853 at
    1e-9, tests/test_plane_circle_strike.py, the same quadrature on the top
    face): rebound speed, peak force and contact duration within 1e-4."""
    res, _ = strikes[1e-6]
    st, basis = _strip(["left", "right"], {"top": slice(0, 40)}, 20)
    sol, rhs, _ = _strike(st, basis, np.array([0.2, H / 2 + R + 1e-6]), np.array([0.0, -1.0]),
                          R, parts=20)
    peak, duration = _peak_and_duration(sol, rhs)
    on, off = res.summary["contacts"]["hit"]["intervals"][0]
    diffs = (res.series["dq/ball/y"][-1] / sol.y[-1, -1] - 1,
             np.max(res.series["force/hit"]) / peak - 1, (off - on) / duration - 1)
    assert max(map(abs, diffs)) < 1e-4, diffs
    claim = Claim(S, "within 1e-4 (measured 3e-6, 8e-6 and 1e-5)", CMD, 1e-5, abs=0.5e-5)
    assert_printed(claim)
    assert_reproduced(claim, max(map(abs, diffs)))


def test_a_loaded_circle_rolling_over_a_corner_of_a_free_body_closes_the_ledger(tmp_path):
    """A free strip (no supports: three rigid modes and three elastic ones):
    the ball, pressed into its top face by 1 kN and carried at 3 m/s, rolls
    over the corner and leaves; the force on it turns from the top's normal
    to over 40 degrees towards the end face's, and the energy drifts by a
    small share of the stored energy, falling as the step squared (the
    force's turn within a step, not handed over, is of higher order)."""
    drifts = []
    for step in (8e-6, 4e-6):
        path = _scene(tmp_path, step=step, t_end=4e-3, contact_step=step, modes=6, bodies=ROLL,
                      **{'supports = { fixed = ["left", "right"] }': "supports = {}"})
        scene = cosim.load_scene(path)
        res = cosim.simulate(scene, estimate=False)
        assert res.status == "finished", res.message
        system = scene.build()[0]
        stored, _ = _replay(res, system, (0.395, H / 2 + R - 5e-5))
        drifts.append(res.summary["energy"]["max_abs_drift"] / stored.max())
    assert drifts[0] / drifts[1] > 3.5, drifts
    assert np.count_nonzero(_circle(system)[0].natural_frequencies_hz < 1.0) == 3   # free
    stored, force = _replay(res, system, (0.395, H / 2 + R - 5e-5))
    loaded = np.hypot(*force.T) > 0.05 * np.hypot(*force.T).max()
    angle = np.degrees(np.arctan2(force[loaded, 0], force[loaded, 1]))
    assert angle.min() < 1.0 and angle.max() > 40.0, (angle.min(), angle.max())
    (on, off), = res.summary["contacts"]["hit"]["intervals"]
    assert off < 4e-3 and res.series["q/ball/x"][-1] > 0.005     # left past the corner
    drift = res.summary["energy"]["max_abs_drift"] / stored.max()
    assert drift < 1e-3, drift
    for printed, value, measured in (("rolled over the corner, 1.2e-4", 1.2e-4, drift),
                                     ("6.1e-4 at 8 µs", 6.1e-4, drifts[0]),
                                     ("turns by 43 degrees", 43.0, angle.max())):
        claim = Claim(S, printed, CMD, value, abs=0.5 * 10 ** math.floor(math.log10(value) - 1))
        assert_printed(claim)
        assert_reproduced(claim, measured)


def test_the_compiled_loop_refuses_a_circle_with_its_reason(tmp_path):
    from cosim.core.schemes import driver
    system, scheme = cosim.load_scene(_scene(tmp_path, modes=4)).build()
    assert driver.refusal(scheme, system) == (
        "side `strip` hosts a circle contact (`hit`), which its numpy step integrates")


def _refused(path, key, *words, build=False):
    with pytest.raises(SceneError) as info:
        scene = cosim.load_scene(path)
        if build:
            scene.build()
    msg = str(info.value)
    assert str(path) in msg and key in msg, msg
    for w in words:
        assert w in msg, msg
    return msg


@pytest.mark.parametrize("radius, words", [("0.0", "> 0"), ("-0.01", "> 0"),
                                            ("inf", "finite"), ('"big"', "number")])
def test_a_bad_radius_is_refused_at_its_key(tmp_path, radius, words):
    _refused(_scene(tmp_path, radius=radius), "contacts.hit.radius", words)


@pytest.mark.parametrize("replace, key, words", [
    ({'b = "strip.top"': 'b = "ball.centre"', 'a = "ball.centre"': 'a = "strip.top"'},
     "contacts.hit.radius", ("side b must be a plane body",)),
    ({'type = "linear", contact_stiffness = 1e12': 'type = "kelvin_voigt", contact_stiffness = 1e9, contact_damping = 1.0'},
     "contacts.hit.law", ("must be `linear`", "Pa/m")),
    ({"radius = 0.01": 'radius = 0.01\nplacement = "coupler"'}, "contacts.hit.placement",
     ("must be `embedded`",)),
    ({"radius = 0.01": 'radius = 0.01\nhost = "ball"'}, "contacts.hit.host",
     ("must be the plane body",)),
    ({"radius = 0.01": 'radius = 0.01\nfriction = { coefficient = 0.3, slip_velocity = 0.01 }'},
     "contacts.hit.friction", ("not supported on a circle",)),
    ({"radius = 0.01": 'radius = 0.01\nfollow = true'}, "contacts.hit.follow", ("does not apply to a circle",)),
])
def test_what_a_circle_cannot_be_is_refused_at_its_key(tmp_path, replace, key, words):
    _refused(_scene(tmp_path, **replace), key, *words)


@pytest.mark.parametrize("replace, key, words", [
    ({'name = "gauss_seidel"': 'name = "jacobi"', 'sequence = ["strip", "ball"]': ''}, "scheme.name",
     ("runs with scheme `gauss_seidel` only", "got `jacobi`")),
    ({'name = "gauss_seidel"': 'name = "implicit"', 'sequence = ["strip", "ball"]': ''}, "scheme.name", ("got `implicit`",)),
    ({'name = "gauss_seidel"': 'name = "monolithic"', 'sequence = ["strip", "ball"]': ''}, "scheme.name", ("got `monolithic`",)),
    ({'sequence = ["strip", "ball"]': 'sequence = ["ball", "strip"]'}, "scheme.sequence",
     ("must step the plane body `strip` before `ball`",)),
    ({"modes = { count = 4 }": "modes = { count = 4, static_correction = true }"},
     "subsystems.strip.modes.static_correction", ("turn the correction off",)),
    ({"integrator = { contact_step = 2e-07 }": 'integrator = { method = "newmark" }'},
     "subsystems.strip.integrator.method", ("leave the method out",)),
])
@pytest.mark.filterwarnings("ignore:.*ignores the options")   # the monolithic case's macro_step
def test_a_scene_a_circle_cannot_run_in_is_refused_at_build(tmp_path, replace, key, words):
    _refused(_scene(tmp_path, modes=4, **replace), key, *words, build=True)


def test_a_circle_on_a_plane_side_a_is_refused(tmp_path):
    """The circle's centre is side a's point: a plane body there is refused
    (a rigid one too, by the same rule)."""
    path = _scene(tmp_path, **{'b = "strip.top"': 'b = "strip2.top"',
                               'a = "ball.centre"': 'a = "strip.top"'})
    text = path.read_text().replace("[subsystems.ball]", "[subsystems.strip2]\ntype = \"plane\"\n"
                                    "mesh = \"strip.msh\"\nthickness = 0.01\nyoungs_modulus = "
                                    "210e9\npoisson_ratio = 0.3\ndensity = 7850.0\nsupports = "
                                    "{ fixed = \"left\" }\npoints = { top = { boundary = \"top\", "
                                    "s = 0.1 } }\nmodes = { count = 2 }\n\n[subsystems.ball]")
    path.write_text(text)
    _refused(path, "contacts.hit.radius", "must move with another body than a plane one")


def test_info_says_a_circle_has_no_one_spring(tmp_path):
    """`cosim info` judges no point contact's spring for a circle (its k is in
    Pa/m): it names the circle and says why its frequency is not evaluated,
    and gives the plane body no mode rule against it."""
    from cosim.scene.info import scene_info
    info = scene_info(cosim.load_scene(_scene(tmp_path, modes=4)))
    hit = info["contacts"]["hit"]
    assert hit["radius"] == R and hit["stiffness_pa_per_m"] == 1e12 and hit["host"] == "strip"
    assert "frequency" not in hit and "no one spring" in hit["not_evaluated"]
    assert "mode_rule" not in json.dumps(info["subsystems"]["strip"])


def test_the_accuracy_estimate_judges_no_omega_h_for_a_circle(tmp_path):
    """The companions' ladder judges each exchanged contact by omega h of
    its one spring; a circle has none (its k is in Pa/m): it is left out,
    not judged as a 1e12 N/m spring."""
    from cosim.studies.companion import exchanged_omega_h
    scene = cosim.load_scene(_scene(tmp_path, modes=4))
    system, _ = scene.build()
    assert 0 in system.circles and exchanged_omega_h(scene, system) == {}


PIN = """
[subsystems.pin]
type = "multibody"
integrator = { method = "rk4", max_step = 1e-6 }

[subsystems.pin.bodies.pin]
mass = 0.1
inertia = 1e-5
points = { tip = [0.0, 0.0] }
joint = { name = "y", type = "prismatic", parent = "ground", axis = [0.0, 1.0], offset = [0.1, 0.020001], dq0 = -1.0 }

[contacts.poke]
a = "pin.tip"
b = "strip.poke"
normal = [0.0, 1.0]
law = { type = "linear", contact_stiffness = 1e8 }
placement = "embedded"
host = "strip"
"""


def test_a_body_hosts_a_circle_and_a_point_contact_together(tmp_path):
    """A pin (0.1 kg, 1e8 N/m) strikes the strip at 0.1 m while the circle
    strikes at mid-span, both hosted by the strip: both close, and the
    ledger of the whole closes to the coupling errors (the point contact's
    the larger, as a point contact's lag is)."""
    import warnings
    path = _scene(tmp_path, **{
        'points = { top = { boundary = "top", s = 0.2 } }':
            'points = { top = { boundary = "top", s = 0.2 }, poke = { boundary = "top", s = 0.1 } }',
        'sequence = ["strip", "ball"]': 'sequence = ["strip", "ball", "pin"]'})
    path.write_text(path.read_text() + PIN)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")         # the pin is a point contact on a continuum
        scene = cosim.load_scene(path)
        res = cosim.simulate(scene, estimate=False)
    assert res.status == "finished", res.message
    contacts = res.summary["contacts"]
    assert contacts["hit"]["count"] == contacts["poke"]["count"] == 1
    e0 = res.summary["energy"]["initial"]
    assert res.summary["energy"]["max_abs_drift"] < 1e-4 * e0
    assert abs(contacts["hit"]["coupling_error"]) < 1e-6 * e0
    assert abs(contacts["poke"]["coupling_error"]) < 1e-5 * e0

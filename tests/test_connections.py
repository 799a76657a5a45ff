"""Connections beyond the unilateral contact: grasp, release, friction.

The scenes are a point mass carried by two prismatic joints (``x`` then
``y``) of a massless slider, against points of a rigid ``ground``; each test
writes its scene from :func:`scene_text` so the closed forms below read
directly off it.
"""
import math
import re

import numpy as np
import pytest

import cosim
from cosim.scene.load import SceneError, load_scene

G = 9.81
MASS = 2.0


def scene_text(contacts: str, *, t_end: float, q0=(0.0, 0.0), dq0=(0.0, 0.0),
               points="{ bar = [0.0, 0.0] }", scheme='name = "monolithic"',
               gravity=True, max_step=1e-4) -> str:
    return f"""
name = "connections"
t_end = {t_end!r}
[scheme]
{scheme}
{"[effects]" + chr(10) + "gravity = 9.81" if gravity else ""}
[subsystems.robot]
type = "multibody"
integrator = {{ method = "rk4", max_step = {max_step!r} }}
[subsystems.robot.bodies.slider]
mass = 0.0
joint = {{ name = "x", type = "prismatic", parent = "ground", axis = [1.0, 0.0], q0 = {q0[0]!r}, dq0 = {dq0[0]!r} }}
[subsystems.robot.bodies.mass]
mass = {MASS!r}
points = {{ grip = [0.0, 0.0] }}
joint = {{ name = "y", type = "prismatic", parent = "slider", axis = [0.0, 1.0], q0 = {q0[1]!r}, dq0 = {dq0[1]!r} }}
[subsystems.ground]
type = "rigid"
points = {points}
{contacts}
"""


def run(tmp_path, text, scheme=None, overrides=()):
    path = tmp_path / "scene.toml"
    path.write_text(text)
    result = cosim.simulate(load_scene(path, overrides=list(overrides), scheme=scheme),
                            estimate=False)
    assert result.status == "finished", result.message
    return result


# the mass hangs from the bar: the bar's normal points down, towards the mass
HANG = """
[contacts.hold]
a = "robot.grip"
b = "ground.bar"
normal = [0.0, -1.0]
law = {{ type = "linear", contact_stiffness = 1e6 }}
grasp = {{ stiffness = {k!r}, damping = {c!r}, tangential_stiffness = {kt!r}, tangential_damping = {ct!r}, close = "start"{release} }}
"""

# scheme, overrides, bound on the ledger's drift relative to the energy dissipated
CO_SIM = [("monolithic", []),
          ("gauss_seidel", ['scheme.macro_step=1e-3']),                       # embedded
          ("implicit", ['scheme.macro_step=1e-3', 'contacts.hold.placement="coupler"'])]


@pytest.mark.parametrize("scheme,overrides", CO_SIM, ids=[s for s, _ in CO_SIM])
def test_grasp_at_start_holds_a_hanging_mass_at_its_static_deflection(tmp_path, scheme,
                                                                      overrides):
    k = 1e4
    c = 2 * 0.5 * math.sqrt(k * MASS)           # damping ratio 0.5: settled by t = 0.6 s
    text = scene_text(HANG.format(k=k, c=c, kt=k, ct=c, release=""), t_end=0.6)
    r = run(tmp_path, text, scheme, overrides)
    y = r.summary["final_state"]["robot"]["y"]["q"]
    assert y == pytest.approx(-MASS * G / k, rel=1e-6)
    assert r.summary["switches"] == [{"time": 0.0, "contact": "hold", "from": "open",
                                      "to": "grasped"}]
    assert r.summary["contacts"]["hold"]["intervals"] == [[0.0, 0.6]]
    assert r.series["force/hold"][-1] == pytest.approx(-MASS * G, rel=1e-6)  # it pulls
    assert np.all(r.series["mode/hold"] == 1)
    # what the dampers took is what the fall gave: m g d - k d^2 / 2 = (m g)^2 / 2k
    # (a co-simulated contact's damping power is integrated by the trapezoidal
    # rule over macro steps: measured 4.2e-4 relative drift, 1e-11 otherwise)
    e = r.summary["energy"]
    coupled = "coupler" in " ".join(overrides)
    assert e["max_abs_drift"] < (1e-3 if coupled else 1e-8) * (MASS * G) ** 2 / (2 * k)
    assert e["dissipated"] == pytest.approx((MASS * G) ** 2 / (2 * k), rel=1e-3)


@pytest.mark.parametrize("scheme,overrides", CO_SIM[:2], ids=[s for s, _ in CO_SIM[:2]])
def test_tangential_spring_holds_a_sideways_push_as_an_oscillator(tmp_path, scheme, overrides):
    k, kt, v0 = 1e4, 5e3, 0.1
    text = scene_text(HANG.format(k=k, c=0.0, kt=kt, ct=0.0, release=""), t_end=0.2,
                      dq0=(v0, 0.0), q0=(0.0, -MASS * G / k))
    r = run(tmp_path, text, scheme, overrides)
    t, x = r.t, r.series["q/robot/x"]
    omega = math.sqrt(kt / MASS)
    expected = v0 / omega * np.sin(omega * t)
    assert np.max(np.abs(x - expected)) < 1e-6 * v0 / omega
    # the tangential row is named after the contact, and it is the spring's force
    assert np.allclose(r.series["force/hold.t"], -kt * r.series["gap/hold.t"], atol=1e-9)
    assert np.allclose(r.series["gap/hold.t"], x, atol=1e-12)
    # frequency from the first up-crossing of x (one period after the start),
    # interpolated linearly between samples
    (i,) = np.flatnonzero((x[:-1] < 0) & (x[1:] >= 0))[:1]
    period = t[i] - x[i] * (t[i + 1] - t[i]) / (x[i + 1] - x[i])
    assert 2 * math.pi / period == pytest.approx(omega, rel=1e-5)


# the mass falls onto the ground: the surface's normal points up
DROP = """
[contacts.floor]
a = "robot.grip"
b = "ground.bar"
normal = [0.0, 1.0]
law = {{ type = "linear", contact_stiffness = {k!r} }}
grasp = {{ stiffness = {k!r}, damping = {c!r}, tangential_stiffness = {k!r}, tangential_damping = {c!r}, close = "touch"{release} }}
"""


@pytest.mark.parametrize("scheme,overrides", CO_SIM[:2], ids=[s for s, _ in CO_SIM[:2]])
def test_grasp_closes_at_the_first_touch_and_holds(tmp_path, scheme, overrides):
    h, k, c = 0.01, 1e6, 100.0
    text = scene_text(DROP.format(k=k, c=c, release=""), t_end=0.08, q0=(0.0, h))
    r = run(tmp_path, text, scheme, overrides)
    t_touch = math.sqrt(2 * h / G)
    (sw,) = r.summary["switches"]
    assert sw["contact"] == "floor" and (sw["from"], sw["to"]) == ("open", "grasped")
    assert sw["time"] == pytest.approx(t_touch, rel=1e-8)
    assert r.summary["contacts"]["floor"]["intervals"][0][0] == pytest.approx(sw["time"],
                                                                              abs=1e-12)
    # no rebound: the gap stays within the bilateral spring's reach of the
    # impact speed, v/omega + m g/k (a unilateral spring would send it 1 cm up)
    v = math.sqrt(2 * G * h)
    bound = v / math.sqrt(k / MASS) + MASS * G / k
    after = r.t > sw["time"]
    gap = r.series["gap/floor"][after]
    assert np.max(np.abs(gap)) < bound
    assert np.max(gap) > 0.05 * bound             # it pulls: the gap opens and is held
    assert r.summary["contacts"]["floor"]["count"] == 1


def test_release_on_time_lets_the_mass_fly_ballistically(tmp_path):
    k = 1e4
    c = 2 * 0.2 * math.sqrt(k * MASS)
    T = 0.1
    text = scene_text(HANG.format(k=k, c=c, kt=k, ct=c, release=f", release = {{ time = {T} }}"),
                      t_end=0.2, dq0=(0.3, 0.0))
    r = run(tmp_path, text)
    assert [(s["time"], s["to"]) for s in r.summary["switches"]] == [(0.0, "grasped"),
                                                                     (T, "released")]
    t = r.t
    free = t > T
    assert np.all(r.series["force/hold"][free] == 0.0)
    assert np.all(r.series["force/hold.t"][free] == 0.0)
    assert np.all(r.series["mode/hold"][t >= T] == 2) and np.all(r.series["mode/hold"][t < T] == 1)
    i = int(np.searchsorted(t, T))                # the sample at the release
    assert t[i] == pytest.approx(T, abs=1e-15)
    for q, a in (("x", 0.0), ("y", -G)):
        q0, v0 = r.series[f"q/robot/{q}"][i], r.series[f"dq/robot/{q}"][i]
        tau = t[free] - T
        expected = q0 + v0 * tau + 0.5 * a * tau * tau
        assert np.max(np.abs(r.series[f"q/robot/{q}"][free] - expected)) < 1e-9
    assert r.summary["contacts"]["hold"]["intervals"] == [[0.0, T]]
    # the ledger holds across the release: the springs' energy is booked as lost
    assert r.summary["energy"]["max_abs_drift"] < 1e-9


TWO_GRASPS = """
[contacts.hold]
a = "robot.grip"
b = "ground.bar"
normal = [0.0, -1.0]
law = { type = "linear", contact_stiffness = 1e6 }
grasp = { stiffness = 1e4, damping = 50.0, tangential_stiffness = 1e4, tangential_damping = 50.0, close = "start", release = { after = "other.grasp", delay = 0.02 } }

[contacts.other]
a = "robot.grip"
b = "ground.other"
normal = [0.0, -1.0]
law = { type = "linear", contact_stiffness = 1e6 }
grasp = { stiffness = 1e4, damping = 50.0, tangential_stiffness = 1e4, tangential_damping = 50.0, close = { time = 0.05 }, release = { after = "hold.release", delay = 0.03 } }
"""


@pytest.mark.parametrize("scheme,overrides", [
    ("monolithic", []),
    ("gauss_seidel", ["scheme.macro_step=1e-3"]),
    ("jacobi", ["scheme.macro_step=1e-3"])])
def test_release_on_a_condition_chains_the_grasps(tmp_path, scheme, overrides):
    text = scene_text(TWO_GRASPS, t_end=0.15,
                      points="{ bar = [0.0, 0.0], other = [0.0, 0.0] }")
    r = run(tmp_path, text, scheme, overrides)
    log = [(s["contact"], s["to"], s["time"]) for s in r.summary["switches"]]
    assert [(c, m) for c, m, _ in log] == [("hold", "grasped"), ("other", "grasped"),
                                           ("hold", "released"), ("other", "released")]
    times = [t for _, _, t in log]
    assert times == pytest.approx([0.0, 0.05, 0.07, 0.10], abs=1e-12)
    free = r.t > 0.10
    assert np.all(r.series["force/hold"][free] == 0) and np.all(r.series["force/other"][free] == 0)
    assert np.allclose(np.diff(r.series["dq/robot/y"][free]) / np.diff(r.t[free]), -G,
                       rtol=1e-6)
    # while both hold, each carries its share of the weight
    both = (r.t > 0.055) & (r.t < 0.07)
    total = r.series["force/hold"][both] + r.series["force/other"][both]
    assert np.all(total < 0)


# ----------------------------------------------------------------- rollback
ROLLBACK = DROP + """
[subsystems.load]
type = "multibody"
integrator = {{ method = "rk4", max_step = 1e-4 }}
[subsystems.load.bodies.block]
mass = 0.5
points = {{ bottom = [0.0, 0.0] }}
joint = {{ name = "y", type = "prismatic", parent = "ground", axis = [0.0, 1.0], q0 = {h!r}, dq0 = 0.0 }}

[contacts.tie]
a = "load.bottom"
b = "robot.grip"
normal = [0.0, 1.0]
law = {{ type = "linear", contact_stiffness = 1e5 }}
grasp = {{ stiffness = 1e5, damping = 20.0, tangential_stiffness = 0.0, tangential_damping = 0.0, close = "start" }}
"""


def test_implicit_scheme_restores_modes_on_repeated_steps(tmp_path):
    """The robot touches the floor inside a step that the implicit scheme
    repeats (the load tied to it by a co-simulated grasp keeps it
    iterating); every pass must start open, so the switch time and the motion
    after it agree with the monolithic reference."""
    h = 0.01
    text = scene_text(ROLLBACK.format(k=1e6, c=100.0, release="", h=h), t_end=0.06,
                      q0=(0.0, h))
    mono = run(tmp_path, text)
    imp = run(tmp_path, text, "implicit", ["scheme.macro_step=1e-4"])
    assert imp.n_iterations > imp.n_windows          # steps were repeated
    sw = {s["contact"]: s for s in imp.summary["switches"]}
    ref = {s["contact"]: s for s in mono.summary["switches"]}
    assert len(imp.summary["switches"]) == 2          # the repeats left no duplicates
    assert sw["floor"]["time"] == pytest.approx(ref["floor"]["time"], abs=1e-9)
    assert ref["floor"]["time"] == pytest.approx(math.sqrt(2 * h / G), rel=1e-8)
    # the largest gap under the grasp: 6.19075e-4 m against the reference's
    # 6.19096e-4 m (3.5e-5 relative); with the modes left grasped on the
    # repeats, the gripper pulls before the touch and it is 6.17996e-4 m
    peak = [np.max(np.abs(r.series["gap/floor"][r.t > ref["floor"]["time"]]))
            for r in (imp, mono)]
    assert peak[0] == pytest.approx(peak[1], rel=2e-4)


def test_system_state_carries_the_modes(tmp_path):
    text = scene_text(DROP.format(k=1e6, c=100.0, release=""), t_end=0.08, q0=(0.0, 0.01),
                      scheme='name = "gauss_seidel"\nmacro_step = 0.01')
    path = tmp_path / "scene.toml"
    path.write_text(text)
    system, _ = load_scene(path).build()
    saved = system.get_state()
    robot = system.subsystems[0]
    robot.step(0.0, 0.05)                           # touches at 45.2 ms
    assert system.connections.mode[0] == 1 and len(system.connections.log) == 1
    system.set_state(saved)
    assert system.connections.mode[0] == 0 and system.connections.log == []
    robot.step(0.0, 0.05)
    assert len(system.connections.log) == 1


# ----------------------------------------------------------------- friction
SLIDE = """
[contacts.floor]
a = "robot.grip"
b = "ground.bar"
normal = [0.0, 1.0]
law = {{ type = "linear", contact_stiffness = {k!r} }}
{friction}
"""


@pytest.mark.parametrize("scheme,overrides", CO_SIM[:2], ids=[s for s, _ in CO_SIM[:2]])
def test_sliding_block_decelerates_at_mu_g_and_stops(tmp_path, scheme, overrides):
    mu, vs, v0, k = 0.3, 1e-4, 1.0, 1e6
    fr = f"friction = {{ coefficient = {mu}, slip_velocity = {vs} }}"
    text = scene_text(SLIDE.format(k=k, friction=fr), t_end=0.4, dq0=(v0, 0.0),
                      q0=(0.0, -MASS * G / k), max_step=5e-5)
    r = run(tmp_path, text, scheme, overrides)
    t, v = r.t, r.series["dq/robot/x"]
    t_stop = v0 / (mu * G)
    sliding = (t > 0.01) & (t < t_stop - 0.01)
    assert np.max(np.abs(v[sliding] - (v0 - mu * G * t[sliding]))) < 1e-4 * v0
    assert abs(v[-1]) < 1e-9 and np.all(np.abs(v[t > t_stop + 0.01]) < 1e-6)
    x_stop = r.summary["final_state"]["robot"]["x"]["q"]
    assert x_stop == pytest.approx(v0 ** 2 / (2 * mu * G), rel=1e-3)
    # the contact's ledger took the kinetic energy that was lost
    lost = 0.5 * MASS * v0 ** 2
    assert r.summary["contacts"]["floor"]["dissipated"] == pytest.approx(lost, rel=1e-6)
    assert r.summary["energy"]["max_abs_drift"] < 1e-6 * lost
    # the tangent is t = (-n_y, n_x) = (-1, 0): the force on the block along
    # t is +mu m g, i.e. against its motion along +x
    assert np.all(r.series["force/floor.t"][sliding] == pytest.approx(mu * MASS * G, rel=1e-6))


@pytest.mark.parametrize("friction", ["", "friction = { coefficient = 0.0 }"])
def test_no_friction_row_without_a_coefficient(tmp_path, friction):
    text = scene_text(SLIDE.format(k=1e6, friction=friction), t_end=0.01, dq0=(1.0, 0.0))
    path = tmp_path / "scene.toml"
    path.write_text(text)
    system, _ = load_scene(path).build()
    assert system.n_rows == system.n_contacts == 1 and system.connections is None
    r = cosim.simulate(load_scene(path), estimate=False)
    assert "force/floor.t" not in r.series and r.summary["switches"] == []
    assert r.summary["final_state"]["robot"]["x"]["dq"] == 1.0    # nothing slows it


# ------------------------------------------------------------- scene errors
SPRING = "contacts.wall"
GRASP_OK = ('{stiffness = 1e6, damping = 10.0, tangential_stiffness = 1e6, '
            'tangential_damping = 10.0, close = "touch"}')
BAD = [
    ([f"{SPRING}.grasp={{stiffness = -1e6, damping = 10.0, tangential_stiffness = 1e6, "
      f"tangential_damping = 10.0, close = \"touch\"}}"],
     f"`{SPRING}.grasp.stiffness` must be > 0 N/m, got -1000000.0"),
    ([f"{SPRING}.grasp={GRASP_OK}", f'{SPRING}.grasp.close="sometimes"'],
     f"`{SPRING}.grasp.close` must be \"start\", \"touch\", {{ time = T }}"),
    ([f"{SPRING}.grasp={GRASP_OK}", f'{SPRING}.grasp.release="touch"'],
     f"`{SPRING}.grasp.release` must be {{ time = T }} or {{ after"),
    ([f"{SPRING}.grasp={GRASP_OK}", f'{SPRING}.grasp.release={{after = "nobody.grasp"}}'],
     f"`{SPRING}.grasp.release.after` names 'nobody.grasp', but no contact named `nobody` "
     f"has a grasp"),
    ([f"{SPRING}.grasp={GRASP_OK}", f'{SPRING}.grasp.release={{after = "wall.hold"}}'],
     f"`{SPRING}.grasp.release.after` must read CONTACT.grasp or CONTACT.release, "
     f"got 'wall.hold'"),
    ([f"{SPRING}.grasp={GRASP_OK}", f'{SPRING}.grasp.close={{after = "wall.grasp"}}'],
     f"`{SPRING}.grasp.close.after` cannot wait for an event of its own grasp"),
    ([f"{SPRING}.grasp={GRASP_OK}", f'{SPRING}.grasp.close={{time = 1.0, after = "w.grasp"}}'],
     f"`{SPRING}.grasp.close` must be"),
    ([f"{SPRING}.grasp={GRASP_OK}", f'{SPRING}.grasp.close={{time = -1.0}}'],
     f"`{SPRING}.grasp.close.time` must be >= 0 s, got -1.0"),
    ([f"{SPRING}.grasp={GRASP_OK}", f'{SPRING}.grasp.close={{time = 1.0}}',
      f'{SPRING}.grasp.release={{time = 0.5}}'],
     f"`{SPRING}.grasp.release` time 0.5 s must come after the close time 1.0 s"),
    ([f"{SPRING}.grasp={GRASP_OK}", f'{SPRING}.grasp.grip=1.0'],
     f"`{SPRING}.grasp.grip` is not a known key"),
    ([f"{SPRING}.grasp={{stiffness = 1e6, damping = 1.0, tangential_stiffness = 0.0, "
      f"tangential_damping = 0.0}}"],
     f"`{SPRING}.grasp.close` is required"),
    ([f"{SPRING}.grasp={{stiffness = 1e6, close = \"touch\"}}"],
     f"`{SPRING}.grasp.damping` is required but missing"),
    ([f"{SPRING}.law={{type = \"rigid\", restitution = 0.5, friction = 0.1}}",
      f"{SPRING}.friction={{coefficient = 0.3, slip_velocity = 1e-3}}"],
     f"`{SPRING}.friction` does not apply to a `rigid` law"),
    ([f"{SPRING}.law={{type = \"rigid\", restitution = 0.5, friction = 0.1}}",
      f"{SPRING}.grasp={GRASP_OK}"],
     f"`{SPRING}.grasp` needs a penalty law"),
    ([f"{SPRING}.friction={{coefficient = -0.3, slip_velocity = 1e-3}}"],
     f"`{SPRING}.friction.coefficient` must be >= 0 1, got -0.3"),
    ([f"{SPRING}.friction={{coefficient = 0.3}}"],
     f"`{SPRING}.friction.slip_velocity` is required but missing"),
    ([f"{SPRING}.friction={{coefficient = 0.3, slip_velocity = 0.0}}"],
     f"`{SPRING}.friction.slip_velocity` must be > 0 m/s, got 0.0"),
]


@pytest.mark.parametrize("overrides,message", BAD, ids=[o[-1][:60] for o, _ in BAD])
def test_bad_connection_keys_name_the_file_and_key(spring_drop, overrides, message):
    with pytest.raises(SceneError, match=re.escape(f"{spring_drop}: {message}")):
        load_scene(spring_drop, overrides=overrides)


CHAIN = """
[subsystems.chain]
type = "chain"
masses = [{ms!r}]
stiffnesses = [{ks!r}]
spacing = 0.05
origin = [0.0, 0.0]
points = {{ top = 0 }}
static_equilibrium = true
rayleigh = [800.0, 0.0]
"""


@pytest.mark.parametrize("scheme,overrides", [("monolithic", []),
                                              ("implicit", ["scheme.macro_step=2e-3"])])
def test_grasp_of_a_chain_top_between_two_moving_sides(tmp_path, scheme, overrides):
    """Both sides move, so the scheme exchanges both rows; the chain feels
    only the normal one (its field is vertical)."""
    k, ks, ms = 1e4, 2e4, 0.5
    c = 300.0              # with rayleigh a0 = 800/s the slowest mode decays at 39.7/s
    hang = HANG.format(k=k, c=c, kt=k, ct=c, release="").replace("ground.bar", "chain.top")
    text = scene_text(hang + CHAIN.format(ms=ms, ks=ks), t_end=0.5)
    r = run(tmp_path, text, scheme, overrides)
    assert r.summary["contacts"]["hold"]["placement"] == "coupler"
    y = r.summary["final_state"]["robot"]["y"]["q"]
    top = r.summary["final_state"]["chain"]["m1"]["q"]
    assert top == pytest.approx(-(MASS + ms) * G / ks, rel=1e-6)
    assert y - top == pytest.approx(-MASS * G / k, rel=1e-6)
    # measured: 1e-10 (monolithic), 1.1e-3 (implicit: the co-simulated
    # dampers' power is integrated by the trapezoidal rule over 2 ms steps)
    bound = 1e-8 if scheme == "monolithic" else 3e-3
    assert r.summary["energy"]["max_abs_drift"] < bound * r.summary["energy"]["dissipated"]


def test_coupler_touch_grasps_at_the_communication_point_after_the_onset(tmp_path):
    """Exchanged by the scheme, the touch is seen at the first communication
    point at which the law gives a force."""
    h, H = 0.01, 1e-4
    text = scene_text(DROP.format(k=1e6, c=100.0, release=""), t_end=0.06, q0=(0.0, h))
    r = run(tmp_path, text, "implicit", [f"scheme.macro_step={H}",
                                         'contacts.floor.placement="coupler"'])
    (sw,) = r.summary["switches"]
    t_touch = math.sqrt(2 * h / G)
    assert t_touch < sw["time"] <= t_touch + H * (1 + 1e-9)
    assert sw["time"] / H == pytest.approx(round(sw["time"] / H), abs=1e-6)
    gap = r.series["gap/floor"][r.t > sw["time"]]
    assert np.max(np.abs(gap)) < math.sqrt(2 * G * h) / math.sqrt(1e6 / MASS) + MASS * G / 1e6


def test_preflight_judges_a_grasp_stiffer_than_its_law(tmp_path):
    from cosim.errors import UnsafeStepError
    hang = HANG.format(k=1e6, c=0.0, kt=0.0, ct=0.0, release="").replace(
        "contact_stiffness = 1e6", "contact_stiffness = 1e2")
    text = scene_text(hang, t_end=0.01)
    with pytest.raises(UnsafeStepError, match=r"contact `hold`: macro step 0\.001 s .*"
                                              r"omega = 707\.1 rad/s"):
        run(tmp_path, text, "gauss_seidel", ["scheme.macro_step=1e-3",
                                             'contacts.hold.placement="coupler"'])


def test_co_simulated_friction_row_under_the_implicit_scheme(tmp_path):
    """The tangential row is exchanged like the normal one.  The fixed point
    converges while the friction's damping near rest, mu f_n / v_s, is soft
    against the step (here mu g H / v_s = 0.29); with v_s = 1e-4 and
    H = 1e-3 it does not (README)."""
    mu, vs, v0, k, H = 0.3, 1e-2, 1.0, 1e6, 1e-3
    fr = f"friction = {{ coefficient = {mu}, slip_velocity = {vs} }}"
    text = scene_text(SLIDE.format(k=k, friction=fr), t_end=0.4, dq0=(v0, 0.0),
                      q0=(0.0, -MASS * G / k), max_step=2e-4)
    r = run(tmp_path, text, "implicit", [f"scheme.macro_step={H}",
                                         'contacts.floor.placement="coupler"'])
    t, v = r.t, r.series["dq/robot/x"]
    sliding = (t > 0.02) & (t < v0 / (mu * G) - 0.02)
    assert np.max(np.abs(v[sliding] - (v0 - mu * G * t[sliding]))) < 1e-3 * v0
    assert r.summary["final_state"]["robot"]["x"]["q"] == pytest.approx(
        v0 ** 2 / (2 * mu * G), rel=1e-3)
    assert abs(v[-1]) < 1e-6
    lost = 0.5 * MASS * v0 ** 2
    assert r.summary["contacts"]["floor"]["dissipated"] == pytest.approx(lost, rel=1e-3)


# CASES.md section 7 in miniature: a two-link robot hangs from a tensioned
# cable by gripper 1, swings gripper 2 up onto the cable 0.8 m further, which
# grasps on touch; gripper 1 lets go 50 ms later.  (Not the scene itself: no
# drive, a coarse cable with 12 modes.)
BRACHIATION = """name = "brachiation_step"
t_end = 0.4
[scheme]
name = "monolithic"
rtol = 1e-8
atol = 1e-10
[effects]
gravity = 9.81
[subsystems.cable]
type = "cable"
length = 4.0
youngs_modulus = 100e9
density = 7850.0
section = { diameter = 0.01 }
tension = 2000.0
elements = 40
left = "pinned"
right = "pinned"
origin = [0.0, 0.0]
axis = [1.0, 0.0]
direction = [0.0, 1.0]
points = { g1 = 1.6, g2 = 2.4 }
modes = { count = 12 }
static_equilibrium = true
[subsystems.robot]
type = "multibody"
integrator = { method = "rk4", max_step = 2e-5 }
[subsystems.robot.bodies.sx]
mass = 0.0
joint = { name = "x", type = "prismatic", parent = "ground", axis = [1.0, 0.0], q0 = 1.6 }
[subsystems.robot.bodies.sy]
mass = 0.0
joint = { name = "y", type = "prismatic", parent = "sx", axis = [0.0, 1.0], q0 = -0.0 }
[subsystems.robot.bodies.link1]
mass = 1.5
inertia = 0.03125
com = [0.25, 0.0]
points = { g1 = [0.0, 0.0] }
joint = { name = "shoulder", type = "revolute", parent = "sy", q0 = -0.6435 }
[subsystems.robot.bodies.link2]
mass = 1.5
inertia = 0.03125
com = [0.25, 0.0]
points = { g2 = [0.5, 0.0] }
joint = { name = "elbow", type = "revolute", parent = "link1", offset = [0.5, 0.0], q0 = 1.2, dq0 = 3.0 }
[contacts.gripper1]
a = "robot.g1"
b = "cable.g1"
normal = [0.0, -1.0]
law = { type = "linear", contact_stiffness = 1e5 }
grasp = { stiffness = 1e5, damping = 50.0, tangential_stiffness = 1e5, tangential_damping = 50.0, close = "start", release = { after = "gripper2.grasp", delay = 0.05 } }
[contacts.gripper2]
a = "robot.g2"
b = "cable.g2"
normal = [0.0, -1.0]
law = { type = "linear", contact_stiffness = 1e5 }
grasp = { stiffness = 1e5, damping = 50.0, tangential_stiffness = 1e5, tangential_damping = 50.0, close = "touch" }
"""


def test_brachiation_step_hands_over_from_one_gripper_to_the_other(tmp_path):
    r = run(tmp_path, BRACHIATION)
    log = [(s["contact"], s["to"]) for s in r.summary["switches"]]
    assert log == [("gripper1", "grasped"), ("gripper2", "grasped"), ("gripper1", "released")]
    t2 = r.summary["switches"][1]["time"]
    assert 0.0 < t2 < 0.1
    assert r.summary["switches"][2]["time"] == pytest.approx(t2 + 0.05, abs=1e-12)
    assert r.summary["contacts"]["gripper2"]["intervals"][0][0] == pytest.approx(t2, abs=1e-12)
    # gripper 2 holds the swinging robot: its gap stays within a few weights / k
    held = r.t > t2
    assert np.max(np.abs(r.series["gap/gripper2"][held])) < 2e-3
    assert np.max(np.abs(r.series["gap/gripper2.t"][held])) < 2e-3
    # the robot swings about gripper 2, its links' length (1 m) from it
    x, y = r.summary["final_state"]["robot"]["x"]["q"], r.summary["final_state"]["robot"]["y"]["q"]
    assert math.hypot(2.4 - x, y) == pytest.approx(1.0, abs=5e-3)
    assert r.summary["energy"]["max_abs_drift"] < 1e-5 * r.summary["energy"]["dissipated"]

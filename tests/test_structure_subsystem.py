"""Structures as subsystems: exact modal stepping, ports anywhere, rod_impact."""
import math
import subprocess
import sys
import warnings

import numpy as np
import pytest

import cosim
import fem
from conftest import CASES, ROOT
from cosim.sides.fem import StructureSubsystem
from cosim.core.subsystem import StepInput

E, RHO, L = 210e9, 7850.0, 1.0
SEC = fem.rectangular_section(0.04, 0.01)


def pinned_beam(n):
    return fem.Beam(L, E, SEC.second_moment, RHO, SEC.area, n, "pinned", "pinned").assemble()


def continuum_response(a, x, t, force, terms=400):
    """Pinned-pinned Euler-Bernoulli beam, step force at a from t = 0:
    w(x, t) = sum_i 2/(rho A L) sin(i pi a/L) sin(i pi x/L) F (1 - cos w_i t) / w_i^2."""
    i = np.arange(1, terms + 1)
    w = (i * np.pi / L) ** 2 * math.sqrt(E * SEC.second_moment / (RHO * SEC.area))
    phi = 2 / (RHO * SEC.area * L) * np.sin(i * np.pi * a / L) * np.sin(i * np.pi * x / L)
    return float(np.sum(phi * force * (1 - np.cos(w * t)) / w ** 2))


def test_point_force_at_a_non_nodal_point_matches_the_modal_solution():
    """Force 100 N suddenly applied at s = 0.437 m (no node for any mesh used),
    displacement read at s = 0.3 m after 5 ms (about 1/8 of the first period):
    the FE subsystem, stepped exactly, converges to the continuum's series."""
    a, x, t_end, force = 0.437, 0.3, 5e-3, 100.0
    ref = continuum_response(a, x, t_end, force)
    errs = []
    for n in (8, 16, 32):
        s = pinned_beam(n)
        sub = StructureSubsystem("beam", s, fem.modes(s), {"load": a, "probe": x})
        coeffs = np.zeros((1, 2, 2))
        coeffs[0, 0] = (0.0, force)
        for k in range(10):
            sub.step(k * t_end / 10, t_end / 10, StepInput(k * t_end / 10, t_end / 10, coeffs))
        errs.append(abs(sub.outputs(sub.t, sub.x)[0][1, 1] - ref) / abs(ref))
    assert errs[-1] < 2e-3, errs
    assert errs[0] > errs[1] > errs[2], errs


def test_exact_step_is_independent_of_the_macro_step():
    s = pinned_beam(16)
    outs = []
    for n_steps in (1, 7, 50):
        sub = StructureSubsystem("beam", s, fem.modes(s), {"p": 0.45})
        h = 0.02 / n_steps
        for k in range(n_steps):
            c = np.zeros((2, 1, 2))
            c[0, 0, 1] = -50.0 + 1000.0 * k * h       # a ramp, linear over each step
            c[1, 0, 1] = 1000.0 * h
            sub.step(k * h, h, StepInput(k * h, h, c))
        outs.append(sub.x.copy())
    assert np.allclose(outs[0], outs[1], rtol=1e-9, atol=1e-15)
    assert np.allclose(outs[0], outs[2], rtol=1e-9, atol=1e-15)


def test_rod_impact_tends_to_saint_venant():
    """Contact span (first touch to last release) -> 2L/c and rebound speed
    (impulse / mass - v0) -> v0 as the mesh refines; convergence is slow and
    not monotone (observed span/tc 0.964, 0.962, 0.988, 0.994, 0.999 for
    10..160 elements), so the trend and the finest error are asserted."""
    c = math.sqrt(E / RHO)
    tc, mass = 2 * L / c, RHO * 1e-4 * L
    span_err, reb_err, drift = [], [], []
    for n in (20, 80, 160):
        res = cosim.simulate(cosim.load_scene(CASES / "rod_impact.toml", overrides=[
            f"subsystems.rod.elements={n}",
            f"subsystems.rod.integrator.contact_step={2e-7 * 50 / n}"]), estimate=False)
        assert res.success, res.message
        cc = res.summary["contacts"]["wall"]
        span_err.append(abs((cc["intervals"][-1][1] - cc["intervals"][0][0]) / tc - 1))
        reb_err.append(abs(cc["impulse"] / mass - 1 - 1))
        e = res.summary["energy"]
        drift.append(e["max_abs_drift"] / e["initial"])
    # the rod and its linear wall spring are stepped in closed form, touch and
    # release located on the exact solution: the energy keeps to round-off
    # (observed 8e-13, 5e-13, 6e-12 of it; RK4 through the contact drifted
    # 8.6e-4, 3.2e-5, 5.1e-6)
    assert max(drift) < 1e-10, drift
    assert span_err[-1] < 2e-3 and reb_err[-1] < 1e-2, (span_err, reb_err)
    assert span_err[-1] < span_err[0] and reb_err[-1] < reb_err[0]


def test_monolithic_and_exact_cosimulation_agree_on_a_structure(tmp_path):
    """A chain hit by nothing but gravity, from rest: the monolithic ODE of the
    modal equations and the exact modal step give the same motion."""
    p = tmp_path / "chain.toml"
    p.write_text(CHAIN)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        mono = cosim.simulate(cosim.load_scene(p, scheme="monolithic"), estimate=False).summary
    ex = cosim.simulate(cosim.load_scene(p), estimate=False).summary
    for dof in ("m1", "m2", "m3"):
        assert ex["final_state"]["chain"][dof]["q"] == pytest.approx(
            mono["final_state"]["chain"][dof]["q"], rel=1e-7, abs=1e-12)


CHAIN = """
t_end = 0.05
[scheme]
name = "jacobi"
macro_step = 1e-3
[effects]
gravity = 9.81
[subsystems.chain]
type = "chain"
masses = [0.15, 0.15, 0.15]
stiffnesses = [1.6e5, 1.6e5, 1.6e5]
spacing = 0.05
points = { top = 0 }
"""


def test_a_chain_scene_loads_neither_scikit_fem_nor_meshio(tmp_path):
    p = tmp_path / "chain.toml"
    p.write_text(CHAIN)
    code = ("import sys, cosim; r = cosim.run_scene(sys.argv[1]); assert r.success; "
            "print(sorted(m for m in ('skfem', 'meshio', 'matplotlib', 'dask') "
            "if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code, str(p)], capture_output=True, text=True,
                         cwd=ROOT, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"


def test_info_lists_the_beam_frequencies():
    """cosim info on beam_impact: the pinned-pinned closed form
    f_n = (n pi / L)^2 sqrt(EI / rho A) / (2 pi); with 32 Hermite elements the
    discretisation error, O(h^4), is 4e-5 for the fifth mode.  The
    frequencies are the built structure's: info's runs (to the first touch,
    and those confirming the explicit schemes' steps) are left out."""
    from cosim.scene.info import scene_info
    info = scene_info(cosim.load_scene(CASES / "beam_impact.toml"), budget_s=0, confirm_steps=0)
    f = np.array(info["subsystems"]["beam"]["natural_frequencies_hz"][:5])
    n = np.arange(1, 6)
    ref = (n * np.pi / L) ** 2 * math.sqrt(E * SEC.second_moment / (RHO * SEC.area)) / (2 * np.pi)
    assert f == pytest.approx(ref, rel=1e-4)
    assert f[0] == pytest.approx(ref[0], rel=1e-6)        # observed 6.5e-8
    assert info["subsystems"]["beam"]["dofs"] == 64
    assert info["subsystems"]["beam"]["modes_kept"] + info["subsystems"]["beam"][
        "modes_dropped"] == 64


@pytest.mark.parametrize("method,opts,tol", [
    ("newmark", {}, 2e-3), ("generalized_alpha", {"rho_inf": 1.0}, 2e-3),
    ("hht_alpha", {"alpha": -0.05}, 5e-3), ("central_difference", {}, 2e-3)])
def test_time_stepping_integrators_agree_with_the_exact_step(method, opts, tol):
    """A beam under a ramp load, 16 elements, modes below 2 kHz (h = 2e-5 s,
    omega_max h = 0.25): second-order schemes within a few 1e-3 of exact."""
    s = pinned_beam(16)
    basis = fem.modes(s, cutoff_hz=2000.0)

    def run(m, o):
        sub = StructureSubsystem("beam", s, basis, {"p": 0.45}, integrator=m,
                                 integrator_options=o)
        h = 2e-5
        for k in range(500):
            c = np.zeros((2, 1, 2))
            c[0, 0, 1], c[1, 0, 1] = -1000.0 * k * h, -1000.0 * h
            sub.step(k * h, h, StepInput(k * h, h, c))
        return sub.outputs(sub.t, sub.x)[0][0, 1]
    ref = run("exact", None)
    assert run(method, opts) == pytest.approx(ref, rel=tol)


def test_central_difference_refused_beyond_its_limit():
    with pytest.raises(cosim.SceneError, match=r"`subsystems\.beam\.integrator\.method` "
                                               r"`central_difference` is stable only for steps "
                                               r"below"):
        cosim.load_scene(CASES / "beam_impact.toml", overrides=[
            'subsystems.beam.integrator.method="central_difference"']).build()


def test_export_writes_the_field_for_paraview(tmp_path):
    """XDMF with XML data: nodes, line cells, one entry per exported sample,
    the field equal to the recorded DOFs."""
    import meshio
    from cosim import cli
    assert cli.main(["run", str(CASES / "rod_impact.toml"), "--set", "subsystems.rod.elements=20",
                     "--set", "subsystems.rod.integrator.contact_step=4e-7",
                     "--set", 'output.export=["rod"]', "--set", "output.export_every=10",
                     "--out", str(tmp_path)]) == 0
    series = np.load(tmp_path / "series.npz")
    reader = meshio.xdmf.TimeSeriesReader(str(tmp_path / "rod.xdmf"))
    points, cells = reader.read_points_cells()
    assert points.shape == (21, 2) and cells[0].type == "line" and len(cells[0].data) == 20
    assert reader.num_steps == len(range(0, len(series["t"]), 10))
    t, point_data, _ = reader.read_data(3)
    assert t == pytest.approx(series["t"][30])
    assert point_data["w"][0] == pytest.approx(series["q/rod/u0"][30])
    assert point_data["displacement"][5, 0] == pytest.approx(series["q/rod/u5"][30])
    assert not list(tmp_path.glob(".*.xdmf"))        # no temporary left behind


def test_export_names_must_be_structures():
    with pytest.raises(cosim.SceneError, match=r"`output\.export` names 'wall', which is not a "
                                               r"structure of this scene; structures are \['rod'\]"):
        cosim.load_scene(CASES / "rod_impact.toml", overrides=['output.export=["wall"]'])


def test_following_contact_keeps_the_struck_point_under_c():
    """beam_impact's contact C follows: after each macro step the beam's port
    sits at the material coordinate below C (updated before each step, so
    within one macro step's drift of C)."""
    from cosim.core.recorder import Recorder
    scene = cosim.load_scene(CASES / "beam_impact.toml", overrides=["t_end=0.02"])
    system, scheme = scene.build()
    scheme.run(system, scene.t_end, Recorder(system, "b", "implicit", scene.t_end))
    beam = system.subsystems[system.names.index("beam")]
    robot = system.subsystems[system.names.index("robot")]
    pos, vel = robot.outputs(robot.t, robot.x)
    c = robot.port_index("C")
    s_expected = beam.material_coordinate(pos[c])
    assert s_expected != pytest.approx(0.45, abs=1e-3)        # C has drifted
    assert beam.port_coordinates[0] == pytest.approx(
        s_expected, abs=abs(vel[c][0]) * scene.scheme_options["macro_step"] * 1.01)


def test_follow_needs_a_line_structure():
    with pytest.raises(cosim.SceneError, match=r"`contacts\.A\.follow` moves side b's point "
                                               r"along a line structure; `ground` is a rigid"):
        cosim.load_scene(CASES / "beam_impact.toml", overrides=["contacts.A.follow=true"])


SLIDE = """
name = "slide"
t_end = 0.006                 # one contact of P, 2.4 ms, sliding 12 mm along the beam
[scheme]
name = "monolithic"
rtol = 1e-10
atol = 1e-13
[subsystems.beam]
type = "beam"
length = 1.0
youngs_modulus = 210e9
density = 7850.0
section = { width = 0.04, height = 0.01 }
elements = 8
left = "pinned"
right = "pinned"
origin = [0.0, 0.0]
axis = [1.0, 0.0]
direction = [0.0, 1.0]
points = { under = 0.3 }
modes = { cutoff_hz = 2000.0 }
[subsystems.slider]
type = "multibody"
integrator = { method = "rk4", max_step = 1e-4 }
[subsystems.slider.bodies.frame]
mass = 0.0
joint = { name = "x", type = "prismatic", parent = "ground", axis = [1.0, 0.0], q0 = 0.3, dq0 = 5.0 }
[subsystems.slider.bodies.mass]
mass = 1.0
points = { P = [0.0, 0.0] }
joint = { name = "y", type = "prismatic", parent = "frame", axis = [0.0, 1.0], q0 = 0.0005, dq0 = -1.0 }
[contacts.C]
a = "slider.P"
b = "beam.under"
normal = [0.0, 1.0]
follow = true
law = { type = "linear", contact_stiffness = 1e6 }
placement = "coupler"
"""


def test_following_contact_on_a_moving_beam_conserves_energy(tmp_path):
    """A mass slides at 5 m/s across a pinned beam while pressing into it
    (no damping, no gravity).  With the force along the deformed surface's
    normal (`CoupledSystem.update_followers`) the monolithic reference keeps
    the energy as well as with the struck point fixed: both to 1e-9 J of 13 J.
    (The force along the contact's normal alone created 1.9e-3 J here.)"""
    path = tmp_path / "slide.toml"
    path.write_text(SLIDE)
    drift = {}
    for follow in (True, False):
        scene = cosim.load_scene(path, overrides=[f"contacts.C.follow={str(follow).lower()}"])
        res = cosim.simulate(scene, estimate=False)
        assert res.success, res.message
        assert res.summary["contacts"]["C"]["count"] == 1
        drift[follow] = res.summary["energy"]["max_abs_drift"]
        assert abs(res.summary["contacts"]["C"]["coupling_error"]) < 1e-9
        assert res.summary["energy"]["initial"] == pytest.approx(13.0, rel=1e-3)
    assert drift[True] < 1e-9 and drift[False] < 1e-9, drift


def test_following_contact_differs_from_a_fixed_one_by_the_slope_force(tmp_path):
    """The slope term is not idle: following P moves the point of impact and
    turns the force, so the impulse on P's horizontal motion is non-zero (a
    fixed point or a vertical force would leave dx/dt at exactly 5 m/s)."""
    path = tmp_path / "slide.toml"
    path.write_text(SLIDE)
    res = cosim.simulate(cosim.load_scene(path), estimate=False)
    dx = res.summary["final_state"]["slider"]["x"]["dq"]
    assert dx != pytest.approx(5.0, abs=1e-6)
    fixed = cosim.simulate(cosim.load_scene(path, overrides=["contacts.C.follow=false"]),
                           estimate=False)
    assert fixed.summary["final_state"]["slider"]["x"]["dq"] == pytest.approx(5.0, abs=1e-12)


def test_following_contact_hosted_by_the_point_is_refused():
    """Embedded in the robot, the slope force would be left out: refused, naming
    the contact and what to do (a scene is refused at load,
    tests/test_following_host.py; a system built in Python, here)."""
    import dataclasses

    from cosim.core.system import CoupledSystem
    system, _ = cosim.load_scene(CASES / "beam_impact.toml").build()
    c = system.contact_names.index("C")
    links = list(system.links)
    links[c] = dataclasses.replace(links[c], host=links[c].sub_a)
    with pytest.raises(ValueError, match=r"contact `C`: a following contact hosted by its "
                                         r"point's side \(`robot`\) would miss the surface's "
                                         r"slope force; host it in `beam`"):
        CoupledSystem(system.subsystems, links)

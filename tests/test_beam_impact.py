"""beam_impact (CASES.md section 6): the answer converges as the mesh refines,
does not depend on where the nodes fall relative to C, and a point mass
dropped on the same beam meets the continuum's exact modal solution."""
import math
import warnings

import numpy as np
import pytest

import cosim
from analytic import mass_on_pinned_beam
from conftest import CASES
from cosim.studies.metrics import impact_metrics, relative_errors
from roundoff import assert_robust

E, RHO, L = 210e9, 7850.0, 1.0
WIDTH, HEIGHT = 0.04, 0.01
EI, RHO_A = E * WIDTH * HEIGHT ** 3 / 12, RHO * WIDTH * HEIGHT

#: C's two contacts end at 0.1217 s; the run stops just past the last release.
SHORT = ["t_end=0.125", "subsystems.beam.modes={count=12}"]



def test_default_scheme_hosts_c_in_the_beam_and_matches_the_monolithic_reference():
    """The scene's default (Gauss-Seidel, C hosted by the beam, 1 ms / 50 us)
    against the monolithic reference, both with 12 modes and stopped just
    past C's last release to keep the reference's DOP853 short (6 s): same
    2 contacts, peak 2.2e-5 and exit velocity 1.9e-4 off (measured; with the
    scene's 28 modes and t_end, 1.8e-5 and 1.9e-4 against a 28 s reference).
    The 1 % bound is the issue's acceptance criterion."""
    scene = cosim.load_scene(CASES / "beam_impact.toml", overrides=SHORT)
    assert scene.scheme == "gauss_seidel"
    system, _ = scene.build()
    c = system.contact_names.index("C")
    assert system.subsystems[system.embedded[c][0]].name == "beam"
    res = cosim.simulate(scene, estimate=False)
    with warnings.catch_warnings():     # the reference ignores the co-simulation's options
        warnings.simplefilter("ignore")
        ref = cosim.simulate(cosim.load_scene(CASES / "beam_impact.toml", overrides=SHORT,
                                              scheme="monolithic"), estimate=False)
    assert res.success and ref.success, (res.message, ref.message)
    err = relative_errors(impact_metrics(res, "C", "robot/arm"),
                          impact_metrics(ref, "C", "robot/arm"))
    assert err["count"] == 0 and err["peak"] < 0.01 and err["exit_velocity"] < 0.01, err
    # C's two contacts hold for the scene's round-off copies (the default scheme's:
    # 0.2 s a run; measured 2 for each of 5 copies)
    assert_robust(scene, lambda r: (r.status, r.summary["contacts"]["C"]["count"]),
                  ("finished", 2))

def c_contact(elements, follow=True):
    """C's count, peak penetration [m], first touch and last release [s], and
    the arm's exit velocity [rad/s], under the scene's default scheme with the
    beam cut to ``elements`` elements and 12 modes (and C's struck point
    sliding with the arm, as shipped, or held at its material point)."""
    res = cosim.simulate(cosim.load_scene(CASES / "beam_impact.toml", overrides=[
        *SHORT, f"subsystems.beam.elements={elements}",
        f"contacts.C.follow={str(follow).lower()}"]), estimate=False)
    assert res.success, res.message
    m = impact_metrics(res, "C", "robot/arm")
    iv = res.summary["contacts"]["C"]["intervals"]
    return {"count": m["count"], "peak": m["peak"], "first": iv[0][0], "last": iv[-1][1],
            "exit": m["exit_velocity"]}


def _rate(runs, key):
    h = np.array([1 / 16, 1 / 32, 1 / 64])
    diff = np.abs(np.diff([r[key] for r in runs]))
    return np.polyfit(np.log(h), np.log(diff), 1)[0], diff


def test_c_converges_with_the_mesh():
    """16, 32, 64 and 128 elements (0.45 m is no node of any: 7.2, 14.4, 28.8
    and 57.6 element lengths), 12 modes kept in each so that only the mesh
    changes (with the scene's 20 kHz cutoff the kept modes grow with the mesh,
    16, 25, 28, 29, 29 for 8 to 128 elements, a second, stepwise change), C
    struck at a fixed material point so that only the beam's discretisation
    is measured.  Cubic Hermite elements approximate each mode's frequency
    and shape to O(h^4), and so does the contact: the differences between
    successive meshes fall at the fitted rates 4.4 (last release: 1.40e-6,
    1.14e-7, 3.1e-9 s), 3.95 (the arm's exit velocity: 6.3e-3, 2.2e-4,
    2.6e-5 rad/s) and 3.7 (C's peak penetration: 2.3e-7, 1.2e-7, 1.4e-9 m).
    The first touch depends on the static sag only, which Hermite elements
    give exactly at the nodes: the same on every mesh to 1e-9 s.  C closes
    twice on every mesh."""
    runs = [c_contact(n, follow=False) for n in (16, 32, 64, 128)]
    assert [r["count"] for r in runs] == [2, 2, 2, 2]
    for key, ceiling in (("last", 1e-8), ("exit", 1e-4), ("peak", 1e-8)):
        slope, diff = _rate(runs, key)
        assert abs(slope - 4.0) < 0.5, f"{key}: observed rate {slope:.2f}, differences {diff}"
        assert diff[-1] < ceiling, (key, diff)
    first = np.array([r["first"] for r in runs])
    assert np.ptp(first) < 1e-9, first


def test_sliding_c_settles_with_the_mesh():
    """The shipped scene: C's struck point slides under the arm
    (``follow``), the force along the bent surface's normal.  The last
    release still converges at rate 3.9 (1.44e-6, 9.5e-8, 6.2e-9 s), but the
    exit velocity's differences (4.0e-3, 1.8e-4, 5.6e-5 rad/s, rate 3.1) and
    the located peak's (2.1e-8, 9.0e-8, 7.5e-9 m) settle without a clean
    rate: the surface point moves, and its slope is taken, once per macro
    step, and that error does not depend on the mesh alone.  What is held
    here: the count, the release's rate, the exit velocity's differences
    shrinking, and on the finest pair every difference below the same
    ceilings as the fixed point's and below the coarser pairs'."""
    runs = [c_contact(n) for n in (16, 32, 64, 128)]
    assert [r["count"] for r in runs] == [2, 2, 2, 2]
    slope, diff = _rate(runs, "last")
    assert abs(slope - 4.0) < 0.5, f"last: observed rate {slope:.2f}, differences {diff}"
    for key, ceiling in (("last", 1e-8), ("exit", 1e-4), ("peak", 1e-8)):
        diff = np.abs(np.diff([r[key] for r in runs]))
        assert diff[-1] < min(diff[:-1]) and diff[-1] < ceiling, (key, diff)
    exit_diff = np.abs(np.diff([r["exit"] for r in runs]))
    assert exit_diff[0] > exit_diff[1] > exit_diff[2], exit_diff


def test_where_the_nodes_fall_does_not_matter():
    """C's first touch at 0.45 m lands on a node with 20 and 40 elements, and
    at 0.45 and 0.55 of an element with 19, 21 and 39, 41 (the port follows C
    over 0.444-0.450 m during the contacts, so a node stays within a quarter
    element of it).  The spread over each trio is the mesh's own error at
    that density, and shrinks with it as the convergence test does: measured
    peak 4.2e-4 and 2.2e-5, exit velocity 2.6e-4 and 1.2e-5 (relative), last
    release 1.3e-6 and 5.9e-8 s.  The tolerance at 40 elements, 1e-4
    relative, is a hundredth of the 1 % to which the scheme is held against
    the monolithic reference: placement is then invisible beside every other
    error of the run."""
    spreads = []
    for trio in ((19, 20, 21), (39, 40, 41)):
        runs = [c_contact(n) for n in trio]
        assert [r["count"] for r in runs] == [2, 2, 2]
        spreads.append({k: np.ptp([r[k] for r in runs]) / (1.0 if k == "last" else abs(
            runs[1][k])) for k in ("peak", "exit", "last")})
    coarse, fine = spreads
    assert fine["peak"] < 1e-4 and fine["exit"] < 1e-4 and fine["last"] < 2e-7, fine
    for k in fine:
        assert fine[k] < coarse[k] / 4, spreads


MASS_DROP = """
name = "mass_on_beam"
t_end = 2.5e-3
[scheme]
name = "monolithic"
rtol = 1e-11
atol = 1e-14
[subsystems.beam]
type = "beam"
length = 1.0
youngs_modulus = 210e9
density = 7850.0
section = {{ width = 0.04, height = 0.01 }}
elements = {elements}
left = "pinned"
right = "pinned"
origin = [0.0, 0.0]
axis = [1.0, 0.0]
direction = [0.0, 1.0]
points = {{ under = 0.45 }}
modes = {{ count = 12 }}
[subsystems.drop]
type = "multibody"
integrator = {{ method = "rk4", max_step = 1e-6 }}
[subsystems.drop.bodies.mass]
mass = 0.2
points = {{ tip = [0.0, 0.0] }}
[subsystems.drop.bodies.mass.joint]
name = "y"
type = "prismatic"
parent = "ground"
axis = [0.0, 1.0]
offset = [0.45, 0.0]
q0 = 1e-4
dq0 = -1.0
[contacts.C]
a = "drop.tip"
b = "beam.under"
normal = [0.0, 1.0]
law = {{ type = "linear", contact_stiffness = 1.6e6 }}
"""


def test_a_point_mass_dropped_on_the_beam_meets_the_continuum(tmp_path):
    """0.2 kg at 1 m/s on x0 = 0.45 m (no node of 16, 32 or 64 elements),
    spring 1.6e6 N/m, no gravity, 12 modes on both sides: the FE beam's first
    contact against the exact solution of the mass and 12 continuum modes
    (`cosim.studies.analytic.mass_on_pinned_beam`: 1.02171 ms, 0.294397 mm, and the
    mass leaves upwards at 0.523661 m/s).  The FE modes converge to the
    continuum's at O(h^4), and so does the contact.  Measured relative errors
    (duration, peak, rebound velocity): 16 elements 1.9e-4, 1.2e-4, 1.5e-4;
    32: 3.8e-5, 4.6e-5, 3.5e-5; 64: 8.7e-7, 5.5e-7, 6.7e-7; fitted rate 3.9
    for each.  (128 elements: 1.5e-7, 1.8e-7, 1.4e-7, where the reference
    run's own tolerance and the sampled velocity take over.)  With the
    continuum's 28 modes in place of 12 the contact lasts 0.17 % longer: the
    modes are what the mesh cannot supply by refinement alone."""
    ref = mass_on_pinned_beam(0.2, 1.6e6, 1.0, 0.45, L, EI, RHO_A, 12)
    errs = []
    for n in (16, 32, 64):
        p = tmp_path / f"drop{n}.toml"
        p.write_text(MASS_DROP.format(elements=n))
        res = cosim.simulate(cosim.load_scene(p), estimate=False)
        assert res.success, res.message
        c = res.summary["contacts"]["C"]
        t_on, t_off = c["intervals"][0]
        v = float(np.interp(t_off, res.t, res.series["dq/drop/y"]))
        errs.append([abs((t_off - t_on) / ref["duration"] - 1),
                     abs(c["peak_penetration"] / ref["peak_penetration"] - 1),
                     abs(v / ref["rebound_velocity"] - 1)])
    errs = np.array(errs)
    h = np.array([1 / 16, 1 / 32, 1 / 64])
    for j, name in enumerate(("duration", "peak", "rebound")):
        slope = np.polyfit(np.log(h), np.log(errs[:, j]), 1)[0]
        assert abs(slope - 4.0) < 0.5, f"{name}: observed rate {slope:.2f}, errors {errs[:, j]}"
    assert np.all(errs[-1] < 2e-6), errs
    assert np.all(errs[1] < 1e-4), errs


def test_the_closed_form_tends_to_a_rigid_support_as_the_beam_stiffens():
    """A beam 1e6 times stiffer is a wall: the contact lasts pi sqrt(m/k) and
    the mass leaves at its approach speed (observed 2.3e-5, 3e-8 off; the
    peak sqrt(m/k) v0 2.3e-5 off)."""
    r = mass_on_pinned_beam(0.2, 1.6e6, 1.0, 0.45, L, 1e6 * EI, RHO_A, 12)
    assert r["duration"] == pytest.approx(math.pi * math.sqrt(0.2 / 1.6e6), rel=1e-3)
    assert r["rebound_velocity"] == pytest.approx(1.0, rel=1e-6)
    assert r["peak_penetration"] == pytest.approx(math.sqrt(0.2 / 1.6e6), rel=1e-3)

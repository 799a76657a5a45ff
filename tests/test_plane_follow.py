"""A contact that follows a plane body's boundary (``follow = true``): the
port slides to the point of the deformed boundary closest to the striking
point (node-to-segment over the closed chain of the mesh's boundary
facets), across corners onto the next segment, with the normal of the
deformed boundary there; the force acts along that normal, so sliding does
no work that no spring stores and the ledger closes.

The body: the steel square [0, 0.1 m]^2 (P2, 8 x 8 squares cut in two),
held on its left and bottom sides.  A 1 kg mass on two prismatic joints
(x, then y: no constraint force along the boundary) strikes its top face
near the top-right corner at (5, -1) m/s and slides off over the corner.
"""
import numpy as np
import pytest

import cosim
from cosim.scene.load import SceneError
from plane_files import spy_kernels, write_msh

L = 0.1
SCENE = """\
name = "corner_slide"
t_end = {t_end}

[scheme]
name = "{scheme}"
{scheme_options}

[subsystems.plate]
type = "plane"
mesh = "square.msh"
thickness = 0.01
youngs_modulus = 210e9
poisson_ratio = 0.3
density = 7850.0
supports = {{ fixed = ["left", "bottom"] }}
points = {{ on_top = {{ boundary = "top", s = {s} }} }}
modes = {{ count = 12 }}
integrator = {{ contact_step = 1e-7 }}

[subsystems.slider]
type = "multibody"
integrator = {{ method = "rk4", max_step = 1e-6 }}

[subsystems.slider.bodies.frame]
mass = 0.0
joint = {{ name = "x", type = "prismatic", parent = "ground", axis = [1.0, 0.0], q0 = {x0}, dq0 = {vx} }}

[subsystems.slider.bodies.mass]
mass = 1.0
points = {{ P = [0.0, 0.0] }}
joint = {{ name = "y", type = "prismatic", parent = "frame", axis = [0.0, 1.0], q0 = {y0}, dq0 = -1.0 }}

[contacts.C]
a = "slider.P"
b = "plate.on_top"
normal = [0.0, 1.0]
offset = {offset}
follow = true
law = {{ type = "linear", contact_stiffness = 1e6 }}
placement = "{placement}"
"""
MONOLITHIC = 'rtol = 1e-10\natol = 1e-13'
#: a ball of radius 2 mm rolls over the corner (the vertex's fan, outside);
#: a bare point cuts the corner inside, where the closest face changes
BALL = dict(offset=0.002, x0=0.094, y0=0.1025, vx=5.0, s=0.094)
POINT = dict(offset=0.0, x0=0.0988, y0=0.1002, vx=1.0, s=0.0988)


def _scene(tmp_path, scheme="monolithic", options=MONOLITHIC, placement="coupler",
           t_end=0.0017, **kw):
    from fem.plane import quad_region
    mesh = quad_region([(0.0, 0.0), (L, 0.0), (L, L), (0.0, L)], 8, 8)
    write_msh(tmp_path / "square.msh", mesh)
    path = tmp_path / "corner.toml"
    path.write_text(SCENE.format(scheme=scheme, scheme_options=options, placement=placement,
                                 t_end=t_end, **{**BALL, **kw}))
    return path


def _slide(path, overrides=()):
    """Run ``path`` and return its result."""
    res = cosim.simulate(cosim.load_scene(path, overrides=list(overrides)), estimate=False)
    assert res.success, res.message
    return res


def _replayed(path, res):
    """The recorded run's loaded instants (force over a tenth of its peak)
    projected again on the deformed boundary from the recorded modal
    coordinates and striking point: per instant the loop's arc length, the
    normal's angle [deg] and the penetration (the offset less the distance),
    with the recorded gaps there."""
    from fem.plane.boundary import BoundaryLoop
    system, _ = cosim.load_scene(path).build()
    plate = system.subsystems[system.names.index("plate")]
    loop = BoundaryLoop(plate.structure, "top", plate.port_coordinates[0][1])
    loop.set_modes(plate.Phi)
    f = np.asarray(res.series["force/C"])
    on = np.flatnonzero(f > 0.1 * f.max())
    Q = np.column_stack([res.series[f"q/plate/mode{i + 1}"] for i in range(plate.n_modes)])
    P = np.column_stack([res.series["q/slider/x"], res.series["q/slider/y"]])
    offset = system.links[0].contact.offset
    out = []
    for j in on:
        k, xi, n, g = loop.project(P[j], Q[j])
        out.append((loop.coordinate(k, xi), np.degrees(np.arctan2(n[1], n[0])), offset - g))
    return np.array(out), np.asarray(res.series["gap/C"])[on]


@pytest.mark.parametrize("case", ["ball", "point"])
def test_the_ledger_closes_while_a_loaded_contact_slides_over_a_corner(tmp_path, case):
    """Monolithic reference (DOP853, rtol 1e-10): the energy drifts by less
    than 1e-9 of the spring's largest energy (measured about 1e-12 J of
    0.2 J) while the loaded contact slides along the top face and over the
    corner: the ball's normal turns by more than 30 degrees about the
    vertex, the bare point's jumps to the right face's inside the body.
    The recorded gap is the signed distance of the striking point to the
    deformed boundary less the offset, found again from the records."""
    kw = BALL if case == "ball" else POINT
    path = _scene(tmp_path, **kw)
    res = _slide(path)
    c = res.summary["contacts"]["C"]
    assert c["count"] == 1
    spring = 0.5 * 1e6 * c["peak_penetration"] ** 2
    assert spring > 0.05                                      # loaded: over 0.05 J
    e = res.summary["energy"]
    assert e["max_abs_drift"] <= 1e-9 * spring, (e, spring)
    replay, gap = _replayed(path, res)
    # the recorded gap is minus the penetration
    np.testing.assert_allclose(replay[:, 2], -gap, rtol=0, atol=1e-9 * c["peak_penetration"])
    # the loop starts at the start of the port's segment, the top face's
    # last (from x = 0.0875 m): the corner is 12.5 mm along it
    corner = L - 0.0875
    assert replay[0, 1] == pytest.approx(90.0, abs=1.0) and replay[0, 0] < corner
    if case == "ball":                    # rolls on the vertex
        assert np.min(replay[:, 1]) < 60.0
        assert np.max(replay[:, 0]) == pytest.approx(corner, abs=1e-12)
    else:                                 # the right face's, past the corner
        assert np.min(replay[:, 1]) == pytest.approx(0.0, abs=1.0)
        assert np.max(replay[:, 0]) > corner


def test_the_ledger_test_sees_a_force_off_the_deformed_normal(tmp_path, monkeypatch):
    """The same slide with the force along the boundary's reference normal
    instead of the deformed one (the closest point kept): the energy drifts
    by over 1e3 times the bound above (measured 2.9e-6 J against 1.2e-10 J
    for the bare point, 3.4e-5 J for the ball)."""
    from fem.plane.boundary import BoundaryLoop
    monkeypatch.setattr(BoundaryLoop, "tangent_normal", lambda self, k, tangent: self.normals[k])
    res = _slide(_scene(tmp_path, **POINT))
    spring = 0.5 * 1e6 * res.summary["contacts"]["C"]["peak_penetration"] ** 2
    assert res.summary["energy"]["max_abs_drift"] > 1e3 * 1e-9 * spring


def _corner_state(tmp_path, element="P2"):
    """The square's boundary loop from the top face's last segment, with a
    random deformation in the modes' span (displacements up to 1e-2 of a
    segment)."""
    from fem.plane.boundary import BoundaryLoop
    path = _scene(tmp_path)
    path.write_text(path.read_text().replace("thickness =", f'element = "{element}"\nthickness ='))
    system, _ = cosim.load_scene(path).build()
    plate = system.subsystems[system.names.index("plate")]
    loop = BoundaryLoop(plate.structure, "top", 0.094)
    loop.set_modes(plate.Phi)
    # a random nodal field's projection on the modes: the same deformation
    # whichever basis ARPACK returns (signs, degenerate pairs)
    u0 = np.random.default_rng(7).standard_normal(plate.Phi.shape[0])
    q = np.linalg.lstsq(plate.Phi, u0, rcond=None)[0]
    u = plate.Phi @ q
    return loop, q * (1.25e-4 / np.max(np.abs(u)))


def _gradient_errors(loop, q, points, h=1e-9):
    """Per point: how far the gap's gradients in the point and in the modal
    coordinates (central differences) are from what the forces apply,
    ``n`` on the point and ``-n . (the material point's modal rows)`` on the
    body, relative to their sizes."""
    out = []
    for p in points:
        k, xi, n, g = loop.project(p, q)
        dp = [(loop.project(p + h * e, q)[3] - loop.project(p - h * e, q)[3]) / (2 * h)
              for e in np.eye(2)]
        rows = n @ loop.modal_rows(k, xi)
        dq = [(loop.project(p, q + hq * e)[3] - loop.project(p, q - hq * e)[3]) / (2 * hq)
              for e, hq in zip(np.eye(q.size), 1e-3 * np.abs(q) + 1e-12)]
        out.append((np.max(np.abs(np.array(dp) - n)),
                    np.max(np.abs(np.array(dq) + rows)) / np.max(np.abs(rows))))
    return np.array(out)


@pytest.mark.parametrize("element", ["P2", "P1"])
def test_the_gap_is_a_potential_whose_gradients_are_the_forces(tmp_path, monkeypatch, element):
    """Why the ledger closes, point by point around the corner (0.1, 0.1):
    the gap's gradient in the striking point is the normal the force acts
    along, and in the modal coordinates minus the row the body's force acts
    through (within 1e-6, measured 2e-7: central differences), on the top
    face, in the corner's fan outside, inside near the bisector and on the
    right face, for P2's parabolic segments and P1's straight ones;
    and along a path round the corner the gap never moves faster than the
    point (a distance is 1-Lipschitz: no jump when the closest point
    crosses onto the next segment).  With the force along the reference
    normal the q-gradient is off by over 1e-4, a hundred times the bound
    (the boundary's slopes: 2e-3 on P2, 9e-4 on P1 here); with
    the segment's normal kept at the vertex the gap jumps on the path by
    over 0.1 mm (a run with it stalls on the jump: it did not finish in
    150 s)."""
    from fem.plane.boundary import BoundaryLoop
    loop, q = _corner_state(tmp_path, element)
    assert loop.quadratic == (element == "P2")      # a parabola, or straight segments
    points = np.array([(0.097, 0.1003), (0.1015, 0.1012), (0.1004, 0.1021), (0.0994, 0.0990),
                       (0.0991, 0.0993), (0.1008, 0.097), (0.0962, 0.0999)])
    err = _gradient_errors(loop, q, points)
    assert np.all(err < 1e-6), err
    angle = np.linspace(-0.6, 2.2, 2001)       # round the corner at 2 mm, and through it
    path = np.c_[L + 0.002 * np.cos(angle), L + 0.002 * np.sin(angle)]
    path = np.concatenate([path, np.c_[np.linspace(0.1005, 0.0985, 2001),
                                       np.linspace(0.0985, 0.1005, 2001)]])
    gaps = np.array([loop.project(p, q)[3] for p in path])
    steps = np.hypot(*np.diff(path, axis=0).T)
    assert np.all(np.abs(np.diff(gaps)) <= steps * (1 + 1e-9))
    monkeypatch.setattr(BoundaryLoop, "tangent_normal", lambda self, k, tangent: self.normals[k])
    assert np.max(_gradient_errors(loop, q, points)[:, 1]) > 1e-4
    monkeypatch.undo()
    monkeypatch.setattr(BoundaryLoop, "vertex_normal", lambda self, k, xi, diff: self.normals[k])
    gaps = np.array([loop.project(p, q)[3] for p in path])
    assert np.max(np.abs(np.diff(gaps)) - steps) > 1e-4


def _cosim(tmp_path, macro_step, kernel, monkeypatch):
    monkeypatch.setenv("COSIM_KERNEL", kernel)
    path = _scene(tmp_path, scheme="gauss_seidel", options=f"macro_step = {macro_step}",
                  placement="embedded")
    return _slide(path)


def test_compiled_and_numpy_kernels_agree_on_the_hosted_slide(tmp_path, monkeypatch):
    """Co-simulated (gauss_seidel; the contact hosted by the plate, its port
    and normal moved between macro steps), the compiled structure step
    takes the turning normal (``set_normal``) and the moving row, and agrees
    with the numpy reference: contact times to 1e-9 s, every series within
    1e-10 of its largest value (measured 6e-12; not bit-equal, the two sum
    in other orders)."""
    built = spy_kernels(monkeypatch)
    fast = _cosim(tmp_path, 1e-5, "compiled", monkeypatch)
    assert built and all(k is not None for k in built)
    ref = _cosim(tmp_path, 1e-5, "numpy", monkeypatch)
    c = ref.summary["contacts"]["C"]
    assert c["count"] == 1
    np.testing.assert_allclose(np.ravel(fast.summary["contacts"]["C"]["intervals"]),
                               np.ravel(c["intervals"]), rtol=0, atol=1e-9)
    assert set(fast.series) == set(ref.series)
    for key in ref.series:
        a, b = np.asarray(ref.series[key]), np.asarray(fast.series[key])
        assert np.max(np.abs(a - b)) <= 1e-10 * max(float(np.max(np.abs(a))), 1e-300), key


def test_the_cosimulated_slide_drifts_at_first_order_in_the_macro_step(tmp_path, monkeypatch):
    """Between macro steps the port and its normal stand still while the
    ball rolls on (5 m/s, 50 um a step at 10 us), so co-simulated the
    energy drifts, as a beam's following contact does; the drift halves with
    the macro step (measured 0.0113, 0.0057, 0.0029 J at 10, 5, 2.5 us:
    ratios within 2 +- 0.1), so it is the scheme's, not the contact's."""
    drift = [abs(_cosim(tmp_path, h, "compiled", monkeypatch).summary["energy"]["max_abs_drift"])
             for h in (1e-5, 5e-6, 2.5e-6)]
    assert drift[0] < 1e-3 * 13.0
    ratios = np.array(drift[:-1]) / np.array(drift[1:])
    assert np.all(np.abs(ratios - 2.0) < 0.1), (drift, ratios)


# ---------------------------------------------------------------------------
# The key, checked like every key
# ---------------------------------------------------------------------------
def _refused(path, key, *words, build=True):
    with pytest.raises(SceneError) as info:
        scene = cosim.load_scene(path)
        if build:
            scene.build()
    msg = str(info.value)
    assert str(path) in msg and key in msg, msg
    for w in words:
        assert w in msg, msg


def _edit(path, old, new):
    text = path.read_text()
    assert old in text
    path.write_text(text.replace(old, new))
    return path


def test_a_bad_follow_on_a_plane_body_is_refused_naming_the_file_and_key(tmp_path):
    path = _scene(tmp_path)
    _edit(path, "follow = true", 'follow = "yes"')
    _refused(path, "contacts.C.follow", "true or false", build=False)
    path = _edit(_scene(tmp_path), "normal = [0.0, 1.0]", "normal = [1.0, 0.0]")
    _refused(path, "contacts.C.normal", "outward normal of the boundary at `plate.on_top`",
             "[0, 1]", "got [1, 0]")
    path = _edit(_scene(tmp_path), "count = 12 }", "count = 12, static_correction = true }")
    # the correction follows the port per macro step: not under the monolithic
    # scheme, which moves the port at every evaluation (co-simulated it runs:
    # tests/test_plane_follow_correction.py)
    _refused(path, "contacts.C.follow", "static_correction", "monolithic scheme",
             "co-simulation scheme", "turn the correction off")
    path = _edit(_scene(tmp_path), '{ boundary = "top", s = 0.094 }', '{ boundary = "top" }')
    _refused(path, "contacts.C.follow", "average of the group `top`", "give it an arc length")


def test_a_boundary_that_touches_itself_is_refused_for_a_following_point(tmp_path):
    """Two squares sharing one corner: that vertex lies on four boundary
    segments, so the loop a point slides along is not one chain."""
    from fem.plane import PlaneMesh
    pts = [(0, 0), (0.1, 0), (0.1, 0.1), (0, 0.1), (0.2, 0.1), (0.2, 0.2), (0.1, 0.2)]
    mesh = PlaneMesh(np.array(pts, float), np.array([(0, 1, 2), (0, 2, 3), (2, 4, 5), (2, 5, 6)]),
                     "triangle", {"top": [(3, 2)], "left": [(0, 3)], "bottom": [(0, 1)]})
    path = _edit(_scene(tmp_path), "s = 0.094", "s = 0.05")
    write_msh(tmp_path / "square.msh", mesh)
    _refused(path, "contacts.C.follow", "square.msh", "touches itself at a vertex")


def test_a_following_contact_on_a_plane_body_is_hosted_by_it(tmp_path):
    """Embedded between two moving sides, a following contact is hosted by
    the plane body (b), as on a beam; hosted by the striker it is refused."""
    path = _scene(tmp_path, scheme="gauss_seidel", options="macro_step = 1e-5",
                  placement="embedded")
    system, _ = cosim.load_scene(path).build()
    assert system.links[0].host == system.names.index("plate")
    _edit(path, 'placement = "embedded"', 'placement = "embedded"\nhost = "slider"')
    _refused(path, "contacts.C.host", "must be 'plate'", build=False)

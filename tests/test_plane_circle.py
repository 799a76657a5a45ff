"""A circle pressed into a plane body, its penalty spread over the boundary
inside it (fem.plane.circle): the force is the energy's gradient, the
tangent is the force's, and a rigid cylinder pressed into a block reaches
Johnson's Hertz pressure, converging with the mesh (unlike a point
contact, whose compliance grows at every halving: Flamant)."""
import functools

import numpy as np
import pytest
from scipy.sparse.linalg import spsolve

import fem
from documented import Claim, assert_printed, assert_reproduced
from fem.plane import Plane, grid, rectangle
from fem.plane.circle import CircleContact, hertz_cylinder

S = "docs/structures.md"
STEEL = dict(thickness=0.01, youngs_modulus=210e9, poisson_ratio=0.3, density=7850.0)
E_STAR = STEEL["youngs_modulus"] / (1 - STEEL["poisson_ratio"] ** 2)


def _plate(element="P2", fixed="bottom"):
    return Plane(rectangle(0.2, 0.1, 16, 8), fixed=fixed, **STEEL, element=element).assemble()


def _pressed(st, radius=0.05, depth=3e-3):
    """A centre over the top face's middle ``depth`` into the body, and a
    field with some of everything."""
    rng = np.random.default_rng(3)
    u = 1e-5 * rng.standard_normal(st.n_dof)
    return np.array([0.1, 0.05 + radius - depth]), u


@pytest.mark.parametrize("element", ["P1", "P2", "Q2"])
def test_the_force_is_minus_the_energys_gradient(element):
    kind = "quad" if element.startswith("Q") else "triangle"
    st = Plane(rectangle(0.2, 0.1, 16, 8, kind), fixed="bottom", **STEEL,
               element=element).assemble()
    cc = CircleContact(st, 0.05, 1e13)
    c, u = _pressed(st)
    energy, force, on_circle = cc.evaluate(u, c)
    assert energy > 0 and np.count_nonzero(cc.penetration(u, c) > 0) > 8
    h = 1e-9                        # a central difference, O(h^2) off the kink
    rng = np.random.default_rng(5)
    for _ in range(4):
        d = rng.standard_normal(st.n_dof)
        fd = (cc.evaluate(u + h * d, c)[0] - cc.evaluate(u - h * d, c)[0]) / (2 * h)
        assert abs(-fd - force @ d) < 1e-8 * np.abs(force).sum() * np.abs(d).max()  # 3e-10
    for i in range(2):              # the circle's force is -dV/dc
        e = np.zeros(2)
        e[i] = h
        fd = (cc.evaluate(u, c + e)[0] - cc.evaluate(u, c - e)[0]) / (2 * h)
        assert abs(-fd - on_circle[i]) < 1e-8 * np.abs(on_circle).sum()
    assert on_circle[1] > 0         # the body pushes the circle out


def test_the_tangent_is_the_forces_gradient():
    st = _plate()
    cc = CircleContact(st, 0.05, 1e13)
    c, u = _pressed(st)
    k_t = cc.stiffness_matrix(u, c)
    rng = np.random.default_rng(7)
    d = rng.standard_normal(st.n_dof)
    h = 1e-10
    fd = -(cc.evaluate(u + h * d, c)[1] - cc.evaluate(u - h * d, c)[1]) / (2 * h)
    assert np.max(np.abs(fd - k_t @ d)) < 1e-5 * np.max(np.abs(k_t @ d))
    # symmetric, and positive semi-definite here (shallow: g << |x - c|)
    dense = k_t.toarray()
    assert np.max(np.abs(dense - dense.T)) < 1e-12 * np.max(np.abs(dense))


def test_the_modal_contact_is_the_full_one_projected():
    """With a basis, the coordinates are modal: the energy is the full
    contact's at ``u = Phi q``, the force ``Phi^T f``."""
    st = _plate()
    basis = fem.modes(st, n_modes=12)
    full = CircleContact(st, 0.05, 1e13)
    modal = CircleContact(st, 0.05, 1e13, basis=basis.shapes)
    c, _ = _pressed(st)
    q = 1e-4 * np.random.default_rng(1).standard_normal(12)
    e_full, f_full, r_full = full.evaluate(basis.shapes @ q, c)
    e_mod, f_mod, r_mod = modal.evaluate(q, c)
    scale = np.abs(basis.shapes.T @ f_full).max()
    assert abs(e_mod / e_full - 1) < 1e-12          # the same sums in another order
    assert np.max(np.abs(f_mod - basis.shapes.T @ f_full)) < 1e-12 * scale
    assert np.max(np.abs(r_mod - r_full)) < 1e-12 * np.abs(r_full).max()
    k_mod = modal.stiffness_matrix(q, c)
    k_ref = basis.shapes.T @ (full.stiffness_matrix(basis.shapes @ q, c) @ basis.shapes)
    assert np.max(np.abs(k_mod - k_ref)) < 1e-10 * np.abs(k_ref).max()


def test_a_circle_clear_of_the_body_does_nothing():
    st = _plate()
    cc = CircleContact(st, 0.05, 1e13, groups=["top"])
    energy, force, on_circle = cc.evaluate(np.zeros(st.n_dof), [0.1, 0.05 + 0.05 + 1e-9])
    assert energy == 0.0 and not force.any() and not on_circle.any()


@pytest.mark.parametrize("kw, match", [
    (dict(radius=0.0), "`radius` must be > 0 m"),
    (dict(radius=np.inf), "`radius` must be > 0 m"),
    (dict(stiffness=-1.0), "`stiffness` must be > 0 Pa/m"),
    (dict(gauss=0), "`gauss` must be an integer"),
    (dict(parts=0), "`parts` must be an integer >= 1"),
])
def test_bad_parameters_are_refused(kw, match):
    st = _plate()
    args = {"radius": 0.05, "stiffness": 1e13, **kw}
    with pytest.raises(ValueError, match=match):
        CircleContact(st, **args)


def test_a_graded_grid_keeps_its_coordinates_and_groups():
    mesh = grid([0.0, 0.1, 0.3], [-0.2, -0.05, 0.0], "quad")
    assert sorted(set(mesh.points[:, 0])) == [0.0, 0.1, 0.3]
    assert sorted(set(mesh.points[mesh.group("top").ravel(), 1])) == [0.0]
    with pytest.raises(ValueError, match="must be increasing"):
        grid([0.0, 0.0, 1.0], [0.0, 1.0])


# -------------------------------------------------------- Johnson's cylinder
RADIUS, DEPTH = 0.1, 2.1e-5          # the cylinder, and how far its centre is pushed down


def _graded(h: float, inner: float, outer: float, ratio: float = 1.25) -> np.ndarray:
    """0, h, 2h, ... to ``inner``, then growing by ``ratio`` to ``outer``."""
    xs = list(np.arange(0.0, inner + 0.5 * h, h))
    step = h
    while xs[-1] < outer:
        step *= ratio
        xs.append(xs[-1] + step)
    return np.array(xs)


@functools.lru_cache(maxsize=None)
def _press(h: float, alpha: float = 1e3):
    """A block 40 mm wide and 20 mm deep (clamped below, plane strain, Q2)
    meshed at ``h`` under the contact and graded away from it, pressed by a
    rigid cylinder of radius 0.1 m whose centre is ``DEPTH`` below the
    touching height; the static penalty problem solved by Newton on the
    full system.  The penalty is ``alpha E* / (1 mm)`` (the half-width is
    about 1 mm).  Returns the load per length [N/m], the pressure under the
    centre [Pa], the second-moment half-width [m], Newton's iterations."""
    xs = _graded(h, 1.5e-3, 20e-3)
    mesh = grid(np.concatenate([-xs[::-1], xs[1:]]), -_graded(h, 1.5e-3, 20e-3)[::-1], "quad")
    st = Plane(mesh, fixed="bottom", model="plane_strain", element="Q2", **STEEL).assemble()
    k = alpha * E_STAR / 1e-3
    cc = CircleContact(st, RADIUS, k, groups=["top"])
    centre = np.array([0.0, RADIUS - DEPTH])
    stiff = st.stiffness.tocsc()
    u = np.zeros(st.n_dof)
    for it in range(60):
        _, f, _ = cc.evaluate(u, centre)
        du = spsolve((stiff + cc.stiffness_matrix(u, centre)).tocsc(), f - stiff @ u)
        u += du
        if np.abs(du).max() < 1e-12 * np.abs(u).max():
            break
    else:
        raise AssertionError("Newton did not converge")
    _, _, on_circle = cc.evaluate(u, centre)
    top = np.flatnonzero(np.all(np.abs(mesh.points) < 1e-15, axis=1))[0]   # under the centre
    x0 = mesh.points[top] + st.nodal_displacement(u)[top]
    p_centre = k * (RADIUS - np.hypot(*(x0 - centre)))
    p = cc.pressure(u, centre) * cc.weights
    x = cc.points[:, 0]
    half_width = 2.0 * np.sqrt((p * x ** 2).sum() / p.sum())   # Hertz: <x^2> = a^2 / 4
    return on_circle[1] / STEEL["thickness"], p_centre, half_width, it


def test_a_cylinder_pressed_into_a_block_reaches_johnsons_p0():
    """12.5 elements across the contact: the pressure under the centre within
    1 % of Johnson's p0 for the load the block carries (measured -3.5e-4),
    the half-width within 1 % of Hertz's (measured +1.3e-3)."""
    load, p_centre, half_width, _ = _press(h=2e-3 / 12)
    a, p0 = hertz_cylinder(load, RADIUS, STEEL["youngs_modulus"], STEEL["poisson_ratio"])
    assert 11.5 < 2 * a / (2e-3 / 12) < 13.5
    assert abs(p_centre / p0 - 1) < 1e-2
    assert abs(half_width / a - 1) < 1e-2
    cmd = "pytest tests/test_plane_circle.py"
    for claim, measured in (
            (Claim(S, "graded to 12.5 elements across the contact", cmd, 12.5, abs=0.05),
             2 * a / (2e-3 / 12)),
            (Claim(S, "Hertz pressure p0 for its load within 0.035 %", cmd, 0.035, abs=0.005),
             100 * abs(p_centre / p0 - 1)),
            (Claim(S, "the half-width within 0.13 %", cmd, 0.13, abs=0.005),
             100 * abs(half_width / a - 1))):
        assert_printed(claim)
        assert_reproduced(claim, measured)


def test_the_pressure_converges_with_the_mesh():
    """From 4 to 8 to 12 elements across the contact the error in p0 falls
    from over 1 % to under 1e-3 and stays there (a point contact's
    compliance instead grows by 2 ln 2 / (pi E t) at every halving)."""
    err = []
    for n in (4, 8, 12):
        load, p_centre, _, _ = _press(h=2e-3 / n)
        err.append(p_centre / hertz_cylinder(load, RADIUS, STEEL["youngs_modulus"],
                                             STEEL["poisson_ratio"])[1] - 1)
    assert abs(err[0]) > 1e-2, err
    assert abs(err[1]) < 1e-3 and abs(err[2]) < 1e-3, err
    cmd = "pytest tests/test_plane_circle.py"
    for claim, measured in (
            (Claim(S, "falls from 1.9 % at 4 elements across", cmd, 1.9, abs=0.05), err[0]),
            (Claim(S, "to 0.06 % at 8 and stays there", cmd, 0.06, abs=0.005), err[1])):
        assert_printed(claim)
        assert_reproduced(claim, 100 * abs(measured))


def test_a_stiffer_penalty_leaves_less_winkler_softening():
    """The penalty is a Winkler layer on the body: a soft one spreads the
    contact and lowers the peak; as ``k a / E*`` grows the peak tends to
    Hertz's."""
    err = []
    for alpha in (3.0, 30.0, 300.0):
        load, p_centre, _, _ = _press(h=2e-3 / 8, alpha=alpha)
        err.append(p_centre / hertz_cylinder(load, RADIUS, STEEL["youngs_modulus"],
                                             STEEL["poisson_ratio"])[1] - 1)
    assert err[0] < err[1] < 0 and abs(err[2]) < abs(err[1]) < abs(err[0]), err
    printed = "lowers p0 by 8.7 %, 0.93 % and 0.05 %"
    for value, tol, measured in ((8.7, 0.05, err[0]), (0.93, 0.005, err[1]),
                                 (0.05, 0.005, err[2])):
        claim = Claim(S, printed, "pytest tests/test_plane_circle.py", value, abs=tol)
        assert_printed(claim)
        assert_reproduced(claim, -100 * measured)

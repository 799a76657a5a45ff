"""A rigid circle (a point mass with a radius) striking a plane body reduced
to its modes, its penalty spread over the boundary inside it
(fem.plane.circle with a basis): the energy of mass, modes and penalty is
conserved through a strike and while the loaded circle slides across a
corner, and a small circle is a point contact with the circle's own law on
a flat face.

These integrate the mass and the modes together (scipy's DOP853 at tight
tolerance), not through a scene: they check the force element itself."""
import numpy as np
import pytest
from scipy.integrate import solve_ivp

import fem
from documented import Claim, assert_printed, assert_reproduced
from fem.plane import Plane, PlaneMesh, rectangle
from fem.plane.circle import CircleContact

STEEL = dict(thickness=0.01, youngs_modulus=210e9, poisson_ratio=0.3, density=7850.0)
S, CMD = "docs/structures.md", "pytest tests/test_plane_circle_strike.py"
MASS, K_AREA, H = 0.2, 1e12, 0.04     # [kg], [Pa/m], the strip's height [m]


def _strip(fixed, strike, n_modes):
    """The strip 0.4 m x 0.04 m (P2 on 40 x 4 squares cut in two) with the
    group ``strike``: ``{group: slice}`` of boundary segments the circle may
    touch (a few, so that each evaluation is cheap)."""
    m0 = rectangle(0.4, H, 40, 4)
    pairs = np.concatenate([m0.groups[g][sl] for g, sl in strike.items()])
    mesh = PlaneMesh(m0.points, m0.cells, m0.kind, {**m0.groups, "strike": pairs})
    st = Plane(mesh, fixed=fixed, **STEEL).assemble()
    return st, fem.modes(st, n_modes=n_modes)


def _flat_law(radius: float, depth):
    """The force [N] of the circle's penalty on a rigid flat face it
    penetrates by ``depth``: ``t k int (R - r) (h / r) dx`` with ``h = R -
    depth``, ``r = sqrt(x^2 + h^2)``, over the chord: ``2 t k (R h asinh(X/h)
    - h X)``, ``X = sqrt(R^2 - h^2)``."""
    d = np.clip(depth, 0.0, 0.99 * radius)
    h = radius - d
    x = np.sqrt(radius ** 2 - h ** 2)
    return 2.0 * STEEL["thickness"] * K_AREA * (radius * h * np.arcsinh(x / h) - h * x)


def _strike(st, basis, centre, velocity, radius, point=None, parts=100, t_end=2e-3,
            push=(0.0, 0.0), until_release=True):
    """Integrate the mass (its centre free in the plane, pushed by the
    constant force ``push`` [N]) and the modes from rest; ``point = (group,
    s)`` replaces the circle by a point contact there, along the face's
    normal, with :func:`_flat_law`.  Returns the solution (stopped at the
    release when ``until_release``), the right-hand side and the energy."""
    push = np.asarray(push, dtype=float)
    phi, w2 = basis.shapes, basis.omega ** 2
    n = phi.shape[1]
    if point is None:
        cc = CircleContact(st, radius, K_AREA, basis=phi, groups=["strike"], gauss=2,
                           parts=parts)
    else:
        dofs, w = st.point_operator(point)
        row = w @ phi[dofs]
        normal = st.boundary_point(*point).normal
        surface = st.reference_position(point) @ normal

    def penetration(y):
        q, c = y[:n], y[2 * n:2 * n + 2]
        if point is None:
            return float(cc.penetration(q, c).max())
        return float(surface + row @ q - (c @ normal - radius))

    def split(y):
        return y[:n], y[n:2 * n], y[2 * n:2 * n + 2], y[2 * n + 2:]

    def rhs(_, y):
        q, dq, c, v = split(y)
        if point is None:
            _, f_q, f_c = cc.evaluate(q, c)
        else:
            f = float(_flat_law(radius, penetration(y)))
            f_q, f_c = -f * row, f * normal
        return np.concatenate([dq, f_q - w2 * q, v, (f_c + push) / MASS])

    def energy(y):
        q, dq, c, v = split(y)
        stored = cc.evaluate(q, c)[0] if point is None else np.nan
        return 0.5 * dq @ dq + 0.5 * w2 @ q ** 2 + 0.5 * MASS * v @ v + stored - push @ c

    def touch(_, y):
        return penetration(y)

    def release(_, y):
        return penetration(y)
    touch.direction, release.direction, release.terminal = 1, -1, until_release
    y0 = np.concatenate([np.zeros(2 * n), centre, velocity])
    sol = solve_ivp(rhs, (0.0, t_end), y0, method="DOP853", rtol=1e-9, atol=1e-14,
                    dense_output=True, events=[touch, release])
    return sol, rhs, energy


def _peak_and_duration(sol, rhs):
    t_on, t_off = sol.t_events[0][0], sol.t_events[1][0]
    ts = np.linspace(t_on, t_off, 401)
    force = np.array([np.hypot(*rhs(0.0, y)[-2:]) * MASS for y in sol.sol(ts).T])
    return force.max(), t_off - t_on


def test_a_strike_closes_the_ledger():
    """0.2 kg at 1 m/s, obliquely, on the clamped strip near mid-span: mass,
    modes and penalty keep their energy through the contact (the force is
    the energy's gradient in the modes and in the centre alike)."""
    st, basis = _strip(["left", "right"], {"top": slice(14, 26)}, 20)
    radius = 0.01
    sol, rhs, energy = _strike(st, basis, np.array([0.19, H / 2 + radius + 1e-6]),
                               np.array([0.3, -1.0]), radius, parts=40)
    assert sol.status == 1                          # released
    e = np.array([energy(y) for y in sol.sol(np.linspace(0.0, sol.t[-1], 400)).T])
    q, dq = sol.y[:20, -1], sol.y[20:40, -1]
    modal = 0.5 * dq @ dq + 0.5 * (basis.omega ** 2) @ q ** 2
    assert modal > 0.05 * e[0]                      # the strip took a share
    drift = np.max(np.abs(e - e[0])) / e[0]
    assert drift < 1e-9
    claim = Claim(S, "(measured 5e-10 and 3e-10)", CMD, 5e-10, abs=0.5e-10)
    assert_printed(claim)
    assert_reproduced(claim, drift)


def test_a_loaded_circle_sliding_across_a_corner_closes_the_ledger():
    """The strip held along its bottom: the circle, pressed into the top face
    and pushed down by 1 kN, slides at 3 m/s over the free top corner and
    rolls around it onto the end face; the force on it turns from the top's
    normal to about 49 degrees towards the end's, and mass, modes, penalty
    and the push's potential keep their energy."""
    st, basis = _strip("bottom", {"top": slice(38, 40), "right": slice(2, 4)}, 6)
    radius, push = 0.01, np.array([0.0, -1000.0])
    sol, rhs, energy = _strike(st, basis, np.array([0.395, H / 2 + radius - 5e-5]),
                               np.array([3.0, 0.0]), radius, parts=40, t_end=1e-2, push=push)
    assert sol.status == 1 and sol.y[12, -1] > 0.4          # released past the corner
    ys = sol.sol(np.linspace(0.0, sol.t[-1], 400)).T
    e = np.array([energy(y) for y in ys])
    f = np.array([rhs(0.0, y)[-2:] * MASS - push for y in ys])
    loaded = np.hypot(*f.T) > 0.05 * np.abs(f).max()
    angle = np.degrees(np.arctan2(f[loaded, 0], f[loaded, 1]))
    assert angle.min() < 1.0 and angle.max() > 40.0, (angle.min(), angle.max())
    drift = np.max(np.abs(e - e[0])) / np.abs(e).max()
    assert drift < 1e-9
    claim = Claim(S, "(measured 5e-10 and 3e-10)", CMD, 3e-10, abs=0.5e-10)
    assert_printed(claim)
    assert_reproduced(claim, drift)


def test_a_small_circle_is_a_point_contact_with_its_own_law():
    """A circle of 16 mm (its contact about 3 mm wide, under a third of a
    segment) against the point contact at its centre's foot with the
    circle's law on a flat face: the same peak force and duration within
    1e-3 (quadrature and sampling)."""
    st, basis = _strip(["left", "right"], {"top": slice(17, 23)}, 20)
    radius, out = 0.0156, []
    for point in (None, ("top", 0.2)):
        sol, rhs, _ = _strike(st, basis, np.array([0.2, H / 2 + radius + 1e-6]),
                              np.array([0.0, -1.0]), radius, point=point)
        out.append(_peak_and_duration(sol, rhs))
    (p_c, d_c), (p_p, d_p) = out
    assert abs(p_c / p_p - 1) < 1e-3 and abs(d_c / d_p - 1) < 1e-3, (p_c / p_p - 1,
                                                                      d_c / d_p - 1)
    for value, measured in ((3e-4, p_c / p_p - 1), (2e-4, d_c / d_p - 1)):
        claim = Claim(S, "within 1e-3 (measured 3e-4 and 2e-4;", CMD, value, abs=0.5e-4)
        assert_printed(claim)
        assert_reproduced(claim, abs(measured))


@pytest.mark.slow
def test_the_circle_tends_to_the_point_contact_as_it_shrinks():
    """Radii 1 m, 0.25 m, 62.5 mm on the strip with 40 modes: the peak
    force's difference from the point contact with the circle's law falls
    about fourfold per quartering of the radius (as the contact's width
    squared), from over 3e-3 to under 1e-3."""
    st, basis = _strip(["left", "right"], {"top": slice(14, 26)}, 40)
    diff = []
    for radius in (1.0, 0.25, 0.0625):
        out = []
        for point in (None, ("top", 0.2)):
            sol, rhs, _ = _strike(st, basis, np.array([0.2, H / 2 + radius + 1e-6]),
                                  np.array([0.0, -1.0]), radius, point=point)
            out.append(_peak_and_duration(sol, rhs)[0])
        diff.append(out[0] / out[1] - 1)
    assert diff[0] > 3e-3 and abs(diff[2]) < 1e-3, diff
    assert diff[0] > 2.5 * diff[1] > 0, diff

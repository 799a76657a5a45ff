"""A plane body's natural frequencies against sharp references: the clamped
strip (Timoshenko and the converged 2-D values, with the observed rate of
convergence), NAFEMS FV32, cosim's own P1 rod on the same nodes, and Love's
lateral-inertia correction of the rod."""
import numpy as np
import pytest

import fem
from fem.plane import Plane, lame, quad_region, rectangle

STEEL = dict(youngs_modulus=210e9, poisson_ratio=0.3, density=7850.0)


def _strip(nx, ny, kind="triangle", element="P2", fixed="left", **kw):
    material = {**STEEL, **kw}
    return Plane(rectangle(1.0, 0.1, nx, ny, kind), thickness=0.01, element=element,
                 fixed=fixed, **material).assemble()


def test_the_clamped_strip_converges_to_timoshenko_at_the_singular_corners_rate():
    """Plane stress, 1 m x 0.1 m, left edge clamped.  Reference values (issue
    38): Timoshenko with kappa = 5/6 gives 82.894 and 496.815 Hz, the 2-D
    limit (Richardson to 320 x 32) 82.990 and 497.85 Hz.  The clamped
    corners are singular, so P2 converges at about h^1.5 rather than h^4:
    the limit is extrapolated with the rate the three meshes show."""
    f = np.array([fem.natural_frequencies(_strip(20 * k, 2 * k), 2) for k in (1, 2, 4)])
    timoshenko, converged = np.array([82.894, 496.815]), np.array([82.990, 497.85])
    assert np.all(np.abs(f[-1] / timoshenko - 1) < 3e-3)
    assert np.all(np.abs(f[-1] / converged - 1) < 1e-3)
    assert np.all(np.diff(f, axis=0) < 0)                  # from above, monotonically
    rate = np.log2((f[0] - f[1]) / (f[1] - f[2]))
    assert np.all((1.2 < rate) & (rate < 2.5)), rate       # not 4: the corners' singularity
    limit = f[2] - (f[1] - f[2]) / (2.0 ** rate - 1.0)
    assert np.all(np.abs(limit / converged - 1) < 2e-4), limit


def test_p1_locks_in_bending_where_p2_does_not():
    p1 = fem.natural_frequencies(_strip(40, 4, element="P1"), 1)[0]
    p2 = fem.natural_frequencies(_strip(40, 4), 1)[0]
    assert p1 / 82.990 - 1 > 1e-2 > 5 * (p2 / 82.990 - 1)


@pytest.mark.parametrize("element, kind, tol", [("P2", "triangle", 1e-3), ("Q2", "quad", 1e-4)])
def test_nafems_fv32_tapered_membrane(element, kind, tol):
    """NAFEMS FV32 (Abbassian, Dawswell, Knowles, *Selected Benchmarks for
    Natural Frequency Analysis*, NAFEMS 1987, test 32): a cantilevered
    membrane tapering from 5 m to 1 m over 10 m, E 200 GPa, nu 0.3,
    rho 8000 kg/m^3, plane stress, the 5 m edge fixed, on 16 x 8 cells."""
    mesh = quad_region([(0, 0), (10, 2), (10, 3), (0, 5)], 16, 8, kind)
    st = Plane(mesh, thickness=0.05, youngs_modulus=200e9, poisson_ratio=0.3, density=8000.0,
               element=element, fixed="left").assemble()
    f = fem.natural_frequencies(st, 6)
    ref = np.array([44.623, 130.03, 162.70, 246.05, 379.90, 391.44])
    assert np.all(np.abs(f / ref - 1) < tol), f / ref - 1


def _axial(basis, structure):
    """Frequencies of the modes whose kinetic energy is over 90 % axial."""
    out = []
    for k in np.flatnonzero(basis.omega > 0):
        phi = basis.shapes[:, k]
        x = np.where(np.arange(phi.size) % 2 == 0, phi, 0.0)
        if x @ (structure.mass @ x) > 0.9:
            out.append(basis.frequencies_hz[k])
    return np.array(out)


def test_a_q1_strip_with_nu_0_has_the_frequencies_of_the_p1_rod_on_its_nodes():
    """With nu = 0 the axial motion of a Q1 strip is its columns moving as
    one: the stiffness and consistent mass of cosim's P1 rod on the same
    nodes, so its frequencies are the rod's up to the eigen-solvers'
    round-off (a few 1e-15 relative, bounded at 1e-12)."""
    nx, ny = 20, 2
    st = _strip(nx, ny, kind="quad", element="Q1", poisson_ratio=0.0)
    rod = fem.Rod(1.0, 210e9, 7850.0, 1e-3, nx, left="fixed", right="free")
    f_rod = fem.modes(rod).frequencies_hz
    plane = fem.modes(st)
    # the rod's modes: no lateral motion, every column of nodes moving as one
    ux = st.nodal_displacement(plane.shapes.T)[..., 0].reshape(-1, nx + 1, ny + 1)
    uy = st.nodal_displacement(plane.shapes.T)[..., 1]
    size = np.abs(ux).max(axis=(1, 2))
    columns = np.ptp(ux, axis=2).max(axis=1) < 1e-9 * size
    lateral = np.abs(uy).max(axis=1) < 1e-9 * size
    f_2d = plane.frequencies_hz[columns & lateral]
    assert f_2d.size == f_rod.size == nx
    assert np.all(np.abs(f_2d / f_rod - 1) < 1e-12)


def test_loves_correction_of_the_free_strip():
    """A free-free strip with nu = 0.3: its axial frequencies fall below the
    rod's (nu = 0) by Love's lateral inertia, nu^2 n^2 pi^2 H^2 / (24 L^2)
    (radius of gyration H / sqrt(12)); the next term of the expansion is
    O((n H / L)^2) relative to it, so the ratio departs from 1 as n^2."""
    def axial(nu):
        st = _strip(40, 4, kind="quad", element="Q2", fixed=(), poisson_ratio=nu)
        basis = fem.modes(st, n_modes=20)
        assert basis.n_rigid == 3                        # two translations, one rotation
        assert np.all(basis.omega[:3] == 0) and basis.omega[3] > 0
        return _axial(basis, st)[:3]

    shift = 1.0 - axial(0.3) / axial(0.0)
    n = np.arange(1, 4)
    love = 0.3 ** 2 * n ** 2 * np.pi ** 2 * 0.1 ** 2 / 24.0
    ratio = shift / love
    assert abs(ratio[0] - 1) < 0.015
    excess = (ratio - 1) / n ** 2
    assert np.all(np.abs(excess / excess[0] - 1) < 0.15), ratio


def test_plane_strain_is_plane_stress_with_the_stiffer_lame_constant():
    lam_s, mu = lame(210e9, 0.3, "plane_stress")
    lam_e, mu_e = lame(210e9, 0.3, "plane_strain")
    assert mu == mu_e and lam_e > lam_s
    # plane stress with E* = E/(1 - nu^2), nu* = nu/(1 - nu) is plane strain
    e_star, nu_star = 210e9 / (1 - 0.09), 0.3 / 0.7
    a = fem.natural_frequencies(_strip(10, 2, model="plane_strain"), 3)
    b = fem.natural_frequencies(_strip(10, 2, youngs_modulus=e_star,
                                       poisson_ratio=nu_star), 3)
    assert np.allclose(a, b, rtol=1e-10)


def test_placement_rotates_the_body_not_its_frequencies():
    mesh = rectangle(1.0, 0.1, 10, 2)
    a = Plane(mesh, thickness=0.01, fixed="left", **STEEL).assemble()
    b = Plane(mesh, thickness=0.01, fixed="left", origin=(2.0, 1.0), angle=np.pi / 2,
              **STEEL).assemble()
    assert np.allclose(fem.natural_frequencies(a, 3), fem.natural_frequencies(b, 3),
                       rtol=1e-10)
    pt = b.boundary_point("top", 0.5)              # the top side now faces -x
    assert np.allclose(pt.position, [2.0 - 0.05, 1.5]) and np.allclose(pt.normal, [-1, 0])
    assert np.allclose(b.nodes()[0], [2.05, 1.0])

"""Structural models (chain, beam, string, rod) and their modal analysis against
closed forms: Blevins, "Formulas for natural frequency and mode shape" (1979);
Timoshenko, Young & Weaver, "Vibration problems in engineering" (1974)."""
import subprocess
import sys

import numpy as np
import pytest
from scipy.optimize import brentq

from fem.beam import Beam, String, rectangular_section
from fem.chain import Chain
from fem.modal import modes, natural_frequencies, residual_compliance
from fem.rod import Rod

# Scene 6 (beam_impact): steel, 40 mm x 10 mm.
L, E, RHO = 1.0, 210e9, 7850.0
SEC = rectangular_section(0.04, 0.01)
EI, RHOA = E * SEC.second_moment, RHO * SEC.area


def beam(n, left="pinned", right="pinned", **kw):
    return Beam(L, E, SEC.second_moment, RHO, SEC.area, n, left, right, **kw).assemble()


def clamped_free_roots(k):
    """beta_n L of cos(x) cosh(x) = -1, i.e. cos(x) + 1/cosh(x) = 0."""
    f = lambda x: np.cos(x) + 1.0 / np.cosh(x)  # noqa: E731
    return np.array([brentq(f, (n - 0.5) * np.pi - 0.6, (n - 0.5) * np.pi + 0.5, xtol=1e-15)
                     for n in range(1, k + 1)])


def p1_dispersion(k, h, c):
    """Exact eigenfrequency of consistent-mass P1 elements for wave number k."""
    return c / h * np.sqrt(6 * (1 - np.cos(k * h)) / (2 + np.cos(k * h)))


def slope(h, err):
    return np.polyfit(np.log(h), np.log(err), 1)[0]


def test_clamped_free_roots_match_blevins_table():
    assert np.allclose(clamped_free_roots(5), [1.8751, 4.6941, 7.8548, 10.9955, 14.1372],
                       atol=6e-5)


@pytest.mark.parametrize("ends,beta_l", [
    (("pinned", "pinned"), np.pi * np.arange(1, 6)),
    (("clamped", "free"), clamped_free_roots(5)),
])
def test_beam_frequencies_converge_at_order_four(ends, beta_l):
    exact = beta_l ** 2 / L ** 2 * np.sqrt(EI / RHOA)
    ns = np.array([10, 20, 40, 80])
    err = [np.max(np.abs(modes(beam(n, *ends), n_modes=5).omega / exact - 1)) for n in ns]
    p = slope(L / ns, err)
    assert abs(p - 4) < 0.3, f"Hermite frequency error slope {p:.3f}, expected 4"
    assert err[-1] < 3e-6, f"finest-mesh relative error {err[-1]:.2e}"


def test_string_frequencies_exact_discrete_and_order_two():
    T, rho, area, n_modes = 500.0, 7850.0, 1e-5, 5
    c = np.sqrt(T / (rho * area))
    k = np.pi * np.arange(1, n_modes + 1) / L
    ns = np.array([10, 20, 40, 80])
    err = []
    for n in ns:
        w = modes(String(L, T, rho, area, n), n_modes=n_modes).omega
        assert np.allclose(w, p1_dispersion(k, L / n, c), rtol=1e-10)
        err.append(np.max(np.abs(w / (k * c) - 1)))
    p = slope(L / ns, err)
    assert abs(p - 2) < 0.3, f"P1 string frequency error slope {p:.3f}, expected 2"
    assert err[-1] < 1.3 * (5 * np.pi / 80) ** 2 / 24, f"finest error {err[-1]:.2e}"


def test_tensioned_pinned_beam_matches_axial_load_formula():
    # Scene 7 cable: span 4 m, T = 2000 N, 10 mm steel rope, E = 100e9 Pa.
    span, T, d = 4.0, 2000.0, 0.01
    area, inertia = np.pi * d ** 2 / 4, np.pi * d ** 4 / 64
    cable = Beam(span, 100e9, inertia, 7850.0, area, 40, "pinned", "pinned", tension=T)
    k = np.pi * np.arange(1, 4) / span
    exact = np.sqrt((k ** 4 * 100e9 * inertia + k ** 2 * T) / (7850.0 * area))
    assert np.allclose(modes(cable, n_modes=3).omega, exact, rtol=1e-6)
    string_f1 = np.sqrt(T / (7850.0 * area)) / (2 * span)    # bending adds a little
    assert 1 < natural_frequencies(cable, 1)[0] / string_f1 < 1.01


def test_rod_free_free_sparse_and_fixed_free_dense():
    c = np.sqrt(E / RHO)
    rod = Rod(L, E, RHO, 1e-4, 600).assemble()               # 601 DOFs: sparse path
    basis = modes(rod, n_modes=5)
    k = np.pi * np.arange(1, 5) / L
    assert basis.n_rigid == 1 and basis.omega[0] == 0.0
    assert np.allclose(basis.omega[1:], p1_dispersion(k, L / 600, c), rtol=1e-9)
    assert np.allclose(basis.omega[1:], k * c, rtol=1e-4)
    assert np.allclose(basis.shapes[:, 0], basis.shapes[0, 0])  # rigid translation
    assert modes(Rod(L, E, RHO, 1e-4, 50), n_modes=2).omega[0] == 0.0  # dense path too
    fixed = Rod(L, E, RHO, 1e-4, 200, left="fixed").assemble()  # 200 DOFs: dense path
    k = (2 * np.arange(1, 5) - 1) * np.pi / (2 * L)
    w = modes(fixed, n_modes=4).omega
    assert np.allclose(w, p1_dispersion(k, L / 200, c), rtol=1e-9)
    assert np.allclose(w, k * c, rtol=3e-4)
    with pytest.raises(ValueError, match="1 rigid-body mode"):
        rod.static_displacement(np.zeros(rod.n_dof))


def point_load_deflection(x, a, P):
    """Pinned-pinned beam, point load P at a (Timoshenko, Strength of Materials)."""
    b = L - a
    y = L - x
    w = np.where(x <= a, P * b * x * (L ** 2 - b ** 2 - x ** 2),
                 P * a * y * (L ** 2 - a ** 2 - y ** 2)) / (6 * EI * L)
    dw = np.where(x <= a, P * b * (L ** 2 - b ** 2 - 3 * x ** 2),
                  -P * a * (L ** 2 - a ** 2 - 3 * y ** 2)) / (6 * EI * L)
    return w, dw


def test_point_load_at_non_nodal_position():
    # The exact deflection is cubic between nodes in every element but the
    # loaded one (its w''' jumps at a), and Hermite Galerkin is nodally exact
    # (nodal Green's functions lie in the FE space): so w_h equals the exact
    # w outside the loaded element and its Hermite interpolant inside it.
    s, a, P = beam(10), 0.437, 1e3
    u = s.static_displacement(s.point_load(a, P))
    at = lambda op, x: [op(xi)[1] @ u[op(xi)[0]] for xi in x]  # noqa: E731
    w_max = point_load_deflection(np.array([a]), a, P)[0][0]
    x = np.array([0.0, 0.123, 0.25, 0.3, 0.5, 0.66, 0.91, 1.0])
    w, dw = point_load_deflection(x, a, P)
    assert np.allclose(at(s.point_operator, x), w, rtol=0, atol=1e-10 * w_max)
    assert np.allclose(at(s.slope_operator, x), dw, rtol=0, atol=1e-10 * w_max / L)
    x = np.array([0.41, 0.437, 0.48])                          # inside [0.4, 0.5]
    (w0, w1), (t0, t1) = point_load_deflection(np.array([0.4, 0.5]), a, P)
    xi, h = (x - 0.4) / 0.1, 0.1
    hermite = (w0 * (1 - 3 * xi ** 2 + 2 * xi ** 3) + t0 * h * (xi - 2 * xi ** 2 + xi ** 3)
               + w1 * (3 * xi ** 2 - 2 * xi ** 3) + t1 * h * (xi ** 3 - xi ** 2))
    assert np.allclose(at(s.point_operator, x), hermite, rtol=0, atol=1e-10 * w_max)
    assert abs(at(s.point_operator, [a])[0] - w_max) > 1e-6 * w_max   # not exact there


def test_gravity_load_and_self_weight_deflection():
    s = beam(8)
    f = s.gravity_load((0.0, -9.81))
    mid = s.point_operator(0.5)
    w_mid = mid[1] @ s.static_displacement(f)[mid[0]]
    exact = -5 * RHOA * 9.81 * L ** 4 / (384 * EI)           # nodal: exact
    assert w_mid == pytest.approx(exact, rel=1e-10)
    free = beam(8, "free", "free")
    total = free.gravity_load((3.0, -9.81))[list(free.dof_map[:, 0])].sum()
    assert total == pytest.approx(-RHOA * L * 9.81, rel=1e-12)
    assert free.rigid_body_modes().shape == (free.n_dof, 2)
    assert beam(8, "sliding", "free").rigid_body_modes().shape[1] == 1
    guided = modes(beam(20, "sliding", "pinned"), n_modes=1).omega[0]   # beta L = pi/2
    assert guided == pytest.approx((np.pi / 2 / L) ** 2 * np.sqrt(EI / RHOA), rel=1e-7)


def test_point_operator_reproduces_cubic_and_matches_skfem_probes():
    import skfem

    s = beam(7, "free", "free")
    x = s.node_coordinates
    cubic = lambda t: 2 - 3 * t + 5 * t ** 2 - 4 * t ** 3  # noqa: E731
    dcubic = lambda t: -3 + 10 * t - 12 * t ** 2  # noqa: E731
    u = np.zeros(s.n_dof)
    u[s.dof_map[:, 0]], u[s.dof_map[:, 1]] = cubic(x), dcubic(x)
    pts = np.random.default_rng(0).uniform(0, L, 25)
    for p in pts:
        dofs, weights = s.point_operator(p)
        assert weights @ u[dofs] == pytest.approx(cubic(p), abs=1e-13)
        dofs, weights = s.slope_operator(p)
        assert weights @ u[dofs] == pytest.approx(dcubic(p), abs=1e-12)
    basis = skfem.Basis(skfem.MeshLine(x), skfem.ElementLineHermite())
    probes = basis.probes(pts[None, :]).toarray()
    ours = np.array([s.point_load(p, 1.0) for p in pts])
    assert np.allclose(ours, probes, atol=1e-14)
    # Virtual work: the consistent load does P w(s) of work on any u.
    v = np.random.default_rng(1).normal(size=s.n_dof)
    dofs, weights = s.point_operator(0.3)
    assert s.point_load(0.3, 7.5) @ v == pytest.approx(7.5 * weights @ v[dofs], rel=1e-14)


def test_pinned_end_drops_constrained_weights_and_exports_nodes():
    s = beam(4, rayleigh=(2.0, 1e-5))
    dofs, weights = s.point_operator(0.1)                       # element 0: w0 pinned
    assert len(dofs) == 3 and s.dof_names[0] == "t0"
    assert np.allclose(s.nodes(), np.c_[np.linspace(0, L, 5), np.zeros(5)])
    u = np.arange(1.0, s.n_dof + 1)
    assert np.allclose(s.nodal_displacement(u), [0, u[1], u[3], u[5], 0])
    assert np.allclose(s.nodal_displacement(np.vstack([u, u])).shape, (2, 5))
    assert abs(s.damping - (2.0 * s.mass + 1e-5 * s.stiffness)).max() == 0
    assert beam(4).damping is None
    assert np.allclose(s.position(0.5, u), [0.5, u[3]])


M3, K3 = (0.15, 0.3, 0.45), (1.6e5, 2e5, 3e5)


def test_chain_matches_hand_built_matrices_and_gravity():
    s = Chain(M3, K3, spacing=0.05).assemble()
    k1, k2, k3 = K3
    K = np.array([[k1, -k1, 0], [-k1, k1 + k2, -k2], [0, -k2, k2 + k3]])
    assert np.array_equal(s.stiffness, K)
    assert np.array_equal(s.mass, np.diag(M3))
    lam = np.linalg.eigh(np.diag(np.sqrt(1 / np.array(M3))) @ K
                         @ np.diag(np.sqrt(1 / np.array(M3))))[0]
    assert np.allclose(modes(s).omega, np.sqrt(lam), rtol=1e-12)
    g = 9.81
    u3 = -sum(M3) * g / k3                 # the ground spring carries everything
    u2 = u3 - (M3[0] + M3[1]) * g / k2
    u1 = u2 - M3[0] * g / k1
    u = s.static_displacement(s.gravity_load((0.0, -g)))
    assert np.allclose(u, [u1, u2, u3], rtol=1e-12)
    assert s.dof_names == ("m1", "m2", "m3")
    assert np.allclose(s.nodes(), [[0, 0], [0, -0.05], [0, -0.1]])
    hang = Chain(M3, K3, ground_below=False, positions=[[0, 1], [0, .5], [0, 0]]).assemble()
    assert np.array_equal(hang.stiffness,
                          [[k1 + k2, -k2, 0], [-k2, k2 + k3, -k3], [0, -k3, k3]])
    assert np.allclose(hang.position(2, [0, 0, 0.01]), [0, 0.01])


def test_chain_and_unassembled_models_do_not_import_skfem():
    code = ("import sys, fem.chain, fem.modal, fem.beam, fem.rod;"
            "fem.modal.modes(fem.chain.Chain((1.0, 2.0), (3.0, 4.0), spacing=1.0));"
            "fem.beam.Beam(1, 1, 1, 1, 1, 2, 'pinned', 'free');"
            "bad = [m for m in ('skfem', 'meshio') if m in sys.modules];"
            "assert not bad, bad")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr


def test_modal_basis_is_mass_normalised_and_cutoff_exact():
    s = beam(30, "clamped", "pinned")
    full = modes(s)
    phi, w = full.shapes, full.omega
    assert np.allclose(phi.T @ (s.mass @ phi), np.eye(s.n_dof), atol=1e-10)
    assert np.allclose(phi.T @ (s.stiffness @ phi), np.diag(w ** 2), atol=1e-9 * w[-1] ** 2)
    cut = 0.5 * (full.frequencies_hz[6] + full.frequencies_hz[7])
    part = modes(s, cutoff_hz=cut)
    assert (part.kept, part.dropped, part.cutoff_hz) == (7, s.n_dof - 7, cut)
    assert np.allclose(part.omega, w[:7], rtol=1e-12)
    assert np.allclose(np.abs(part.shapes), np.abs(phi[:, :7]), atol=1e-8)
    # Static correction: the dropped modes' compliance at a point.
    b = s.point_load(0.45, 1.0)
    dropped = np.sum((phi[:, 7:].T @ b) ** 2 / w[7:] ** 2)
    assert residual_compliance(s, part, 0.45) == pytest.approx(dropped, rel=1e-6)
    # complete basis: zero up to the round-off of a solve with K, whose
    # condition number is (omega_max / omega_min)^2 (observed 1.0e-10 of the
    # total compliance with (omega_max / omega_min)^2 = 8.6e6)
    kappa = (w[-1] / w[0]) ** 2
    assert abs(residual_compliance(s, full, 0.45)) < \
        10 * np.finfo(float).eps * kappa * (b @ s.static_displacement(b))


def test_sparse_path_agrees_with_dense_and_cutoff():
    s = beam(250, "clamped", "free")                          # 500 DOFs
    exact = clamped_free_roots(6) ** 2 * np.sqrt(EI / RHOA) / L ** 2
    basis = modes(s, n_modes=6)
    assert np.allclose(basis.omega, exact, rtol=1e-7)
    phi = basis.shapes
    assert np.allclose(phi.T @ (s.mass @ phi), np.eye(6), atol=1e-10)
    part = modes(s, cutoff_hz=exact[4] / (2 * np.pi) * 1.01)    # doubling search
    assert part.kept == 5 and part.dropped == s.n_dof - 5
    rod = Rod(L, E, RHO, 1e-4, 500, axis=(0, -1))              # free-free, sparse
    f1 = np.sqrt(E / RHO) / (2 * L)
    part = modes(rod, cutoff_hz=2.5 * f1)
    assert part.kept == 3 and part.n_rigid == 1
    assert np.allclose(part.frequencies_hz, [0, f1, 2 * f1], rtol=1e-5)


def bad(factory, kwargs):
    return lambda: factory(**kwargs)


BEAM = dict(length=L, youngs_modulus=E, second_moment=1e-9, density=RHO, area=1e-4,
            n_elements=4, left="pinned", right="pinned")
ROD = dict(length=L, youngs_modulus=E, density=RHO, area=1e-4, n_elements=4)


@pytest.mark.parametrize("call,message", [
    (bad(Beam, {**BEAM, "length": -1.0}), r"`length` must be > 0 m, got -1\.0"),
    (bad(Beam, {**BEAM, "left": "fixed"}),
     r"`left` must be one of 'clamped', 'free', 'pinned', 'sliding', got 'fixed'"),
    (bad(Beam, {**BEAM, "tension": -5.0}), r"`tension` must be >= 0 N, got -5\.0"),
    (bad(Beam, {**BEAM, "n_elements": 0}), r"`n_elements` must be an integer >= 1, got 0"),
    (bad(Beam, {**BEAM, "direction": (1, 0)}), r"`direction` must be perpendicular"),
    (bad(Beam, {**BEAM, "rayleigh": (-1, 0)}), r"`rayleigh` must be a pair"),
    (bad(String, dict(length=L, tension=0.0, density=RHO, area=1e-4, n_elements=4)),
     r"`tension` must be > 0 N, got 0\.0"),
    (bad(Rod, {**ROD, "right": "pinned"}), r"`right` must be one of 'fixed', 'free'"),
    (lambda: Rod(**{**ROD, "n_elements": 1}, left="fixed", right="fixed").assemble(),
     r"`n_elements` must leave a free DOF"),
    (bad(Chain, dict(masses=(1, 1), stiffnesses=(1,), spacing=1)),
     r"`stiffnesses` must have one entry per mass \(2\), got 1"),
    (bad(Chain, dict(masses=(1, -2), stiffnesses=(1, 1), spacing=1)),
     r"`masses\[1\]` must be > 0 kg, got -2"),
    (bad(Chain, dict(masses=(1,), stiffnesses=(1,))), r"give exactly one of `spacing`"),
    (lambda: modes(Chain((1,), (1,), spacing=1), n_modes=0),
     r"`n_modes` must be an integer >= 1, got 0"),
    (lambda: modes(Chain((1,), (1,), spacing=1), cutoff_hz=-1.0),
     r"`cutoff_hz` must be > 0 Hz, got -1\.0"),
    (lambda: Chain((1,), (1,), spacing=1).assemble().point_operator(0.5),
     r"`s` must be a mass index in 0\.\.0, got 0\.5"),
    (lambda: Rod(**ROD).assemble().point_operator(1.5), r"`s` must be in \[0, 1\.0\] m"),
])
def test_invalid_parameters_raise(call, message):
    with pytest.raises(ValueError, match=message):
        call()

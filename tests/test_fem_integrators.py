"""Structural integrators (fem.integrators): order, exactness, energy, stability."""
import math
from types import SimpleNamespace

import numpy as np
import pytest
import scipy.linalg as sla
import scipy.sparse as sp

from fem.integrators import (STRUCTURAL_INTEGRATORS, CentralDifference, ExactModal,
                             GeneralizedAlpha, HHTAlpha, Newmark, get_structural_integrator)

STEPPERS = [n for n, c in STRUCTURAL_INTEGRATORS.items() if not math.isinf(c.order)]

# two masses [kg], springs ground-1 200 N/m and 1-2 100 N/m; omega = 5.60, 17.85 rad/s
M2 = np.diag([1.0, 2.0])
K2 = np.array([[300.0, -100.0], [-100.0, 100.0]])
C2 = 0.05 * M2 + 2e-3 * K2                                  # Rayleigh [N s/m]


def oscillator(omega, zeta, q0, v0, c, t):
    """(q, q') at t of q'' + 2 zeta omega q' + omega^2 q = c0 + c1 t + c2 t^2."""
    d = 2 * zeta * omega
    w2 = omega * omega
    p2 = c[2] / w2
    p1 = (c[1] - 2 * d * p2) / w2
    p0 = (c[0] - d * p1 - 2 * p2) / w2
    A, B = q0 - p0, v0 - p1                                 # homogeneous part at 0
    if zeta == 1:
        lam = -omega
        qh = np.exp(lam * t) * (A + (B - lam * A) * t)
        vh = np.exp(lam * t) * (lam * A + (B - lam * A) * (1 + lam * t))
    else:
        r = np.sqrt(complex(zeta * zeta - 1))
        l1, l2 = omega * (-zeta + r), omega * (-zeta - r)
        a1 = (B - l2 * A) / (l1 - l2)
        a2 = A - a1
        qh = (a1 * np.exp(l1 * t) + a2 * np.exp(l2 * t)).real
        vh = (a1 * l1 * np.exp(l1 * t) + a2 * l2 * np.exp(l2 * t)).real
    return qh + p0 + p1 * t + p2 * t * t, vh + p1 + 2 * p2 * t


def local_load(c, t, h):
    """Coefficients in s = (t' - t)/h of c0 + c1 t' + c2 t'^2 over [t, t + h]."""
    return np.array([[c[0] + c[1] * t + c[2] * t * t], [(c[1] + 2 * c[2] * t) * h],
                     [c[2] * h * h]])


def run_single(integ, omega, zeta, c, q0, v0, t_end, n):
    h = t_end / n
    u, v = np.array([q0]), np.array([v0])
    a = integ.initial_acceleration(u, v, np.array([c[0]]))
    for k in range(n):
        u, v, a = integ.step(u, v, a, h, local_load(c, k * h, h))
    return u[0], v[0]


# (zeta, load coefficients, error ceiling at h = 5 ms).  Observed slopes 1.993-2.001;
# errors at 5 ms: free 1.8e-4 (central difference) .. 4.0e-4 (HHT), damped 4.5e-5 .. 9.7e-5
CONV = [(0.0, (0.0, 0.0, 0.0), 6e-4), (0.1, (1.0, -2.0, 3.0), 1.5e-4)]


@pytest.mark.parametrize("name", STEPPERS)
@pytest.mark.parametrize("zeta,c,ceiling", CONV, ids=["free", "damped_loaded"])
def test_order_on_a_single_mode(name, zeta, c, ceiling):
    """h = 40, 20, 10, 5 ms over 2 s of omega = 2 pi; error in (u, v / omega)."""
    omega, t_end = 2 * np.pi, 2.0
    cls = STRUCTURAL_INTEGRATORS[name]
    integ = cls(np.eye(1), np.array([[2 * zeta * omega]]), np.array([[omega ** 2]]))
    qr, vr = oscillator(omega, zeta, 0.3, -1.0, c, t_end)
    ns = np.array([50, 100, 200, 400])
    errs = [math.hypot(q - qr, (v - vr) / omega)
            for q, v in (run_single(integ, omega, zeta, c, 0.3, -1.0, t_end, n) for n in ns)]
    slope = np.polyfit(np.log(t_end / ns), np.log(errs), 1)[0]
    assert abs(slope - cls.order) < 0.15, f"{name}: observed order {slope:.3f}, errors {errs}"
    assert errs[-1] < ceiling, f"{name}: error {errs[-1]:.2e} at h = 5 ms"


@pytest.mark.parametrize("zeta", [0.0, 0.05, 1.0, 2.5])
@pytest.mark.parametrize("degree", [0, 1, 2])
@pytest.mark.parametrize("n", [2000, 7, 1])
def test_exact_scheme_matches_the_closed_form(zeta, degree, n):
    """Any h: 2.5 ms to 5 s (omega h up to 15), under- to over-damped."""
    omega, t_end = 3.0, 5.0
    c = (2.0, -0.7, 0.3)[:degree + 1] + (0.0,) * (2 - degree)
    integ = ExactModal(np.eye(1) * 1.0, np.array([[2 * zeta * omega]]), np.array([[9.0]]))
    q, v = run_single(integ, omega, zeta, c, 0.4, 1.1, t_end, n)
    qr, vr = oscillator(omega, zeta, 0.4, 1.1, c, t_end)
    err = math.hypot(q - qr, (v - vr) / omega) / math.hypot(qr, vr / omega)
    assert err < 1e-12, f"relative error {err:.2e}"


def test_exact_scheme_moves_rigid_body_modes_exactly():
    """A free mass and a free-free pair under constant loads: u = F t^2 / (2 m)."""
    one = ExactModal(np.array([[2.0]]), None, np.zeros((1, 1)))
    u, v, a = np.zeros(1), np.zeros(1), np.zeros(1)
    for h in (0.37, 1.0, 5.0):
        u, v, a = one.step(u, v, a, h, [[3.0]])
    t = 6.37
    assert u[0] == pytest.approx(3.0 * t * t / 4.0, rel=1e-13)
    assert v[0] == pytest.approx(3.0 * t / 2.0, rel=1e-13)
    pair = ExactModal(np.diag([1.0, 3.0]), None, np.array([[50.0, -50.0], [-50.0, 50.0]]))
    assert pair.omega[0] == 0.0
    u, v, a = np.zeros(2), np.zeros(2), np.zeros(2)
    for _ in range(10):
        u, v, a = pair.step(u, v, a, 0.25, [[8.0, 0.0]])
    assert (u @ [1.0, 3.0]) / 4.0 == pytest.approx(8.0 * 2.5 ** 2 / 8.0, rel=1e-12)


def test_exact_scheme_on_a_damped_chain_against_expm():
    """100 random steps and random quadratic loads on three masses; reference:
    expm of the augmented first-order system [u, v, 1, s, s^2] per step."""
    rng = np.random.default_rng(7)
    M = np.diag([1.0, 2.0, 1.5])
    K = np.array([[150.0, -50.0, 0.0], [-50.0, 130.0, -80.0], [0.0, -80.0, 80.0]])
    C = 0.1 * M + 1e-3 * K
    integ = ExactModal(M, C, K)
    Minv = np.linalg.inv(M)
    u, v = rng.normal(size=3), rng.normal(size=3)
    a = integ.initial_acceleration(u, v, np.zeros(3))
    z = np.concatenate([u, v])
    for _ in range(100):
        h, F = rng.uniform(0.01, 0.5), rng.normal(size=(3, 3))
        u, v, a = integ.step(u, v, a, h, F)
        A = np.zeros((9, 9))
        A[:3, 3:6] = h * np.eye(3)
        A[3:6, :3], A[3:6, 3:6], A[3:6, 6:] = -h * Minv @ K, -h * Minv @ C, h * Minv @ F.T
        A[7, 6], A[8, 7] = 1.0, 2.0
        z = (sla.expm(A) @ np.concatenate([z, [1.0, 0.0, 0.0]]))[:6]
    assert np.abs(np.concatenate([u, v]) - z).max() < 1e-9 * np.abs(z).max()


def test_truncated_basis_and_modal_state():
    """Modal reduction keeps a mode-1 motion exact; to_modal/from_modal round-trip."""
    full = ExactModal(M2, C2, K2)
    low = ExactModal(M2, C2, K2, n_modes=1)
    assert low.omega.shape == (1,) and low.omega[0] == pytest.approx(full.omega[0])
    cut = ExactModal(M2, C2, K2, basis=(full.omega, full.Phi), cutoff=10.0)
    np.testing.assert_allclose(cut.Phi, low.Phi)
    duck = ExactModal(M2, C2, K2, basis=SimpleNamespace(omega=low.omega, shapes=low.Phi))
    np.testing.assert_array_equal(duck.omega, low.omega)
    u, v = 0.01 * full.Phi[:, 0], 0.2 * full.Phi[:, 0]
    np.testing.assert_allclose(full.from_modal(*full.to_modal(u, v))[0], u, rtol=1e-13)
    ur, vr, _ = low.step(u, v, None, 0.3, np.zeros((1, 2)))
    uf, vf, _ = full.step(u, v, None, 0.3, np.zeros((1, 2)))
    np.testing.assert_allclose(np.r_[ur, vr], np.r_[uf, vf], atol=1e-14)
    q, dq = low.to_modal(u, v)
    q1, dq1 = low.step_modal(q, dq, 0.3, np.zeros((1, 1)))
    np.testing.assert_allclose(low.from_modal(q1, dq1)[0], uf, atol=1e-14)


# Undamped 2-DOF free vibration, 10^4 steps of h = 0.1 * (2 pi / omega_max) = 35 ms
H_E = 0.1 * 2 * np.pi / 17.84976376
W2, PHI = sla.eigh(K2, M2)


def free_run(integ, n=10_000):
    u, v = np.array([1.0, -0.5]), np.array([0.3, 2.0])
    a = integ.initial_acceleration(u, v, np.zeros(2))
    zero = np.zeros((1, 2))
    hist = [(u, v, a)]
    for _ in range(n):
        u, v, a = integ.step(u, v, a, H_E, zero)
        hist.append((u, v, a))
    U, V, A = (np.array(x) for x in zip(*hist))
    return U, V, A, 0.5 * (np.einsum("ki,ij,kj->k", V, M2, V)
                           + np.einsum("ki,ij,kj->k", U, K2, U))


@pytest.mark.parametrize("cls,opts", [(Newmark, {}), (GeneralizedAlpha, {"rho_inf": 1.0}),
                                      (ExactModal, {})], ids=["newmark", "ga_1", "exact"])
def test_energy_conserving_schemes(cls, opts):
    """Observed drifts: 4e-14 (Newmark), 1.3e-13 (rho_inf = 1), 4e-12 (exact)."""
    e = free_run(cls(M2, None, K2, **opts))[3]
    assert np.abs(e / e[0] - 1).max() < 1e-10


@pytest.mark.parametrize("cls,opts", [(HHTAlpha, {"alpha": -0.1}),
                                      (GeneralizedAlpha, {"rho_inf": 0.5})], ids=["hht", "ga_0.5"])
def test_dissipative_schemes_damp_the_high_mode_first(cls, opts):
    """E(u, v) never exceeds E0 and its envelope over each period of the lowest mode
    never grows.  Step to step it is NOT monotone (the carried acceleration holds
    energy too: increases up to 5e-3 E0 observed), so that is not asserted.
    Observed modal energy ratios after 10^4 steps: 0.74 / 9e-12 (HHT), 0.58 / 2e-20."""
    U, V, _, e = free_run(cls(M2, None, K2, **opts))
    assert e.max() <= e[0] * (1 + 1e-12)
    period = round(2 * np.pi / np.sqrt(W2[0]) / H_E)
    env = e[: e.size // period * period].reshape(-1, period).max(axis=1)
    assert np.all(np.diff(env) <= 1e-12 * e[0])
    q, dq = (np.array([X[k] @ M2 @ PHI for k in (0, -1)]) for X in (U, V))
    modal = 0.5 * (dq ** 2 + W2 * q ** 2)
    ratio = modal[1] / modal[0]
    assert ratio[1] < 1e-3 * ratio[0] and ratio[0] < 1.0, ratio


def test_central_difference_conserves_its_modified_energy():
    """E - (h^2/8) a^T M a is invariant (observed 5e-14); E itself stays within 10 %."""
    _, _, A, e = free_run(CentralDifference(M2, None, K2))
    e_mod = e - H_E ** 2 / 8 * np.einsum("ki,ij,kj->k", A, M2, A)
    assert np.abs(e_mod / e_mod[0] - 1).max() < 1e-10
    assert np.abs(e / e[0] - 1).max() < 0.1


def test_central_difference_stability_limit():
    integ = CentralDifference(M2, C2, K2)
    limit = integ.max_stable_step()
    assert limit == pytest.approx(2 / 17.84976376, rel=1e-6)
    assert Newmark(M2, C2, K2).max_stable_step() == math.inf
    assert Newmark(M2, None, K2, beta=0.0).max_stable_step() == pytest.approx(limit, rel=1e-12)
    u, v = np.array([0.01, 0.0]), np.zeros(2)
    with pytest.raises(ValueError, match=r"`h` = 0\.11316\d* s exceeds the central-difference "
                                         r"stability limit 0\.11204\d* s "
                                         r"\(omega_max = 17\.8498 rad/s\)"):
        integ.step(u, v, np.zeros(2), 1.01 * limit, np.zeros((1, 2)))
    for _ in range(3):
        u, v, _a = integ.step(u, v, np.zeros(2), 0.99 * limit, np.zeros((1, 2)))
    assert np.all(np.isfinite(u))


@pytest.mark.parametrize("name", STRUCTURAL_INTEGRATORS)
def test_operators_are_built_once_per_step_size(name):
    integ = get_structural_integrator(name)(M2, C2, K2)
    u, v, F = np.array([0.01, 0.0]), np.zeros(2), np.ones((3, 2))
    a = integ.initial_acceleration(u, v, F[0])
    for h in (0.01, 0.01, 0.02, 0.01, 0.02):
        u, v, a = integ.step(u, v, a, h, F)
    assert integ.n_factorizations == 2


@pytest.mark.parametrize("name", STRUCTURAL_INTEGRATORS)
def test_sparse_and_dense_matrices_agree(name):
    cls = get_structural_integrator(name)
    dense, sparse = cls(M2, C2, K2), cls(sp.csr_matrix(M2), sp.csr_matrix(C2), sp.csr_matrix(K2))
    x = (np.array([0.01, -0.02]), np.array([0.1, 0.0]), np.zeros(2))
    F = np.array([[1.0, 2.0], [0.5, 0.0]])
    np.testing.assert_allclose(np.concatenate(sparse.step(*x, 0.01, F)),
                               np.concatenate(dense.step(*x, 0.01, F)), rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("cls,opts,match", [
    (Newmark, {"beta": -0.1}, r"`beta` must be >= 0, got -0\.1"),
    (Newmark, {"gamma": 0.4}, r"`gamma` must be >= 1/2, got 0\.4"),
    (HHTAlpha, {"alpha": 0.1}, r"`alpha` must be in \[-1/3, 0\], got 0\.1"),
    (HHTAlpha, {"alpha": -0.5}, r"`alpha` must be in \[-1/3, 0\], got -0\.5"),
    (GeneralizedAlpha, {"rho_inf": 1.5}, r"`rho_inf` must be in \[0, 1\], got 1\.5"),
    (GeneralizedAlpha, {"rho_inf": "1"}, r"`rho_inf` must be a finite real number, got '1'"),
    (ExactModal, {"n_modes": 0}, r"`n_modes` must be an integer in \[1, 2\], got 0"),
    (ExactModal, {"cutoff": 1.0}, r"`cutoff` = 1 rad/s keeps no mode \(lowest omega = 5\.60"),
    (ExactModal, {"basis": (np.ones(2), np.eye(2))}, r"`basis` must be mass-normalised modes"),
])
def test_options_are_checked(cls, opts, match):
    with pytest.raises(ValueError, match=match):
        cls(M2, None, K2, **opts)


def test_bad_inputs_are_refused():
    with pytest.raises(ValueError, match=r"`K` must be shape \(2, 2\) like `M`, "
                                         r"got shape \(3, 3\)"):
        Newmark(M2, None, np.eye(3))
    with pytest.raises(ValueError, match=r"`C` is not modal .*use a time-stepping scheme"):
        ExactModal(M2, np.array([[1.0, 0.0], [0.0, 0.0]]), K2)
    integ = Newmark(M2, None, K2)
    with pytest.raises(ValueError, match=r"`h` must be > 0 s, got -0\.1"):
        integ.step(np.zeros(2), np.zeros(2), np.zeros(2), -0.1, np.zeros((1, 2)))
    with pytest.raises(ValueError, match=r"`F` must have shape \(p \+ 1, 2\) with p <= 2, "
                                         r"got \(4, 2\)"):
        integ.step(np.zeros(2), np.zeros(2), np.zeros(2), 0.1, np.zeros((4, 2)))
    with pytest.raises(ValueError, match=r"unknown structural integrator 'rk4'; valid names are "
                                         r"\['central_difference', 'exact', 'generalized_alpha', "
                                         r"'hht_alpha', 'newmark'\]"):
        get_structural_integrator("rk4")
    assert get_structural_integrator(HHTAlpha) is HHTAlpha

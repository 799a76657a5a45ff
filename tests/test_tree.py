"""Planar tree (multibody.tree): kinematics and dynamics against independent
references built from finite differences of plain loop-based forward kinematics.

Tolerances: first derivatives by central differences with step 1e-6 are good to
~1e-9 relative, so those checks use rtol 1e-6; nested differences (derivatives of
M) use rtol 1e-5; closed forms use 1e-12.
"""
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from multibody.tree import Body, Joint, TreeModel

SEEDS = [0, 1, 2, 3, 4]
G = np.array([0.0, -9.81])
H = 1e-6


def random_tree(seed, n=None, chain=False):
    """1-6 bodies, random parents/kinds/geometry/inertia, one point `p` per body."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 7)) if n is None else n
    bodies, joints = [], []
    for i in range(n):
        parent = i - 1 if chain else int(rng.integers(-1, i))
        kind = "revolute" if rng.random() < 0.6 else "prismatic"
        joints.append(Joint(f"j{i}", kind, parent, rng.uniform(-1, 1, 2), rng.normal(size=2),
                            rng.uniform(-np.pi, np.pi)))
        bodies.append(Body(f"b{i}", rng.uniform(0.5, 3.0), rng.uniform(0.05, 0.5),
                           rng.uniform(-0.5, 0.5, 2), {"p": rng.uniform(-1, 1, 2)}))
    return TreeModel(bodies, joints), rng


def rot(t):
    return np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])


def ref_fk(model, q):
    """Loop-based forward kinematics: absolute angles (n,) and frame origins (n, 2)."""
    n = model.n_dof
    th, org = np.zeros(n), np.zeros((n, 2))
    for i, j in enumerate(model.joints):
        tp, op = (0.0, np.zeros(2)) if j.parent < 0 else (th[j.parent], org[j.parent])
        slide = q[i] * np.array(j.axis) if j.kind == "prismatic" else 0.0
        org[i] = op + rot(tp) @ (np.array(j.offset) + slide)
        th[i] = tp + j.angle + (q[i] if j.kind == "revolute" else 0.0)
    return th, org


def ref_material(model, q, local):
    """World positions (n, 2) of one local point per body (local: (n, 2))."""
    th, org = ref_fk(model, q)
    return np.array([org[b] + rot(th[b]) @ local[b] for b in range(model.n_dof)])


def fd_jac(f, q, h=H):
    """Central-difference Jacobian of f: R^n -> array, stacked on a last axis."""
    cols = []
    for k in range(len(q)):
        e = np.zeros_like(q)
        e[k] = h
        cols.append((f(q + e) - f(q - e)) / (2 * h))
    return np.stack(cols, axis=-1)


def state(model, rng):
    n = model.n_dof
    return rng.uniform(-1.5, 1.5, n), rng.uniform(-2, 2, n)


def close(a, b, rtol):
    """|a - b| <= rtol * max(max|b|, 1): relative to the reference's largest entry
    (all quantities here are O(1) in SI units, so 1 floors a zero reference)."""
    a, b = np.asarray(a), np.asarray(b)
    np.testing.assert_allclose(a, b, rtol=0, atol=rtol * max(np.abs(b).max(), 1.0))


def coms(model):
    return np.array([b.com for b in model.bodies])


def local_points(model):
    return np.array([b.points["p"] for b in model.bodies])


@pytest.mark.parametrize("seed", SEEDS)
def test_frames_match_loop_forward_kinematics(seed):
    model, rng = random_tree(seed)
    q, dq = state(model, rng)
    fr = model.frames(q, dq)
    th, org = ref_fk(model, q)
    close(fr.theta, th, 1e-12)
    close(np.stack((fr.origin.real, fr.origin.imag), -1), org, 1e-12)
    close(fr.omega, fd_jac(lambda x: ref_fk(model, x)[0], q) @ dq, 1e-6)


@pytest.mark.parametrize("seed", SEEDS)
def test_mass_matrix_from_fd_jacobians_of_com_and_angle(seed):
    model, rng = random_tree(seed)
    q, _ = state(model, rng)
    jc = fd_jac(lambda x: ref_material(model, x, coms(model)), q)     # (n, 2, n)
    jw = fd_jac(lambda x: ref_fk(model, x)[0], q)                       # (n, n)
    m_ref = (np.einsum("b,bxi,bxj->ij", model.mass, jc, jc)
             + np.einsum("b,bi,bj->ij", model.inertia, jw, jw))
    M = model.mass_matrix(q)
    close(M, m_ref, 1e-6)
    close(M, M.T, 1e-14)
    assert np.all(np.linalg.eigvalsh(M) > 0)


@pytest.mark.parametrize("seed", SEEDS)
def test_point_jacobian_velocity_and_accel_bias(seed):
    model, rng = random_tree(seed)
    q, dq = state(model, rng)
    body, loc = np.arange(model.n_dof), local_points(model)
    pk = model.points(model.frames(q, dq), dq, body, loc)
    close(pk.position, ref_material(model, q, loc), 1e-12)
    close(pk.jacobian, fd_jac(lambda x: ref_material(model, x, loc), q), 1e-6)
    close(pk.velocity, pk.jacobian @ dq, 1e-12)

    def jdq(eps):   # J(q + eps dq) @ dq, dq held fixed
        x = q + eps * dq
        return model.points(model.frames(x, dq), dq, body, loc).jacobian @ dq
    close(pk.accel_bias, (jdq(H) - jdq(-H)) / (2 * H), 1e-6)

    # second time-difference of positions along q + t dq (independent of J)
    h = 1e-4
    x_of = lambda t: ref_material(model, q + t * dq, loc)
    close(pk.accel_bias, (x_of(h) - 2 * x_of(0) + x_of(-h)) / h**2, 1e-5)

    # dynamics() evaluates the same extra points in its single pass
    *_, extra = model.dynamics(q, dq, G, body, loc)
    for a, b in zip(extra, pk):
        close(a, b, 1e-12)


@pytest.mark.parametrize("seed", SEEDS)
def test_velocity_terms_follow_lagrange_equations(seed):
    model, rng = random_tree(seed)
    q, dq = state(model, rng)
    dM = fd_jac(model.mass_matrix, q)                                  # (n, n, k)
    dMdt = np.einsum("ijk,k->ij", dM, dq)
    f_ref = dMdt @ dq - 0.5 * np.einsum("jki,j,k->i", dM, dq, dq)
    _, M, F, extra = model.dynamics(q, dq)
    assert extra is None
    close(M, model.mass_matrix(q), 1e-14)
    close(F, f_ref, 1e-6)
    # gravity: F_grav - F = dV/dq; the kinetic energy is 1/2 dq^T M dq
    _, _, Fg, _ = model.dynamics(q, dq, G)
    close(Fg - F, fd_jac(lambda x: np.array(model.potential_energy(x, G)), q), 1e-6)
    assert model.potential_energy(q, None) == 0.0
    assert model.kinetic_energy(q, dq) == pytest.approx(0.5 * dq @ M @ dq, rel=1e-12)
    # independent V from the loop kinematics
    v_ref = -np.sum(model.mass * (ref_material(model, q, coms(model)) @ G))
    assert model.potential_energy(q, G) == pytest.approx(v_ref, rel=1e-12, abs=1e-12)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_energy_conserved_for_free_chain_under_gravity(seed):
    model, rng = random_tree(100 + seed, n=3, chain=True)
    q0, dq0 = state(model, rng)
    n = model.n_dof

    def rhs(_, y):
        _, M, F, _ = model.dynamics(y[:n], y[n:], G)
        return np.concatenate((y[n:], np.linalg.solve(M, -F)))

    sol = solve_ivp(rhs, (0.0, 0.5), np.concatenate((q0, dq0)), method="DOP853",
                    rtol=1e-11, atol=1e-12, dense_output=False, t_eval=np.linspace(0, 0.5, 26))
    assert sol.success
    T = np.array([model.kinetic_energy(y[:n], y[n:]) for y in sol.y.T])
    V = np.array([model.potential_energy(y[:n], G) for y in sol.y.T])
    E = T + V
    scale = np.abs(T).max() + np.abs(V).max()   # relative to the energies exchanged
    assert np.ptp(T) > 1e-3 * scale                # something actually moved
    assert np.abs(E - E[0]).max() <= 1e-7 * scale


@pytest.mark.parametrize("m, com", [(2.5, (0.0, 0.0)), (0.7, (0.3, -0.4))])
def test_single_prismatic_body_along_x(m, com):
    model = TreeModel([Body("b", m, 0.2, com)], [Joint("x", "prismatic", axis=(3.0, 0.0))])
    for q, dq in [(0.0, 0.0), (1.3, -2.0)]:
        for g in (None, G):   # gravity is perpendicular to the slide
            _, M, F, _ = model.dynamics(np.array([q]), np.array([dq]), g)
            np.testing.assert_allclose(M, [[m]], rtol=1e-14)
            np.testing.assert_allclose(F, [0.0], atol=1e-14)


@pytest.mark.parametrize("q", [0.0, 0.4, -2.2, np.pi / 2])
def test_revolute_pendulum_closed_form(q):
    # com at (l cos q, l sin q): V = m g l sin q, Q_grav = -dV/dq = -m g l cos q,
    # so F = -Q_grav = m g l cos q (the centripetal acceleration is radial and
    # does no work on the joint, so F does not depend on dq).
    m, l, inertia, g = 1.7, 0.8, 0.05, 9.81
    model = TreeModel([Body("b", m, inertia, (l, 0.0))], [Joint("th", "revolute")])
    for dq in (0.0, 3.0):
        _, M, F, _ = model.dynamics(np.array([q]), np.array([dq]), np.array([0.0, -g]))
        np.testing.assert_allclose(M, [[m * l**2 + inertia]], rtol=1e-12)
        np.testing.assert_allclose(F, [m * g * l * np.cos(q)], rtol=1e-12, atol=1e-12)
        _, _, F0, _ = model.dynamics(np.array([q]), np.array([dq]))
        np.testing.assert_allclose(F0, [0.0], atol=1e-12)


def test_constructor_errors():
    b = [Body("a", 1.0, 0.1), Body("b", 1.0, 0.1)]
    with pytest.raises(ValueError, match="parent"):
        TreeModel(b, [Joint("j0", "revolute"), Joint("j1", "revolute", parent=1)])
    with pytest.raises(ValueError, match="parent"):
        TreeModel(b, [Joint("j0", "revolute", parent=-2), Joint("j1", "revolute")])
    with pytest.raises(ValueError, match="one joint per body"):
        TreeModel(b, [Joint("j0", "revolute")])
    with pytest.raises(ValueError, match="one joint per body"):
        TreeModel([], [])
    with pytest.raises(ValueError, match="kind"):
        Joint("j", "spherical")
    with pytest.raises(ValueError, match="mass"):
        Body("a", -1.0, 0.1)
    with pytest.raises(ValueError, match="inertia"):
        Body("a", 1.0, -0.1)
    with pytest.raises(ValueError, match="names must be unique"):
        TreeModel([Body("a", 1.0, 0.1)] * 2, [Joint("j0", "revolute"), Joint("j1", "revolute")])
    with pytest.raises(ValueError, match="singular"):
        TreeModel([Body("a", 0.0, 0.0, (0.5, 0.0))], [Joint("j", "revolute")])
    # two coaxial revolute joints (massless link between) spin one body: M = I [[1,1],[1,1]]
    with pytest.raises(ValueError, match="singular"):
        TreeModel([Body("a", 0.0, 0.0), Body("b", 1.0, 0.1)],
                  [Joint("j0", "revolute"), Joint("j1", "revolute", 0)])


# ------------------------------------------ cross-check: recursive Newton-Euler
@pytest.mark.parametrize("seed", range(8))
def test_vectorised_dynamics_match_recursive_newton_euler(seed):
    """The ancestor-matrix projection (the integrators' path) against the
    textbook recursion (multibody.recursive), on random trees of both joint
    kinds, with gravity: M, F and forward dynamics solve(M, tau - F)."""
    from multibody.recursive import bias_rnea, inverse_dynamics, mass_matrix_rnea
    tree, rng = random_tree(1000 + seed, n=4 + seed % 3)
    n = tree.n_dof
    q, dq, tau = rng.normal(size=n), rng.normal(size=n), rng.normal(size=n)
    g = np.array([0.0, -9.81])
    _, M, F, _ = tree.dynamics(q, dq, g)
    assert np.allclose(M, mass_matrix_rnea(tree, q), rtol=1e-12, atol=1e-12)
    assert np.allclose(F, bias_rnea(tree, q, dq, g), rtol=1e-12, atol=1e-12)
    ddq = np.linalg.solve(M, tau - F)
    assert np.allclose(inverse_dynamics(tree, q, dq, ddq, g), tau, rtol=1e-10, atol=1e-10)

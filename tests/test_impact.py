"""Rigid impact laws: closed forms, complementarity, energy, friction branches."""
import dataclasses
import math

import numpy as np
import pytest

from multibody.impact import (MAX_CONTACTS, ImpactResult, frictional_impact,
                              frictionless_impact, kinetic_energy)


def spd(rng, n):
    A = rng.normal(size=(n, n))
    return A @ A.T + n * np.eye(n)


def contact_basis(wnt, wtt=1.0):
    """``M = I2`` and rows ``Jn``, ``Jt`` with ``W = [[1, wnt], [wnt, wtt]]``."""
    L = np.linalg.cholesky([[1.0, wnt], [wnt, wtt]])
    return np.eye(2), L[0], L[1]


def velocity_for(Jn, Jt, vn, vt):
    return np.linalg.solve(np.vstack([Jn, Jt]), [vn, vt])


def bar(mass=2.0, length=1.0):
    """Bar with DOF (x, y, theta), lying flat: mass matrix and the normal
    Jacobian ``[0, 1, d]`` of its material point at abscissa ``d``."""
    inertia = mass * length**2 / 12
    return np.diag([mass, mass, inertia]), lambda d: np.array([0.0, 1.0, d])


# ------------------------------------------------------------- frictionless
@pytest.mark.parametrize("e", [0.0, 0.5, 1.0])
@pytest.mark.parametrize("seed", range(5))
def test_single_contact_matches_closed_form(e, seed):
    rng = np.random.default_rng(seed)
    n = 4
    M, Jn, dq = spd(rng, n), rng.normal(size=n), rng.normal(size=n)
    dq = -dq if Jn @ dq > 0 else dq
    v_minus = Jn @ dq
    W = Jn @ np.linalg.solve(M, Jn)
    r = frictionless_impact(M, dq, Jn, e)
    assert r.compression_impulse[0] == pytest.approx(-v_minus / W, rel=1e-12)
    assert r.normal_impulse[0] == pytest.approx((1 + e) * -v_minus / W, rel=1e-12)
    assert Jn @ r.dq_plus == pytest.approx(-e * v_minus, abs=1e-12)
    np.testing.assert_allclose(r.dq_plus, dq + np.linalg.solve(M, Jn) * r.normal_impulse[0],
                               rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(r.tangential_impulse, [0.0])
    assert r.slip_history == () and r.slip_end is None


def test_separating_contact_gets_no_impulse():
    M, Jn = np.diag([1.0, 3.0]), np.array([1.0, 0.5])
    r = frictionless_impact(M, [0.2, 0.4], Jn, 0.7)
    np.testing.assert_array_equal(r.normal_impulse, [0.0])
    np.testing.assert_array_equal(r.dq_plus, [0.2, 0.4])


def random_multicontact(rng):
    n, k = int(rng.integers(2, 7)), int(rng.integers(1, 5))
    M, Jn, dq = spd(rng, n), rng.normal(size=(k, n)), rng.normal(size=n)
    e = rng.uniform() if rng.uniform() < 0.5 else rng.uniform(size=k)
    return M, dq, Jn, e


def test_frictionless_energy_never_increases():
    rng = np.random.default_rng(20240601)
    gains = []
    for _ in range(300):
        M, dq, Jn, e = random_multicontact(rng)
        r = frictionless_impact(M, dq, Jn, e)
        assert r.kinetic_energy_before == pytest.approx(kinetic_energy(M, dq), rel=1e-14)
        gain = r.kinetic_energy_after - r.kinetic_energy_before
        if gain > 1e-9 * r.kinetic_energy_before + 1e-14:
            gains.append((gain, e))
    assert not gains, f"energy gained in {len(gains)} cases: {gains[:3]}"


def test_complementarity_in_random_multicontact_cases():
    rng = np.random.default_rng(7)
    for _ in range(300):
        M, dq, Jn, e = random_multicontact(rng)
        e = np.broadcast_to(e, Jn.shape[:1])
        r = frictionless_impact(M, dq, Jn, e)
        MinvJ = np.linalg.solve(M, Jn.T)
        Pc, P = r.compression_impulse, r.normal_impulse
        W = Jn @ MinvJ
        tol = 1e-10 * max(1.0, np.abs(W).max() * np.abs(P).max())   # impulses may be large
        vc = Jn @ (dq + MinvJ @ Pc)                                   # recomputed, not read back
        assert np.all(Pc >= 0)
        assert np.all(vc >= -tol), vc
        assert np.all(np.abs(Pc * vc) <= tol * (1 + np.abs(Pc))), Pc * vc
        np.testing.assert_allclose(r.compression_velocity, vc, atol=tol)
        extra = P - (1 + e) * Pc                 # expansion LCP unknown Pe'
        v_plus = Jn @ r.dq_plus
        assert np.all(extra >= -tol) and np.all(v_plus >= -tol), (extra, v_plus)
        assert np.all(np.abs(extra * v_plus) <= tol * (1 + np.abs(extra)))
        np.testing.assert_allclose(r.dq_plus, dq + MinvJ @ P, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("e", [0.0, 0.4, 1.0])
def test_bar_landing_flat_on_two_points(e):
    mass, v = 2.0, 1.5
    M, jn = bar(mass)
    r = frictionless_impact(M, [0.3, -v, 0.0], [jn(-0.5), jn(0.5)], e)
    P = r.normal_impulse
    assert P[0] == pytest.approx(P[1], rel=1e-12)
    assert P.sum() == pytest.approx((1 + e) * mass * v, rel=1e-12)
    np.testing.assert_allclose(r.dq_plus, [0.3, e * v, 0.0], atol=1e-12)
    # one end alone would set the bar spinning: simultaneity matters
    single = frictionless_impact(M, [0.3, -v, 0.0], jn(-0.5), e)
    assert abs(single.dq_plus[2]) > 1.0


@pytest.mark.parametrize("e", [0.0, 0.6])
def test_redundant_contacts_give_unique_velocities(e):
    M, jn = bar()
    dq = np.array([0.0, -1.0, 0.8])
    single = frictionless_impact(M, dq, jn(0.5), e)
    twin = frictionless_impact(M, dq, [jn(0.5), jn(0.5)], e)
    np.testing.assert_allclose(twin.dq_plus, single.dq_plus, atol=1e-12)
    assert twin.normal_impulse.sum() == pytest.approx(single.normal_impulse[0], rel=1e-10)
    assert np.all(twin.normal_impulse >= 0)
    # three collinear points: rank 2, the middle one is redundant
    pair = frictionless_impact(M, dq, [jn(-0.5), jn(0.5)], e)
    triple = frictionless_impact(M, dq, [jn(-0.5), jn(0.0), jn(0.5)], e)
    np.testing.assert_allclose(triple.dq_plus, pair.dq_plus, atol=1e-12)
    d = np.array([-0.5, 0.0, 0.5])
    assert triple.normal_impulse.sum() == pytest.approx(pair.normal_impulse.sum(), rel=1e-10)
    assert d @ triple.normal_impulse == pytest.approx(pair.normal_impulse @ d[[0, 2]], abs=1e-10)


# ------------------------------------------------------------- friction
def test_zero_friction_equals_frictionless():
    rng = np.random.default_rng(3)
    for _ in range(50):
        n = int(rng.integers(2, 7))
        M, (Jn, Jt), dq = spd(rng, n), rng.normal(size=(2, n)), rng.normal(size=n)
        e = rng.uniform()
        a, b = frictional_impact(M, dq, Jn, Jt, e, 0.0), frictionless_impact(M, dq, Jn, e)
        np.testing.assert_allclose(a.dq_plus, b.dq_plus, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(a.normal_impulse, b.normal_impulse, rtol=1e-10, atol=1e-14)
        np.testing.assert_allclose(a.compression_impulse, b.compression_impulse,
                                   rtol=1e-10, atol=1e-14)
        assert a.tangential_impulse[0] == 0.0


@pytest.mark.parametrize(("mu", "sticks"), [(0.1, False), (0.3, False), (2.0, True)])
def test_point_mass_hits_wall_obliquely(mu, sticks):
    m, e, vn, vt = 2.0, 0.6, -2.0, 3.0
    r = frictional_impact(m * np.eye(2), [vn, vt], [1.0, 0.0], [0.0, 1.0], e, mu)
    assert r.dq_plus[0] == pytest.approx(-e * vn, rel=1e-12)
    expected_vt = 0.0 if sticks else vt - mu * (1 + e) * abs(vn) * math.copysign(1, vt)
    assert r.dq_plus[1] == pytest.approx(expected_vt, abs=1e-12)
    assert r.slip_end == ("stuck" if sticks else "slipping")
    assert r.normal_impulse[0] == pytest.approx((1 + e) * m * abs(vn), rel=1e-12)


def test_slip_throughout():
    M, Jn, Jt = contact_basis(0.3)
    mu, e = 0.1, 0.5
    r = frictional_impact(M, velocity_for(Jn, Jt, -1.0, 5.0), Jn, Jt, e, mu)
    assert [m for *_, m in r.slip_history] == ["slip+"] and r.slip_end == "slipping"
    pc = 1.0 / (1.0 - mu * 0.3)                      # dvn/dp = Wnn - mu Wnt
    assert r.compression_impulse[0] == pytest.approx(pc, rel=1e-12)
    assert r.normal_impulse[0] == pytest.approx((1 + e) * pc, rel=1e-12)
    assert r.tangential_impulse[0] == pytest.approx(-mu * (1 + e) * pc, rel=1e-12)


def test_slip_then_stick():
    M, Jn, Jt = contact_basis(0.3)                   # |r| = 0.3 <= mu
    r = frictional_impact(M, velocity_for(Jn, Jt, -1.0, 0.1), Jn, Jt, 0.5, 0.8)
    assert [m for *_, m in r.slip_history] == ["slip+", "stick"] and r.slip_end == "stuck"
    assert r.slip_history[0][1] == pytest.approx(0.1 / 0.5, rel=1e-12)   # vt / |Wnt - mu Wtt|
    assert Jt @ r.dq_plus == pytest.approx(0.0, abs=1e-14)


def test_slip_reversal_matches_hand_solution():
    wnt, mu, e = 0.6, 0.2, 0.5                      # |r| = 0.6 > mu: no stick
    M, Jn, Jt = contact_basis(wnt)
    r = frictional_impact(M, velocity_for(Jn, Jt, -1.0, -0.2), Jn, Jt, e, mu)
    assert [m for *_, m in r.slip_history] == ["slip-", "slip+"] and r.slip_end == "reversed"
    p1 = 0.2 / (wnt + mu)                           # vt reaches 0
    vn1 = -1.0 + (1 + mu * wnt) * p1
    pc = p1 - vn1 / (1 - mu * wnt)
    pf = (1 + e) * pc
    assert r.slip_history[0][1] == pytest.approx(p1, rel=1e-12)
    assert r.slip_history[-1][1] == pytest.approx(pf, rel=1e-12)
    assert r.compression_impulse[0] == pytest.approx(pc, rel=1e-12)
    assert r.tangential_impulse[0] == pytest.approx(mu * p1 - mu * (pf - p1), rel=1e-12)
    assert Jn @ r.dq_plus == pytest.approx((1 - mu * wnt) * (pf - pc), rel=1e-12)
    assert Jt @ r.dq_plus == pytest.approx((wnt - mu) * (pf - p1), rel=1e-12)


@pytest.mark.parametrize(("wnt", "modes"), [(0.3, ["stick"]), (0.6, ["slip+"]), (-0.6, ["slip-"])])
def test_initial_zero_tangential_velocity(wnt, modes):
    M, Jn, Jt = contact_basis(wnt)
    r = frictional_impact(M, velocity_for(Jn, Jt, -1.0, 0.0), Jn, Jt, 0.5, 0.4)
    assert [m for *_, m in r.slip_history] == modes
    assert r.slip_end == ("stuck" if modes == ["stick"] else "slipping")
    if modes == ["stick"]:
        assert r.tangential_impulse[0] == pytest.approx(-wnt * r.normal_impulse[0], rel=1e-12)
        assert Jt @ r.dq_plus == pytest.approx(0.0, abs=1e-14)


def test_painleve_jam_raises():
    M, Jn, Jt = contact_basis(0.9)
    with pytest.raises(ValueError, match="Painleve"):
        frictional_impact(M, velocity_for(Jn, Jt, -1.0, 1.0), Jn, Jt, 0.5, 2.0)


def test_frictional_energy_never_increases():
    rng = np.random.default_rng(11)
    ends, gains, jams = {"slipping": 0, "stuck": 0, "reversed": 0}, [], 0
    for _ in range(300):
        n = int(rng.integers(2, 7))
        M, (Jn, Jt), dq = spd(rng, n), rng.normal(size=(2, n)), rng.normal(size=n)
        dq = -dq if Jn @ dq > 0 else dq
        e, mu = rng.uniform(), rng.uniform()
        try:
            r = frictional_impact(M, dq, Jn, Jt, e, mu)
        except ValueError as err:
            assert "Painleve" in str(err)
            jams += 1
            continue
        ends[r.slip_end] += 1
        starts = [a for a, _, _ in r.slip_history]
        stops = [b for _, b, _ in r.slip_history]
        assert starts[0] == 0.0 and starts[1:] == pytest.approx(stops[:-1], rel=1e-14)
        assert stops[-1] == pytest.approx(r.normal_impulse[0], rel=1e-12)
        assert r.normal_impulse[0] == pytest.approx((1 + e) * r.compression_impulse[0], rel=1e-12)
        assert abs(r.tangential_impulse[0]) <= mu * r.normal_impulse[0] * (1 + 1e-12)
        gain = r.kinetic_energy_after - r.kinetic_energy_before
        if gain > 1e-12 * r.kinetic_energy_before:
            gains.append((gain, e, mu, r.slip_history))
    assert not gains, f"energy gained in {len(gains)} cases: {gains[:3]}"
    assert jams < 30 and min(ends.values()) >= 20, (ends, jams)     # every branch sampled


# ------------------------------------------------------------- API
def test_errors_name_the_argument():
    M, Jn, Jt = np.eye(2), [1.0, 0.0], [0.0, 1.0]
    with pytest.raises(ValueError, match=r"`restitution` must be in \[0, 1\], got 1.5"):
        frictionless_impact(M, [-1.0, 0.0], Jn, 1.5)
    with pytest.raises(ValueError, match=r"`restitution` must be in \[0, 1\], got -0.1"):
        frictionless_impact(M, [-1.0, 0.0], [Jn, Jt], [0.5, -0.1])
    with pytest.raises(ValueError, match="`friction` must be finite and >= 0, got -0.2"):
        frictional_impact(M, [-1.0, 0.0], Jn, Jt, 0.5, -0.2)
    with pytest.raises(ValueError, match="`M` must be positive definite"):
        frictionless_impact([[1.0, 2.0], [2.0, 1.0]], [-1.0, 0.0], Jn, 0.5)
    with pytest.raises(ValueError, match="`M` must be symmetric"):
        frictionless_impact([[1.0, 0.1], [0.0, 1.0]], [-1.0, 0.0], Jn, 0.5)
    with pytest.raises(ValueError, match="`dq_minus` must be 2 finite numbers"):
        frictionless_impact(M, [-1.0, 0.0, 0.0], Jn, 0.5)
    with pytest.raises(ValueError, match="`Jn` row 1 must be nonzero"):
        frictionless_impact(M, [-1.0, 0.0], [Jn, [0.0, 0.0]], 0.5)
    with pytest.raises(ValueError, match="linearly independent"):
        frictional_impact(M, [-1.0, 0.0], Jn, [2.0, 0.0], 0.5, 0.3)
    with pytest.raises(ValueError, match=f"at most {MAX_CONTACTS} rows"):
        frictionless_impact(M, [-1.0, 0.0], np.ones((MAX_CONTACTS + 1, 2)), 0.5)


def test_result_is_frozen_and_read_only():
    r = frictionless_impact(np.eye(2), [-1.0, 0.5], [1.0, 0.0], 0.5)
    assert isinstance(r, ImpactResult)
    with pytest.raises(dataclasses.FrozenInstanceError):
        r.dq_plus = np.zeros(2)
    with pytest.raises(ValueError, match="read-only"):
        r.dq_plus[0] = 0.0
    assert r.energy_loss == pytest.approx(0.5 * (1 - 0.25), rel=1e-12)
    assert kinetic_energy(np.diag([2.0, 4.0]), [1.0, 0.5]) == pytest.approx(1.5)


def test_redundant_impulses_follow_the_documented_least_norm_choice():
    M, jn = bar()
    twin = frictionless_impact(M, [0.0, -1.0, 0.8], [jn(0.5), jn(0.5)], 0.6)
    assert twin.normal_impulse[0] == pytest.approx(twin.normal_impulse[1], rel=1e-10)

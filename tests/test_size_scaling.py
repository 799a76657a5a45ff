"""The size-scaling benchmark: its log-log slope on synthetic costs with
known exponents, its scenes, and its core on two small sizes (no timing is
asserted: speed is the benchmark's own output).  Also the ports-only
evaluation of ``fem.undamped_response`` that the closed-form contact steps
use."""
import csv
import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

from fem import undamped_response
from fem import response as fem_response

_PATH = Path(__file__).resolve().parents[1] / "benchmarks" / "size_scaling.py"
_spec = importlib.util.spec_from_file_location("size_scaling", _PATH)
bench = importlib.util.module_from_spec(_spec)
sys.modules.setdefault("size_scaling", bench)      # dataclasses look their module up
_spec.loader.exec_module(bench)

SIZES = np.array([16, 32, 64, 128, 256, 512, 1024], float)


@pytest.mark.parametrize("p", [0.0, 0.5, 1.0, 2.0, 3.0])
def test_slope_of_an_exact_power_law(p):
    slope, intercept = bench.loglog_slope(SIZES, 3e-4 * SIZES ** p)
    assert slope == pytest.approx(p, abs=1e-12)
    assert intercept == pytest.approx(np.log(3e-4), abs=1e-10)


@pytest.mark.parametrize("p", [1.0, 2.0])
def test_slope_with_noise(p):
    """5 % multiplicative noise over two decades of size moves the slope by
    a few hundredths; the seed fixes the draw."""
    rng = np.random.default_rng(12)
    cost = 2e-3 * SIZES ** p * np.exp(rng.normal(0.0, 0.05, SIZES.size))
    slope, _ = bench.loglog_slope(SIZES, cost)
    assert abs(slope - p) < 0.05, f"slope {slope:.3f} for exponent {p}"


def test_a_constant_offset_bends_the_full_fit_but_not_the_tail():
    """cost = c0 + a n^2 with c0 = a 128^2: the full-range fit sees the flat
    start and falls well below 2; the three largest sizes follow n^2."""
    cost = 1.0 + SIZES ** 2 / 128.0 ** 2
    full, _ = bench.loglog_slope(SIZES, cost)
    tail, _ = bench.loglog_slope(SIZES, cost, tail=3)
    assert full < 1.5, f"full-range slope {full:.3f}"
    assert abs(tail - 2.0) < 0.15, f"tail slope {tail:.3f}"
    # the order of the points does not matter
    order = np.random.default_rng(0).permutation(SIZES.size)
    assert bench.loglog_slope(SIZES[order], cost[order], tail=3)[0] == pytest.approx(tail)


def test_slope_refuses_what_has_no_slope():
    with pytest.raises(ValueError, match="at least two distinct sizes"):
        bench.loglog_slope([8, 8], [1.0, 2.0])
    with pytest.raises(ValueError, match="finite and > 0"):
        bench.loglog_slope([8, 16], [1.0, 0.0])
    with pytest.raises(ValueError, match="`tail` must be >= 2"):
        bench.loglog_slope([8, 16, 32], [1.0, 2.0, 3.0], tail=1)
    with pytest.raises(ValueError, match="same length"):
        bench.loglog_slope([8, 16, 32], [1.0, 2.0])


def test_chain_of_n_masses_starts_at_rest_with_its_top_at_zero():
    """The benchmark's lift of the chain (its top's static sag, g m n(n+1)/2k)
    puts the top at y = 0 in the static state, as in three_mass."""
    from cosim import load_scene
    robot = {j: {"q": 0.0, "dq": 0.0} for j in bench.JOINTS}
    for n in (3, 7):
        scene = load_scene(bench.CASES / "three_mass.toml", "f100",
                           bench.overrides("chain", n, robot, 0.01))
        system, _ = scene.build()
        chain = system.subsystems[system.names.index("chain")]
        assert chain.structure.n_dof == n
        pos, vel = chain.outputs(0.0, chain.x)
        assert pos[0, 1] == pytest.approx(0.0, abs=1e-12)
        assert np.all(vel == 0.0)


def test_beam_without_reduction_keeps_every_mode():
    from cosim import load_scene
    robot = {j: {"q": 0.0, "dq": 0.0} for j in bench.JOINTS}
    for series, kept in (("beam_full", 32), ("beam_modal", None)):
        scene = load_scene(bench.CASES / "beam_impact.toml", None,
                           bench.overrides(series, 16, robot, 0.01))
        system, _ = scene.build()
        beam = system.subsystems[system.names.index("beam")]
        assert beam.structure.n_dof == 32
        if kept is None:    # the 20 kHz cutoff drops the mesh's top modes
            assert beam.n_modes < 32 and beam.natural_frequencies_hz.max() < 2e4
        else:
            assert beam.n_modes == kept


def test_core_on_two_small_sizes_writes_the_csv(tmp_path):
    points = []
    for series, sizes in (("chain", (3, 4)), ("beam_modal", (4, 8))):
        points += bench.run_series(series, sizes, window=0.012)
    path = bench.write_csv(points, tmp_path / "size_scaling.csv")
    with path.open() as fh:
        rows = list(csv.DictReader(fh))
    assert tuple(rows[0]) == bench.COLUMNS
    assert [(r["series"], int(r["size"])) for r in rows] == [
        ("chain", 3), ("chain", 4), ("beam_modal", 4), ("beam_modal", 8)]
    assert all(r["status"] == "finished" for r in rows)
    assert [int(r["dofs"]) for r in rows] == [3, 4, 8, 16]
    for r in rows:
        assert float(r["window_s"]) == 0.012 and int(r["macro_steps"]) > 0
        assert 0.0 < float(r["cpu_structure_s"]) <= float(r["cpu_solve_s"])
        assert float(r["cpu_per_step_s"]) == pytest.approx(
            float(r["cpu_solve_s"]) / int(r["macro_steps"]))
    # C strikes within the window: the robot starts just before the impact
    assert all(int(r["contacts_C"]) >= 1 and float(r["peak_C"]) > 0 for r in rows)
    fits = bench.slopes(points)
    assert set(fits) == {"chain", "beam_modal"}
    assert set(fits["chain"]) == set(bench.SLOPE_METRICS)


@pytest.mark.parametrize("n_rigid", [0, 2])
def test_undamped_response_at_ports_equals_the_projected_states(n_rigid, monkeypatch):
    """``rows`` gives ``z @ rows`` without forming the states, rigid-body
    modes included, and in chunks of instants (forced small here)."""
    rng = np.random.default_rng(3)
    m = 40
    lam = rng.uniform(1.0, 1e6, m)
    lam[:n_rigid] = 0.0
    z0, dz0 = rng.normal(size=m), rng.normal(size=m)
    a = rng.normal(size=(4, m))
    tau = np.linspace(0.0, 0.01, 37)
    rows = rng.normal(size=(m, 3))
    z, dz = undamped_response(lam, z0, dz0, a, tau)
    monkeypatch.setattr(fem_response, "_CHUNK_VALUES", 5 * m)    # 5 instants a chunk
    zp, dzp = undamped_response(lam, z0, dz0, a, tau, rows=rows)
    np.testing.assert_allclose(zp, z @ rows, rtol=1e-12, atol=1e-12 * np.abs(zp).max())
    np.testing.assert_allclose(dzp, dz @ rows, rtol=1e-12, atol=1e-12 * np.abs(dzp).max())
    with pytest.raises(ValueError, match=r"`rows` must have shape \(40, p\)"):
        undamped_response(lam, z0, dz0, a, tau, rows=rows[:5])


@pytest.mark.parametrize("scene_file,variant", [("three_mass.toml", "f100"),
                                                ("beam_impact.toml", None)])
def test_closed_form_segment_integrals_match_a_fine_quadrature(scene_file, variant):
    """The closed spring's impulse, first moment and work on the host, and the
    ports' velocity moments, over a segment of a hosted contact step (partner
    moving along a cubic, port loaded along a line), against Gauss-Legendre on
    1000 panels of the same exact response."""
    from cosim import load_scene
    from cosim.core.subsystem import StepInput
    scene = load_scene(bench.CASES / scene_file, variant)
    system, _ = scene.build()
    sub = next(s for s in system.subsystems if hasattr(s, "_segment_quadratures"))
    e = sub._embedded[0]
    m, t, h, tc, L = sub.n_modes, 0.1, 2e-4, 0.10005, 1.2e-4
    p0 = complex(*sub._ref[e.port])
    # the partner sits 1 mm into the host's port and moves on a cubic in s
    inward = e.side * e.normal * 1e-3
    e.set_motion(t, h, np.array([p0 + inward, 0.3e-3 * e.normal, -0.2e-3, 0.1e-3j]))
    coeffs = np.zeros((2, sub.n_ports, 2))
    coeffs[:, e.port] = [[0.0, -3.0], [0.0, 5.0]]
    inputs = StepInput(t, h, coeffs)
    rng = np.random.default_rng(5)
    q, dq = 1e-6 * rng.normal(size=m), 1e-4 * rng.normal(size=m)
    active = (True,)
    lam, Psi, _ = sub._active_basis(active)
    Gin = sub._modal_force(inputs.coeffs).copy()
    Gin[0] += sub._g_modal
    seg = sub._segment(lam, Psi, q, dq, sub._segment_load(t, h, tc, Gin, active))
    sub.aux[:] = 0.0
    sub.port_moments = np.zeros((3, sub.n_ports), complex)
    sub._segment_quadratures(t, h, tc, L, seg, active, inputs)
    got = sub.aux[:4].copy(), sub.port_moments.copy()
    x, w = np.polynomial.legendre.leggauss(8)
    n = 1000
    taus = ((np.arange(n)[:, None] + 0.5 * (x + 1.0)[None]) * (L / n)).ravel()
    wts = np.tile(0.5 * w, n) * (L / n)
    W, DW = sub._port_states(seg, taus)
    d, _ = sub._gaps(tc, taus, W, DW)
    assert d.min() > 0.0                       # closed over the whole segment
    f = e.law.contact_stiffness * d[:, 0]
    beta = e.side * (e.normal.conjugate() * complex(*sub._dir)).real
    ref = [wts @ f, wts @ (f * (tc + taus - t)), wts @ (beta * f * DW[:, e.port])]
    np.testing.assert_allclose(got[0][[0, 2, 3]], ref, rtol=1e-9)
    assert got[0][1] == 0.0                    # dissipation: a linear spring has none
    s = (tc + taus - t) / h
    V = DW * complex(*sub._dir)
    for j in range(3):
        np.testing.assert_allclose(got[1][j], (wts * s ** j) @ V, rtol=1e-9,
                                   atol=1e-12 * np.abs(V).max() * L)


def test_a_slow_mode_beside_a_very_fast_one_is_not_taken_for_rigid():
    """A 512-element beam with all its modes spans 12 decades of omega^2 (its
    first mode is 5.7e-13 of the top one).  Held at its static deflection
    under a constant load, the slow mode stays there; it does not fall freely
    as a rigid-body mode would (c0 tau^2 / 2 = 1.1e-3 here at 10 ms)."""
    lam = np.array([2.2e4, 3.8e16])
    c0 = np.array([-22.0, 5.0])
    static = c0 / lam
    tau = np.array([1e-3, 1e-2])
    z, dz = undamped_response(lam, static, np.zeros(2), c0[None], tau)
    np.testing.assert_allclose(z[:, 0], static[0], rtol=1e-9)
    np.testing.assert_allclose(dz[:, 0], 0.0, atol=1e-9 * abs(static[0]) * np.sqrt(lam[0]))
    # a genuinely rigid mode (omega^2 = 0) integrates the load twice
    zr, dzr = undamped_response(np.array([0.0, 3.8e16]), [0.0, 0.0], [0.0, 0.0], c0[None], tau)
    np.testing.assert_allclose(zr[:, 0], c0[0] * tau ** 2 / 2, rtol=1e-12)
    np.testing.assert_allclose(dzr[:, 0], c0[0] * tau, rtol=1e-12)


@pytest.mark.parametrize("case", ["uniform", "wide", "deflated", "unsorted"])
def test_rank_one_eigh_matches_a_dense_solver(case):
    """diag(d) + z z^T by its secular equation: eigenvalues as LAPACK's to
    1e-13 of the matrix's size, residual and orthogonality to round-off,
    over 12 decades of d (a beam with all its modes) and with components of
    z that vanish (deflated: their d and unit vector stay)."""
    from scipy.linalg import eigh

    from fem.rank_one import rank_one_eigh
    rng = np.random.default_rng(7)
    m = 120
    d = (np.sort(rng.uniform(0.0, 1.0, m)) if case == "uniform"
         else np.sort(10.0 ** rng.uniform(0.0, 12.0, m)))
    z = rng.normal(size=m) * (1.0 if case == "uniform" else 1e3)
    if case == "deflated":
        z[::5] = 0.0
    if case == "unsorted":
        perm = rng.permutation(m)
        d, z = d[perm], z[perm]
    A = np.diag(d) + np.outer(z, z)
    lam, V = rank_one_eigh(d, z)
    size = np.abs(A).max()
    np.testing.assert_allclose(np.sort(lam), eigh(A, eigvals_only=True), rtol=0,
                               atol=1e-13 * size)
    assert np.abs(A @ V - V * lam).max() <= 1e-13 * size
    assert np.abs(V.T @ V - np.eye(m)).max() <= 1e-13
    if case == "deflated":
        for j in np.flatnonzero(z == 0.0):
            assert d[j] in lam


def test_rank_one_eigh_rotates_equal_coupled_entries_apart():
    """diag(1, 2, 2, 3) + 1 1^T: the two equal entries are rotated so that
    one of them, (0, 1, -1, 0) / sqrt 2, keeps the eigenvalue 2 uncoupled;
    the other three roots are the secular equation's."""
    from fem.rank_one import rank_one_eigh
    d = np.array([1.0, 2.0, 2.0, 3.0])
    lam, V = rank_one_eigh(d, np.ones(4))
    A = np.diag(d) + 1.0
    np.testing.assert_allclose(np.sort(lam), np.linalg.eigvalsh(A), rtol=0, atol=1e-14 * 7)
    assert np.abs(A @ V - V * lam).max() <= 1e-14 * 7
    assert np.abs(V.T @ V - np.eye(4)).max() <= 1e-15 * 4
    j = int(np.argmin(np.abs(lam - 2.0)))
    assert lam[j] == 2.0
    np.testing.assert_allclose(np.abs(V[:, j]), [0.0, 0.5 ** 0.5, 0.5 ** 0.5, 0.0], atol=1e-15)
    lam, V = rank_one_eigh(np.array([1.0, 2.0]), np.zeros(2))
    np.testing.assert_array_equal(lam, [1.0, 2.0])
    np.testing.assert_array_equal(V, np.eye(2))


def test_rank_one_eigh_keeps_low_eigenvalues_accurate_beside_a_huge_one():
    """diag(1e3, 2e3, 1e16) + z z^T with z = (sqrt(1e3), sqrt(1e3), 1): the two
    low roots solve 1 + 1/(1 - mu) + 1/(2 - mu) = 0 (lam = 1e3 mu, the 1e16
    pole shifts them by 1e-16 relative), mu = (5 -+ sqrt 5)/2.  A dense
    solver's error is eps times the largest entry, about 2 here, which is
    1e-3 of them; the secular equation keeps them to round-off."""
    from fem.rank_one import rank_one_eigh
    d = np.array([1e3, 2e3, 1e16])
    z = np.array([np.sqrt(1e3), np.sqrt(1e3), 1.0])
    lam, V = rank_one_eigh(d, z)
    low = np.sort(lam)[:2]
    np.testing.assert_allclose(low, 1e3 * (5.0 + np.array([-1.0, 1.0]) * np.sqrt(5.0)) / 2,
                               rtol=1e-13)
    # their eigenvectors satisfy the equations relative to their own size
    A = np.diag(d) + np.outer(z, z)
    for j in np.argsort(lam)[:2]:
        r = A @ V[:, j] - lam[j] * V[:, j]
        assert np.abs(r[:2]).max() <= 1e-12 * lam[j]

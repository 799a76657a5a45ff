"""The implicit scheme's compiled iterations (``cosim.core.schemes._implicit_step``)
against the Python reference (``Implicit.compiled_iterations = False``), both
stepping the same compiled sides.

The two compute the same formulas in the same order except where the
reference calls numpy's BLAS and LAPACK (the port-force maps, a structure's
ports, dot products, the QR factorisations of IQN-ILS), so they agree to
round-off: every recorded series within 1e-10 of its largest value, the
same iteration counts and the same grasp switches, for the scene and for
its copies moved by a few ulps (a count that round-off could turn would
differ among those).
"""
import contextlib
import warnings

import numpy as np
import pytest

import cosim
from conftest import CASES
from roundoff import COPIES
from cosim.core.schemes.implicit import IQNILS, Aitken, Implicit
from cosim.studies.roundoff import spread

ks = pytest.importorskip("cosim.core.schemes._implicit_step",
                         reason="the compiled iterations are not built here")

SCENE = CASES / "brachiation.toml"
#: bound of a series' difference between the two, relative to its largest
#: value: the iterations stop at a relative 1e-6, so round-off in the
#: guesses (1e-16 relative, amplified by IQN-ILS's least squares at most by
#: the QR filter's 1e6) stays far below it (measured 1.2e-11, brachiation)
SERIES_RTOL = 1e-10


@contextlib.contextmanager
def iterations(compiled: bool):
    """Run the implicit scheme's compiled iterations (``compiled``) or the
    Python reference; yields a list that collects the macro steps the
    compiled iterations took."""
    taken = []
    original = Implicit._advance_compiled

    def spy(self, *args):
        taken.append(args[1])
        return original(self, *args)

    saved = Implicit.compiled_iterations
    Implicit.compiled_iterations = compiled
    Implicit._advance_compiled = spy
    try:
        yield taken
    finally:
        Implicit.compiled_iterations = saved
        Implicit._advance_compiled = original


def simulate(scene, compiled: bool):
    with iterations(compiled) as taken, warnings.catch_warnings():
        warnings.simplefilter("ignore")       # aitken ignores `reuse`
        res = cosim.simulate(scene, estimate=False)
    assert res.status == "finished", res.message
    return res, len(taken)


def load(variant=None, overrides=()):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")       # aitken ignores `reuse`
        return cosim.load_scene(SCENE, variant, list(overrides))


def switches(res):
    return [(s["contact"], s["to"], s["time"]) for s in res.summary["switches"]]


def assert_series_close(res, ref):
    assert sorted(res.series) == sorted(ref.series)
    for key, y in ref.series.items():
        x, y = np.asarray(res.series[key], float), np.asarray(y, float)
        assert x.shape == y.shape, key
        big = np.max(np.abs(y), initial=0.0)
        assert np.max(np.abs(x - y), initial=0.0) <= SERIES_RTOL * big, key


# ------------------------------------------------------------ brachiation
@pytest.mark.parametrize("name,overrides,copies", [
    ("iqn_ils", [], COPIES),          # the scene: IQN-ILS with the secants of two steps
    ("aitken", ['scheme.acceleration="aitken"'], 3),
    ("no reuse", ["scheme.reuse=0", "t_end=0.9"], 3),
    # gripper 2's unilateral law damped until it grasps
    ("kelvin_voigt", ['contacts.gripper2.law={ type = "kelvin_voigt", contact_stiffness = 1e5, '
                      'contact_damping = 50.0 }', "t_end=0.9"], 3),
])
def test_brachiation_iterates_in_compiled_code_as_the_reference(name, overrides, copies):
    """Same iterations (measured 2551 for the scene, 5592 with Aitken), the
    same grasp, touch and release at the same communication points, and the
    series within round-off, for the scene and its copies moved by +-1 (and
    +-2) ulps (the variants with fewer copies, for time)."""
    scene = load(overrides=overrides)
    for i, copy in enumerate(spread(scene, copies)):
        res, taken = simulate(copy, compiled=True)
        ref, none = simulate(copy, compiled=False)
        assert taken == res.n_windows and none == 0      # each ran as asked
        assert res.n_iterations == ref.n_iterations, (i, res.n_iterations, ref.n_iterations)
        assert switches(res) == switches(ref)
        assert [s[:2] for s in switches(res)] == [("gripper1", "grasped"),
                                                  ("gripper2", "grasped"),
                                                  ("gripper1", "released")][:len(switches(res))]
        if i == 0:
            assert len(switches(res)) == 3
            assert_series_close(res, ref)


def test_the_numpy_reference_and_other_systems_iterate_in_python(monkeypatch):
    """Where a side has no compiled step without Python the reference
    iterates: the numpy kernel chosen (then the answers agree with the
    compiled run's to round-off), or the rigid cable, against which the
    grasps are embedded in the robot (no coupler contact is left)."""
    for i, copy in enumerate(spread(load(overrides=["t_end=0.05"]), COPIES)):
        monkeypatch.delenv("COSIM_KERNEL", raising=False)
        res, taken = simulate(copy, compiled=True)
        assert taken == 50
        monkeypatch.setenv("COSIM_KERNEL", "numpy")
        ref, taken = simulate(copy, compiled=True)
        assert taken == 0
        assert res.n_iterations == ref.n_iterations, i
        if i == 0:
            assert_series_close(res, ref)
    monkeypatch.delenv("COSIM_KERNEL")
    rigid, taken = simulate(load("rigid_cable", ["t_end=0.01"]), compiled=True)
    assert taken == 0 and rigid.n_windows == 10


def test_an_unconverged_step_fails_as_in_the_reference():
    """Two iterations cannot settle the grasps' first step: the same
    error, naming the same row and residual."""
    scene = load(overrides=["t_end=0.01", "scheme.max_iterations=2"])
    out = []
    for compiled in (True, False):
        with iterations(compiled) as taken:
            res = cosim.simulate(scene, estimate=False)
        assert res.status == "failed" and len(taken) == (1 if compiled else 0)
        out.append(res.message)
    assert out[0] == out[1]
    assert "contact `gripper1.t` has a force residual of 0.653 N" in out[0]


@pytest.mark.parametrize("law", ["linear", "kelvin_voigt"])
def test_the_compiled_row_forces_are_the_systems_in_every_mode(law):
    """Both grippers open, grasped or released, at random port positions
    and velocities around the touch: the kernel's row forces are
    ``CoupledSystem.forces`` of the coupler rows (the same formulas in the
    same order: within a few ulps of the largest)."""
    over = [] if law == "linear" else [
        f'contacts.{g}.law={{ type = "kelvin_voigt", contact_stiffness = 1e5, '
        f'contact_damping = 50.0 }}' for g in ("gripper1", "gripper2")]
    system, scheme = load(overrides=over).build()
    kernel = scheme._compiled_iterations(system)
    assert kernel is not None
    cs = system.connections
    rng = np.random.default_rng(3)
    outs = system.outputs()
    pos0, vel0 = np.concatenate([o[0] for o in outs]), np.concatenate([o[1] for o in outs])
    rows = system.coupler_rows
    assert len(rows) == 4
    for trial in range(200):
        cs.mode[:] = rng.integers(0, 3, size=cs.mode.size)     # open, grasped, released
        cs.anchor[:] = rng.normal(scale=1e-3, size=cs.anchor.size)
        pos = pos0 + rng.normal(scale=3e-3, size=pos0.shape)  # the gap is +-3 mm
        vel = vel0 + rng.normal(scale=0.5, size=vel0.shape)
        cuts = np.cumsum([len(o[0]) for o in outs])[:-1]
        at = list(zip(np.split(pos, cuts), np.split(vel, cuts)))
        want = system.forces(*system.penetrations(at))[rows]
        got = kernel.row_forces(pos, vel)[rows]
        assert np.max(np.abs(got - want)) <= 4 * np.spacing(np.max(np.abs(want))), trial


# ------------------------------------------------------- the accelerations
def _fixed_point(rng, n):
    """A contracting-or-not affine map H(x) = A x + b, as an interface of n rows."""
    A = rng.normal(size=(n, n)) * rng.uniform(0.2, 2.0)
    return A, rng.normal(size=n) * 100.0


@pytest.mark.parametrize("kind", ["aitken", "iqn_ils"])
@pytest.mark.parametrize("n", [1, 2, 4, 6])
def test_the_compiled_accelerations_follow_the_reference(kind, n):
    """Fed the same guesses, images and residuals over several macro steps
    (IQN-ILS keeping the secants of two steps, dropping them when the key
    changes), the compiled accelerations give the reference's next guesses
    to round-off (relative 1e-9 of the guess: IQN-ILS's least squares
    amplifies round-off by the conditioning its QR filter allows, 1e6;
    measured 1.6e-13 for IQN-ILS, 5.9e-15 for Aitken)."""
    rng = np.random.default_rng(7 + n)
    for trial in range(20):
        if kind == "aitken":
            ref, new = Aitken(relaxation=0.5), ks.Acceleration("aitken", n, 0.5)
        else:
            ref = IQNILS(relaxation=0.5, reuse=2, filter_tolerance=1e-6)
            new = ks.Acceleration("iqn_ils", n, 0.5, 2, 1e-6, 50)
        A, b = _fixed_point(rng, n)
        key_prev = None
        for step in range(4):
            key = (1e-3, (step != 2,))          # step 2 drops the kept secants
            ref.start(key)
            new.start(key_prev is not None and key == key_prev)
            key_prev = key
            z = rng.normal(size=n) * 100.0
            for it in range(6):
                hz = A @ z + b
                r = hz - z
                if np.max(np.abs(r)) <= 1e-9 * np.max(np.abs(hz)):
                    break                       # converged: the scheme stops here
                want = ref.update(z, hz, r)
                got = new.update(z, hz, r)
                scale = max(np.max(np.abs(want)), np.max(np.abs(z)), 1.0)
                assert np.max(np.abs(got - want)) <= 1e-9 * scale, (trial, step, it)
                z = want
            ref.finish()
            new.finish()


def test_the_qr_filter_drops_the_same_secant():
    """A residual difference nearly parallel to an earlier one (sine 1e-9,
    below the filter's 1e-6) is dropped by both, and the next guess comes
    from the remaining column; with a sine of 1e-3 it is kept by both."""
    d, e = np.array([1.0, 2.0, 0.5]), np.array([0.3, -1.0, 2.0])
    for tilt in (1e-9, 1e-3):
        ref = IQNILS(relaxation=0.5, reuse=0)
        new = ks.Acceleration("iqn_ils", 3, 0.5, 0, 1e-6, 50)
        ref.start((1e-3, (True,)))
        new.start(False)
        r = np.array([3.0, -1.0, 2.0])
        z = np.zeros(3)
        for step in (0.0, 1.0, 2.0, 4.0):
            r = r + step * d + (tilt * e if step == 4.0 else 0.0)
            hz = z + r
            want, got = ref.update(z, hz, r), new.update(z, hz, r)
            assert np.max(np.abs(got - want)) <= 1e-9 * max(np.max(np.abs(want)), 1.0)
            z = want
        kept = ref._columns(3)[0].shape[1]
        assert kept == (1 if tilt == 1e-9 else 2), kept


def test_a_repeated_residual_is_dropped_as_a_zero_secant():
    """An iteration whose residual repeats the last one exactly gives a zero
    secant: the QR filter drops it (0 >= 0 would keep it, and the solve
    would divide by zero), in both, and the guess is relaxed from the
    columns left."""
    ref = IQNILS(relaxation=0.5, reuse=0)
    new = ks.Acceleration("iqn_ils", 2, 0.5, 0, 1e-6, 50)
    ref.start((1e-3, (True,)))
    new.start(False)
    z, r = np.array([1.0, 2.0]), np.array([0.5, -0.25])
    for _ in range(3):
        want, got = ref.update(z, z + r, r), new.update(z, z + r, r)
        assert np.all(np.isfinite(want)) and np.max(np.abs(got - want)) <= 1e-14
    assert ref._columns(2) == (None, None)


def test_the_least_squares_solve_matches_numpy_lstsq():
    """IQN-ILS's solve (Householder QR, back substitution) against
    ``numpy.linalg.lstsq`` on random full-rank problems: within the
    round-off the problem's conditioning allows (the least-squares
    perturbation bound, Golub and Van Loan 2013, sec. 5.3.7, with 64 eps):
    ``64 eps k (|alpha| + (k + 1) |V alpha + r| / |V|)``, ``k = cond(V)``."""
    rng = np.random.default_rng(11)
    eps = np.finfo(float).eps
    for _ in range(300):
        n = int(rng.integers(1, 8))
        m = int(rng.integers(1, n + 1))
        V = rng.normal(size=(n, m)) * 10.0 ** rng.uniform(-3, 3, size=m)
        r = rng.normal(size=n) * 10.0 ** rng.uniform(-3, 3)
        want = np.linalg.lstsq(V, -r, rcond=None)[0]
        got = ks.least_squares(V, r)
        k = np.linalg.cond(V)
        bound = 64 * eps * k * (np.linalg.norm(want) + (k + 1) * np.linalg.norm(V @ want + r)
                                / np.linalg.norm(V, 2))
        assert np.linalg.norm(got - want) <= bound, (n, m, k)
    with pytest.raises(ValueError, match="`V` must be n x m with 0 < m <= n"):
        ks.least_squares(np.ones((2, 3)), np.ones(2))

"""The secular solver of ``diag(d) + z z^T`` on hard cases, both twins.

:func:`fem.rank_one.rank_one_eigh` (the numpy reference) and the compiled
``cosim.sides._structure_step.rank_one_eigh`` against LAPACK's dense
``eigh``.  The bounds are the theory's, in units of ``n eps``: the dense
solver is backward stable (eigenvalues within ``O(n eps ||A||)``); the
secular roots are found to a few ulps each and the eigenvectors from the
Gu-Eisenstat recomputed ``z`` are orthogonal to ``O(n eps)`` with residual
``O(n eps ||A||)``; a deflation (a component of ``z``, or the coupling
left between two entries of ``d`` rotated together) drops at most ``8 eps
max(|d|, |z|^2)`` each.  Each is held at ``4 n eps`` (times ``||A||``
where it scales with the matrix); measured at most 0.35 here.
"""
import numpy as np
import pytest
from scipy.linalg import eigh

from cosim.sides._structure_step import rank_one_eigh as compiled
from fem.rank_one import rank_one_eigh as reference

EPS = np.finfo(float).eps

#: the bounds, in units of n eps (see the module)
UNITS = 4.0


def _case(name, rng):
    m = 60
    d = np.sort(rng.uniform(1.0, 2.0, m))
    z = rng.normal(size=m)
    if name.startswith("cluster"):
        # twelve groups of five, 1e-8 to 1e-14 apart relative (the last
        # within the deflation tolerance: rotated together), or equal
        gap = {"cluster-1e-8": 1e-8, "cluster-1e-12": 1e-12, "cluster-1e-14": 1e-14,
               "cluster-equal": 0.0}[name]
        d = np.repeat(np.linspace(1.0, 2.0, 12), 5) * (1.0 + gap * np.tile(np.arange(5), 12))
    elif name == "zeros":
        z[::3] = 0.0
        z[1::7] = 1e-20
    elif name == "k-small":
        z *= 1e-7
    elif name == "k-below-round-off":         # every coupling deflated
        z *= 1e-9
    elif name == "k-large":
        z *= 1e3
    elif name == "k-huge":                    # |z|^2 6e17: every d alike beside it
        z *= 1e8
    elif name == "wide":                      # a beam with all its modes
        d = np.sort(10.0 ** rng.uniform(0.0, 12.0, m))
        z *= 1e3
    elif name == "unsorted":
        perm = rng.permutation(m)
        d, z = d[perm], z[perm]
    return d, z


CASES = ["random", "cluster-1e-8", "cluster-1e-12", "cluster-1e-14", "cluster-equal", "zeros",
         "k-small", "k-below-round-off", "k-large", "k-huge", "wide", "unsorted"]


@pytest.mark.parametrize("solver", [reference, compiled], ids=["numpy", "compiled"])
@pytest.mark.parametrize("name", CASES)
def test_eigenpairs_against_a_dense_solver(solver, name):
    rng = np.random.default_rng(CASES.index(name))
    d, z = _case(name, rng)
    n = d.size
    A = np.diag(d) + np.outer(z, z)
    size = np.abs(A).max()
    lam, V = solver(d, z)
    dense = eigh(A, eigvals_only=True)
    assert np.abs(np.sort(lam) - dense).max() <= UNITS * n * EPS * np.abs(dense).max()
    assert np.abs(V.T @ V - np.eye(n)).max() <= UNITS * n * EPS
    assert np.abs(A @ V - V * lam).max() <= UNITS * n * EPS * size
    if name in ("zeros", "k-below-round-off"):
        # a deflated component keeps its entry of d and its unit vector
        tol = 8 * EPS * max(np.abs(d).max(), z @ z)       # the solvers' own
        for j in np.flatnonzero(np.abs(z) * np.linalg.norm(z) <= tol):
            k = int(np.argmax(np.abs(V[j])))
            assert lam[k] == d[j] and abs(V[j, k]) == 1.0


def test_the_twins_agree():
    """The compiled solver is the reference's twin: the same operations in
    the same order (only libm's hypot and sqrt may round otherwise), so the
    same eigenpairs to round-off on every case above: eigenvalues as the
    bound above, eigenvectors within 1e-12 (measured 9e-16, clusters 1e-8
    apart included)."""
    for name in CASES:
        d, z = _case(name, np.random.default_rng(CASES.index(name)))
        (la, Va), (lb, Vb) = reference(d, z), compiled(d, z)
        size = np.abs(np.diag(d) + np.outer(z, z)).max()
        assert np.abs(la - lb).max() <= UNITS * d.size * EPS * size, name
        assert np.abs(Va - Vb).max() <= 1e-12, name


def test_a_declined_spring_gets_lapacks_modes(monkeypatch):
    """The host's fallback where the secular iteration does not converge
    (here: made to decline): the modes of diag(omega^2) + z z^T from LAPACK."""
    import fem
    import cosim.sides.fem_closed_form as closed_form
    from cosim.sides.fem import StructureSubsystem
    from couplers import LinearLaw, PointContact
    s = fem.Chain((0.1, 0.1, 0.1), (1e5, 1e5, 1e5), spacing=0.05).assemble()
    sub = StructureSubsystem("chain", s, fem.modes(s), {"top": 0})
    sub.embed_contact(PointContact("c", LinearLaw(1e6), (0.0, 1.0)), 0, -1.0, (0.0, 1e-4))
    monkeypatch.setattr(closed_form, "rank_one_eigh", lambda d, z: None)
    lam, Psi, _ = sub._active_basis((True,))
    z = 1e3 * sub._R[0]
    A = np.diag(sub.omega ** 2) + np.outer(z, z)
    assert np.abs(A @ Psi - Psi * lam).max() <= UNITS * 3 * EPS * np.abs(A).max()
    assert np.abs(Psi.T @ Psi - np.eye(3)).max() <= UNITS * 3 * EPS

"""The modal decomposition is solved once per structure and reused by the
builds of one command (the run, its error estimate's companion, the
accuracy choice's candidates), each build getting arrays of its own."""
import numpy as np

import fem
from fem import modal


def _beam(length=1.0):
    return fem.Beam(length=length, n_elements=12, youngs_modulus=2.1e11, density=7800.0,
                    area=1e-4, second_moment=8.3e-10, left="clamped", right="free").assemble()


def test_the_same_matrices_are_solved_once_and_each_caller_gets_its_own_copy(monkeypatch):
    calls = []
    from fem import integrators
    eigh = integrators.generalized_eigh

    def counted(k, m):
        calls.append(1)
        return eigh(k, m)
    monkeypatch.setattr(integrators, "generalized_eigh", counted)
    monkeypatch.setattr(modal, "_SOLVED", {})
    a = fem.modes(_beam(), n_modes=4)
    b = fem.modes(_beam(), n_modes=4)          # another assembly, the same matrices
    assert len(calls) == 1
    assert np.array_equal(a.omega, b.omega) and np.array_equal(a.shapes, b.shapes)
    assert not np.shares_memory(a.shapes, b.shapes)      # each caller's arrays its own
    assert not np.shares_memory(a.omega, b.omega)
    fem.modes(_beam(length=1.1), n_modes=4)    # other matrices: solved again
    assert len(calls) == 2


def test_the_store_is_bounded(monkeypatch):
    monkeypatch.setattr(modal, "_SOLVED", {})
    for i in range(modal._SOLVED_MAX + 3):
        fem.modes(_beam(length=1.0 + 0.01 * i), n_modes=2)
    assert len(modal._SOLVED) == modal._SOLVED_MAX

"""The sparse eigen-solve runs on one OpenBLAS thread and gives the threads
back after (fem.blas_threads); the modes do not depend on it."""
import numpy as np
import pytest

from fem.blas_threads import one_blas_thread, openblas_controls


def _counts():
    return [get() for get, _ in openblas_controls()]


def test_one_thread_inside_and_the_counts_given_back():
    import scipy.sparse.linalg  # noqa: F401  (loads scipy's OpenBLAS)

    controls = openblas_controls()
    if not controls:
        pytest.skip("no OpenBLAS found in this process (not Linux, or another BLAS)")
    before = _counts()
    controls[0][1](2)                                      # a count to give back
    try:
        start = _counts()
        with one_blas_thread():
            assert _counts() == [1] * len(controls)
        assert _counts() == start
        with pytest.raises(ZeroDivisionError):             # given back on an error too
            with one_blas_thread():
                1 / 0
        assert _counts() == start
    finally:
        for (_, put), n in zip(controls, before):
            put(n)


def test_keep_leaves_the_threads_alone(monkeypatch):
    import scipy.sparse.linalg  # noqa: F401

    controls = openblas_controls()
    if not controls:
        pytest.skip("no OpenBLAS found in this process")
    before = _counts()
    controls[0][1](2)
    try:
        start = _counts()
        monkeypatch.setenv("COSIM_BLAS_THREADS", "keep")
        with one_blas_thread():
            assert _counts() == start
    finally:
        for (_, put), n in zip(controls, before):
            put(n)


def test_the_modes_do_not_depend_on_the_threads(monkeypatch):
    """The sparse path (over 400 DOFs) with one thread and with the threads
    kept: the same frequencies to 1e-10 and the same shapes to 1e-8 of their
    largest entry (a threaded reduction sums in another order)."""
    from fem.modal import DENSE_LIMIT, clear_solved, modes
    from fem.plane import Plane, rectangle

    s = Plane(rectangle(1.0, 0.1, 30, 3), thickness=0.01, youngs_modulus=210e9,
              poisson_ratio=0.3, density=7850.0, fixed=("left",)).assemble()
    assert s.n_dof > DENSE_LIMIT
    clear_solved()
    one = modes(s, n_modes=12)
    monkeypatch.setenv("COSIM_BLAS_THREADS", "keep")
    clear_solved()
    kept = modes(s, n_modes=12)
    clear_solved()
    assert np.allclose(one.omega, kept.omega, rtol=1e-10, atol=0)
    scale = np.abs(one.shapes).max()
    assert np.max(np.abs(one.shapes - kept.shapes)) <= 1e-8 * scale


def test_a_blas_loaded_later_is_found_too():
    # numpy's OpenBLAS first; scipy's own copy, where its wheel bundles one,
    # once its linear algebra loads: each library loaded after is controlled too
    import subprocess
    import sys
    code = ("from fem.blas_threads import openblas_controls, _loaded_libraries\n"
            "a, la = len(openblas_controls()), len(_loaded_libraries())\n"
            "import scipy.linalg\n"
            "print(a, la, len(openblas_controls()), len(_loaded_libraries()))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.split()
    first, libs_first, then, libs_then = map(int, out)
    if first == 0:
        pytest.skip("no OpenBLAS found in this process")
    assert first == libs_first and then == libs_then, out


def test_the_count_is_left_alone_while_other_threads_run():
    # another thread may be inside OpenBLAS: the block then changes nothing
    import threading
    controls = openblas_controls()
    if not controls:
        pytest.skip("no OpenBLAS found in this process")
    before = [get() for get, _ in controls]
    stop = threading.Event()
    other = threading.Thread(target=stop.wait)
    other.start()
    try:
        with one_blas_thread():
            inside = [get() for get, _ in controls]
    finally:
        stop.set()
        other.join()
    assert inside == before

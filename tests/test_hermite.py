"""The one cubic Hermite module of the coupling core against the
polynomial written out, sampled densely."""
from __future__ import annotations

import numpy as np
import pytest

from cosim.core import hermite


def _written_out(d0, v0, d1, v1, h, s):
    return (d0 * (2 * s**3 - 3 * s**2 + 1) + h * v0 * (s**3 - 2 * s**2 + s)
            + d1 * (-2 * s**3 + 3 * s**2) + h * v1 * (s**3 - s**2))


def _cases(n, seed):
    rng = np.random.default_rng(seed)
    for _ in range(n):
        d0, d1 = rng.normal(size=2)
        h = 10.0 ** rng.uniform(-6, 0)
        v0, v1 = rng.normal(size=2) / h
        if rng.random() < 0.2:              # c3 = 0: the derivative is linear
            v1 = 2.0 * (d1 - d0) / h - v0
        yield d0, v0, d1, v1, h


def test_value_and_rate_are_the_hermite_cubic():
    s = np.linspace(0.0, 1.0, 11)
    for d0, v0, d1, v1, h in _cases(50, 3):
        scale = abs(d0) + abs(d1) + h * (abs(v0) + abs(v1))
        p = _written_out(d0, v0, d1, v1, h, s)
        assert np.allclose(hermite.hermite_value(d0, v0, d1, v1, h, s), p,
                           rtol=0, atol=1e-13 * scale)
        x, v = hermite.hermite_point(d0, v0, d1, v1, h, s)
        assert np.allclose(x, p, rtol=0, atol=1e-13 * scale)
        ds = 1e-6
        fd = (_written_out(d0, v0, d1, v1, h, s + ds)
              - _written_out(d0, v0, d1, v1, h, s - ds)) / (2 * ds * h)
        assert np.allclose(v, fd, rtol=1e-6, atol=1e-6 * scale / h)
        # the ends are the data
        assert hermite.hermite_point(d0, v0, d1, v1, h, 1.0) == pytest.approx(
            (d1, v1), rel=1e-12, abs=1e-12 * scale / h)


def test_complex_positions_are_interpolated_componentwise():
    x0, v0, x1, v1, h = 1 + 2j, -3 + 0.5j, 0.5 - 1j, 2 - 4j, 0.3
    s = 0.37
    x, v = hermite.hermite_point(x0, v0, x1, v1, h, s)
    for part in (np.real, np.imag):
        assert part(x) == pytest.approx(_written_out(part(x0), part(v0), part(x1), part(v1),
                                                     h, s), rel=1e-13)


def test_cubic_max_against_dense_sampling():
    s = np.linspace(0.0, 1.0, 200001)
    for d0, v0, d1, v1, h in _cases(300, 29):
        p = _written_out(d0, v0, d1, v1, h, s)
        value, where = hermite.hermite_cubic_max(d0, v0, d1, v1, h)
        assert value == pytest.approx(p.max(), rel=1e-9, abs=1e-9 * abs(d1 - d0)), \
            (d0, v0, d1, v1, h)
        assert 0.0 <= where <= h
        assert _written_out(d0, v0, d1, v1, h, where / h) == pytest.approx(
            value, rel=1e-9, abs=1e-9 * abs(d1 - d0))


def test_the_old_homes_hand_out_the_same_functions():
    """Users imported these from the recorder, the integrators and the
    protocol: the names still work there and are this module's."""
    from cosim.core import ode, recorder, subsystem
    assert recorder.hermite_cubic_max is hermite.hermite_cubic_max
    assert ode.substep_peaks is hermite.substep_peaks
    assert subsystem.hermite_coefficients is hermite.hermite_coefficients

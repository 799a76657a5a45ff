"""The cubic Hermite interpolant in time, in one place.

Between two instants ``h`` [s] apart where a quantity's values ``y0``, ``y1``
and rates ``v0``, ``v1`` are known, the coupling core stands for it by the
cubic Hermite polynomial in the normalised time ``s = (t - t0) / h``:

.. math:: p(s) = c_0 + c_1 s + c_2 s^2 + c_3 s^3,

with ``c0 = y0``, ``c1 = h v0``, ``c2 = 3 (y1 - y0) - h (2 v0 + v1)`` and
``c3 = -2 (y1 - y0) + h (v0 + v1)`` (:func:`hermite_coefficients`), evaluated
by Horner's rule.  The integrators locate a contact's switch on it
(:func:`hermite_value`), the schemes hand a partner port's motion over a step
as its coefficients, and the recorder and the integrators find a
penetration's peak between two samples on it (:func:`hermite_cubic_max`,
:func:`~cosim.core.hermite.substep_peaks`).

The compiled step kernels (``cosim.sides._multibody_step``,
``cosim.sides._structure_step``) keep C twins of these formulas; their tests
hold them to this module.  The cubic Hermite *shape functions* of the beam's
finite elements (:mod:`fem.beam`) are the same polynomials in space and live
with the beam.
"""
from __future__ import annotations

import math

__all__ = ["hermite_coefficients", "hermite_value", "hermite_point", "hermite_cubic_max",
           "substep_peaks"]


def hermite_coefficients(x0, v0, x1, v1, h: float) -> tuple:
    """Coefficients in ``s = (t - t0) / h`` (lowest first) of the cubic
    Hermite through positions ``x0``, ``x1`` with velocities ``v0``, ``v1``
    at the two ends of a step ``h`` (scalars or arrays, real or complex)."""
    dx = x1 - x0
    return x0, h * v0, 3 * dx - h * (2 * v0 + v1), -2 * dx + h * (v0 + v1)


def hermite_value(y0, f0, y1, f1, h: float, s):
    """Value at ``s`` in [0, 1] of the cubic Hermite through ``y0``, ``y1``
    with rates ``f0``, ``f1`` at the ends of a step ``h`` [s] (scalars or
    arrays)."""
    c0, c1, c2, c3 = hermite_coefficients(y0, f0, y1, f1, h)
    return c0 + s * (c1 + s * (c2 + s * c3))


def hermite_point(x0, v0, x1, v1, h: float, s) -> tuple:
    """Value and rate (per second) at ``s`` in [0, 1] of the cubic Hermite
    through ``x0``, ``x1`` with rates ``v0``, ``v1`` at the ends of a step
    ``h`` [s] (scalars or arrays, real or complex).

    The coefficients are those of :func:`hermite_coefficients`, formed here
    without calling it: a multirate side asks for this at every sub-step.
    """
    dx = x1 - x0
    c1, c2, c3 = h * v0, 3 * dx - h * (2 * v0 + v1), -2 * dx + h * (v0 + v1)
    return x0 + s * (c1 + s * (c2 + s * c3)), (c1 + s * (2 * c2 + 3 * s * c3)) / h


def _stationary(c1: float, c2: float, c3: float) -> tuple[float, float]:
    """The roots in ``s`` of ``p'(s) = c1 + 2 c2 s + 3 c3 s^2``, in the form
    that does not cancel (NaN where there is none); a negative discriminant
    (a double root lost to rounding) gives the vertex."""
    qa, qb = 3.0 * c3, 2.0 * c2
    disc = qb * qb - 4.0 * qa * c1
    r = math.sqrt(disc) if disc > 0.0 else 0.0
    q = -0.5 * (qb + (r if qb >= 0.0 else -r))
    return (c1 / q if q != 0.0 else math.nan), (q / qa if qa != 0.0 else math.nan)


def _interior_max(d0: float, v0: float, d1: float, v1: float, h: float) -> tuple[float, float]:
    """Largest value of the cubic Hermite at a stationary point inside
    (0, 1), and its ``s`` (``-inf`` and NaN where there is none)."""
    dd = d1 - d0
    c1 = h * v0
    c2 = 3.0 * dd - h * (2.0 * v0 + v1)
    c3 = -2.0 * dd + h * (v0 + v1)
    best, where = -math.inf, math.nan
    for s in _stationary(c1, c2, c3):
        if 0.0 < s < 1.0:
            p = d0 + s * (c1 + s * (c2 + s * c3))
            if p > best:
                best, where = p, s
    return best, where


def hermite_cubic_max(d0, v0, d1, v1, h) -> tuple[float, float]:
    """Largest value of the cubic Hermite interpolant on [0, h] and where it
    is [s from the start].

    Parameters
    ----------
    d0, v0, d1, v1 : float
        Values and rates [per s] at the two ends.
    h : float
        The interval's length [s].
    """
    best, where = (d0, 0.0) if d0 >= d1 else (d1, 1.0)
    p, s = _interior_max(d0, v0, d1, v1, h)
    if p > best:
        best, where = p, s
    return best, where * h


def substep_peaks(peak, d0, v0, d1, v1, h: float) -> None:
    """Raise each ``peak[j]`` to the largest value on one accepted sub-step
    of the cubic Hermite through ``d0[j]``, ``d1[j]`` with rates ``v0[j]``,
    ``v1[j]`` at its two ends, ``h`` [s] apart.

    This is all the per-sub-step work of locating peak penetrations: the
    end value, and where the rate goes from positive to negative (a maximum
    inside the sub-step) the one root of the interpolant's derivative there
    (``p'(0) > 0 > p'(1)``, so exactly one root in (0, 1)).  The start is
    not looked at: it is the previous sub-step's end.

    Parameters
    ----------
    peak : (n,) float array, updated in place
    d0, v0, d1, v1 : sequences of n floats
        Values [m] and rates [m/s] at the sub-step's start and end.
    h : float
        The sub-step's length [s].
    """
    for j in range(len(peak)):
        p = d1[j]
        if v0[j] > 0.0 > v1[j]:
            p = max(p, _interior_max(d0[j], v0[j], d1[j], v1[j], h)[0])
        if p > peak[j]:
            peak[j] = p

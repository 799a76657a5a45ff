"""Restitution of the Hunt-Crossley family of contact laws, in closed form.

The laws (``couplers.laws``) compute their own damping from a requested
restitution with these relations; ``cosim.studies.analytic`` re-exports them for the
verification suite, so they live here once.  scipy is imported on first use.
"""
from __future__ import annotations

import math

__all__ = ["hunt_crossley_restitution", "hunt_crossley_damping_for_restitution"]


def hunt_crossley_restitution(chi_v0: float, exponent: float = 1.5) -> float:
    """Restitution of a Hunt-Crossley impact ``f = k d^n (1 + chi dd)``.

    A mass ``m`` meets the contact at speed ``v0``; the rebound speed over
    ``v0`` is a function of ``alpha = chi v0`` alone.  It solves

    ``alpha (1 + e) = ln((1 + alpha) / (1 - alpha e))``,

    explicitly ``e = (1 + W0(-(1 + alpha) exp(-(1 + alpha)))) / alpha`` with
    ``W0`` the principal Lambert function; it is evaluated here by root
    finding on the first form, which stays accurate as ``alpha -> 0``.
    ``e = 1 - 2 alpha / 3 + O(alpha^2)``, and ``e < 1/alpha``.

    Parameters
    ----------
    chi_v0 : float
        ``alpha = chi v0`` [-], hysteresis damping [s/m] times approach
        speed [m/s], ``>= 0``.
    exponent : float
        ``n`` [-], ``> 0``.  Checked, but it does not enter: see Notes.

    Returns
    -------
    float
        Restitution ``e`` in ``(0, 1]``.

    Notes
    -----
    Neither ``m``, ``k`` nor ``n`` matter.  With ``v = dd`` and the elastic
    energy ``W = k d^(n+1) / (n+1)``, the motion ``m dv/dt = -k d^n (1 + chi v)``
    becomes ``m v dv / (1 + chi v) = -dW``: ``n`` and ``k`` hide in ``W``.
    Integrating in from ``v0`` to 0 (``W`` from 0 to ``W_max``) and out from
    0 to ``-e v0`` (``W`` back to 0) gives ``H(alpha) = H(-alpha e)`` with
    ``H(s) = s - ln(1 + s)``, the relation above.  The factor ``1 + chi v``
    never reaches zero on the way out (``d/dt (1 + chi v) = -(k chi/m) d^n
    (1 + chi v)``), so the force is never clipped and the contact ends with
    ``d = 0``.  The test suite checks this against the integrated impact for
    several ``n``.
    """
    _checked(exponent, "exponent", "> 0")
    a = _checked(chi_v0, "chi_v0", ">= 0")
    if a == 0.0:
        return 1.0
    h_in = _h(a)
    if a < 1.0:
        # H(-a e) - H(a) is -H(a) < 0 at e = 0 and H(-a) - H(a) > 0 at e = 1
        scale = 1.0 / (a * a)
        from scipy.optimize import brentq
        return brentq(lambda e: (_h(-a * e) - h_in) * scale, 0.0, 1.0, xtol=1e-16,
                      rtol=1e-15, maxiter=200)
    # e is close to 1/a: solve for y = 1 - a e in (0, 1), y - 1 - ln(y) = H(a)
    if h_in > 700.0:                 # y < exp(-700): e = 1/a to double precision
        return 1.0 / a
    from scipy.optimize import brentq
    y = brentq(lambda y: y - 1.0 - math.log(y) - h_in, math.exp(-(h_in + 1.0)), 1.0,
               xtol=1e-300, rtol=1e-15, maxiter=200)
    return (1.0 - y) / a


def hunt_crossley_damping_for_restitution(restitution: float, exponent: float = 1.5) -> float:
    """``alpha = chi v0`` [-] for which a Hunt-Crossley impact has the
    restitution ``e``; the inverse of :func:`hunt_crossley_restitution`.

    Parameters
    ----------
    restitution : float
        ``e`` in ``(0, 1]``.
    exponent : float
        ``n`` [-], ``> 0``; does not enter (see
        :func:`hunt_crossley_restitution`).

    Returns
    -------
    float
        ``alpha >= 0``; the hysteresis damping is ``chi = alpha / v0`` [s/m].
    """
    _checked(exponent, "exponent", "> 0")
    e = float(restitution)
    if not 0.0 < e <= 1.0:
        raise ValueError(f"`restitution` must be in (0, 1], got {restitution!r}")
    if e == 1.0:
        return 0.0
    # e(alpha) falls from 1 at alpha = 0 and stays below 1/alpha
    from scipy.optimize import brentq
    return brentq(lambda a: hunt_crossley_restitution(a) - e, 0.0, 1.0 / e, xtol=1e-15,
                  rtol=1e-15, maxiter=200)


def _h(s: float) -> float:
    """``s - ln(1 + s)`` for ``s > -1``, without cancellation near 0."""
    if abs(s) < 0.05:
        # sum_{j>=2} (-s)^j / j; 14 terms leave a relative error below 1e-18
        return sum((-s) ** j / j for j in range(2, 16))
    return s - math.log1p(s)


def _checked(value, name: str, rule: str) -> float:
    v = float(value)
    ok = math.isfinite(v) and (v > 0 if rule == "> 0" else v >= 0)
    if not ok:
        raise ValueError(f"`{name}` must be {rule}, got {value!r}")
    return v

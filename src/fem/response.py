"""Closed-form response of undamped modes to a polynomial load.

Each mode obeys ``z'' + lam z = a(tau)`` with ``a(tau) = sum_j a_j tau**j``
(``j <= 3``).  For ``lam > 0`` the response is a particular polynomial plus
a harmonic; for ``lam = 0`` (a rigid-body mode) it is the load integrated
twice.  Evaluating it at any instants costs a few array operations, with no
matrix exponential per step length: what an event locator needs to find,
by root finding on the exact solution, where a contact opens or closes.
"""
from __future__ import annotations

import numpy as np

__all__ = ["undamped_response"]

_DEGREE = 3


def undamped_response(lam, z0, dz0, a, tau):
    """Modal displacements and velocities at times ``tau`` after the start.

    Parameters
    ----------
    lam : (m,) array
        Squared circular frequencies [rad^2/s^2], >= 0 (a value below
        ``1e-12 * max(lam)`` counts as a rigid-body mode).
    z0, dz0 : (m,) arrays
        State at ``tau = 0``.
    a : (p + 1, m) array
        Load coefficients in powers of ``tau`` [s], lowest first, ``p <= 3``.
    tau : (k,) array
        Times after the start [s].

    Returns
    -------
    z, dz : (k, m) arrays
    """
    lam = np.asarray(lam, float)
    a = np.atleast_2d(np.asarray(a, float))
    if a.shape[0] > _DEGREE + 1:
        raise ValueError(f"`a` must have at most {_DEGREE + 1} rows (degree <= {_DEGREE}), "
                         f"got {a.shape[0]}")
    c = np.zeros((_DEGREE + 1, lam.size))
    c[:a.shape[0]] = a
    tau = np.asarray(tau, float)[:, None]
    rigid = lam <= 1e-12 * max(float(lam.max(initial=0.0)), 1e-300)
    lam_e = np.where(rigid, 1.0, lam)
    omega = np.sqrt(lam_e)
    # particular polynomial b of P'' + lam P = a (elastic modes)
    b3 = c[3] / lam_e
    b2 = c[2] / lam_e
    b1 = (c[1] - 6.0 * b3) / lam_e
    b0 = (c[0] - 2.0 * b2) / lam_e
    A = z0 - b0
    B = (dz0 - b1) / omega
    wt = tau * omega
    cs, sn = np.cos(wt), np.sin(wt)
    z = b0 + tau * (b1 + tau * (b2 + tau * b3)) + A * cs + B * sn
    dz = b1 + tau * (2.0 * b2 + 3.0 * tau * b3) + omega * (B * cs - A * sn)
    if np.any(rigid):
        t2 = tau * tau
        zr = z0 + dz0 * tau + t2 * (c[0] / 2 + tau * (c[1] / 6 + tau * (c[2] / 12
                                                                       + tau * c[3] / 20)))
        dzr = dz0 + tau * (c[0] + tau * (c[1] / 2 + tau * (c[2] / 3 + tau * c[3] / 4)))
        z = np.where(rigid, zr, z)
        dz = np.where(rigid, dzr, dz)
    return z, dz

"""Closed-form response of undamped modes to a polynomial load.

Each mode obeys ``z'' + lam z = a(tau)`` with ``a(tau) = sum_j a_j tau**j``
(``j <= 3``).  For ``lam > 0`` the response is a particular polynomial plus
a harmonic; for ``lam = 0`` (a rigid-body mode) it is the load integrated
twice.  Evaluating it at any instants costs a few array operations, with no
matrix exponential per step length: what an event locator needs to find,
by root finding on the exact solution, where a contact opens or closes.
:func:`undamped_moments` integrates it against powers of time in closed
form, so that impulses and work over a segment cost O(m) however fast the
fastest mode turns.
"""
from __future__ import annotations

import numpy as np

__all__ = ["undamped_response", "undamped_moments"]

_DEGREE = 3


def undamped_response(lam, z0, dz0, a, tau, rows=None):
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

    rows : (m, p) array, optional
        Return only the combinations ``z @ rows`` and ``dz @ rows`` (for
        instance the displacements of ``p`` points): the response is then
        summed mode by mode without forming the ``(k, m)`` states, in chunks
        of instants, so the memory stays bounded however many instants are
        asked for.

    Returns
    -------
    z, dz : (k, m) arrays, or (k, p) arrays with ``rows``
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
    if rows is not None:
        return _combined(rows, rigid, omega, np.stack([b0, b1, b2, b3]), A, B,
                         np.asarray(z0, float), np.asarray(dz0, float), c, tau)
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


#: instants per chunk of :func:`_combined`: chunk x modes stays near 2**21 values
_CHUNK_VALUES = 2 ** 21


def _combined(rows, rigid, omega, b, A, B, z0, dz0, c, tau):
    """``z @ rows`` and ``dz @ rows`` of :func:`undamped_response`, summed mode
    by mode: the polynomial parts are combined once (O(m p)), the harmonic
    ones by a product of the (chunk, m) cosines and sines with (m, p)
    weights, so the cost is O(k m p) and the memory O(chunk m)."""
    rows = np.asarray(rows, float)
    if rows.ndim != 2 or rows.shape[0] != omega.size:
        raise ValueError(f"`rows` must have shape ({omega.size}, p), got {rows.shape}")
    el = ~rigid
    Pe, we = rows[el], omega[el]
    bp = b[:, el] @ Pe                                         # (4, p)
    wc, ws = A[el, None] * Pe, B[el, None] * Pe                # (me, p)
    vc, vs = we[:, None] * ws, -we[:, None] * wc
    # rigid-body modes: the load integrated twice, powers 0..5 of tau
    Pr = rows[rigid]
    cr = c[:, rigid]
    zr = np.stack([z0[rigid], dz0[rigid], cr[0] / 2, cr[1] / 6, cr[2] / 12, cr[3] / 20]) @ Pr
    dzr = np.stack([dz0[rigid], cr[0], cr[1] / 2, cr[2] / 3, cr[3] / 4]) @ Pr
    k, p = tau.shape[0], rows.shape[1]
    z, dz = np.empty((k, p)), np.empty((k, p))
    step = max(1, _CHUNK_VALUES // max(int(we.size), 1))
    for i in range(0, k, step):
        t = tau[i:i + step]
        wt = t * we
        cs, sn = np.cos(wt), np.sin(wt)
        z[i:i + step] = bp[0] + t * (bp[1] + t * (bp[2] + t * bp[3])) + cs @ wc + sn @ ws
        dz[i:i + step] = bp[1] + t * (2.0 * bp[2] + 3.0 * t * bp[3]) + cs @ vc + sn @ vs
        if Pr.shape[0]:
            z[i:i + step] += _powers(t, zr)
            dz[i:i + step] += _powers(t, dzr)
    return z, dz


def _powers(t, coeffs):
    """``sum_j coeffs[j] t**j`` for instants ``t`` (k, 1) and coeffs (n, p)."""
    out = np.zeros((t.shape[0], coeffs.shape[1]))
    for cj in coeffs[::-1]:
        out = out * t + cj
    return out


#: below this omega L, the moments of cos and sin are summed as series
_SERIES_BELOW = 1.0
_SERIES_TERMS = 12            # (omega L)^24 / 24! < 2e-24


def _trig_moments(omega, length, degree):
    """``int_0^L tau^j cos(omega tau)`` and ``... sin ...`` for ``j <= degree``:
    (degree + 1, m) each.  By parts (a two-term recurrence) where
    ``omega L >= 1``; as power series where it is smaller, which the
    recurrence would lose to cancellation."""
    m = omega.size
    C, S = np.empty((degree + 1, m)), np.empty((degree + 1, m))
    x = omega * length
    big = x >= _SERIES_BELOW
    if np.any(big):
        w, xb = omega[big], x[big]
        cl, sl = np.cos(xb), np.sin(xb)
        c, s = sl / w, (1.0 - cl) / w
        C[0, big], S[0, big] = c, s
        for j in range(1, degree + 1):
            lj = length ** j
            c, s = (lj * sl - j * s) / w, (j * c - lj * cl) / w
            C[j, big], S[j, big] = c, s
    small = ~big
    if np.any(small):
        xs = x[small]
        x2 = xs * xs
        for j in range(degree + 1):
            cc, ss = np.zeros(xs.size), np.zeros(xs.size)
            term = np.ones(xs.size)          # x^(2n) / (2n)!, then x^(2n+1) / (2n+1)!
            sign = 1.0
            for n in range(_SERIES_TERMS):
                cc += sign * term / (2 * n + j + 1)
                term = term * xs / (2 * n + 1)
                ss += sign * term / (2 * n + j + 2)
                term = term * xs / (2 * n + 2)
                sign = -sign
            C[j, small] = length ** (j + 1) * cc
            S[j, small] = length ** (j + 1) * ss
    return C, S


def undamped_moments(lam, z0, dz0, a, length, rows, degree=3):
    """Moments ``int_0^L tau**j (z(tau) @ rows) dtau``, ``j = 0..degree``,
    of the response of :func:`undamped_response`, in closed form.

    Parameters
    ----------
    lam, z0, dz0, a
        As in :func:`undamped_response`.
    length : float
        ``L`` [s].
    rows : (m, p) array
        Combinations of the modes (for instance the displacements of points).
    degree : int
        Highest power of ``tau``.

    Returns
    -------
    (degree + 1, p) array
        [unit of z s^(j+1)]
    """
    lam = np.asarray(lam, float)
    rows = np.asarray(rows, float)
    if rows.ndim != 2 or rows.shape[0] != lam.size:
        raise ValueError(f"`rows` must have shape ({lam.size}, p), got {rows.shape}")
    a = np.atleast_2d(np.asarray(a, float))
    c = np.zeros((_DEGREE + 1, lam.size))
    c[:a.shape[0]] = a
    z0, dz0 = np.asarray(z0, float), np.asarray(dz0, float)
    L = float(length)
    rigid = lam <= 1e-12 * max(float(lam.max(initial=0.0)), 1e-300)
    el = ~rigid
    lam_e = lam[el]
    omega = np.sqrt(lam_e)
    ce = c[:, el]
    b3 = ce[3] / lam_e
    b2 = ce[2] / lam_e
    b1 = (ce[1] - 6.0 * b3) / lam_e
    b0 = (ce[0] - 2.0 * b2) / lam_e
    A = z0[el] - b0
    B = (dz0[el] - b1) / omega
    # polynomial parts: elastic b0..b3 and rigid powers 0..5, combined by rows first
    cr = c[:, rigid]
    poly = np.zeros((6, rows.shape[1]))
    poly[:4] = np.stack([b0, b1, b2, b3]) @ rows[el]
    poly += np.stack([z0[rigid], dz0[rigid], cr[0] / 2, cr[1] / 6, cr[2] / 12,
                      cr[3] / 20]) @ rows[rigid]
    out = np.empty((degree + 1, rows.shape[1]))
    C, S = _trig_moments(omega, L, degree)
    Pa, Pb = A[:, None] * rows[el], B[:, None] * rows[el]
    for j in range(degree + 1):
        q = np.arange(6)
        out[j] = (L ** (q + j + 1) / (q + j + 1)) @ poly + C[j] @ Pa + S[j] @ Pb
    return out

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

from functools import lru_cache
from math import factorial

import numpy as np

__all__ = ["undamped_response", "undamped_moments", "undamped_envelope"]

_DEGREE = 3

#: instants per chunk when ``rows`` is given: chunk x modes stays near 2**21 values
_CHUNK_VALUES = 2 ** 21


def _split(lam, z0, dz0, a):
    """Rigid mask, omega, the particular polynomial's coefficients, the
    harmonic's amplitudes and the padded load of each mode."""
    lam = np.asarray(lam, float)
    a = np.atleast_2d(np.asarray(a, float))
    if a.shape[0] > _DEGREE + 1:
        raise ValueError(f"`a` must have at most {_DEGREE + 1} rows (degree <= {_DEGREE}), "
                         f"got {a.shape[0]}")
    c = np.zeros((_DEGREE + 1, lam.size))
    c[:a.shape[0]] = a
    z0, dz0 = np.asarray(z0, float), np.asarray(dz0, float)
    # an eigen-solver's round-off on lam is about eps * max(lam): values within
    # 45 times that are rigid-body modes.  (A threshold of 1e-12 max(lam) took
    # the first mode of a 512-element beam with all its modes, 5.7e-13
    # max(lam), for a rigid one, which then fell freely under its weight.)
    rigid = lam <= 1e-14 * max(float(lam.max(initial=0.0)), 1e-300)
    lam_e = np.where(rigid, 1.0, lam)
    omega = np.sqrt(lam_e)
    # particular polynomial b of P'' + lam P = a (elastic modes)
    b3 = c[3] / lam_e
    b2 = c[2] / lam_e
    b1 = (c[1] - 6.0 * b3) / lam_e
    b0 = (c[0] - 2.0 * b2) / lam_e
    A = z0 - b0
    B = (dz0 - b1) / omega
    return rigid, omega, (b0, b1, b2, b3), A, B, z0, dz0, c


def _states(rigid, omega, b, A, B, z0, dz0, c, tau):
    """(k, m) states at instants ``tau`` (k, 1)."""
    b0, b1, b2, b3 = b
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


def undamped_response(lam, z0, dz0, a, tau, rows=None):
    """Modal displacements and velocities at times ``tau`` after the start.

    Parameters
    ----------
    lam : (m,) array
        Squared circular frequencies [rad^2/s^2], >= 0 (a value below
        ``1e-14 * max(lam)`` counts as a rigid-body mode).
    z0, dz0 : (m,) arrays
        State at ``tau = 0``.
    a : (p + 1, m) array
        Load coefficients in powers of ``tau`` [s], lowest first, ``p <= 3``.
    tau : (k,) array
        Times after the start [s].
    rows : (m, p) array, optional
        Return only the combinations ``z @ rows`` and ``dz @ rows`` (for
        instance the displacements of ``p`` points), evaluated over chunks
        of instants, so that the memory stays bounded however many instants
        are asked for.

    Returns
    -------
    z, dz : (k, m) arrays, or (k, p) arrays with ``rows``
    """
    parts = _split(lam, z0, dz0, a)
    tau = np.asarray(tau, float)[:, None]
    if rows is None:
        return _states(*parts, tau)
    rows = np.asarray(rows, float)
    m = parts[1].size
    if rows.ndim != 2 or rows.shape[0] != m:
        raise ValueError(f"`rows` must have shape ({m}, p), got {rows.shape}")
    k = tau.shape[0]
    step = max(1, _CHUNK_VALUES // max(m, 1))
    if k <= step:
        z, dz = _states(*parts, tau)
        return z @ rows, dz @ rows
    z, dz = np.empty((k, rows.shape[1])), np.empty((k, rows.shape[1]))
    for i in range(0, k, step):
        zi, dzi = _states(*parts, tau[i:i + step])
        z[i:i + step], dz[i:i + step] = zi @ rows, dzi @ rows
    return z, dz


#: below this omega L, the moments of cos and sin are summed as power series
_SERIES_BELOW = 1.0
_SERIES_TERMS = 12            # (omega L)^24 / 24! < 2e-24


@lru_cache(maxsize=8)
def _series_weights(degree: int):
    """Weights of ``x^(2n)`` in the series of ``int_0^1 u^j cos(x u) du`` and
    of ``x^(2n+1)`` in ``int_0^1 u^j sin(x u) du``: (degree + 1, terms) each."""
    n = np.arange(_SERIES_TERMS)
    j = np.arange(degree + 1)[:, None]
    sign = (-1.0) ** n
    fc = np.array([factorial(2 * k) for k in n], float)
    fs = np.array([factorial(2 * k + 1) for k in n], float)
    return sign / (fc * (2 * n + j + 1)), sign / (fs * (2 * n + j + 2))


def _trig_moments(omega, length, degree):
    """``int_0^L tau^j cos(omega tau)`` and ``... sin ...`` for ``j <= degree``:
    (degree + 1, m) each.  By parts (a two-term recurrence) where
    ``omega L >= 1``; as power series where it is smaller, which the
    recurrence would lose to cancellation."""
    m = omega.size
    x = omega * length
    big = x >= _SERIES_BELOW
    nbig = int(np.count_nonzero(big))
    C, S = np.empty((degree + 1, m)), np.empty((degree + 1, m))
    if nbig:
        w, xb = (omega, x) if nbig == m else (omega[big], x[big])
        cl, sl = np.cos(xb), np.sin(xb)
        c, s = sl / w, (1.0 - cl) / w
        Cb, Sb = [c], [s]
        for j in range(1, degree + 1):
            lj = length ** j
            c, s = (lj * sl - j * s) / w, (j * c - lj * cl) / w
            Cb.append(c)
            Sb.append(s)
        if nbig == m:
            return np.array(Cb), np.array(Sb)
        C[:, big], S[:, big] = Cb, Sb
    small = ~big
    xs = x[small]
    wc, ws = _series_weights(degree)
    powers = (xs * xs)[None, :] ** np.arange(_SERIES_TERMS)[:, None]   # x^(2n)
    scale = length ** np.arange(1, degree + 2)[:, None]
    C[:, small] = scale * (wc @ powers)
    S[:, small] = scale * (ws @ powers) * xs
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
        [unit of z times s^(j+1)]
    """
    rigid, omega, b, A, B, z0, dz0, c = _split(lam, z0, dz0, a)
    rows = np.asarray(rows, float)
    if rows.ndim != 2 or rows.shape[0] != omega.size:
        raise ValueError(f"`rows` must have shape ({omega.size}, p), got {rows.shape}")
    L = float(length)
    # polynomial parts: elastic b0..b3 and rigid powers 0..5, combined by rows first
    poly = np.zeros((6, rows.shape[1]))
    el = ~rigid
    if np.all(el):
        poly[:4] = np.stack(b) @ rows
        Pa, Pb = A[:, None] * rows, B[:, None] * rows
        C, S = _trig_moments(omega, L, degree)
    else:
        cr = c[:, rigid]
        poly[:4] = np.stack(b)[:, el] @ rows[el]
        poly += np.stack([z0[rigid], dz0[rigid], cr[0] / 2, cr[1] / 6, cr[2] / 12,
                          cr[3] / 20]) @ rows[rigid]
        Pa, Pb = A[el, None] * rows[el], B[el, None] * rows[el]
        C, S = _trig_moments(omega[el], L, degree)
    q = np.arange(6)
    j = np.arange(degree + 1)[:, None]
    return (L ** (q + j + 1) / (q + j + 1)) @ poly + C @ Pa + S @ Pb


def undamped_envelope(lam, z0, dz0, a, rows, length):
    """Bounds of the response of :func:`undamped_response` combined by
    ``rows``, over ``0 <= tau <= L``, in O(m p): without evaluating it.

    Each elastic mode is its particular polynomial plus a harmonic
    ``A cos(omega tau) + B sin(omega tau)``, at most ``hypot(A, B)`` in size,
    so ``z(tau) @ rows`` lies within ``E`` of the polynomial ``Q(tau)``.

    Parameters
    ----------
    lam, z0, dz0, a
        As in :func:`undamped_response`.
    rows : (m, p) array
        Combinations of the modes (for instance the displacements of points).
    length : float
        ``L`` [s].

    Returns
    -------
    (Q, E, size) or None
        ``Q`` (4, p) the polynomial's coefficients in powers of ``tau``,
        lowest first; ``E`` (p,) the harmonics' bound; ``size`` (p,) the sum
        of the magnitudes of the terms a value is made of over ``[0, L]``
        (the scale of its round-off).  None where a mode is rigid (its
        polynomial has degree 5; not bounded here).
    """
    rigid, omega, b, A, B, _, _, _ = _split(lam, z0, dz0, a)
    if np.any(rigid):
        return None
    rows = np.asarray(rows, float)
    if rows.ndim != 2 or rows.shape[0] != omega.size:
        raise ValueError(f"`rows` must have shape ({omega.size}, p), got {rows.shape}")
    L = float(length)
    b0, b1, b2, b3 = (np.abs(x) for x in b)
    ar = np.abs(rows)
    E = np.sqrt(A * A + B * B) @ ar
    size = (b0 + L * (b1 + L * (b2 + L * b3)) + np.abs(A) + np.abs(B)) @ ar
    return np.stack(b) @ rows, E, size

"""Eigen-decomposition of a diagonal matrix plus a rank-one term, in O(m^2).

A structure in its own modes is ``diag(omega^2)``; one closed linear spring
at a point adds ``k r r^T`` (``r`` the point's shape row).  The modes of the
sum are the roots of the secular equation

    1 + sum_j z_j^2 / (d_j - lam) = 0,      z = sqrt(k) r,  d = omega^2,

one between each pair of consecutive ``d`` and one above the largest, and
each eigenvector is ``(D - lam)^-1 z`` normalised.  Solving the ``m`` roots
costs O(m) each, so the whole decomposition O(m^2) against O(m^3) for a
dense eigen-solver.

Components of ``z`` below round-off are deflated (their ``d`` and unit
vector kept), and so are entries of ``d`` that the term couples but that
are equal to round-off: a plane rotation moves the pair's coupling onto one
of them, and the other is left with a residual coupling of round-off size,
dropped ([1]_, and LAPACK's ``dlaed2``, which we follow in the criterion).

References
----------
.. [0] G. H. Golub, "Some modified matrix eigenvalue problems", SIAM Review
   15 (1973) 318-334: the secular equation of a rank-one modification.
.. [1] J. R. Bunch, C. P. Nielsen, D. C. Sorensen, "Rank-one modification of
   the symmetric eigenproblem", Numer. Math. 31 (1978) 31-48: interlacing,
   deflation and the secular equation.
.. [2] R.-C. Li, "Solving secular equations stably and efficiently", LAPACK
   Working Note 89 (1993): the two-pole rational model of the iteration.
.. [3] M. Gu, S. C. Eisenstat, "A stable and efficient algorithm for the
   rank-one modification of the symmetric eigenproblem", SIAM J. Matrix
   Anal. Appl. 15 (1994) 1266-1276: recomputing ``z`` from the computed
   roots (Loewner's formula), so the eigenvectors come out orthogonal.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["rank_one_eigh"]

_EPS = np.finfo(float).eps


def rank_one_eigh(d, z, *, max_iterations: int = 50):
    """Eigenvalues and orthonormal eigenvectors of ``diag(d) + z z^T``.

    Parameters
    ----------
    d : (m,) array
        Diagonal (any order).
    z : (m,) array
        The rank-one term's vector.
    max_iterations : int
        Iterations of the root finder before it gives up.

    Returns
    -------
    (lam, V) or None
        ``lam`` (m,) and ``V`` (m, m) with ``V^T V = I`` and
        ``(diag(d) + z z^T) V = V diag(lam)``; eigenvalues are not sorted.
        ``None`` when the iteration did not converge: the caller then uses
        a dense solver.  Entries of ``d`` that the term couples and that are
        equal to round-off are first rotated apart (:func:`_deflate_close`).
    """
    d = np.asarray(d, float)
    z = np.asarray(z, float)
    m = d.size
    if z.shape != (m,):
        raise ValueError(f"`z` must have shape ({m},), got {z.shape}")
    order = np.argsort(d, kind="stable")
    ds, zs = d[order], z[order]
    z2sum = float(zs @ zs)
    V = np.eye(m)
    # deflation: a component whose coupling to the rest is below round-off
    # keeps its diagonal entry and unit vector
    tol = 8.0 * _EPS * max(float(np.abs(ds).max(initial=0.0)), z2sum)
    idx = np.flatnonzero(np.abs(zs) * math.sqrt(z2sum) > tol)
    rotations = []
    if idx.size > 1:
        idx, rotations = _deflate_close(ds, zs, idx, tol)
    if idx.size:
        res = _secular(ds[idx], zs[idx], max_iterations)
        if res is None:
            return None
        lam_k, Vk = res
        V[np.ix_(idx, idx)] = Vk
    lam = ds.copy()
    if idx.size:
        lam[idx] = lam_k
    for i, j, c, s in reversed(rotations):
        V[[i, j]] = c * V[i] + s * V[j], c * V[j] - s * V[i]
    out = np.empty_like(V)
    out[order] = V
    return lam, out


def _deflate_close(d, z, idx, tol):
    """Rotate away the couplings of entries of ``d`` too close to part.

    Two kept entries ``d_i < d_j`` (consecutive among ``idx``) are turned
    by the rotation ``G`` of their plane that takes ``(z_i, z_j)`` to
    ``(0, r)``; ``G diag(d) G^T`` then couples them by ``c s (d_i - d_j)``.
    Where that is at most ``tol`` it is dropped (a perturbation of the
    matrix of round-off size, as in [1]'s deflation): ``i`` keeps
    ``c^2 d_i + s^2 d_j`` and its unit vector, and ``j`` goes on with
    ``s^2 d_i + c^2 d_j`` and ``z_j = r``, compared with the next entry.
    Modifies ``d`` and ``z`` in place; returns the entries still coupled
    (sorted, each pair apart by more than ``2 tol``) and the rotations
    ``(i, j, c, s)`` in the order made."""
    kept = [int(idx[0])]
    rotations = []
    for j in idx[1:]:
        j = int(j)
        i = kept[-1]
        r = math.hypot(z[i], z[j])
        c, s = z[j] / r, z[i] / r
        if abs((d[j] - d[i]) * c * s) <= tol:
            # c^2 d_i + s^2 d_j and s^2 d_i + c^2 d_j, exact where d_i = d_j
            t = s * s * (d[j] - d[i])
            d[i], d[j] = d[i] + t, d[j] - t
            z[i], z[j] = 0.0, r
            rotations.append((i, j, c, s))
            kept[-1] = j
        else:
            kept.append(j)
    return np.array(kept), rotations


def _secular(d, z, max_iterations):
    """Roots and eigenvectors for sorted, distinct ``d`` and non-zero ``z``."""
    n = d.size
    z2 = z * z
    if n == 1:
        return d + z2, np.ones((1, 1))
    i = np.arange(n)
    # each root's origin: the nearer of its two poles, so that d_j - lam is
    # formed as (d_j - d_origin) - tau without cancellation
    mid = 0.5 * (d[:-1] + d[1:])
    fmid = 1.0 + (z2[None, :] / (d[None, :] - mid[:, None])).sum(axis=1)
    right = np.zeros(n, bool)
    right[:-1] = fmid < 0.0                         # root in (mid, d_{i+1})
    k = np.where(right, i + 1, i)
    G = d[None, :] - d[k][:, None]                  # d_j - d_origin
    lo = np.zeros(n)
    hi = np.zeros(n)
    lo[:-1] = np.where(right[:-1], mid - d[1:], 0.0)
    hi[:-1] = np.where(right[:-1], 0.0, mid - d[:-1])
    hi[-1] = z2.sum()
    tau = 0.5 * (lo + hi)
    left_poles = i[None, :] <= i[:, None]           # psi: poles j <= i
    a_col = i                                       # pole d_i
    b_col = np.minimum(i + 1, n - 1)                # pole d_{i+1}
    last = i == n - 1
    rows = i                                        # roots still iterated
    for _ in range(max_iterations):
        # only the rows of unconverged roots: most converge in a few passes
        t = tau[rows]
        delta = G[rows] - t[:, None]                # d_j - lam_i
        T = z2 / delta
        T2 = T / delta
        left = left_poles[rows]
        psi = np.where(left, T, 0.0).sum(axis=1)
        dpsi = np.where(left, T2, 0.0).sum(axis=1)
        phi = T.sum(axis=1) - psi
        dphi = T2.sum(axis=1) - dpsi
        f = 1.0 + psi + phi
        go = np.abs(f) > 8.0 * _EPS * (1.0 + np.abs(psi) + np.abs(phi))
        lo_r = np.where(f < 0.0, t, lo[rows])
        hi_r = np.where(f > 0.0, t, hi[rows])
        r = np.arange(rows.size)
        a = delta[r, a_col[rows]]
        b = delta[r, b_col[rows]]
        s, p = dpsi * a * a, psi - dpsi * a
        S, q = dphi * b * b, phi - dphi * b
        with np.errstate(divide="ignore", invalid="ignore"):
            # two poles: C + s/(a - eta) + S/(b - eta) = 0, root in (a, b)
            C = 1.0 + p + q
            B2 = -(C * (a + b) + s + S)
            C2 = C * a * b + s * b + S * a
            root = np.sqrt(np.maximum(B2 * B2 - 4.0 * C * C2, 0.0))
            qq = -0.5 * (B2 + np.copysign(root, B2))
            r1, r2 = qq / C, C2 / qq
            eta = np.where((r1 > a) & (r1 < b), r1, r2)
            # above the largest pole: C + s/(a - eta) = 0
            eta = np.where(last[rows], a + s / (1.0 + p), eta)
        new = t + eta
        bad = ~np.isfinite(new) | (new <= lo_r) | (new >= hi_r)
        new = np.where(bad, 0.5 * (lo_r + hi_r), new)
        narrow = np.abs(hi_r - lo_r) <= 4.0 * _EPS * np.maximum(np.abs(lo_r), np.abs(hi_r))
        tau[rows] = np.where(go, new, t)
        lo[rows], hi[rows] = lo_r, hi_r
        rows = rows[go & ~narrow]
        if not rows.size:
            break
    else:
        return None
    delta = G - tau[:, None]                        # d_j - lam_i, (n, n)
    lam = d[k] + tau
    # Loewner: the z for which the computed roots are exact
    den = np.empty((n - 1, n))
    kk = np.arange(n - 1)[:, None]
    jj = np.arange(n)[None, :]
    den[:] = np.where(kk < jj, d[kk] - d[jj], d[np.minimum(kk + 1, n - 1)] - d[jj])
    with np.errstate(over="ignore", under="ignore"):
        zhat2 = -delta[n - 1] * np.prod(-delta[:-1] / den, axis=0)
    if not np.all(np.isfinite(zhat2)) or np.any(zhat2 < 0.0):
        return None
    zhat = np.copysign(np.sqrt(zhat2), z)
    V = (zhat[None, :] / delta).T                   # column i: zhat_j / (d_j - lam_i)
    V /= np.linalg.norm(V, axis=0)
    return lam, V

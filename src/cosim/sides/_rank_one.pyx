# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True
# cython: initializedcheck=False, nonecheck=False
"""The rank-one eigen-update of the compiled structure step: the modes of
``diag(d) + z z^T`` (the structure's own modes with one contact spring
closed) by the secular equation, the compiled twin of :mod:`fem.rank_one`
(``tests/test_rank_one.py`` holds the two together).
:class:`cosim.sides._structure_modes.ModalResponse` calls :func:`_rank_one`
through its ``.pxd`` (a C call); :func:`rank_one_eigh` is its Python door.
"""
from libc.math cimport fabs, sqrt, hypot, copysign, isfinite
from libc.float cimport DBL_EPSILON

import numpy as np


cdef int _secular(int n, const double* d, const double* z, double* lam, double* V,
                  int max_iterations, double* work) noexcept nogil:
    """Roots and eigenvectors of ``diag(d) + z z^T`` for sorted, distinct ``d``
    and non-zero ``z`` (:func:`fem.rank_one._secular`, each root iterated on
    its own as the reference iterates its rows): ``lam`` (n), ``V`` (n, n)
    row-major, columns the eigenvectors.  ``work`` holds 2 n^2 + 8 n doubles.
    Returns -1 where the reference returns None."""
    cdef double* G = work                   # (n, n): d_j - d_origin(i)
    cdef double* delta = work + n * n       # (n, n)
    cdef double* z2 = work + 2 * n * n
    cdef double* tau = z2 + n
    cdef double* lo = tau + n
    cdef double* hi = lo + n
    cdef double* kd = hi + n                # d at each root's origin
    cdef double* zhat = kd + n
    cdef double* fm = zhat + n
    cdef double* nrm = fm + n
    cdef int i, j, it, r, kk, ac, bc, left_done
    cdef double mid, f, t, T, T2, psi, dpsi, tot, dtot, phi, dphi, lo_r, hi_r, a, b
    cdef double s_, p_, S_, q_, C, B2, C2, root, qq, r1, r2, eta, new, prod, x, den
    cdef bint go, narrow, bad
    for j in range(n):
        z2[j] = z[j] * z[j]
    if n == 1:
        lam[0] = d[0] + z2[0]
        V[0] = 1.0
        return 0
    for i in range(n):
        if i < n - 1:
            mid = 0.5 * (d[i] + d[i + 1])
            f = 1.0
            for j in range(n):
                f += z2[j] / (d[j] - mid)
            if f < 0.0:                     # root in (mid, d_{i+1})
                kd[i] = d[i + 1]
                lo[i] = mid - d[i + 1]
                hi[i] = 0.0
                fm[i] = i + 1
            else:
                kd[i] = d[i]
                lo[i] = 0.0
                hi[i] = mid - d[i]
                fm[i] = i
        else:
            kd[i] = d[i]
            fm[i] = i
            lo[i] = 0.0
            hi[i] = 0.0
            for j in range(n):
                hi[i] += z2[j]
        for j in range(n):
            G[i * n + j] = d[j] - kd[i]
        tau[i] = 0.5 * (lo[i] + hi[i])
    for r in range(n):
        ac = r
        bc = r + 1 if r + 1 < n else n - 1
        for it in range(max_iterations + 1):
            if it == max_iterations:
                return -1
            t = tau[r]
            psi = 0.0
            dpsi = 0.0
            tot = 0.0
            dtot = 0.0
            for j in range(n):
                x = G[r * n + j] - t
                delta[r * n + j] = x
                T = z2[j] / x
                T2 = T / x
                tot += T
                dtot += T2
                if j <= r:
                    psi += T
                    dpsi += T2
            phi = tot - psi
            dphi = dtot - dpsi
            f = 1.0 + psi + phi
            go = fabs(f) > 8.0 * DBL_EPSILON * (1.0 + fabs(psi) + fabs(phi))
            lo_r = t if f < 0.0 else lo[r]
            hi_r = t if f > 0.0 else hi[r]
            a = delta[r * n + ac]
            b = delta[r * n + bc]
            s_ = dpsi * a * a
            p_ = psi - dpsi * a
            S_ = dphi * b * b
            q_ = phi - dphi * b
            C = 1.0 + p_ + q_
            B2 = -(C * (a + b) + s_ + S_)
            C2 = C * a * b + s_ * b + S_ * a
            x = B2 * B2 - 4.0 * C * C2
            root = sqrt(x if x > 0.0 else 0.0)
            qq = -0.5 * (B2 + copysign(root, B2))
            r1 = qq / C
            r2 = C2 / qq
            eta = r1 if (r1 > a and r1 < b) else r2
            if r == n - 1:
                eta = a + s_ / (1.0 + p_)
            new = t + eta
            bad = not isfinite(new) or new <= lo_r or new >= hi_r
            if bad:
                new = 0.5 * (lo_r + hi_r)
            narrow = fabs(hi_r - lo_r) <= 4.0 * DBL_EPSILON * (
                fabs(lo_r) if fabs(lo_r) > fabs(hi_r) else fabs(hi_r))
            tau[r] = new if go else t
            lo[r] = lo_r
            hi[r] = hi_r
            if not go or narrow:
                break
    for i in range(n):
        for j in range(n):
            delta[i * n + j] = G[i * n + j] - tau[i]
        lam[i] = kd[i] + tau[i]
    # Loewner: the z for which the computed roots are exact
    for j in range(n):
        prod = 1.0
        for kk in range(n - 1):
            if kk < j:
                den = d[kk] - d[j]
            else:
                den = d[kk + 1 if kk + 1 < n else n - 1] - d[j]
            prod *= -delta[kk * n + j] / den
        x = -delta[(n - 1) * n + j] * prod
        if not isfinite(x) or x < 0.0:
            return -1
        zhat[j] = copysign(sqrt(x), z[j])
    for i in range(n):
        nrm[i] = 0.0
        for j in range(n):
            x = zhat[j] / delta[i * n + j]
            V[j * n + i] = x
            nrm[i] += x * x
        nrm[i] = sqrt(nrm[i])
    for j in range(n):
        for i in range(n):
            V[j * n + i] /= nrm[i]
    return 0


def rank_one_eigh(d, z, int max_iterations=50):
    """:func:`fem.rank_one.rank_one_eigh` compiled: ``(lam, V)`` of
    ``diag(d) + z z^T``, or None where the reference declines."""
    cdef int m = len(d)
    ws = np.empty(3 * m * m + 20 * m)
    lam = np.empty(m)
    V = np.empty((m, m))
    cdef double[::1] dv = np.ascontiguousarray(d, dtype=float)
    cdef double[::1] zv = np.ascontiguousarray(z, dtype=float)
    if zv.shape[0] != m:
        raise ValueError(f"`z` must have shape ({m},), got {np.shape(z)}")
    cdef double[::1] w = ws, lv = lam
    cdef double[:, ::1] Vv = V
    if _rank_one(m, &dv[0], &zv[0], &lv[0], &Vv[0, 0], max_iterations, &w[0]):
        return None
    return lam, V


cdef int _rank_one(int m, const double* d, const double* z, double* lam, double* out,
                   int max_iterations, double* work) noexcept nogil:
    """:func:`fem.rank_one.rank_one_eigh` into ``lam`` (m) and ``out`` (m, m)
    row-major; -1 where the reference returns None.  ``work``: 3 m^2 + 20 m."""
    cdef double* ds = work
    cdef double* zs = work + m
    cdef double* order = work + 2 * m        # the sorting permutation (as doubles)
    cdef double* dk = work + 3 * m
    cdef double* zk = work + 4 * m
    cdef double* lk = work + 5 * m
    cdef double* Vk = work + 6 * m           # (n, n)
    cdef double* sec = Vk + m * m            # _secular's 2 n^2 + 8 n
    cdef int* idx = <int*> (sec + 2 * m * m + 8 * m)    # m ints in 2 m doubles' room
    # the rotations of _deflate_close: pairs (i, j) as doubles, c, s
    cdef double* rot = sec + 2 * m * m + 10 * m         # (m, 4)
    cdef int i, j, n, a, b, nrot = 0, ri, rj
    cdef double z2sum = 0.0, dmax = 0.0, tol, x, r, c, s_, di, vi, vj
    # stable argsort of d (insertion sort: once per new set of closed springs)
    for i in range(m):
        j = i
        while j > 0 and d[<int> order[j - 1]] > d[i]:
            order[j] = order[j - 1]
            j -= 1
        order[j] = i
    for i in range(m):
        ds[i] = d[<int> order[i]]
        zs[i] = z[<int> order[i]]
        z2sum += zs[i] * zs[i]
        if fabs(ds[i]) > dmax:
            dmax = fabs(ds[i])
    for i in range(m):
        for j in range(m):
            out[i * m + j] = 0.0
    tol = 8.0 * DBL_EPSILON * (dmax if dmax > z2sum else z2sum)
    n = 0
    x = sqrt(z2sum)
    for i in range(m):
        if fabs(zs[i]) * x > tol:
            if n > 0:
                # _deflate_close: the last kept entry against this one
                a = idx[n - 1]
                r = hypot(zs[a], zs[i])
                c = zs[i] / r
                s_ = zs[a] / r
                if fabs((ds[i] - ds[a]) * c * s_) <= tol:
                    # c^2 d_a + s^2 d_i and s^2 d_a + c^2 d_i, exact where equal
                    di = s_ * s_ * (ds[i] - ds[a])
                    ds[a] = ds[a] + di
                    ds[i] = ds[i] - di
                    zs[a] = 0.0
                    zs[i] = r
                    rot[4 * nrot] = a
                    rot[4 * nrot + 1] = i
                    rot[4 * nrot + 2] = c
                    rot[4 * nrot + 3] = s_
                    nrot += 1
                    idx[n - 1] = i
                    continue
            idx[n] = i
            n += 1
    for a in range(n):
        dk[a] = ds[idx[a]]
        zk[a] = zs[idx[a]]
    if n and _secular(n, dk, zk, lk, Vk, max_iterations, sec):
        return -1
    for i in range(m):
        lam[i] = ds[i]
    # V = I with the kept block replaced; rows back in the original order
    for i in range(m):
        out[(<int> order[i]) * m + i] = 1.0
    for a in range(n):
        lam[idx[a]] = lk[a]
        out[(<int> order[idx[a]]) * m + idx[a]] = 0.0
    for a in range(n):
        for b in range(n):
            out[(<int> order[idx[a]]) * m + idx[b]] = Vk[a * n + b]
    # the rotations undone, last first: rows i, j <- (c v_i + s v_j, c v_j - s v_i)
    for a in range(nrot - 1, -1, -1):
        ri = <int> order[<int> rot[4 * a]]
        rj = <int> order[<int> rot[4 * a + 1]]
        c = rot[4 * a + 2]
        s_ = rot[4 * a + 3]
        for b in range(m):
            vi = out[ri * m + b]
            vj = out[rj * m + b]
            out[ri * m + b] = c * vi + s_ * vj
            out[rj * m + b] = c * vj - s_ * vi
    return 0


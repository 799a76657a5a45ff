# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True
# cython: initializedcheck=False, nonecheck=False
"""The structure's modal response in closed form, compiled (the base of
:class:`cosim.sides._structure_step.StructureStep`, see that module).

A segment between switches of the hosted springs is a linear system under a
polynomial load, stepped exactly in the modes of its set of closed springs:
those modes (kept, from the rank-one update of :mod:`cosim.sides._rank_one`
or asked of the host), the segment's start and load in them, the split of the
response into its polynomial and harmonic parts, the ports' displacements and
their time moments in closed form, and the exact step of a structure that
hosts no contact (its velocity moments by three-point Gauss-Legendre).  The
state it works on is declared in its ``.pxd``.
"""
from libc.math cimport sin, cos, pow, fabs, sqrt

from cosim.sides._rank_one cimport _rank_one

import numpy as np

#: below this omega L, the moments of cos and sin are summed as power series
#: (as :mod:`fem.response`)
cdef double SERIES_BELOW = 1.0

#: Gauss-Legendre nodes and weights on [0, 1] (as the reference's ``_GAUSS``)
cdef double[3] GAUSS_NODES = [0.5 - sqrt(15.0) / 10, 0.5, 0.5 + sqrt(15.0) / 10]
cdef double[3] GAUSS_WEIGHTS = [5.0 / 18.0, 8.0 / 18.0, 5.0 / 18.0]


cdef class ModalResponse:
    """The modal state and closed-form response of one structure's compiled
    step (its fields are set by :class:`cosim.sides._structure_step.StructureStep`)."""

    # ------------------------------------------------- closed-form response
    cdef void _split(self, const double* lam) noexcept nogil:
        """:func:`fem.response._split` of ``(lam, z0, dz0, aS)``."""
        cdef int i, m = self.m
        cdef double lmax = 0.0, le
        for i in range(m):
            if lam[i] > lmax:
                lmax = lam[i]
        if lmax < 1e-300:
            lmax = 1e-300
        for i in range(m):
            self.rigid[i] = lam[i] <= 1e-14 * lmax
            le = 1.0 if self.rigid[i] else lam[i]
            self.om[i] = sqrt(le)
            self.b3[i] = self.aS[3, i] / le
            self.b2[i] = self.aS[2, i] / le
            self.b1[i] = (self.aS[1, i] - 6.0 * self.b3[i]) / le
            self.b0[i] = (self.aS[0, i] - 2.0 * self.b2[i]) / le
            self.A[i] = self.z0[i] - self.b0[i]
            self.B[i] = (self.dz0[i] - self.b1[i]) / self.om[i]

    cdef inline void _mode(self, int i, double tau, double* z, double* dz) noexcept nogil:
        """Mode ``i``'s displacement and velocity at ``tau`` (:func:`fem.response._states`)."""
        cdef double wt, cs, sn, t2
        if self.rigid[i]:
            t2 = tau * tau
            z[0] = self.z0[i] + self.dz0[i] * tau + t2 * (
                self.aS[0, i] / 2 + tau * (self.aS[1, i] / 6 + tau * (
                    self.aS[2, i] / 12 + tau * self.aS[3, i] / 20)))
            dz[0] = self.dz0[i] + tau * (self.aS[0, i] + tau * (
                self.aS[1, i] / 2 + tau * (self.aS[2, i] / 3 + tau * self.aS[3, i] / 4)))
            return
        wt = tau * self.om[i]
        cs = cos(wt)
        sn = sin(wt)
        z[0] = (self.b0[i] + tau * (self.b1[i] + tau * (self.b2[i] + tau * self.b3[i]))
                + self.A[i] * cs + self.B[i] * sn)
        dz[0] = (self.b1[i] + tau * (2.0 * self.b2[i] + 3.0 * tau * self.b3[i])
                 + self.om[i] * (self.B[i] * cs - self.A[i] * sn))

    cdef void _ports(self, double tau, const double* P, double* W, double* DW) noexcept nogil:
        """Ports' displacements and velocities along the field at ``tau``
        (``P`` (m, n_p) row-major: the ports' rows in the segment's modes)."""
        cdef int i, p, npt = self.np_
        cdef double z, dz
        for p in range(npt):
            W[p] = 0.0
            DW[p] = 0.0
        for i in range(self.m):
            self._mode(i, tau, &z, &dz)
            for p in range(npt):
                W[p] += z * P[i * npt + p]
                DW[p] += dz * P[i * npt + p]

    cdef double _port(self, double tau, const double* P, int p, double* dw) noexcept nogil:
        """One port's displacement (and velocity into ``dw``) at ``tau``."""
        cdef int i, npt = self.np_
        cdef double z, dz, w = 0.0, v = 0.0
        for i in range(self.m):
            self._mode(i, tau, &z, &dz)
            w += z * P[i * npt + p]
            v += dz * P[i * npt + p]
        dw[0] = v
        return w

    cdef void _modes_at(self, double tau) noexcept nogil:
        """Every mode's state at ``tau`` into ``zt``, ``dzt``."""
        cdef int i
        for i in range(self.m):
            self._mode(i, tau, &self.zt[i], &self.dzt[i])

    cdef void _trig_moments(self, double L) noexcept nogil:
        """:func:`fem.response._trig_moments` of the elastic modes, degree 3."""
        cdef int i, j, n
        cdef double w, x, cl, sl, c, s, cn, lj, x2, xp, fc, fs, sc, ss, sign
        for i in range(self.m):
            if self.rigid[i]:
                continue
            w = self.om[i]
            x = w * L
            if x >= SERIES_BELOW:
                cl = cos(x)
                sl = sin(x)
                c = sl / w
                s = (1.0 - cl) / w
                self.C[0, i] = c
                self.S[0, i] = s
                for j in range(1, DEG1):
                    lj = pow(L, j)
                    cn = (lj * sl - j * s) / w
                    s = (j * c - lj * cl) / w
                    c = cn
                    self.C[j, i] = c
                    self.S[j, i] = s
            else:
                x2 = x * x
                for j in range(DEG1):
                    sc = 0.0
                    ss = 0.0
                    xp = 1.0
                    fc = 1.0            # (2n)!
                    fs = 1.0            # (2n + 1)!
                    sign = 1.0
                    for n in range(SERIES_TERMS):
                        if n > 0:
                            xp = xp * x2
                            fc = fc * (2 * n - 1) * (2 * n)
                            fs = fs * (2 * n) * (2 * n + 1)
                            sign = -sign
                        sc += sign / (fc * (2 * n + j + 1)) * xp
                        ss += sign / (fs * (2 * n + j + 2)) * xp
                    self.C[j, i] = pow(L, j + 1) * sc
                    self.S[j, i] = pow(L, j + 1) * ss * x

    cdef void _moments(self, double L, const double* P) noexcept nogil:
        """``Wm[j, p] = int_0^L tau^j w_p`` (:func:`fem.undamped_moments`, degree 3)."""
        cdef int i, j, p, qq, npt = self.np_
        cdef double pq, r
        cdef double poly[6]
        self._trig_moments(L)
        for p in range(npt):
            for qq in range(6):
                poly[qq] = 0.0
            for j in range(DEG1):
                self.Wm[j, p] = 0.0
            for i in range(self.m):
                r = P[i * npt + p]
                if self.rigid[i]:
                    poly[0] += self.z0[i] * r
                    poly[1] += self.dz0[i] * r
                    poly[2] += self.aS[0, i] / 2 * r
                    poly[3] += self.aS[1, i] / 6 * r
                    poly[4] += self.aS[2, i] / 12 * r
                    poly[5] += self.aS[3, i] / 20 * r
                else:
                    poly[0] += self.b0[i] * r
                    poly[1] += self.b1[i] * r
                    poly[2] += self.b2[i] * r
                    poly[3] += self.b3[i] * r
                    for j in range(DEG1):
                        self.Wm[j, p] += (self.C[j, i] * (self.A[i] * r)
                                          + self.S[j, i] * (self.B[i] * r))
            for j in range(DEG1):
                pq = 0.0
                for qq in range(6):
                    pq += pow(L, qq + j + 1) / (qq + j + 1) * poly[qq]
                self.Wm[j, p] += pq

    # ---------------------------------------------------------- the bases
    cdef int _basis(self, long long mask):
        """Slot of the kept modes of the closed set ``mask``, asked of the
        host when not kept."""
        cdef int s, i, j, p, k, m = self.m, npt = self.np_
        cdef double acc
        for s in range(self.n_bases):
            if self.b_mask[s] == mask:
                return s
        s = self.next_base
        if self._rank_one_basis(mask, s):
            self.n_host_bases += 1
            lam, Psi, wmax = self.host_basis(tuple(bool(self.active[k])
                                                   for k in range(self.nc)))
            self.b_wmax[s] = wmax
            lam = np.asarray(lam, float)
            for i in range(m):
                self.b_lam[s, i] = lam[i]
            if Psi is None:
                self.b_ident[s] = 1
                for i in range(m):
                    for p in range(npt):
                        self.b_P[s, i, p] = self.R[p, i]
            else:
                self.b_ident[s] = 0
                Psi = np.ascontiguousarray(Psi, dtype=float)
                np.asarray(self.b_psi)[s] = Psi
                PR = Psi.T @ np.asarray(self.R).T
                for i in range(m):
                    for p in range(npt):
                        self.b_P[s, i, p] = PR[i, p]
        self.next_base = (s + 1) % MAX_BASES
        if self.n_bases < MAX_BASES:
            self.n_bases += 1
        self.b_mask[s] = mask
        return s

    cdef int _rank_one_basis(self, long long mask, int s) noexcept nogil:
        """Slot ``s`` filled with the modes of ``mask`` where no spring or one
        spring is closed, as the host's ``_active_basis`` makes them; -1 where
        the host must (several springs, or the rank-one update declined)."""
        cdef int i, j, k, p, m = self.m, npt = self.np_, one = -1, count = 0
        cdef double c, lmax, acc
        for k in range(self.nc):
            if self.active[k]:
                one = k
                count += 1
        if count == 0:                      # the structure's own modes
            self.b_ident[s] = 1
            for i in range(m):
                self.b_lam[s, i] = self.lam0[i]
            self.b_wmax[s] = self.wmax0
            for i in range(m):
                for p in range(npt):
                    self.b_P[s, i, p] = self.R[p, i]
            return 0
        if count > 1:
            return -1
        p = self.c_port[one]
        c = self.c_nre[one] * self.dirs[p, 0] + self.c_nim[one] * self.dirs[p, 1]
        for i in range(m):
            self.r1_z[i] = sqrt(self.c_k[one]) * fabs(c) * self.R[p, i]
        if _rank_one(m, &self.lam0[0], &self.r1_z[0], &self.r1_lam[0], &self.r1_V[0], 50,
                     &self.r1_work[0]):
            return -1
        self.b_ident[s] = 0
        lmax = self.r1_lam[0]
        for i in range(m):
            if self.r1_lam[i] > lmax:
                lmax = self.r1_lam[i]
            self.b_lam[s, i] = self.r1_lam[i] if self.r1_lam[i] > 0.0 else 0.0
            for j in range(m):
                self.b_psi[s, i, j] = self.r1_V[i * m + j]
        self.b_wmax[s] = sqrt(lmax if lmax > 0.0 else 0.0)
        for i in range(m):
            for p in range(npt):
                acc = 0.0
                for k in range(m):
                    acc += self.b_psi[s, k, i] * self.R[p, k]
                self.b_P[s, i, p] = acc
        return 0

    # ------------------------------------------- a segment's start and end
    cdef void _to_segment(self, int s) noexcept nogil:
        """The segment's start and load in the modes of slot ``s``."""
        cdef int i, j, k, m = self.m
        cdef double z, dz
        if self.b_ident[s]:
            for i in range(m):
                self.z0[i] = self.q[i]
                self.dz0[i] = self.dq[i]
                for j in range(DEG1):
                    self.aS[j, i] = self.a[j, i]
            return
        for i in range(m):
            z = 0.0
            dz = 0.0
            for k in range(m):
                z += self.b_psi[s, k, i] * self.q[k]
                dz += self.b_psi[s, k, i] * self.dq[k]
            self.z0[i] = z
            self.dz0[i] = dz
            for j in range(DEG1):
                z = 0.0
                for k in range(m):
                    z += self.a[j, k] * self.b_psi[s, k, i]
                self.aS[j, i] = z

    cdef void _end_state(self, int s, double tau) noexcept nogil:
        """Modal state at ``tau`` after the segment's start into ``q``, ``dq``."""
        cdef int i, k, m = self.m
        cdef double z, dz
        self._modes_at(tau)
        if self.b_ident[s]:
            for i in range(m):
                self.q[i] = self.zt[i]
                self.dq[i] = self.dzt[i]
            return
        for i in range(m):
            z = 0.0
            dz = 0.0
            for k in range(m):
                z += self.b_psi[s, i, k] * self.zt[k]
                dz += self.b_psi[s, i, k] * self.dzt[k]
            self.q[i] = z
            self.dq[i] = dz

    # ------------------------------------------ the step with no contact
    cdef void _free(self, double* x, double* pm) noexcept nogil:
        """:meth:`step_free` on ``x`` (2 m) and ``pm`` ((3, 2 n_p) row-major)."""
        cdef int m = self.m, npt = self.np_, i, j, p, g
        cdef double col[DEG1]
        cdef double out[DEG1]
        cdef double sn, wh, v
        for i in range(m):
            for j in range(self.g_len):
                col[j] = self.Gin[j, i]
            _reparam(col, self.g_len, 0.0, 1.0 / self.h, out)
            for j in range(DEG1):
                self.aS[j, i] = out[j] if j < self.g_len else 0.0
            self.z0[i] = x[i]
            self.dz0[i] = x[m + i]
        self._split(&self.lam0[0])
        if self.loaded:
            for g in range(3):
                sn = GAUSS_NODES[g]
                wh = GAUSS_WEIGHTS[g] * self.h
                self._modes_at(sn * self.h)
                for p in range(npt):
                    v = 0.0
                    for i in range(m):
                        v += self.R[p, i] * self.dzt[i]
                    pm[2 * p] += wh * (v * self.dirs[p, 0])
                    pm[2 * p + 1] += wh * (v * self.dirs[p, 1])
                    pm[2 * npt + 2 * p] += wh * (sn * (v * self.dirs[p, 0]))
                    pm[2 * npt + 2 * p + 1] += wh * (sn * (v * self.dirs[p, 1]))
                    pm[4 * npt + 2 * p] += wh * (sn * sn * (v * self.dirs[p, 0]))
                    pm[4 * npt + 2 * p + 1] += wh * (sn * sn * (v * self.dirs[p, 1]))
        self._modes_at(self.h)
        for i in range(m):
            x[i] = self.zt[i]
            x[m + i] = self.dzt[i]


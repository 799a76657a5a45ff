# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True
# cython: initializedcheck=False, nonecheck=False
"""The hosted springs' phases of the structure's compiled step (see
:mod:`cosim.sides._structure_step`): each contact's penetration on the exact
solution, the segment's load with the closed springs, the bound that spares
an open segment its probes, the springs' impulses, moments and work and the
ports' velocity moments in closed form, the switches located (sampled, then
safeguarded Newton) and each closed spring's largest penetration (Illinois
regula falsi where its rate falls through zero).  The modal response it
steps is :class:`cosim.sides._structure_modes.ModalResponse`.
"""
from libc.math cimport pow, ceil, fabs, sqrt, INFINITY
from libc.float cimport DBL_EPSILON

from cosim.core._side_face cimport SwitchLog, free_log, log_switch
from cosim.sides._structure_modes cimport DEG1, _reparam, ModalResponse

cdef enum:
    SEGMENTS = 10000

#: segments (contact switches) one step may take before it is said to stall
MAX_SEGMENTS = SEGMENTS


class StalledStep(RuntimeError):
    """The compiled step stopped advancing (a switch found again and again at
    one instant); the host redoes the step with the numpy reference."""



cdef class ContactPhases(ModalResponse):
    """The contact phases of one structure's compiled step, and the step
    (:meth:`step`, which :class:`cosim.sides._structure_step.StructureStep`
    inherits)."""

    # ------------------------------------------------------------- contacts
    cdef inline void _partner(self, int k, double time, double* xr, double* xi, double* vr,
                              double* vi) noexcept nogil:
        """Partner position and velocity at ``time`` (``np.polyval``'s Horner)."""
        cdef int i
        cdef double s = (time - self.m_t0[k]) / self.m_h[k], ar = 0.0, ai = 0.0
        for i in range(self.m_len[k] - 1, -1, -1):
            ar = ar * s + self.m_re[k, i]
            ai = ai * s + self.m_im[k, i]
        xr[0], xi[0] = ar, ai
        ar, ai = 0.0, 0.0
        for i in range(self.dm_len[k] - 1, -1, -1):
            ar = ar * s + self.dm_re[k, i]
            ai = ai * s + self.dm_im[k, i]
        vr[0], vi[0] = ar, ai

    cdef inline void _gap(self, int k, double time, double w, double dw, double* d,
                          double* dd) noexcept nogil:
        """Penetration and rate of contact ``k`` for its port at ``w``, ``dw``
        along the field (:meth:`EmbeddedContact.penetrations`)."""
        cdef int p = self.c_port[k]
        cdef double xr, xi, vr, vi
        self._partner(k, time, &xr, &xi, &vr, &vi)
        xr = (self.ref[p, 0] + w * self.dirs[p, 0]) - xr
        xi = (self.ref[p, 1] + w * self.dirs[p, 1]) - xi
        vr = dw * self.dirs[p, 0] - vr
        vi = dw * self.dirs[p, 1] - vi
        d[0] = self.c_off[k] - self.c_side[k] * (self.c_nre[k] * xr + self.c_nim[k] * xi)
        dd[0] = -self.c_side[k] * (self.c_nre[k] * vr + self.c_nim[k] * vi)


    # ------------------------------------------------------------ stepping
    cdef void _segment_load(self, double tc) noexcept nogil:
        """:meth:`StructureSubsystem._segment_load` into ``a`` (DEG1, m)."""
        cdef int j, i, k, p, m = self.m
        cdef double col[DEG1]
        cdef double out[DEG1]
        cdef double outi[DEG1]
        cdef double c, ck, base, nre, nim
        for j in range(DEG1):
            for i in range(m):
                self.a[j, i] = 0.0
        for i in range(m):
            for j in range(self.g_len):
                col[j] = self.Gin[j, i]
            _reparam(col, self.g_len, (tc - self.t) / self.h, 1.0 / self.h, out)
            for j in range(self.g_len):
                self.a[j, i] = out[j]
        for k in range(self.nc):
            if not self.active[k]:
                continue
            p = self.c_port[k]
            nre, nim = self.c_nre[k], self.c_nim[k]
            c = nre * self.dirs[p, 0] + nim * self.dirs[p, 1]
            _reparam(&self.m_re[k, 0], self.m_len[k], (tc - self.m_t0[k]) / self.m_h[k],
                          1.0 / self.m_h[k], out)
            _reparam(&self.m_im[k, 0], self.m_len[k], (tc - self.m_t0[k]) / self.m_h[k],
                          1.0 / self.m_h[k], outi)
            base = self.c_side[k] * c * self.c_k[k] * (
                self.c_off[k] - self.c_side[k] * (nre * self.ref[p, 0] + nim * self.ref[p, 1]))
            ck = c * self.c_k[k]
            for j in range(self.m_len[k]):
                out[j] = nre * out[j] + nim * outi[j]
            for i in range(m):
                self.a[0, i] += base * self.R[p, i]
                for j in range(self.m_len[k]):
                    self.a[j, i] += ck * (out[j] * self.R[p, i])


    cdef bint _stays_open(self, double tc, double L, const double* P) noexcept nogil:
        """:meth:`StructureSubsystem._stays_open`: True where every contact,
        open at the segment's start, provably stays open over ``[0, L]``.

        Contact ``k``'s penetration is ``f(tau) + beta (w_p - Q_p)(tau)``:
        ``f`` the partner's motion and the offset less ``beta`` times the
        port's particular polynomial ``Q_p`` (degree 3), and ``w_p - Q_p`` a
        sum of harmonics, at most ``E_p = sum_i |P_ip| |(A_i, B_i)|``.  With
        ``tau^j`` in ``[0, L^j]``, ``f(tau) <= f_0 + sum_j max(f_j, 0) L^j``;
        that bound plus ``|beta| E_p`` below ``-margin`` (the probes' own
        round-off, with room to spare) means no probe could find it closed.
        A rigid mode (its polynomial of degree 5) is not bounded here."""
        cdef int i, j, k, p, n, m = self.m, npt = self.np_
        cdef double beta, nre, nim, E, S, amp, Lj, f, bound, margin, pr
        cdef double alpha[DEG1]
        cdef double alphai[DEG1]
        cdef double Q[DEG1]
        cdef double wL = 0.0
        for i in range(m):
            if self.rigid[i]:
                return False
            if self.om[i] * L > wL:
                wL = self.om[i] * L
        # relative to the terms' sizes S: the probes sum m modes, each with
        # its phase omega tau rounded (about omega L eps), and the gap a few
        # terms more; plus 1e-9 of S, for a segment that near a touch loses
        # nothing by being probed
        margin = 1e-9 + 16.0 * DBL_EPSILON * (m + 4 + wL)
        for k in range(self.nc):
            p = self.c_port[k]
            nre, nim = self.c_nre[k], self.c_nim[k]
            beta = self.c_side[k] * (nre * self.dirs[p, 0] + nim * self.dirs[p, 1])
            n = self.m_len[k]
            for j in range(DEG1):
                alpha[j] = 0.0
                alphai[j] = 0.0
                Q[j] = 0.0
            _reparam(&self.m_re[k, 0], n, (tc - self.m_t0[k]) / self.m_h[k],
                          1.0 / self.m_h[k], alpha)
            _reparam(&self.m_im[k, 0], n, (tc - self.m_t0[k]) / self.m_h[k],
                          1.0 / self.m_h[k], alphai)
            for j in range(n):
                alpha[j] = self.c_side[k] * (nre * alpha[j] + nim * alphai[j])
            S = fabs(self.c_off[k]) + fabs(nre * self.ref[p, 0] + nim * self.ref[p, 1])
            alpha[0] += self.c_off[k] - self.c_side[k] * (nre * self.ref[p, 0]
                                                          + nim * self.ref[p, 1])
            E = 0.0
            amp = 0.0
            for i in range(m):
                pr = P[i * npt + p]
                Q[0] += pr * self.b0[i]
                Q[1] += pr * self.b1[i]
                Q[2] += pr * self.b2[i]
                Q[3] += pr * self.b3[i]
                E += fabs(pr) * sqrt(self.A[i] * self.A[i] + self.B[i] * self.B[i])
                amp += fabs(pr) * (fabs(self.b0[i]) + L * (fabs(self.b1[i]) + L * (
                    fabs(self.b2[i]) + L * fabs(self.b3[i]))) + fabs(self.A[i])
                    + fabs(self.B[i]))
            bound = alpha[0] - beta * Q[0]
            Lj = 1.0
            for j in range(DEG1):
                if j:
                    Lj *= L
                    f = alpha[j] - beta * Q[j]
                    if f > 0.0:
                        bound += f * Lj
                S += fabs(alpha[j]) * Lj
            S += fabs(beta) * amp
            if bound + fabs(beta) * E >= -margin * S:
                return False
        return True

    cdef void _quadratures(self, double[::1] aux, double[:, ::1] pm, double tc, double L,
                           const double* P, bint any_active) noexcept nogil:
        """:meth:`StructureSubsystem._segment_quadratures` over ``[tc, tc + L]``."""
        cdef int k, p, j, n, npt = self.np_
        cdef double beta, nre, nim, a0, ia0, ia1, aL, da, sig, s0, s1, x
        cdef double alpha[DEG1]
        cdef double alphai[DEG1]
        cdef double dw
        if not self.loaded and not any_active:
            return
        self._moments(L, P)
        for p in range(npt):
            self.W0[p] = self._port(0.0, P, p, &dw)
            self.WL[p] = self._port(L, P, p, &dw)
        sig = tc - self.t
        for k in range(self.nc):
            if not self.active[k]:
                continue
            p = self.c_port[k]
            nre, nim = self.c_nre[k], self.c_nim[k]
            beta = self.c_side[k] * (nre * self.dirs[p, 0] + nim * self.dirs[p, 1])
            n = self.m_len[k]
            _reparam(&self.m_re[k, 0], n, (tc - self.m_t0[k]) / self.m_h[k],
                          1.0 / self.m_h[k], alpha)
            _reparam(&self.m_im[k, 0], n, (tc - self.m_t0[k]) / self.m_h[k],
                          1.0 / self.m_h[k], alphai)
            for j in range(n):
                alpha[j] = self.c_side[k] * (nre * alpha[j] + nim * alphai[j])
            alpha[0] += self.c_off[k] - self.c_side[k] * (nre * self.ref[p, 0]
                                                          + nim * self.ref[p, 1])
            ia0 = 0.0
            ia1 = 0.0
            for j in range(n):
                ia0 += alpha[j] * (pow(L, j + 1) / (j + 1))
                ia1 += alpha[j] * (pow(L, j + 2) / (j + 2))
            aux[4 * k] += self.c_k[k] * (ia0 - beta * self.Wm[0, p])
            aux[4 * k + 2] += self.c_k[k] * (sig * ia0 + ia1 - beta * (
                sig * self.Wm[0, p] + self.Wm[1, p]))
            da = 0.0
            for j in range(1, n):
                da += (alpha[j] * j) * self.Wm[j - 1, p]
            aL = 0.0
            for j in range(n - 1, -1, -1):
                aL = aL * L + alpha[j]
            aux[4 * k + 3] += beta * self.c_k[k] * (
                aL * self.WL[p] - alpha[0] * self.W0[p] - da
                - 0.5 * beta * (self.WL[p] * self.WL[p] - self.W0[p] * self.W0[p]))
        if self.loaded:
            s0 = sig / self.h
            s1 = (sig + L) / self.h
            for p in range(npt):
                x = self.WL[p] - self.W0[p]
                pm[0, 2 * p] += x * self.dirs[p, 0]
                pm[0, 2 * p + 1] += x * self.dirs[p, 1]
                x = s1 * self.WL[p] - s0 * self.W0[p] - self.Wm[0, p] / self.h
                pm[1, 2 * p] += x * self.dirs[p, 0]
                pm[1, 2 * p + 1] += x * self.dirs[p, 1]
                x = (s1 * s1 * self.WL[p] - s0 * s0 * self.W0[p]
                     - 2.0 * (sig * self.Wm[0, p] + self.Wm[1, p]) / (self.h * self.h))
                pm[2, 2 * p] += x * self.dirs[p, 0]
                pm[2, 2 * p + 1] += x * self.dirs[p, 1]

    cdef double _switch_time(self, int k, bint was_closed, double lo, double hi, double d_lo,
                             double d_hi, double tol, double tc,
                             const double* P) noexcept nogil:
        """:meth:`StructureSubsystem._switch_time`: safeguarded Newton on the
        exact solution, started by regula falsi."""
        cdef int it, p = self.c_port[k]
        cdef double x, width, dx, rate, xn, w, dw
        if d_lo != d_hi:
            x = lo + (hi - lo) * (d_lo / (d_lo - d_hi))
        else:
            x = 0.5 * (lo + hi)
        for it in range(100):
            if not (lo < x and x < hi):
                x = 0.5 * (lo + hi)
            width = hi - lo
            w = self._port(x, P, p, &dw)
            self._gap(k, tc + x, w, dw, &dx, &rate)
            if (dx > 0) == was_closed:
                lo = x
            else:
                hi = x
            if hi - lo <= tol:
                break
            if rate != 0.0:
                xn = x - dx / rate
            else:
                xn = 0.5 * (lo + hi)
            if fabs(xn - x) < tol:
                xn = x + 0.5 * tol if x == lo else x - 0.5 * tol
            elif not (lo < xn and xn < hi) or hi - lo > 0.5 * width:
                xn = 0.5 * (lo + hi)
            x = xn
        return hi

    cdef double _rate_root_value(self, int k, double tc, double lo, double hi, double v_lo,
                                 double v_hi, const double* P) noexcept nogil:
        """:meth:`StructureSubsystem._rate_root_value`: the penetration of
        contact ``k`` where its rate, ``v_lo > 0 >= v_hi`` at ``lo`` and ``hi``
        after ``tc``, falls through zero (Illinois regula falsi, at most 60
        evaluations)."""
        cdef int it, side = 0, p = self.c_port[k]
        cdef double d_best = -INFINITY, x, dx, vx, w, dw, tol
        x = fabs(tc) + hi
        tol = 1e-14 * (x if x > 1.0 else 1.0)
        for it in range(60):
            if v_hi == v_lo:
                x = hi
            else:
                x = (lo * v_hi - hi * v_lo) / (v_hi - v_lo)
            if not (lo <= x and x <= hi):
                x = 0.5 * (lo + hi)
            w = self._port(x, P, p, &dw)
            self._gap(k, tc + x, w, dw, &dx, &vx)
            if dx > d_best:
                d_best = dx
            if vx > 0.0:
                lo = x
                v_lo = vx
                if side == 1:
                    v_hi *= 0.5
                side = 1
            else:
                hi = x
                v_hi = vx
                if side == -1:
                    v_lo *= 0.5
                side = -1
            if hi - lo <= tol or vx == 0.0:
                break
        return d_best

    cdef void _peak_interval(self, int k, double tc, double lo, double hi, double v_lo,
                             double d_hi, double v_hi, const double* P) noexcept nogil:
        """One interval of :meth:`StructureSubsystem._segment_peaks` for the
        closed contact ``k``: the segment's largest penetration so far
        ``seg_peak[k]`` raised to the value ``d_hi`` at the interval's end and,
        where the rate falls through zero inside it, to the penetration there."""
        cdef double r
        if d_hi > self.seg_peak[k]:
            self.seg_peak[k] = d_hi
        if v_lo > 0.0 and v_hi <= 0.0:
            r = self._rate_root_value(k, tc, lo, hi, v_lo, v_hi, P)
            if r > self.seg_peak[k]:
                self.seg_peak[k] = r

    # -------------------------------------------------------------- the step
    def step(self, double[::1] x, double[::1] aux, double[:, ::1] pm, signed char[::1] closed,
             double[::1] peak):
        """Advance the modal state ``x = [q, dq]`` (2 m) over the loaded step
        in closed form with the hosted springs switching, adding to ``aux``
        (4 per contact, as the reference) and to the ports' velocity moments
        ``pm`` (3, 2 n_p; complex interleaved).  ``closed`` (n_c) holds each
        contact's state at the end of the last step (1 closed, 0 open, -1
        unknown), and on return at the end of this one.  ``peak`` (n_c), the
        host's largest penetrations, is raised in place to each closed
        contact's largest penetration over each segment (the reference's
        ``_segment_peaks``).  Returns the located switches
        ``[(time, contact, closed), ...]``."""
        cdef int m = self.m, npt = self.np_, nc = self.nc, i, stalled
        cdef double tc = self.t
        cdef SwitchLog log
        if x.shape[0] != 2 * m or aux.shape[0] != 4 * nc + 2 or pm.shape[0] != 3 \
                or pm.shape[1] != 2 * npt or closed.shape[0] != nc or peak.shape[0] != nc:
            raise ValueError(f"`x`, `aux`, `pm`, `closed` and `peak` must have {2 * m}, "
                             f"{4 * nc + 2}, (3, {2 * npt}), {nc} and {nc} entries, got "
                             f"{x.shape[0]}, {aux.shape[0]}, ({pm.shape[0]}, {pm.shape[1]}), "
                             f"{closed.shape[0]} and {peak.shape[0]}")
        log.n, log.cap, log.time, log.slot, log.on = 0, 0, NULL, NULL, NULL
        try:
            stalled = self._advance(x, aux, pm, closed, peak, &log, &tc)
            out = [(log.time[i], log.slot[i], log.on[i] != 0) for i in range(log.n)]
        finally:
            free_log(&log)
        if stalled:
            raise StalledStep(f"the compiled structure step made {MAX_SEGMENTS} segments "
                              f"in the step from t = {self.t!r} s without reaching its "
                              f"end (at t = {tc!r} s)")
        return out

    cdef int _advance(self, double[::1] x, double[::1] aux, double[:, ::1] pm,
                      signed char[::1] closed, double[::1] peak, SwitchLog* log,
                      double* at) except -1:
        """:meth:`step`, its switches appended to ``log``; returns 1 where the
        step stalled (after ``SEGMENTS`` segments, at ``at[0]``; ``x`` is
        then untouched), else 0."""
        cdef int m = self.m, npt = self.np_, nc = self.nc, j, k, s, p
        cdef long i, n, row
        cdef double t1 = self.t + self.h, tc = self.t, eps, L, tau, tol, best, hi, lo0, hi0
        cdef double d, dd, w, acc, wmax, taup
        cdef long long mask
        cdef bint any_active, flipped
        cdef const double* P
        cdef long[64] who
        cdef int n_who
        for k in range(nc):
            aux[4 * k + 2] = 0.0            # first moments are per step
        for i in range(m):
            self.q[i] = x[i]
            self.dq[i] = x[m + i]
        eps = 1e-13 * (fabs(t1) if fabs(t1) > 1.0 else 1.0)
        cdef long segments = 0
        while t1 - tc > eps:
            segments += 1
            if segments > SEGMENTS:
                at[0] = tc
                return 1
            L = t1 - tc
            # the contacts at the segment's start: R q, R dq
            for p in range(npt):
                w = 0.0
                acc = 0.0
                for i in range(m):
                    w += self.R[p, i] * self.q[i]
                    acc += self.R[p, i] * self.dq[i]
                self.W[p] = w
                self.DW[p] = acc
            mask = 0
            any_active = False
            for k in range(nc):
                p = self.c_port[k]
                self._gap(k, tc, self.W[p], self.DW[p], &d, &dd)
                self.d0[k] = d
                self.dd0[k] = dd
                self.active[k] = d > 0 or (d == 0 and dd > 0)
                if d == 0 and dd > 0:
                    log_switch(log, tc, k, True)
                if self.active[k]:
                    mask |= (<long long> 1) << k
                    any_active = True
            if tc == self.t:
                # a touch on the step boundary (see the reference)
                for k in range(nc):
                    if self.active[k] and closed[k] == 0 and self.d0[k] != 0 \
                            and self.dd0[k] > 0:
                        log_switch(log, tc, k, True)
            for k in range(nc):
                closed[k] = self.active[k]
            s = self._basis(mask)
            wmax = self.b_wmax[s]
            P = &self.b_P[s, 0, 0]
            self._segment_load(tc)
            self._to_segment(s)
            self._split(&self.b_lam[s, 0])
            self.n_segments += 1
            # probes half a radian of the fastest mode apart, uncapped (the
            # reference's count); between two that keep every contact's side,
            # a closed contact's peak is sought where its rate falls through
            # zero (the reference's _segment_peaks, interval by interval)
            n = <long> ceil(2.0 * L * wmax)
            if n < 2:
                n = 2
            if self.bound_open and not any_active and self._stays_open(tc, L, P):
                # every contact open and bound to stay so: the probes would
                # find nothing, and the segment ends as theirs would
                self.n_unprobed += 1
                self._quadratures(aux, pm, tc, L, P, any_active)
                self._end_state(s, L * n / n)
                break
            row = -1
            for k in range(nc):
                self.dprev[k] = self.d0[k]
                self.ddprev[k] = self.dd0[k]
                self.seg_peak[k] = self.d0[k]
            taup = 0.0
            for i in range(1, n + 1):
                tau = L * i / n
                self._ports(tau, P, &self.W[0], &self.DW[0])
                flipped = False
                for k in range(nc):
                    p = self.c_port[k]
                    self._gap(k, tc + tau, self.W[p], self.DW[p], &self.dcur[k],
                              &self.ddcur[k])
                    if (self.dcur[k] > 0) != (self.active[k] != 0):
                        flipped = True
                if flipped:
                    row = i
                    break
                for k in range(nc):
                    if self.active[k]:
                        self._peak_interval(k, tc, taup, tau, self.ddprev[k], self.dcur[k],
                                            self.ddcur[k], P)
                    self.dprev[k] = self.dcur[k]
                    self.ddprev[k] = self.ddcur[k]
                taup = tau
            if row < 0:
                self._quadratures(aux, pm, tc, L, P, any_active)
                self._raise_peaks(peak)
                self._end_state(s, L * n / n)
                break
            lo0 = L * (row - 1) / n if row > 1 else 0.0
            hi0 = L * row / n
            best = hi0
            n_who = 0
            tol = 1e-15 * (fabs(tc) if fabs(tc) > 1.0 else 1.0)
            for k in range(nc):
                if (self.dcur[k] > 0) == (self.active[k] != 0):
                    continue
                hi = self._switch_time(k, self.active[k] != 0, lo0, hi0, self.dprev[k],
                                       self.dcur[k], tol, tc, P)
                if hi < best - 1e-15:
                    best = hi
                    who[0] = k
                    n_who = 1
                elif fabs(hi - best) <= 1e-15:
                    who[n_who] = k
                    n_who += 1
            self._quadratures(aux, pm, tc, best, P, any_active)
            if any_active:
                # the last interval ends at the switch
                self._ports(best, P, &self.W[0], &self.DW[0])
                for k in range(nc):
                    if self.active[k]:
                        p = self.c_port[k]
                        self._gap(k, tc + best, self.W[p], self.DW[p], &d, &dd)
                        self._peak_interval(k, tc, taup, best, self.ddprev[k], d, dd, P)
                self._raise_peaks(peak)
            self._end_state(s, best)
            tc += best
            for j in range(n_who):
                log_switch(log, tc, who[j], not self.active[who[j]])
                closed[who[j]] = not self.active[who[j]]
        for i in range(m):
            x[i] = self.q[i]
            x[m + i] = self.dq[i]
        return 0

    cdef void _raise_peaks(self, double[::1] peak) noexcept nogil:
        """``peak`` of each closed contact raised to its segment's largest
        penetration."""
        cdef int k
        for k in range(self.nc):
            if self.active[k] and self.seg_peak[k] > peak[k]:
                peak[k] = self.seg_peak[k]


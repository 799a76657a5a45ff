# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True
# cython: initializedcheck=False, nonecheck=False
"""The planar tree's model in the compiled multibody step: what one
evaluation of the right-hand side needs.

:class:`TreeDynamics` holds a tree (joints, bodies, ports), its hosted
contacts' laws, its joint springs, dampers and drives, and the step's input
and partners' motion, and evaluates from them the tree's kinematics,
``M(q)`` and ``F(q, dq)``, the small symmetric solve, the penalty laws, the
joint effects and the energy: the compiled twin of :mod:`multibody.tree`
(:meth:`TreeModel.evaluate`) and of :meth:`cosim.sides.multibody.MultibodySubsystem._rhs`,
the same formulas in the same order.  The integrator that steps it (RK4,
switches located inside the sub-steps, the sampled path and the C face) is
:class:`cosim.sides._multibody_step.MultibodyStep`, its subclass.  The state
layout is that module's.
"""
from libc.math cimport sin, cos, pow, sqrt

import numpy as np


cdef double _interp(double t, const double* ts, const double* vs, int m) noexcept nogil:
    """``numpy.interp`` on one value: held outside the table."""
    cdef int lo = 0, hi = m - 1, mid
    cdef double slope, r
    if t < ts[0] or m == 1:
        return vs[0]
    if t >= ts[m - 1]:
        return vs[m - 1]
    while hi - lo > 1:                  # ts[lo] <= t < ts[hi]
        mid = (lo + hi) // 2
        if ts[mid] <= t:
            lo = mid
        else:
            hi = mid
    if t == ts[lo]:
        return vs[lo]
    slope = (vs[lo + 1] - vs[lo]) / (ts[lo + 1] - ts[lo])
    r = slope * (t - ts[lo]) + vs[lo]
    if r != r:
        r = slope * (t - ts[lo + 1]) + vs[lo + 1]
    return r


cdef double _table_rate(double t, const double* ts, const double* vs, int m) noexcept nogil:
    """The slope of the table's segment at ``t`` (zero outside and at its ends)."""
    cdef int lo = 0, hi = m - 1, mid
    if m < 2 or t <= ts[0] or t >= ts[m - 1]:
        return 0.0
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if ts[mid] <= t:
            lo = mid
        else:
            hi = mid
    return (vs[lo + 1] - vs[lo]) / (ts[lo + 1] - ts[lo])


cdef class TreeDynamics:
    """The tree's model and the step's loads; the parameters are those of
    :class:`cosim.sides._multibody_step.MultibodyStep`."""

    def __init__(self, parent, revolute, offset, axis, angle0, ancestors, mass, inertia, com,
                 rot_mass, gravity, port_body, port_local, contacts, effects=None):
        cdef int n = len(parent)
        self.n = n
        self.np_ = len(port_body)
        self.nc = len(contacts)
        self.nm = n + self.np_
        self.nq = 2 * n
        self.ny = 2 * n + 4 * self.nc + 2 + 6 * self.np_
        self.parent = np.ascontiguousarray(parent, dtype=np.int_)
        self.rev = np.ascontiguousarray(revolute, dtype=float)
        self.pris = 1.0 - np.asarray(self.rev)
        offset, axis, com = (np.asarray(a, complex) for a in (offset, axis, com))
        port_local = np.asarray(port_local, complex)
        self.off_re, self.off_im = np.ascontiguousarray(offset.real), np.ascontiguousarray(offset.imag)
        self.ax_re, self.ax_im = np.ascontiguousarray(axis.real), np.ascontiguousarray(axis.imag)
        self.angle0 = np.ascontiguousarray(angle0, dtype=float)
        self.anc = np.ascontiguousarray(ancestors, dtype=float)
        self.mass = np.ascontiguousarray(mass, dtype=float)
        self.inertia = np.ascontiguousarray(inertia, dtype=float)
        self.com_re, self.com_im = np.ascontiguousarray(com.real), np.ascontiguousarray(com.imag)
        self.rot_mass = np.ascontiguousarray(rot_mass, dtype=float)
        self.has_g = gravity is not None
        self.g_re = 0.0 if gravity is None else complex(gravity).real
        self.g_im = 0.0 if gravity is None else complex(gravity).imag
        self.port_body = np.ascontiguousarray(port_body, dtype=np.int_)
        self.pl_re = np.ascontiguousarray(port_local.real)
        self.pl_im = np.ascontiguousarray(port_local.imag)
        nc = max(self.nc, 1)
        self.c_port = np.array([c[0] for c in contacts] or [0], dtype=np.int_)
        self.c_side = np.array([c[1] for c in contacts] or [0.0])
        self.c_nre = np.array([complex(c[2]).real for c in contacts] or [0.0])
        self.c_nim = np.array([complex(c[2]).imag for c in contacts] or [0.0])
        self.c_off = np.array([c[3] for c in contacts] or [0.0])
        self.c_kind = np.array([c[4] for c in contacts] or [0], dtype=np.int_)
        self.c_k = np.array([c[5] for c in contacts] or [0.0])
        self.c_c = np.array([c[6] for c in contacts] or [0.0])
        self.c_n = np.array([c[7] for c in contacts] or [1.0])
        self.t0, self.h = 0.0, 1.0
        self.u_len = 0
        self.u_coef = np.zeros((MAX_COEF, max(self.np_, 1), 2))
        self.m_len = np.ones(nc, dtype=np.int_)
        self.m_still = np.ones(nc, dtype=np.int_)
        self.m_t0 = np.zeros(nc)
        self.m_h = np.ones(nc)
        self.m_re = np.zeros((nc, MAX_COEF))
        self.m_im = np.zeros((nc, MAX_COEF))
        self.dm_re = np.zeros((nc, MAX_COEF))
        self.dm_im = np.zeros((nc, MAX_COEF))
        if self.nc > MAX_CONTACTS:
            raise ValueError(f"the kernel hosts at most {MAX_CONTACTS} contacts per subsystem, "
                             f"got {self.nc}")
        m = self.nm
        self.qs = np.zeros(n); self.th = np.zeros(n); self.rot_re = np.zeros(n); self.rot_im = np.zeros(n)
        self.org_re = np.zeros(n); self.org_im = np.zeros(n)
        self.axw_re = np.zeros(n); self.axw_im = np.zeros(n)
        self.om = np.zeros(n); self.vel_re = np.zeros(n); self.vel_im = np.zeros(n)
        self.pom = np.zeros(n); self.F = np.zeros(n); self.b = np.zeros(n)
        self.px_re = np.zeros(m); self.px_im = np.zeros(m)
        self.pv_re = np.zeros(m); self.pv_im = np.zeros(m)
        self.pa_re = np.zeros(m); self.pa_im = np.zeros(m)
        self.J_re = np.zeros((m, n)); self.J_im = np.zeros((m, n))
        self.M = np.zeros((n, n)); self.L = np.zeros((n, n))
        self.u_re = np.zeros(max(self.np_, 1)); self.u_im = np.zeros(max(self.np_, 1))
        self.sw_tmp = np.zeros(max(self.nc, 1))
        self.stage = np.zeros((10, self.ny))
        self.sws = np.zeros((4, max(self.nc, 1)))
        self.pen = np.zeros((4, max(self.nc, 1)))
        self.n_rhs = 0
        self._set_effects(n, effects)

    def _set_effects(self, int n, effects):
        """Joint springs, dampers and drives from ``effects``: None, or
        ``(stiffness, rest, damping, drives)`` with per-joint arrays and
        drives ``(joint, kind, gains (3,), reference kind, reference
        params (4,), table times, table values)`` (see
        :func:`cosim.sides.multibody.kernel_effects`)."""
        self.tau = np.zeros(n)
        if effects is None:
            self.has_springs = self.has_dampers = False
            self.e_k = self.e_rest = self.e_c = np.zeros(n)
            drives = []
        else:
            k, rest, c, drives = effects
            self.e_k = np.ascontiguousarray(k, dtype=float)
            self.e_rest = np.ascontiguousarray(rest, dtype=float)
            self.e_c = np.ascontiguousarray(c, dtype=float)
            self.has_springs = bool(np.any(self.e_k))
            self.has_dampers = bool(np.any(self.e_c))
        self.nd = len(drives)
        m = max(self.nd, 1)
        self.d_joint = np.array([d[0] for d in drives] or [0], dtype=np.int_)
        self.d_kind = np.array([d[1] for d in drives] or [0], dtype=np.int_)
        self.d_pd = np.array([list(d[2]) for d in drives] or [[0.0] * 3], dtype=float)
        self.d_ref = np.array([d[3] for d in drives] or [0], dtype=np.int_)
        self.d_par = np.array([list(d[4]) for d in drives] or [[0.0] * 4], dtype=float)
        tabs = [(np.asarray(d[5], float), np.asarray(d[6], float)) for d in drives]
        self.d_len = np.array([t.size for t, _ in tabs] or [0], dtype=np.int_)
        self.d_off = np.array(np.cumsum([0] + [2 * t.size for t, _ in tabs])[:m], dtype=np.int_)
        self.d_tab = np.concatenate([np.concatenate([t, v]) for t, v in tabs] + [np.zeros(1)])

    # ------------------------------------------------------------ the step
    def set_step(self, double t0, double h, inputs, embedded):
        """Load the step: its start ``t0`` and length ``h`` [s], the input
        (a :class:`cosim.core.subsystem.StepInput` or None) and the partners'
        motion from the host's embedded contacts
        (:class:`cosim.core.subsystem.EmbeddedContact`: ``t0``, ``h`` and complex
        ``motion`` coefficients in the partner's normalised time, lowest
        first)."""
        cdef int j, k, p, i, m
        cdef double[:, :, :] c
        cdef double complex[:] mc
        cdef double mh
        self.t0, self.h = t0, h
        if inputs is None:
            self.u_len = 0
        else:
            c = inputs.coeffs
            if c.shape[0] > MAX_COEF or c.shape[1] != self.np_ or c.shape[2] != 2:
                raise ValueError(f"input coefficients must have shape (<= {MAX_COEF}, "
                                 f"{self.np_}, 2), got {np.shape(inputs.coeffs)}")
            self.u_len = c.shape[0]
            self.u_t0, self.u_h = inputs.t0, inputs.h
            for j in range(self.u_len):
                for p in range(self.np_):
                    self.u_coef[j, p, 0] = c[j, p, 0]
                    self.u_coef[j, p, 1] = c[j, p, 1]
        for k in range(self.nc):
            e = embedded[k]
            mc = e.motion
            m = mc.shape[0]
            if m > MAX_COEF:
                raise ValueError(f"partner motion of order {m - 1} is above the "
                                 f"kernel's {MAX_COEF - 1}")
            self.m_len[k] = m
            self.m_t0[k] = e.t0
            self.m_h[k] = mh = e.h
            self.m_still[k] = 1
            for i in range(m):
                self.m_re[k, i] = mc[i].real
                self.m_im[k, i] = mc[i].imag
                if i > 0:
                    if mc[i] != 0:
                        self.m_still[k] = 0
                    self.dm_re[k, i - 1] = mc[i].real * i / mh
                    self.dm_im[k, i - 1] = mc[i].imag * i / mh

    cdef void _frames(self, const double* q, const double* dq) noexcept nogil:
        cdef int i, p
        cdef double prr, pri, sr, si, ar, ai
        for i in range(self.n):
            p = self.parent[i]
            # theta = angle0 + sum over the path of revolute q
            if p >= 0:
                self.qs[i] = self.qs[p] + self.rev[i] * q[i]
                prr, pri = self.rot_re[p], self.rot_im[p]
            else:
                self.qs[i] = self.rev[i] * q[i]
                prr, pri = 1.0, 0.0
            self.th[i] = self.angle0[i] + self.qs[i]
            self.rot_re[i] = cos(self.th[i])
            self.rot_im[i] = sin(self.th[i])
            ar = prr * self.ax_re[i] - pri * self.ax_im[i]
            ai = prr * self.ax_im[i] + pri * self.ax_re[i]
            self.axw_re[i], self.axw_im[i] = ar, ai
            sr = self.off_re[i] + self.pris[i] * q[i] * self.ax_re[i]
            si = self.off_im[i] + self.pris[i] * q[i] * self.ax_im[i]
            self.org_re[i] = prr * sr - pri * si
            self.org_im[i] = prr * si + pri * sr
            if p >= 0:
                self.org_re[i] += self.org_re[p]
                self.org_im[i] += self.org_im[p]
                self.om[i] = self.om[p] + self.rev[i] * dq[i]
                self.pom[i] = self.om[p]
                # v_i = v_p + i w_p (o_i - o_p) + prismatic axis dq_i
                self.vel_re[i] = (self.vel_re[p] - self.om[p] * (self.org_im[i] - self.org_im[p])
                                  + self.pris[i] * ar * dq[i])
                self.vel_im[i] = (self.vel_im[p] + self.om[p] * (self.org_re[i] - self.org_re[p])
                                  + self.pris[i] * ai * dq[i])
            else:
                self.om[i] = self.rev[i] * dq[i]
                self.pom[i] = 0.0
                self.vel_re[i] = self.pris[i] * ar * dq[i]
                self.vel_im[i] = self.pris[i] * ai * dq[i]

    cdef void _point(self, int k, int body, double lr, double li, const double* dq,
                     bint full) noexcept nogil:
        """Position, velocity (and with ``full`` Jacobian row and
        velocity-product term) of point ``k`` at ``lr + i li`` on ``body``."""
        cdef int j
        cdef double xr, xi, cr, ci, vr = 0.0, vi = 0.0, ar = 0.0, ai = 0.0, a
        xr = self.org_re[body] + self.rot_re[body] * lr - self.rot_im[body] * li
        xi = self.org_im[body] + self.rot_re[body] * li + self.rot_im[body] * lr
        self.px_re[k], self.px_im[k] = xr, xi
        for j in range(self.n):
            a = self.anc[body, j]
            if a == 0.0:
                cr = 0.0
                ci = 0.0
            else:
                # rev_j i (x - o_j) + pris_j axis_j
                cr = a * (-self.rev[j] * (xi - self.org_im[j]) + self.pris[j] * self.axw_re[j])
                ci = a * (self.rev[j] * (xr - self.org_re[j]) + self.pris[j] * self.axw_im[j])
            if full:
                self.J_re[k, j] = cr
                self.J_im[k, j] = ci
            vr += cr * dq[j]
            vi += ci * dq[j]
        self.pv_re[k], self.pv_im[k] = vr, vi
        if not full:
            return
        for j in range(self.n):
            a = self.anc[body, j]
            if a == 0.0:
                continue
            # rev_j i (v - v_j) + pris_j i w_parent(j) axis_j
            ar += a * (-self.rev[j] * (vi - self.vel_im[j])
                       - self.pris[j] * self.pom[j] * self.axw_im[j]) * dq[j]
            ai += a * (self.rev[j] * (vr - self.vel_re[j])
                       + self.pris[j] * self.pom[j] * self.axw_re[j]) * dq[j]
        self.pa_re[k], self.pa_im[k] = ar, ai

    cdef void _mass_and_forces(self) noexcept nogil:
        """``M`` and ``F`` from the mass centres' rows (points 0 .. n-1)."""
        cdef int n = self.n, b, i, j
        cdef double s, mb, gr, gi
        for i in range(n):
            for j in range(i, n):
                s = 0.0
                for b in range(n):
                    s += self.mass[b] * (self.J_re[b, i] * self.J_re[b, j]
                                         + self.J_im[b, i] * self.J_im[b, j])
                self.M[i, j] = s + self.rot_mass[i, j]
                self.M[j, i] = self.M[i, j]
        for i in range(n):
            s = 0.0
            for b in range(n):
                gr = self.pa_re[b] - self.g_re
                gi = self.pa_im[b] - self.g_im
                s += self.mass[b] * (self.J_re[b, i] * gr + self.J_im[b, i] * gi)
            self.F[i] = s

    cdef int _solve(self, double* x) noexcept nogil:
        """``M x = b`` by Cholesky; -1 if ``M`` is not positive definite."""
        cdef int n = self.n, i, j, k
        cdef double s
        for i in range(n):
            for j in range(i + 1):
                s = self.M[i, j]
                for k in range(j):
                    s -= self.L[i, k] * self.L[j, k]
                if i == j:
                    if s <= 0.0:
                        return -1
                    self.L[i, i] = sqrt(s)
                else:
                    self.L[i, j] = s / self.L[j, j]
        for i in range(n):
            s = self.b[i]
            for k in range(i):
                s -= self.L[i, k] * x[k]
            x[i] = s / self.L[i, i]
        for i in range(n - 1, -1, -1):
            s = x[i]
            for k in range(i + 1, n):
                s -= self.L[k, i] * x[k]
            x[i] = s / self.L[i, i]
        return 0

    # ------------------------------------------------------------ contacts
    cdef void _partner(self, int k, double t, double* xr, double* xi, double* vr,
                       double* vi) noexcept nogil:
        cdef int i, m
        cdef double s, ar, ai, br, bi
        if self.m_still[k]:
            xr[0], xi[0], vr[0], vi[0] = self.m_re[k, 0], self.m_im[k, 0], 0.0, 0.0
            return
        s = (t - self.m_t0[k]) / self.m_h[k]
        m = self.m_len[k]
        ar, ai = 0.0, 0.0
        for i in range(m - 1, -1, -1):
            ar = ar * s + self.m_re[k, i]
            ai = ai * s + self.m_im[k, i]
        br, bi = 0.0, 0.0
        for i in range(m - 2, -1, -1):
            br = br * s + self.dm_re[k, i]
            bi = bi * s + self.dm_im[k, i]
        xr[0], xi[0], vr[0], vi[0] = ar, ai, br, bi

    cdef void _penetration(self, int k, double t, double* d, double* dd) noexcept nogil:
        cdef int p = self.c_port[k] + self.n
        cdef double xr, xi, vr, vi
        self._partner(k, t, &xr, &xi, &vr, &vi)
        # Re(conj(n) z) = n_re z_re + n_im z_im
        d[0] = self.c_off[k] - self.c_side[k] * (self.c_nre[k] * (self.px_re[p] - xr)
                                                 + self.c_nim[k] * (self.px_im[p] - xi))
        dd[0] = -self.c_side[k] * (self.c_nre[k] * (self.pv_re[p] - vr)
                                   + self.c_nim[k] * (self.pv_im[p] - vi))

    cdef double _law_switch(self, int k, double d, double dd) noexcept nogil:
        cdef int kind = self.c_kind[k]
        cdef double a
        if kind == KELVIN_VOIGT:
            a = d + (self.c_c[k] / self.c_k[k]) * dd
            return d if d < a else a
        if kind == POWER and self.c_c[k] != 0.0:
            a = d * (1.0 + self.c_c[k] * dd)
            return d if d < a else a
        if kind == RIGID:
            return d if dd >= 0.0 or d < dd else dd
        return d

    cdef void _law(self, int k, double d, double dd, double* f, double* p, double* sw) noexcept nogil:
        """Force [N], dissipated power [W] and switch value [m]
        (:meth:`couplers.ContactLaw.evaluate`)."""
        cdef int kind = self.c_kind[k]
        cdef double s, fa, dp, slope
        if kind == LINEAR:
            f[0] = self.c_k[k] * d if d > 0.0 else 0.0
            p[0] = 0.0
            sw[0] = d
            return
        s = self._law_switch(k, d, dd)
        dp = d if d > 0.0 else 0.0
        if kind == KELVIN_VOIGT:
            fa = self.c_k[k] * d + self.c_c[k] * dd
            slope = self.c_k[k] * dp
        elif kind == POWER:
            slope = self.c_k[k] * pow(dp, self.c_n[k])
            fa = slope * (1.0 + self.c_c[k] * dd)
        else:
            fa = 0.0
            slope = 0.0
        if s > 0.0:
            f[0] = fa if fa > 0.0 else 0.0
        else:
            f[0] = 0.0
        p[0] = (f[0] - slope) * dd
        sw[0] = s

    # ------------------------------------------------------- right-hand side
    cdef void _inputs(self, double t) noexcept nogil:
        """The ports' input forces at ``t`` into ``u_re``, ``u_im``: the step's
        force polynomial (Horner), zero without one."""
        cdef int npt = self.np_, p, j
        cdef double s, ur, ui
        if self.u_len > 0:
            s = (t - self.u_t0) / self.u_h
            for p in range(npt):
                ur = self.u_coef[self.u_len - 1, p, 0]
                ui = self.u_coef[self.u_len - 1, p, 1]
                for j in range(self.u_len - 2, -1, -1):
                    ur = ur * s + self.u_coef[j, p, 0]
                    ui = ui * s + self.u_coef[j, p, 1]
                self.u_re[p], self.u_im[p] = ur, ui
        else:
            for p in range(npt):
                self.u_re[p], self.u_im[p] = 0.0, 0.0

    cdef int _rhs(self, double t, const double* y, double* out, double* sw) noexcept nogil:
        """``dy/dt`` into ``out`` and the contacts' switch values into ``sw``."""
        cdef int n = self.n, npt = self.np_, k, j, i, p, base
        cdef double s, tau, ur, ui, f, pw, swk, d, dd, fr, fi
        cdef const double* q = y
        cdef const double* dq = y + n
        self.n_rhs += 1
        self._frames(q, dq)
        for i in range(n):
            self._point(i, i, self.com_re[i], self.com_im[i], dq, True)
        for i in range(npt):
            self._point(n + i, self.port_body[i], self.pl_re[i], self.pl_im[i], dq, True)
        self._mass_and_forces()
        # port forces: the input polynomial, then the contacts
        self._inputs(t)
        tau = t - self.t0
        base = 2 * n
        for k in range(self.nc):
            p = self.c_port[k]
            self._penetration(k, t, &d, &dd)
            self.pen[0, k] = d
            self.pen[1, k] = dd
            self._law(k, d, dd, &f, &pw, &swk)
            fr = self.c_side[k] * f * self.c_nre[k]
            fi = self.c_side[k] * f * self.c_nim[k]
            self.u_re[p] += fr
            self.u_im[p] += fi
            out[base + 4 * k] = f
            out[base + 4 * k + 1] = pw
            out[base + 4 * k + 2] = f * tau
            out[base + 4 * k + 3] = fr * self.pv_re[n + p] + fi * self.pv_im[n + p]
            sw[k] = swk
        # generalised forces Re(J^H u) - (F - effects), then ddq
        if self.nd or self.has_springs or self.has_dampers:
            self._effects(t, q, dq, &out[2 * n + 4 * self.nc])
            for i in range(n):
                self.F[i] = self.F[i] - self.tau[i]
        for i in range(n):
            s = 0.0
            for p in range(npt):
                s += self.J_re[n + p, i] * self.u_re[p] + self.J_im[n + p, i] * self.u_im[p]
            self.b[i] = s - self.F[i]
        for i in range(n):
            out[i] = dq[i]
        if self._solve(out + n) != 0:
            return -1
        base = 2 * n + 4 * self.nc
        if not (self.nd or self.has_springs or self.has_dampers):
            out[base] = 0.0
            out[base + 1] = 0.0
        base += 2
        s = tau / self.h
        for p in range(npt):
            out[base + 2 * p] = self.pv_re[n + p]
            out[base + 2 * p + 1] = self.pv_im[n + p]
            out[base + 2 * npt + 2 * p] = s * self.pv_re[n + p]
            out[base + 2 * npt + 2 * p + 1] = s * self.pv_im[n + p]
            out[base + 4 * npt + 2 * p] = (s * s) * self.pv_re[n + p]
            out[base + 4 * npt + 2 * p + 1] = (s * s) * self.pv_im[n + p]
        return 0

    cdef double _reference(self, int k, double t, bint rate) noexcept nogil:
        """The value (or rate) of drive ``k``'s reference at ``t``
        (:mod:`multibody.effects` trajectories)."""
        cdef int kind = self.d_ref[k]
        cdef double x, a, w
        cdef const double* ts
        if kind == REF_TABLE:
            ts = &self.d_tab[self.d_off[k]]
            if rate:
                return _table_rate(t, ts, ts + self.d_len[k], self.d_len[k])
            return _interp(t, ts, ts + self.d_len[k], self.d_len[k])
        if kind == REF_MINIMUM_JERK:    # params: start, end, t_start, t_end
            x = (t - self.d_par[k, 2]) / (self.d_par[k, 3] - self.d_par[k, 2])
            x = 0.0 if x < 0.0 else x
            x = 1.0 if x > 1.0 else x
            if rate:
                a = (self.d_par[k, 1] - self.d_par[k, 0]) / (self.d_par[k, 3] - self.d_par[k, 2])
                return a * 30 * x * x * pow(1 - x, 2.0)
            return (self.d_par[k, 0] + (self.d_par[k, 1] - self.d_par[k, 0]) * pow(x, 3.0)
                    * (10 - 15 * x + 6 * x * x))
        # sinusoid: amplitude, frequency, phase, offset
        w = 2 * 3.141592653589793 * self.d_par[k, 1]
        if rate:
            return self.d_par[k, 0] * w * cos(w * t + self.d_par[k, 2])
        return self.d_par[k, 3] + self.d_par[k, 0] * sin(2 * 3.141592653589793
                                                         * self.d_par[k, 1] * t
                                                         + self.d_par[k, 2])

    cdef void _effects(self, double t, const double* q, const double* dq,
                       double* rates) noexcept nogil:
        """Joint effects' generalised forces into ``tau`` and the power the
        dampers dissipate and the drives supply into ``rates[0:2]``
        (:class:`multibody.JointEffects`)."""
        cdef int i, k, j, kind
        cdef double tq, diss = 0.0, sup = 0.0, r, rd
        cdef const double* ts
        for i in range(self.n):
            self.tau[i] = 0.0
        for k in range(self.nd):
            j = self.d_joint[k]
            kind = self.d_kind[k]
            if kind == DRIVE_CONSTANT:
                tq = self.d_pd[k, 0]
            elif kind == DRIVE_TABLE:
                ts = &self.d_tab[self.d_off[k]]
                tq = _interp(t, ts, ts + self.d_len[k], self.d_len[k])
            else:                       # PD
                r = self._reference(k, t, False)
                rd = self._reference(k, t, True)
                tq = self.d_pd[k, 0] * (r - q[j]) + self.d_pd[k, 1] * (rd - dq[j])
                if tq < -self.d_pd[k, 2]:
                    tq = -self.d_pd[k, 2]
                if tq > self.d_pd[k, 2]:
                    tq = self.d_pd[k, 2]
            self.tau[j] += tq
        if self.nd:
            for i in range(self.n):
                sup += self.tau[i] * dq[i]
        if self.has_dampers:
            for i in range(self.n):
                diss += self.e_c[i] * dq[i] * dq[i]
        if self.has_springs:
            for i in range(self.n):
                self.tau[i] -= self.e_k[i] * (q[i] - self.e_rest[i])
        if self.has_dampers:
            for i in range(self.n):
                self.tau[i] -= self.e_c[i] * dq[i]
        rates[0] = diss
        rates[1] = sup

    cdef void _switch(self, double t, const double* y, double* sw) noexcept nogil:
        """The contacts' switch values at ``(t, y)``: port kinematics only."""
        cdef int k, p
        cdef double d, dd
        self._frames(y, y + self.n)
        for k in range(self.nc):
            p = self.c_port[k]
            self._point(self.n + p, self.port_body[p], self.pl_re[p], self.pl_im[p],
                        y + self.n, False)
            self._penetration(k, t, &d, &dd)
            sw[k] = self._law_switch(k, d, dd)

    def sample_penetrations(self, double[::1] T, double[:, ::1] Y, double[:, ::1] D):
        """The contacts' penetrations [m] at many states, one call:
        ``D[j, k]`` at ``(T[j], Y[j])`` (rows ``[q, dq, ...]``), as
        ``penetrations`` gives them one state at a time."""
        cdef int j, k, p, n = self.n
        cdef double d, dd
        if Y.shape[0] < T.shape[0] or D.shape[0] < T.shape[0] or D.shape[1] != self.nc \
                or Y.shape[1] < 2 * n:
            raise ValueError(f"`Y` must be ({T.shape[0]}, >= {2 * n}), `D` ({T.shape[0]}, "
                             f"{self.nc})")
        for j in range(T.shape[0]):
            self._frames(&Y[j, 0], &Y[j, n])
            for k in range(self.nc):
                p = self.c_port[k]
                self._point(n + p, self.port_body[p], self.pl_re[p], self.pl_im[p], &Y[j, n],
                            False)
                self._penetration(k, T[j], &d, &dd)
                D[j, k] = d


    cdef double _energy(self, const double* y) noexcept nogil:
        """:meth:`energy` at ``y``."""
        cdef int i, j, n = self.n
        cdef double kin = 0.0, pot = 0.0, row
        self._frames(y, y + n)
        for i in range(n):
            self._point(i, i, self.com_re[i], self.com_im[i], y + n, True)
        self._mass_and_forces()
        for i in range(n):
            row = 0.0
            for j in range(n):
                row += self.M[i, j] * y[n + j]
            kin += y[n + i] * row
        if self.has_g:
            for i in range(n):
                pot -= self.mass[i] * (self.px_re[i] * self.g_re + self.px_im[i] * self.g_im)
        return 0.5 * kin + pot

    def energies(self, X):
        """:meth:`_energy` (the step kernel's ``energy``) at each row of the
        states ``X`` (m, >= 2 n) [J], in one call (the recorder's rows)."""
        X = np.ascontiguousarray(X, dtype=float)
        if len(X) == 0:             # no rows: no energies (a reshape of none cannot infer)
            return np.empty(0)
        cdef double[:, ::1] xv = X.reshape(len(X), -1)
        out = np.empty(xv.shape[0])
        cdef double[::1] ov = out
        cdef Py_ssize_t i
        if xv.shape[0] and xv.shape[1] < 2 * self.n:
            raise ValueError(f"`X` must have {2 * self.n} columns, got {xv.shape[1]}")
        for i in range(xv.shape[0]):
            ov[i] = self._energy(&xv[i, 0])
        return out

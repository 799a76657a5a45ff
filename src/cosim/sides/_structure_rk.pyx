# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True
# cython: initializedcheck=False, nonecheck=False
"""The structure's RK4 step with hosted penalty contacts, compiled.

While a contact the structure hosts is, or becomes, closed and the step is
not taken in closed form (a nonlinear law: Hertz, Hunt-Crossley,
Lankarani-Nikravesh, Flores, Kelvin-Voigt; or modal damping), the numpy
reference (:meth:`cosim.sides.fem.StructureSubsystem._step_impl`) integrates
the modal equations by :meth:`cosim.core.ode.TimeStepper.integrate` (RK4,
switches located on each sub-step's cubic Hermite, the contacts' peaks on
the accepted sub-steps).  This is that integration in C: the same
right-hand side (:meth:`StructureSubsystem._rhs`: the port loads' modal
force, gravity, modal damping, the contacts' forces from the partners'
motion; the contacts' impulse, dissipation, first moment and work, the
damping's dissipation and the ports' velocity moments) and the same
integrator, in the same order of arithmetic up to the order of sums.

The contacts' laws, the partners' motion and the step's input polynomial are
those of the multibody kernel's model (:class:`cosim.sides._multibody_tree.
TreeDynamics`, cimported; a tree of no body here): one evaluation of each
law for every compiled side.

State layout (``y``, length ``2 m + 4 n_c + 2 + 6 n_p``)::

    q (m) | dq (m) | per contact: impulse, dissipated, first moment, work (4 n_c)
    | modal damping's dissipation, 0 (2)
    | port velocity moments int v s^j dt, j = 0, 1, 2, complex interleaved (6 n_p)
"""
from libc.math cimport ceil, fabs, sqrt
from libc.string cimport memcpy

from cpython.exc cimport PyErr_CheckSignals
from cpython.pycapsule cimport PyCapsule_New

from cosim.core._side_face cimport COSIM_SIDE_FACE, SideFace, free_log, log_switch

import numpy as np

from cosim.sides._multibody_tree cimport TreeDynamics, MAX_COEF, MAX_CONTACTS, SIGNAL_POLL

#: the interface :mod:`cosim.sides.fem` calls (checked there)
RK_API = 1


# the sub-step's cubic Hermite and its peaks
from cosim.sides._hermite cimport _hermite, _substep_peaks


cdef class StructureRK(TreeDynamics):
    """Compiled RK4 of one :class:`cosim.sides.fem.StructureSubsystem` with
    hosted penalty contacts.

    Parameters
    ----------
    omega, damping : (m,) float arrays
        Modal angular frequencies [rad/s] and modal damping ``d`` [1/s].
    R : (n_p, m) float array
        Port rows of the mode shapes.
    ref, dirs : (n_p, 2) float arrays
        Ports' reference positions [m] and directions.
    g_modal : (m,) float array
        Modal weight load.

    ``R``, ``ref`` and ``dirs`` are the host's own arrays where they are
    contiguous floats (as the host's are), not copies: a port that follows a
    point moves in place and the kernel reads it there.
    contacts : list of tuples
        Per hosted contact: ``(port, side, normal (complex), offset [m],
        kind, k, c_or_chi, exponent)`` (:func:`cosim.core.links.kernel_law`).
    """
    cdef int m, npt, nys
    cdef double[::1] om2, damp, gm
    cdef double[:, ::1] R, ref, dirs
    cdef double[::1] w, dw
    cdef double[:, ::1] st           # rows: k1, k2, k3, k4, tmp, y1, k1n, yi, ya
    cdef double[:, ::1] swr          # rows: s0, s1, s, snew
    cdef list log
    # the C face (cosim.core._side_face): RK4's largest sub-step, the stepping
    # state, and whether the switches go to the face's log
    cdef SideFace cface
    cdef double cs_max_step
    cdef double[::1] cs_y
    cdef bint cs_logging
    #: right-hand sides evaluated so far
    cdef public long n_evals

    def __init__(self, omega, damping, R, ref, dirs, g_modal, contacts):
        R = np.ascontiguousarray(R, dtype=float)
        npt = R.shape[0]
        e0 = np.zeros((0, 0))
        TreeDynamics.__init__(self, np.zeros(0, int), np.zeros(0), np.zeros(0, complex),
                              np.zeros(0, complex), np.zeros(0), e0, np.zeros(0), np.zeros(0),
                              np.zeros(0, complex), e0, None, np.zeros(npt, int),
                              np.zeros(npt, complex), contacts)
        if self.nc < 1:
            raise ValueError("the structure's RK4 kernel is for hosted contacts; got none")
        self.m, self.npt = R.shape[1], npt
        self.nys = 2 * self.m + 4 * self.nc + 2 + 6 * npt
        omega = np.asarray(omega, dtype=float)
        self.om2 = np.ascontiguousarray(omega * omega)
        self.damp = np.ascontiguousarray(damping, dtype=float)
        self.gm = np.ascontiguousarray(g_modal, dtype=float)
        self.R = R
        self.ref = np.ascontiguousarray(ref, dtype=float).reshape(npt, 2)
        self.dirs = np.ascontiguousarray(dirs, dtype=float).reshape(npt, 2)
        self.w, self.dw = np.zeros(max(npt, 1)), np.zeros(max(npt, 1))
        self.st = np.zeros((9, self.nys))
        self.swr = np.zeros((4, max(self.nc, 1)))
        self.n_evals = 0
        self.cface.nx, self.cface.naux, self.cface.nports = 2 * self.m, 4 * self.nc + 2, npt
        self.cs_max_step = 0.0
        self.cs_y = np.zeros(self.nys)

    def __dealloc__(self):
        free_log(&self.cface.log)

    # ------------------------------------------------------- right-hand side
    cdef void _ports(self, const double* y, bint rates) noexcept nogil:
        """Port displacements ``w = R q`` (and rates ``R dq``) along their directions."""
        cdef int p, i, m = self.m
        cdef double a, b
        for p in range(self.npt):
            a = 0.0
            b = 0.0
            for i in range(m):
                a += self.R[p, i] * y[i]
                if rates:
                    b += self.R[p, i] * y[m + i]
            self.w[p] = a
            self.dw[p] = b

    cdef void _gap(self, int k, double t, double* d, double* dd) noexcept nogil:
        """Penetration and rate of contact ``k`` at ``t`` (the ports as last
        set by :meth:`_ports`): :meth:`EmbeddedContact.penetration`."""
        cdef int p = self.c_port[k]
        cdef double xr, xi, vr, vi
        self._partner(k, t, &xr, &xi, &vr, &vi)
        d[0] = self.c_off[k] - self.c_side[k] * (
            self.c_nre[k] * ((self.ref[p, 0] + self.w[p] * self.dirs[p, 0]) - xr)
            + self.c_nim[k] * ((self.ref[p, 1] + self.w[p] * self.dirs[p, 1]) - xi))
        dd[0] = -self.c_side[k] * (self.c_nre[k] * (self.dw[p] * self.dirs[p, 0] - vr)
                                   + self.c_nim[k] * (self.dw[p] * self.dirs[p, 1] - vi))

    cdef int _rhs(self, double t, const double* y, double* out, double* sw) noexcept nogil:
        """``dy/dt`` into ``out`` and the switch values into ``sw``
        (:meth:`StructureSubsystem._rhs`)."""
        cdef int m = self.m, npt = self.npt, k, j, i, p, base
        cdef double s, tau, ur, ui, f, pw, swk, d, dd, fr, fi, g, dp
        cdef const double* dq = y + m
        self.n_evals += 1
        self._ports(y, True)
        self._inputs(t)
        tau = t - self.t0
        base = 2 * m
        for k in range(self.nc):
            p = self.c_port[k]
            self._gap(k, t, &d, &dd)
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
            out[base + 4 * k + 3] = (fr * self.dirs[p, 0] + fi * self.dirs[p, 1]) * self.dw[p]
            sw[k] = swk
        dp = 0.0
        for i in range(m):
            g = 0.0
            for p in range(npt):
                g += (self.u_re[p] * self.dirs[p, 0] + self.u_im[p] * self.dirs[p, 1]) \
                    * self.R[p, i]
            g += self.gm[i]
            out[i] = dq[i]
            out[m + i] = g - self.damp[i] * dq[i] - self.om2[i] * y[i]
            dp += self.damp[i] * (dq[i] * dq[i])
        base = 2 * m + 4 * self.nc
        out[base] = dp
        out[base + 1] = 0.0
        base += 2
        s = tau / self.h
        for p in range(npt):
            fr = self.dw[p] * self.dirs[p, 0]
            fi = self.dw[p] * self.dirs[p, 1]
            out[base + 2 * p] = fr
            out[base + 2 * p + 1] = fi
            out[base + 2 * npt + 2 * p] = s * fr
            out[base + 2 * npt + 2 * p + 1] = s * fi
            out[base + 4 * npt + 2 * p] = (s * s) * fr
            out[base + 4 * npt + 2 * p + 1] = (s * s) * fi
        return 0

    cdef void _switch(self, double t, const double* y, double* sw) noexcept nogil:
        """The contacts' switch values at ``(t, y)``."""
        cdef int k
        cdef double d, dd
        self._ports(y, True)
        for k in range(self.nc):
            self._gap(k, t, &d, &dd)
            sw[k] = self._law_switch(k, d, dd)

    # ------------------------------------------------------------ stepping
    cdef void _single(self, double t, const double* y, double h, const double* k1,
                      double* out) noexcept nogil:
        """One RK4 step of ``h`` from ``(t, y)`` into ``out`` (``k1 = f(t, y)``)."""
        cdef int i, ny = self.nys
        cdef double* k2 = &self.st[1, 0]
        cdef double* k3 = &self.st[2, 0]
        cdef double* k4 = &self.st[3, 0]
        cdef double* tmp = &self.st[4, 0]
        cdef double* sw = &self.sw_tmp[0]
        for i in range(ny):
            tmp[i] = y[i] + 0.5 * h * k1[i]
        self._rhs(t + 0.5 * h, tmp, k2, sw)
        for i in range(ny):
            tmp[i] = y[i] + 0.5 * h * k2[i]
        self._rhs(t + 0.5 * h, tmp, k3, sw)
        for i in range(ny):
            tmp[i] = y[i] + h * k3[i]
        self._rhs(t + h, tmp, k4, sw)
        for i in range(ny):
            out[i] = y[i] + (h / 6.0) * (k1[i] + 2.0 * (k2[i] + k3[i]) + k4[i])

    cdef double _locate(self, double t, const double* y0, const double* f0, const double* y1,
                        const double* f1, double h, const double* s0,
                        const char* flipped) noexcept nogil:
        """:meth:`TimeStepper._locate`: the earliest switch in ``(t, t + h)``
        on the Hermite interpolant, just past the root; -1 at the end."""
        cdef double lo = 0.0, hi = 1.0, mid, tol
        cdef int it, k, i, hit
        cdef double* yi = &self.st[7, 0]
        cdef double* s = &self.swr[2, 0]
        tol = 1e-14 * (fabs(t) if fabs(t) > 1.0 else 1.0)
        for it in range(60):
            mid = 0.5 * (lo + hi)
            for i in range(2 * self.m):
                yi[i] = _hermite(y0[i], f0[i], y1[i], f1[i], h, mid)
            self._switch(t + mid * h, yi, s)
            hit = 0
            for k in range(self.nc):
                if flipped[k] and ((s[k] > 0.0) != (s0[k] > 0.0)):
                    hit = 1
            if hit:
                hi = mid
            else:
                lo = mid
            if (hi - lo) * h <= tol:
                break
        if hi >= 1.0 - 1e-12:
            return -1.0
        return t + hi * h

    cdef void _watch(self, double* peak, double h) noexcept nogil:
        _substep_peaks(peak, &self.pen[2, 0], &self.pen[3, 0], &self.pen[0, 0], &self.pen[1, 0],
                       h, self.nc)
        self._watched()

    cdef void _watched(self) noexcept nogil:
        cdef int k
        for k in range(self.nc):
            self.pen[2, k] = self.pen[0, k]
            self.pen[3, k] = self.pen[1, k]

    cdef int _flips(self, double t, const double* s_old, const double* s_new) except -1:
        """Log each flipped switch: ``(t, contact, closed)`` (``_on_switch``)."""
        cdef int j
        for j in range(self.nc):
            if (s_old[j] > 0.0) != (s_new[j] > 0.0):
                if self.cs_logging:
                    log_switch(&self.cface.log, t, j, s_new[j] > 0.0)
                else:
                    self.log.append((t, j, s_new[j] > 0.0))
        return 0

    cdef int _integrate(self, double t0, double* y, double t1, double max_step,
                        double* pk) except -1:
        """:meth:`cosim.core.ode.TimeStepper.integrate` (no free step, no
        jumps) in place on ``y``, raising ``pk``."""
        cdef int ny = self.nys, nc = self.nc, i, n, k
        cdef double t = t0, te, h, dt, ts
        cdef bint any_flip
        cdef double* k1 = &self.st[0, 0]
        cdef double* y1 = &self.st[5, 0]
        cdef double* k1n = &self.st[6, 0]
        cdef double* s0 = &self.swr[0, 0]
        cdef double* s1 = &self.swr[1, 0]
        cdef double* snew = &self.swr[3, 0]
        cdef char flipped[MAX_CONTACTS]
        cdef unsigned long polls = 0
        self._rhs(t, y, k1, s0)
        self._watched()
        n = <int>ceil((t1 - t0) / max_step - 1e-9)
        if n < 1:
            n = 1
        dt = (t1 - t0) / n
        i = 0
        while i < n:
            polls += 1
            if polls & SIGNAL_POLL == 0:
                PyErr_CheckSignals()
            te = t1 if i == n - 1 else t0 + (i + 1) * dt
            h = te - t
            self._single(t, y, h, k1, y1)
            self._rhs(te, y1, k1n, s1)
            any_flip = False
            for k in range(nc):
                flipped[k] = (s0[k] > 0.0) != (s1[k] > 0.0)
                if flipped[k]:
                    any_flip = True
            if any_flip:
                ts = self._locate(t, y, k1, y1, k1n, h, s0, flipped)
                if ts >= 0.0:
                    self._single(t, y, ts - t, k1, &self.st[8, 0])
                    memcpy(y, &self.st[8, 0], ny * sizeof(double))
                    self._rhs(ts, y, k1, snew)
                    self._watch(pk, ts - t)
                    t = ts
                    self._flips(t, s0, snew)
                    memcpy(s0, snew, nc * sizeof(double))
                    continue
                self._watch(pk, h)
                self._flips(te, s0, s1)
            else:
                self._watch(pk, h)
            memcpy(s0, s1, nc * sizeof(double))
            t = te
            memcpy(y, y1, ny * sizeof(double))
            memcpy(k1, k1n, ny * sizeof(double))
            i += 1
        return 0

    # ------------------------------------------------------- Python faces
    def closed(self, double t, x):
        """Whether any hosted contact is closed at ``(t, x)`` (``x = [q, dq]``):
        a switch value above zero, as ``StructureSubsystem._switch``."""
        cdef double[::1] xv = np.ascontiguousarray(x, dtype=float)
        cdef int k
        if xv.shape[0] < 2 * self.m:
            raise ValueError(f"`x` must hold {2 * self.m} entries, got {xv.shape[0]}")
        self._switch(t, &xv[0], &self.swr[2, 0])
        for k in range(self.nc):
            if self.swr[2, k] > 0.0:
                return True
        return False

    def step(self, double t, double h, x, aux, double max_step, peak):
        """The reference's RK4 over ``[t, t + h]`` (the step loaded by
        :meth:`set_step`): ``x = [q, dq]`` and ``aux`` advanced in place,
        ``peak`` raised; returns the port velocity moments ``(3, n_p)``
        complex and the switches ``[(t, contact, closed)]``."""
        cdef double[::1] xv = x
        cdef double[::1] av = aux
        cdef double[::1] pkv = peak
        cdef int i, nx = xv.shape[0], na = av.shape[0]
        if nx + na + 6 * self.npt != self.nys or pkv.shape[0] != self.nc:
            raise ValueError(f"`x` and `aux` must hold {self.nys - 6 * self.npt} entries and "
                             f"`peak` {self.nc}, got {nx + na} and {pkv.shape[0]}")
        if not max_step > 0.0:
            raise ValueError(f"`max_step` must be > 0 s, got {max_step!r}")
        y = np.zeros(self.nys)
        cdef double[::1] yv = y
        for i in range(nx):
            yv[i] = xv[i]
        for i in range(na):
            yv[nx + i] = av[i]
        self.log = []
        self._integrate(t, &yv[0], t + h, max_step, &pkv[0])
        for i in range(nx):
            xv[i] = yv[i]
        for i in range(na):
            av[i] = yv[nx + i]
        return y[nx + na:].view(complex).reshape(3, self.npt), self.log

    # ------------------------------------------------------------ the C face
    def configure_rk(self, double max_step):
        """RK4's largest sub-step [s] (the host's ``contact_step``), for the C face."""
        self.cs_max_step = max_step

    def side_face(self):
        """The C face (:mod:`cosim.core._side_face`) of :meth:`side_loop`,
        :meth:`side_motion` and :meth:`side_outputs`, a capsule that lives as
        long as this kernel.  Its ``step`` (the implicit scheme's) refuses:
        that scheme takes no structure that hosts contacts."""
        self.cface.side = <void*> self
        self.cface.step = _face_step
        self.cface.outputs = _face_outputs
        self.cface.loop = _face_loop
        self.cface.motion = _face_motion
        return PyCapsule_New(&self.cface, COSIM_SIDE_FACE, NULL)

    def retire(self):
        """The host no longer steps through this kernel: the face's
        ``generation`` changes, so that a loop holding it asks the host again."""
        self.cface.generation += 1

    cdef int side_loop(self, double t, double h, const double* u, int rows, double* x,
                       double* aux, double* pm, double* peak) except -1:
        """The host's step (``_step_impl``) where a hosted contact is closed
        at ``t``: the RK4 of :meth:`step` under the input polynomial ``u``
        ((rows, n_p, 2) row-major, in ``(time - t) / h``) and the partners'
        motion as last set, the switches to the face's log.  Returns 1,
        touching nothing, where every contact is open at ``t`` (the host's
        exact step, in Python, takes it), where the input is beyond the
        kernel or :meth:`configure_rk` was not called."""
        cdef int j, p, i, nx = 2 * self.m, na = 4 * self.nc + 2, any_closed = 0
        cdef double* y = &self.cs_y[0]
        self.cface.log.n = 0
        if rows > MAX_COEF or self.cs_max_step <= 0.0:
            return 1
        self.t0, self.h = t, h
        self.u_len, self.u_t0, self.u_h = rows, t, h
        for j in range(rows):
            for p in range(self.npt):
                self.u_coef[j, p, 0] = u[(j * self.npt + p) * 2]
                self.u_coef[j, p, 1] = u[(j * self.npt + p) * 2 + 1]
        self._switch(t, x, &self.swr[2, 0])
        for j in range(self.nc):
            if self.swr[2, j] > 0.0:
                any_closed = 1
        if not any_closed:
            return 1
        for i in range(nx):
            y[i] = x[i]
        for i in range(na):
            y[nx + i] = aux[i]
        for j in range(self.nc):
            y[nx + 4 * j + 2] = 0.0             # first moments are per step
        for i in range(6 * self.npt):
            y[nx + na + i] = 0.0
        self.cs_logging = True
        try:
            self._integrate(t, y, t + h, self.cs_max_step, peak)
        finally:
            self.cs_logging = False
        for i in range(nx):
            x[i] = y[i]
        for i in range(na):
            aux[i] = y[nx + i]
        for i in range(6 * self.npt):
            pm[i] = y[nx + na + i]
        return 0

    cdef int side_motion(self, int k, double t0, double h, const double* c,
                         int n) noexcept:
        """Contact ``k``'s partner motion as :meth:`set_step` loads it from an
        ``EmbeddedContact``; 1 where it is beyond the kernel."""
        cdef int i
        if n > MAX_COEF or n < 1 or not 0 <= k < self.nc:
            return 1
        self.m_len[k] = n
        self.m_t0[k] = t0
        self.m_h[k] = h
        self.m_still[k] = 1
        for i in range(n):
            self.m_re[k, i] = c[2 * i]
            self.m_im[k, i] = c[2 * i + 1]
            if i > 0:
                if c[2 * i] != 0.0 or c[2 * i + 1] != 0.0:
                    self.m_still[k] = 0
                self.dm_re[k, i - 1] = c[2 * i] * i / h
                self.dm_im[k, i - 1] = c[2 * i + 1] * i / h
        return 0

    cdef void side_outputs(self, const double* x, double* pos, double* vel) noexcept:
        """Ports' positions and velocities (:meth:`StructureSubsystem.outputs`)."""
        cdef int p
        self._ports(x, True)
        for p in range(self.npt):
            pos[2 * p] = self.ref[p, 0] + self.w[p] * self.dirs[p, 0]
            pos[2 * p + 1] = self.ref[p, 1] + self.w[p] * self.dirs[p, 1]
            vel[2 * p] = self.dw[p] * self.dirs[p, 0]
            vel[2 * p + 1] = self.dw[p] * self.dirs[p, 1]


# ------------------------------------------------- the C face's functions
cdef int _face_step(void* side, double t, double h, const double* u, int rows, double* x,
                    double* aux, double* pm) except -1:
    raise ValueError("the structure's RK4 kernel takes no step of the implicit scheme")


cdef void _face_outputs(void* side, const double* x, double* pos, double* vel) noexcept:
    (<StructureRK> side).side_outputs(x, pos, vel)


cdef int _face_loop(void* side, double t, double h, const double* u, int rows, double* x,
                    double* aux, double* pm, double* peak, signed char* closed) except -1:
    return (<StructureRK> side).side_loop(t, h, u, rows, x, aux, pm, peak)


cdef int _face_motion(void* side, int slot, double t0, double h, const double* c,
                      int n) noexcept:
    return (<StructureRK> side).side_motion(slot, t0, h, c, n)

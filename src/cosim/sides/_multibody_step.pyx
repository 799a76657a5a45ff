# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True
# cython: initializedcheck=False, nonecheck=False
"""The multibody side's step, compiled.

One call advances a planar tree over a macro step with RK4: the tree's
kinematics, ``M(q)`` and ``F(q, dq)``, the small symmetric solve, the penalty
laws of the contacts evaluated inside the integrator, their impulses,
dissipated energy, first moments and work, the port velocity moments, and
the location of every touch and release inside the sub-steps.  It is the
compiled twin of the numpy reference in :mod:`cosim.sides.multibody`
(:meth:`MultibodySubsystem._rhs`), :mod:`multibody.tree`
(:meth:`TreeModel.evaluate`) and :meth:`cosim.core.ode.TimeStepper.integrate`:
the same formulas in the same order, so the two agree to round-off, which
``tests/test_kernel.py`` holds them to.

No Python object is touched inside a step except to tell the host of a
located switch (``on_switch``), which may return a state with jumped
velocities (a rigid impact).

State layout (``y``, length ``2 n + 4 n_c + 2 + 6 n_p``)::

    q (n) | dq (n) | per contact: impulse, dissipated, first moment, work (4 n_c)
    | joint dampers' dissipation, drives' supply (2)
    | port velocity moments int v s^j dt, j = 0, 1, 2, complex interleaved (6 n_p)
"""
from libc.math cimport sin, cos, pow, ceil, fabs, sqrt, isfinite
from libc.string cimport memcpy

from cpython.exc cimport PyErr_CheckSignals
from cpython.pycapsule cimport PyCapsule_New

from cosim.core._side_face cimport COSIM_SIDE_FACE, SideFace

import numpy as np

# a C struct only: nothing of the core is imported at run time
from cosim.core._stacked cimport FaceTable

cdef enum:
    # law kinds (couplers.laws)
    LINEAR = 0          # f = k d
    KELVIN_VOIGT = 1    # f = max(k d + c dd, 0), switch min(d, d + c/k dd)
    POWER = 2           # f = k d^n (1 + chi dd), switch d or min(d, d (1 + chi dd))
    RIGID = 3           # no force; switch d, or min(d, dd * 1 s) moving away
    # joint drives (multibody.effects) and the references a PD drive tracks
    DRIVE_CONSTANT = 0
    DRIVE_TABLE = 1
    DRIVE_PD = 2
    REF_TABLE = 0
    REF_MINIMUM_JERK = 1
    REF_SINUSOID = 2
    # largest number of polynomial coefficients of a partner's motion or an input
    MAX_COEF = 8
    # most contacts one subsystem hosts in the kernel
    MAX_CONTACTS = 64
    # RK4 steps between two looks at the signals (a power of two, less one): a
    # step under a tiny `max_step` may take millions of them, and Ctrl-C or
    # SIGTERM must stop it within a fraction of a second, not at its end
    SIGNAL_POLL = 4095

LAW_KINDS = {"linear": LINEAR, "kelvin_voigt": KELVIN_VOIGT, "power": POWER, "rigid": RIGID}
DRIVE_KINDS = {"constant": DRIVE_CONSTANT, "table": DRIVE_TABLE, "pd": DRIVE_PD}
REFERENCE_KINDS = {"table": REF_TABLE, "minimum_jerk": REF_MINIMUM_JERK,
                   "sinusoid": REF_SINUSOID}


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


cdef inline double _hermite(double y0, double f0, double y1, double f1, double h,
                            double theta) noexcept nogil:
    cdef double t2 = theta * theta
    cdef double t3 = t2 * theta
    return ((2 * t3 - 3 * t2 + 1) * y0 + (t3 - 2 * t2 + theta) * h * f0
            + (-2 * t3 + 3 * t2) * y1 + (t3 - t2) * h * f1)


cdef void _substep_peaks(double* peak, const double* d0, const double* v0, const double* d1,
                         const double* v1, double h, int n) noexcept nogil:
    """Raise each ``peak[j]`` to the largest value of the cubic Hermite
    through ``d0[j]``, ``d1[j]`` with rates ``v0[j]``, ``v1[j]`` over one
    accepted sub-step of ``h`` (:func:`cosim.core.ode.substep_peaks`, the
    same arithmetic)."""
    cdef int j
    cdef double p, dd, c1, c2, c3, qa, qb, disc, r, q, s, x
    for j in range(n):
        p = d1[j]
        if v0[j] > 0.0 and 0.0 > v1[j]:
            dd = d1[j] - d0[j]
            c1 = h * v0[j]
            c2 = 3.0 * dd - h * (2.0 * v0[j] + v1[j])
            c3 = -2.0 * dd + h * (v0[j] + v1[j])
            qa = 3.0 * c3
            qb = 2.0 * c2
            disc = qb * qb - 4.0 * qa * c1
            r = sqrt(disc) if disc > 0.0 else 0.0
            q = -0.5 * (qb + (r if qb >= 0.0 else -r))
            s = c1 / q if q != 0.0 else 1.0
            if not (0.0 < s < 1.0) and qa != 0.0:
                s = q / qa
            if 0.0 < s < 1.0:
                x = d0[j] + s * (c1 + s * (c2 + s * c3))
                if x > p:
                    p = x
        if p > peak[j]:
            peak[j] = p


cdef class MultibodyStep:
    """Compiled RK4 step of one :class:`cosim.sides.multibody.MultibodySubsystem`.

    Parameters
    ----------
    parent : (n,) int array
        Parent body of each joint, -1 for the ground.
    revolute : (n,) float array
        1 for a revolute joint, 0 for a prismatic one.
    offset, axis : (n,) complex arrays
        Joint positions and sliding directions in the parent frames [m].
    angle0 : (n,) float array
        Absolute angles at ``q = 0`` [rad].
    ancestors : (n, n) float array
        ``A[b, j] = 1`` when joint ``j`` is on the path to body ``b``.
    mass, inertia : (n,) float arrays
        [kg], [kg m^2].
    com : (n,) complex array
        Mass centres in the body frames [m].
    rot_mass : (n, n) float array
        The rotational part of the mass matrix.
    gravity : complex or None
        [m/s^2].
    port_body : (n_p,) int array, port_local : (n_p,) complex array
        Ports: body and point in its frame [m].
    contacts : list of tuples
        Per embedded contact: ``(port, side, normal (complex), offset [m],
        kind (LAW_KINDS), k, c_or_chi, exponent)``.
    """

    cdef int n, np_, nc, nm, ny, nq
    cdef long[::1] parent, port_body, c_port, c_kind
    cdef double[::1] rev, pris, off_re, off_im, ax_re, ax_im, angle0, mass, inertia
    cdef double[::1] com_re, com_im, pl_re, pl_im
    cdef double[:, ::1] anc, rot_mass
    cdef bint has_g
    cdef double g_re, g_im
    cdef double[::1] c_side, c_nre, c_nim, c_off, c_k, c_c, c_n
    # the step: its start and length, the input polynomial, the partners' motion
    cdef double t0, h, u_t0, u_h
    cdef int u_len
    cdef double[:, :, ::1] u_coef          # (MAX_COEF, n_p, 2)
    cdef long[::1] m_len, m_still
    cdef double[::1] m_t0, m_h
    cdef double[:, ::1] m_re, m_im, dm_re, dm_im   # (n_c, MAX_COEF)
    # workspace
    cdef double[::1] qs, th, rot_re, rot_im, org_re, org_im, axw_re, axw_im, om, vel_re, vel_im
    cdef double[::1] pom, px_re, px_im, pv_re, pv_im, pa_re, pa_im
    cdef double[:, ::1] J_re, J_im, M, L
    cdef double[::1] F, b, u_re, u_im, sw_tmp
    cdef double[:, ::1] stage          # rows: k1, k2, k3, k4, tmp, y1, k1n, yi, ya, ka
    cdef double[:, ::1] sws            # rows: s0, s1, s, snew
    cdef double[:, ::1] pen            # rows: d, dd at the last rhs; d, dd at the last sub-step end
    # joint effects
    cdef bint has_springs, has_dampers
    cdef int nd
    cdef double[::1] e_k, e_rest, e_c, tau
    cdef long[::1] d_joint, d_kind, d_ref, d_off, d_len
    cdef double[:, ::1] d_pd                   # (n_d, 3): kp, kd, max torque (or the torque)
    cdef double[:, ::1] d_par                  # (n_d, 4): the reference's parameters
    cdef double[::1] d_tab                     # tables: times then values, per drive
    #: number of right-hand-side evaluations so far
    cdef public long n_rhs
    #: number of located switches told to the host so far
    cdef public long n_switches
    #: rows :meth:`sample_steps` has filled in its current (or last) call
    cdef public long n_sampled
    # the C face (cosim.core._side_face): RK4's largest and free sub-steps,
    # and the stepping state
    cdef double cs_max_step, cs_free_step
    cdef double[::1] cs_y
    cdef SideFace cface

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
        self.n_switches = 0
        self.n_sampled = 0
        self._set_effects(n, effects)
        self.cface.nx, self.cface.naux, self.cface.nports = 2 * n, 4 * self.nc + 2, self.np_
        self.cs_max_step, self.cs_free_step = 0.0, 0.0
        self.cs_y = np.zeros(self.ny)

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

    def step(self, double t, double h, x, aux, inputs, embedded, double max_step,
             double free_step, on_switch, peak=None):
        """One macro step of the host: ``x = [q, dq]`` and ``aux`` (the
        embedded contacts' quadratures, whose first moments restart at zero)
        are advanced in place by RK4 (:meth:`integrate`, which raises
        ``peak`` to the contacts' peaks); returns the port velocity moments
        ``int v s^j dt``, ``(3, n_p)`` complex."""
        cdef double[::1] xv = x
        cdef double[::1] av = aux
        cdef int i, nx = xv.shape[0], na = av.shape[0]
        if nx + na + 6 * self.np_ != self.ny:
            raise ValueError(f"`x` and `aux` must hold {self.ny - 6 * self.np_} entries, "
                             f"got {nx + na}")
        self.set_step(t, h, inputs, embedded)
        for i in range(self.nc):
            av[4 * i + 2] = 0.0                 # first moments are per step
        y0 = np.zeros(self.ny)
        cdef double[::1] yv = y0
        for i in range(nx):
            yv[i] = xv[i]
        for i in range(na):
            yv[nx + i] = av[i]
        y1 = self.integrate(t, y0, t + h, max_step, free_step, True, on_switch, peak)
        yv = y1
        for i in range(nx):
            xv[i] = yv[i]
        for i in range(na):
            av[i] = yv[nx + i]
        return y1[nx + na:].view(complex).reshape(3, self.np_)

    # ------------------------------------------------------------ the C face
    def configure_side(self, double max_step, double free_step):
        """RK4's largest sub-step and its sub-step while no contact is closed
        (``<= 0``: none) [s], for :meth:`side_step`."""
        self.cs_max_step, self.cs_free_step = max_step, free_step

    def side_face(self):
        """The C face of :meth:`side_step` and :meth:`side_outputs`, a
        capsule (:mod:`cosim.core._side_face`) that lives as long as this kernel."""
        self.cface.side = <void*> self
        self.cface.step = _face_step
        self.cface.outputs = _face_outputs
        return PyCapsule_New(&self.cface, COSIM_SIDE_FACE, NULL)

    cdef int side_step(self, double t, double h, const double* u, int rows, double* x,
                       double* aux, double* pm) except -1:
        """:meth:`step` of a tree that hosts no contact, under the input
        polynomial ``u`` ((rows, n_p, 2) row-major, in ``(time - t) / h``)."""
        cdef int j, p, i, nx = self.nq, na = self.cface.naux
        cdef double* y = &self.cs_y[0]
        if self.nc or rows > MAX_COEF or self.cs_max_step <= 0.0:
            raise ValueError("the C step takes a tree that hosts no contact, an input of at "
                             f"most {MAX_COEF} coefficients, and `configure_side` first")
        self.t0, self.h = t, h
        self.u_len = rows
        self.u_t0, self.u_h = t, h
        for j in range(rows):
            for p in range(self.np_):
                self.u_coef[j, p, 0] = u[(j * self.np_ + p) * 2]
                self.u_coef[j, p, 1] = u[(j * self.np_ + p) * 2 + 1]
        for i in range(nx):
            y[i] = x[i]
        for i in range(na):
            y[nx + i] = aux[i]
        for i in range(nx + na, self.ny):
            y[i] = 0.0
        self._integrate(t, y, t + h, self.cs_max_step, self.cs_free_step, True, None, NULL)
        for i in range(nx):
            x[i] = y[i]
        for i in range(na):
            aux[i] = y[nx + i]
        for i in range(6 * self.np_):
            pm[i] = y[nx + na + i]
        return 0

    cdef void side_outputs(self, const double* x, double* pos, double* vel) noexcept:
        """:meth:`outputs` into ``pos`` and ``vel`` ((n_p, 2) row-major)."""
        cdef int p, n = self.n
        self._frames(&x[0], &x[n])
        for p in range(self.np_):
            self._point(n + p, self.port_body[p], self.pl_re[p], self.pl_im[p], &x[n], False)
            pos[2 * p], pos[2 * p + 1] = self.px_re[n + p], self.px_im[n + p]
            vel[2 * p], vel[2 * p + 1] = self.pv_re[n + p], self.pv_im[n + p]

    # ------------------------------------------------------------ kinematics
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

    # ------------------------------------------------------------ stepping
    cdef int _single(self, double t, const double* y, double h, const double* k1,
                     double* out) noexcept nogil:
        """One RK4 step of ``h`` from ``(t, y)`` into ``out`` (``k1 = f(t, y)``)."""
        cdef int i, ny = self.ny
        cdef double* k2 = &self.stage[1, 0]
        cdef double* k3 = &self.stage[2, 0]
        cdef double* k4 = &self.stage[3, 0]
        cdef double* tmp = &self.stage[4, 0]
        cdef double* sw = &self.sw_tmp[0]
        for i in range(ny):
            tmp[i] = y[i] + 0.5 * h * k1[i]
        if self._rhs(t + 0.5 * h, tmp, k2, sw):
            return -1
        for i in range(ny):
            tmp[i] = y[i] + 0.5 * h * k2[i]
        if self._rhs(t + 0.5 * h, tmp, k3, sw):
            return -1
        for i in range(ny):
            tmp[i] = y[i] + h * k3[i]
        if self._rhs(t + h, tmp, k4, sw):
            return -1
        for i in range(ny):
            out[i] = y[i] + (h / 6.0) * (k1[i] + 2.0 * (k2[i] + k3[i]) + k4[i])
        return 0

    cdef double _locate(self, double t, const double* y0, const double* f0, const double* y1,
                        const double* f1, double h, const double* s0,
                        const char* flipped) noexcept nogil:
        """Earliest switch time in ``(t, t + h)`` on the Hermite interpolant,
        just past the root; -1 when the switch sits at the sub-step's end."""
        cdef double lo = 0.0, hi = 1.0, mid, tol
        cdef int it, k, i, hit
        cdef double* yi = &self.stage[7, 0]
        cdef double* s = &self.sws[2, 0]
        tol = 1e-14 * (fabs(t) if fabs(t) > 1.0 else 1.0)
        for it in range(60):
            mid = 0.5 * (lo + hi)
            for i in range(self.nq):
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

    cdef object _notify(self, object on_switch, double t, double* y, double* k,
                        double* s_old, double* s_new):
        """Tell the host of each flipped switch; apply a jump it returns."""
        cdef int j, i
        flips = [j for j in range(self.nc) if (s_old[j] > 0.0) != (s_new[j] > 0.0)]
        self.n_switches += len(flips)
        for j in flips:
            yarr = np.asarray(<double[:self.ny]> y).copy()
            jumped = on_switch(t, j, bool(s_new[j] > 0.0), yarr)
            if jumped is not None:
                jarr = np.ascontiguousarray(jumped, dtype=float)
                for i in range(self.ny):
                    y[i] = jarr[i]
                if self._rhs(t, y, k, s_new):
                    self._fail(t)

    cdef _fail(self, double t):
        raise FloatingPointError(f"the mass matrix is not positive definite at t = {t:.6g} s")

    cdef void _watch(self, double* peak, double h) noexcept nogil:
        """One accepted sub-step of ``h`` whose end the last right-hand side
        evaluated: raise ``peak`` over it; its end becomes the next start."""
        _substep_peaks(peak, &self.pen[2, 0], &self.pen[3, 0], &self.pen[0, 0], &self.pen[1, 0],
                       h, self.nc)
        self._watched()

    cdef void _watched(self) noexcept nogil:
        """The last right-hand side's penetrations start the next sub-step."""
        cdef int k
        for k in range(self.nc):
            self.pen[2, k] = self.pen[0, k]
            self.pen[3, k] = self.pen[1, k]

    def integrate(self, double t0, y0, double t1, double max_step, double free_step,
                  bint coarse, on_switch=None, peak=None):
        """Advance ``y0`` from ``t0`` to ``t1`` (see
        :meth:`cosim.core.ode.TimeStepper.integrate`, whose algorithm this
        is); ``free_step <= 0`` means none.  With ``peak`` (one entry per
        contact), each contact's largest penetration over the step is located
        on the accepted sub-steps' cubic Hermite and raised into it, as the
        reference's ``probe``/``peak`` do.  Returns the new state."""
        ybuf = np.array(y0, dtype=float)
        if ybuf.size != self.ny:
            raise ValueError(f"`y0` must have {self.ny} entries, got {ybuf.size}")
        cdef double[::1] yv = ybuf
        cdef double[::1] pkv
        cdef double* pk = NULL
        if peak is not None and self.nc > 0:
            pkv = peak
            if pkv.shape[0] != self.nc:
                raise ValueError(f"`peak` must have {self.nc} entries, got {pkv.shape[0]}")
            pk = &pkv[0]
        self._integrate(t0, &yv[0], t1, max_step, free_step, coarse, on_switch, pk)
        return ybuf

    cdef int _integrate(self, double t0, double* y, double t1, double max_step,
                        double free_step, bint coarse, object on_switch,
                        double* pk) except -1:
        """:meth:`integrate` in place on ``y``; ``pk`` NULL: no peaks."""
        cdef int ny = self.ny, nc = self.nc, i, n, it, k
        cdef double t = t0, te, h, dt, step, ts
        cdef bint any_closed, any_flip, has_sw = nc > 0
        cdef double* k1 = &self.stage[0, 0]
        cdef double* y1 = &self.stage[5, 0]
        cdef double* k1n = &self.stage[6, 0]
        cdef double* s0 = &self.sws[0, 0]
        cdef double* s1 = &self.sws[1, 0]
        cdef double* snew = &self.sws[3, 0]
        cdef char flipped[MAX_CONTACTS]
        cdef unsigned long polls = 0
        if self._rhs(t, y, k1, s0):
            self._fail(t)
        if pk != NULL:
            self._watched()
        step = max_step
        if coarse and free_step > 0.0:
            any_closed = False
            for k in range(nc):
                if s0[k] > 0.0:
                    any_closed = True
            if not any_closed:
                step = free_step
        n = <int>ceil((t1 - t0) / step - 1e-9)
        if n < 1:
            n = 1
        dt = (t1 - t0) / n
        i = 0
        while i < n:
            polls += 1
            if polls & SIGNAL_POLL == 0:
                # a signal's Python handler runs here; the exception it raises
                # (KeyboardInterrupt) ends the step, leaving `y` at a whole RK4 step
                PyErr_CheckSignals()
            te = t1 if i == n - 1 else t0 + (i + 1) * dt
            h = te - t
            if self._single(t, y, h, k1, y1):
                self._fail(t)
            if self._rhs(te, y1, k1n, s1):
                self._fail(te)
            if has_sw:
                any_flip = False
                for k in range(nc):
                    flipped[k] = (s0[k] > 0.0) != (s1[k] > 0.0)
                    if flipped[k]:
                        any_flip = True
                if any_flip and step > max_step:
                    step = max_step
                    t0 = t
                    i = 0
                    n = <int>ceil((t1 - t0) / step - 1e-9)
                    if n < 1:
                        n = 1
                    dt = (t1 - t0) / n
                    continue
                if any_flip:
                    ts = self._locate(t, y, k1, y1, k1n, h, s0, flipped)
                    if ts >= 0.0:
                        if self._single(t, y, ts - t, k1, &self.stage[8, 0]):
                            self._fail(t)
                        memcpy(y, &self.stage[8, 0], ny * sizeof(double))
                        if self._rhs(ts, y, k1, snew):
                            self._fail(ts)
                        if pk != NULL:
                            self._watch(pk, ts - t)
                        t = ts
                        if on_switch is not None:
                            self._notify(on_switch, t, y, k1, s0, snew)
                            if pk != NULL:
                                self._watched()     # after a jump of the rates
                        memcpy(s0, snew, nc * sizeof(double))
                        continue
                    if pk != NULL:
                        self._watch(pk, h)
                    if on_switch is not None:
                        self._notify(on_switch, te, y1, k1n, s0, s1)
                        if pk != NULL:
                            self._watched()
                elif pk != NULL:
                    self._watch(pk, h)
                memcpy(s0, s1, nc * sizeof(double))
            t = te
            memcpy(y, y1, ny * sizeof(double))
            memcpy(k1, k1n, ny * sizeof(double))
            i += 1
        return 0

    # ------------------------------------------------------- Python faces
    def face(self):
        """The tree's compiled model-exchange face (:class:`TreeFace`), for the
        monolithic reference's compiled right-hand side."""
        return TreeFace(self)

    def rhs(self, double t, y):
        """``dy/dt`` at ``(t, y)`` (the numpy reference's ``_rhs``)."""
        yin = np.ascontiguousarray(y, dtype=float)
        if yin.size != self.ny:
            raise ValueError(f"`y` must have {self.ny} entries, got {yin.size}")
        out = np.empty(self.ny)
        cdef double[::1] yv = yin
        cdef double[::1] ov = out
        if self._rhs(t, &yv[0], &ov[0], &self.sws[2, 0]):
            self._fail(t)
        return out

    def switch(self, double t, y):
        """The contacts' switch values at ``(t, y)``."""
        yin = np.ascontiguousarray(y, dtype=float)
        out = np.empty(self.nc)
        cdef double[::1] yv = yin
        if self.nc:
            self._switch(t, &yv[0], &self.sws[2, 0])
            for k in range(self.nc):
                out[k] = self.sws[2, k]
        return out

    def evaluate(self, y):
        """``M``, ``F`` and the ports' complex positions, velocities and
        Jacobian rows at state ``y = [q, dq, ...]``: what
        :meth:`multibody.TreeModel.evaluate` returns (less the
        velocity-product terms), for a right-hand side written in Python."""
        yin = np.ascontiguousarray(y, dtype=float)
        cdef double[::1] yv = yin
        cdef int i, j, n = self.n, npt = self.np_
        self._frames(&yv[0], &yv[n])
        for i in range(n):
            self._point(i, i, self.com_re[i], self.com_im[i], &yv[n], True)
        for i in range(npt):
            self._point(n + i, self.port_body[i], self.pl_re[i], self.pl_im[i], &yv[n], True)
        self._mass_and_forces()
        M = np.array(self.M)
        F = np.array(self.F)
        x = np.empty(npt, complex)
        v = np.empty(npt, complex)
        J = np.empty((npt, n), complex)
        for i in range(npt):
            x[i] = complex(self.px_re[n + i], self.px_im[n + i])
            v[i] = complex(self.pv_re[n + i], self.pv_im[n + i])
            for j in range(n):
                J[i, j] = complex(self.J_re[n + i, j], self.J_im[n + i, j])
        return M, F, x, v, J

    def outputs(self, y):
        """Port positions and velocities, each ``(n_p, 2)`` [m], [m/s], at
        state ``y = [q, dq, ...]``."""
        yin = np.ascontiguousarray(y, dtype=float)
        cdef double[::1] yv = yin
        cdef int p, n = self.n
        pos = np.empty((self.np_, 2))
        vel = np.empty((self.np_, 2))
        cdef double[:, ::1] pv = pos
        cdef double[:, ::1] vv = vel
        self._frames(&yv[0], &yv[n])
        for p in range(self.np_):
            self._point(n + p, self.port_body[p], self.pl_re[p], self.pl_im[p], &yv[n], False)
            pv[p, 0], pv[p, 1] = self.px_re[n + p], self.px_im[n + p]
            vv[p, 0], vv[p, 1] = self.pv_re[n + p], self.pv_im[n + p]
        return pos, vel

    def energy(self, y):
        """Kinetic energy plus gravity's potential energy relative to the
        world origin [J] at state ``y = [q, dq, ...]``
        (:meth:`multibody.TreeModel.kinetic_energy` and ``potential_energy``)."""
        yin = np.ascontiguousarray(y, dtype=float)
        cdef double[::1] yv = yin
        return self._energy(&yv[0])

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

    def penetrations(self, double t, y):
        """The contacts' penetrations [m] and rates [m/s] at ``(t, y)``, as
        two lists (the reference's ``MultibodySubsystem._probe``)."""
        yin = np.ascontiguousarray(y, dtype=float)
        cdef double[::1] yv = yin
        cdef int k, p
        cdef double d, dd
        ds, dds = [], []
        self._frames(&yv[0], &yv[self.n])
        for k in range(self.nc):
            p = self.c_port[k]
            self._point(self.n + p, self.port_body[p], self.pl_re[p], self.pl_im[p],
                        &yv[self.n], False)
            self._penetration(k, t, &d, &dd)
            ds.append(d)
            dds.append(dd)
        return ds, dds

    # ------------------------------------------------- many output points
    def sample_steps(self, x, aux, embedded, long k0, long k1, double H, double t_end,
                     double sliver, double max_step, double free_step, on_switch, peak,
                     double[::1] T, double[:, ::1] Y, double[:, ::1] PK, moments):
        """Take the host's macro steps ``k0 .. k1 - 1`` in one call, each as
        :meth:`step` takes it (from ``t = k H`` over ``h = min(H, t_end - t)``,
        RK4 restarted at ``t``, first moments from zero, no input force: a
        side whose contacts all have rigid partners receives none), and
        keep what a recorder needs at the end of each.

        Row ``j`` of ``T`` gets the step's end time ``t + h`` [s], of ``Y``
        the state ``[x, aux]`` there and of ``PK`` each contact's largest
        penetration over the step (``peak`` is raised during the step, copied,
        then zeroed: what the host's ``take_peaks`` gives at each sample).
        ``x`` and ``aux`` are advanced in place; ``moments`` (the host's
        ``port_moments``, ``(3, n_p)`` complex) gets the last step's.

        Returns after step ``k1 - 1``, after a step ``h`` of which is at
        most ``sliver`` (not taken: the run has ended), after a step in
        which a switch was located (the host was told: its logs hold the
        step's switches and impacts, which its recorder must see before
        the sample), or after a step that left the state non-finite.
        Returns ``(rows, why)``, ``why`` one of ``"steps"``, ``"end"``,
        ``"switch"``, ``"nonfinite"``.  :attr:`n_sampled` counts the rows
        filled as they are, so a caller that catches an exception raised
        inside a step (by the host's ``on_switch``) knows which rows hold
        whole steps.
        """
        cdef double[::1] xv = x
        cdef double[::1] av = aux
        cdef int i, nx = xv.shape[0], na = av.shape[0], ny = self.ny, nc = self.nc
        cdef long k, j = 0, switches
        cdef double t, h
        cdef double[::1] pkv
        cdef double* pk = NULL
        cdef bint finite
        if nx + na + 6 * self.np_ != ny:
            raise ValueError(f"`x` and `aux` must hold {ny - 6 * self.np_} entries, "
                             f"got {nx + na}")
        if Y.shape[1] != nx + na or PK.shape[1] != nc or T.shape[0] < k1 - k0 \
                or Y.shape[0] < k1 - k0 or PK.shape[0] < k1 - k0:
            raise ValueError(f"the buffers must hold {k1 - k0} rows of {nx + na} states and "
                             f"{nc} peaks")
        if nc > 0:
            if peak is None or len(peak) != nc:
                raise ValueError(f"`peak` must have {nc} entries")
            pkv = peak
            pk = &pkv[0]
        self.n_sampled = 0
        ybuf = np.zeros(ny)
        cdef double[::1] yv = ybuf
        cdef double* y = &yv[0]
        for i in range(nx):
            y[i] = xv[i]
        for i in range(na):
            y[nx + i] = av[i]
        self.set_step(k0 * H, H, None, embedded)
        why = "steps"
        for k in range(k0, k1):
            t = k * H
            h = H if H <= t_end - t else t_end - t
            if h <= sliver:
                why = "end"
                break
            self.t0, self.h = t, h
            for i in range(nc):
                y[nx + 4 * i + 2] = 0.0              # first moments are per step
            for i in range(nx + na, ny):
                y[i] = 0.0
            switches = self.n_switches
            self._integrate(t, y, t + h, max_step, free_step, True, on_switch, pk)
            T[j] = t + h
            finite = True
            for i in range(nx + na):
                Y[j, i] = y[i]
                if not isfinite(y[i]):
                    finite = False
            for i in range(nc):
                PK[j, i] = pk[i]
                pk[i] = 0.0
            j += 1
            self.n_sampled = j
            for i in range(nx):
                xv[i] = y[i]
            for i in range(na):
                av[i] = y[nx + i]
            if not finite:
                why = "nonfinite"
                break
            if self.n_switches != switches:
                why = "switch"
                break
        moments[...] = ybuf[nx + na:].view(complex).reshape(3, self.np_)
        return j, why

    def sample_outputs(self, double[:, ::1] Y, double[:, :, ::1] P, double[::1] E):
        """Ports' positions and velocities and the energy (:meth:`outputs`,
        :meth:`energy`) at each row of states ``Y`` (``[q, dq, ...]``):
        ``P[j] = [positions (n_p, 2), velocities (n_p, 2)]`` stacked as
        ``(2 n_p, 2)``, ``E[j]`` [J]."""
        cdef int j, p, n = self.n, npt = self.np_
        cdef int m = Y.shape[0]
        if P.shape[0] < m or P.shape[1] != 2 * npt or E.shape[0] < m or Y.shape[1] < 2 * n:
            raise ValueError(f"`P` must be ({m}, {2 * npt}, 2) and `E` ({m},)")
        for j in range(m):
            E[j] = self._energy(&Y[j, 0])
            for p in range(npt):
                self._point(n + p, self.port_body[p], self.pl_re[p], self.pl_im[p], &Y[j, n],
                            False)
                P[j, p, 0], P[j, p, 1] = self.px_re[n + p], self.px_im[n + p]
                P[j, npt + p, 0], P[j, npt + p, 1] = self.pv_re[n + p], self.pv_im[n + p]

cdef int _tree_outputs(void* obj, const double* x, double* pos, double* vel) except -1:
    return (<TreeFace>obj).outputs(x, pos, vel)


cdef int _tree_derivatives(void* obj, double t, const double* x, const double* u,
                           double* dx) except -1:
    return (<TreeFace>obj).derivatives(t, x, u, dx)


cdef int _tree_ledger(void* obj, double t, const double* x, double* rates) except -1:
    return (<TreeFace>obj).ledger_rates(t, x, rates)


cdef int _tree_follow(void* obj, int port, double px, double py, const double* x,
                      double* out) except -1:
    raise TypeError("a tree's ports do not follow a point")


cdef class TreeFace:
    """The model-exchange face of a tree (``cosim.core._stacked``'s
    ``FaceTable``): :meth:`MultibodySubsystem.derivatives`, ``outputs`` and
    ``ledger_rates`` on the kernel's kinematics, mass matrix and joint
    effects, for state ``x = [q, dq]``.  It shares the kernel's workspace (the
    monolithic reference does not step the tree)."""

    cdef MultibodyStep k
    cdef double[::1] rates
    cdef FaceTable tab

    def __init__(self, MultibodyStep kernel):
        self.k = kernel
        self.rates = np.zeros(2)
        self.tab.obj = <void*>self
        self.tab.n_states = 2 * kernel.n
        self.tab.n_ports = kernel.np_
        self.tab.can_follow = 0
        self.tab.outputs = _tree_outputs
        self.tab.derivatives = _tree_derivatives
        self.tab.ledger_rates = _tree_ledger
        self.tab.follow = _tree_follow

    def table(self):
        """The face's ``FaceTable`` in a capsule named ``cosim.FaceTable``."""
        return PyCapsule_New(&self.tab, b"cosim.FaceTable", NULL)

    @property
    def can_follow(self):
        return False
    cdef int outputs(self, const double* x, double* pos, double* vel) except -1:
        cdef MultibodyStep k = self.k
        cdef int p, n = k.n
        k._frames(x, x + n)
        for p in range(k.np_):
            k._point(n + p, k.port_body[p], k.pl_re[p], k.pl_im[p], x + n, False)
            pos[2 * p], pos[2 * p + 1] = k.px_re[n + p], k.px_im[n + p]
            vel[2 * p], vel[2 * p + 1] = k.pv_re[n + p], k.pv_im[n + p]
        return 0

    cdef int derivatives(self, double t, const double* x, const double* u,
                         double* dx) except -1:
        """``[dq, M^-1 (Re(J^H u) - F + effects)]`` for port forces ``u``."""
        cdef MultibodyStep k = self.k
        cdef int i, p, n = k.n, npt = k.np_
        cdef double s
        cdef const double* dq = x + n
        k._frames(x, dq)
        for i in range(n):
            k._point(i, i, k.com_re[i], k.com_im[i], dq, True)
        for p in range(npt):
            k._point(n + p, k.port_body[p], k.pl_re[p], k.pl_im[p], dq, True)
        k._mass_and_forces()
        if k.nd or k.has_springs or k.has_dampers:
            k._effects(t, x, dq, &self.rates[0])
            for i in range(n):
                k.F[i] = k.F[i] - k.tau[i]
        for i in range(n):
            s = 0.0
            for p in range(npt):
                s += k.J_re[n + p, i] * u[2 * p] + k.J_im[n + p, i] * u[2 * p + 1]
            k.b[i] = s - k.F[i]
        for i in range(n):
            dx[i] = dq[i]
        if k._solve(dx + n) != 0:
            k._fail(t)
        return 0

    cdef int ledger_rates(self, double t, const double* x, double* rates) except -1:
        """Power dissipated by the joint dampers and supplied by the drives [W]."""
        cdef MultibodyStep k = self.k
        if k.nd or k.has_springs or k.has_dampers:
            k._effects(t, x, x + k.n, rates)
        else:
            rates[0] = 0.0
            rates[1] = 0.0
        return 0

# ------------------------------------------------- the C face's functions
cdef int _face_step(void* side, double t, double h, const double* u, int rows, double* x,
                    double* aux, double* pm) except -1:
    return (<MultibodyStep> side).side_step(t, h, u, rows, x, aux, pm)


cdef void _face_outputs(void* side, const double* x, double* pos, double* vel) noexcept:
    (<MultibodyStep> side).side_outputs(x, pos, vel)

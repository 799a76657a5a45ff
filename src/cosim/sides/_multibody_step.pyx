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

The tree's model that the step integrates (kinematics, mass matrix and
forces, laws, right-hand side, energy) is the base class
:class:`cosim.sides._multibody_tree.TreeDynamics`; here are the integrator
(RK4 with switches located in the sub-steps), the sampled path and the C face;
the model-exchange face of the monolithic reference is
:mod:`cosim.sides._tree_face`.

State layout (``y``, length ``2 n + 4 n_c + 2 + 6 n_p``)::

    q (n) | dq (n) | per contact: impulse, dissipated, first moment, work (4 n_c)
    | joint dampers' dissipation, drives' supply (2)
    | port velocity moments int v s^j dt, j = 0, 1, 2, complex interleaved (6 n_p)
"""
from libc.math cimport sin, cos, pow, ceil, fabs, sqrt, isfinite
from libc.string cimport memcpy

from cpython.exc cimport PyErr_CheckSignals
from cpython.pycapsule cimport PyCapsule_New

from cosim.core._side_face cimport COSIM_SIDE_FACE, SideFace, free_log, log_switch

import numpy as np

# the tree's model (kinematics, laws, right-hand side, energy), which the
# step below integrates, and the kinds and limits both use
from cosim.sides._multibody_tree cimport (
    TreeDynamics, LINEAR, KELVIN_VOIGT, POWER, RIGID, DRIVE_CONSTANT, DRIVE_TABLE, DRIVE_PD,
    REF_TABLE, REF_MINIMUM_JERK, REF_SINUSOID, MAX_COEF, MAX_CONTACTS, SIGNAL_POLL)

LAW_KINDS = {"linear": LINEAR, "kelvin_voigt": KELVIN_VOIGT, "power": POWER, "rigid": RIGID}
DRIVE_KINDS = {"constant": DRIVE_CONSTANT, "table": DRIVE_TABLE, "pd": DRIVE_PD}
REFERENCE_KINDS = {"table": REF_TABLE, "minimum_jerk": REF_MINIMUM_JERK,
                   "sinusoid": REF_SINUSOID}


# the sub-step's cubic Hermite and its peaks
from cosim.sides._hermite cimport _hermite, _substep_peaks


cdef class _Located:
    """``on_switch`` of the steps of :meth:`MultibodyStep.sample_steps`: a
    switch is kept in the rows ``ST``, ``SJ`` (time; step's row, contact,
    on), but a rigid law's touch, or a switch with no row left, is the
    host's (``told``)."""
    cdef MultibodyStep k
    cdef object host
    cdef double[::1] st
    cdef long[:, ::1] sj
    cdef long row
    cdef bint told

    def __init__(self, MultibodyStep k, host, double[::1] st, long[:, ::1] sj):
        self.k, self.host, self.st, self.sj = k, host, st, sj
        self.row, self.told = 0, False
        k.n_located = 0

    def __call__(self, double t, int j, bint on, y):
        cdef long i = self.k.n_located
        if (self.k.c_kind[j] != RIGID or not on) and i < self.st.shape[0]:
            self.st[i] = t
            self.sj[i, 0], self.sj[i, 1], self.sj[i, 2] = self.row, j, on
            self.k.n_located = i + 1
            return None
        self.told = True
        return self.host(t, j, on, y)


cdef class MultibodyStep(TreeDynamics):
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

    #: number of located switches told to the host so far
    cdef public long n_switches
    #: rows :meth:`sample_steps` has filled in its current (or last) call
    cdef public long n_sampled
    #: switches :meth:`sample_steps` has kept in its rows in its current (or last) call
    cdef public long n_located
    # the C face (cosim.core._side_face): RK4's largest and free sub-steps,
    # and the stepping state
    cdef double cs_max_step, cs_free_step
    cdef double[::1] cs_y
    cdef SideFace cface
    # the compiled loop's step is under way: switches go to the face's log
    cdef bint cs_logging

    def __init__(self, *args, **kwargs):
        TreeDynamics.__init__(self, *args, **kwargs)
        self.n_switches = 0
        self.n_sampled = 0
        self.n_located = 0
        self.cface.nx, self.cface.naux, self.cface.nports = 2 * self.n, 4 * self.nc + 2, self.np_
        self.cs_max_step, self.cs_free_step = 0.0, 0.0
        self.cs_y = np.zeros(self.ny)

    def __dealloc__(self):
        free_log(&self.cface.log)

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
        self.cface.loop = _face_loop
        self.cface.motion = _face_motion
        return PyCapsule_New(&self.cface, COSIM_SIDE_FACE, NULL)

    def retire(self):
        """The host no longer steps through this kernel: the face's
        ``generation`` changes, so that a loop holding it asks the host again."""
        self.cface.generation += 1

    cdef int side_loop(self, double t, double h, const double* u, int rows, double* x,
                       double* aux, double* pm, double* peak) except -1:
        """:meth:`step` under the input polynomial ``u`` ((rows, n_p, 2)
        row-major, in ``(time - t) / h``), the partners' motion as last set
        (:meth:`set_step`, ``side_motion``); the located switches go to the
        face's log.  Returns 1, touching nothing, where the input is beyond
        the kernel or :meth:`configure_side` was not called."""
        cdef int j, p, i, nx = self.cface.nx, na = self.cface.naux
        cdef double* y = &self.cs_y[0]
        if rows > MAX_COEF or self.cs_max_step <= 0.0:
            return 1
        self.t0, self.h = t, h
        self.u_len = rows
        self.u_t0, self.u_h = t, h
        for j in range(rows):
            for p in range(self.np_):
                self.u_coef[j, p, 0] = u[(j * self.np_ + p) * 2]
                self.u_coef[j, p, 1] = u[(j * self.np_ + p) * 2 + 1]
        for i in range(self.nc):
            aux[4 * i + 2] = 0.0                # first moments are per step
        for i in range(nx):
            y[i] = x[i]
        for i in range(na):
            y[nx + i] = aux[i]
        for i in range(nx + na, self.ny):
            y[i] = 0.0
        self.cface.log.n = 0
        self.cs_logging = True
        try:
            self._integrate(t, y, t + h, self.cs_max_step, self.cs_free_step, True, None,
                            peak if self.nc > 0 else NULL)
        finally:
            self.cs_logging = False
        for i in range(nx):
            x[i] = y[i]
        for i in range(na):
            aux[i] = y[nx + i]
        for i in range(6 * self.np_):
            pm[i] = y[nx + na + i]
        return 0

    cdef int side_motion(self, int k, double t0, double h, const double* c,
                         int n) noexcept:
        """Contact ``k``'s partner motion, as :meth:`set_step` loads it from
        its ``EmbeddedContact``; 1 where it is beyond the kernel."""
        cdef int i
        cdef double re, im
        if n > MAX_COEF or not 0 <= k < self.nc:
            return 1
        self.m_len[k] = n
        self.m_t0[k] = t0
        self.m_h[k] = h
        self.m_still[k] = 1
        for i in range(n):
            re, im = c[2 * i], c[2 * i + 1]
            self.m_re[k, i] = re
            self.m_im[k, i] = im
            if i > 0:
                if re != 0 or im != 0:
                    self.m_still[k] = 0
                self.dm_re[k, i - 1] = re * i / h
                self.dm_im[k, i - 1] = im * i / h
        return 0

    cdef int _log_flips(self, double t, const double* s_old, const double* s_new) except -1:
        """:meth:`_notify` for the compiled loop: each flipped switch into the
        face's log."""
        cdef int j
        for j in range(self.nc):
            if (s_old[j] > 0.0) != (s_new[j] > 0.0):
                self.n_switches += 1
                log_switch(&self.cface.log, t, j, s_new[j] > 0.0)
        return 0

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
                        elif self.cs_logging:
                            self._log_flips(t, s0, snew)
                        memcpy(s0, snew, nc * sizeof(double))
                        continue
                    if pk != NULL:
                        self._watch(pk, h)
                    if on_switch is not None:
                        self._notify(on_switch, te, y1, k1n, s0, s1)
                        if pk != NULL:
                            self._watched()
                    elif self.cs_logging:
                        self._log_flips(te, s0, s1)
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
        from cosim.sides._tree_face import TreeFace
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
                     double[::1] T, double[:, ::1] Y, double[:, ::1] PK, moments,
                     double[::1] ST, long[:, ::1] SJ):
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

        A switch located in a step (a penalty law's touch or release, a
        rigid law's release) is written to row ``i`` of ``ST`` (its time)
        and ``SJ`` (the step's row, the contact, 1 for on) and the steps go
        on; a rigid law's touch (an impact, resolved in Python) and a switch
        past the buffers' end go to the host's ``on_switch`` (its logs hold
        them), and the call returns after that step.

        Returns after step ``k1 - 1``, after a step ``h`` of which is at
        most ``sliver`` (not taken: the run has ended), after a step in
        which the host was told of a switch (its recorder must see the
        step's switches and impacts before the sample), or after a step
        that left the state non-finite.  Returns ``(rows, why, located)``,
        ``why`` one of ``"steps"``, ``"end"``, ``"switch"``,
        ``"nonfinite"``, ``located`` the rows of ``ST`` and ``SJ`` filled.
        :attr:`n_sampled` and :attr:`n_located` count the rows filled as
        they are, so a caller that catches an exception raised inside a
        step (a signal's, or the host's ``on_switch``'s) knows which rows
        hold whole steps.
        """
        cdef double[::1] xv = x
        cdef double[::1] av = aux
        cdef int i, nx = xv.shape[0], na = av.shape[0], ny = self.ny, nc = self.nc
        cdef long k, j = 0
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
        if SJ.shape[1] != 3 or SJ.shape[0] != ST.shape[0]:
            raise ValueError("`SJ` must have 3 columns and as many rows as `ST`")
        cdef _Located rows = _Located(self, on_switch, ST, SJ)
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
            rows.row = j
            self._integrate(t, y, t + h, max_step, free_step, True, rows, pk)
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
            if rows.told:
                why = "switch"
                break
        moments[...] = ybuf[nx + na:].view(complex).reshape(3, self.np_)
        return j, why, self.n_located

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

# ------------------------------------------------- the C face's functions
cdef int _face_step(void* side, double t, double h, const double* u, int rows, double* x,
                    double* aux, double* pm) except -1:
    return (<MultibodyStep> side).side_step(t, h, u, rows, x, aux, pm)


cdef void _face_outputs(void* side, const double* x, double* pos, double* vel) noexcept:
    (<MultibodyStep> side).side_outputs(x, pos, vel)


cdef int _face_loop(void* side, double t, double h, const double* u, int rows, double* x,
                    double* aux, double* pm, double* peak, signed char* closed) except -1:
    return (<MultibodyStep> side).side_loop(t, h, u, rows, x, aux, pm, peak)


cdef int _face_motion(void* side, int slot, double t0, double h, const double* c,
                      int n) noexcept:
    return (<MultibodyStep> side).side_motion(slot, t0, h, c, n)

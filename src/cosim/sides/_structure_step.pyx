# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True
# cython: initializedcheck=False, nonecheck=False
"""The structure side's step, compiled.

One call advances an undamped linear structure in its kept modes over a macro
step in closed form: each phase between switches of its hosted linear springs
is a linear system under a polynomial load, stepped exactly in the modes of
that phase; touch and release are located on the exact solution (sampled,
then safeguarded Newton; a phase with every spring open is not sampled where
a bound of the exact solution proves none can close in it); the springs'
impulses, first moments and work and the ports' velocity moments are
integrated in closed form; each closed
spring's largest penetration over a segment is located on the exact solution
where its rate falls through zero (Illinois regula falsi), and raises the
host's ``peak``.  A structure that
hosts no contact is stepped exactly under the port loads, its velocity
moments by three-point Gauss-Legendre.  It is the compiled twin of the numpy
reference in :mod:`cosim.sides.fem` (:meth:`StructureSubsystem._step_closed_form`
and the open exact step) and :mod:`fem.response`: the same formulas in the
same order, so the two agree to round-off, which
``tests/test_kernel_structure.py`` holds them to.

The modes of each set of closed springs (an eigen-decomposition) are asked of
the host once (``basis(active)``, LAPACK or the rank-one update there) and
kept here, so no Python object is touched inside a step except on that rare
event and to hand back the located switches.

Arrays shared with the host (read at each step, so the host may change them
in place between steps, as a contact that follows a moving point does): the
ports' shape rows ``R`` (n_p, m), reference positions ``ref`` (n_p, 2) and,
given per port, directions ``dirs`` (n_p, 2).  After changing ``R`` or
``dirs`` the host calls :meth:`StructureStep.forget_bases`; a hosted
contact's normal it changes with :meth:`StructureStep.set_normal`.

The kernel is four modules, each a concept, which call one another in C
(their ``.pxd``): :mod:`cosim.sides._rank_one` (the modes with one spring
closed, by the secular equation), :mod:`cosim.sides._structure_modes`
(:class:`ModalResponse`: the state, the kept modes and a segment's exact
response, the step with no contact), :mod:`cosim.sides._structure_contacts`
(:class:`ContactPhases`: the springs' phases, their switches, peaks and
quadratures, and the step with them) and this one, :class:`StructureStep`, the
face its host calls (Python, and the C face of :mod:`cosim.core._side_face`).
"""
from cpython.pycapsule cimport PyCapsule_New

from cosim.core._side_face cimport COSIM_SIDE_FACE, SideFace, free_log
from cosim.sides._structure_contacts cimport ContactPhases
from cosim.sides._structure_modes cimport DEG1, MAX_BASES, MAX_CONTACTS

import numpy as np

# the names a host imports from here
from cosim.sides._rank_one import rank_one_eigh
from cosim.sides._structure_contacts import MAX_SEGMENTS, StalledStep


#: the interface the host (:mod:`cosim.sides.fem`, its ``STEP_API``) calls:
#: bumped when a call changes (2: ``StructureStep.step`` takes ``peak``; 3:
#: ``direction`` may be given per port, and ``set_normal``)
STEP_API = 3


cdef class StructureStep(ContactPhases):
    """Compiled step of one :class:`cosim.sides.fem.StructureSubsystem`.

    Parameters
    ----------
    omega : (m,) array
        Circular frequencies of the kept modes [rad/s] (undamped).
    R : (n_p, m) array
        The ports' shape rows, shared (see the module).
    ref : (n_p, 2) array
        The ports' reference positions [m], shared.
    direction : (2,) or (n_p, 2) array
        The field's direction, or each port's, shared (a plane body's ports
        move along their segments' normals).
    g_modal : (m,) array
        The weight's modal load.
    contacts : list of tuples
        Per hosted contact, a linear spring: ``(port, side, normal (complex),
        offset [m], contact_stiffness [N/m])``.
    basis : callable
        ``basis(active) -> (lam, Psi or None, omega_max)``: the modes of the
        modal equations with the springs of the closed contacts ``active``
        (a tuple of bools) added; ``Psi`` None for the structure's own modes.
    """

    # the C face (cosim.core._side_face), and the compiled loop's copies of
    # the host's state that a step it declines leaves untouched
    cdef SideFace face
    cdef double[::1] cs_x, cs_aux, cs_peak
    cdef double[:, ::1] cs_pm
    cdef signed char[::1] cs_closed

    def __init__(self, omega, R, ref, direction, g_modal, contacts, basis):
        cdef int m = len(omega)
        self.m = m
        self.R = R
        self.ref = ref
        self.np_ = self.R.shape[0]
        if self.R.shape[1] != m or self.ref.shape[0] != self.np_:
            raise ValueError(f"`R` must have shape (n_ports, {m}) and `ref` (n_ports, 2), "
                             f"got {np.shape(R)} and {np.shape(ref)}")
        self.nc = len(contacts)
        if self.nc > MAX_CONTACTS:
            raise ValueError(f"the kernel hosts at most {MAX_CONTACTS} contacts per "
                             f"structure, got {self.nc}")
        dirs = np.asarray(direction, dtype=float)
        if dirs.shape == (2,):
            dirs = np.tile(dirs, (self.np_, 1))
        if dirs.shape != (self.np_, 2):
            raise ValueError(f"`direction` must have shape (2,) or (n_ports, 2), got "
                             f"{np.shape(direction)}")
        self.dirs = dirs if self.np_ else np.zeros((1, 2))
        self.lam0 = np.ascontiguousarray(np.asarray(omega, float) ** 2)
        self.wmax0 = float(np.max(omega, initial=0.0))
        self.g_modal = np.ascontiguousarray(g_modal, dtype=float)
        nc = max(self.nc, 1)
        self.c_port = np.array([c[0] for c in contacts] or [0], dtype=np.int_)
        self.c_side = np.array([c[1] for c in contacts] or [0.0])
        self.c_nre = np.array([complex(c[2]).real for c in contacts] or [0.0])
        self.c_nim = np.array([complex(c[2]).imag for c in contacts] or [0.0])
        self.c_off = np.array([c[3] for c in contacts] or [0.0])
        self.c_k = np.array([c[4] for c in contacts] or [0.0])
        self.host_basis = basis
        self.t, self.h, self.g_len, self.loaded = 0.0, 1.0, 1, False
        self.Gin = np.zeros((DEG1, m))
        self.m_len = np.ones(nc, dtype=np.int_)
        self.dm_len = np.ones(nc, dtype=np.int_)
        self.m_t0 = np.zeros(nc)
        self.m_h = np.ones(nc)
        self.m_re = np.zeros((nc, DEG1 + 1))
        self.m_im = np.zeros((nc, DEG1 + 1))
        self.dm_re = np.zeros((nc, DEG1 + 1))
        self.dm_im = np.zeros((nc, DEG1 + 1))
        self.n_bases, self.next_base = 0, 0
        self.b_mask = np.zeros(MAX_BASES, dtype=np.longlong)
        self.b_ident = np.zeros(MAX_BASES, dtype=np.int_)
        self.b_wmax = np.zeros(MAX_BASES)
        self.b_lam = np.zeros((MAX_BASES, m))
        self.b_psi = np.zeros((MAX_BASES, m, m))
        self.b_P = np.zeros((MAX_BASES, m, max(self.np_, 1)))
        self.q = np.zeros(m); self.dq = np.zeros(m)
        self.z0 = np.zeros(m); self.dz0 = np.zeros(m)
        self.zt = np.zeros(m); self.dzt = np.zeros(m)
        self.om = np.zeros(m); self.b0 = np.zeros(m); self.b1 = np.zeros(m)
        self.b2 = np.zeros(m); self.b3 = np.zeros(m); self.A = np.zeros(m); self.B = np.zeros(m)
        self.rigid = np.zeros(m, dtype=np.int_)
        self.a = np.zeros((DEG1, m)); self.aS = np.zeros((DEG1, m))
        self.C = np.zeros((DEG1, m)); self.S = np.zeros((DEG1, m))
        npp = max(self.np_, 1)
        self.Wm = np.zeros((DEG1, npp))
        self.W = np.zeros(npp); self.DW = np.zeros(npp)
        self.W0 = np.zeros(npp); self.WL = np.zeros(npp)
        self.d0 = np.zeros(nc); self.dd0 = np.zeros(nc); self.dprev = np.zeros(nc)
        self.dcur = np.zeros(nc); self.ddcur = np.zeros(nc)
        self.ddprev = np.zeros(nc); self.seg_peak = np.zeros(nc)
        self.active = np.zeros(nc, dtype=np.int_)
        self.r1_work = np.zeros(3 * m * m + 20 * m)
        self.r1_z = np.zeros(m)
        self.r1_lam = np.zeros(m)
        self.r1_V = np.zeros(m * m)
        self.n_segments = 0
        self.n_host_bases = 0
        self.n_unprobed = 0
        self.bound_open = True
        # the C face: a structure that hosts no contact, stepped exactly; its
        # quadratures are not touched
        self.face.nx, self.face.naux, self.face.nports = 2 * m, 0, self.np_
        self.cs_x, self.cs_aux, self.cs_peak = np.zeros(2 * m), np.zeros(4 * nc + 2), np.zeros(nc)
        self.cs_pm = np.zeros((3, 2 * max(self.np_, 1)))
        self.cs_closed = np.zeros(nc, dtype=np.int8)

    def __dealloc__(self):
        free_log(&self.face.log)

    # --------------------------------------------------------------- loading
    def forget_bases(self):
        """Drop the kept modes (the ports' shape rows changed)."""
        self.n_bases, self.next_base = 0, 0

    def set_normal(self, int k, normal):
        """Hosted contact ``k``'s normal (complex) is now ``normal`` (a
        contact that follows a plane body's boundary turns with it); the
        host calls :meth:`forget_bases` too."""
        if not 0 <= k < self.nc:
            raise IndexError(f"contact {k} of {self.nc}")
        self.c_nre[k], self.c_nim[k] = complex(normal).real, complex(normal).imag

    def set_step(self, double t, double h, coeffs, motions):
        """Load the step: its start ``t`` and length ``h`` [s], the port
        forces' polynomial coefficients in ``s = (time - t) / h``
        ((p + 1, n_p, 2) array, or None) and, per contact, the partner's
        motion ``(t0, h, coeffs, dcoeffs)`` (complex coefficients of its
        position and velocity in the partner's normalised time).

        Returns False, loading nothing, when the step is beyond the kernel
        (a load or a motion of degree above 3): the reference takes it."""
        cdef int k, i, rows = 1
        cdef double[:, :, ::1] cv
        if coeffs is not None:
            cv = np.ascontiguousarray(coeffs, dtype=float)
            rows = cv.shape[0]
            if rows > DEG1 - 1 or cv.shape[1] != self.np_ or cv.shape[2] != 2:
                return False
        for mt0, mh, mc, dmc in motions:
            if len(mc) > DEG1 or len(dmc) > DEG1:
                return False
        self._load(t, h, NULL if coeffs is None else &cv[0, 0, 0], rows)
        for k, (mt0, mh, mc, dmc) in enumerate(motions):
            self.m_t0[k], self.m_h[k] = mt0, mh
            self.m_len[k], self.dm_len[k] = len(mc), len(dmc)
            for i in range(len(mc)):
                self.m_re[k, i] = mc[i].real
                self.m_im[k, i] = mc[i].imag
            for i in range(len(dmc)):
                self.dm_re[k, i] = dmc[i].real
                self.dm_im[k, i] = dmc[i].imag
        return True

    cdef void _load(self, double t, double h, const double* cv, int rows) noexcept nogil:
        """The step's start, length and modal load from the port forces
        ``cv`` ((rows, n_p, 2) row-major, or NULL for none)."""
        cdef int j, i, p, m = self.m, npt = self.np_
        cdef double u
        self.t, self.h = t, h
        self.g_len = rows
        self.loaded = False
        for j in range(DEG1):
            for i in range(m):
                self.Gin[j, i] = 0.0
        if cv != NULL:
            # (u @ dir) @ R, then the weight
            for j in range(rows):
                for p in range(npt):
                    if cv[(j * npt + p) * 2] != 0.0 or cv[(j * npt + p) * 2 + 1] != 0.0:
                        self.loaded = True
                    u = (cv[(j * npt + p) * 2] * self.dirs[p, 0]
                         + cv[(j * npt + p) * 2 + 1] * self.dirs[p, 1])
                    for i in range(m):
                        self.Gin[j, i] += u * self.R[p, i]
        for i in range(m):
            self.Gin[0, i] += self.g_modal[i]

    # ------------------------------------------------------ the C face
    def side_face(self):
        """The C face of :meth:`side_step` and :meth:`side_outputs`, a
        capsule (:mod:`cosim.core._side_face`) that lives as long as this kernel."""
        self.face.side = <void*> self
        self.face.step = _face_step
        self.face.outputs = _face_outputs
        self.face.loop = _face_loop
        self.face.motion = _face_motion
        return PyCapsule_New(&self.face, COSIM_SIDE_FACE, NULL)

    def retire(self):
        """The host no longer steps through this kernel: the face's
        ``generation`` changes, so that a loop holding it asks the host again."""
        self.face.generation += 1

    cdef int side_loop(self, double t, double h, const double* u, int rows, double* x,
                       double* aux, double* pm, double* peak, signed char* closed) except -1:
        """The host's step as its ``_step_impl`` takes it through :meth:`set_step`
        (the partners' motion as last set) and :meth:`step` or :meth:`step_free`,
        on copies of its state: the switches go to the face's log.  Returns
        1, touching nothing, where the load is beyond the kernel or the step
        stalled (the host's own step then takes it)."""
        cdef int i, nc = self.nc, m = self.m, npt = self.np_
        cdef double at
        if rows > DEG1 - 1:
            return 1
        self._load(t, h, u, rows)
        self.face.log.n = 0
        if not nc:
            for i in range(6 * npt):
                pm[i] = 0.0
            self._free(x, pm)
            return 0
        for i in range(2 * m):
            self.cs_x[i] = x[i]
        for i in range(4 * nc + 2):
            self.cs_aux[i] = aux[i]
        for i in range(nc):
            self.cs_peak[i] = peak[i]
            self.cs_closed[i] = closed[i]
        for i in range(6 * npt):
            self.cs_pm[i // (2 * npt), i % (2 * npt)] = 0.0
        if self._advance(self.cs_x, self.cs_aux, self.cs_pm, self.cs_closed, self.cs_peak,
                         &self.face.log, &at):
            self.face.log.n = 0
            return 1
        for i in range(2 * m):
            x[i] = self.cs_x[i]
        for i in range(4 * nc + 2):
            aux[i] = self.cs_aux[i]
        for i in range(nc):
            peak[i] = self.cs_peak[i]
            closed[i] = self.cs_closed[i]
        for i in range(6 * npt):
            pm[i] = self.cs_pm[i // (2 * npt), i % (2 * npt)]
        return 0

    cdef int side_motion(self, int k, double t0, double h, const double* c,
                         int n) noexcept:
        """Contact ``k``'s partner motion, as :meth:`set_step` loads it from
        an ``EmbeddedContact`` (its ``velocity_coeffs`` with numpy's complex
        arithmetic); 1 where it is beyond the kernel."""
        cdef int i
        cdef double re, im, pr, pi, rat, scl
        if n > DEG1 or not 0 <= k < self.nc:
            return 1
        self.m_t0[k], self.m_h[k] = t0, h
        self.m_len[k] = n
        for i in range(n):
            self.m_re[k, i] = c[2 * i]
            self.m_im[k, i] = c[2 * i + 1]
        if n < 2:
            self.dm_len[k] = 1
            self.dm_re[k, 0] = 0.0
            self.dm_im[k, 0] = 0.0
            return 0
        self.dm_len[k] = n - 1
        rat = 0.0 / h
        scl = 1.0 / (h + 0.0 * rat)
        for i in range(1, n):
            re, im = c[2 * i], c[2 * i + 1]
            pr = re * i - im * 0.0              # (c * (i + 0j)) / (h + 0j) as numpy
            pi = re * 0.0 + im * i
            self.dm_re[k, i - 1] = (pr + pi * rat) * scl
            self.dm_im[k, i - 1] = (pi - pr * rat) * scl
        return 0

    cdef int side_step(self, double t, double h, const double* u, int rows, double* x,
                       double* aux, double* pm) except -1:
        """The exact step of a structure that hosts no contact (what
        :meth:`set_step` and :meth:`step_free` do for its Python host);
        ``aux`` is not touched."""
        cdef int i
        if self.nc or rows > DEG1 - 1:
            raise ValueError("the C step takes a structure that hosts no contact, under a "
                             f"load of at most {DEG1 - 1} coefficients")
        self._load(t, h, u, rows)
        for i in range(6 * self.np_):
            pm[i] = 0.0
        self._free(x, pm)
        return 0

    cdef void side_outputs(self, const double* x, double* pos, double* vel) noexcept:
        """Ports' positions and velocities (:meth:`StructureSubsystem.outputs`)."""
        cdef int i, p, m = self.m
        cdef double w, dw
        for p in range(self.np_):
            w = 0.0
            dw = 0.0
            for i in range(m):
                w += self.R[p, i] * x[i]
                dw += self.R[p, i] * x[m + i]
            pos[2 * p] = self.ref[p, 0] + w * self.dirs[p, 0]
            pos[2 * p + 1] = self.ref[p, 1] + w * self.dirs[p, 1]
            vel[2 * p] = dw * self.dirs[p, 0]
            vel[2 * p + 1] = dw * self.dirs[p, 1]

    def outputs(self, double[::1] x):
        """Ports' positions and velocities, each ``(n_p, 2)``, at state ``x``
        (:meth:`side_outputs`: the host's ``outputs`` where it is stepped here,
        so that its Python step and the C face read the same bits)."""
        if x.shape[0] < 2 * self.m:
            raise ValueError(f"`x` must have {2 * self.m} entries, got {x.shape[0]}")
        pos = np.empty((self.np_, 2))
        vel = np.empty((self.np_, 2))
        cdef double[:, ::1] pv = pos
        cdef double[:, ::1] vv = vel
        if self.np_:
            self.side_outputs(&x[0], &pv[0, 0], &vv[0, 0])
        return pos, vel

    # ------------------------------------------------ stepping with no contact
    def step_free(self, double[::1] x, double[:, ::1] pm):
        """Advance ``x`` exactly over the loaded step with no hosted contact
        (:meth:`fem.ExactModal.step_modal` on undamped modes), and the
        ports' velocity moments ``pm`` by three-point Gauss-Legendre when a
        port is loaded (the reference's ``_gauss_moments``)."""
        if x.shape[0] != 2 * self.m or pm.shape[0] != 3 or pm.shape[1] != 2 * self.np_:
            raise ValueError(f"`x` must have {2 * self.m} entries and `pm` shape "
                             f"(3, {2 * self.np_})")
        self._free(&x[0], &pm[0, 0])


# ------------------------------------------------- the C face's functions
cdef int _face_step(void* side, double t, double h, const double* u, int rows, double* x,
                    double* aux, double* pm) except -1:
    return (<StructureStep> side).side_step(t, h, u, rows, x, aux, pm)


cdef void _face_outputs(void* side, const double* x, double* pos, double* vel) noexcept:
    (<StructureStep> side).side_outputs(x, pos, vel)


cdef int _face_loop(void* side, double t, double h, const double* u, int rows, double* x,
                    double* aux, double* pm, double* peak, signed char* closed) except -1:
    return (<StructureStep> side).side_loop(t, h, u, rows, x, aux, pm, peak, closed)


cdef int _face_motion(void* side, int slot, double t0, double h, const double* c,
                      int n) noexcept:
    return (<StructureStep> side).side_motion(slot, t0, h, c, n)

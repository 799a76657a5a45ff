# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True
# cython: initializedcheck=False, nonecheck=False
"""The monolithic reference's right-hand side, compiled.

:class:`StackedRHS` evaluates what the Python right-hand side of
:class:`cosim.core.schemes.monolithic.Monolithic` does, in the same order
and with the same formulas: every subsystem's port outputs, the following
contacts' surface points (:meth:`cosim.core.system.CoupledSystem.update_followers`),
the penetrations, the forces of the active contacts, each subsystem's
derivatives under its port forces, the contacts' dissipated power and work
and the subsystems' ledger rates.  It reaches the subsystems only through
their compiled model-exchange faces (a ``FaceTable`` of C functions,
declared in ``_stacked.pxd``), which the sides' kernel modules fill; the
core imports no side, and no side imports this module.  :meth:`StackedRHS.events` gives the switch value and the
penetration rate of every contact, the event functions' values.

The two agree to round-off, not bit for bit (a Cholesky solve against
LAPACK's LU, sums in another order): ``tests/test_monolithic_compiled.py``
bounds the difference.
"""
from cpython.pycapsule cimport PyCapsule_GetPointer, PyCapsule_New
from libc.math cimport pow
from libc.stdlib cimport free, malloc

import numpy as np

cdef enum:
    # law kinds, as cosim.core.links.kernel_law numbers them
    LINEAR = 0          # f = k d
    KELVIN_VOIGT = 1    # f = k d + c dd, switch min(d, d + c/k dd)
    POWER = 2           # f = k max(d, 0)^n (1 + chi dd), switch d or min(d, d (1 + chi dd))
    RIGID = 3           # no force; switch d, or min(d, dd * 1 s) moving away


#: the name of the capsule a face's ``table()`` returns
FACE_CAPSULE = "cosim.FaceTable"
cdef const char* FACE_CAPSULE_C = b"cosim.FaceTable"


cdef int _fixed_outputs(void* obj, const double* x, double* pos, double* vel) except -1:
    cdef FixedFace face = <FixedFace>obj
    cdef int i
    for i in range(2 * face.tab.n_ports):
        pos[i] = face.pos[i]
        vel[i] = 0.0
    return 0


cdef int _no_derivatives(void* obj, double t, const double* x, const double* u,
                         double* dx) except -1:
    return 0


cdef int _no_ledger(void* obj, double t, const double* x, double* rates) except -1:
    rates[0] = 0.0
    rates[1] = 0.0
    return 0


cdef int _no_follow(void* obj, int port, double px, double py, const double* x,
                    double* out) except -1:
    raise TypeError("this subsystem cannot move a port")


cdef class FixedFace:
    """The face of a rigid reference (wall, ground): fixed ports, no states.

    Parameters
    ----------
    positions : (n_ports, 2) array
        Port positions [m].
    """

    cdef double[::1] pos
    cdef FaceTable tab

    def __init__(self, positions):
        p = np.ascontiguousarray(positions, dtype=float).reshape(-1)
        self.pos = p.copy()
        self.tab.obj = <void*>self
        self.tab.n_states = 0
        self.tab.n_ports = p.size // 2
        self.tab.can_follow = 0
        self.tab.outputs = _fixed_outputs
        self.tab.derivatives = _no_derivatives
        self.tab.ledger_rates = _no_ledger
        self.tab.follow = _no_follow

    def table(self):
        """The ``FaceTable``, in a capsule named :data:`FACE_CAPSULE`."""
        return PyCapsule_New(&self.tab, FACE_CAPSULE_C, NULL)

    @property
    def can_follow(self):
        return False


cdef class StackedRHS:
    """The stacked right-hand side of the monolithic reference.

    Parameters
    ----------
    faces : list
        One per subsystem, in the system's order: objects whose ``table()``
        gives their :c:type:`FaceTable` (``Subsystem.compiled_face``).
    offsets : (n_sub + 1,) int array
        Each subsystem's slice of the stacked state.
    contacts : list of tuples
        Per contact: ``(sub_a, port_a, sub_b, port_b, normal_x, normal_y,
        offset [m], kind, k, c_or_chi, exponent, follow)`` with the law as
        :func:`cosim.core.links.kernel_law` gives it and ``follow``
        true for a contact whose surface point moves under the point.
    active : (n_contacts,) bool array
        Which contacts are on their active branch; read at each call (the
        scheme switches it between segments).
    """

    cdef list faces
    cdef FaceTable** tab
    cdef int ns, nc, n_x, n_out
    cdef long[::1] off, first, sub_a, port_a, sub_b, port_b, kind, fol
    cdef double[::1] nx, ny, c_off, c_k, c_c, c_n
    cdef const unsigned char[::1] active
    cdef double[::1] pos, vel, u, d, dd, f, axis, sigma, rates, tmp, last_y, ev
    cdef bint has_followers, has_last
    #: number of right-hand-side and event evaluations so far
    cdef public long n_rhs, n_events

    def __init__(self, faces, offsets, contacts, active):
        cdef int s, c, n_ports = 0
        self.faces = list(faces)
        self.ns = len(self.faces)
        self.nc = len(contacts)
        self.off = np.ascontiguousarray(offsets, dtype=np.int_)
        if self.off.shape[0] != self.ns + 1:
            raise ValueError(f"`offsets` must have {self.ns + 1} entries, "
                             f"got {self.off.shape[0]}")
        self.tab = <FaceTable**>malloc(max(self.ns, 1) * sizeof(FaceTable*))
        if self.tab == NULL:
            raise MemoryError()
        first = [0]
        for s in range(self.ns):
            n_ports = first[s]
            # the face objects stay referenced by self.faces: their tables live
            self.tab[s] = <FaceTable*>PyCapsule_GetPointer(self.faces[s].table(),
                                                           FACE_CAPSULE_C)
            if self.tab[s].n_states != self.off[s + 1] - self.off[s]:
                raise ValueError(f"faces[{s}] has {self.tab[s].n_states} states, its slice "
                                 f"{self.off[s + 1] - self.off[s]}")
            first.append(n_ports + self.tab[s].n_ports)
        self.first = np.array(first, dtype=np.int_)
        self.n_x = self.off[self.ns]
        self.n_out = self.n_x + 3 * self.nc + 2
        cols = list(zip(*contacts)) if contacts else [()] * 12
        self.sub_a, self.port_a, self.sub_b, self.port_b = (
            np.array(cols[i], dtype=np.int_).reshape(-1) for i in range(4))
        self.nx, self.ny, self.c_off = (np.array(cols[i], dtype=float).reshape(-1)
                                        for i in range(4, 7))
        self.kind = np.array(cols[7], dtype=np.int_).reshape(-1)
        self.c_k, self.c_c, self.c_n = (np.array(cols[i], dtype=float).reshape(-1)
                                        for i in range(8, 11))
        self.fol = np.array([bool(v) for v in cols[11]], dtype=np.int_).reshape(-1)
        for c in range(self.nc):
            for s, p in ((self.sub_a[c], self.port_a[c]), (self.sub_b[c], self.port_b[c])):
                if not (0 <= s < self.ns and 0 <= p < self.first[s + 1] - self.first[s]):
                    raise ValueError(f"contact {c}: no port {p} on subsystem {s}")
            if self.fol[c] and not self.tab[self.sub_b[c]].can_follow:
                raise ValueError(f"contact {c} follows its point, and subsystem "
                                 f"{self.sub_b[c]}'s face cannot move a port")
        self.has_followers = bool(np.any(self.fol))
        self.active = np.ascontiguousarray(active).view(np.uint8)
        if self.active.shape[0] != self.nc:
            raise ValueError(f"`active` must have {self.nc} entries, got {self.active.shape[0]}")
        n_ports = self.first[self.ns]
        m = max(self.nc, 1)
        self.pos, self.vel, self.u = (np.zeros(2 * max(n_ports, 1)) for _ in range(3))
        self.d, self.dd, self.f, self.sigma = (np.zeros(m) for _ in range(4))
        self.axis = np.zeros(2 * m)
        self.rates = np.zeros(2)
        self.tmp = np.zeros(8)
        self.last_y = np.zeros(max(self.n_x, 1))
        self.ev = np.zeros(2 * m)
        self.has_last = False
        self.n_rhs = self.n_events = 0

    def __dealloc__(self):
        free(self.tab)

    # ------------------------------------------------------------- contacts
    cdef int _state(self, const double* y) except -1:
        """Port outputs, moved surface points, penetrations and rates at ``y``."""
        cdef int s, c, a, b
        cdef FaceTable* face
        cdef double* tmp = &self.tmp[0]
        for s in range(self.ns):
            face = self.tab[s]
            face.outputs(face.obj, y + self.off[s], &self.pos[2 * self.first[s]],
                         &self.vel[2 * self.first[s]])
        if self.has_followers:      # as CoupledSystem.update_followers, then outputs again
            for c in range(self.nc):
                if not self.fol[c]:
                    continue
                a = 2 * (self.first[self.sub_a[c]] + self.port_a[c])
                face = self.tab[self.sub_b[c]]
                if face.follow(face.obj, self.port_b[c], self.pos[a], self.pos[a + 1],
                               y + self.off[self.sub_b[c]], tmp):
                    self.sigma[c] = self.nx[c] * tmp[2] + self.ny[c] * tmp[3]
                    self.axis[2 * c], self.axis[2 * c + 1] = tmp[0], tmp[1]
                else:                   # clipped to an end: s no longer moves with x_a
                    self.sigma[c] = 0.0
                    self.axis[2 * c], self.axis[2 * c + 1] = 0.0, 0.0
            for s in range(self.ns):
                face = self.tab[s]
                face.outputs(face.obj, y + self.off[s], &self.pos[2 * self.first[s]],
                             &self.vel[2 * self.first[s]])
        for c in range(self.nc):
            a = 2 * (self.first[self.sub_a[c]] + self.port_a[c])
            b = 2 * (self.first[self.sub_b[c]] + self.port_b[c])
            self.d[c] = self.c_off[c] - ((self.pos[a] - self.pos[b]) * self.nx[c]
                                         + (self.pos[a + 1] - self.pos[b + 1]) * self.ny[c])
            self.dd[c] = -((self.vel[a] - self.vel[b]) * self.nx[c]
                           + (self.vel[a + 1] - self.vel[b + 1]) * self.ny[c])
            if self.fol[c]:
                self.dd[c] += self.sigma[c] * (self.vel[a] * self.axis[2 * c]
                                               + self.vel[a + 1] * self.axis[2 * c + 1])
        return 0

    cdef inline double _switch(self, int c) noexcept nogil:
        """The law's ``switch(d, dd)`` (:mod:`couplers.laws`)."""
        cdef int kind = self.kind[c]
        cdef double d = self.d[c], dd = self.dd[c], a
        if kind == KELVIN_VOIGT:
            a = d + (self.c_c[c] / self.c_k[c]) * dd
            return d if d < a else a
        if kind == POWER and self.c_c[c] != 0.0:
            a = d * (1.0 + self.c_c[c] * dd)
            return d if d < a else a
        if kind == RIGID:
            return d if dd >= 0.0 or d < dd else dd
        return d

    cdef inline double _slope(self, int c) noexcept nogil:
        """``dV/dd`` of the law's elastic part."""
        cdef int kind = self.kind[c]
        cdef double dp = self.d[c] if self.d[c] > 0.0 else 0.0
        if kind == LINEAR or kind == KELVIN_VOIGT:
            return self.c_k[c] * dp
        if kind == POWER:
            return self.c_k[c] * pow(dp, self.c_n[c])
        return 0.0

    cdef inline double _force_active(self, int c) noexcept nogil:
        """``force_active(d, dd)``: the active branch, unclipped."""
        cdef int kind = self.kind[c]
        cdef double dp
        if kind == LINEAR:
            return self.c_k[c] * self.d[c]
        if kind == KELVIN_VOIGT:
            return self.c_k[c] * self.d[c] + self.c_c[c] * self.dd[c]
        if kind == POWER:
            dp = self.d[c] if self.d[c] > 0.0 else 0.0
            return self.c_k[c] * pow(dp, self.c_n[c]) * (1.0 + self.c_c[c] * self.dd[c])
        return 0.0

    # ---------------------------------------------------------- Python faces
    def rhs(self, double t, y):
        """``dy/dt`` of the stacked state ``y`` (subsystems' states, then per
        contact the impulse, the dissipated energy and the work, then the
        subsystems' ledger): a new array."""
        yin = np.ascontiguousarray(y, dtype=float)
        if yin.shape[0] != self.n_out:
            raise ValueError(f"`y` must have {self.n_out} entries, got {yin.shape[0]}")
        out = np.empty(self.n_out)
        cdef double[::1] yv = yin
        cdef double[::1] ov = out
        cdef int s, c, a, b, i, nc = self.nc, n_x = self.n_x
        cdef double fc, ca0, ca1
        cdef FaceTable* face
        self.n_rhs += 1
        self._state(&yv[0])
        for i in range(self.u.shape[0]):
            self.u[i] = 0.0
        for c in range(nc):
            if self.active[c]:
                fc = self._force_active(c)
                self.f[c] = fc if fc > 0.0 else 0.0
            else:
                self.f[c] = 0.0
            # the port-force maps of CoupledSystem: +n on a (n - sigma e where
            # it follows), -n on b
            a = 2 * (self.first[self.sub_a[c]] + self.port_a[c])
            b = 2 * (self.first[self.sub_b[c]] + self.port_b[c])
            ca0, ca1 = self.nx[c], self.ny[c]
            if self.fol[c]:
                ca0 = ca0 - self.sigma[c] * self.axis[2 * c]
                ca1 = ca1 - self.sigma[c] * self.axis[2 * c + 1]
            self.u[a] += ca0 * self.f[c]
            self.u[a + 1] += ca1 * self.f[c]
            self.u[b] += -self.nx[c] * self.f[c]
            self.u[b + 1] += -self.ny[c] * self.f[c]
        ov[n_x + 3 * nc] = 0.0
        ov[n_x + 3 * nc + 1] = 0.0
        for s in range(self.ns):
            face = self.tab[s]
            face.derivatives(face.obj, t, &yv[self.off[s]], &self.u[2 * self.first[s]],
                             &ov[self.off[s]])
            face.ledger_rates(face.obj, t, &yv[self.off[s]], &self.rates[0])
            ov[n_x + 3 * nc] += self.rates[0]
            ov[n_x + 3 * nc + 1] += self.rates[1]
        for c in range(nc):
            ov[n_x + c] = self.f[c]
            ov[n_x + nc + c] = (self.f[c] - self._slope(c)) * self.dd[c]
            ov[n_x + 2 * nc + c] = -self.f[c] * self.dd[c]
        return out

    def events(self, y):
        """Per contact its law's switch value [m], then its penetration rate
        [m/s], at the stacked state ``y``: (2 n_contacts,), the object's own
        array, overwritten by the next call at another state (a call at the
        state of the last one returns it unchanged, for the solver asks every
        event function in turn at the same state)."""
        yin = np.ascontiguousarray(y, dtype=float)
        if yin.shape[0] < self.n_x:
            raise ValueError(f"`y` must have at least {self.n_x} entries, got {yin.shape[0]}")
        cdef double[::1] yv = yin
        cdef int i, c, nc = self.nc
        cdef bint same = self.has_last
        if same:
            for i in range(self.n_x):
                if yv[i] != self.last_y[i]:
                    same = False
                    break
        if not same:
            self.n_events += 1
            self._state(&yv[0])
            for c in range(nc):
                self.ev[c] = self._switch(c)
                self.ev[nc + c] = self.dd[c]
            for i in range(self.n_x):
                self.last_y[i] = yv[i]
            self.has_last = True
        return np.asarray(self.ev)[:2 * nc]

# cython: boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
"""The following contacts (``follow = true``) of the compiled macro loop:
:meth:`cosim.core.system.CoupledSystem.update_followers` in C.

Before each try of a macro step, each following contact's surface port on
side ``b`` (a structure meshed along a line) moves to the material coordinate
``s = (x_a - o) . e`` below side ``a``'s point at the step's start, clipped to
the structure.  The structure's compiled face (``follow_face`` of the
``compiled_follow`` capability, :class:`cosim.sides._modal_face.ModalFace`
built on the subsystem's own arrays) evaluates the shape functions at ``s``,
projects them on the kept modes into the port's shape row and moves its
reference position, in place, where the structure's compiled step reads
them; and gives the deformed surface's tangent ``e + w'(s) r`` at the
structure's present state.  With ``sigma = n . (e + w' r)`` (0 where ``s`` was
clipped), the column of side ``a``'s exchanged-force map for the contact
becomes ``n - sigma e`` and the penetration rate gains ``sigma (e . v_a)``
(:meth:`rate`): the energy-consistent sliding of the Python loop, which stays
the reference.  Only where ``s`` changed does the side hear of it
(``port_moved``, one call: its kernel drops the modes it kept for the old
shape row).  ``cosim.core`` imports nothing of ``cosim.sides`` here: the
face is reached through the :c:type:`FaceTable` of ``cosim/core/_stacked.pxd``.
The compiled loop imports this module only for a run with a following
contact, and calls it through its :c:type:`FollowTable` (``_follow.pxd``).
"""
import numpy as np
from cpython.pycapsule cimport PyCapsule_GetPointer, PyCapsule_New
from libc.stdlib cimport calloc, free

from cosim.core._stacked cimport FaceTable

cdef const char* FACE_CAPSULE_C = b"cosim.FaceTable"
cdef const char* FOLLOW_CAPSULE_C = b"cosim.FollowTable"


cdef int _update(void* obj, const double* P0) except -1:
    return (<Followers>obj).update(P0)


cdef double _rate(void* obj, int c, double va0, double va1) noexcept nogil:
    return (<Followers>obj).rate(c, va0, va1)


cdef class Followers:
    """The following contacts of ``system``, for one run of the compiled loop.

    Parameters
    ----------
    system : CoupledSystem
    Gc : list of (2 n_ports, n_rows) arrays
        The compiled loop's own exchanged-force maps (written in place).
    """

    cdef int n, nc
    # per follower: contact, point a's side and port row, side b and its port
    cdef long[::1] c, sub_a, port_a, row_a, sub_b, port_b
    cdef double[::1] nx, ny, s_now
    # per contact (n_contacts): whether it follows, ``sigma`` and the axis
    # (zero where ``s`` is clipped), as CoupledSystem.update_followers keeps them
    cdef long[::1] follows
    cdef double[::1] slope
    cdef double[:, ::1] axis
    cdef FaceTable** tab
    cdef double** xb                # side b's state (its own array, never rebound)
    cdef double** gc                # side a's exchanged-force map (the loop's copy)
    cdef long[::1] gc_cols
    cdef list keep, moved
    cdef double[8] out
    cdef FollowTable ftab

    def __init__(self, system, list Gc):
        cdef int k, c
        cdef double[::1] xv
        cdef double[:, ::1] gv
        links = system.links
        idx = [c for c, ln in enumerate(links) if ln.follow]
        self.n = len(idx)
        self.nc = system.n_contacts
        first = np.cumsum([0] + [sub.n_ports for sub in system.subsystems])
        self.c = np.array(idx, dtype=np.int_)
        self.sub_a = np.array([links[c].sub_a for c in idx], dtype=np.int_)
        self.port_a = np.array([links[c].port_a for c in idx], dtype=np.int_)
        self.row_a = np.array([first[links[c].sub_a] + links[c].port_a for c in idx],
                              dtype=np.int_)
        self.sub_b = np.array([links[c].sub_b for c in idx], dtype=np.int_)
        self.port_b = np.array([links[c].port_b for c in idx], dtype=np.int_)
        self.nx = np.array([float(links[c].contact.normal[0]) for c in idx])
        self.ny = np.array([float(links[c].contact.normal[1]) for c in idx])
        self.follows = np.zeros(max(self.nc, 1), dtype=np.int_)
        self.slope = np.zeros(max(self.nc, 1))
        self.axis = np.zeros((max(self.nc, 1), 2))
        self.s_now = np.zeros(max(self.n, 1))
        self.gc_cols = np.array([G.shape[1] for G in Gc] or [0], dtype=np.int_)
        self.tab = <FaceTable**>calloc(max(self.n, 1), sizeof(FaceTable*))
        self.xb = <double**>calloc(max(self.n, 1), sizeof(double*))
        self.gc = <double**>calloc(max(self.n, 1), sizeof(double*))
        if self.tab == NULL or self.xb == NULL or self.gc == NULL:
            raise MemoryError()
        self.keep, self.moved = [], []
        for k in range(self.n):
            c = self.c[k]
            self.follows[c] = 1
            sub = system.subsystems[self.sub_b[k]]
            face = sub.follow_face()
            if face is None:
                raise ValueError(f"contact `{links[c].contact.name}`: side `{sub.name}` cannot "
                                 f"move its ports in compiled code")
            self.keep += [face, sub.x, Gc[self.sub_a[k]]]
            self.tab[k] = <FaceTable*>PyCapsule_GetPointer(face.table(), FACE_CAPSULE_C)
            xv = sub.x
            self.xb[k] = &xv[0]
            gv = Gc[self.sub_a[k]]
            self.gc[k] = &gv[0, 0]
            self.moved.append(sub.port_moved)
            self.s_now[k] = float(sub.port_coordinates[self.port_b[k]])
        self.ftab.obj = <void*>self
        self.ftab.update = _update
        self.ftab.rate = _rate

    def table(self):
        """The :c:type:`FollowTable` in a capsule named ``cosim.FollowTable``
        (valid while this object lives)."""
        return PyCapsule_New(&self.ftab, FOLLOW_CAPSULE_C, NULL)

    def __dealloc__(self):
        free(self.tab)
        free(self.xb)
        free(self.gc)

    cdef int update(self, const double* P0) except -1:
        """Move every following contact's surface port under its point's
        position at the step's start (``P0``, the ports' rows, (n_ports, 2)
        row-major) and turn side a's force on it (``update_followers``)."""
        cdef int k, c, a, r, ncol
        cdef bint along
        cdef double sigma, col0, col1
        cdef double* G
        cdef FaceTable* face
        for k in range(self.n):
            c = self.c[k]
            a = self.row_a[k]
            face = self.tab[k]
            along = face.follow(face.obj, self.port_b[k], P0[2 * a], P0[2 * a + 1], self.xb[k],
                                self.out)
            if self.out[4] != self.s_now[k]:
                self.s_now[k] = self.out[4]
                self.moved[k](self.port_b[k], self.out[4])
            if along:
                sigma = self.nx[k] * self.out[2] + self.ny[k] * self.out[3]
                self.axis[c, 0], self.axis[c, 1] = self.out[0], self.out[1]
            else:                       # clipped to an end: s no longer moves with x_a
                sigma = 0.0
                self.axis[c, 0], self.axis[c, 1] = 0.0, 0.0
            self.slope[c] = sigma
            # the column of side a's map for the contact's row (where it is exchanged)
            ncol = self.gc_cols[self.sub_a[k]]
            G = self.gc[k]
            r = 2 * self.port_a[k]
            if G[r * ncol + c] != 0.0 or G[(r + 1) * ncol + c] != 0.0:
                col0 = self.nx[k] - sigma * self.axis[c, 0]
                col1 = self.ny[k] - sigma * self.axis[c, 1]
                G[r * ncol + c] = col0
                G[(r + 1) * ncol + c] = col1
        return 0

    cdef double rate(self, int c, double va0, double va1) noexcept nogil:
        """What contact ``c``'s surface point moving with its point adds to the
        penetration rate: ``sigma (e . v_a)`` (0 for a contact that does not follow)."""
        if not self.follows[c]:
            return 0.0
        return self.slope[c] * (va0 * self.axis[c, 0] + va1 * self.axis[c, 1])

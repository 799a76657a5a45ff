# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True
# cython: initializedcheck=False, nonecheck=False
"""The model-exchange face of a structure in modal coordinates, compiled.

:class:`ModalFace` is :meth:`cosim.sides.fem.StructureSubsystem.derivatives`,
``outputs`` and ``ledger_rates`` (the kept modes' diagonal equations, the
ports' shape rows) as the monolithic reference's compiled right-hand side
calls them (through the ``FaceTable`` of ``cosim.core._stacked``), and, on a structure meshed
along a line (:class:`fem.linear_structure.LineStructure`), the move of a
port under a point with its surface slope
(:meth:`~cosim.sides.fem.StructureSubsystem.move_port` and
``surface_tangent``): the same shape functions, evaluated here.  The face
keeps its own copy of the port rows, so moving a port here leaves the
subsystem's (the Python reference's) as they are; built with ``shared``, it
moves the subsystem's own rows and reference positions in place (the
compiled macro loop's following contacts, whose structure kernel reads those
arrays at each step).
"""
import numpy as np

from cpython.pycapsule cimport PyCapsule_New

# a C struct only: nothing of the core is imported at run time
from cosim.core._stacked cimport FaceTable


cdef int _modal_outputs(void* obj, const double* x, double* pos, double* vel) except -1:
    return (<ModalFace>obj).outputs(x, pos, vel)


cdef int _modal_derivatives(void* obj, double t, const double* x, const double* u,
                            double* dx) except -1:
    return (<ModalFace>obj).derivatives(t, x, u, dx)


cdef int _modal_ledger(void* obj, double t, const double* x, double* rates) except -1:
    return (<ModalFace>obj).ledger_rates(t, x, rates)


cdef int _modal_follow(void* obj, int port, double px, double py, const double* x,
                       double* out) except -1:
    return (<ModalFace>obj).follow(port, px, py, x, out)


cdef class ModalFace:
    """Parameters
    ----------
    rows : (n_ports, m) array
        The ports' shape rows ``R`` (``w = R q``).
    reference : (n_ports, 2) array
        The ports' undeformed positions [m].
    direction : (2,) array
        The deflection direction.
    omega, damping, gravity : (m,) arrays
        Natural frequencies [rad/s], modal damping [1/s], modal gravity load.
    line : tuple or None
        ``(node_coordinates (N,), dof_map (N, k), hermite, shapes (n_dof, m),
        origin (2,), axis (2,), port_coordinates (n_ports,))`` of a line
        structure, whose ports may then follow a point; None: they may not.
    shared : bool
        Use ``rows`` and ``reference`` themselves (C-contiguous float
        arrays), not copies: :meth:`follow` then moves the caller's ports.
    """

    cdef int m, n_ports
    cdef bint follows
    cdef FaceTable tab
    cdef double[:, ::1] R, ref, Phi
    cdef double[::1] dirv, w2, damp, gmod, nodes, origin, axis, s_port, row
    cdef long[:, ::1] dof_map
    cdef bint hermite
    cdef double length

    def __init__(self, rows, reference, direction, omega, damping, gravity, line=None,
                 shared=False):
        if shared:                           # the caller's arrays, written in place
            self.R = rows
            self.ref = reference
        else:
            self.R = np.array(rows, dtype=float, order="C", ndmin=2)
            self.ref = np.array(reference, dtype=float, order="C").reshape(-1, 2)
        self.m = self.R.shape[1]
        self.dirv = np.array(direction, dtype=float)
        om = np.asarray(omega, dtype=float)
        self.w2 = om ** 2                    # as the reference squares it
        self.damp = np.array(damping, dtype=float)
        self.gmod = np.array(gravity, dtype=float)
        self.n_ports = self.R.shape[0]
        self.row = np.zeros(max(self.m, 1))
        self.follows = line is not None
        self.tab.obj = <void*>self
        self.tab.n_states = 2 * self.m
        self.tab.n_ports = self.n_ports
        self.tab.can_follow = self.follows
        self.tab.outputs = _modal_outputs
        self.tab.derivatives = _modal_derivatives
        self.tab.ledger_rates = _modal_ledger
        self.tab.follow = _modal_follow
        if line is not None:
            nodes, dof_map, hermite, shapes, origin, axis, s_port = line
            self.nodes = np.array(nodes, dtype=float)
            self.dof_map = np.array(dof_map, dtype=np.int_, order="C", ndmin=2)
            self.hermite = bool(hermite)
            self.Phi = np.array(shapes, dtype=float, order="C")
            self.origin = np.array(origin, dtype=float)
            self.axis = np.array(axis, dtype=float)
            self.s_port = np.array(s_port, dtype=float)
            self.length = self.nodes[self.nodes.shape[0] - 1] - self.nodes[0]

    def table(self):
        """The face's ``FaceTable`` in a capsule named ``cosim.FaceTable``."""
        return PyCapsule_New(&self.tab, b"cosim.FaceTable", NULL)

    @property
    def can_follow(self):
        return bool(self.follows)

    cdef int outputs(self, const double* x, double* pos, double* vel) except -1:
        cdef int p, j, m = self.m
        cdef double w, dw
        for p in range(self.n_ports):
            w = 0.0
            dw = 0.0
            for j in range(m):
                w += self.R[p, j] * x[j]
                dw += self.R[p, j] * x[m + j]
            pos[2 * p] = self.ref[p, 0] + w * self.dirv[0]
            pos[2 * p + 1] = self.ref[p, 1] + w * self.dirv[1]
            vel[2 * p] = dw * self.dirv[0]
            vel[2 * p + 1] = dw * self.dirv[1]
        return 0

    cdef int derivatives(self, double t, const double* x, const double* u,
                         double* dx) except -1:
        """``[dq, R^T (u . dir) + g - d dq - omega^2 q]``."""
        cdef int p, j, m = self.m
        cdef double g
        for j in range(m):
            g = 0.0
            for p in range(self.n_ports):
                g += (u[2 * p] * self.dirv[0] + u[2 * p + 1] * self.dirv[1]) * self.R[p, j]
            g += self.gmod[j]
            dx[j] = x[m + j]
            dx[m + j] = g - self.damp[j] * x[m + j] - self.w2[j] * x[j]
        return 0

    cdef int ledger_rates(self, double t, const double* x, double* rates) except -1:
        """Power dissipated by the modal damping [W]."""
        cdef int j, m = self.m
        cdef double s = 0.0
        for j in range(m):
            s += self.damp[j] * (x[m + j] * x[m + j])
        rates[0] = s
        rates[1] = 0.0
        return 0

    cdef void _shape_row(self, double s, bint slope) noexcept nogil:
        """``row`` = the shape row of ``w`` (or of ``dw/ds``) at ``s``
        (:meth:`fem.linear_structure.LineStructure.point_operator`,
        ``slope_operator``)."""
        cdef int nn = self.nodes.shape[0], e, i, j, k, kk = self.dof_map.shape[1], dof
        cdef double h, x, x2, x3
        cdef double sh[4]
        # e = clip(searchsorted(nodes, s, "right") - 1, 0, N - 2)
        e = 0
        while e < nn and self.nodes[e] <= s:
            e += 1
        e -= 1
        if e < 0:
            e = 0
        if e > nn - 2:
            e = nn - 2
        h = self.nodes[e + 1] - self.nodes[e]
        x = (s - self.nodes[e]) / h
        x = 0.0 if x < 0.0 else (1.0 if x > 1.0 else x)
        if self.hermite:
            x2 = x * x
            x3 = x * x * x
            if slope:
                sh[0], sh[1] = (6 * x * x - 6 * x) / h, 1 - 4 * x + 3 * x * x
                sh[2], sh[3] = (6 * x - 6 * x * x) / h, 3 * x * x - 2 * x
            else:
                sh[0], sh[1] = 1 - 3 * x2 + 2 * x3, h * (x - 2 * x2 + x3)
                sh[2], sh[3] = 3 * x2 - 2 * x3, h * (x3 - x2)
        elif slope:
            sh[0], sh[1] = -1.0 / h, 1.0 / h
        else:
            sh[0], sh[1] = 1.0 - x, x
        for j in range(self.m):
            self.row[j] = 0.0
        # the element's DOFs: (w, dw/ds) of its two nodes (Hermite), w (P1)
        for i in range(4 if self.hermite else 2):
            dof = (self.dof_map[e + i // 2, i % 2] if self.hermite
                   else self.dof_map[e + i, 0])
            if dof < 0:
                continue
            for j in range(self.m):
                self.row[j] += sh[i] * self.Phi[dof, j]

    cdef int follow(self, int port, double px, double py, const double* x,
                    double* out) except -1:
        """Move ``port`` to the material point under ``(px, py)`` (clipped to
        the ends); ``out[0:2]`` = the axis, ``out[2:4]`` = the deformed
        surface's tangent ``dx/ds`` there, ``out[4]`` = the coordinate ``s``
        it took [m].  Returns 0 where ``s`` was clipped
        (it no longer moves with the point), 1 elsewhere."""
        cdef int j, m = self.m
        cdef double s_raw, s, wp
        if not self.follows:
            raise TypeError("this structure's ports cannot follow a point")
        s_raw = (px - self.origin[0]) * self.axis[0] + (py - self.origin[1]) * self.axis[1]
        s = s_raw
        s = 0.0 if s < 0.0 else s
        s = self.length if s > self.length else s
        if s != self.s_port[port]:
            self._shape_row(s, False)
            for j in range(m):
                self.R[port, j] = self.row[j]
            self.ref[port, 0] = self.origin[0] + s * self.axis[0]
            self.ref[port, 1] = self.origin[1] + s * self.axis[1]
            self.s_port[port] = s
        self._shape_row(s, True)
        wp = 0.0
        for j in range(m):
            wp += self.row[j] * x[j]
        out[0], out[1] = self.axis[0], self.axis[1]
        out[2] = self.axis[0] + wp * self.dirv[0]
        out[3] = self.axis[1] + wp * self.dirv[1]
        out[4] = s
        return 1 if s == s_raw else 0

# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True
# cython: initializedcheck=False, nonecheck=False
"""The model-exchange face of a planar tree, for the monolithic reference's
compiled right-hand side (:mod:`cosim.core._stacked`): the tree's
derivatives, port outputs and ledger rates on the compiled kernel's model
(:class:`cosim.sides._multibody_tree.TreeDynamics`), which
:meth:`cosim.sides._multibody_step.MultibodyStep.face` hands out."""
from cpython.pycapsule cimport PyCapsule_New

import numpy as np

# a C struct only: nothing of the core is imported at run time
from cosim.core._stacked cimport FaceTable
from cosim.sides._multibody_tree cimport TreeDynamics


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

    cdef TreeDynamics k
    cdef double[::1] rates
    cdef FaceTable tab

    def __init__(self, TreeDynamics kernel):
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
        cdef TreeDynamics k = self.k
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
        cdef TreeDynamics k = self.k
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
            raise FloatingPointError(f"the mass matrix is not positive definite at t = {t:.6g} s")
        return 0

    cdef int ledger_rates(self, double t, const double* x, double* rates) except -1:
        """Power dissipated by the joint dampers and supplied by the drives [W]."""
        cdef TreeDynamics k = self.k
        if k.nd or k.has_springs or k.has_dampers:
            k._effects(t, x, x + k.n, rates)
        else:
            rates[0] = 0.0
            rates[1] = 0.0
        return 0


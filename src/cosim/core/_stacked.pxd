# cython: language_level=3
"""The compiled model-exchange face of a subsystem, as the monolithic
reference's compiled right-hand side (:mod:`cosim.core._stacked`) calls it.

A side that has compiled kernels subclasses :class:`Face` in its own kernel
module (the sides import the core, never the other way round) and hands an
instance out through ``Subsystem.compiled_face()``.  Planar vectors are
interleaved ``(n_ports, 2)`` rows: ``x0, y0, x1, y1, ...``.
"""


cdef class Face:
    #: length of the subsystem's state and number of its ports
    cdef public int n_states, n_ports
    #: whether :meth:`follow` moves a port (a structure with a material axis)
    cdef public bint can_follow

    cdef int outputs(self, const double* x, double* pos, double* vel) except -1
    cdef int derivatives(self, double t, const double* x, const double* u,
                         double* dx) except -1
    cdef int ledger_rates(self, double t, const double* x, double* rates) except -1
    cdef int follow(self, int port, double px, double py, const double* x,
                    double* out) except -1

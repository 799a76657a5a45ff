# cython: language_level=3
"""The C face of a side's compiled step (see ``_side_kernel.pyx``)."""


cdef class CompiledSide:
    #: sizes of the side's state ``x``, its quadratures ``aux`` and its ports
    cdef public int cs_nx, cs_naux, cs_nports

    cdef int side_step(self, double t, double h, const double* u, int rows, double* x,
                       double* aux, double* pm) except -1
    cdef void side_outputs(self, const double* x, double* pos, double* vel) noexcept

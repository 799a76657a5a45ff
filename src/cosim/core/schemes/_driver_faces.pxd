# cython: language_level=3
"""Declarations of :mod:`cosim.core.schemes._driver_faces`: the sides as the
compiled macro loop holds them (their C faces, live arrays, saved states and
switch logs), which :class:`cosim.core.schemes._driver.Driver` and
:func:`cosim.core.schemes._driver_block.fill` call in C."""
from cosim.core._side_face cimport SideFace, SwitchLog


cdef class Sides:
    cdef list subs, kernels, capsules, arrays
    cdef int nsub
    cdef double[::1] max_step, free_step
    cdef SideFace** face
    cdef long* gen
    cdef SwitchLog* plog
    cdef SwitchLog** log
    # per side: the live arrays (NULL where empty) and their saved copies
    cdef double** px
    cdef double** paux
    cdef double** ppeak
    cdef signed char** pcl
    cdef double** sx
    cdef double** saux
    cdef double** speak
    cdef signed char** scl
    cdef long* nx
    cdef long* naux
    cdef long* npk
    cdef long* ncl
    cdef double[::1] t, saved_t
    cdef long[::1] n_steps, saved_n, rigid
    #: steps the sides took through their C faces, and through their Python steps
    cdef public long n_face_steps, n_python_steps

    cdef bint ready(self, int s) noexcept
    cdef int loop(self, int s, double t, double h, const double* u, int rows,
                  double* pm) except -1
    cdef void outputs(self, int s, double* pos, double* vel) noexcept
    cdef int motion(self, int s, int slot, double t0, double h, const double* c,
                    int n) noexcept
    cdef void save(self) noexcept
    cdef void restore(self) noexcept
    cdef int took_python_step(self, int s) except -1
    cdef int to_python(self) except -1

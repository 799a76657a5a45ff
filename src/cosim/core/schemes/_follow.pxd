# cython: language_level=3
"""Declarations of :mod:`cosim.core.schemes._follow` (the compiled macro
loop's following contacts), cimported by :mod:`cosim.core.schemes._driver`."""
from cosim.core._stacked cimport FaceTable


cdef class Followers:
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
    cdef double** gc                # side a's exchanged-force map (driver's copy)
    cdef long[::1] gc_cols
    cdef list keep, moved
    cdef double[8] out
    cdef int update(self, double[:, ::1] P0) except -1
    cdef double rate(self, int c, double va0, double va1) noexcept nogil

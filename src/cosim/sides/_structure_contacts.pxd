# cython: language_level=3
"""Declarations of :mod:`cosim.sides._structure_contacts`: the hosted
springs' phases of the structure's compiled step, which
:class:`cosim.sides._structure_step.StructureStep` extends with its Python face."""
from cosim.core._side_face cimport SwitchLog
from cosim.sides._structure_modes cimport ModalResponse


cdef class ContactPhases(ModalResponse):
    cdef inline void _partner(self, int k, double time, double* xr, double* xi, double* vr,
                              double* vi) noexcept nogil
    cdef inline void _gap(self, int k, double time, double w, double dw, double* d,
                          double* dd) noexcept nogil
    cdef void _segment_load(self, double tc) noexcept nogil
    cdef bint _stays_open(self, double tc, double L, const double* P) noexcept nogil
    cdef void _quadratures(self, double[::1] aux, double[:, ::1] pm, double tc, double L,
                           const double* P, bint any_active) noexcept nogil
    cdef double _switch_time(self, int k, bint was_closed, double lo, double hi, double d_lo,
                             double d_hi, double tol, double tc,
                             const double* P) noexcept nogil
    cdef double _rate_root_value(self, int k, double tc, double lo, double hi, double v_lo,
                                 double v_hi, const double* P) noexcept nogil
    cdef void _peak_interval(self, int k, double tc, double lo, double hi, double v_lo,
                             double d_hi, double v_hi, const double* P) noexcept nogil
    cdef void _raise_peaks(self, double[::1] peak) noexcept nogil
    cdef int _advance(self, double[::1] x, double[::1] aux, double[:, ::1] pm,
                      signed char[::1] closed, double[::1] peak, SwitchLog* log,
                      double* at) except -1

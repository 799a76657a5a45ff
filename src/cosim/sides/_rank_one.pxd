# cython: language_level=3
"""Declarations of :mod:`cosim.sides._rank_one`: the rank-one update of the
modes, which the structure's compiled step calls in C."""


cdef int _rank_one(int m, const double* d, const double* z, double* lam, double* out,
                   int max_iterations, double* work) noexcept nogil

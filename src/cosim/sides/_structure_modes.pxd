# cython: language_level=3
"""Declarations of :mod:`cosim.sides._structure_modes`: the structure's
state and its modal response in closed form (the kept modes of each set of
closed springs, a segment's exact response, its moments, the exact step of a
structure that hosts no contact), which
:class:`cosim.sides._structure_contacts.ContactPhases` extends with the
contact phases and :class:`cosim.sides._structure_step.StructureStep` with
the Python face."""
from libc.math cimport pow


cdef enum:
    # rows of a load polynomial (degree <= 3) and of a partner's motion
    DEG1 = 4
    # sets of closed springs whose modes are kept
    MAX_BASES = 8
    # terms of the power series of the trigonometric moments
    SERIES_TERMS = 12
    # most contacts one structure hosts in the kernel
    MAX_CONTACTS = 62



cdef inline double _comb(int n, int k) noexcept nogil:
    cdef double c = 1.0
    cdef int i
    for i in range(k):
        c = c * (n - i) / (i + 1)
    return c


cdef inline void _reparam(const double* c, int n, double a, double b,
                          double* out) noexcept nogil:
    """:func:`cosim.core.subsystem.reparametrised` of one polynomial (``n`` coefficients)."""
    cdef int i, k
    for k in range(n):
        out[k] = 0.0
    for i in range(n):
        for k in range(i + 1):
            out[k] += _comb(i, k) * pow(a, i - k) * pow(b, k) * c[i]


cdef class ModalResponse:
    cdef int m, np_, nc
    cdef double[:, ::1] R, ref
    cdef double[:, ::1] dirs                # each port's direction, shared
    cdef double[::1] lam0, g_modal
    cdef double wmax0
    cdef long[::1] c_port
    cdef double[::1] c_side, c_nre, c_nim, c_off, c_k
    cdef object host_basis
    # the step
    cdef double t, h
    cdef int g_len
    cdef bint loaded
    cdef double[:, ::1] Gin                 # (DEG1, m) in s = (time - t) / h
    cdef long[::1] m_len, dm_len
    cdef double[::1] m_t0, m_h
    cdef double[:, ::1] m_re, m_im, dm_re, dm_im     # (nc, DEG1 + 1)
    # kept bases
    cdef int n_bases, next_base
    cdef long long[::1] b_mask
    cdef long[::1] b_ident
    cdef double[::1] b_wmax
    cdef double[:, ::1] b_lam               # (MAX_BASES, m)
    cdef double[:, :, ::1] b_psi            # (MAX_BASES, m, m)
    cdef double[:, :, ::1] b_P              # (MAX_BASES, m, n_p): Psi^T R^T
    # the segment: its modes' start, load, and the split of the response
    cdef double[::1] q, dq, z0, dz0, zt, dzt
    cdef double[:, ::1] a, aS               # (DEG1, m)
    cdef long[::1] rigid
    cdef double[::1] om, b0, b1, b2, b3, A, B
    cdef double[:, ::1] C, S                # trig moments (DEG1, m)
    cdef double[:, ::1] Wm                  # (DEG1, n_p)
    cdef double[::1] W, DW, W0, WL, d0, dd0, dprev, ddprev, dcur, ddcur, seg_peak
    # the rank-one update of one closed spring: workspace, z, lam, V
    cdef double[::1] r1_work, r1_z, r1_lam, r1_V
    cdef long[::1] active
    #: segments stepped so far (closed-form phases)
    cdef public long n_segments
    #: bases asked of the host (several springs closed, or the rank-one
    #: update declined)
    cdef public long n_host_bases
    #: segments with every contact open that a bound proved stay open, so
    #: stepped without probes (see :meth:`_stays_open`)
    cdef public long n_unprobed
    #: whether :meth:`_stays_open` may spare a segment its probes (the
    #: host's ``bound_open``; False probes every segment)
    cdef public bint bound_open

    cdef void _split(self, const double* lam) noexcept nogil
    cdef inline void _mode(self, int i, double tau, double* z, double* dz) noexcept nogil
    cdef void _ports(self, double tau, const double* P, double* W, double* DW) noexcept nogil
    cdef double _port(self, double tau, const double* P, int p, double* dw) noexcept nogil
    cdef void _modes_at(self, double tau) noexcept nogil
    cdef void _trig_moments(self, double L) noexcept nogil
    cdef void _moments(self, double L, const double* P) noexcept nogil
    cdef int _basis(self, long long mask)
    cdef int _rank_one_basis(self, long long mask, int s) noexcept nogil
    cdef void _to_segment(self, int s) noexcept nogil
    cdef void _end_state(self, int s, double tau) noexcept nogil
    cdef void _free(self, double* x, double* pm) noexcept nogil

# cython: language_level=3
"""Declarations of :mod:`cosim.sides._multibody_tree`: the planar tree's model
as the compiled multibody step evaluates it (its state, workspace and
model functions), which :class:`cosim.sides._multibody_step.MultibodyStep`
extends with the integrator."""


cdef enum:
    # law kinds (couplers.laws)
    LINEAR = 0          # f = k d
    KELVIN_VOIGT = 1    # f = max(k d + c dd, 0), switch min(d, d + c/k dd)
    POWER = 2           # f = k d^n (1 + chi dd), switch d or min(d, d (1 + chi dd))
    RIGID = 3           # no force; switch d, or min(d, dd * 1 s) moving away
    # joint drives (multibody.effects) and the references a PD drive tracks
    DRIVE_CONSTANT = 0
    DRIVE_TABLE = 1
    DRIVE_PD = 2
    REF_TABLE = 0
    REF_MINIMUM_JERK = 1
    REF_SINUSOID = 2
    # largest number of polynomial coefficients of a partner's motion or an input
    MAX_COEF = 8
    # most contacts one subsystem hosts in the kernel
    MAX_CONTACTS = 64
    # RK4 steps between two looks at the signals (a power of two, less one): a
    # step under a tiny `max_step` may take millions of them, and Ctrl-C or
    # SIGTERM must stop it within a fraction of a second, not at its end
    SIGNAL_POLL = 4095


cdef class TreeDynamics:
    cdef int n, np_, nc, nm, ny, nq
    cdef long[::1] parent, port_body, c_port, c_kind
    cdef double[::1] rev, pris, off_re, off_im, ax_re, ax_im, angle0, mass, inertia
    cdef double[::1] com_re, com_im, pl_re, pl_im
    cdef double[:, ::1] anc, rot_mass
    cdef bint has_g
    cdef double g_re, g_im
    cdef double[::1] c_side, c_nre, c_nim, c_off, c_k, c_c, c_n
    # the step: its start and length, the input polynomial, the partners' motion
    cdef double t0, h, u_t0, u_h
    cdef int u_len
    cdef double[:, :, ::1] u_coef          # (MAX_COEF, n_p, 2)
    cdef long[::1] m_len, m_still
    cdef double[::1] m_t0, m_h
    cdef double[:, ::1] m_re, m_im, dm_re, dm_im   # (n_c, MAX_COEF)
    # workspace
    cdef double[::1] qs, th, rot_re, rot_im, org_re, org_im, axw_re, axw_im, om, vel_re, vel_im
    cdef double[::1] pom, px_re, px_im, pv_re, pv_im, pa_re, pa_im
    cdef double[:, ::1] J_re, J_im, M, L
    cdef double[::1] F, b, u_re, u_im, sw_tmp
    cdef double[:, ::1] stage          # rows: k1, k2, k3, k4, tmp, y1, k1n, yi, ya, ka
    cdef double[:, ::1] sws            # rows: s0, s1, s, snew
    cdef double[:, ::1] pen            # rows: d, dd at the last rhs; d, dd at the last sub-step end
    # joint effects
    cdef bint has_springs, has_dampers
    cdef int nd
    cdef double[::1] e_k, e_rest, e_c, tau
    cdef long[::1] d_joint, d_kind, d_ref, d_off, d_len
    cdef double[:, ::1] d_pd                   # (n_d, 3): kp, kd, max torque (or the torque)
    cdef double[:, ::1] d_par                  # (n_d, 4): the reference's parameters
    cdef double[::1] d_tab                     # tables: times then values, per drive
    #: number of right-hand-side evaluations so far
    cdef public long n_rhs

    cdef void _frames(self, const double* q, const double* dq) noexcept nogil
    cdef void _point(self, int k, int body, double lr, double li, const double* dq,
                     bint full) noexcept nogil
    cdef void _mass_and_forces(self) noexcept nogil
    cdef int _solve(self, double* x) noexcept nogil
    cdef void _partner(self, int k, double t, double* xr, double* xi, double* vr,
                       double* vi) noexcept nogil
    cdef void _penetration(self, int k, double t, double* d, double* dd) noexcept nogil
    cdef double _law_switch(self, int k, double d, double dd) noexcept nogil
    cdef void _law(self, int k, double d, double dd, double* f, double* p, double* sw) noexcept nogil
    cdef void _inputs(self, double t) noexcept nogil
    cdef int _rhs(self, double t, const double* y, double* out, double* sw) noexcept nogil
    cdef double _reference(self, int k, double t, bint rate) noexcept nogil
    cdef void _effects(self, double t, const double* q, const double* dq,
                       double* rates) noexcept nogil
    cdef void _switch(self, double t, const double* y, double* sw) noexcept nogil
    cdef double _energy(self, const double* y) noexcept nogil

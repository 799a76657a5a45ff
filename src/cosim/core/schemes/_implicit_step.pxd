# cython: language_level=3
"""The declarations of :mod:`cosim.core.schemes._implicit_step`'s classes,
for a compiled macro loop (:mod:`cosim.core.schemes._implicit_block`) to
call the iterations of a step with no Python call (:meth:`ImplicitStep.c_advance`)."""
from cosim.core._side_face cimport SideFace


cdef class Acceleration:
    cdef int kind, n, reuse, max_cols
    cdef double relax, filt, omega
    cdef bint have_prev
    cdef double[::1] r_prev, hx_prev
    # this step's columns in the order they came; the kept steps' blocks,
    # newest first, each newest column first (the reference's ``_old``)
    cdef double[:, ::1] cur_v, cur_w
    cdef int n_cur
    cdef double[:, :, ::1] old_v, old_w
    cdef long[::1] old_n
    cdef int n_old
    # the columns in use, newest first: block (-1 this step's) and index
    cdef long[::1] col_blk, col_idx
    cdef double[::1] qr_a, qr_beta, qr_b, qr_alpha


    cdef void c_start(self, bint keep_old) noexcept
    cdef void c_finish(self) noexcept
    cdef void c_update(self, double* z, const double* hz, const double* r) noexcept
    cdef double* _col(self, int j, bint w) noexcept
    cdef void _iqn(self, double* z, const double* hz, const double* r) noexcept


cdef class ImplicitStep:
    cdef int ns, n_rows, nq, ncc, max_it, maxp
    cdef list kernels, xs, auxs
    cdef SideFace* faces
    cdef long[::1] s_nx, s_na, s_np, s_first
    cdef double[:, ::1] saved_x, saved_aux
    cdef double[:, :, ::1] G
    cdef double[:, ::1] u, pm
    cdef double[::1] pos, vel
    cdef long[::1] k_c, k_a, k_b, k_trow, k_kind, k_grasp
    cdef double[::1] k_nx, k_ny, k_off, k_k, k_cd, g_k, g_c, g_kt, g_ct
    cdef long long[::1] mode
    cdef double[::1] anchor
    cdef long[::1] rows
    cdef double ftol, tol, roundoff
    cdef double[::1] f, coef1, z, hz, r
    cdef Acceleration acc
    # IQNILS.start's key of the last step: its length, the closed coupler rows
    cdef bint have_key
    cdef double key_h
    cdef long[::1] key_closed
    #: the side whose step raised (its index among ``sides``), -1 if none
    cdef public int failed_side

    #: whether the last step's iterations converged
    cdef public bint converged

    cdef int c_advance(self, double t, double h, double[::1] f_n, double[:, :] cv,
                       double[::1] guess) except -1
    cdef int _pass(self, double t, double h, double[::1] f_n, double[::1] guess) except -1
    cdef void _forces(self) noexcept
    cdef bint _residual(self, double[::1] guess) noexcept

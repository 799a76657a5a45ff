# cython: language_level=3
"""Declarations of :mod:`cosim.core.schemes._driver`, the compiled macro loop,
which :func:`cosim.core.schemes._driver_block.fill` steps in C."""
from cosim.core.schemes._driver_faces cimport Sides
from cosim.core.schemes._follow cimport FollowTable


cdef class Driver:
    cdef object system, subs, laws, hosted_embs, step_input, scheme
    cdef int nsub, nports, nc, nr, order, width_gs, n_order, n_hosted, n_coupler, n_exch
    cdef bint gs, controlled, land
    cdef double H, contact_step, horizon
    # layout
    cdef long[::1] kind, port0, nport, seq, rigid
    cdef long[::1] row_a, row_b, sub_a, sub_b, coupler, exchanged
    # the system's own arrays, read-only (a following contact may turn its normal)
    cdef const double[:, ::1] normal
    cdef const double[::1] offset
    cdef long[::1] h_c, h_host, h_slot, h_partner, h_pport
    cdef list Gc
    # each side's exchange map (2 n_ports, n_rows), C-contiguous, as a pointer
    cdef double** gp
    # each side's rows, flat (rows_idx[rows_off[s]:rows_off[s + 1]])
    cdef long[::1] rows_idx, rows_off
    # the following contacts (cosim.core.schemes._follow), None where there are none
    cdef object fol
    cdef FollowTable* ft
    cdef double[::1] max_step, free_step
    # state (StepState's fields)
    cdef double[:, ::1] P, V, P0, V0, Pp, Vp
    cdef bint has_prev, has_dd_prev, aimed
    cdef double h_prev_step, h_next, h_prev
    cdef double[:, ::1] hist
    cdef int nhist
    cdef public object f, d, dd
    cdef double[::1] fv, dv, ddv, dd_prev, d1, dd1, f1
    cdef public object stepped, work
    cdef double[::1] stv, wv
    # the books (StepBooks): per contact, impulse [N s], dissipated [J] and
    # work [J] so far, the work as recorded (with the embedded contacts'),
    # the subsystems' internal ledger, and the coupler rows' dissipation rates
    cdef public object impulse, diss, work_total, work_rec
    cdef double[::1] impv, dissv, wtv, p_prev, wrv
    cdef public double internal_dissipated, internal_supplied
    cdef public bint finite
    cdef long[::1] e_c, e_host, e_slot, law_kind
    cdef double[::1] law_k, law_c
    cdef int n_emb
    cdef bint coupler_diss
    # scratch
    cdef double[:, ::1] base, coeffs
    cdef double[::1] ubuf, pmbuf, gotv
    # the hosted contacts' partner motions (complex interleaved), set each step
    cdef double[:, ::1] mot
    cdef long[::1] mot_n, force_py
    cdef double[::1] mot_t0, mot_h
    #: the sides as the loop steps them (their C faces)
    cdef public Sides sides
    #: True: each step's rows are new arrays (the recorder keeps what it is
    #: given step by step); False: written in place (taken in blocks)
    cdef public bint fresh
    cdef double[::1] imp0
    cdef long[::1] done
    #: counters: accepted steps and rejected tries taken by the driver
    cdef public long n_steps, n_rejected

    cdef double _propose(self, double remaining)
    cdef object _judge(self, double t, double h)
    cdef object _landing(self, double t, double h)
    cdef bint _hosted_touch(self, int k, double* first) noexcept
    cdef object _onset(self, double t, double h)
    cdef void _outputs(self, int s) except *
    cdef int _step_side(self, int s, double t, double h, int width) except -1
    cdef int _python_step(self, int s, double t, double h, int width) except -1
    cdef object _step_structure(self, int s, kern, double t, double h, inp)
    cdef void _partner_motion(self, int k, double t, double h, bint after) noexcept
    cdef void _penetration(self, int c, double* d, double* dd)
    cdef double _force(self, int c, double d, double dd)
    cdef int _extrapolated(self, double ratio)
    cdef void _advance_jacobi(self, double t, double h, double ratio) except *
    cdef void _advance_gs(self, double t, double h, double ratio) except *
    cdef void _penetration_pred(self, int c, int s, double h, double* d, double* dd)
    cdef double step_c(self, double t, double remaining, double h_fixed) except? -1.0
    cdef void _book(self, double h) except *

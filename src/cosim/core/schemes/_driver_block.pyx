# cython: boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
"""The compiled macro loop's samples in blocks: :func:`fill` takes accepted
steps of a :class:`cosim.core.schemes._driver.Driver` one after the other and
writes each step's sample (what :meth:`StepBooks.book_driven
<cosim.core.schemes.step_control.StepBooks.book_driven>` hands the recorder:
time, rows, forces, impulse, dissipated energy, the subsystems' ledger, work,
their stacked states and the embedded contacts' peaks)
into preallocated rows, without returning to Python.

The switches its sides located in a step are listed with the step's row
(the recorder reports them before that sample, as step by step).  It
returns when the rows are full, at the run's end, at the first step whose
rows are not finite, or when a step raised (a signal's KeyboardInterrupt included): the rows written
before are whole samples, and :mod:`cosim.core.schemes.driven_block` records
them before anything else happens.
"""
from libc.string cimport memcpy

from cosim.core._side_face cimport SwitchLog
from cosim.core.schemes._driver cimport Driver
from cosim.core.schemes._driver_faces cimport Sides

#: why a block ended
cdef enum:
    FULL = 0
    END = 1
    NONFINITE = 2
    RAISED = 3

REASONS = ("full", "end", "nonfinite", "raised")


cdef void _put(double[:, ::1] out, int i, double[::1] v):
    cdef Py_ssize_t n = v.shape[0]
    if n:
        memcpy(&out[i, 0], &v[0], n * sizeof(double))


def fill(Driver drv, list subs, list edges, long[::1] e_c, long[::1] e_host, long[::1] e_slot,
         double t, double t_end, long k, long n, double H, double sliver, bint controlled,
         double[::1] T, double[:, ::1] D, double[:, ::1] DD, double[:, ::1] F,
         double[:, ::1] IMP, double[:, ::1] DISS, double[:, ::1] INT, double[:, ::1] W,
         double[:, ::1] X, double[:, ::1] PK, long[::1] REJ):
    """Fill rows from 0 with accepted steps of ``drv`` from time ``t`` and
    step count ``k`` (``n`` steps of ``H`` when not ``controlled``).

    ``subs`` are the subsystems (their ``x`` stacked in that order), ``e_c``,
    ``e_host``, ``e_slot`` the embedded contacts with their host and slot;
    the switches the sides located in a step are appended to ``edges`` as
    ``(row, contact, time, on)``, to be reported before that row's sample.

    Returns ``(rows, t, k, reason, error)``: rows written, the time and
    count after them, why the block ended (:data:`REASONS`) and the
    exception a step raised (reason ``raised``).
    """
    cdef int m = T.shape[0], i = 0, j, s, nsub = len(subs), nc = e_c.shape[0]
    cdef int reason = FULL
    cdef double h
    cdef double* pk
    cdef Py_ssize_t off
    cdef Sides sides = drv.sides
    cdef SwitchLog* log
    error = None
    while i < m:
        if controlled:
            if t_end - t <= sliver:
                reason = END
                break
        else:
            if k >= n:
                reason = END
                break
            t = k * H
            h = t_end - t
            if H < h:
                h = H
            if h <= sliver:
                reason = END
                break
        try:
            if controlled:
                h = drv.step_c(t, t_end - t, 0.0)
            else:
                drv.step_c(t, h, h)
            k += 1
            T[i] = t + h
            REJ[i] = drv.n_rejected
            if controlled:
                t = t + h
            if not drv.finite:
                reason = NONFINITE
                i += 1
                break
            _put(D, i, drv.dv)
            _put(DD, i, drv.ddv)
            _put(F, i, drv.fv)
            _put(IMP, i, drv.impv)
            _put(DISS, i, drv.dissv)
            _put(W, i, drv.wrv)
            INT[i, 0] = drv.internal_dissipated
            INT[i, 1] = drv.internal_supplied
            off = 0
            for s in range(nsub):
                if sides.nx[s]:
                    memcpy(&X[i, off], sides.px[s], sides.nx[s] * sizeof(double))
                off += sides.nx[s]
            # the embedded contacts' peaks since the last sample, taken as
            # take_peaks takes them (read, then the hosts start again from 0)
            for j in range(nc):
                pk = sides.ppeak[e_host[j]]
                PK[i, e_c[j]] = pk[e_slot[j]]
            for j in range(nc):
                pk = sides.ppeak[e_host[j]]
                pk[e_slot[j]] = 0.0
            for j in range(nc):
                log = sides.log[e_host[j]]
                for s in range(log.n):
                    if log.slot[s] == e_slot[j]:
                        edges.append((i, e_c[j], log.time[s], log.on[s] != 0))
        except BaseException as exc:
            # a signal's KeyboardInterrupt too: the row is not written (a
            # step taken counts, as step by step, where its sample is refused)
            error = exc
            reason = RAISED
            break
        i += 1
    return i, t, k, REASONS[reason], error


def crossings(const double[::1] t0, const double[::1] t1, const double[::1] d0,
              const double[::1] v0, const double[::1] d1, const double[::1] v1,
              const unsigned char[::1] was, double[::1] out):
    """The times where the cubic Hermite of each row (``t0 .. t1``, ends
    ``d0, v0`` and ``d1, v1``) crosses zero, into ``out``: the recorder's
    bisection of a crossing (:mod:`cosim.core.recorder_block`) for a law
    that switches on the penetration itself, its formulas in its order
    (60 halvings; ``was``: the contact was active before).  The build turns
    off contraction into fused multiply-adds, so each operation rounds as
    Python's and numpy's do."""
    cdef Py_ssize_t i, n = t0.shape[0]
    cdef int it
    cdef double h, dx, c1, c2, c3, lo, hi, mid, p
    cdef bint w
    for i in range(n):
        h = t1[i] - t0[i]
        dx = d1[i] - d0[i]
        c1 = h * v0[i]
        c2 = 3 * dx - h * (2 * v0[i] + v1[i])
        c3 = -2 * dx + h * (v0[i] + v1[i])
        w = was[i] != 0
        lo = 0.0
        hi = 1.0
        for it in range(60):
            mid = 0.5 * (lo + hi)
            p = d0[i] + mid * (c1 + mid * (c2 + mid * c3))
            if (p > 0) == w:
                lo = mid
            else:
                hi = mid
        out[i] = t0[i] + 0.5 * (lo + hi) * h

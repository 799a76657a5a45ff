# cython: language_level=3
"""The cubic Hermite of a sub-step, shared by the compiled integrators that
locate switches and peaks inside their sub-steps (the multibody step, the
structure's RK4): :func:`cosim.core.hermite.hermite_value` of one component
and :func:`cosim.core.ode.substep_peaks`, the same arithmetic.  Inline
definitions only: cimporting them loads no module."""
from libc.math cimport sqrt


cdef inline double _hermite(double y0, double f0, double y1, double f1, double h,
                            double theta) noexcept nogil:
    cdef double t2 = theta * theta
    cdef double t3 = t2 * theta
    return ((2 * t3 - 3 * t2 + 1) * y0 + (t3 - 2 * t2 + theta) * h * f0
            + (-2 * t3 + 3 * t2) * y1 + (t3 - t2) * h * f1)


cdef inline void _substep_peaks(double* peak, const double* d0, const double* v0,
                                const double* d1, const double* v1, double h,
                                int n) noexcept nogil:
    """Raise each ``peak[j]`` to the largest value of the cubic Hermite
    through ``d0[j]``, ``d1[j]`` with rates ``v0[j]``, ``v1[j]`` over one
    accepted sub-step of ``h`` (:func:`cosim.core.ode.substep_peaks`, the
    same arithmetic)."""
    cdef int j
    cdef double p, dd, c1, c2, c3, qa, qb, disc, r, q, s, x
    for j in range(n):
        p = d1[j]
        if v0[j] > 0.0 and 0.0 > v1[j]:
            dd = d1[j] - d0[j]
            c1 = h * v0[j]
            c2 = 3.0 * dd - h * (2.0 * v0[j] + v1[j])
            c3 = -2.0 * dd + h * (v0[j] + v1[j])
            qa = 3.0 * c3
            qb = 2.0 * c2
            disc = qb * qb - 4.0 * qa * c1
            r = sqrt(disc) if disc > 0.0 else 0.0
            q = -0.5 * (qb + (r if qb >= 0.0 else -r))
            s = c1 / q if q != 0.0 else 1.0
            if not (0.0 < s < 1.0) and qa != 0.0:
                s = q / qa
            if 0.0 < s < 1.0:
                x = d0[j] + s * (c1 + s * (c2 + s * c3))
                if x > p:
                    p = x
        if p > peak[j]:
            peak[j] = p

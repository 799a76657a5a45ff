# cython: language_level=3
"""The C face of a side's compiled step, which a scheme's compiled loop calls.

A side whose step is compiled (:mod:`cosim.sides._multibody_step`,
:mod:`cosim.sides._structure_step`) derives its kernel from
:class:`CompiledSide` and implements its two C methods; a scheme that
iterates in compiled code (:mod:`cosim.core.schemes._implicit_step`) then
steps the side and reads its ports with no Python call.  Core declares the
face and the sides implement it, so core never imports a side.
"""


cdef class CompiledSide:
    """Base of a compiled side kernel.

    ``side_step(t, h, u, rows, x, aux, pm)`` advances the side's state ``x``
    (``cs_nx``) and quadratures ``aux`` (``cs_naux``) in place from ``t`` to
    ``t + h`` [s] under the port forces ``u``, a polynomial in
    ``s = (time - t) / h`` of ``rows`` coefficients, ``(rows, cs_nports, 2)``
    row-major [N], and writes the ports' velocity moments ``int v s^j dt``
    (``(3, cs_nports, 2)``, ``j = 0, 1, 2``) into ``pm``: what the side's
    Python step does with a :class:`cosim.core.subsystem.StepInput`.
    ``side_outputs(x, pos, vel)`` writes the ports' positions and velocities
    ``(cs_nports, 2)`` at state ``x``: what the side's ``outputs`` gives.
    A side implements them only for the steps that call no Python (no
    contact embedded in it); it says which through its subsystem's
    ``compiled_side``.
    """

    cdef int side_step(self, double t, double h, const double* u, int rows, double* x,
                       double* aux, double* pm) except -1:
        raise NotImplementedError(f"{type(self).__name__} has no compiled step")

    cdef void side_outputs(self, const double* x, double* pos, double* vel) noexcept:
        pass

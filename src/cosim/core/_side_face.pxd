# cython: language_level=3
"""The C face of a side's compiled step, which a scheme's compiled loop calls.

A side whose step is compiled (:mod:`cosim.sides._multibody_step`,
:mod:`cosim.sides._structure_step`) hands out, through its kernel's
``side_face()``, a capsule named ``cosim.side_face`` that holds a
:c:type:`SideFace`: the kernel and two C functions.  A scheme that iterates in
compiled code (:mod:`cosim.core.schemes._implicit_step`) then steps the side
and reads its ports with no Python call.  Core declares the face and the
sides fill it in, so core imports no side; these are declarations only, so
cimporting them loads no module.

``step(side, t, h, u, rows, x, aux, pm)`` advances the side's state ``x``
(``nx``) and quadratures ``aux`` (``naux``) in place from ``t`` to ``t + h``
[s] under the port forces ``u``, a polynomial in ``s = (time - t) / h`` of
``rows`` coefficients, ``(rows, nports, 2)`` row-major [N], and writes the
ports' velocity moments ``int v s^j dt`` (``(3, nports, 2)``, ``j = 0, 1,
2``) into ``pm``: what the side's Python step does with a
:class:`cosim.core.subsystem.StepInput`.  ``outputs(side, x, pos, vel)``
writes the ports' positions and velocities ``(nports, 2)`` at state ``x``:
what the side's ``outputs`` gives.  The capsule lives no longer than the
kernel that made it; the caller keeps the kernel.
"""

#: the name of the capsule that holds a SideFace
cdef extern from *:
    """
    #define COSIM_SIDE_FACE "cosim.side_face"
    """
    const char* COSIM_SIDE_FACE

ctypedef int (*side_step_fn)(void* side, double t, double h, const double* u, int rows,
                             double* x, double* aux, double* pm) except -1
ctypedef void (*side_outputs_fn)(void* side, const double* x, double* pos,
                                 double* vel) noexcept

ctypedef struct SideFace:
    void* side
    side_step_fn step
    side_outputs_fn outputs
    int nx, naux, nports

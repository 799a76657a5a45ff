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

The explicit schemes' compiled loop (:mod:`cosim.core.schemes._driver`)
steps a side that hosts contacts through ``loop(side, t, h, u, rows, x,
aux, pm, peak, closed)``: the side's whole step as its Python step takes it
(the embedded contacts' quadratures in ``aux``, their peaks raised in
``peak``, a structure's closed ends in ``closed``, NULL for a tree), each
switch it locates appended to ``log`` (emptied at the step's start).  It
returns 0, or 1 where it declines the step (beyond the kernel, or stalled),
having changed none of ``x``, ``aux``, ``peak``, ``closed``: the side's own
Python step then takes it.  ``motion(side, slot, t0, h, c, n)`` sets hosted
contact ``slot``'s partner motion as ``EmbeddedContact.set_motion`` does
(``c``: ``n`` complex coefficients, interleaved; returns 1 where it is
beyond the kernel).  ``generation`` changes when the side stops stepping
through this kernel (it dropped or renewed it): the loop then asks the side
again.
"""

from libc.stdlib cimport realloc, free

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
ctypedef int (*side_loop_fn)(void* side, double t, double h, const double* u, int rows,
                             double* x, double* aux, double* pm, double* peak,
                             signed char* closed) except -1
ctypedef int (*side_motion_fn)(void* side, int slot, double t0, double h, const double* c,
                               int n) noexcept

ctypedef struct SwitchLog:
    int n, cap
    double* time
    int* slot
    signed char* on


ctypedef struct SideFace:
    void* side
    side_step_fn step
    side_outputs_fn outputs
    int nx, naux, nports
    # the explicit compiled loop's step (cosim.core.schemes._driver_faces)
    side_loop_fn loop
    side_motion_fn motion
    long generation
    SwitchLog log



cdef inline int log_switch(SwitchLog* log, double t, int slot, bint on) except -1 nogil:
    """Append a located switch to ``log`` (grown as needed)."""
    cdef int cap
    cdef void* p
    if log.n == log.cap:
        cap = 16 if log.cap < 16 else 2 * log.cap
        p = realloc(log.time, cap * sizeof(double))
        if p == NULL:
            with gil:
                raise MemoryError()
        log.time = <double*> p
        p = realloc(log.slot, cap * sizeof(int))
        if p == NULL:
            with gil:
                raise MemoryError()
        log.slot = <int*> p
        p = realloc(log.on, cap * sizeof(signed char))
        if p == NULL:
            with gil:
                raise MemoryError()
        log.on = <signed char*> p
        log.cap = cap
    log.time[log.n] = t
    log.slot[log.n] = slot
    log.on[log.n] = 1 if on else 0
    log.n += 1
    return 0


cdef inline void free_log(SwitchLog* log) noexcept nogil:
    free(log.time)
    free(log.slot)
    free(log.on)
    log.time, log.slot, log.on = NULL, NULL, NULL
    log.n, log.cap = 0, 0

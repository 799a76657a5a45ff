# cython: language_level=3
"""The compiled model-exchange face of a subsystem, as the monolithic
reference's compiled right-hand side (:mod:`cosim.core._stacked`) calls it.

A side's kernel module fills a :c:type:`FaceTable` (C functions and the
object they act on) and hands it out in a capsule named
``FACE_CAPSULE`` from its face object's ``table()``.  Only this
declaration is shared: the sides import nothing of the core at run time
for it, and the core nothing of the sides.  Planar vectors are interleaved
``(n_ports, 2)`` rows: ``x0, y0, x1, y1, ...``.
"""

cdef struct FaceTable:
    void* obj               # the face object (the Python object that owns the table)
    int n_states            # length of the subsystem's state
    int n_ports
    int can_follow          # whether ``follow`` moves a port (a structure along a line)
    # port positions and velocities [m], [m/s] at state ``x``
    int (*outputs)(void* obj, const double* x, double* pos, double* vel) except -1
    # ``dx/dt`` at ``(t, x)`` under port forces ``u`` [N]
    int (*derivatives)(void* obj, double t, const double* x, const double* u,
                       double* dx) except -1
    # power dissipated inside the subsystem and supplied to it [W]
    int (*ledger_rates)(void* obj, double t, const double* x, double* rates) except -1
    # move ``port`` under the world point ``(px, py)``: ``out[0:2]`` the axis,
    # ``out[2:4]`` the surface tangent, ``out[4]`` the material coordinate it took
    # (``out`` holds at least 5); 0 where the point is past an end
    int (*follow)(void* obj, int port, double px, double py, const double* x,
                  double* out) except -1

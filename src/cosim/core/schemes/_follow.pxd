# cython: language_level=3
"""The C face of :mod:`cosim.core.schemes._follow` (the compiled macro loop's
following contacts), which :mod:`cosim.core.schemes._driver` calls.

``Followers.table()`` hands out, in a capsule named ``cosim.FollowTable``, a
:c:type:`FollowTable`: the object and its two functions.  Declarations only:
cimporting them loads no module, so a run without a following contact never
imports ``_follow``.
"""

ctypedef struct FollowTable:
    void* obj
    # move every following contact's surface port under its point's position
    # at the step's start (``P0``: the ports' rows, (n_ports, 2) row-major) and
    # turn side a's force (CoupledSystem.update_followers)
    int (*update)(void* obj, const double* P0) except -1
    # what contact ``c``'s moving surface point adds to its penetration rate,
    # ``sigma (e . v_a)`` (0 for a contact that does not follow)
    double (*rate)(void* obj, int c, double va0, double va1) noexcept nogil

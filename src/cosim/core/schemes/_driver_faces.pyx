# cython: boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
"""The sides as the compiled macro loop (:mod:`cosim.core.schemes._driver`)
holds them: each side's C face (:mod:`cosim.core._side_face`), through which
a macro step of the side calls no Python, its live arrays (``x``, ``aux``,
``peak``, ``closed_end``) as pointers, their saved copies for a rejected try,
its time and step count, and the switches its last step located.

A side is stepped through its face where its kernel offers one
(``side_face()`` with a ``loop``) and the side hands that kernel out
(:meth:`~cosim.core.loop_face.LoopFace.loop_kernel`: its Python step and
outputs are those the kernel mirrors).  A face whose ``generation``
changed (the side dropped or renewed its kernel), a step the face declines
(beyond the kernel, or stalled) and a side with no face take the side's
Python step (the loop's reference path), after which the side is asked
again for its face.  The sides' ``t``, ``n_steps`` and ``switch_log`` are
kept here and handed back (:meth:`Sides.to_python`) before any Python step
and whenever the loop returns to Python.
"""
from cpython.pycapsule cimport PyCapsule_GetPointer
from libc.stdlib cimport calloc, free
from libc.string cimport memcpy

import numpy as np

from cosim.core._side_face cimport COSIM_SIDE_FACE, SideFace, SwitchLog, free_log, log_switch
from cosim.core.loop_face import LoopFace
from cosim.core.subsystem import StepInput


cdef void* _ptr(object arr, object keep):
    """The data of a contiguous array of at least one entry (kept alive in
    ``keep``), or NULL."""
    if arr is None or arr.size == 0:
        return NULL
    keep.append(arr)
    return <void*> <size_t> arr.ctypes.data


cdef class Sides:
    """The sides ``subs`` of one run of the compiled loop (see the module);
    ``max_step``, ``free_step``: each multibody side's RK4 sub-steps [s]."""

    def __cinit__(self, list subs, *args):
        cdef int n = max(len(subs), 1)
        self.face = <SideFace**> calloc(n, sizeof(SideFace*))
        self.gen = <long*> calloc(n, sizeof(long))
        self.plog = <SwitchLog*> calloc(n, sizeof(SwitchLog))
        self.log = <SwitchLog**> calloc(n, sizeof(SwitchLog*))
        self.px = <double**> calloc(n, sizeof(double*))
        self.paux = <double**> calloc(n, sizeof(double*))
        self.ppeak = <double**> calloc(n, sizeof(double*))
        self.pcl = <signed char**> calloc(n, sizeof(signed char*))
        self.sx = <double**> calloc(n, sizeof(double*))
        self.saux = <double**> calloc(n, sizeof(double*))
        self.speak = <double**> calloc(n, sizeof(double*))
        self.scl = <signed char**> calloc(n, sizeof(signed char*))
        self.nx = <long*> calloc(n, sizeof(long))
        self.naux = <long*> calloc(n, sizeof(long))
        self.npk = <long*> calloc(n, sizeof(long))
        self.ncl = <long*> calloc(n, sizeof(long))
        if (self.face == NULL or self.gen == NULL or self.plog == NULL or self.log == NULL
                or self.px == NULL or self.paux == NULL or self.ppeak == NULL
                or self.pcl == NULL or self.sx == NULL or self.saux == NULL
                or self.speak == NULL or self.scl == NULL or self.nx == NULL
                or self.naux == NULL or self.npk == NULL or self.ncl == NULL):
            raise MemoryError()

    def __dealloc__(self):
        cdef int s
        if self.plog != NULL:
            for s in range(self.nsub):
                free_log(&self.plog[s])
        free(self.face); free(self.gen); free(self.plog); free(self.log)
        free(self.px); free(self.paux); free(self.ppeak); free(self.pcl)
        free(self.sx); free(self.saux); free(self.speak); free(self.scl)
        free(self.nx); free(self.naux); free(self.npk); free(self.ncl)

    def __init__(self, list subs, max_step, free_step):
        cdef int s
        self.subs = subs
        self.nsub = len(subs)
        self.max_step = np.array(max_step, dtype=float)
        self.free_step = np.array(free_step, dtype=float)
        self.kernels = [None] * self.nsub
        self.capsules = [None] * self.nsub
        self.arrays = [None] * self.nsub
        self.t = np.zeros(self.nsub)
        self.saved_t = np.zeros(self.nsub)
        self.n_steps = np.zeros(self.nsub, dtype=np.int_)
        self.saved_n = np.zeros(self.nsub, dtype=np.int_)
        self.rigid = np.zeros(self.nsub, dtype=np.int_)
        self.n_face_steps = self.n_python_steps = 0
        for s, sub in enumerate(subs):
            self.log[s] = &self.plog[s]
            self.rigid[s] = bool(sub.rigid)
            self.t[s] = sub.t
            self.n_steps[s] = sub.n_steps
            if not self.rigid[s]:
                self._arrays(s)
                self._capture(s)

    def _arrays(self, int s):
        """Side ``s``'s live arrays, and room for their saved copies."""
        sub = self.subs[s]
        keep = []
        cl = sub.closed_end
        live = (sub.x, sub.aux, getattr(sub, "peak", None), cl)
        for a in live:
            if a is not None and not (isinstance(a, np.ndarray) and a.flags.c_contiguous
                                      and a.dtype == (np.int8 if a is cl else np.float64)):
                raise TypeError(f"side `{sub.name}`: its state arrays must be contiguous")
        self.px[s] = <double*> _ptr(sub.x, keep)
        self.paux[s] = <double*> _ptr(sub.aux, keep)
        self.ppeak[s] = <double*> _ptr(live[2], keep)
        self.pcl[s] = <signed char*> _ptr(cl, keep)
        self.nx[s], self.naux[s] = sub.x.size, sub.aux.size
        self.npk[s] = 0 if live[2] is None else live[2].size
        self.ncl[s] = 0 if cl is None else cl.size
        self.sx[s] = <double*> _ptr(np.empty(max(sub.x.size, 1)), keep)
        self.saux[s] = <double*> _ptr(np.empty(max(sub.aux.size, 1)), keep)
        self.speak[s] = <double*> _ptr(np.empty(max(self.npk[s], 1)), keep)
        self.scl[s] = <signed char*> _ptr(np.empty(max(self.ncl[s], 1), np.int8), keep)
        self.arrays[s] = (live, keep)

    def _capture(self, int s):
        """Side ``s``'s C face where it offers one (see the module), with its
        contacts' partner motions loaded; else none."""
        cdef SideFace* f
        cdef double[::1] c
        sub = self.subs[s]
        self.face[s] = NULL
        self.kernels[s] = self.capsules[s] = None
        if not isinstance(sub, LoopFace):
            return
        kern = sub.loop_kernel(StepInput.zero(sub.t, 1.0, sub.n_ports))
        if kern is None or not hasattr(kern, "side_face") or not hasattr(kern, "retire"):
            return
        cap = kern.side_face()
        f = <SideFace*> PyCapsule_GetPointer(cap, COSIM_SIDE_FACE)
        if f.loop == NULL or f.motion == NULL or f.nx != self.nx[s]:
            return
        if hasattr(kern, "configure_side"):
            kern.configure_side(self.max_step[s], self.free_step[s])
        for slot, e in enumerate(sub.embedded_contacts):
            c = np.ascontiguousarray(e.motion, dtype=complex).view(float)
            if f.motion(f.side, slot, e.t0, e.h, &c[0], c.shape[0] // 2):
                return
        self.face[s] = f
        self.gen[s] = f.generation
        self.kernels[s] = kern
        self.capsules[s] = cap

    # ------------------------------------------------------------ stepping
    cdef bint ready(self, int s) noexcept:
        """Whether side ``s`` steps through its face."""
        return self.face[s] != NULL and self.face[s].generation == self.gen[s]

    cdef int loop(self, int s, double t, double h, const double* u, int rows,
                  double* pm) except -1:
        """Step side ``s`` through its face; 1 where the face declines."""
        cdef SideFace* f = self.face[s]
        if f.loop(f.side, t, h, u, rows, self.px[s], self.paux[s], pm, self.ppeak[s],
                  self.pcl[s]):
            return 1
        self.log[s] = &f.log
        self.t[s] = t + h
        self.n_steps[s] += 1
        self.n_face_steps += 1
        return 0

    cdef void outputs(self, int s, double* pos, double* vel) noexcept:
        self.face[s].outputs(self.face[s].side, self.px[s], pos, vel)

    cdef int motion(self, int s, int slot, double t0, double h, const double* c,
                    int n) noexcept:
        """Hosted contact ``slot`` of side ``s``: its partner's motion; 1
        where the face cannot take it (the side's Python step must)."""
        return self.face[s].motion(self.face[s].side, slot, t0, h, c, n)

    cdef void save(self) noexcept:
        cdef int s
        for s in range(self.nsub):
            if self.rigid[s]:
                continue
            if self.nx[s]:
                memcpy(self.sx[s], self.px[s], self.nx[s] * sizeof(double))
            if self.naux[s]:
                memcpy(self.saux[s], self.paux[s], self.naux[s] * sizeof(double))
            if self.npk[s]:
                memcpy(self.speak[s], self.ppeak[s], self.npk[s] * sizeof(double))
            if self.ncl[s]:
                memcpy(self.scl[s], self.pcl[s], self.ncl[s])
            self.saved_t[s] = self.t[s]
            self.saved_n[s] = self.n_steps[s]

    cdef void restore(self) noexcept:
        cdef int s
        for s in range(self.nsub):
            if self.rigid[s]:
                continue
            if self.nx[s]:
                memcpy(self.px[s], self.sx[s], self.nx[s] * sizeof(double))
            if self.naux[s]:
                memcpy(self.paux[s], self.saux[s], self.naux[s] * sizeof(double))
            if self.npk[s]:
                memcpy(self.ppeak[s], self.speak[s], self.npk[s] * sizeof(double))
            if self.ncl[s]:
                memcpy(self.pcl[s], self.scl[s], self.ncl[s])
            self.t[s] = self.saved_t[s]
            self.n_steps[s] = self.saved_n[s]

    # ------------------------------------------------------- back to Python
    cdef int to_python(self) except -1:
        """Hand the sides their time, step count and last switches."""
        cdef int s, i
        cdef SwitchLog* lg
        for s in range(self.nsub):
            if self.rigid[s]:
                continue
            sub = self.subs[s]
            sub.t = self.t[s]
            sub.n_steps = self.n_steps[s]
            lg = self.log[s]
            if lg != &self.plog[s]:
                sub.switch_log = [(lg.time[i], lg.slot[i], lg.on[i] != 0) for i in range(lg.n)]
        return 0

    cdef int took_python_step(self, int s) except -1:
        """Side ``s`` took its Python step: read back its time, step count
        and switches; its arrays and face again where it changed them."""
        sub = self.subs[s]
        self.t[s] = sub.t
        self.n_steps[s] = sub.n_steps
        self.plog[s].n = 0
        for ts, j, on in sub.switch_log:
            log_switch(&self.plog[s], ts, j, on)
        self.log[s] = &self.plog[s]
        self.n_python_steps += 1
        live = self.arrays[s][0]
        if (sub.x is not live[0] or sub.aux is not live[1]
                or getattr(sub, "peak", None) is not live[2]
                or sub.closed_end is not live[3]):
            self._arrays(s)
            self._capture(s)
        elif self.face[s] != NULL and self.face[s].generation != self.gen[s]:
            self._capture(s)
        return 0

    def sync(self):
        """:meth:`to_python`, from Python."""
        self.to_python()

    def switches(self, int s):
        """Side ``s``'s last step's switches ``[(time, slot, on), ...]``."""
        cdef SwitchLog* lg = self.log[s]
        return [(lg.time[i], lg.slot[i], lg.on[i] != 0) for i in range(lg.n)]

    def face_kernel(self, int s):
        """The kernel whose face steps side ``s``, or None."""
        return self.kernels[s] if self.ready(s) else None

# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True
# cython: initializedcheck=False, nonecheck=False
"""The implicit scheme's macro loop, compiled, its samples in blocks.

:meth:`ImplicitBlocks.fill` takes macro steps one after the other as
:meth:`cosim.core.schemes.base.CoSimulationScheme.run`'s Python loop takes
them for a system whose iterations are compiled
(:class:`cosim.core.schemes._implicit_step.ImplicitStep`): the forces
extrapolated from their history, one call of the compiled iterations, the
ports read through the sides' C faces, the rows and forces in the
connections' current modes, and the books of :meth:`StepBooks.book
<cosim.core.schemes.step_control.StepBooks.book>` (impulse, trapezoidal
dissipation, the exchanged forces' work, the sides' internal ledger) with
each step's sample written into preallocated rows.
:mod:`cosim.core.schemes.implicit_block` hands the rows to the recorder.

A block ends when its rows are full, at the run's end, at the first step
whose rows are not finite (its row not written), when a step raised (a
signal's KeyboardInterrupt included; its row not written), or at a step
after which a connection may switch mode (a touch that closes a grasp, a
``time`` or ``after`` trigger come): its row is not written either, the
Python half records the rows before (the recorder takes a block in one
mode), lets :meth:`CoupledSystem.switch_modes
<cosim.core.system.CoupledSystem.switch_modes>` decide, and the next
:meth:`fill` books that step first (:meth:`resume`).

The same arithmetic in the same order as the Python loop, except the
port-force work (``mom @ G`` by BLAS there, a loop here), so the two agree
to round-off (``tests/test_implicit_block.py``).
"""
from cpython.pycapsule cimport PyCapsule_GetPointer, PyCapsule_IsValid
from libc.math cimport isfinite
from libc.stdlib cimport free, malloc
from libc.string cimport memcpy

from cosim.core._side_face cimport COSIM_SIDE_FACE, SideFace
from cosim.core.schemes._implicit_step cimport ImplicitStep

import numpy as np

from cosim.core.schemes._implicit_step import grasp_columns

cdef enum:
    # why a block ended
    FULL = 0
    END = 1
    NONFINITE = 2
    RAISED = 3
    SWITCH = 4
    # laws (couplers.linear_laws) and the grasped mode (couplers.modes.GRASPED)
    LINEAR = 0
    KELVIN_VOIGT = 1
    OPEN = 0
    GRASPED = 1

REASONS = ("full", "end", "nonfinite", "raised", "switch")
#: the law kinds this loop evaluates, by the law's ``name``
LAW_KINDS = {"linear": LINEAR, "kelvin_voigt": KELVIN_VOIGT}


cdef class ImplicitBlocks:
    """The implicit scheme's macro loop over one run
    (built by :func:`cosim.core.schemes.implicit_block.run_blocks`).

    Parameters
    ----------
    scheme : Implicit
        Its ``_kernel`` iterates each step; ``extrapolation_order``.
    system : CoupledSystem
    sides : list of tuples
        Per side the kernel steps, in its order: ``(subsystem, kernel, G,
        first)``, the side's compiled kernel (its ``side_face()``), its
        port-force map ``(2 n_p, n_rows)`` and its first port's index.
    pos, vel : (n_ports, 2) arrays
        Every subsystem's ports now (the rigid ones stay there).
    contacts : list of tuples
        Per contact (every one is exchanged): ``(port_a, port_b, normal,
        offset, kind, k, c, tangent_row, grasp, closes_on_touch)``, ``grasp``
        None or ``(k, c, k_t, c_t)``.
    hist : list of (n_rows,) arrays
        The force history, oldest first (at most three).
    p_prev : (n_contacts,) array
        The dissipation rates at the start.
    h_prev : float
        The length the first step's ratio is taken against [s].
    """

    cdef object scheme, system, subs, ksubs, not_converged, coupler_rows
    cdef ImplicitStep kernel
    cdef list kernels, xs, moments
    cdef SideFace* faces
    cdef int ns, nsub, nc, nr, order, nhist, pending
    cdef long[::1] s_first, s_np, c_a, c_b, c_kind, c_trow, c_grasp, c_touch
    cdef double[::1] c_nx, c_ny, c_off, c_k, c_cd, g_k, g_c, g_kt, g_ct
    cdef list G
    cdef double[::1] pos, vel, d, dd, f, fn, guess, impulse, diss, work, w, p_prev, stepped
    cdef double[:, ::1] hist, co0, co1, co2, mom
    cdef list co
    cdef long long[::1] mode
    cdef double[::1] anchor
    cdef double t_pend, h_pend
    cdef long it_pend
    #: the length of the last step [s]; the earliest time a ``time`` or
    #: ``after`` trigger may fire (inf: none known) [s]
    cdef public double h_prev, next_trigger
    #: iterations taken so far (the scheme's ``n_iterations`` adds them)
    cdef public long n_iterations

    def __init__(self, scheme, system, sides, pos, vel, contacts, hist, p_prev, double h_prev):
        cdef int s, c
        self.scheme, self.system = scheme, system
        self.kernel = scheme._kernel
        self.not_converged = scheme._not_converged
        self.coupler_rows = system.coupler_rows
        self.subs = list(system.subsystems)
        self.nsub = len(self.subs)
        self.ns = len(sides)
        self.ksubs = [sd[0] for sd in sides]
        self.kernels = [sd[1] for sd in sides]       # kept: their faces point into them
        self.faces = <SideFace*> malloc(max(self.ns, 1) * sizeof(SideFace))
        if self.faces == NULL:
            raise MemoryError()
        for s in range(self.ns):
            cap = self.kernels[s].side_face()
            if not PyCapsule_IsValid(cap, COSIM_SIDE_FACE):
                raise TypeError(f"{type(self.kernels[s]).__name__}.side_face() is not a "
                                f"capsule of the C face")
            self.faces[s] = (<SideFace*> PyCapsule_GetPointer(cap, COSIM_SIDE_FACE))[0]
        self.xs = [sd[0].x for sd in sides]
        self.G = [np.array(sd[2], dtype=float, order="C") for sd in sides]
        self.s_first = np.array([sd[3] for sd in sides], dtype=np.int_)
        self.s_np = np.array([self.faces[s].nports for s in range(self.ns)], dtype=np.int_)
        self.pos = np.ascontiguousarray(pos, dtype=float).ravel().copy()
        self.vel = np.ascontiguousarray(vel, dtype=float).ravel().copy()
        self.nc = system.n_contacts
        self.nr = system.n_rows
        if len(contacts) != self.nc:
            raise ValueError(f"one entry per contact: {self.nc}, got {len(contacts)}")
        self.c_a = np.array([k[0] for k in contacts], dtype=np.int_)
        self.c_b = np.array([k[1] for k in contacts], dtype=np.int_)
        self.c_nx = np.array([float(k[2][0]) for k in contacts])
        self.c_ny = np.array([float(k[2][1]) for k in contacts])
        self.c_off = np.array([float(k[3]) for k in contacts])
        self.c_kind = np.array([k[4] for k in contacts], dtype=np.int_)
        self.c_k = np.array([float(k[5]) for k in contacts])
        self.c_cd = np.array([float(k[6]) for k in contacts])
        self.c_trow = np.array([k[7] for k in contacts], dtype=np.int_)
        self.c_grasp = np.array([k[8] is not None for k in contacts], dtype=np.int_)
        self.g_k, self.g_c, self.g_kt, self.g_ct = grasp_columns(contacts, 8)
        self.c_touch = np.array([bool(k[9]) for k in contacts], dtype=np.int_)
        cs = system.connections
        self.mode = cs.mode if cs is not None else np.zeros(max(self.nc, 1), dtype=np.longlong)
        self.anchor = cs.anchor if cs is not None else np.zeros(max(self.nc, 1))
        n = max(self.nr, 1)
        self.d, self.dd, self.f = np.zeros(n), np.zeros(n), np.zeros(n)
        self.fn, self.w, self.stepped = np.zeros(n), np.zeros(n), np.zeros(n)
        self.guess = np.zeros(n)
        # each side's port moments of its last step (what took_compiled_step
        # keeps): complex (3, n_p) views of one buffer, read as floats here
        maxp = max([1] + [int(k) for k in self.s_np])
        buf = np.zeros((max(self.ns, 1), 3 * maxp), dtype=complex)
        self.moments = [buf[s, :3 * self.s_np[s]].reshape(3, self.s_np[s])
                        for s in range(self.ns)]
        self.mom = buf.view(float)
        m = max(self.nc, 1)
        self.impulse, self.diss, self.work = np.zeros(m), np.zeros(m), np.zeros(m)
        self.p_prev = np.zeros(m)
        for c in range(self.nc):
            self.p_prev[c] = p_prev[c]
        self.order = scheme.extrapolation_order
        self.co = [np.zeros((p + 1, self.nr)) for p in range(3)]
        self.co0, self.co1, self.co2 = self.co
        self.hist = np.zeros((3, n))
        self.set_history(hist)
        self.h_prev = h_prev
        self.next_trigger = float("inf")
        self.n_iterations = 0
        self.pending = 0

    def __dealloc__(self):
        free(self.faces)

    # ----------------------------------------------------------- Python face
    def set_history(self, hist):
        """Take the force history (oldest first, the last three kept)."""
        cdef int k, r
        hist = list(hist)
        hist = hist[max(len(hist) - 3, 0):]
        self.nhist = len(hist)
        for k in range(self.nhist):
            for r in range(self.nr):
                self.hist[k, r] = hist[k][r]

    def history(self):
        """The force history, oldest first (new arrays)."""
        return [np.array(self.hist[k, :self.nr]) for k in range(self.nhist)]

    @property
    def rows(self):
        """``(d, dd, f)`` at the last step's end (new arrays)."""
        return (np.array(self.d[:self.nr]), np.array(self.dd[:self.nr]),
                np.array(self.f[:self.nr]))

    @property
    def pending_step(self):
        """Whether a step taken awaits its booking (its modes decided)."""
        return bool(self.pending)

    def resume(self, bint changed):
        """The connections' modes were decided after the pending step:
        ``changed``, its rows are found again (a grasp moves the tangential
        anchor); the next :meth:`fill` books it first."""
        if changed:
            self._rows()

    # --------------------------------------------------------------- the loop
    def fill(self, double t_end, long k, long n, double H, double sliver,
             double[::1] T, double[:, ::1] D, double[:, ::1] DD, double[:, ::1] F,
             double[:, ::1] IMP, double[:, ::1] DISS, double[:, ::1] INT, double[:, ::1] W,
             double[:, ::1] X, double[::1] POT, long[::1] ITS):
        """Fill rows from 0 with the steps from count ``k`` (``n`` steps of
        ``H``, the last to ``t_end``).  Returns ``(rows, k, reason, error,
        t1)``: the rows written, the count after the steps taken (the
        pending one included), why the block ended (:data:`REASONS`), the
        exception a step raised (reason ``raised``) and the end of the last
        step taken [s].  ``ITS`` takes the iterations so far at each row."""
        cdef int m = T.shape[0], i = 0, reason = FULL
        cdef double t = 0.0, h = 0.0, t1 = 0.0
        error = None
        if self.pending:
            self.pending = 0
            self._book(self.h_pend)
            self._write(i, self.t_pend, T, D, DD, F, IMP, DISS, INT, W, X, POT)
            ITS[i] = self.it_pend
            i += 1
        while i < m:
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
                self._advance(t, h)
            except BaseException as exc:
                # a signal's KeyboardInterrupt too: the step is not counted
                error = exc
                reason = RAISED
                break
            k += 1
            self._rows()
            t1 = t + h
            if not self._finite():
                reason = NONFINITE
                break
            if self._may_switch(t1):
                self.pending = 1
                self.t_pend, self.h_pend = t1, h
                self.it_pend = self.n_iterations
                reason = SWITCH
                break
            self._book(h)
            self._write(i, t + h, T, D, DD, F, IMP, DISS, INT, W, X, POT)
            ITS[i] = self.n_iterations
            i += 1
        return i, k, REASONS[reason], error, t1

    cdef int _advance(self, double t, double h) except -1:
        """One macro step: the extrapolated forces, the compiled iterations,
        the sides told of their step (as ``Implicit._advance_compiled``)."""
        cdef int p, r, s
        cdef double ratio = h / self.h_prev, f0, f1, f2, g
        cdef double[:, ::1] co
        cdef int it
        p = self.order if self.order < self.nhist - 1 else self.nhist - 1
        co = self.co0 if p == 0 else self.co1 if p == 1 else self.co2
        for r in range(self.nr):            # extrapolation_coeffs, its formulas in its order
            f0 = self.hist[self.nhist - 1, r]
            self.fn[r] = f0
            co[0, r] = f0
            if p == 1:
                co[1, r] = (f0 - self.hist[self.nhist - 2, r]) * ratio
            elif p == 2:
                f1 = self.hist[self.nhist - 2, r]
                f2 = self.hist[self.nhist - 3, r]
                co[1, r] = 0.5 * (3 * f0 - 4 * f1 + f2) * ratio
                co[2, r] = 0.5 * (f0 - 2 * f1 + f2) * ratio * ratio
            if ratio > 1.0 + 1e-9 and f0 == 0.0:     # a growing step holds an open contact
                for s in range(1, p + 1):
                    co[s, r] = 0.0
        try:
            it = self.kernel.c_advance(t, h, self.fn, co, self.guess)
        except BaseException:
            if self.kernel.failed_side >= 0:    # as Subsystem.step marks a side whose step raised
                self.ksubs[self.kernel.failed_side].status = "failed"
            raise
        for r in range(self.nr):            # the impulse and force polynomial the step applied
            g = self.guess[r]
            f0 = self.fn[r]
            self.stepped[r] = h * (f0 + 0.5 * (g - f0))
        self._work()
        for s in range(self.ns):
            self.ksubs[s].took_compiled_step(t, h, self.moments[s])
        self.n_iterations += it
        if not self.kernel.converged:
            self.not_converged(self.system, t, h, np.array(self.fn[:self.nr]),
                               np.array(self.guess[:self.nr]), self.kernel.residual,
                               self.coupler_rows, [])
        self.h_prev = h
        for s in range(self.ns):            # the ports at the step's end
            xv = self.xs[s]
            self._outputs(s, xv)
        return 0

    cdef void _outputs(self, int s, double[::1] x):
        cdef int j = 2 * self.s_first[s]
        self.faces[s].outputs(self.faces[s].side, &x[0], &self.pos[j], &self.vel[j])

    cdef int _work(self) except -1:
        """:meth:`CoupledSystem.exchange_work`'s rows: each side's force
        polynomial ``[f_n, guess - f_n]`` against its ports' velocity moments
        (which it keeps, as ``took_compiled_step`` is handed them)."""
        cdef double[:, ::1] G
        cdef double[::1] mom
        cdef int s, r, q, nq
        cdef double a, b
        for r in range(self.nr):
            self.w[r] = 0.0
        for s in range(self.ns):
            nq = 2 * self.s_np[s]
            mom = self.mom[s]
            for q in range(3 * nq):
                mom[q] = self.kernel.pm[s, q]
            G = self.G[s]
            for r in range(self.nr):
                a = 0.0
                b = 0.0
                for q in range(nq):
                    a += mom[q] * G[q, r]
                    b += mom[nq + q] * G[q, r]
                self.w[r] += self.fn[r] * a + (self.guess[r] - self.fn[r]) * b
        return 0

    cdef void _rows(self) noexcept:
        """The rows and forces of every contact (:meth:`CoupledSystem.penetrations`
        and :meth:`~CoupledSystem.forces`) in the current modes."""
        cdef int c, a, b, tr
        cdef double dx0, dx1, dv0, dv1, nx, ny, d, dd, fa, sw
        for c in range(self.nc):
            a = 2 * self.c_a[c]
            b = 2 * self.c_b[c]
            nx = self.c_nx[c]
            ny = self.c_ny[c]
            dx0 = self.pos[a] - self.pos[b]
            dx1 = self.pos[a + 1] - self.pos[b + 1]
            dv0 = self.vel[a] - self.vel[b]
            dv1 = self.vel[a + 1] - self.vel[b + 1]
            d = self.c_off[c] - (dx0 * nx + dx1 * ny)
            dd = -(dv0 * nx + dv1 * ny)
            self.d[c] = d
            self.dd[c] = dd
            tr = self.c_trow[c]
            if tr >= 0:                     # t = (-n_y, n_x), e from the anchor
                self.d[tr] = (dx0 * -ny + dx1 * nx) - self.anchor[c]
                self.dd[tr] = dv0 * -ny + dv1 * nx
            if self.c_grasp[c] and self.mode[c] == GRASPED:
                self.f[c] = self.g_k[c] * d + self.g_c[c] * dd
                self.f[tr] = -(self.g_kt[c] * self.d[tr] + self.g_ct[c] * self.dd[tr])
                continue
            if self.c_kind[c] == LINEAR:
                fa = self.c_k[c] * d
                sw = d
            else:
                fa = self.c_k[c] * d + self.c_cd[c] * dd
                sw = d + (self.c_cd[c] / self.c_k[c]) * dd
                if d < sw:
                    sw = d
            self.f[c] = (fa if fa > 0.0 else 0.0) if sw > 0.0 else 0.0
            if tr >= 0:
                self.f[tr] = 0.0

    cdef bint _finite(self) noexcept:
        cdef int r
        for r in range(self.nr):
            if not (isfinite(self.d[r]) and isfinite(self.dd[r])):
                return False
        return True

    cdef bint _may_switch(self, double t1) noexcept:
        """Whether a connection may switch at ``t1``: an open grasp that
        closes on touch whose law gives a force, or a trigger's time come
        (``next_trigger``, set below the trigger by more than
        :meth:`Trigger.due`'s tolerance)."""
        cdef int c
        cdef double d, sw
        if t1 >= self.next_trigger:
            return True
        for c in range(self.nc):
            if self.c_touch[c] and self.mode[c] == OPEN:
                d = self.d[c]
                sw = d
                if self.c_kind[c] == KELVIN_VOIGT:
                    sw = d + (self.c_cd[c] / self.c_k[c]) * self.dd[c]
                    if d < sw:
                        sw = d
                if sw > 0.0:
                    return True
        return False

    cdef void _book(self, double h) noexcept:
        """What the Python loop does after the modes are decided:
        ``accept`` (the history), then :meth:`StepBooks.book`'s ledgers."""
        cdef int c, r, tr
        cdef double dp, rate, e, de, ft
        if self.nhist == 3:
            for r in range(self.nr):
                self.hist[0, r] = self.hist[1, r]
                self.hist[1, r] = self.hist[2, r]
            self.nhist = 2
        for r in range(self.nr):
            self.hist[self.nhist, r] = self.f[r]
        self.nhist += 1
        for c in range(self.nc):            # bincount of the rows' work
            tr = self.c_trow[c]
            if tr >= 0:
                self.work[c] += (0.0 + self.w[c]) + self.w[tr]
            else:
                self.work[c] += 0.0 + self.w[c]
        for c in range(self.nc):
            self.impulse[c] += self.stepped[c]
            tr = self.c_trow[c]
            ft, e, de = (self.f[tr], self.d[tr], self.dd[tr]) if tr >= 0 else (0.0, 0.0, 0.0)
            if self.c_grasp[c] and self.mode[c] == GRASPED:
                rate = self.g_c[c] * self.dd[c] * self.dd[c] + self.g_ct[c] * de * de
            else:
                dp = self.d[c] if self.d[c] > 0.0 else 0.0
                rate = (self.f[c] - self.c_k[c] * dp) * self.dd[c]
                if self.c_grasp[c]:
                    rate = rate - ft * de
            self.diss[c] += 0.5 * h * (self.p_prev[c] + rate)
            self.p_prev[c] = rate

    cdef int _write(self, int i, double t1, double[::1] T, double[:, ::1] D, double[:, ::1] DD,
                    double[:, ::1] F, double[:, ::1] IMP, double[:, ::1] DISS,
                    double[:, ::1] INT, double[:, ::1] W, double[:, ::1] X,
                    double[::1] POT) except -1:
        """Row ``i``: the sample the recorder is handed, with the states and
        the contacts' stored energy in the current modes."""
        cdef int r, c, s, tr
        cdef double a = 0.0, b = 0.0, dp, e, pot = 0.0
        cdef double[::1] v
        cdef Py_ssize_t off = 0
        T[i] = t1
        for r in range(self.nr):
            D[i, r] = self.d[r]
            DD[i, r] = self.dd[r]
            F[i, r] = self.f[r]
        for c in range(self.nc):
            IMP[i, c] = self.impulse[c]
            DISS[i, c] = self.diss[c]
            W[i, c] = self.work[c] + 0.0
            tr = self.c_trow[c]
            if self.c_grasp[c] and self.mode[c] == GRASPED:
                e = self.d[tr]
                pot += 0.5 * (self.g_k[c] * self.d[c] * self.d[c] + self.g_kt[c] * e * e)
            else:
                dp = self.d[c] if self.d[c] > 0.0 else 0.0
                pot += 0.5 * self.c_k[c] * dp * dp
        POT[i] = pot
        for s in range(self.nsub):
            sub = self.subs[s]
            la, lb = sub.ledger()
            a += la
            b += lb
            v = sub.x
            if v.shape[0]:
                memcpy(&X[i, off], &v[0], v.shape[0] * sizeof(double))
            off += v.shape[0]
        INT[i, 0] = a
        INT[i, 1] = b
        return 0

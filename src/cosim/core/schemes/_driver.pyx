# cython: boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
"""Compiled macro loop of the explicit co-simulation schemes (Jacobi and
Gauss-Seidel): the propose / save / advance / judge / retry / accept cycle
of :class:`cosim.core.schemes.step_control.StepController` and the explicit
schemes' ``advance``, over the loop's state held in C arrays (the fields of
:class:`~cosim.core.schemes.step_control.StepState`).

:class:`Driver` takes one accepted macro step per call (with any rejected
tries before it) and keeps the step's books; :mod:`cosim.core.schemes._driver_block`
calls it step after step and writes the samples into blocks that the
recorder and the run guard take as arrays
(:mod:`cosim.core.schemes.driven_block`), and the Python loop may instead
book and record each step as it comes
(:meth:`~cosim.core.schemes.step_control.StepBooks.book_driven`).  What the driver covers
is decided once per run by :func:`cosim.core.schemes.driver.refusal`; the
Python loop (:meth:`cosim.core.schemes.base.CoSimulationScheme.run`) stays
the reference it is tested against.

The sides are stepped through the C faces of their compiled kernels
(:mod:`cosim.core._side_face`, held by
:class:`cosim.core.schemes._driver_faces.Sides`), so that a macro step calls
no Python where every side offers one; a side without a face, or one that
declines a step, takes its Python step there (duck-typed through its
kernel's Python methods), and ``cosim.core`` imports nothing of
``cosim.sides``.  Every formula below is the Python loop's, written in the
same order of operations.
"""
import importlib

import numpy as np
from libc.math cimport isfinite, isnan, NAN
from libc.stdlib cimport calloc, free
from libc.string cimport memcpy

from cosim.core.subsystem import StepInput
from cosim.core._side_face cimport SwitchLog
from cosim.core.schemes._driver_faces cimport Sides
from cosim.core.schemes._driver_faces import Sides
# declarations only: _follow is imported for a run with a following contact
from cosim.core.schemes._follow cimport FollowTable
from cpython.pycapsule cimport PyCapsule_GetPointer
from cosim.core.schemes.step_control import LAND_MARGIN, ONSET_WINDOW, onset_contacts

# the step controller's constants, as C doubles (read at every step)
cdef double LAND_M = LAND_MARGIN, ONSET_W = ONSET_WINDOW

#: kinds of side
cdef enum:
    RIGID = 0
    MULTIBODY = 1
    STRUCTURE = 2


cdef class Driver:
    """The compiled macro loop of one run.

    Parameters
    ----------
    scheme : Jacobi or GaussSeidel
    system : CoupledSystem
    order : list of int
        The moving subsystems in the order they step.
    state : StepState
        The loop's state at the start (outputs, forces, history).
    d, dd : (n_rows,) arrays
        The rows at the start.
    controlled : bool
        Whether the step is controlled (``contact_step`` given and rows exchanged).
    """

    def __init__(self, scheme, system, order, state, d, dd, bint controlled):
        cdef int s, c, r, k, i
        self.system = system
        self.scheme = scheme
        self.subs = system.subsystems
        self.nsub = len(self.subs)
        self.gs = scheme.name == "gauss_seidel"
        self.order = scheme.extrapolation_order
        self.H = scheme.macro_step
        self.horizon = scheme.horizon
        self.contact_step = scheme.contact_step if scheme.contact_step is not None else NAN
        self.controlled = controlled
        self.land = bool(getattr(scheme, "land_onsets", False))
        self.nc = system.n_contacts
        self.nr = system.n_rows
        self.laws = [ln.contact.law for ln in system.links]
        self.step_input = StepInput
        self.kind = np.zeros(self.nsub, dtype=np.int_)
        self.rigid = np.zeros(self.nsub, dtype=np.int_)
        self.port0 = np.zeros(self.nsub + 1, dtype=np.int_)
        self.nport = np.zeros(self.nsub, dtype=np.int_)
        self.max_step = np.zeros(self.nsub)
        self.free_step = np.zeros(self.nsub)
        for s, sub in enumerate(self.subs):
            self.nport[s] = sub.n_ports
            self.port0[s + 1] = self.port0[s] + sub.n_ports
            if sub.rigid:
                self.kind[s], self.rigid[s] = RIGID, 1
            elif sub.closed_end is not None:
                self.kind[s] = STRUCTURE
            else:
                self.kind[s] = MULTIBODY
                self.max_step[s] = sub.integrator.max_step
                self.free_step[s] = sub.integrator.free_step or 0.0
        self.nports = self.port0[self.nsub]
        self.seq = np.array(order, dtype=np.int_)
        self.n_order = len(order)
        links = system.links
        row_a, row_b = system.contact_rows
        self.row_a = np.array(row_a, dtype=np.int_)
        self.row_b = np.array(row_b, dtype=np.int_)
        self.sub_a = np.array([ln.sub_a for ln in links], dtype=np.int_)
        self.sub_b = np.array([ln.sub_b for ln in links], dtype=np.int_)
        self.normal = np.ascontiguousarray(system.contact_normals, dtype=float).reshape(self.nc, 2)
        self.offset = np.ascontiguousarray(system.contact_offsets, dtype=float)
        self.coupler = np.array(system.coupler_rows, dtype=np.int_)
        self.n_coupler = self.coupler.shape[0]
        self.exchanged = np.array(system.exchanged, dtype=np.int_)
        self.n_exch = self.exchanged.shape[0]
        hc = sorted(system.hosted)
        self.n_hosted = len(hc)
        self.h_c = np.array(hc, dtype=np.int_)
        self.h_host = np.array([system.hosted[c].host for c in hc], dtype=np.int_)
        self.h_slot = np.array([system.hosted[c].slot for c in hc], dtype=np.int_)
        self.h_partner = np.array([system.hosted[c].partner for c in hc], dtype=np.int_)
        self.h_pport = np.array([system.hosted[c].partner_port for c in hc], dtype=np.int_)
        self.hosted_embs = [system.hosted[c].embedded for c in hc]
        # copies: a following contact turns side a's column in place (_follow)
        self.Gc = [np.array(G, dtype=float, order="C") for G in system.exchange_maps]
        self.gp = <double**> calloc(max(self.nsub, 1), sizeof(double*))
        if self.gp == NULL:
            raise MemoryError()
        for s in range(self.nsub):
            if self.Gc[s].size:
                self.gp[s] = <double*> <size_t> self.Gc[s].ctypes.data
        self.fol, self.ft = None, NULL
        if system.followers:
            self.fol = importlib.import_module("cosim.core.schemes._follow").Followers(
                system, self.Gc)
            self.ft = <FollowTable*>PyCapsule_GetPointer(self.fol.table(), b"cosim.FollowTable")
        rows_of = [list(scheme.rows_of(system, s)) for s in range(self.nsub)]
        self.rows_idx = np.array([r for rs in rows_of for r in rs] or [0], dtype=np.int_)
        self.rows_off = np.cumsum([0] + [len(rs) for rs in rows_of]).astype(np.int_)
        self.P = np.zeros((self.nports, 2))
        self.V = np.zeros((self.nports, 2))
        for s in range(self.nsub):
            pos, vel = state.outs[s]
            for i in range(self.nport[s]):
                self.P[self.port0[s] + i, 0] = pos[i, 0]
                self.P[self.port0[s] + i, 1] = pos[i, 1]
                self.V[self.port0[s] + i, 0] = vel[i, 0]
                self.V[self.port0[s] + i, 1] = vel[i, 1]
        self.P0 = np.array(self.P)
        self.V0 = np.array(self.V)
        self.Pp = np.zeros((self.nports, 2))
        self.Vp = np.zeros((self.nports, 2))
        self.has_prev = False
        self.has_dd_prev = False
        self.aimed = False
        self.h_next = NAN
        self.h_prev_step = NAN
        self.hist = np.zeros((3, self.nr))
        self.nhist = len(state.hist)
        for k in range(self.nhist):
            for r in range(self.nr):
                self.hist[k, r] = state.hist[k][r]
        self.f = np.array(state.f, dtype=float)
        self.d = np.array(d, dtype=float)
        self.dd = np.array(dd, dtype=float)
        self.fv, self.dv, self.ddv = self.f, self.d, self.dd
        self.dd_prev = np.zeros(self.nr)
        self.d1 = np.zeros(self.nr)
        self.dd1 = np.zeros(self.nr)
        self.f1 = np.zeros(self.nr)
        self.stepped = np.zeros(self.nr)
        self.work = np.zeros(self.nr)
        self.stv, self.wv = self.stepped, self.work
        self.base = np.zeros((3, self.nr))
        self.coeffs = np.zeros((3, self.nr))
        self.sides = Sides(list(self.subs), self.max_step, self.free_step)
        self.fresh = True
        self.ubuf = np.zeros(3 * 2 * max(self.nports, 1))
        self.pmbuf = np.zeros(6 * max(self.nports, 1))
        self.gotv = np.zeros(max(self.nr, 1))
        self.mot = np.zeros((max(self.n_hosted, 1), 8))
        self.mot_n = np.zeros(max(self.n_hosted, 1), dtype=np.int_)
        self.mot_t0 = np.zeros(max(self.n_hosted, 1))
        self.mot_h = np.ones(max(self.n_hosted, 1))
        self.force_py = np.zeros(self.nsub, dtype=np.int_)
        self.imp0 = np.zeros(max(self.n_hosted, 1))
        self.done = np.zeros(self.nsub, dtype=np.int_)
        self.n_steps = self.n_rejected = 0
        # the books
        emb = sorted(system.embedded.items())
        self.n_emb = len(emb)
        self.e_c = np.array([c for c, _ in emb], dtype=np.int_)
        self.e_host = np.array([hs[0] for _, hs in emb], dtype=np.int_)
        self.e_slot = np.array([hs[1] for _, hs in emb], dtype=np.int_)
        self.impulse = np.zeros(self.nc)
        self.diss = np.zeros(self.nc)
        self.work_total = np.zeros(self.nc)
        self.impv, self.dissv, self.wtv = self.impulse, self.diss, self.work_total
        self.work_rec = np.zeros(self.nc)
        self.wrv = self.work_rec
        self.p_prev = np.zeros(self.nc)
        self.coupler_diss = False
        rates = system.dissipation_rates(self.f, self.d, self.dd)
        for i in range(self.n_coupler):
            self.p_prev[self.coupler[i]] = rates[self.coupler[i]]
        # laws evaluated here: 0 linear, 1 Kelvin-Voigt, -1 the law's own evaluate
        self.law_kind = np.full(self.nc, -1, dtype=np.int_)
        self.law_k = np.zeros(self.nc)
        self.law_c = np.zeros(self.nc)
        for c, law in enumerate(self.laws):
            if type(law).__name__ == "LinearLaw" and type(law).__module__.startswith("couplers."):
                self.law_kind[c], self.law_k[c] = 0, law.contact_stiffness
            elif type(law).__name__ == "KelvinVoigtLaw" and \
                    type(law).__module__.startswith("couplers."):
                self.law_kind[c], self.law_k[c] = 1, law.contact_stiffness
                self.law_c[c] = law.contact_damping
                self.coupler_diss = True
            else:
                self.coupler_diss = True

    # ------------------------------------------------------------ control
    cdef double _propose(self, double remaining):
        """StepController.propose."""
        cdef int i, c
        cdef double h
        cdef bint short = False
        if not isnan(self.h_next):
            h = self.h_next
            self.h_next = NAN
            return h if h < remaining else remaining
        if self.nhist > 1:
            for i in range(self.n_exch):
                if self.hist[self.nhist - 2, self.exchanged[i]] != 0:
                    short = True
        for i in range(self.n_exch):
            c = self.exchanged[i]
            if self.fv[c] > 0:              # in touch (no connections here)
                short = True
            if c < self.nc and self.dv[c] + self.horizon * self.ddv[c] > 0:
                short = True
        h = self.contact_step if short else self.H
        return h if h < remaining else remaining

    cdef object _judge(self, double t, double h):
        """StepController.judge without interface error control: the step to
        retry and whether it is aimed, or None."""
        cdef int i, c, r
        cdef double dl, late
        if not h > self.contact_step:
            if self.land and not self.aimed:
                return self._landing(t, h)
            return None
        if not self.aimed:
            onset = self._onset(t, h)
            if onset is None:
                for i in range(self.n_coupler):        # touched
                    r = self.coupler[i]
                    if self.fv[r] == 0.0 and self.stv[r] != 0.0:
                        return 0.5 * h, False
            return onset
        for i in range(self.n_coupler):                # overshot
            c = self.coupler[i]
            if c >= self.nc:
                continue
            late = self.dd1[c] if self.dd1[c] > 0.0 else 0.0
            if self.dv[c] <= 0 and self.d1[c] > late * self.contact_step:
                return 0.5 * h, False
        return None

    cdef object _landing(self, double t, double h):
        """StepController.landing (numpy only where a contact closed)."""
        cdef int i, c, k
        cdef double tau
        cdef bint closed = False, hosted = False
        for i in range(self.n_coupler):
            c = self.coupler[i]
            if c < self.nc and self.dv[c] <= 0 and self.d1[c] > 0:
                closed = True
        for k in range(self.n_hosted):
            if self._hosted_touch(k, &tau):
                hosted = True
        if not (closed or hosted):
            return None
        onset = self._onset(t, h)
        if onset is None or not onset[1]:
            return None
        tau = onset[0] + (LAND_M if hosted else -LAND_M) * self.contact_step
        return (tau, True) if tau > ONSET_W * self.contact_step else None

    cdef bint _hosted_touch(self, int k, double* first) noexcept:
        """Whether hosted contact ``k`` touched in its host's last step, and
        when first (``first[0]``)."""
        cdef SwitchLog* log = self.sides.log[self.h_host[k]]
        cdef int i
        cdef bint found = False
        for i in range(log.n):
            if log.slot[i] == self.h_slot[k] and log.on[i]:
                if not found or log.time[i] < first[0]:
                    first[0] = log.time[i]
                found = True
        return found

    cdef object _onset(self, double t, double h):
        """StepController.onset (its root finding, a rare path, in numpy)."""
        cdef int i, c, k
        cdef double a, ts, first = 0.0
        cdef bint hosted = False
        for k in range(self.n_hosted):
            if self._hosted_touch(k, &ts):
                if not hosted or ts < first:
                    first = ts
                hosted = True
        if hosted:
            a = first - t
            return (1e-12 * h if 1e-12 * h > a else a), True
        closing = [int(c) for c in self.system.coupler
                   if self.dv[c] <= 0 and self.d1[c] > 0]
        if not closing:
            return None
        found, all_found = [], True
        for c in closing:
            a = 0.0
            if self.has_dd_prev:
                a = (self.ddv[c] - self.dd_prev[c]) / self.h_prev_step
            roots = np.roots([0.5 * a, self.ddv[c], self.dv[c]]) if a else (
                [-self.dv[c] / self.ddv[c]] if self.ddv[c] > 0 else [])
            tau = [r.real for r in np.atleast_1d(roots) if abs(r.imag) < 1e-12 and
                   0 < r.real < h]
            found += tau
            all_found = all_found and bool(tau)
        if all_found:
            return max(min(found), 1e-12 * h), True
        return max(min([0.5 * h] + found), 1e-12 * h), False

    # ---------------------------------------------------------- the sides
    cdef void _outputs(self, int s) except *:
        """Read side ``s``'s port outputs into the live arrays: through its C
        face, else its Python ``outputs``."""
        cdef int i, p0 = self.port0[s]
        cdef double[:, ::1] pos, vel
        if self.sides.ready(s):
            self.sides.outputs(s, &self.P[p0, 0], &self.V[p0, 0])
            return
        self.sides.to_python()
        sub = self.subs[s]
        po, ve = sub.outputs(sub.t, sub.x)
        pos = np.ascontiguousarray(po, dtype=float)
        vel = np.ascontiguousarray(ve, dtype=float)
        for i in range(self.nport[s]):
            self.P[p0 + i, 0] = pos[i, 0]
            self.P[p0 + i, 1] = pos[i, 1]
            self.V[p0 + i, 0] = vel[i, 0]
            self.V[p0 + i, 1] = vel[i, 1]

    cdef int _step_side(self, int s, double t, double h, int width) except -1:
        """Step side ``s`` over ``[t, t + h]`` under the row forces
        ``self.coeffs[:width]`` (``_step_side`` of the base class without
        sub-steps): through its C face, else (no face, or the face declines)
        its Python step; add the work they did to ``self.work`` and leave
        the impulse each row gave in ``self.gotv``."""
        cdef int j, k, r, np2 = 2 * self.nport[s]
        cdef double acc, mg
        cdef const double* G = self.gp[s]
        cdef double* u = &self.ubuf[0]
        cdef double* mom = &self.pmbuf[0]
        for j in range(width):          # coeffs @ Gc[s].T
            for k in range(np2):
                acc = 0.0
                for r in range(self.nr):
                    acc += self.coeffs[j, r] * G[k * self.nr + r]
                u[j * np2 + k] = acc
        if not (self.sides.ready(s) and not self.force_py[s]
                and self.sides.loop(s, t, h, u, width, mom) == 0):
            self._python_step(s, t, h, width)
        self.force_py[s] = 0
        for r in range(self.nr):        # collect_work: einsum("jc,jc->c", coeffs, mom[:p] @ G)
            acc = 0.0
            for j in range(width):
                mg = 0.0
                for k in range(np2):
                    mg += mom[j * np2 + k] * G[k * self.nr + r]
                acc += self.coeffs[j, r] * mg
            self.wv[r] += acc
        for r in range(self.nr):
            acc = self.coeffs[0, r] / 1.0
            for j in range(1, width):
                acc += self.coeffs[j, r] / (j + 1.0)
            self.gotv[r] = h * acc
        return 0

    cdef int _python_step(self, int s, double t, double h, int width) except -1:
        """Side ``s``'s step through its Python methods (the reference
        path): its kernel asked for at each step, as the side's own step
        asks (a side may change its kernel or decline one step), else its
        own step; the port moments into ``self.pmbuf``."""
        cdef int k, i, np2 = 2 * self.nport[s]
        cdef double[::1] mv
        self.sides.to_python()
        for k in range(self.n_hosted):          # the partners' motion, as set in C
            if self.h_host[k] == s:
                self.hosted_embs[k].set_motion(self.mot_t0[k], self.mot_h[k], np.asarray(
                    self.mot[k, :2 * self.mot_n[k]]).view(complex).copy())
        sub = self.subs[s]
        u = np.array(self.ubuf[:width * np2]).reshape(width, self.nport[s], 2)
        inp = self.step_input(t, h, u)
        kern = sub.compiled_step(inp)
        if kern is None:                # the side's own step: its reference
            sub.reference_step(t, h, inp)
            pm = sub.port_moments
        elif self.kind[s] == MULTIBODY:
            sub.begin_step(t, h)
            sub.switch_log = []
            sub.impact_log = []
            pm = kern.step(t, h, sub.x, sub.aux, inp, sub.embedded_contacts, self.max_step[s],
                           self.free_step[s], sub.switch_handler, sub.peak)
            sub.port_moments = pm
        else:
            pm = self._step_structure(s, kern, t, h, inp)
        sub.t = t + h
        sub.n_steps += 1
        mv = np.ascontiguousarray(pm).view(float).reshape(-1)
        for i in range(3 * np2):
            self.pmbuf[i] = mv[i]
        self.sides.took_python_step(s)
        return 0

    cdef object _step_structure(self, int s, kern, double t, double h, inp):
        """The structure's step by its kernel, as its ``_step_impl`` takes it;
        where the kernel does not take it (a load or motion beyond its
        degree, a stalled step) the structure's own step does (the
        reference, saying so once).  Returns the port moments."""
        sub = self.subs[s]
        embs = sub.embedded_contacts
        sub.switch_log = []
        sub.begin_step(t, h)
        if kern.set_step(t, h, inp.coeffs,
                         [(e.t0, e.h, e.motion, e.velocity_coeffs) for e in embs]):
            pm = np.zeros((3, self.nport[s]), complex)
            sub.port_moments = pm
            if not embs:
                kern.step_free(sub.x, pm.view(float))
                return pm
            saved = sub.aux.copy(), sub.closed_end.copy(), sub.peak.copy()
            try:
                sub.switch_log = kern.step(sub.x, sub.aux, pm.view(float), sub.closed_end,
                                           sub.peak)
                return pm
            except RuntimeError as exc:
                if type(exc).__name__ != "StalledStep":
                    raise
                sub.aux[:], sub.closed_end[:], sub.peak[:] = saved
        sub.reference_step(t, h, inp)
        return sub.port_moments

    cdef void _partner_motion(self, int k, double t, double h, bint after) noexcept:
        """_set_partner_motion of hosted contact ``k``: the cubic Hermite to
        the partner's outputs at ``t + h`` (``after``), else extrapolated;
        into ``self.mot[k]`` and the host's face (its Python step sets the
        contact's)."""
        cdef int p = self.port0[self.h_partner[k]] + self.h_pport[k], host = self.h_host[k]
        cdef double x0r = self.P0[p, 0], x0i = self.P0[p, 1], v0r = self.V0[p, 0]
        cdef double v0i = self.V0[p, 1], x1r, x1i, v1r, v1i, dxr, dxi, ar = 0.0, ai = 0.0
        cdef double* m = &self.mot[k, 0]
        m[0], m[1], m[2], m[3] = x0r, x0i, h * v0r, h * v0i
        if after:
            x1r, x1i, v1r, v1i = self.P[p, 0], self.P[p, 1], self.V[p, 0], self.V[p, 1]
            dxr, dxi = x1r - x0r, x1i - x0i
            m[4] = 3 * dxr - h * (2 * v0r + v1r)
            m[5] = 3 * dxi - h * (2 * v0i + v1i)
            m[6] = -2 * dxr + h * (v0r + v1r)
            m[7] = -2 * dxi + h * (v0i + v1i)
            self.mot_n[k] = 4
        else:
            if self.order > 0 and self.has_prev:
                ar = (v0r - self.Vp[p, 0]) / self.h_prev_step
                ai = (v0i - self.Vp[p, 1]) / self.h_prev_step
            m[4], m[5] = 0.5 * ar * h * h, 0.5 * ai * h * h
            self.mot_n[k] = 3
        self.mot_t0[k], self.mot_h[k] = t, h
        if self.sides.ready(host) and self.sides.motion(host, self.h_slot[k], t, h, m,
                                                        self.mot_n[k]):
            self.force_py[host] = 1

    def sync(self):
        """Hand the sides, and the hosted contacts, what the loop kept in C:
        their time, step count and last switches, the partners' motion."""
        cdef int k
        for k in range(self.n_hosted):
            if self.mot_n[k]:
                self.hosted_embs[k].set_motion(self.mot_t0[k], self.mot_h[k], np.asarray(
                    self.mot[k, :2 * self.mot_n[k]]).view(complex).copy())
        self.sides.to_python()

    cdef void _penetration(self, int c, double* d, double* dd):
        cdef int a = self.row_a[c], b = self.row_b[c]
        d[0] = self.offset[c] - ((self.P[a, 0] - self.P[b, 0]) * self.normal[c, 0]
                                 + (self.P[a, 1] - self.P[b, 1]) * self.normal[c, 1])
        dd[0] = -((self.V[a, 0] - self.V[b, 0]) * self.normal[c, 0]
                  + (self.V[a, 1] - self.V[b, 1]) * self.normal[c, 1])
        if self.ft != NULL:
            dd[0] += self.ft.rate(self.ft.obj, c, self.V[a, 0], self.V[a, 1])

    cdef double _force(self, int c, double d, double dd):
        """The law's force (``evaluate(d, dd)[0]``), in C for the linear and
        Kelvin-Voigt laws, with their formulas."""
        cdef double k, cd, a, sw, fa
        cdef int kind = self.law_kind[c]
        if kind == 0:
            return self.law_k[c] * d if d > 0.0 else 0.0
        if kind == 1:
            k, cd = self.law_k[c], self.law_c[c]
            a = d + (cd / k) * dd
            sw = d if d < a else a
            fa = k * d + cd * dd
            return (fa if fa > 0.0 else 0.0) if sw > 0.0 else 0.0
        return float(self.laws[c].evaluate(d, dd)[0])

    # --------------------------------------------------------- the advance
    cdef int _extrapolated(self, double ratio):
        """``_extrapolated`` of InputExtrapolation into ``self.base``; returns its rows."""
        cdef int p = self.order if self.order < self.nhist - 1 else self.nhist - 1
        cdef int r, j
        cdef double fn, f1, f2
        for r in range(self.nr):
            fn = self.hist[self.nhist - 1, r]
            self.base[0, r] = fn
            if p == 1:
                self.base[1, r] = (fn - self.hist[self.nhist - 2, r]) * ratio
            elif p == 2:
                f1 = self.hist[self.nhist - 2, r]
                f2 = self.hist[self.nhist - 3, r]
                self.base[1, r] = 0.5 * (3 * fn - 4 * f1 + f2) * ratio
                self.base[2, r] = 0.5 * (fn - 2 * f1 + f2) * ratio * ratio
            if ratio > 1.0 + 1e-9 and fn == 0.0:
                for j in range(1, p + 1):
                    self.base[j, r] = 0.0
        return p + 1

    cdef void _advance_jacobi(self, double t, double h, double ratio) except *:
        cdef int rows = self._extrapolated(ratio), i, j, r, s, k, q
        for j in range(rows):
            for r in range(self.nr):
                self.coeffs[j, r] = self.base[j, r]
        for k in range(self.n_hosted):
            self._partner_motion(k, t, h, False)
        for r in range(self.nr):
            self.stv[r] = 0.0
        for i in range(self.n_order):
            s = self.seq[i]
            self._step_side(s, t, h, rows)
            for q in range(self.rows_off[s], self.rows_off[s + 1]):
                r = self.rows_idx[q]
                if self.sub_a[r] == s:
                    self.stv[r] = self.gotv[r]
            self._outputs(s)

    cdef void _advance_gs(self, double t, double h, double ratio) except *:
        cdef int rows = self._extrapolated(ratio), width = rows if rows > 2 else 2
        cdef int i, j, r, s, k, c, other, host, q
        cdef double imp, mom, m0, m1, d, dd, ftilde
        cdef double* aux
        for s in range(self.nsub):
            self.done[s] = self.rigid[s]
        for r in range(self.nr):
            self.stv[r] = 0.0
        for k in range(self.n_hosted):
            self.imp0[k] = self.sides.paux[self.h_host[k]][4 * self.h_slot[k]]
        for i in range(self.n_order):
            s = self.seq[i]
            for j in range(width):
                for r in range(self.nr):
                    self.coeffs[j, r] = self.base[j, r] if j < rows else 0.0
            for k in range(self.n_hosted):
                host = self.h_host[k]
                c = self.h_c[k]
                if host == s:
                    self._partner_motion(k, t, h, self.done[self.h_partner[k]]
                                         and not self.rigid[self.h_partner[k]])
                elif self.h_partner[k] == s and self.done[host]:    # hosted_force
                    aux = self.sides.paux[host]
                    imp = aux[4 * self.h_slot[k]]
                    mom = aux[4 * self.h_slot[k] + 2]
                    m0 = (imp - self.imp0[k]) / h
                    m1 = mom / (h * h)
                    for j in range(width):
                        self.coeffs[j, c] = 0.0
                    self.coeffs[0, c] = 4.0 * m0 - 6.0 * m1
                    self.coeffs[1, c] = 12.0 * m1 - 6.0 * m0
            for q in range(self.rows_off[s], self.rows_off[s + 1]):
                r = self.rows_idx[q]
                other = self.sub_b[r] if self.sub_a[r] == s else self.sub_a[r]
                if self.done[other]:
                    self._penetration_pred(r, s, h, &d, &dd)
                    ftilde = self._force(r, d, dd)
                    for j in range(width):
                        self.coeffs[j, r] = 0.0
                    self.coeffs[0, r] = self.hist[self.nhist - 1, r]
                    self.coeffs[1, r] = ftilde - self.hist[self.nhist - 1, r]
            self._step_side(s, t, h, width)
            for q in range(self.rows_off[s], self.rows_off[s + 1]):
                r = self.rows_idx[q]
                if self.sub_a[r] == s or self.rigid[self.sub_a[r]]:
                    self.stv[r] = self.gotv[r]
            self.done[s] = 1
            self._outputs(s)

    cdef void _penetration_pred(self, int c, int s, double h, double* d, double* dd):
        """Penetration of row ``c`` with side ``s``'s outputs extrapolated from
        ``t`` (moved by ``h`` at its velocity at order >= 1) and the others' as
        they are now."""
        cdef int a = self.row_a[c], b = self.row_b[c], lo = self.port0[s]
        cdef int hi = self.port0[s + 1]
        cdef double xa0, xa1, xb0, xb1, va0, va1, vb0, vb1
        if lo <= a < hi:
            xa0, xa1, va0, va1 = self.P0[a, 0], self.P0[a, 1], self.V0[a, 0], self.V0[a, 1]
            if self.order > 0:
                xa0 = xa0 + h * va0
                xa1 = xa1 + h * va1
        else:
            xa0, xa1, va0, va1 = self.P[a, 0], self.P[a, 1], self.V[a, 0], self.V[a, 1]
        if lo <= b < hi:
            xb0, xb1, vb0, vb1 = self.P0[b, 0], self.P0[b, 1], self.V0[b, 0], self.V0[b, 1]
            if self.order > 0:
                xb0 = xb0 + h * vb0
                xb1 = xb1 + h * vb1
        else:
            xb0, xb1, vb0, vb1 = self.P[b, 0], self.P[b, 1], self.V[b, 0], self.V[b, 1]
        d[0] = self.offset[c] - ((xa0 - xb0) * self.normal[c, 0] + (xa1 - xb1) * self.normal[c, 1])
        dd[0] = -((va0 - vb0) * self.normal[c, 0] + (va1 - vb1) * self.normal[c, 1])
        if self.ft != NULL:
            dd[0] += self.ft.rate(self.ft.obj, c, va0, va1)

    # ------------------------------------------------------------ one step
    def step(self, double t, double remaining, double h_fixed=0.0):
        """Take one accepted macro step from ``t`` (controlled: proposed
        within ``remaining`` [s], rejected tries retried; else of length
        ``h_fixed``).  Leaves the rows, forces, impulse and work of the step
        in :attr:`d`, :attr:`dd`, :attr:`f`, :attr:`stepped`, :attr:`work`
        and returns its length [s]; the sides are handed what was kept in C
        (:meth:`sync`)."""
        cdef double h = self.step_c(t, remaining, h_fixed)
        self.sync()
        return h

    cdef double step_c(self, double t, double remaining, double h_fixed) except? -1.0:
        """:meth:`step` in C, the sides' Python state left behind (see :meth:`sync`)."""
        cdef double h, ratio, w
        cdef int c, r, k, i
        cdef bint was_aimed, at_onset
        while True:
            if self.controlled:
                h = self._propose(remaining)
                self.sides.save()
            else:
                h = h_fixed
            if self.ft != NULL:         # surface points under their points at t
                self.ft.update(self.ft.obj, &self.P0[0, 0])
            ratio = h / self.h_prev
            for r in range(self.nr):
                self.wv[r] = 0.0
            if self.gs:
                self._advance_gs(t, h, ratio)
            else:
                self._advance_jacobi(t, h, ratio)
            for c in range(self.nc):
                self._penetration(c, &self.d1[c], &self.dd1[c])
                self.f1[c] = self._force(c, self.d1[c], self.dd1[c])
            if self.controlled:
                retry = self._judge(t, h)
                if retry is not None:
                    self.sides.restore()
                    self.P[...] = self.P0
                    self.V[...] = self.V0
                    self.h_next = retry[0]
                    self.aimed = retry[1]
                    self.n_rejected += 1
                    continue
            break
        # accept
        was_aimed, at_onset = self.aimed, False
        w = ONSET_W * self.contact_step
        self.aimed = False
        if self.controlled and self.land:
            for i in range(self.n_coupler):
                c = self.coupler[i]
                if c < self.nc and (self.d1[c] <= 0 and self.d1[c] + w * self.dd1[c] > 0 or (
                        was_aimed and self.f1[c] != 0 and self.fv[c] == 0)):
                    at_onset = True
        # new arrays where the recorder keeps what it is given, step by step
        f_was = self.f if self.fresh or not at_onset else np.array(self.f)
        for r in range(self.nr):
            self.dd_prev[r] = self.ddv[r]
        self.has_dd_prev = True
        self.h_prev_step = h
        self.Pp[...] = self.P0
        self.Vp[...] = self.V0
        self.has_prev = True
        self.P0[...] = self.P
        self.V0[...] = self.V
        if self.nhist == 3:
            self.hist[0, :] = self.hist[1, :]
            self.hist[1, :] = self.hist[2, :]
            self.nhist = 2
        for r in range(self.nr):
            self.hist[self.nhist, r] = self.f1[r]
        self.nhist += 1
        if self.fresh:
            self.f = np.array(self.f1)
            self.d = np.array(self.d1)
            self.dd = np.array(self.dd1)
            self.fv, self.dv, self.ddv = self.f, self.d, self.dd
        else:
            self.fv[...] = self.f1
            self.dv[...] = self.d1
            self.ddv[...] = self.dd1
        self.h_prev = h
        if at_onset:                    # the history starts again at the onset
            onsets = onset_contacts(self.system, self.contact_step, self.d, self.dd, self.f,
                                    f_was, was_aimed)
            if len(onsets):
                hist = self.scheme.onset_history(self.system, self.d, self.dd, self.f, onsets,
                                                  self.contact_step)
                self.nhist = len(hist)
                for k in range(self.nhist):
                    for r in range(self.nr):
                        self.hist[k, r] = hist[k][r]
                self.h_prev = self.contact_step
        self.n_steps += 1
        self._book(h)
        return h

    cdef void _book(self, double h) except *:
        """StepBooks.book's ledgers: the exchanged forces' work, the coupler
        rows' impulse and (trapezoidal) dissipation, the embedded contacts'
        quadratures, the subsystems' internal ledger; and whether the rows
        are finite."""
        cdef int i, c, s
        cdef double a, b
        cdef double* aux
        cdef double[::1] wr
        for c in range(self.nc):        # nr == nc: bincount is the rows' own work
            self.wtv[c] += self.wv[c]
        if self.n_coupler:
            if self.coupler_diss:
                rates = self.system.dissipation_rates(self.f, self.d, self.dd)
            for i in range(self.n_coupler):
                c = self.coupler[i]
                self.impv[c] += self.stv[c]
                a = rates[c] if self.coupler_diss else 0.0
                self.dissv[c] += 0.5 * h * (self.p_prev[c] + a)
                self.p_prev[c] = a
        for i in range(self.n_emb):
            aux = self.sides.paux[self.e_host[i]]
            c = self.e_c[i]
            self.impv[c] = aux[4 * self.e_slot[i]]
            self.dissv[c] = aux[4 * self.e_slot[i] + 1]
        a = 0.0
        b = 0.0
        for s in range(self.nsub):
            if self.rigid[s]:
                continue
            aux = self.sides.paux[s]
            a += aux[self.sides.naux[s] - 2]
            if self.kind[s] == MULTIBODY:
                b += aux[self.sides.naux[s] - 1]
        self.internal_dissipated, self.internal_supplied = a, b
        if self.fresh:
            self.work_rec = np.empty(self.nc)
            self.wrv = self.work_rec
        wr = self.wrv
        for c in range(self.nc):
            wr[c] = self.wtv[c] + 0.0
        for i in range(self.n_emb):
            aux = self.sides.paux[self.e_host[i]]
            c = self.e_c[i]
            wr[c] = self.wtv[c] + aux[4 * self.e_slot[i] + 3]
        self.finite = True
        for c in range(self.nr):
            if not (isfinite(self.dv[c]) and isfinite(self.ddv[c])):
                self.finite = False

    def __dealloc__(self):
        free(self.gp)

    def side_counts(self):
        """``face_steps``: the sides' steps (rejected tries included) taken
        through their C faces; ``python_side_steps``: through their Python
        methods."""
        return {"face_steps": self.sides.n_face_steps,
                "python_side_steps": self.sides.n_python_steps}

    def start(self, double h_prev):
        """Set the length the first step's ratio is taken against [s]."""
        self.h_prev = h_prev

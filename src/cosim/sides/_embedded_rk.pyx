# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True
# cython: initializedcheck=False
"""The embedded Runge-Kutta pairs of :mod:`cosim.core.embedded_rk` (DOP853,
RK45) compiled: the same error norm, step-size control, starting step, dense
output, Illinois event location, ``max_step`` and landing on ``t1``, in the
same order of arithmetic, with no Python call per accepted step.

The numpy module stays the reference (its docstring names the algorithm and
its sources) and holds the tableaux, which :class:`_Pair` copies once.  What
is integrated is a :class:`Problem`: the multibody tree's compiled right-hand
side with its contacts' switch functions and penetration rates as events
(:class:`TreeRK`, the multibody side's adaptive steps), or ``y' = A y`` with
events ``C y`` (:func:`solve_linear`, for the tests).

A run returns to Python where the reference's would stop: at ``t1``, at a
terminal event (a switch, which the side resolves in Python: a rigid impact's
jump) or on failure.  Non-terminal events (the contacts' deepest points) are
collected in lists on the way.
"""
from libc.math cimport fabs, sqrt, pow, nextafter, INFINITY
from cpython.exc cimport PyErr_CheckSignals

import numpy as np

from cosim.sides._multibody_tree cimport TreeDynamics

cdef double EPS = 2.220446049250313e-16       # np.finfo(float).eps
cdef double TINY = 2.2250738585072014e-308    # np.finfo(float).tiny
cdef double SAFETY = 0.9
#: accepted steps between two looks at the signals (Ctrl-C, SIGTERM)
cdef int SIGNAL_POLL = 1023

_PAIRS = {}


cdef inline double _pymax(double a, double b) noexcept nogil:
    """Python's ``max(a, b)``: ``b`` only where ``b > a`` (a NaN ``b`` loses)."""
    return b if b > a else a


cdef inline double _pymin(double a, double b) noexcept nogil:
    """Python's ``min(a, b)``: ``b`` only where ``b < a``."""
    return b if b < a else a


cdef class _Pair:
    """A pair's tableau as the compiled loop reads it (from
    :data:`cosim.core.embedded_rk.PAIRS`); each stage's row keeps its
    non-zero coefficients only."""
    cdef int stages, n_all, n_dense, order, error_order
    cdef bint has_e3
    cdef double fac_min, fac_max
    cdef double[::1] c, b, e, e3
    cdef double[:, ::1] a, dense
    cdef long[:, ::1] nz           # per stage: the columns of its non-zero a
    cdef long[::1] n_nz

    def __init__(self, pair):
        cdef int i, j, k
        self.stages, self.order, self.error_order = pair.stages, pair.order, pair.error_order
        self.n_all = len(pair.c)
        self.n_dense = len(pair.dense)
        self.fac_min, self.fac_max = pair.fac_min, pair.fac_max
        self.c = np.array(pair.c, float)
        self.a = np.ascontiguousarray(pair.a, float)
        self.b = np.array(pair.b, float)
        self.e = np.array(pair.e, float)
        self.has_e3 = pair.e3 is not None
        self.e3 = np.array(pair.e3 if self.has_e3 else pair.e, float)
        self.dense = np.ascontiguousarray(pair.dense, float)
        self.nz = np.zeros((self.n_all, self.n_all), dtype=np.int_)
        self.n_nz = np.zeros(self.n_all, dtype=np.int_)
        for i in range(self.n_all):
            k = 0
            for j in range(i):
                if self.a[i, j] != 0.0:
                    self.nz[i, k] = j
                    k += 1
            self.n_nz[i] = k


def _pair(str name):
    p = _PAIRS.get(name)
    if p is None:
        from cosim.core.embedded_rk import PAIRS
        if name not in PAIRS:
            raise ValueError(f"unknown pair {name!r}; the compiled pairs are {sorted(PAIRS)}")
        p = _PAIRS[name] = _Pair(PAIRS[name])
    return p


cdef class Problem:
    """``y' = f(t, y)`` with ``m`` event functions ``g(t, y)``, in C."""
    cdef int n, m

    cdef int rhs(self, double t, const double* y, double* out) noexcept:
        return 0

    cdef void events(self, double t, const double* y, double* g) noexcept:
        pass

    cdef fail(self, double t):
        raise FloatingPointError(f"the right-hand side failed at t = {t:.6g} s")


cdef class _Linear(Problem):
    """``y' = A y``, events ``C y``."""
    cdef double[:, ::1] A, C

    def __init__(self, A, C):
        self.A = np.ascontiguousarray(A, float)
        self.C = np.ascontiguousarray(C, float)
        self.n, self.m = self.A.shape[0], self.C.shape[0]

    cdef int rhs(self, double t, const double* y, double* out) noexcept:
        cdef int i, j
        cdef double s
        for i in range(self.n):
            s = 0.0
            for j in range(self.n):
                s += self.A[i, j] * y[j]
            out[i] = s
        return 0

    cdef void events(self, double t, const double* y, double* g) noexcept:
        cdef int i, j
        cdef double s
        for i in range(self.m):
            s = 0.0
            for j in range(self.n):
                s += self.C[i, j] * y[j]
            g[i] = s


cdef class _Tree(Problem):
    """The tree's right-hand side (``TreeDynamics._rhs``, after its
    ``set_step``); events: the contacts' switch values (``n_sw`` of them:
    all or none), then the first ``n_watch`` penetration rates, as
    ``switch`` and ``penetrations`` give them."""
    cdef TreeDynamics tree
    cdef int n_sw, n_watch
    cdef double[::1] sw

    def __init__(self, TreeDynamics tree):
        self.tree = tree
        self.n = tree.ny
        self.sw = np.zeros(max(tree.nc, 1))

    cdef int rhs(self, double t, const double* y, double* out) noexcept:
        return self.tree._rhs(t, y, out, &self.sw[0])

    cdef void events(self, double t, const double* y, double* g) noexcept:
        cdef TreeDynamics tr = self.tree
        cdef int k, p, n = tr.n
        cdef double d, dd
        tr._frames(y, y + n)
        for k in range(tr.nc):
            if k >= self.n_sw and k >= self.n_watch:
                break
            p = tr.c_port[k]
            tr._point(n + p, tr.port_body[p], tr.pl_re[p], tr.pl_im[p], y + n, False)
            tr._penetration(k, t, &d, &dd)
            if k < self.n_sw:
                g[k] = tr._law_switch(k, d, dd)
            if k < self.n_watch:
                g[self.n_sw + k] = dd

    cdef fail(self, double t):
        raise FloatingPointError(f"the mass matrix is not positive definite at t = {t:.6g} s")


cdef class _Solver:
    """The integration loop of :func:`cosim.core.embedded_rk.solve` over a
    :class:`Problem`, its workspace allocated once per size."""
    cdef _Pair pair
    cdef Problem prob
    cdef int n, m
    cdef double[:, ::1] K, R
    cdef double[::1] y, y_new, abs_y, scale, ytmp, acc, g, g_new, gtmp, ye, dirs
    cdef long[::1] term, act_j
    cdef double[::1] act_t
    cdef public long nfev

    def __init__(self, _Pair pair, Problem prob):
        self.pair, self.prob = pair, prob

    cdef void _size(self, int n, int m):
        if n == self.n and m == self.m and self.K is not None:
            return
        self.n, self.m = n, m
        self.K = np.empty((self.pair.n_all, n))
        self.R = np.empty((4 + self.pair.n_dense, n))
        self.y, self.y_new, self.abs_y = np.empty(n), np.empty(n), np.empty(n)
        self.scale, self.ytmp, self.acc = np.empty(n), np.empty(n), np.empty(n)
        self.ye = np.empty(n)
        self.g, self.g_new, self.gtmp = (np.empty(max(m, 1)) for _ in range(3))
        self.dirs = np.empty(max(m, 1))
        self.term = np.empty(max(m, 1), dtype=np.int_)
        self.act_j = np.empty(max(m, 1), dtype=np.int_)
        self.act_t = np.empty(max(m, 1))

    cdef int _f(self, double t, const double* y, double* out) except -1:
        self.nfev += 1
        if self.prob.rhs(t, y, out) != 0:
            self.prob.fail(t)
            return -1
        return 0

    cdef int _stage(self, int i, double t, double h) except -1:
        """Stage ``i`` of the step ``h`` from ``(t, y)`` into ``K[i]``."""
        cdef _Pair p = self.pair
        cdef int q, j, k, n = self.n
        cdef double s
        for q in range(n):
            s = 0.0
            for k in range(p.n_nz[i]):
                j = p.nz[i, k]
                s += p.a[i, j] * self.K[j, q]
            self.ytmp[q] = self.y[q] + h * s
        return self._f(t + p.c[i] * h, &self.ytmp[0], &self.K[i, 0])

    cdef int _step(self, double t, double h) except -1:
        """Stages ``1 .. stages - 1`` (``K[0]`` given); the solution into ``y_new``."""
        cdef _Pair p = self.pair
        cdef int i, q, n = self.n
        cdef double s
        for i in range(1, p.stages):
            self._stage(i, t, h)
        for q in range(n):
            s = 0.0
            for i in range(p.stages):
                s += p.b[i] * self.K[i, q]
            self.y_new[q] = self.y[q] + h * s
        return 0

    cdef int _dense(self, double t, double h) except -1:
        """The dense output's coefficients of the step just taken (``K[stages]``
        is the slope at its end); DOP853's three extra stages."""
        cdef _Pair p = self.pair
        cdef int i, q, j, n = self.n, s = p.stages
        cdef double acc
        for i in range(s + 1, p.n_all):
            self._stage(i, t, h)
        for q in range(n):
            self.R[0, q] = self.y[q]
            self.R[1, q] = self.y_new[q] - self.y[q]
            self.R[2, q] = h * self.K[0, q] - self.R[1, q]
            self.R[3, q] = self.R[1, q] - h * self.K[s, q] - self.R[2, q]
        for i in range(p.n_dense):
            for q in range(n):
                acc = 0.0
                for j in range(p.n_all):
                    acc += p.dense[i, j] * self.K[j, q]
                self.R[4 + i, q] = acc * h
        return 0

    cdef void _at(self, double s, double* out) noexcept:
        """The dense output at the fraction ``s`` of the step."""
        cdef int q, k, nr = 4 + self.pair.n_dense
        cdef double v, s1 = 1.0 - s
        for q in range(self.n):
            v = self.R[nr - 1, q]
            for k in range(nr - 1, 0, -1):
                v = self.R[k - 1, q] + (s if k % 2 else s1) * v
            out[q] = v

    cdef double _g_at(self, int j, double tt, double t, double h):
        self._at((tt - t) / h, &self.ye[0])
        self.prob.events(tt, &self.ye[0], &self.gtmp[0])
        return self.gtmp[j]

    cdef double _locate(self, int j, double t, double h, double ta, double ga, double tb,
                        double gb, double tol):
        """:func:`cosim.core.embedded_rk.locate_root` on event ``j``'s dense output."""
        cdef double sa = 1.0 if ga > 0.0 else -1.0
        cdef double width = tb - ta, tm, gm
        cdef int since_halved = 0, side_last = 0
        while tb - ta > tol:
            if since_halved >= 3:
                tm = 0.5 * (ta + tb)
            else:
                tm = tb - gb * (tb - ta) / (gb - ga) if gb != ga else 0.5 * (ta + tb)
                if not (ta < tm and tm < tb):
                    tm = 0.5 * (ta + tb)
            gm = self._g_at(j, tm, t, h)
            if gm * sa <= 0.0:
                tb, gb = tm, gm
                if side_last == -1:
                    ga *= 0.5
                side_last = -1
            else:
                ta, ga = tm, gm
                if side_last == 1:
                    gb *= 0.5
                side_last = 1
            since_halved += 1
            if tb - ta <= 0.5 * width:
                since_halved, width = 0, tb - ta
        return tb

    cdef double _rms_scaled(self, const double* v) noexcept:
        cdef int q
        cdef double s = 0.0, x
        for q in range(self.n):
            x = v[q] / self.scale[q]
            s += x * x
        return sqrt(s / self.n)

    cdef double _initial_step(self, double t0, double t1, double rtol, double atol,
                              double max_step) except -1.0:
        cdef int q, n = self.n
        cdef double d0, d1, d2, h0, h1, big
        for q in range(n):
            self.scale[q] = atol + rtol * fabs(self.y[q])
        d0 = self._rms_scaled(&self.y[0])
        d1 = self._rms_scaled(&self.K[0, 0])
        h0 = 1e-6 if (d0 < 1e-5 or d1 < 1e-5) else 0.01 * d0 / d1
        h0 = _pymin(_pymin(h0, max_step), t1 - t0)
        for q in range(n):
            self.ytmp[q] = self.y[q] + h0 * self.K[0, q]
        self._f(t0 + h0, &self.ytmp[0], &self.acc[0])
        for q in range(n):
            self.acc[q] = self.acc[q] - self.K[0, q]
        d2 = self._rms_scaled(&self.acc[0]) / h0
        big = _pymax(d1, d2)
        h1 = _pymax(1e-6, h0 * 1e-3) if big <= 1e-15 else pow(0.01 / big, 1.0 / self.pair.order)
        return _pymin(_pymin(_pymin(100.0 * h0, h1), max_step), t1 - t0)

    def run(self, double t0, y0, double t1, double rtol, double atol, double max_step,
            direction, terminal, t_eval):
        """:func:`cosim.core.embedded_rk.solve` of the problem (events of
        ``direction`` and ``terminal``, as :class:`~cosim.core.embedded_rk.Events`
        takes them; none where empty).  Returns ``(t, y, status, message,
        t_events, y_events, y_eval)``; :attr:`nfev` counts the evaluations."""
        cdef _Pair p = self.pair
        cdef Problem prob = self.prob
        cdef int n = prob.n, m = len(direction), s = p.stages
        cdef int q, i, j, k, n_act, status = 0, n_eval = 0, n_te, steps = 0
        cdef double t = t0, h_abs, h, t_new, min_step, err, fac, h_next, x, expo, tol, tr
        cdef double q5, q3, v5, v3, t_stop
        cdef bint rejected = False, dense, up, down, at_new
        cdef double[::1] te
        cdef double[:, ::1] Yev
        yin = np.ascontiguousarray(y0, dtype=float)
        if yin.size != n:
            raise ValueError(f"`y0` must have {n} entries, got {yin.size}")
        self._size(n, m)
        prob.m = m
        self.nfev = 0
        cdef double[::1] yv = yin
        for q in range(n):
            self.y[q] = yv[q]
        te = np.ascontiguousarray(t_eval if t_eval is not None else np.empty(0), dtype=float)
        n_te = te.shape[0]
        Yev = np.empty((n_te, n))
        t_events = [[] for _ in range(m)]
        y_events = [[] for _ in range(m)]
        message = "reached the end"
        self._f(t, &self.y[0], &self.K[0, 0])
        if m:
            for j in range(m):
                self.dirs[j] = direction[j]
                self.term[j] = 1 if terminal[j] else 0
            prob.events(t, &self.y[0], &self.g[0])
            for j in range(m):
                if self.g[j] == 0.0 and self.dirs[j] != 0.0 and self.term[j]:
                    self.g[j] = -self.dirs[j] * TINY
        if not t < t1:
            return t, np.array(self.y), 0, message, t_events, y_events, np.empty((0, n))
        for q in range(n):
            self.abs_y[q] = fabs(self.y[q])
        h_abs = self._initial_step(t, t1, rtol, atol, max_step)
        expo = -1.0 / (p.error_order + 1)
        while t < t1:
            min_step = 10.0 * (nextafter(t, INFINITY) - t)
            h_abs = _pymin(h_abs, max_step)
            while True:                                   # until a step is accepted
                if not h_abs >= min_step:
                    status = -1
                    message = (f"the step size {h_abs:.3g} s fell below the spacing of "
                               f"numbers at t = {t:.17g} s (or f is not finite there)")
                    break
                t_new = t + h_abs
                if t_new >= t1 or t1 - t_new < min_step:
                    t_new = t1
                h = t_new - t
                h_abs = h
                self._step(t, h)
                for q in range(n):
                    x = fabs(self.y_new[q])
                    self.scale[q] = _pymax(x, self.abs_y[q]) * rtol + atol
                if not p.has_e3:
                    self._f(t_new, &self.y_new[0], &self.K[s, 0])
                    for q in range(n):
                        v5 = 0.0
                        for i in range(s + 1):
                            v5 += p.e[i] * self.K[i, q]
                        self.acc[q] = v5
                    err = fabs(h) * self._rms_scaled(&self.acc[0])
                else:
                    q5 = 0.0
                    q3 = 0.0
                    for q in range(n):
                        v5 = 0.0
                        v3 = 0.0
                        for i in range(s):
                            v5 += p.e[i] * self.K[i, q]
                            v3 += p.e3[i] * self.K[i, q]
                        v5 = v5 / self.scale[q]
                        v3 = v3 / self.scale[q]
                        q5 += v5 * v5
                        q3 += v3 * v3
                    err = fabs(h) * q5 / sqrt(n * (q5 + 0.01 * q3)) if q5 != 0.0 else 0.0
                if err < 1.0:
                    fac = p.fac_max if err == 0.0 else _pymin(p.fac_max, SAFETY * pow(err, expo))
                    if rejected:
                        fac = _pymin(1.0, fac)
                    h_next = h_abs * fac
                    rejected = False
                    break
                h_abs *= _pymax(p.fac_min, SAFETY * pow(err, expo))
                rejected = True
            if status == -1:
                break
            if p.has_e3:
                self._f(t_new, &self.y_new[0], &self.K[s, 0])
            t_stop = t_new
            at_new = True                  # the stop is y_new (else ye, an event's state)
            dense = False
            if m:
                prob.events(t_new, &self.y_new[0], &self.g_new[0])
                n_act = 0
                for j in range(m):
                    up = self.dirs[j] >= 0 and self.g[j] < 0.0 and self.g_new[j] >= 0.0
                    down = self.dirs[j] <= 0 and self.g[j] > 0.0 and self.g_new[j] <= 0.0
                    if up or down:
                        self.act_j[n_act] = j
                        n_act += 1
                if n_act:
                    self._dense(t, h)
                    dense = True
                    tol = 4.0 * EPS * _pymax(fabs(t), fabs(t_new)) + EPS * h
                    for k in range(n_act):
                        j = self.act_j[k]
                        self.act_t[k] = self._locate(j, t, h, t, self.g[j], t_new,
                                                     self.g_new[j], tol)
                    # sorted by (time, index): insertion sort of a handful
                    for k in range(1, n_act):
                        tr, j = self.act_t[k], self.act_j[k]
                        i = k - 1
                        while i >= 0 and (self.act_t[i] > tr
                                          or (self.act_t[i] == tr and self.act_j[i] > j)):
                            self.act_t[i + 1], self.act_j[i + 1] = self.act_t[i], self.act_j[i]
                            i -= 1
                        self.act_t[i + 1], self.act_j[i + 1] = tr, j
                    for k in range(n_act):
                        tr, j = self.act_t[k], self.act_j[k]
                        if tr == t_new:
                            ye = np.array(self.y_new)
                        else:
                            self._at((tr - t) / h, &self.ye[0])
                            ye = np.array(self.ye)
                        t_events[j].append(tr)
                        y_events[j].append(ye)
                        if self.term[j]:
                            t_stop = tr
                            at_new = tr == t_new
                            status = 1
                            message = "a terminal event occurred"
                            break
                for j in range(m):
                    self.g[j] = self.g_new[j]
            if n_eval < n_te and te[n_eval] < t_stop:
                k = n_eval
                while k < n_te and te[k] < t_stop:
                    k += 1
                if not dense:
                    self._dense(t, h)
                for i in range(n_eval, k):
                    self._at((te[i] - t) / h, &Yev[i, 0])
                n_eval = k
            if status == 1:
                # y: the event's state (ye still holds it unless it was y_new)
                if at_new:
                    for q in range(n):
                        self.y[q] = self.y_new[q]
                else:
                    self._at((t_stop - t) / h, &self.y[0])
                t = t_stop
                break
            t = t_stop
            for q in range(n):
                self.y[q] = self.y_new[q]
                self.abs_y[q] = fabs(self.y[q])
                self.K[0, q] = self.K[s, q]
            h_abs = h_next
            steps += 1
            if (steps & SIGNAL_POLL) == 0:
                PyErr_CheckSignals()
        # the samples' rows as they are: a view of this run's own array, not a copy
        return (t, np.array(self.y), status, message, t_events, y_events,
                np.asarray(Yev)[:n_eval])


cdef class TreeRK:
    """A pair integrating a tree's compiled right-hand side: what
    :meth:`cosim.core.ode.ScipyStepper.sample` and ``integrate`` run for a
    multibody side stepped by its compiled kernel (``tree``, a
    :class:`~cosim.sides._multibody_step.MultibodyStep` after its
    ``set_step``)."""
    cdef _Tree prob
    cdef dict solvers

    def __init__(self, TreeDynamics tree):
        self.prob = _Tree(tree)
        self.solvers = {}

    def run(self, str method, double t0, y0, double t1, double rtol, double atol,
            double max_step, sign, int n_watch, t_eval=None):
        """One run from ``(t0, y0)`` towards ``t1``: each contact's switch a
        terminal event away from its side ``sign`` (None: no switches), the
        first ``n_watch`` penetration rates non-terminal falling events
        (:meth:`cosim.core.ode.ScipyStepper._run`).  Returns ``(t, y,
        status, message, t_events, y_events, y_eval)``."""
        solver = self.solvers.get(method)
        if solver is None:
            solver = self.solvers[method] = _Solver(_pair(method), self.prob)
        n_sw = 0 if sign is None else len(sign)
        if n_sw and n_sw != self.prob.tree.nc or n_watch > self.prob.tree.nc:
            raise ValueError(f"{n_sw} switches and {n_watch} watched rates for a tree of "
                             f"{self.prob.tree.nc} contacts")
        self.prob.n_sw, self.prob.n_watch = n_sw, n_watch
        direction = [(-1.0 if sign[j] else 1.0) for j in range(n_sw)] + [-1.0] * n_watch
        terminal = [True] * n_sw + [False] * n_watch
        return (<_Solver>solver).run(t0, y0, t1, rtol, atol, max_step, direction, terminal,
                                     t_eval)


def solve_linear(str method, A, C, direction, terminal, double t0, y0, double t1, *,
                 double rtol, double atol, double max_step=INFINITY, t_eval=None):
    """``y' = A y`` from ``(t0, y0)`` to ``t1`` with events ``C y`` (rows),
    for the tests that hold this module to :func:`cosim.core.embedded_rk.solve`.
    Returns ``(t, y, status, message, t_events, y_events, y_eval, nfev)``."""
    solver = _Solver(_pair(method), _Linear(A, C))
    out = solver.run(t0, y0, t1, rtol, atol, max_step, list(direction), list(terminal), t_eval)
    return (*out, solver.nfev)

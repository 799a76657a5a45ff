# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True
# cython: initializedcheck=False, nonecheck=False
"""The implicit scheme's iterations of one macro step, compiled.

One call of :meth:`ImplicitStep.advance` does what
:meth:`cosim.core.schemes.implicit.Implicit.advance` does for a system
whose moving sides all step in compiled code with no contact embedded in
them, and whose coupler contacts have a linear or Kelvin-Voigt law, with or
without a grasp: restore the sides' states, step each side under the force
polynomials of the current guess (through the C face of its kernel,
:mod:`cosim.core._side_face`), read its ports, evaluate the
coupler rows' forces in the connections' current modes, test the residual
and find the next guess by Aitken relaxation or IQN-ILS
(:class:`cosim.core.schemes.implicit.Aitken`, :class:`~cosim.core.schemes.implicit.IQNILS`),
until the forces agree.  No Python object is touched inside the iterations.

It is the compiled twin of that Python reference: the same formulas in the
same order, except where the reference calls numpy's BLAS and LAPACK (the
port-force maps, the ports of a structure, the dot products, the QR
factorisations of IQN-ILS, done here by Householder reflections), whose
sums may be ordered otherwise: the two agree to round-off, which
``tests/test_implicit_kernel.py`` holds them to.
"""
from cpython.pycapsule cimport PyCapsule_GetPointer, PyCapsule_IsValid
from libc.math cimport fabs, sqrt, copysign
from libc.stdlib cimport free, malloc

from cosim.core._side_face cimport COSIM_SIDE_FACE, SideFace

import numpy as np

cdef enum:
    # contact laws of the coupler contacts (couplers.linear_laws)
    LINEAR = 0
    KELVIN_VOIGT = 1
    # the grasped mode of a connection (couplers.modes.GRASPED)
    GRASPED = 1
    # accelerations
    AITKEN = 0
    IQN_ILS = 1

#: the law kinds this kernel evaluates, by the law's ``name``
LAW_KINDS = {"linear": LINEAR, "kelvin_voigt": KELVIN_VOIGT}
#: the accelerations it runs, by name
ACCELERATION_KINDS = {"aitken": AITKEN, "iqn_ils": IQN_ILS}


cdef int _householder(double* A, int n, int m, double* beta) noexcept nogil:
    """Economy QR of ``A`` (n x m, column-major, m <= n) in place by
    Householder reflections: ``R`` strictly above the diagonal, its diagonal
    in ``beta``, and reflector ``k``'s vector ``v`` in column ``k`` from the
    diagonal down (``v_k = x_k - beta_k``, the rest the column's own
    entries), ``H_k = I + v v^T / (beta_k v_k)`` (:func:`_apply`).  A zero
    or non-finite column leaves ``beta_k`` so (0 or not finite) and no
    reflector (``v_k = 0``).  Returns 0."""
    cdef int i, j, k
    cdef double alpha, sigma, normx, b, vk, s
    for k in range(m):
        alpha = A[k * n + k]
        sigma = 0.0
        for i in range(k + 1, n):
            sigma += A[k * n + i] * A[k * n + i]
        normx = sqrt(alpha * alpha + sigma)
        if normx == 0.0 or normx != normx:
            beta[k] = normx        # 0, or not finite: the column is dropped
            A[k * n + k] = 0.0     # no reflector
            continue
        b = -copysign(normx, alpha)
        vk = alpha - b
        A[k * n + k] = vk          # v = (vk, A[k+1:, k])
        beta[k] = b
        # H x = x - v (v . x) / (-b vk)   (v . v = -2 b vk)
        for j in range(k + 1, m):
            s = 0.0
            for i in range(k, n):
                s += A[k * n + i] * A[j * n + i]
            s = s / (b * vk)
            for i in range(k, n):
                A[j * n + i] += s * A[k * n + i]
    return 0


cdef void _apply(const double* A, const double* beta, int n, int m, double* x) noexcept nogil:
    """``Q^T x`` in place, ``Q`` the reflectors :func:`_householder` left in ``A``."""
    cdef int i, k
    cdef double s, vk
    for k in range(m):
        vk = A[k * n + k]
        if vk == 0.0:
            continue
        s = 0.0
        for i in range(k, n):
            s += A[k * n + i] * x[i]
        s = s / (beta[k] * vk)
        for i in range(k, n):
            x[i] += s * A[k * n + i]


def grasp_columns(contacts, int at):
    """The grasps of ``contacts`` (item ``at`` of each entry: its stiffness,
    damping, tangential stiffness and tangential damping, or None without a
    grasp, which counts as zeros) as four arrays, one entry per contact."""
    grasps = [k[at] or (0.0, 0.0, 0.0, 0.0) for k in contacts]
    return tuple(np.array([float(g[i]) for g in grasps]) for i in range(4))


def least_squares(V, r):
    """``alpha`` minimising ``|V alpha + r|`` by the kernel's QR (``V`` n x m,
    m <= n, of full rank): what IQN-ILS solves at each iteration, for the
    tests to compare with ``numpy.linalg.lstsq``."""
    Va = np.asarray(V, dtype=float)
    ra = np.asarray(r, dtype=float)
    cdef int n = Va.shape[0], m = Va.shape[1], i, k
    if not 0 < m <= n or ra.shape != (n,):
        raise ValueError(f"`V` must be n x m with 0 < m <= n and `r` of length n, got "
                         f"{Va.shape} and {ra.shape}")
    cdef double[::1] A = np.ascontiguousarray(Va.T).ravel()
    cdef double[::1] beta = np.zeros(m)
    cdef double[::1] b = -ra
    out = np.zeros(m)
    cdef double[::1] alpha = out
    _householder(&A[0], n, m, &beta[0])
    _apply(&A[0], &beta[0], n, m, &b[0])
    _solve_r(&A[0], &beta[0], n, m, &b[0], &alpha[0])
    return out


cdef void _solve_r(const double* A, const double* beta, int n, int m, const double* c,
                   double* alpha) noexcept nogil:
    """``R alpha = c`` (first m entries) by back substitution, ``R`` the
    upper triangle of :func:`_householder`'s result (diagonal ``beta``)."""
    cdef int j, k
    cdef double s
    for k in range(m - 1, -1, -1):
        s = c[k]
        for j in range(k + 1, m):
            s -= A[j * n + k] * alpha[j]
        alpha[k] = s / beta[k]



cdef class Acceleration:
    """The next guess of a fixed-point iteration on ``n`` unknowns:
    :class:`cosim.core.schemes.implicit.Aitken` (``kind = "aitken"``) or
    :class:`~cosim.core.schemes.implicit.IQNILS` (``"iqn_ils"``, with
    ``reuse`` and ``filter_tolerance``), at most ``max_columns`` iterations
    a step.  Its Python face (:meth:`start`, :meth:`update`, :meth:`finish`)
    is the reference classes' (``start`` takes whether the columns of
    earlier steps still apply, which :meth:`IQNILS.start` decides from its
    key), for the tests to compare them; :class:`ImplicitStep` calls its C
    face."""

    # the attributes are declared in _implicit_step.pxd

    def __init__(self, str kind, int n, double relaxation, int reuse=0,
                 double filter_tolerance=1e-6, int max_columns=50):
        if kind not in ACCELERATION_KINDS:
            raise ValueError(f"`kind` must be one of {sorted(ACCELERATION_KINDS)}, got {kind!r}")
        self.kind = ACCELERATION_KINDS[kind]
        self.n = n
        self.relax = relaxation
        self.reuse = reuse if self.kind == IQN_ILS else 0
        self.filt = filter_tolerance
        self.max_cols = max(max_columns, 1)
        nq = max(n, 1)
        self.r_prev = np.zeros(nq)
        self.hx_prev = np.zeros(nq)
        self.cur_v = np.zeros((self.max_cols, nq))
        self.cur_w = np.zeros((self.max_cols, nq))
        self.old_v = np.zeros((max(self.reuse, 1), self.max_cols, nq))
        self.old_w = np.zeros((max(self.reuse, 1), self.max_cols, nq))
        self.old_n = np.zeros(max(self.reuse, 1), dtype=np.int_)
        self.n_cur = self.n_old = 0
        ncol = self.max_cols * (self.reuse + 1)
        self.col_blk = np.zeros(ncol, dtype=np.int_)
        self.col_idx = np.zeros(ncol, dtype=np.int_)
        self.qr_a = np.zeros(nq * nq)
        self.qr_beta = np.zeros(nq)
        self.qr_b = np.zeros(nq)
        self.qr_alpha = np.zeros(nq)
        self.c_start(False)

    # ------------------------------------------------------ Python face
    def start(self, bint keep_old):
        """Begin a macro step; ``keep_old``: the kept columns still apply."""
        self.c_start(keep_old)

    def update(self, z, hz, r):
        """The next guess from the guess ``z``, its image ``hz`` and the
        residual ``r = hz - z`` (a new array)."""
        out = np.array(z, dtype=float)
        cdef double[::1] zv = out
        cdef double[::1] hv = np.ascontiguousarray(hz, dtype=float)
        cdef double[::1] rv = np.ascontiguousarray(r, dtype=float)
        if zv.shape[0] != self.n or hv.shape[0] != self.n or rv.shape[0] != self.n:
            raise ValueError(f"`z`, `hz` and `r` must have {self.n} entries")
        if self.kind == IQN_ILS and self.have_prev and self.n_cur == self.max_cols:
            raise ValueError(f"more than {self.max_cols} columns in one step")
        if self.n:
            self.c_update(&zv[0], &hv[0], &rv[0])
        return out

    def finish(self):
        """The macro step converged."""
        self.c_finish()

    # ----------------------------------------------------------- C face
    cdef void c_start(self, bint keep_old) noexcept:
        self.omega = self.relax
        self.have_prev = False
        self.n_cur = 0
        if not keep_old:
            self.n_old = 0

    cdef void c_finish(self) noexcept:
        """IQN-ILS: keep this step's columns (newest first) for the next steps."""
        cdef int b, j, i, k
        if self.kind != IQN_ILS or not self.reuse or not self.n_cur:
            return
        k = self.n_old if self.n_old < self.reuse else self.reuse - 1
        for b in range(k, 0, -1):           # shift the kept blocks back by one
            self.old_n[b] = self.old_n[b - 1]
            for j in range(self.old_n[b]):
                for i in range(self.n):
                    self.old_v[b, j, i] = self.old_v[b - 1, j, i]
                    self.old_w[b, j, i] = self.old_w[b - 1, j, i]
        self.old_n[0] = self.n_cur
        for j in range(self.n_cur):
            for i in range(self.n):
                self.old_v[0, j, i] = self.cur_v[self.n_cur - 1 - j, i]
                self.old_w[0, j, i] = self.cur_w[self.n_cur - 1 - j, i]
        self.n_old = k + 1

    cdef void c_update(self, double* z, const double* hz, const double* r) noexcept:
        """The next guess into ``z`` (in: the guess), from its image ``hz``
        and the residual ``r``."""
        cdef int i
        cdef double dot_rd, denom, dr
        if self.kind == AITKEN:
            if self.have_prev:
                denom = 0.0
                dot_rd = 0.0
                for i in range(self.n):
                    dr = r[i] - self.r_prev[i]
                    denom += dr * dr
                    dot_rd += self.r_prev[i] * dr
                if denom > 0:
                    self.omega = -self.omega * dot_rd / denom
            for i in range(self.n):
                self.r_prev[i] = r[i]
                z[i] = z[i] + self.omega * r[i]
            self.have_prev = True
            return
        if self.have_prev:
            for i in range(self.n):
                self.cur_v[self.n_cur, i] = r[i] - self.r_prev[i]
                self.cur_w[self.n_cur, i] = hz[i] - self.hx_prev[i]
            self.n_cur += 1
        for i in range(self.n):
            self.r_prev[i] = r[i]
            self.hx_prev[i] = hz[i]
        self.have_prev = True
        self._iqn(z, hz, r)

    cdef double* _col(self, int j, bint w) noexcept:
        """Column ``j`` of the combined ``V`` (or ``W``), newest first."""
        cdef int b = self.col_blk[j], k = self.col_idx[j]
        if b < 0:
            return &self.cur_w[k, 0] if w else &self.cur_v[k, 0]
        return &self.old_w[b, k, 0] if w else &self.old_v[b, k, 0]

    cdef void _iqn(self, double* z, const double* hz, const double* r) noexcept:
        """:meth:`IQNILS.update` after the new column: the QR filter
        (the reference's ``_columns``), then the least-squares solve."""
        cdef int n = self.n, N = 0, m = 0, j, i, jj, bad
        cdef double* A = &self.qr_a[0]
        cdef double* beta = &self.qr_beta[0]
        cdef double* col
        cdef double norm, s
        for j in range(self.n_cur - 1, -1, -1):
            self.col_blk[N] = -1
            self.col_idx[N] = j
            N += 1
        for i in range(self.n_old):
            for j in range(self.old_n[i]):
                self.col_blk[N] = i
                self.col_idx[N] = j
                N += 1
        while N > 0:
            m = N if N < n else n
            for j in range(m):
                col = self._col(j, False)
                for i in range(n):
                    A[j * n + i] = col[i]
            _householder(A, n, m, beta)
            bad = -1
            for j in range(m):
                col = self._col(j, False)
                s = 0.0
                for i in range(n):
                    s += col[i] * col[i]
                norm = sqrt(s)
                # not (>=) also drops non-finite columns, norm == 0 zero ones
                if not (fabs(beta[j]) >= self.filt * norm) or norm == 0.0:
                    bad = j
                    break
            if bad < 0:
                break
            for jj in range(bad, N - 1):
                self.col_blk[jj] = self.col_blk[jj + 1]
                self.col_idx[jj] = self.col_idx[jj + 1]
            N -= 1
        if N == 0:
            for i in range(n):
                z[i] = z[i] + self.relax * r[i]
            return
        # A holds the QR of the kept head V[:, :m]: alpha = R^-1 Q^T (-r)
        for i in range(n):
            self.qr_b[i] = -r[i]
        _apply(A, beta, n, m, &self.qr_b[0])
        _solve_r(A, beta, n, m, &self.qr_b[0], &self.qr_alpha[0])
        for i in range(n):
            s = 0.0
            for j in range(m):
                s += self._col(j, True)[i] * self.qr_alpha[j]
            z[i] = hz[i] + s


cdef class ImplicitStep:
    """The compiled iterations of :class:`cosim.core.schemes.implicit.Implicit`
    on one system (built by :meth:`cosim.core.schemes.implicit.Implicit._compiled_iterations`).

    Parameters
    ----------
    sides : list of tuples
        Per moving side: ``(kernel, x, aux, G, first)``: its
        kernel (its ``side_face()``, :mod:`cosim.core._side_face`), its state and
        quadratures (arrays stepped in place), its port-force map of the
        exchanged rows ``(2 n_p, n_rows)`` and the index of its first port
        among all ports.
    pos, vel : (n_ports, 2) arrays
        Every subsystem's ports (the rigid ones are read from here).
    contacts : list of tuples
        Per coupler contact: ``(c, port_a, port_b, normal, offset, kind, k,
        c_damping, tangent_row, grasp)`` with ``grasp`` None or ``(k, c,
        k_t, c_t)``.
    rows : (n_q,) int array
        The coupler rows, as the residual orders them.
    n_rows : int
    mode, anchor : arrays
        The connections' modes and anchors (read at each call), or None.
    options : dict
        ``max_iterations``, ``tolerance``, ``force_tolerance``, ``acceleration``,
        ``relaxation``, ``reuse``, ``filter_tolerance``, ``roundoff``.
    """

    # the attributes are declared in _implicit_step.pxd

    def __init__(self, sides, pos, vel, contacts, rows, int n_rows, mode, anchor, options):
        cdef int s, i
        self.ns = len(sides)
        # the kernels are kept: their faces point into them
        self.kernels = [sd[0] for sd in sides]
        self.faces = <SideFace*> malloc(max(self.ns, 1) * sizeof(SideFace))
        if self.faces == NULL:
            raise MemoryError()
        for s in range(self.ns):
            cap = self.kernels[s].side_face()
            if not PyCapsule_IsValid(cap, COSIM_SIDE_FACE):
                raise TypeError(f"{type(self.kernels[s]).__name__}.side_face() is not a "
                                f"capsule of the C face")
            self.faces[s] = (<SideFace*> PyCapsule_GetPointer(cap, COSIM_SIDE_FACE))[0]
        self.xs = [sd[1] for sd in sides]
        self.auxs = [sd[2] for sd in sides]
        self.s_nx = np.array([self.faces[s].nx for s in range(self.ns)], dtype=np.int_)
        self.s_na = np.array([self.faces[s].naux for s in range(self.ns)], dtype=np.int_)
        self.s_np = np.array([self.faces[s].nports for s in range(self.ns)], dtype=np.int_)
        self.s_first = np.array([sd[4] for sd in sides], dtype=np.int_)
        for s in range(self.ns):
            if np.asarray(self.xs[s]).shape != (self.s_nx[s],) or \
                    np.asarray(self.auxs[s]).shape[0] < self.s_na[s]:
                raise ValueError(f"side {s}: state or quadratures of the wrong size")
        self.maxp = max([1] + [int(n) for n in self.s_np])
        self.saved_x = np.zeros((self.ns, max([1] + [int(n) for n in self.s_nx])))
        self.saved_aux = np.zeros((self.ns, max([1] + [int(n) for n in self.s_na])))
        self.n_rows = n_rows
        G = np.zeros((self.ns, 2 * self.maxp, n_rows))
        for s in range(self.ns):
            g = np.asarray(sides[s][3], float)
            if g.shape != (2 * self.s_np[s], n_rows):
                raise ValueError(f"side {s}: the port-force map must be "
                                 f"({2 * self.s_np[s]}, {n_rows}), got {g.shape}")
            G[s, :g.shape[0], :] = g
        self.G = G
        self.u = np.zeros((self.ns, 4 * self.maxp))
        self.pm = np.zeros((self.ns, 6 * self.maxp))
        self.pos = np.ascontiguousarray(pos, dtype=float).ravel().copy()
        self.vel = np.ascontiguousarray(vel, dtype=float).ravel().copy()
        self.ncc = len(contacts)
        self.k_c = np.array([c[0] for c in contacts], dtype=np.int_)
        self.k_a = np.array([c[1] for c in contacts], dtype=np.int_)
        self.k_b = np.array([c[2] for c in contacts], dtype=np.int_)
        self.k_nx = np.array([float(c[3][0]) for c in contacts])
        self.k_ny = np.array([float(c[3][1]) for c in contacts])
        self.k_off = np.array([float(c[4]) for c in contacts])
        self.k_kind = np.array([c[5] for c in contacts], dtype=np.int_)
        self.k_k = np.array([float(c[6]) for c in contacts])
        self.k_cd = np.array([float(c[7]) for c in contacts])
        self.k_trow = np.array([c[8] for c in contacts], dtype=np.int_)
        self.k_grasp = np.array([c[9] is not None for c in contacts], dtype=np.int_)
        self.g_k, self.g_c, self.g_kt, self.g_ct = grasp_columns(contacts, 9)
        self.mode = mode if mode is not None else np.zeros(1, dtype=np.longlong)
        self.anchor = anchor if anchor is not None else np.zeros(1)
        self.rows = np.ascontiguousarray(rows, dtype=np.int_)
        self.nq = self.rows.shape[0]
        nq = max(self.nq, 1)
        self.max_it = options["max_iterations"]
        self.tol = options["tolerance"]
        self.ftol = options["force_tolerance"]
        self.roundoff = options["roundoff"]
        self.acc = Acceleration(options["acceleration"], self.nq, options["relaxation"],
                                options.get("reuse", 0), options.get("filter_tolerance", 1e-6),
                                self.max_it)
        self.f = np.zeros(max(n_rows, 1))
        self.coef1 = np.zeros(max(n_rows, 1))
        self.z = np.zeros(nq)
        self.hz = np.zeros(nq)
        self.r = np.zeros(nq)
        self.have_key, self.key_h = False, 0.0
        self.key_closed = np.zeros(nq, dtype=np.int_)
        self.failed_side = -1

    def __dealloc__(self):
        free(self.faces)

    # ------------------------------------------------------------ results
    @property
    def residual(self):
        """The last iteration's residual ``H(x) - x`` of the coupler rows [N]."""
        return np.array(self.r[:self.nq])

    def port_moments(self, int s):
        """Side ``s``'s port velocity moments of the last pass, ``(3, n_p)`` complex."""
        cdef int i, n = self.s_np[s]
        out = np.empty((3, n), dtype=complex)
        cdef double[::1] ov = out.reshape(-1).view(float)
        for i in range(6 * n):
            ov[i] = self.pm[s, i]
        return out

    def row_forces(self, pos, vel):
        """The coupler rows' forces [N] (``(n_rows,)``, the other rows 0) at
        the ports' positions and velocities ``pos``, ``vel`` (every
        subsystem's, ``(n_ports, 2)``) in the connections' current modes:
        what :meth:`cosim.core.system.CoupledSystem.forces` gives them, for
        the tests to compare."""
        p = np.ascontiguousarray(pos, dtype=float).ravel()
        v = np.ascontiguousarray(vel, dtype=float).ravel()
        if p.shape[0] != self.pos.shape[0] or v.shape[0] != self.vel.shape[0]:
            raise ValueError(f"`pos` and `vel` must hold {self.pos.shape[0] // 2} ports")
        at, rate, f = np.asarray(self.pos), np.asarray(self.vel), np.asarray(self.f)
        kept = at.copy(), rate.copy()
        at[:], rate[:], f[:] = p, v, 0.0
        self._forces()
        at[:], rate[:] = kept       # the rigid sides' ports are read from here
        return f[:self.n_rows].copy()

    # ------------------------------------------------------------ the step
    def advance(self, double t, double h, double[::1] f_n, co):
        """Iterate the macro step ``[t, t + h]`` from the forces ``f_n`` at
        ``t`` (n_rows) and their extrapolation over the step ``co`` (rows of
        polynomial coefficients, (k, n_rows)), whose sum is the first guess
        of the forces at ``t + h`` (as ``numpy.sum(co, axis=0)``).  IQN-ILS
        keeps the columns of earlier steps at the same step length and the
        same closed coupler rows (:meth:`IQNILS.start`).

        Returns ``(iterations, converged, guess, impulse, coeffs,
        moments)``: the last guess (n_rows), the impulse
        ``h (f_n + (guess - f_n) / 2)`` [N s] the step applied, its force
        polynomials ``[f_n, guess - f_n]`` (2, n_rows) and each side's port
        velocity moments ((3, n_p) complex), all new arrays."""
        cdef int s, r, it, n = self.n_rows
        cdef double[:, :] cv = co
        if f_n.shape[0] != n or cv.shape[1] != n or cv.shape[0] < 1:
            raise ValueError(f"`f_n` must have {n} entries and `co` (k >= 1, {n})")
        guess_a = np.empty(n)
        cdef double[::1] guess = guess_a
        it = self.c_advance(t, h, f_n, cv, guess)
        impulse_a = np.empty(n)
        coeffs_a = np.empty((2, n))
        cdef double[::1] impulse = impulse_a
        cdef double[:, ::1] coeffs = coeffs_a
        for r in range(n):
            coeffs[0, r] = f_n[r]
            coeffs[1, r] = guess[r] - f_n[r]
            impulse[r] = h * (f_n[r] + 0.5 * (guess[r] - f_n[r]))
        moments = [self.port_moments(s) for s in range(self.ns)]
        return it, bool(self.converged), guess_a, impulse_a, coeffs_a, moments

    cdef int c_advance(self, double t, double h, double[::1] f_n, double[:, :] cv,
                       double[::1] guess) except -1:
        """:meth:`advance`'s iterations: the last guess into ``guess``
        (n_rows), whether they converged into ``converged``, each side's port
        moments in ``pm``; returns the iterations taken."""
        cdef int s, i, r, it, n = self.n_rows
        cdef double[::1] xv, av
        cdef bint keep
        self.converged = 0
        for r in range(n):                  # numpy's sum over rows: one row after another
            guess[r] = cv[0, r]
            for i in range(1, cv.shape[0]):
                guess[r] += cv[i, r]
        keep = self.have_key and fabs(h - self.key_h) <= 1e-9 * max(fabs(h), fabs(self.key_h))
        for i in range(self.nq):
            if keep and (f_n[self.rows[i]] > 0) != self.key_closed[i]:
                keep = False
            self.key_closed[i] = f_n[self.rows[i]] > 0
        self.have_key, self.key_h = True, h
        for s in range(self.ns):
            xv = self.xs[s]
            av = self.auxs[s]
            for i in range(self.s_nx[s]):
                self.saved_x[s, i] = xv[i]
            for i in range(self.s_na[s]):
                self.saved_aux[s, i] = av[i]
        self.acc.c_start(keep)
        for it in range(1, self.max_it + 1):
            if it > 1:
                for s in range(self.ns):
                    xv = self.xs[s]
                    av = self.auxs[s]
                    for i in range(self.s_nx[s]):
                        xv[i] = self.saved_x[s, i]
                    for i in range(self.s_na[s]):
                        av[i] = self.saved_aux[s, i]
            self._pass(t, h, f_n, guess)
            self._forces()
            if self._residual(guess):
                self.acc.c_finish()
                self.converged = 1
                break
            self.acc.c_update(&self.z[0], &self.hz[0], &self.r[0])
            for i in range(self.nq):
                guess[self.rows[i]] = self.z[i]
        return it

    cdef int _pass(self, double t, double h, double[::1] f_n, double[::1] guess) except -1:
        """Step every side under ``[f_n, guess - f_n]`` and read its ports."""
        cdef int s, q, r, j, npt
        cdef double a, b
        cdef double[::1] xv, av
        for r in range(self.n_rows):
            self.coef1[r] = guess[r] - f_n[r]
        for s in range(self.ns):
            npt = self.s_np[s]
            # port forces: G @ coefficients, per coefficient row
            for q in range(2 * npt):
                a = 0.0
                b = 0.0
                for r in range(self.n_rows):
                    a += self.G[s, q, r] * f_n[r]
                    b += self.G[s, q, r] * self.coef1[r]
                self.u[s, q] = a
                self.u[s, 2 * npt + q] = b
            xv = self.xs[s]
            av = self.auxs[s]
            self.failed_side = s
            self.faces[s].step(self.faces[s].side, t, h, &self.u[s, 0], 2, &xv[0],
                               &av[0] if av.shape[0] else NULL, &self.pm[s, 0])
            self.failed_side = -1
            j = 2 * self.s_first[s]
            self.faces[s].outputs(self.faces[s].side, &xv[0], &self.pos[j], &self.vel[j])
        return 0

    cdef void _forces(self) noexcept:
        """The coupler contacts' row forces (:meth:`CoupledSystem.forces`)."""
        cdef int i, c, a, b, tr
        cdef double dx0, dx1, dv0, dv1, nx, ny, d, dd, e, de, fa, sw
        for i in range(self.ncc):
            c = self.k_c[i]
            a = 2 * self.k_a[i]
            b = 2 * self.k_b[i]
            nx = self.k_nx[i]
            ny = self.k_ny[i]
            dx0 = self.pos[a] - self.pos[b]
            dx1 = self.pos[a + 1] - self.pos[b + 1]
            dv0 = self.vel[a] - self.vel[b]
            dv1 = self.vel[a + 1] - self.vel[b + 1]
            d = self.k_off[i] - (dx0 * nx + dx1 * ny)
            dd = -(dv0 * nx + dv1 * ny)
            tr = self.k_trow[i]
            if self.k_grasp[i] and self.mode[c] == GRASPED:
                # t = (-n_y, n_x); e from the anchor
                e = (dx0 * -ny + dx1 * nx) - self.anchor[c]
                de = dv0 * -ny + dv1 * nx
                self.f[c] = self.g_k[i] * d + self.g_c[i] * dd
                self.f[tr] = -(self.g_kt[i] * e + self.g_ct[i] * de)
                continue
            if self.k_kind[i] == LINEAR:
                fa = self.k_k[i] * d
                sw = d
            else:
                fa = self.k_k[i] * d + self.k_cd[i] * dd
                sw = d + (self.k_cd[i] / self.k_k[i]) * dd
                if d < sw:
                    sw = d
            self.f[c] = (fa if fa > 0.0 else 0.0) if sw > 0.0 else 0.0
            if tr >= 0:
                self.f[tr] = 0.0

    cdef bint _residual(self, double[::1] guess) noexcept:
        """``z``, ``hz``, ``r`` of the coupler rows; True when converged."""
        cdef int i
        cdef double scale, fl, az, ahz
        cdef bint ok = True
        for i in range(self.nq):
            self.z[i] = guess[self.rows[i]]
            self.hz[i] = self.f[self.rows[i]]
            self.r[i] = self.hz[i] - self.z[i]
            az = fabs(self.z[i])
            ahz = fabs(self.hz[i])
            scale = ahz if ahz >= az else az
            fl = self.roundoff * scale
            if not (fabs(self.r[i]) <= self.ftol + self.tol * scale + fl):
                ok = False
        return ok

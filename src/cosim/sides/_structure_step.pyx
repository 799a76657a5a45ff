# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True
# cython: initializedcheck=False, nonecheck=False
"""The structure side's step, compiled.

One call advances an undamped linear structure in its kept modes over a macro
step in closed form: each phase between switches of its hosted linear springs
is a linear system under a polynomial load, stepped exactly in the modes of
that phase; touch and release are located on the exact solution (sampled,
then safeguarded Newton; a phase with every spring open is not sampled where
a bound of the exact solution proves none can close in it); the springs'
impulses, first moments and work and the ports' velocity moments are
integrated in closed form; each closed
spring's largest penetration over a segment is located on the exact solution
where its rate falls through zero (Illinois regula falsi), and raises the
host's ``peak``.  A structure that
hosts no contact is stepped exactly under the port loads, its velocity
moments by three-point Gauss-Legendre.  It is the compiled twin of the numpy
reference in :mod:`cosim.sides.fem` (:meth:`StructureSubsystem._step_closed_form`
and the open exact step) and :mod:`fem.response`: the same formulas in the
same order, so the two agree to round-off, which
``tests/test_kernel_structure.py`` holds them to.

The modes of each set of closed springs (an eigen-decomposition) are asked of
the host once (``basis(active)``, LAPACK or the rank-one update there) and
kept here, so no Python object is touched inside a step except on that rare
event and to hand back the located switches.

Arrays shared with the host (read at each step, so the host may change them
in place between steps, as a contact that follows a moving point does): the
ports' shape rows ``R`` (n_p, m), reference positions ``ref`` (n_p, 2) and,
given per port, directions ``dirs`` (n_p, 2).  After changing ``R`` or
``dirs`` the host calls :meth:`StructureStep.forget_bases`; a hosted
contact's normal it changes with :meth:`StructureStep.set_normal`.
"""
from libc.math cimport sin, cos, pow, ceil, fabs, sqrt, hypot, copysign, isfinite, INFINITY
from libc.float cimport DBL_EPSILON

from cpython.pycapsule cimport PyCapsule_New

from cosim.core._side_face cimport COSIM_SIDE_FACE, SideFace

import numpy as np

#: the interface the host (:mod:`cosim.sides.fem`, its ``STEP_API``) calls:
#: bumped when a call changes (2: ``StructureStep.step`` takes ``peak``; 3:
#: ``direction`` may be given per port, and ``set_normal``)
STEP_API = 3


#: segments (contact switches) one step may take before it is said to stall
MAX_SEGMENTS = 10000


class StalledStep(RuntimeError):
    """The compiled step stopped advancing (a switch found again and again at
    one instant); the host redoes the step with the numpy reference."""

cdef enum:
    # rows of a load polynomial (degree <= 3) and of a partner's motion
    DEG1 = 4
    # sets of closed springs whose modes are kept
    MAX_BASES = 8
    # terms of the power series of the trigonometric moments
    SERIES_TERMS = 12
    # most contacts one structure hosts in the kernel
    MAX_CONTACTS = 62

#: below this omega L, the moments of cos and sin are summed as power series
#: (as :mod:`fem.response`)
cdef double SERIES_BELOW = 1.0

#: Gauss-Legendre nodes and weights on [0, 1] (as the reference's ``_GAUSS``)
cdef double[3] GAUSS_NODES = [0.5 - sqrt(15.0) / 10, 0.5, 0.5 + sqrt(15.0) / 10]
cdef double[3] GAUSS_WEIGHTS = [5.0 / 18.0, 8.0 / 18.0, 5.0 / 18.0]

cdef double _comb(int n, int k) noexcept nogil:
    cdef double c = 1.0
    cdef int i
    for i in range(k):
        c = c * (n - i) / (i + 1)
    return c


cdef int _secular(int n, const double* d, const double* z, double* lam, double* V,
                  int max_iterations, double* work) noexcept nogil:
    """Roots and eigenvectors of ``diag(d) + z z^T`` for sorted, distinct ``d``
    and non-zero ``z`` (:func:`fem.rank_one._secular`, each root iterated on
    its own as the reference iterates its rows): ``lam`` (n), ``V`` (n, n)
    row-major, columns the eigenvectors.  ``work`` holds 2 n^2 + 8 n doubles.
    Returns -1 where the reference returns None."""
    cdef double* G = work                   # (n, n): d_j - d_origin(i)
    cdef double* delta = work + n * n       # (n, n)
    cdef double* z2 = work + 2 * n * n
    cdef double* tau = z2 + n
    cdef double* lo = tau + n
    cdef double* hi = lo + n
    cdef double* kd = hi + n                # d at each root's origin
    cdef double* zhat = kd + n
    cdef double* fm = zhat + n
    cdef double* nrm = fm + n
    cdef int i, j, it, r, kk, ac, bc, left_done
    cdef double mid, f, t, T, T2, psi, dpsi, tot, dtot, phi, dphi, lo_r, hi_r, a, b
    cdef double s_, p_, S_, q_, C, B2, C2, root, qq, r1, r2, eta, new, prod, x, den
    cdef bint go, narrow, bad
    for j in range(n):
        z2[j] = z[j] * z[j]
    if n == 1:
        lam[0] = d[0] + z2[0]
        V[0] = 1.0
        return 0
    for i in range(n):
        if i < n - 1:
            mid = 0.5 * (d[i] + d[i + 1])
            f = 1.0
            for j in range(n):
                f += z2[j] / (d[j] - mid)
            if f < 0.0:                     # root in (mid, d_{i+1})
                kd[i] = d[i + 1]
                lo[i] = mid - d[i + 1]
                hi[i] = 0.0
                fm[i] = i + 1
            else:
                kd[i] = d[i]
                lo[i] = 0.0
                hi[i] = mid - d[i]
                fm[i] = i
        else:
            kd[i] = d[i]
            fm[i] = i
            lo[i] = 0.0
            hi[i] = 0.0
            for j in range(n):
                hi[i] += z2[j]
        for j in range(n):
            G[i * n + j] = d[j] - kd[i]
        tau[i] = 0.5 * (lo[i] + hi[i])
    for r in range(n):
        ac = r
        bc = r + 1 if r + 1 < n else n - 1
        for it in range(max_iterations + 1):
            if it == max_iterations:
                return -1
            t = tau[r]
            psi = 0.0
            dpsi = 0.0
            tot = 0.0
            dtot = 0.0
            for j in range(n):
                x = G[r * n + j] - t
                delta[r * n + j] = x
                T = z2[j] / x
                T2 = T / x
                tot += T
                dtot += T2
                if j <= r:
                    psi += T
                    dpsi += T2
            phi = tot - psi
            dphi = dtot - dpsi
            f = 1.0 + psi + phi
            go = fabs(f) > 8.0 * DBL_EPSILON * (1.0 + fabs(psi) + fabs(phi))
            lo_r = t if f < 0.0 else lo[r]
            hi_r = t if f > 0.0 else hi[r]
            a = delta[r * n + ac]
            b = delta[r * n + bc]
            s_ = dpsi * a * a
            p_ = psi - dpsi * a
            S_ = dphi * b * b
            q_ = phi - dphi * b
            C = 1.0 + p_ + q_
            B2 = -(C * (a + b) + s_ + S_)
            C2 = C * a * b + s_ * b + S_ * a
            x = B2 * B2 - 4.0 * C * C2
            root = sqrt(x if x > 0.0 else 0.0)
            qq = -0.5 * (B2 + copysign(root, B2))
            r1 = qq / C
            r2 = C2 / qq
            eta = r1 if (r1 > a and r1 < b) else r2
            if r == n - 1:
                eta = a + s_ / (1.0 + p_)
            new = t + eta
            bad = not isfinite(new) or new <= lo_r or new >= hi_r
            if bad:
                new = 0.5 * (lo_r + hi_r)
            narrow = fabs(hi_r - lo_r) <= 4.0 * DBL_EPSILON * (
                fabs(lo_r) if fabs(lo_r) > fabs(hi_r) else fabs(hi_r))
            tau[r] = new if go else t
            lo[r] = lo_r
            hi[r] = hi_r
            if not go or narrow:
                break
    for i in range(n):
        for j in range(n):
            delta[i * n + j] = G[i * n + j] - tau[i]
        lam[i] = kd[i] + tau[i]
    # Loewner: the z for which the computed roots are exact
    for j in range(n):
        prod = 1.0
        for kk in range(n - 1):
            if kk < j:
                den = d[kk] - d[j]
            else:
                den = d[kk + 1 if kk + 1 < n else n - 1] - d[j]
            prod *= -delta[kk * n + j] / den
        x = -delta[(n - 1) * n + j] * prod
        if not isfinite(x) or x < 0.0:
            return -1
        zhat[j] = copysign(sqrt(x), z[j])
    for i in range(n):
        nrm[i] = 0.0
        for j in range(n):
            x = zhat[j] / delta[i * n + j]
            V[j * n + i] = x
            nrm[i] += x * x
        nrm[i] = sqrt(nrm[i])
    for j in range(n):
        for i in range(n):
            V[j * n + i] /= nrm[i]
    return 0


def rank_one_eigh(d, z, int max_iterations=50):
    """:func:`fem.rank_one.rank_one_eigh` compiled: ``(lam, V)`` of
    ``diag(d) + z z^T``, or None where the reference declines."""
    cdef int m = len(d)
    ws = np.empty(3 * m * m + 20 * m)
    lam = np.empty(m)
    V = np.empty((m, m))
    cdef double[::1] dv = np.ascontiguousarray(d, dtype=float)
    cdef double[::1] zv = np.ascontiguousarray(z, dtype=float)
    if zv.shape[0] != m:
        raise ValueError(f"`z` must have shape ({m},), got {np.shape(z)}")
    cdef double[::1] w = ws, lv = lam
    cdef double[:, ::1] Vv = V
    if _rank_one(m, &dv[0], &zv[0], &lv[0], &Vv[0, 0], max_iterations, &w[0]):
        return None
    return lam, V


cdef int _rank_one(int m, const double* d, const double* z, double* lam, double* out,
                   int max_iterations, double* work) noexcept nogil:
    """:func:`fem.rank_one.rank_one_eigh` into ``lam`` (m) and ``out`` (m, m)
    row-major; -1 where the reference returns None.  ``work``: 3 m^2 + 20 m."""
    cdef double* ds = work
    cdef double* zs = work + m
    cdef double* order = work + 2 * m        # the sorting permutation (as doubles)
    cdef double* dk = work + 3 * m
    cdef double* zk = work + 4 * m
    cdef double* lk = work + 5 * m
    cdef double* Vk = work + 6 * m           # (n, n)
    cdef double* sec = Vk + m * m            # _secular's 2 n^2 + 8 n
    cdef int* idx = <int*> (sec + 2 * m * m + 8 * m)    # m ints in 2 m doubles' room
    # the rotations of _deflate_close: pairs (i, j) as doubles, c, s
    cdef double* rot = sec + 2 * m * m + 10 * m         # (m, 4)
    cdef int i, j, n, a, b, nrot = 0, ri, rj
    cdef double z2sum = 0.0, dmax = 0.0, tol, x, r, c, s_, di, vi, vj
    # stable argsort of d (insertion sort: once per new set of closed springs)
    for i in range(m):
        j = i
        while j > 0 and d[<int> order[j - 1]] > d[i]:
            order[j] = order[j - 1]
            j -= 1
        order[j] = i
    for i in range(m):
        ds[i] = d[<int> order[i]]
        zs[i] = z[<int> order[i]]
        z2sum += zs[i] * zs[i]
        if fabs(ds[i]) > dmax:
            dmax = fabs(ds[i])
    for i in range(m):
        for j in range(m):
            out[i * m + j] = 0.0
    tol = 8.0 * DBL_EPSILON * (dmax if dmax > z2sum else z2sum)
    n = 0
    x = sqrt(z2sum)
    for i in range(m):
        if fabs(zs[i]) * x > tol:
            if n > 0:
                # _deflate_close: the last kept entry against this one
                a = idx[n - 1]
                r = hypot(zs[a], zs[i])
                c = zs[i] / r
                s_ = zs[a] / r
                if fabs((ds[i] - ds[a]) * c * s_) <= tol:
                    # c^2 d_a + s^2 d_i and s^2 d_a + c^2 d_i, exact where equal
                    di = s_ * s_ * (ds[i] - ds[a])
                    ds[a] = ds[a] + di
                    ds[i] = ds[i] - di
                    zs[a] = 0.0
                    zs[i] = r
                    rot[4 * nrot] = a
                    rot[4 * nrot + 1] = i
                    rot[4 * nrot + 2] = c
                    rot[4 * nrot + 3] = s_
                    nrot += 1
                    idx[n - 1] = i
                    continue
            idx[n] = i
            n += 1
    for a in range(n):
        dk[a] = ds[idx[a]]
        zk[a] = zs[idx[a]]
    if n and _secular(n, dk, zk, lk, Vk, max_iterations, sec):
        return -1
    for i in range(m):
        lam[i] = ds[i]
    # V = I with the kept block replaced; rows back in the original order
    for i in range(m):
        out[(<int> order[i]) * m + i] = 1.0
    for a in range(n):
        lam[idx[a]] = lk[a]
        out[(<int> order[idx[a]]) * m + idx[a]] = 0.0
    for a in range(n):
        for b in range(n):
            out[(<int> order[idx[a]]) * m + idx[b]] = Vk[a * n + b]
    # the rotations undone, last first: rows i, j <- (c v_i + s v_j, c v_j - s v_i)
    for a in range(nrot - 1, -1, -1):
        ri = <int> order[<int> rot[4 * a]]
        rj = <int> order[<int> rot[4 * a + 1]]
        c = rot[4 * a + 2]
        s_ = rot[4 * a + 3]
        for b in range(m):
            vi = out[ri * m + b]
            vj = out[rj * m + b]
            out[ri * m + b] = c * vi + s_ * vj
            out[rj * m + b] = c * vj - s_ * vi
    return 0


cdef class StructureStep:
    """Compiled step of one :class:`cosim.sides.fem.StructureSubsystem`.

    Parameters
    ----------
    omega : (m,) array
        Circular frequencies of the kept modes [rad/s] (undamped).
    R : (n_p, m) array
        The ports' shape rows, shared (see the module).
    ref : (n_p, 2) array
        The ports' reference positions [m], shared.
    direction : (2,) or (n_p, 2) array
        The field's direction, or each port's, shared (a plane body's ports
        move along their segments' normals).
    g_modal : (m,) array
        The weight's modal load.
    contacts : list of tuples
        Per hosted contact, a linear spring: ``(port, side, normal (complex),
        offset [m], contact_stiffness [N/m])``.
    basis : callable
        ``basis(active) -> (lam, Psi or None, omega_max)``: the modes of the
        modal equations with the springs of the closed contacts ``active``
        (a tuple of bools) added; ``Psi`` None for the structure's own modes.
    """

    cdef int m, np_, nc
    cdef double[:, ::1] R, ref
    cdef double[:, ::1] dirs                # each port's direction, shared
    cdef double[::1] lam0, g_modal
    cdef double wmax0
    cdef long[::1] c_port
    cdef double[::1] c_side, c_nre, c_nim, c_off, c_k
    cdef object host_basis
    # the step
    cdef double t, h
    cdef int g_len
    cdef bint loaded
    cdef double[:, ::1] Gin                 # (DEG1, m) in s = (time - t) / h
    cdef long[::1] m_len, dm_len
    cdef double[::1] m_t0, m_h
    cdef double[:, ::1] m_re, m_im, dm_re, dm_im     # (nc, DEG1 + 1)
    # kept bases
    cdef int n_bases, next_base
    cdef long long[::1] b_mask
    cdef long[::1] b_ident
    cdef double[::1] b_wmax
    cdef double[:, ::1] b_lam               # (MAX_BASES, m)
    cdef double[:, :, ::1] b_psi            # (MAX_BASES, m, m)
    cdef double[:, :, ::1] b_P              # (MAX_BASES, m, n_p): Psi^T R^T
    # the segment: its modes' start, load, and the split of the response
    cdef double[::1] q, dq, z0, dz0, zt, dzt
    cdef double[:, ::1] a, aS               # (DEG1, m)
    cdef long[::1] rigid
    cdef double[::1] om, b0, b1, b2, b3, A, B
    cdef double[:, ::1] C, S                # trig moments (DEG1, m)
    cdef double[:, ::1] Wm                  # (DEG1, n_p)
    cdef double[::1] W, DW, W0, WL, d0, dd0, dprev, ddprev, dcur, ddcur, seg_peak
    # the rank-one update of one closed spring: workspace, z, lam, V
    cdef double[::1] r1_work, r1_z, r1_lam, r1_V
    cdef long[::1] active
    #: segments stepped so far (closed-form phases)
    cdef public long n_segments
    #: bases asked of the host (several springs closed, or the rank-one
    #: update declined)
    cdef public long n_host_bases
    #: segments with every contact open that a bound proved stay open, so
    #: stepped without probes (see :meth:`_stays_open`)
    cdef public long n_unprobed
    #: whether :meth:`_stays_open` may spare a segment its probes (the
    #: host's ``bound_open``; False probes every segment)
    cdef public bint bound_open
    # the C face (cosim.core._side_face)
    cdef SideFace face

    def __init__(self, omega, R, ref, direction, g_modal, contacts, basis):
        cdef int m = len(omega)
        self.m = m
        self.R = R
        self.ref = ref
        self.np_ = self.R.shape[0]
        if self.R.shape[1] != m or self.ref.shape[0] != self.np_:
            raise ValueError(f"`R` must have shape (n_ports, {m}) and `ref` (n_ports, 2), "
                             f"got {np.shape(R)} and {np.shape(ref)}")
        self.nc = len(contacts)
        if self.nc > MAX_CONTACTS:
            raise ValueError(f"the kernel hosts at most {MAX_CONTACTS} contacts per "
                             f"structure, got {self.nc}")
        dirs = np.asarray(direction, dtype=float)
        if dirs.shape == (2,):
            dirs = np.tile(dirs, (self.np_, 1))
        if dirs.shape != (self.np_, 2):
            raise ValueError(f"`direction` must have shape (2,) or (n_ports, 2), got "
                             f"{np.shape(direction)}")
        self.dirs = dirs if self.np_ else np.zeros((1, 2))
        self.lam0 = np.ascontiguousarray(np.asarray(omega, float) ** 2)
        self.wmax0 = float(np.max(omega, initial=0.0))
        self.g_modal = np.ascontiguousarray(g_modal, dtype=float)
        nc = max(self.nc, 1)
        self.c_port = np.array([c[0] for c in contacts] or [0], dtype=np.int_)
        self.c_side = np.array([c[1] for c in contacts] or [0.0])
        self.c_nre = np.array([complex(c[2]).real for c in contacts] or [0.0])
        self.c_nim = np.array([complex(c[2]).imag for c in contacts] or [0.0])
        self.c_off = np.array([c[3] for c in contacts] or [0.0])
        self.c_k = np.array([c[4] for c in contacts] or [0.0])
        self.host_basis = basis
        self.t, self.h, self.g_len, self.loaded = 0.0, 1.0, 1, False
        self.Gin = np.zeros((DEG1, m))
        self.m_len = np.ones(nc, dtype=np.int_)
        self.dm_len = np.ones(nc, dtype=np.int_)
        self.m_t0 = np.zeros(nc)
        self.m_h = np.ones(nc)
        self.m_re = np.zeros((nc, DEG1 + 1))
        self.m_im = np.zeros((nc, DEG1 + 1))
        self.dm_re = np.zeros((nc, DEG1 + 1))
        self.dm_im = np.zeros((nc, DEG1 + 1))
        self.n_bases, self.next_base = 0, 0
        self.b_mask = np.zeros(MAX_BASES, dtype=np.longlong)
        self.b_ident = np.zeros(MAX_BASES, dtype=np.int_)
        self.b_wmax = np.zeros(MAX_BASES)
        self.b_lam = np.zeros((MAX_BASES, m))
        self.b_psi = np.zeros((MAX_BASES, m, m))
        self.b_P = np.zeros((MAX_BASES, m, max(self.np_, 1)))
        self.q = np.zeros(m); self.dq = np.zeros(m)
        self.z0 = np.zeros(m); self.dz0 = np.zeros(m)
        self.zt = np.zeros(m); self.dzt = np.zeros(m)
        self.om = np.zeros(m); self.b0 = np.zeros(m); self.b1 = np.zeros(m)
        self.b2 = np.zeros(m); self.b3 = np.zeros(m); self.A = np.zeros(m); self.B = np.zeros(m)
        self.rigid = np.zeros(m, dtype=np.int_)
        self.a = np.zeros((DEG1, m)); self.aS = np.zeros((DEG1, m))
        self.C = np.zeros((DEG1, m)); self.S = np.zeros((DEG1, m))
        npp = max(self.np_, 1)
        self.Wm = np.zeros((DEG1, npp))
        self.W = np.zeros(npp); self.DW = np.zeros(npp)
        self.W0 = np.zeros(npp); self.WL = np.zeros(npp)
        self.d0 = np.zeros(nc); self.dd0 = np.zeros(nc); self.dprev = np.zeros(nc)
        self.dcur = np.zeros(nc); self.ddcur = np.zeros(nc)
        self.ddprev = np.zeros(nc); self.seg_peak = np.zeros(nc)
        self.active = np.zeros(nc, dtype=np.int_)
        self.r1_work = np.zeros(3 * m * m + 20 * m)
        self.r1_z = np.zeros(m)
        self.r1_lam = np.zeros(m)
        self.r1_V = np.zeros(m * m)
        self.n_segments = 0
        self.n_host_bases = 0
        self.n_unprobed = 0
        self.bound_open = True
        # the C face: a structure that hosts no contact, stepped exactly; its
        # quadratures are not touched
        self.face.nx, self.face.naux, self.face.nports = 2 * m, 0, self.np_

    # --------------------------------------------------------------- loading
    def forget_bases(self):
        """Drop the kept modes (the ports' shape rows changed)."""
        self.n_bases, self.next_base = 0, 0

    def set_normal(self, int k, normal):
        """Hosted contact ``k``'s normal (complex) is now ``normal`` (a
        contact that follows a plane body's boundary turns with it); the
        host calls :meth:`forget_bases` too."""
        if not 0 <= k < self.nc:
            raise IndexError(f"contact {k} of {self.nc}")
        self.c_nre[k], self.c_nim[k] = complex(normal).real, complex(normal).imag

    def set_step(self, double t, double h, coeffs, motions):
        """Load the step: its start ``t`` and length ``h`` [s], the port
        forces' polynomial coefficients in ``s = (time - t) / h``
        ((p + 1, n_p, 2) array, or None) and, per contact, the partner's
        motion ``(t0, h, coeffs, dcoeffs)`` (complex coefficients of its
        position and velocity in the partner's normalised time).

        Returns False, loading nothing, when the step is beyond the kernel
        (a load or a motion of degree above 3): the reference takes it."""
        cdef int k, i, rows = 1
        cdef double[:, :, ::1] cv
        if coeffs is not None:
            cv = np.ascontiguousarray(coeffs, dtype=float)
            rows = cv.shape[0]
            if rows > DEG1 - 1 or cv.shape[1] != self.np_ or cv.shape[2] != 2:
                return False
        for mt0, mh, mc, dmc in motions:
            if len(mc) > DEG1 or len(dmc) > DEG1:
                return False
        self._load(t, h, NULL if coeffs is None else &cv[0, 0, 0], rows)
        for k, (mt0, mh, mc, dmc) in enumerate(motions):
            self.m_t0[k], self.m_h[k] = mt0, mh
            self.m_len[k], self.dm_len[k] = len(mc), len(dmc)
            for i in range(len(mc)):
                self.m_re[k, i] = mc[i].real
                self.m_im[k, i] = mc[i].imag
            for i in range(len(dmc)):
                self.dm_re[k, i] = dmc[i].real
                self.dm_im[k, i] = dmc[i].imag
        return True

    cdef void _load(self, double t, double h, const double* cv, int rows) noexcept nogil:
        """The step's start, length and modal load from the port forces
        ``cv`` ((rows, n_p, 2) row-major, or NULL for none)."""
        cdef int j, i, p, m = self.m, npt = self.np_
        cdef double u
        self.t, self.h = t, h
        self.g_len = rows
        self.loaded = False
        for j in range(DEG1):
            for i in range(m):
                self.Gin[j, i] = 0.0
        if cv != NULL:
            # (u @ dir) @ R, then the weight
            for j in range(rows):
                for p in range(npt):
                    if cv[(j * npt + p) * 2] != 0.0 or cv[(j * npt + p) * 2 + 1] != 0.0:
                        self.loaded = True
                    u = (cv[(j * npt + p) * 2] * self.dirs[p, 0]
                         + cv[(j * npt + p) * 2 + 1] * self.dirs[p, 1])
                    for i in range(m):
                        self.Gin[j, i] += u * self.R[p, i]
        for i in range(m):
            self.Gin[0, i] += self.g_modal[i]

    # ------------------------------------------------------ the C face
    def side_face(self):
        """The C face of :meth:`side_step` and :meth:`side_outputs`, a
        capsule (:mod:`cosim.core._side_face`) that lives as long as this kernel."""
        self.face.side = <void*> self
        self.face.step = _face_step
        self.face.outputs = _face_outputs
        return PyCapsule_New(&self.face, COSIM_SIDE_FACE, NULL)

    cdef int side_step(self, double t, double h, const double* u, int rows, double* x,
                       double* aux, double* pm) except -1:
        """The exact step of a structure that hosts no contact (what
        :meth:`set_step` and :meth:`step_free` do for its Python host);
        ``aux`` is not touched."""
        cdef int i
        if self.nc or rows > DEG1 - 1:
            raise ValueError("the C step takes a structure that hosts no contact, under a "
                             f"load of at most {DEG1 - 1} coefficients")
        self._load(t, h, u, rows)
        for i in range(6 * self.np_):
            pm[i] = 0.0
        self._free(x, pm)
        return 0

    cdef void side_outputs(self, const double* x, double* pos, double* vel) noexcept:
        """Ports' positions and velocities (:meth:`StructureSubsystem.outputs`)."""
        cdef int i, p, m = self.m
        cdef double w, dw
        for p in range(self.np_):
            w = 0.0
            dw = 0.0
            for i in range(m):
                w += self.R[p, i] * x[i]
                dw += self.R[p, i] * x[m + i]
            pos[2 * p] = self.ref[p, 0] + w * self.dirs[p, 0]
            pos[2 * p + 1] = self.ref[p, 1] + w * self.dirs[p, 1]
            vel[2 * p] = dw * self.dirs[p, 0]
            vel[2 * p + 1] = dw * self.dirs[p, 1]

    # ------------------------------------------------- closed-form response
    cdef void _split(self, const double* lam) noexcept nogil:
        """:func:`fem.response._split` of ``(lam, z0, dz0, aS)``."""
        cdef int i, m = self.m
        cdef double lmax = 0.0, le
        for i in range(m):
            if lam[i] > lmax:
                lmax = lam[i]
        if lmax < 1e-300:
            lmax = 1e-300
        for i in range(m):
            self.rigid[i] = lam[i] <= 1e-14 * lmax
            le = 1.0 if self.rigid[i] else lam[i]
            self.om[i] = sqrt(le)
            self.b3[i] = self.aS[3, i] / le
            self.b2[i] = self.aS[2, i] / le
            self.b1[i] = (self.aS[1, i] - 6.0 * self.b3[i]) / le
            self.b0[i] = (self.aS[0, i] - 2.0 * self.b2[i]) / le
            self.A[i] = self.z0[i] - self.b0[i]
            self.B[i] = (self.dz0[i] - self.b1[i]) / self.om[i]

    cdef inline void _mode(self, int i, double tau, double* z, double* dz) noexcept nogil:
        """Mode ``i``'s displacement and velocity at ``tau`` (:func:`fem.response._states`)."""
        cdef double wt, cs, sn, t2
        if self.rigid[i]:
            t2 = tau * tau
            z[0] = self.z0[i] + self.dz0[i] * tau + t2 * (
                self.aS[0, i] / 2 + tau * (self.aS[1, i] / 6 + tau * (
                    self.aS[2, i] / 12 + tau * self.aS[3, i] / 20)))
            dz[0] = self.dz0[i] + tau * (self.aS[0, i] + tau * (
                self.aS[1, i] / 2 + tau * (self.aS[2, i] / 3 + tau * self.aS[3, i] / 4)))
            return
        wt = tau * self.om[i]
        cs = cos(wt)
        sn = sin(wt)
        z[0] = (self.b0[i] + tau * (self.b1[i] + tau * (self.b2[i] + tau * self.b3[i]))
                + self.A[i] * cs + self.B[i] * sn)
        dz[0] = (self.b1[i] + tau * (2.0 * self.b2[i] + 3.0 * tau * self.b3[i])
                 + self.om[i] * (self.B[i] * cs - self.A[i] * sn))

    cdef void _ports(self, double tau, const double* P, double* W, double* DW) noexcept nogil:
        """Ports' displacements and velocities along the field at ``tau``
        (``P`` (m, n_p) row-major: the ports' rows in the segment's modes)."""
        cdef int i, p, npt = self.np_
        cdef double z, dz
        for p in range(npt):
            W[p] = 0.0
            DW[p] = 0.0
        for i in range(self.m):
            self._mode(i, tau, &z, &dz)
            for p in range(npt):
                W[p] += z * P[i * npt + p]
                DW[p] += dz * P[i * npt + p]

    cdef double _port(self, double tau, const double* P, int p, double* dw) noexcept nogil:
        """One port's displacement (and velocity into ``dw``) at ``tau``."""
        cdef int i, npt = self.np_
        cdef double z, dz, w = 0.0, v = 0.0
        for i in range(self.m):
            self._mode(i, tau, &z, &dz)
            w += z * P[i * npt + p]
            v += dz * P[i * npt + p]
        dw[0] = v
        return w

    cdef void _modes_at(self, double tau) noexcept nogil:
        """Every mode's state at ``tau`` into ``zt``, ``dzt``."""
        cdef int i
        for i in range(self.m):
            self._mode(i, tau, &self.zt[i], &self.dzt[i])

    cdef void _trig_moments(self, double L) noexcept nogil:
        """:func:`fem.response._trig_moments` of the elastic modes, degree 3."""
        cdef int i, j, n
        cdef double w, x, cl, sl, c, s, cn, lj, x2, xp, fc, fs, sc, ss, sign
        for i in range(self.m):
            if self.rigid[i]:
                continue
            w = self.om[i]
            x = w * L
            if x >= SERIES_BELOW:
                cl = cos(x)
                sl = sin(x)
                c = sl / w
                s = (1.0 - cl) / w
                self.C[0, i] = c
                self.S[0, i] = s
                for j in range(1, DEG1):
                    lj = pow(L, j)
                    cn = (lj * sl - j * s) / w
                    s = (j * c - lj * cl) / w
                    c = cn
                    self.C[j, i] = c
                    self.S[j, i] = s
            else:
                x2 = x * x
                for j in range(DEG1):
                    sc = 0.0
                    ss = 0.0
                    xp = 1.0
                    fc = 1.0            # (2n)!
                    fs = 1.0            # (2n + 1)!
                    sign = 1.0
                    for n in range(SERIES_TERMS):
                        if n > 0:
                            xp = xp * x2
                            fc = fc * (2 * n - 1) * (2 * n)
                            fs = fs * (2 * n) * (2 * n + 1)
                            sign = -sign
                        sc += sign / (fc * (2 * n + j + 1)) * xp
                        ss += sign / (fs * (2 * n + j + 2)) * xp
                    self.C[j, i] = pow(L, j + 1) * sc
                    self.S[j, i] = pow(L, j + 1) * ss * x

    cdef void _moments(self, double L, const double* P) noexcept nogil:
        """``Wm[j, p] = int_0^L tau^j w_p`` (:func:`fem.undamped_moments`, degree 3)."""
        cdef int i, j, p, qq, npt = self.np_
        cdef double pq, r
        cdef double poly[6]
        self._trig_moments(L)
        for p in range(npt):
            for qq in range(6):
                poly[qq] = 0.0
            for j in range(DEG1):
                self.Wm[j, p] = 0.0
            for i in range(self.m):
                r = P[i * npt + p]
                if self.rigid[i]:
                    poly[0] += self.z0[i] * r
                    poly[1] += self.dz0[i] * r
                    poly[2] += self.aS[0, i] / 2 * r
                    poly[3] += self.aS[1, i] / 6 * r
                    poly[4] += self.aS[2, i] / 12 * r
                    poly[5] += self.aS[3, i] / 20 * r
                else:
                    poly[0] += self.b0[i] * r
                    poly[1] += self.b1[i] * r
                    poly[2] += self.b2[i] * r
                    poly[3] += self.b3[i] * r
                    for j in range(DEG1):
                        self.Wm[j, p] += (self.C[j, i] * (self.A[i] * r)
                                          + self.S[j, i] * (self.B[i] * r))
            for j in range(DEG1):
                pq = 0.0
                for qq in range(6):
                    pq += pow(L, qq + j + 1) / (qq + j + 1) * poly[qq]
                self.Wm[j, p] += pq

    # ------------------------------------------------------------- contacts
    cdef inline void _partner(self, int k, double time, double* xr, double* xi, double* vr,
                              double* vi) noexcept nogil:
        """Partner position and velocity at ``time`` (``np.polyval``'s Horner)."""
        cdef int i
        cdef double s = (time - self.m_t0[k]) / self.m_h[k], ar = 0.0, ai = 0.0
        for i in range(self.m_len[k] - 1, -1, -1):
            ar = ar * s + self.m_re[k, i]
            ai = ai * s + self.m_im[k, i]
        xr[0], xi[0] = ar, ai
        ar, ai = 0.0, 0.0
        for i in range(self.dm_len[k] - 1, -1, -1):
            ar = ar * s + self.dm_re[k, i]
            ai = ai * s + self.dm_im[k, i]
        vr[0], vi[0] = ar, ai

    cdef inline void _gap(self, int k, double time, double w, double dw, double* d,
                          double* dd) noexcept nogil:
        """Penetration and rate of contact ``k`` for its port at ``w``, ``dw``
        along the field (:meth:`EmbeddedContact.penetrations`)."""
        cdef int p = self.c_port[k]
        cdef double xr, xi, vr, vi
        self._partner(k, time, &xr, &xi, &vr, &vi)
        xr = (self.ref[p, 0] + w * self.dirs[p, 0]) - xr
        xi = (self.ref[p, 1] + w * self.dirs[p, 1]) - xi
        vr = dw * self.dirs[p, 0] - vr
        vi = dw * self.dirs[p, 1] - vi
        d[0] = self.c_off[k] - self.c_side[k] * (self.c_nre[k] * xr + self.c_nim[k] * xi)
        dd[0] = -self.c_side[k] * (self.c_nre[k] * vr + self.c_nim[k] * vi)

    cdef inline void _reparam(self, const double* c, int n, double a, double b,
                              double* out) noexcept nogil:
        """:func:`cosim.core.subsystem.reparametrised` of one polynomial (``n`` coefficients)."""
        cdef int i, k
        for k in range(n):
            out[k] = 0.0
        for i in range(n):
            for k in range(i + 1):
                out[k] += _comb(i, k) * pow(a, i - k) * pow(b, k) * c[i]

    # ---------------------------------------------------------- the bases
    cdef int _basis(self, long long mask):
        """Slot of the kept modes of the closed set ``mask``, asked of the
        host when not kept."""
        cdef int s, i, j, p, k, m = self.m, npt = self.np_
        cdef double acc
        for s in range(self.n_bases):
            if self.b_mask[s] == mask:
                return s
        s = self.next_base
        if self._rank_one_basis(mask, s):
            self.n_host_bases += 1
            lam, Psi, wmax = self.host_basis(tuple(bool(self.active[k])
                                                   for k in range(self.nc)))
            self.b_wmax[s] = wmax
            lam = np.asarray(lam, float)
            for i in range(m):
                self.b_lam[s, i] = lam[i]
            if Psi is None:
                self.b_ident[s] = 1
                for i in range(m):
                    for p in range(npt):
                        self.b_P[s, i, p] = self.R[p, i]
            else:
                self.b_ident[s] = 0
                Psi = np.ascontiguousarray(Psi, dtype=float)
                np.asarray(self.b_psi)[s] = Psi
                PR = Psi.T @ np.asarray(self.R).T
                for i in range(m):
                    for p in range(npt):
                        self.b_P[s, i, p] = PR[i, p]
        self.next_base = (s + 1) % MAX_BASES
        if self.n_bases < MAX_BASES:
            self.n_bases += 1
        self.b_mask[s] = mask
        return s

    cdef int _rank_one_basis(self, long long mask, int s) noexcept nogil:
        """Slot ``s`` filled with the modes of ``mask`` where no spring or one
        spring is closed, as the host's ``_active_basis`` makes them; -1 where
        the host must (several springs, or the rank-one update declined)."""
        cdef int i, j, k, p, m = self.m, npt = self.np_, one = -1, count = 0
        cdef double c, lmax, acc
        for k in range(self.nc):
            if self.active[k]:
                one = k
                count += 1
        if count == 0:                      # the structure's own modes
            self.b_ident[s] = 1
            for i in range(m):
                self.b_lam[s, i] = self.lam0[i]
            self.b_wmax[s] = self.wmax0
            for i in range(m):
                for p in range(npt):
                    self.b_P[s, i, p] = self.R[p, i]
            return 0
        if count > 1:
            return -1
        p = self.c_port[one]
        c = self.c_nre[one] * self.dirs[p, 0] + self.c_nim[one] * self.dirs[p, 1]
        for i in range(m):
            self.r1_z[i] = sqrt(self.c_k[one]) * fabs(c) * self.R[p, i]
        if _rank_one(m, &self.lam0[0], &self.r1_z[0], &self.r1_lam[0], &self.r1_V[0], 50,
                     &self.r1_work[0]):
            return -1
        self.b_ident[s] = 0
        lmax = self.r1_lam[0]
        for i in range(m):
            if self.r1_lam[i] > lmax:
                lmax = self.r1_lam[i]
            self.b_lam[s, i] = self.r1_lam[i] if self.r1_lam[i] > 0.0 else 0.0
            for j in range(m):
                self.b_psi[s, i, j] = self.r1_V[i * m + j]
        self.b_wmax[s] = sqrt(lmax if lmax > 0.0 else 0.0)
        for i in range(m):
            for p in range(npt):
                acc = 0.0
                for k in range(m):
                    acc += self.b_psi[s, k, i] * self.R[p, k]
                self.b_P[s, i, p] = acc
        return 0

    # ------------------------------------------------------------ stepping
    cdef void _segment_load(self, double tc) noexcept nogil:
        """:meth:`StructureSubsystem._segment_load` into ``a`` (DEG1, m)."""
        cdef int j, i, k, p, m = self.m
        cdef double col[DEG1]
        cdef double out[DEG1]
        cdef double outi[DEG1]
        cdef double c, ck, base, nre, nim
        for j in range(DEG1):
            for i in range(m):
                self.a[j, i] = 0.0
        for i in range(m):
            for j in range(self.g_len):
                col[j] = self.Gin[j, i]
            self._reparam(col, self.g_len, (tc - self.t) / self.h, 1.0 / self.h, out)
            for j in range(self.g_len):
                self.a[j, i] = out[j]
        for k in range(self.nc):
            if not self.active[k]:
                continue
            p = self.c_port[k]
            nre, nim = self.c_nre[k], self.c_nim[k]
            c = nre * self.dirs[p, 0] + nim * self.dirs[p, 1]
            self._reparam(&self.m_re[k, 0], self.m_len[k], (tc - self.m_t0[k]) / self.m_h[k],
                          1.0 / self.m_h[k], out)
            self._reparam(&self.m_im[k, 0], self.m_len[k], (tc - self.m_t0[k]) / self.m_h[k],
                          1.0 / self.m_h[k], outi)
            base = self.c_side[k] * c * self.c_k[k] * (
                self.c_off[k] - self.c_side[k] * (nre * self.ref[p, 0] + nim * self.ref[p, 1]))
            ck = c * self.c_k[k]
            for j in range(self.m_len[k]):
                out[j] = nre * out[j] + nim * outi[j]
            for i in range(m):
                self.a[0, i] += base * self.R[p, i]
                for j in range(self.m_len[k]):
                    self.a[j, i] += ck * (out[j] * self.R[p, i])

    cdef void _to_segment(self, int s) noexcept nogil:
        """The segment's start and load in the modes of slot ``s``."""
        cdef int i, j, k, m = self.m
        cdef double z, dz
        if self.b_ident[s]:
            for i in range(m):
                self.z0[i] = self.q[i]
                self.dz0[i] = self.dq[i]
                for j in range(DEG1):
                    self.aS[j, i] = self.a[j, i]
            return
        for i in range(m):
            z = 0.0
            dz = 0.0
            for k in range(m):
                z += self.b_psi[s, k, i] * self.q[k]
                dz += self.b_psi[s, k, i] * self.dq[k]
            self.z0[i] = z
            self.dz0[i] = dz
            for j in range(DEG1):
                z = 0.0
                for k in range(m):
                    z += self.a[j, k] * self.b_psi[s, k, i]
                self.aS[j, i] = z

    cdef void _end_state(self, int s, double tau) noexcept nogil:
        """Modal state at ``tau`` after the segment's start into ``q``, ``dq``."""
        cdef int i, k, m = self.m
        cdef double z, dz
        self._modes_at(tau)
        if self.b_ident[s]:
            for i in range(m):
                self.q[i] = self.zt[i]
                self.dq[i] = self.dzt[i]
            return
        for i in range(m):
            z = 0.0
            dz = 0.0
            for k in range(m):
                z += self.b_psi[s, i, k] * self.zt[k]
                dz += self.b_psi[s, i, k] * self.dzt[k]
            self.q[i] = z
            self.dq[i] = dz

    cdef bint _stays_open(self, double tc, double L, const double* P) noexcept nogil:
        """:meth:`StructureSubsystem._stays_open`: True where every contact,
        open at the segment's start, provably stays open over ``[0, L]``.

        Contact ``k``'s penetration is ``f(tau) + beta (w_p - Q_p)(tau)``:
        ``f`` the partner's motion and the offset less ``beta`` times the
        port's particular polynomial ``Q_p`` (degree 3), and ``w_p - Q_p`` a
        sum of harmonics, at most ``E_p = sum_i |P_ip| |(A_i, B_i)|``.  With
        ``tau^j`` in ``[0, L^j]``, ``f(tau) <= f_0 + sum_j max(f_j, 0) L^j``;
        that bound plus ``|beta| E_p`` below ``-margin`` (the probes' own
        round-off, with room to spare) means no probe could find it closed.
        A rigid mode (its polynomial of degree 5) is not bounded here."""
        cdef int i, j, k, p, n, m = self.m, npt = self.np_
        cdef double beta, nre, nim, E, S, amp, Lj, f, bound, margin, pr
        cdef double alpha[DEG1]
        cdef double alphai[DEG1]
        cdef double Q[DEG1]
        cdef double wL = 0.0
        for i in range(m):
            if self.rigid[i]:
                return False
            if self.om[i] * L > wL:
                wL = self.om[i] * L
        # relative to the terms' sizes S: the probes sum m modes, each with
        # its phase omega tau rounded (about omega L eps), and the gap a few
        # terms more; plus 1e-9 of S, for a segment that near a touch loses
        # nothing by being probed
        margin = 1e-9 + 16.0 * DBL_EPSILON * (m + 4 + wL)
        for k in range(self.nc):
            p = self.c_port[k]
            nre, nim = self.c_nre[k], self.c_nim[k]
            beta = self.c_side[k] * (nre * self.dirs[p, 0] + nim * self.dirs[p, 1])
            n = self.m_len[k]
            for j in range(DEG1):
                alpha[j] = 0.0
                alphai[j] = 0.0
                Q[j] = 0.0
            self._reparam(&self.m_re[k, 0], n, (tc - self.m_t0[k]) / self.m_h[k],
                          1.0 / self.m_h[k], alpha)
            self._reparam(&self.m_im[k, 0], n, (tc - self.m_t0[k]) / self.m_h[k],
                          1.0 / self.m_h[k], alphai)
            for j in range(n):
                alpha[j] = self.c_side[k] * (nre * alpha[j] + nim * alphai[j])
            S = fabs(self.c_off[k]) + fabs(nre * self.ref[p, 0] + nim * self.ref[p, 1])
            alpha[0] += self.c_off[k] - self.c_side[k] * (nre * self.ref[p, 0]
                                                          + nim * self.ref[p, 1])
            E = 0.0
            amp = 0.0
            for i in range(m):
                pr = P[i * npt + p]
                Q[0] += pr * self.b0[i]
                Q[1] += pr * self.b1[i]
                Q[2] += pr * self.b2[i]
                Q[3] += pr * self.b3[i]
                E += fabs(pr) * sqrt(self.A[i] * self.A[i] + self.B[i] * self.B[i])
                amp += fabs(pr) * (fabs(self.b0[i]) + L * (fabs(self.b1[i]) + L * (
                    fabs(self.b2[i]) + L * fabs(self.b3[i]))) + fabs(self.A[i])
                    + fabs(self.B[i]))
            bound = alpha[0] - beta * Q[0]
            Lj = 1.0
            for j in range(DEG1):
                if j:
                    Lj *= L
                    f = alpha[j] - beta * Q[j]
                    if f > 0.0:
                        bound += f * Lj
                S += fabs(alpha[j]) * Lj
            S += fabs(beta) * amp
            if bound + fabs(beta) * E >= -margin * S:
                return False
        return True

    cdef void _quadratures(self, double[::1] aux, double[:, ::1] pm, double tc, double L,
                           const double* P, bint any_active) noexcept nogil:
        """:meth:`StructureSubsystem._segment_quadratures` over ``[tc, tc + L]``."""
        cdef int k, p, j, n, npt = self.np_
        cdef double beta, nre, nim, a0, ia0, ia1, aL, da, sig, s0, s1, x
        cdef double alpha[DEG1]
        cdef double alphai[DEG1]
        cdef double dw
        if not self.loaded and not any_active:
            return
        self._moments(L, P)
        for p in range(npt):
            self.W0[p] = self._port(0.0, P, p, &dw)
            self.WL[p] = self._port(L, P, p, &dw)
        sig = tc - self.t
        for k in range(self.nc):
            if not self.active[k]:
                continue
            p = self.c_port[k]
            nre, nim = self.c_nre[k], self.c_nim[k]
            beta = self.c_side[k] * (nre * self.dirs[p, 0] + nim * self.dirs[p, 1])
            n = self.m_len[k]
            self._reparam(&self.m_re[k, 0], n, (tc - self.m_t0[k]) / self.m_h[k],
                          1.0 / self.m_h[k], alpha)
            self._reparam(&self.m_im[k, 0], n, (tc - self.m_t0[k]) / self.m_h[k],
                          1.0 / self.m_h[k], alphai)
            for j in range(n):
                alpha[j] = self.c_side[k] * (nre * alpha[j] + nim * alphai[j])
            alpha[0] += self.c_off[k] - self.c_side[k] * (nre * self.ref[p, 0]
                                                          + nim * self.ref[p, 1])
            ia0 = 0.0
            ia1 = 0.0
            for j in range(n):
                ia0 += alpha[j] * (pow(L, j + 1) / (j + 1))
                ia1 += alpha[j] * (pow(L, j + 2) / (j + 2))
            aux[4 * k] += self.c_k[k] * (ia0 - beta * self.Wm[0, p])
            aux[4 * k + 2] += self.c_k[k] * (sig * ia0 + ia1 - beta * (
                sig * self.Wm[0, p] + self.Wm[1, p]))
            da = 0.0
            for j in range(1, n):
                da += (alpha[j] * j) * self.Wm[j - 1, p]
            aL = 0.0
            for j in range(n - 1, -1, -1):
                aL = aL * L + alpha[j]
            aux[4 * k + 3] += beta * self.c_k[k] * (
                aL * self.WL[p] - alpha[0] * self.W0[p] - da
                - 0.5 * beta * (self.WL[p] * self.WL[p] - self.W0[p] * self.W0[p]))
        if self.loaded:
            s0 = sig / self.h
            s1 = (sig + L) / self.h
            for p in range(npt):
                x = self.WL[p] - self.W0[p]
                pm[0, 2 * p] += x * self.dirs[p, 0]
                pm[0, 2 * p + 1] += x * self.dirs[p, 1]
                x = s1 * self.WL[p] - s0 * self.W0[p] - self.Wm[0, p] / self.h
                pm[1, 2 * p] += x * self.dirs[p, 0]
                pm[1, 2 * p + 1] += x * self.dirs[p, 1]
                x = (s1 * s1 * self.WL[p] - s0 * s0 * self.W0[p]
                     - 2.0 * (sig * self.Wm[0, p] + self.Wm[1, p]) / (self.h * self.h))
                pm[2, 2 * p] += x * self.dirs[p, 0]
                pm[2, 2 * p + 1] += x * self.dirs[p, 1]

    cdef double _switch_time(self, int k, bint was_closed, double lo, double hi, double d_lo,
                             double d_hi, double tol, double tc,
                             const double* P) noexcept nogil:
        """:meth:`StructureSubsystem._switch_time`: safeguarded Newton on the
        exact solution, started by regula falsi."""
        cdef int it, p = self.c_port[k]
        cdef double x, width, dx, rate, xn, w, dw
        if d_lo != d_hi:
            x = lo + (hi - lo) * (d_lo / (d_lo - d_hi))
        else:
            x = 0.5 * (lo + hi)
        for it in range(100):
            if not (lo < x and x < hi):
                x = 0.5 * (lo + hi)
            width = hi - lo
            w = self._port(x, P, p, &dw)
            self._gap(k, tc + x, w, dw, &dx, &rate)
            if (dx > 0) == was_closed:
                lo = x
            else:
                hi = x
            if hi - lo <= tol:
                break
            if rate != 0.0:
                xn = x - dx / rate
            else:
                xn = 0.5 * (lo + hi)
            if fabs(xn - x) < tol:
                xn = x + 0.5 * tol if x == lo else x - 0.5 * tol
            elif not (lo < xn and xn < hi) or hi - lo > 0.5 * width:
                xn = 0.5 * (lo + hi)
            x = xn
        return hi

    cdef double _rate_root_value(self, int k, double tc, double lo, double hi, double v_lo,
                                 double v_hi, const double* P) noexcept nogil:
        """:meth:`StructureSubsystem._rate_root_value`: the penetration of
        contact ``k`` where its rate, ``v_lo > 0 >= v_hi`` at ``lo`` and ``hi``
        after ``tc``, falls through zero (Illinois regula falsi, at most 60
        evaluations)."""
        cdef int it, side = 0, p = self.c_port[k]
        cdef double d_best = -INFINITY, x, dx, vx, w, dw, tol
        x = fabs(tc) + hi
        tol = 1e-14 * (x if x > 1.0 else 1.0)
        for it in range(60):
            if v_hi == v_lo:
                x = hi
            else:
                x = (lo * v_hi - hi * v_lo) / (v_hi - v_lo)
            if not (lo <= x and x <= hi):
                x = 0.5 * (lo + hi)
            w = self._port(x, P, p, &dw)
            self._gap(k, tc + x, w, dw, &dx, &vx)
            if dx > d_best:
                d_best = dx
            if vx > 0.0:
                lo = x
                v_lo = vx
                if side == 1:
                    v_hi *= 0.5
                side = 1
            else:
                hi = x
                v_hi = vx
                if side == -1:
                    v_lo *= 0.5
                side = -1
            if hi - lo <= tol or vx == 0.0:
                break
        return d_best

    cdef void _peak_interval(self, int k, double tc, double lo, double hi, double v_lo,
                             double d_hi, double v_hi, const double* P) noexcept nogil:
        """One interval of :meth:`StructureSubsystem._segment_peaks` for the
        closed contact ``k``: the segment's largest penetration so far
        ``seg_peak[k]`` raised to the value ``d_hi`` at the interval's end and,
        where the rate falls through zero inside it, to the penetration there."""
        cdef double r
        if d_hi > self.seg_peak[k]:
            self.seg_peak[k] = d_hi
        if v_lo > 0.0 and v_hi <= 0.0:
            r = self._rate_root_value(k, tc, lo, hi, v_lo, v_hi, P)
            if r > self.seg_peak[k]:
                self.seg_peak[k] = r

    def step(self, double[::1] x, double[::1] aux, double[:, ::1] pm, signed char[::1] closed,
             double[::1] peak):
        """Advance the modal state ``x = [q, dq]`` (2 m) over the loaded step
        in closed form with the hosted springs switching, adding to ``aux``
        (4 per contact, as the reference) and to the ports' velocity moments
        ``pm`` (3, 2 n_p; complex interleaved).  ``closed`` (n_c) holds each
        contact's state at the end of the last step (1 closed, 0 open, -1
        unknown), and on return at the end of this one.  ``peak`` (n_c), the
        host's largest penetrations, is raised in place to each closed
        contact's largest penetration over each segment (the reference's
        ``_segment_peaks``).  Returns the located switches
        ``[(time, contact, closed), ...]``."""
        cdef int m = self.m, npt = self.np_, nc = self.nc, j, k, s, p
        cdef long i, n, row
        cdef double t1 = self.t + self.h, tc = self.t, eps, L, tau, tol, best, hi, lo0, hi0
        cdef double d, dd, w, acc, wmax, taup
        cdef long long mask
        cdef bint any_active, flipped
        cdef const double* P
        cdef long[64] who
        cdef int n_who
        if x.shape[0] != 2 * m or aux.shape[0] != 4 * nc + 2 or pm.shape[0] != 3 \
                or pm.shape[1] != 2 * npt or closed.shape[0] != nc or peak.shape[0] != nc:
            raise ValueError(f"`x`, `aux`, `pm`, `closed` and `peak` must have {2 * m}, "
                             f"{4 * nc + 2}, (3, {2 * npt}), {nc} and {nc} entries, got "
                             f"{x.shape[0]}, {aux.shape[0]}, ({pm.shape[0]}, {pm.shape[1]}), "
                             f"{closed.shape[0]} and {peak.shape[0]}")
        log = []
        for k in range(nc):
            aux[4 * k + 2] = 0.0            # first moments are per step
        for i in range(m):
            self.q[i] = x[i]
            self.dq[i] = x[m + i]
        eps = 1e-13 * (fabs(t1) if fabs(t1) > 1.0 else 1.0)
        cdef long segments = 0
        while t1 - tc > eps:
            segments += 1
            if segments > MAX_SEGMENTS:
                raise StalledStep(f"the compiled structure step made {MAX_SEGMENTS} segments "
                                  f"in the step from t = {self.t!r} s without reaching its "
                                  f"end (at t = {tc!r} s)")
            L = t1 - tc
            # the contacts at the segment's start: R q, R dq
            for p in range(npt):
                w = 0.0
                acc = 0.0
                for i in range(m):
                    w += self.R[p, i] * self.q[i]
                    acc += self.R[p, i] * self.dq[i]
                self.W[p] = w
                self.DW[p] = acc
            mask = 0
            any_active = False
            for k in range(nc):
                p = self.c_port[k]
                self._gap(k, tc, self.W[p], self.DW[p], &d, &dd)
                self.d0[k] = d
                self.dd0[k] = dd
                self.active[k] = d > 0 or (d == 0 and dd > 0)
                if d == 0 and dd > 0:
                    log.append((tc, k, True))
                if self.active[k]:
                    mask |= (<long long> 1) << k
                    any_active = True
            if tc == self.t:
                # a touch on the step boundary (see the reference)
                for k in range(nc):
                    if self.active[k] and closed[k] == 0 and self.d0[k] != 0 \
                            and self.dd0[k] > 0:
                        log.append((tc, k, True))
            for k in range(nc):
                closed[k] = self.active[k]
            s = self._basis(mask)
            wmax = self.b_wmax[s]
            P = &self.b_P[s, 0, 0]
            self._segment_load(tc)
            self._to_segment(s)
            self._split(&self.b_lam[s, 0])
            self.n_segments += 1
            # probes half a radian of the fastest mode apart, uncapped (the
            # reference's count); between two that keep every contact's side,
            # a closed contact's peak is sought where its rate falls through
            # zero (the reference's _segment_peaks, interval by interval)
            n = <long> ceil(2.0 * L * wmax)
            if n < 2:
                n = 2
            if self.bound_open and not any_active and self._stays_open(tc, L, P):
                # every contact open and bound to stay so: the probes would
                # find nothing, and the segment ends as theirs would
                self.n_unprobed += 1
                self._quadratures(aux, pm, tc, L, P, any_active)
                self._end_state(s, L * n / n)
                break
            row = -1
            for k in range(nc):
                self.dprev[k] = self.d0[k]
                self.ddprev[k] = self.dd0[k]
                self.seg_peak[k] = self.d0[k]
            taup = 0.0
            for i in range(1, n + 1):
                tau = L * i / n
                self._ports(tau, P, &self.W[0], &self.DW[0])
                flipped = False
                for k in range(nc):
                    p = self.c_port[k]
                    self._gap(k, tc + tau, self.W[p], self.DW[p], &self.dcur[k],
                              &self.ddcur[k])
                    if (self.dcur[k] > 0) != (self.active[k] != 0):
                        flipped = True
                if flipped:
                    row = i
                    break
                for k in range(nc):
                    if self.active[k]:
                        self._peak_interval(k, tc, taup, tau, self.ddprev[k], self.dcur[k],
                                            self.ddcur[k], P)
                    self.dprev[k] = self.dcur[k]
                    self.ddprev[k] = self.ddcur[k]
                taup = tau
            if row < 0:
                self._quadratures(aux, pm, tc, L, P, any_active)
                self._raise_peaks(peak)
                self._end_state(s, L * n / n)
                break
            lo0 = L * (row - 1) / n if row > 1 else 0.0
            hi0 = L * row / n
            best = hi0
            n_who = 0
            tol = 1e-15 * (fabs(tc) if fabs(tc) > 1.0 else 1.0)
            for k in range(nc):
                if (self.dcur[k] > 0) == (self.active[k] != 0):
                    continue
                hi = self._switch_time(k, self.active[k] != 0, lo0, hi0, self.dprev[k],
                                       self.dcur[k], tol, tc, P)
                if hi < best - 1e-15:
                    best = hi
                    who[0] = k
                    n_who = 1
                elif fabs(hi - best) <= 1e-15:
                    who[n_who] = k
                    n_who += 1
            self._quadratures(aux, pm, tc, best, P, any_active)
            if any_active:
                # the last interval ends at the switch
                self._ports(best, P, &self.W[0], &self.DW[0])
                for k in range(nc):
                    if self.active[k]:
                        p = self.c_port[k]
                        self._gap(k, tc + best, self.W[p], self.DW[p], &d, &dd)
                        self._peak_interval(k, tc, taup, best, self.ddprev[k], d, dd, P)
                self._raise_peaks(peak)
            self._end_state(s, best)
            tc += best
            for j in range(n_who):
                log.append((tc, who[j], not self.active[who[j]]))
                closed[who[j]] = not self.active[who[j]]
        for i in range(m):
            x[i] = self.q[i]
            x[m + i] = self.dq[i]
        return log

    cdef void _raise_peaks(self, double[::1] peak) noexcept nogil:
        """``peak`` of each closed contact raised to its segment's largest
        penetration."""
        cdef int k
        for k in range(self.nc):
            if self.active[k] and self.seg_peak[k] > peak[k]:
                peak[k] = self.seg_peak[k]

    def step_free(self, double[::1] x, double[:, ::1] pm):
        """Advance ``x`` exactly over the loaded step with no hosted contact
        (:meth:`fem.ExactModal.step_modal` on undamped modes), and the
        ports' velocity moments ``pm`` by three-point Gauss-Legendre when a
        port is loaded (the reference's ``_gauss_moments``)."""
        if x.shape[0] != 2 * self.m or pm.shape[0] != 3 or pm.shape[1] != 2 * self.np_:
            raise ValueError(f"`x` must have {2 * self.m} entries and `pm` shape "
                             f"(3, {2 * self.np_})")
        self._free(&x[0], &pm[0, 0])

    cdef void _free(self, double* x, double* pm) noexcept nogil:
        """:meth:`step_free` on ``x`` (2 m) and ``pm`` ((3, 2 n_p) row-major)."""
        cdef int m = self.m, npt = self.np_, i, j, p, g
        cdef double col[DEG1]
        cdef double out[DEG1]
        cdef double sn, wh, v
        for i in range(m):
            for j in range(self.g_len):
                col[j] = self.Gin[j, i]
            self._reparam(col, self.g_len, 0.0, 1.0 / self.h, out)
            for j in range(DEG1):
                self.aS[j, i] = out[j] if j < self.g_len else 0.0
            self.z0[i] = x[i]
            self.dz0[i] = x[m + i]
        self._split(&self.lam0[0])
        if self.loaded:
            for g in range(3):
                sn = GAUSS_NODES[g]
                wh = GAUSS_WEIGHTS[g] * self.h
                self._modes_at(sn * self.h)
                for p in range(npt):
                    v = 0.0
                    for i in range(m):
                        v += self.R[p, i] * self.dzt[i]
                    pm[2 * p] += wh * (v * self.dirs[p, 0])
                    pm[2 * p + 1] += wh * (v * self.dirs[p, 1])
                    pm[2 * npt + 2 * p] += wh * (sn * (v * self.dirs[p, 0]))
                    pm[2 * npt + 2 * p + 1] += wh * (sn * (v * self.dirs[p, 1]))
                    pm[4 * npt + 2 * p] += wh * (sn * sn * (v * self.dirs[p, 0]))
                    pm[4 * npt + 2 * p + 1] += wh * (sn * sn * (v * self.dirs[p, 1]))
        self._modes_at(self.h)
        for i in range(m):
            x[i] = self.zt[i]
            x[m + i] = self.dzt[i]


# ------------------------------------------------- the C face's functions
cdef int _face_step(void* side, double t, double h, const double* u, int rows, double* x,
                    double* aux, double* pm) except -1:
    return (<StructureStep> side).side_step(t, h, u, rows, x, aux, pm)


cdef void _face_outputs(void* side, const double* x, double* pos, double* vel) noexcept:
    (<StructureStep> side).side_outputs(x, pos, vel)

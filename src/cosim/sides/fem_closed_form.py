"""Closed-form stepping of a structure whose embedded contacts are linear
springs (the numpy reference of the compiled ``StructureStep``).

Undamped and stepped exactly, each set of closed contacts is again a linear
system under a polynomial load: its modes are the kept modes with the
springs added (rank-one updates), a step is a sequence of segments stepped
in closed form, each contact's switch located on the exact solution and its
peak, impulse, dissipation and work integrated along it.  A segment with
every contact open is probed for a touch only where a bound of the exact
solution does not rule one out (:meth:`ClosedFormContacts._stays_open`).

:class:`ClosedFormContacts` is a mixin of
:class:`~cosim.sides.fem.StructureSubsystem`; it reads the subsystem's modes,
ports and embedded contacts and adds no call to a step.
"""
from __future__ import annotations

import math

import numpy as np

from fem.integrators import SMALL_DENSE
from fem.rank_one import rank_one_eigh
from fem.response import undamped_envelope, undamped_moments, undamped_response

from cosim.core.subsystem import reparametrised

__all__ = ["ClosedFormContacts"]


class ClosedFormContacts:
    """The closed-form stepping methods of a structure subsystem."""

    @property
    def closed_form_contacts(self) -> bool:
        """The subsystem protocol's name of :attr:`_closed_form`."""
        return self._closed_form

    @property
    def _closed_form(self) -> bool:
        """Undamped, stepped exactly, every embedded contact a linear spring:
        each set of closed contacts is again a linear system under a
        polynomial load, stepped in closed form with its switches located
        on the exact solution."""
        if self._closed_ok is None:
            from couplers import LinearLaw
            self._closed_ok = bool(self._embedded) and self._ts is None \
                and not np.any(self.modal_damping) \
                and all(type(e.law) is LinearLaw for e in self._embedded)
        return self._closed_ok

    _closed_ok = None

    def _active_basis(self, active: tuple):
        """Modes (lam, Psi) of the modal equations with the springs of the
        closed contacts ``active`` added: ``K = diag(omega^2) + sum k c^2 r r^T``."""
        basis = self._bases.get(active)
        if basis is None and not any(active):
            # no spring closed: the structure's own modes, Psi = I (``None``),
            # with no eigen-solve and no change of coordinates
            basis = (self.omega ** 2, None, float(self.omega.max(initial=0.0)))
            self._bases[active] = basis
        elif basis is None:
            springs = []
            for on, e in zip(active, self._embedded):
                if on:
                    c = (e.normal.conjugate() * self._dirc[e.port]).real
                    springs.append(math.sqrt(e.law.contact_stiffness) * abs(c) * self._R[e.port])
            # one spring: diag(omega^2) + z z^T by its secular equation, O(m^2)
            # (follow = true asks for one basis per step in contact, and a
            # dense solve is O(m^3)); several, or a root that did not converge: LAPACK
            res = rank_one_eigh(self.omega ** 2, springs[0]) if len(springs) == 1 else None
            if res is None:
                K = np.diag(self.omega ** 2)
                for z in springs:
                    K += np.outer(z, z)
                if K.shape[0] <= SMALL_DENSE:       # a chain: no scipy import
                    res = np.linalg.eigh(K)
                else:
                    # scipy's LAPACK, not numpy's: on a loaded machine numpy's
                    # threaded dsyevd took 1-20 ms for these 28 x 28 matrices
                    # against 0.06 ms here
                    from scipy.linalg import eigh
                    res = eigh(K, check_finite=False, driver="evd")
            lam, Psi = res
            basis = (np.maximum(lam, 0.0), Psi, math.sqrt(max(float(lam.max()), 0.0)))
            self._bases[active] = basis
        return basis

    #: skip the probes of a segment that :meth:`_stays_open` proves free of
    #: contact (False probes every segment, as before the bound; the
    #: results are the same, which the tests hold)
    bound_open = True
    #: segments stepped without probes so far
    n_unprobed = 0

    def _stays_open(self, tc, L, seg) -> bool:
        """True where every embedded contact, open at ``tc``, provably stays
        open over the segment ``[tc, tc + L]``.

        Contact ``j``'s penetration is ``alpha(tau) - beta w_p(tau)``
        (``alpha`` the partner's motion with the offset, a polynomial of
        degree <= 3), and the port's displacement ``w_p`` lies within
        ``E_p`` of a polynomial ``Q_p`` (:func:`fem.undamped_envelope`).  So
        with ``f = alpha - beta Q_p`` and ``tau^j`` in ``[0, L^j]``, the
        penetration stays below ``f_0 + sum_j max(f_j, 0) L^j + |beta| E_p``.
        Where that is below ``-margin``, no probe could find the contact
        closed: ``margin`` is the probes' round-off, ``16 eps (m + 4 +
        omega_max L)`` of the size of the terms they add (the phase
        ``omega tau`` is rounded to about ``omega L eps``), plus 1e-9 of it.
        O(m) per contact, against O(m) per probe and ``2 omega_max L``
        probes.  (The compiled kernel's ``_stays_open`` is the same.)"""
        lam, z0, dz0, a, P = seg
        env = undamped_envelope(lam, z0, dz0, a, P, L)
        if env is None:
            return False
        Q, E, size = env
        margin = 1e-9 + 16.0 * np.finfo(float).eps * (
            lam.size + 4 + math.sqrt(float(lam.max(initial=0.0))) * L)
        for e in self._embedded:
            p, nc = e.port, e.normal.conjugate()
            beta = e.side * (nc * self._dirc[p]).real
            motion = reparametrised(e.motion, (tc - e.t0) / e.h, 1.0 / e.h)
            alpha = np.zeros(max(4, motion.size))
            alpha[:motion.size] = e.side * (nc * motion).real
            ref = (nc * complex(*self._ref[p])).real
            S = abs(e.offset) + abs(ref)
            alpha[0] += e.offset - e.side * ref
            f = alpha.copy()
            f[:4] -= beta * Q[:, p]
            powers = L ** np.arange(alpha.size)
            bound = f[0] + float(np.maximum(f[1:], 0.0) @ powers[1:]) + abs(beta) * E[p]
            S += float(np.abs(alpha) @ powers) + abs(beta) * size[p]
            if bound >= -margin * S:
                return False
        return True

    def _segment_load(self, t, h, tc, Gin, active):
        """Modal load over a segment starting at ``tc``, in powers of the time
        since ``tc`` [s] (4, m): the port loads and weight, and each closed
        spring's pull towards its partner's moving point."""
        m = self.n_modes
        a = np.zeros((4, m))
        a[:Gin.shape[0]] = reparametrised(Gin, (tc - t) / h, 1.0 / h)
        for on, e in zip(active, self._embedded):
            if not on:
                continue
            k, r, nc = e.law.contact_stiffness, self._R[e.port], e.normal.conjugate()
            c = (nc * self._dirc[e.port]).real
            ref = complex(*self._ref[e.port])
            xp = (nc * reparametrised(e.motion, (tc - e.t0) / e.h, 1.0 / e.h)).real
            a[0] += e.side * c * k * (e.offset - e.side * (nc * ref).real) * r
            a[:xp.size] += c * k * np.outer(xp, r)
        return a

    def _segment(self, lam, Psi, q, dq, a):
        """A segment's start in the coordinates of its modes ``(lam, Psi)``:
        ``(lam, z0, dz0, load, P)`` with ``P`` (m, n_ports) the ports' shape
        rows in those coordinates.  One change of basis per segment (O(m^2));
        the instants probed inside it then cost O(m) each, for only the
        ports' motion is evaluated there."""
        if Psi is None:                 # the structure's own modes
            return lam, q, dq, a, self._R.T
        return lam, Psi.T @ q, Psi.T @ dq, a @ Psi, Psi.T @ self._R.T

    @staticmethod
    def _port_states(seg, taus):
        """Ports' displacements and velocities along the field at ``taus``
        after a segment's start: (k, n_ports) each."""
        lam, z0, dz0, a, P = seg
        return undamped_response(lam, z0, dz0, a, taus, rows=P)

    @staticmethod
    def _end_state(seg, Psi, tau):
        """Modal state ``(q, dq)`` at ``tau`` after a segment's start."""
        lam, z0, dz0, a, _ = seg
        z, dz = undamped_response(lam, z0, dz0, a, [tau])
        if Psi is None:
            return z[0], dz[0]
        return Psi @ z[0], Psi @ dz[0]

    def _gaps(self, tc, taus, W, DW):
        """Penetration and rate of each embedded contact at ``tc + taus``
        for port displacements ``W`` and velocities ``DW`` along the field
        (k, n_ports): (k, n_embedded) each."""
        dirc = self._dirc
        T = tc + np.asarray(taus, float)
        d = np.empty((len(T), len(self._embedded)))
        dd = np.empty_like(d)
        for j, e in enumerate(self._embedded):
            dp = dirc[e.port]
            d[:, j], dd[:, j] = e.penetrations(
                T, complex(*self._ref[e.port]) + W[:, e.port] * dp, DW[:, e.port] * dp)
        return d, dd

    def _segment_quadratures(self, t, h, tc, L, seg, active, inputs):
        """Add the impulse, first moment and work of the closed springs, and
        the ports' velocity moments, over ``[tc, tc + L]``, in closed form.

        A closed spring's penetration is a polynomial (the partner's motion)
        less ``beta w_p`` (the port's displacement along the field), so each
        integral is a combination of the moments ``int tau^j w_p`` of the
        ports' displacements (:func:`fem.undamped_moments`, O(m)) and of their
        values at the segment's ends; the work ``int f w_p'`` and the velocity
        moments are integrated by parts.  No instant is sampled, so the cost
        does not grow with the fastest mode's frequency."""
        loaded = inputs is not None and bool(np.any(inputs.coeffs))
        if not loaded and not any(active):
            return
        lam, z0, dz0, a, P = seg
        degree = max([3] + [e.motion.size - 2 for on, e in zip(active, self._embedded) if on])
        Wm = undamped_moments(lam, z0, dz0, a, L, P, degree)      # (degree + 1, n_ports)
        (W0, WL), _ = self._port_states(seg, [0.0, L])
        dirc = self._dirc
        ne = len(self._embedded)
        quad = self.aux[:4 * ne].reshape(ne, 4)
        sig = tc - t
        for j, (on, e) in enumerate(zip(active, self._embedded)):
            if not on:
                continue
            k, p, nc = e.law.contact_stiffness, e.port, e.normal.conjugate()
            beta = e.side * (nc * dirc[p]).real
            # penetration d(tau) = alpha(tau) - beta w_p(tau)
            alpha = e.side * (nc * reparametrised(e.motion, (tc - e.t0) / e.h, 1.0 / e.h)).real
            alpha[0] += e.offset - e.side * (nc * complex(*self._ref[p])).real
            q = np.arange(alpha.size)
            ia0 = alpha @ (L ** (q + 1) / (q + 1))
            ia1 = alpha @ (L ** (q + 2) / (q + 2))
            quad[j, 0] += k * (ia0 - beta * Wm[0, p])
            quad[j, 2] += k * (sig * ia0 + ia1 - beta * (sig * Wm[0, p] + Wm[1, p]))
            # int f beta w_p' = beta k ([alpha w_p] - int alpha' w_p - beta [w_p^2] / 2)
            dalpha = alpha[1:] * q[1:]
            aL = float(np.polyval(alpha[::-1], L))
            quad[j, 3] += beta * k * (aL * WL[p] - alpha[0] * W0[p] - dalpha @ Wm[:dalpha.size, p]
                                      - 0.5 * beta * (WL[p] ** 2 - W0[p] ** 2))
        if loaded:
            # int s^j w_p' with s = (tc - t + tau) / h, by parts
            s0, s1 = sig / h, (sig + L) / h
            self.port_moments[0] += (WL - W0) * dirc
            self.port_moments[1] += (s1 * WL - s0 * W0 - Wm[0] / h) * dirc
            self.port_moments[2] += (s1 * s1 * WL - s0 * s0 * W0
                                     - 2.0 * (sig * Wm[0] + Wm[1]) / (h * h)) * dirc

    def _step_closed_form(self, t, h, inputs):
        m = self.n_modes
        Gin = self._modal_force(inputs.coeffs) if inputs is not None else np.zeros((1, m))
        Gin = Gin.copy()
        Gin[0] += self._g_modal
        q, dq = self.x[:m].copy(), self.x[m:].copy()
        self.port_moments = np.zeros((3, self.n_ports), complex)
        tc, t1 = t, t + h
        eps = 1e-13 * max(1.0, abs(t1))
        while t1 - tc > eps:
            L = t1 - tc
            d0, dd0 = self._gaps(tc, [0.0], (self._R @ q)[None], (self._R @ dq)[None])
            active = tuple(bool(x > 0 or (x == 0 and v > 0)) for x, v in zip(d0[0], dd0[0]))
            for j in np.flatnonzero((d0[0] == 0) & (dd0[0] > 0)):
                self.switch_log.append((tc, int(j), True))     # touching and closing now
            if tc == t:
                # closed and closing at the start, open at the end of the last
                # step: the touch fell on the step boundary (a step aimed at a
                # located onset ends there to round-off, and the partner's
                # motion is extrapolated anew), so it is this step's start.
                # (Closed but opening is the new extrapolation's jump just
                # after a release: no touch.)
                for j, on in enumerate(active):
                    if on and self._closed_end[j] == 0 and d0[0, j] != 0 and dd0[0, j] > 0:
                        self.switch_log.append((tc, j, True))
            closed = list(active)
            lam, Psi, wmax = self._active_basis(active)
            seg = self._segment(lam, Psi, q, dq, self._segment_load(t, h, tc, Gin, active))
            n = int(max(math.ceil(2.0 * L * wmax), 2))
            if self.bound_open and not any(active) and self._stays_open(tc, L, seg):
                # every contact open and bound to stay so: the probes would
                # find nothing, and the segment ends as theirs would
                self.n_unprobed += 1
                self._segment_quadratures(t, h, tc, L, seg, active, inputs)
                q, dq = self._end_state(seg, Psi, L * n / n)
                break
            taus = L * np.arange(1, n + 1) / n
            W, DW = self._port_states(seg, taus)
            d, dd = self._gaps(tc, taus, W, DW)
            flips = (d > 0) != np.array(active)
            rows = np.flatnonzero(flips.any(axis=1))
            if not len(rows):
                self._segment_quadratures(t, h, tc, L, seg, active, inputs)
                self._segment_peaks(tc, seg, active, np.concatenate([[0.0], taus]),
                                    np.vstack([d0, d]), np.vstack([dd0, dd]))
                q, dq = self._end_state(seg, Psi, taus[-1])
                break
            i = int(rows[0])
            lo0, hi0 = (taus[i - 1] if i else 0.0), taus[i]
            best, who = hi0, []
            tol = 1e-15 * max(1.0, abs(tc))
            for j in np.flatnonzero(flips[i]):
                hi = self._switch_time(j, active[j], lo0, hi0,
                                       d[i - 1, j] if i else d0[0, j], d[i, j], tol,
                                       lambda tau: self._gaps(tc, [tau], *self._port_states(seg, [tau])))
                if hi < best - 1e-15:
                    best, who = hi, [j]
                elif abs(hi - best) <= 1e-15:
                    who.append(j)
            self._segment_quadratures(t, h, tc, best, seg, active, inputs)
            if any(active):
                d_b, dd_b = self._gaps(tc, [best], *self._port_states(seg, [best]))
                self._segment_peaks(tc, seg, active, np.concatenate([[0.0], taus[:i], [best]]),
                                    np.vstack([d0, d[:i], d_b]), np.vstack([dd0, dd[:i], dd_b]))
            q, dq = self._end_state(seg, Psi, best)
            tc += best
            for j in who:
                self.switch_log.append((tc, int(j), not active[j]))
                closed[j] = not active[j]
        self.x[:m], self.x[m:] = q, dq
        self._closed_end[:] = closed

    def _segment_peaks(self, tc, seg, active, taus, D, V) -> None:
        """Raise :attr:`peak` of each closed contact to its largest
        penetration over a segment, on the exact solution.

        ``taus`` (k,) are instants after the segment's start, from 0 to its
        end, dense enough that the switch search trusts them (half a radian
        of the fastest mode apart); ``D``, ``V`` (k, n_embedded) the
        penetrations and rates there.  A maximum is an end value or lies
        where a rate falls through zero between two instants; it is located
        there by regula falsi (Illinois) on the rate of the exact solution,
        and the penetration taken at the root."""
        for j in np.flatnonzero(active):
            best = float(np.max(D[:, j]))
            for i in np.flatnonzero((V[:-1, j] > 0.0) & (V[1:, j] <= 0.0)):
                best = max(best, self._rate_root_value(tc, seg, j, taus[i], taus[i + 1],
                                                       V[i, j], V[i + 1, j]))
            if best > self.peak[j]:
                self.peak[j] = best

    def _rate_root_value(self, tc, seg, j, lo, hi, v_lo, v_hi) -> float:
        """Penetration of contact ``j`` where its rate, ``v_lo > 0 >= v_hi``
        at ``lo`` and ``hi`` after ``tc``, falls through zero."""
        def at(tau):
            dj, vj = self._gaps(tc, [tau], *self._port_states(seg, [tau]))
            return float(dj[0, j]), float(vj[0, j])

        d_best = -math.inf
        side = 0
        tol = 1e-14 * max(1.0, abs(tc) + hi)
        for _ in range(60):
            x = hi if v_hi == v_lo else (lo * v_hi - hi * v_lo) / (v_hi - v_lo)
            if not lo <= x <= hi:
                x = 0.5 * (lo + hi)
            dx, vx = at(x)
            d_best = max(d_best, dx)
            if vx > 0.0:
                lo, v_lo = x, vx
                if side == 1:
                    v_hi *= 0.5
                side = 1
            else:
                hi, v_hi = x, vx
                if side == -1:
                    v_lo *= 0.5
                side = -1
            if hi - lo <= tol or vx == 0.0:
                break
        return d_best

    @staticmethod
    def _switch_time(j, was_closed, lo, hi, d_lo, d_hi, tol, gaps):
        """Earliest time in ``(lo, hi]`` just past where contact ``j``'s
        penetration changes sign, within ``tol`` [s].

        Safeguarded Newton on the exact solution (``gaps(tau)`` gives the
        penetrations and their rates), started by regula falsi: a few
        evaluations where bisection took fifty.  Each evaluation shrinks the
        bracket ``[lo, hi]`` (``lo`` on the old side, ``hi`` on the new);
        a Newton step that leaves it, or does not halve it, falls back to
        bisection, and a converged iterate is nudged across the root so the
        bracket closes.
        """
        x = lo + (hi - lo) * (d_lo / (d_lo - d_hi)) if d_lo != d_hi else 0.5 * (lo + hi)
        for _ in range(100):
            if not lo < x < hi:
                x = 0.5 * (lo + hi)
            width = hi - lo
            dm, ddm = gaps(x)
            dx, rate = dm[0, j], ddm[0, j]
            if (dx > 0) == was_closed:
                lo = x
            else:
                hi = x
            if hi - lo <= tol:
                break
            xn = x - dx / rate if rate != 0.0 else 0.5 * (lo + hi)
            if abs(xn - x) < tol:                   # at the root: step across it
                xn = x + 0.5 * tol if x == lo else x - 0.5 * tol
            elif not lo < xn < hi or hi - lo > 0.5 * width:
                xn = 0.5 * (lo + hi)
            x = xn
        return hi

    #: Gauss-Legendre nodes and weights on [0, 1] (three points)

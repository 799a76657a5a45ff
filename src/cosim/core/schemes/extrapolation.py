"""What a side is given over a macro step it has not seen yet: the coupler
forces extrapolated from their history (order 0, 1 or 2), and a partner
port's motion, by cubic Hermite once the partner has stepped, else
extrapolated from the step's start.

:class:`InputExtrapolation` is a mixin of
:class:`~cosim.core.schemes.base.CoSimulationScheme`; it reads the macro
loop's state (``_state``, a :class:`~cosim.core.schemes.step_control.StepState`).
"""
from __future__ import annotations

import numpy as np

from cosim.core.hermite import hermite_coefficients, hermite_point

__all__ = ["extrapolation_coeffs", "InputExtrapolation"]


def extrapolation_coeffs(hist: list, order: int, ratio: float = 1.0) -> np.ndarray:
    """Coefficients (order + 1, n) of the force over the next step, in the
    step's normalised time ``s`` in [0, 1], extrapolated from the history
    ``[..., f_{n-1}, f_n]`` at equal spacing; ``ratio`` is the next step's
    length over the previous one's."""
    p = min(order, len(hist) - 1)
    fn = hist[-1]
    if p == 0:
        return fn[None, :]
    if p == 1:
        return np.stack([fn, (fn - hist[-2]) * ratio])
    f1, f2 = hist[-2], hist[-3]
    return np.stack([fn, 0.5 * (3 * fn - 4 * f1 + f2) * ratio,
                     0.5 * (fn - 2 * f1 + f2) * ratio * ratio])


class InputExtrapolation:
    """The input-extrapolation methods of a co-simulation scheme."""

    def _starting_history(self, system, d, dd, f, H):
        """Force history to extrapolate the first steps from.  A contact
        closed at the start has a force rate ``df/dt = f'(d) d'`` (taken by a
        central difference of the law along the motion), so a point one
        step back, ``f - H df/dt``, lets the first window extrapolate
        linearly instead of holding the force: held, its O(H) error would
        cap quadratic extrapolation at second order from a generic start."""
        if self.extrapolation_order == 0 or not np.any(f):
            return [f]
        rate = self._law_rates(system, d, dd, f)
        return [f - H * rate, f]

    @staticmethod
    def _law_rates(system, d, dd, f) -> np.ndarray:
        """Each closed contact's force rate ``f'(d) d'`` [N/s] from its law
        (a central difference along the motion); zero elsewhere."""
        rate = np.zeros_like(f)
        for c in np.flatnonzero(f[:system.n_contacts]):
            if system.links[c].connection is not None:
                continue                # a grasp or friction: held for the first step
            law = system.links[c].contact.law
            eps = 1e-6 * max(abs(d[c]), 1e-12)
            fp = float(law.force_active(d[c] + eps, dd[c]))
            fm = float(law.force_active(d[c] - eps, dd[c]))
            rate[c] = (fp - fm) / (2 * eps) * dd[c]
        return rate

    def onset_history(self, system, d, dd, f, onsets, H):
        """The force history to extrapolate the next step from when the
        coupler contacts ``onsets`` start it at their onset
        (``land_onsets``): as at a run's start (:meth:`_starting_history`,
        points ``H`` apart), with each open one of ``onsets`` given the
        law's force at touch-down (``force_active(0, d')``: a Kelvin-Voigt
        law's ``c d'``) and its one-sided rate there.  The recorded forces
        are not changed: only what the next step is given."""
        f = np.array(f, dtype=float)
        rate = self._law_rates(system, d, dd, f)
        for c in onsets:
            if f[c] != 0.0 or system.links[c].connection is not None:
                continue                # closed in an aimed step: its own force
            law = system.links[c].contact.law
            v = max(float(dd[c]), 0.0)
            eps = max(1e-6 * v * H, 1e-300)
            f0 = max(float(law.force_active(0.0, v)), 0.0)
            f[c] = f0
            rate[c] = (max(float(law.force_active(eps, v)), 0.0) - f0) / eps * v
        if self.extrapolation_order == 0:
            return [f]
        return [f - H * rate, f]

    def _extrapolated(self, ratio: float) -> np.ndarray:
        """Force polynomials for the next step.

        When the step grows (``ratio > 1``, as step control lengthens it after
        a release), a contact open at ``t`` is held at zero: extrapolating its
        falling force over the longer step would pull hard.  With equal steps
        the extrapolation is kept: its small overshoot into tension after
        release offsets its lag before, and holding it would double the
        rebound error of linear extrapolation."""
        co = extrapolation_coeffs(self._state.hist, self.extrapolation_order, ratio)
        if ratio > 1.0 + 1e-9:
            co[1:, self._state.hist[-1] == 0.0] = 0.0
        return co

    def _set_partner_motion(self, system, c: int, t: float, h: float, after=None) -> None:
        """Give hosted contact ``c``'s host the partner port's motion over
        ``[t, t + h]``: the cubic Hermite between its outputs at ``t`` and
        ``after`` (the partner's outputs at ``t + h``, when it has already
        stepped), else extrapolated from ``t``: ``x + v tau`` at order 0,
        ``+ a tau^2 / 2`` at order >= 1 with ``a`` from the last two
        velocities."""
        _, _, partner, port, emb = system.hosted[c]
        pos, vel = self._state.outs[partner]
        x0, v0 = complex(*pos[port]), complex(*vel[port])
        if after is not None:
            x1, v1 = complex(*after[0][port]), complex(*after[1][port])
            emb.set_motion(t, h, hermite_coefficients(x0, v0, x1, v1, h))
            return
        a = 0j
        st = self._state
        if self.extrapolation_order > 0 and st.outs_prev is not None:
            a = (v0 - complex(*st.outs_prev[partner][1][port])) / st.h_prev_step
        emb.set_motion(t, h, (x0, h * v0, 0.5 * a * h * h))

    def _predicted_outputs(self, system, s: int, tau: float, t: float, h: float, after: dict,
                           own_ahead: float = 0.0):
        """Every subsystem's port outputs at ``tau`` in ``[t, t + h]`` as
        subsystem ``s`` sees them: its own now (moved on by ``own_ahead``
        seconds at its velocity), a subsystem that has stepped to ``t + h``
        by cubic Hermite between ``t`` and ``t + h``, one that has not
        extrapolated from ``t`` (with the acceleration of the last two
        velocities at order >= 1), a rigid one as it is."""
        out = []
        sg = (tau - t) / h
        for p, sub in enumerate(system.subsystems):
            if p == s or sub.rigid:
                pos, vel = sub.outputs(sub.t, sub.x)
                if p == s and own_ahead:
                    pos = pos + own_ahead * vel
                out.append((pos, vel))
                continue
            x0, v0 = self._state.outs[p]
            if p in after:
                out.append(hermite_point(x0, v0, *after[p], h, sg))
                continue
            a = 0.0
            if self.extrapolation_order > 0 and self._state.outs_prev is not None:
                a = (v0 - self._state.outs_prev[p][1]) / self._state.h_prev_step
            dt = tau - t
            out.append((x0 + dt * v0 + 0.5 * dt * dt * a, v0 + dt * a))
        return out

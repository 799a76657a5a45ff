"""Explicit co-simulation: Jacobi (parallel) and Gauss-Seidel (sequential)."""
from __future__ import annotations

from typing import ClassVar

import numpy as np

from cosim.core import preflight
from .base import CoSimulationScheme, Option

__all__ = ["Jacobi", "GaussSeidel"]


class Jacobi(CoSimulationScheme):
    """Every subsystem steps at once with the contact forces extrapolated
    from the last communication points (order 0: held; 1: linear; 2:
    quadratic)."""

    name: ClassVar[str] = "jacobi"
    explicit: ClassVar[bool] = True
    compiled_loop: ClassVar[bool] = True

    def advance(self, system, t, h, ratio):
        coeffs = self._extrapolated(ratio)
        for c in system.hosted:
            self._set_partner_motion(system, c, t, h)
        impulse = np.zeros(system.n_rows)
        for s in self._moving(system):
            got = self._step_side(system, s, t, h, coeffs, {})
            side_a = [r for r in system.coupler_rows
                      if system.links[system.row_contact[r]].sub_a == s]
            impulse[side_a] = got[side_a]
        return impulse


class GaussSeidel(CoSimulationScheme):
    """Subsystems step one after the other (``sequence``, declaration order by
    default).  A subsystem whose contact partner has already stepped (a rigid
    partner always has) receives the force interpolated linearly from its
    value at ``t`` to the value the law gives with the partner's new outputs
    and its own outputs extrapolated (held at order 0, moved by its velocity
    at order 1 and 2); other contacts are extrapolated as in Jacobi."""

    name: ClassVar[str] = "gauss_seidel"
    explicit: ClassVar[bool] = True
    compiled_loop: ClassVar[bool] = True
    options: ClassVar[dict] = {**CoSimulationScheme.options, "sequence": Option(
        list, None, lambda v: all(isinstance(x, str) for x in v), "a list of subsystem names")}

    def _order(self, system):
        if not self.sequence:
            return self._moving(system)
        return [system.names.index(n) for n in self.sequence
                if not system.subsystems[system.names.index(n)].rigid]

    def _partner_first(self, system, c):
        return preflight.partner_first(system, c, self.name, self.extrapolation_order)

    def advance(self, system, t, h, ratio):
        base = self._extrapolated(ratio)
        width = max(2, base.shape[0])
        # per row, the impulse that side `a` (else `b`) receives
        applied = np.zeros(system.n_rows)
        done = {s for s, sub in enumerate(system.subsystems) if sub.rigid}
        outs_n = self._state.outs
        after = {}                      # outputs at t + h of the subsystems done
        imp0 = self._hosted_impulses(system)
        for s in self._order(system):
            coeffs = np.zeros((width, system.n_rows))
            coeffs[:base.shape[0]] = base
            for c, (host, _, partner, _, _) in system.hosted.items():
                if host == s:           # the partner's motion: its own if it has stepped
                    self._set_partner_motion(system, c, t, h, after.get(partner))
                elif partner == s and host in done:     # the force the host exerted
                    coeffs[:, c] = 0.0
                    coeffs[:2, c] = system.hosted_force(c, h, imp0[c])
            mine = self.rows_of(system, s)
            if mine:
                pred = list(system.outputs())
                pos, vel = outs_n[s]
                if self.extrapolation_order > 0:
                    pos = pos + h * vel
                pred[s] = (pos, vel)
                d, dd = system.penetrations(pred)
                f_pred = system.forces(d, dd)
            for c in mine:
                ln = system.links[system.row_contact[c]]
                other = ln.sub_b if ln.sub_a == s else ln.sub_a
                if other in done:
                    ftilde = float(f_pred[c])
                    coeffs[:, c] = 0.0
                    coeffs[0, c] = self._f[c]
                    coeffs[1, c] = ftilde - self._f[c]
            sub = system.subsystems[s]
            got = self._step_side(system, s, t, h, coeffs, after)
            for c in mine:
                ln = system.links[system.row_contact[c]]
                if ln.sub_a == s or system.subsystems[ln.sub_a].rigid:
                    applied[c] = got[c]
            done.add(s)
            after[s] = sub.outputs(sub.t, sub.x)
        return applied

"""Implicit co-simulation: repeat the macro step until the forces agree."""
from __future__ import annotations

from typing import ClassVar

import numpy as np

from .base import CoSimulationScheme, CouplingError, Option, _pos

__all__ = ["Implicit"]


class Implicit(CoSimulationScheme):
    """Fixed-point iteration on the contact forces at the step's end.

    Each pass restores the saved states, steps every subsystem with the
    force interpolated linearly from ``f(t)`` to the current guess of
    ``f(t + h)``, and compares the guess with the law evaluated on the new
    outputs.  The guess is relaxed with Aitken's dynamic factor (Irons and
    Tuck 1969; Kuettler and Wall 2008, eq. 44).  The predictor is the force
    extrapolated at ``extrapolation_order``.
    """

    name: ClassVar[str] = "implicit"
    explicit: ClassVar[bool] = False
    options: ClassVar[dict] = {
        **CoSimulationScheme.options,
        "extrapolation_order": Option(int, 1, lambda v: v in (0, 1, 2), "0, 1 or 2"),
        "max_iterations": Option(int, 50, lambda v: v >= 1, ">= 1"),
        "tolerance": Option(float, 1e-8, _pos, "> 0 (relative)"),
        "force_tolerance": Option(float, 1e-9, _pos, "> 0 N"),
        "relaxation": Option(float, 0.5, lambda v: 0 < v <= 1, "in (0, 1]"),
    }

    def advance(self, system, t, h, ratio):
        coupler = system.coupler_rows      # normal and tangential rows exchanged
        moving = self._moving(system)
        f_n = self._f
        guess = np.sum(self._extrapolated(ratio), axis=0)
        saved = system.get_state()
        omega = self.relaxation
        r_prev = None
        for it in range(1, self.max_iterations + 1):
            if it > 1:
                system.set_state(saved)
            coeffs = np.stack([f_n, guess - f_n])
            for s in moving:
                system.subsystems[s].step(t, h, system.step_input(s, t, h, coeffs))
            if not len(coupler):
                self.n_iterations += it
                return coeffs
            d, dd = system.penetrations(system.outputs())
            f_new = system.forces(d, dd)
            r = (f_new - guess)[coupler]
            scale = np.maximum(np.abs(f_new[coupler]), np.abs(guess[coupler]))
            if np.all(np.abs(r) <= self.force_tolerance + self.tolerance * scale):
                self.n_iterations += it
                return coeffs
            if r_prev is not None:
                dr = r - r_prev
                denom = float(dr @ dr)
                if denom > 0:
                    omega = -omega * float(r_prev @ dr) / denom
            r_prev = r
            guess = guess.copy()
            guess[coupler] += omega * r
        worst = int(coupler[np.argmax(np.abs(r))])
        raise CouplingError(
            f"implicit coupling did not converge at t = {t:.6g} s within "
            f"{self.max_iterations} iterations: contact `{system.row_names[worst]}` "
            f"has a force residual of {abs(r).max():.3g} N. Reduce `scheme.macro_step` or "
            f"raise `scheme.max_iterations`.")

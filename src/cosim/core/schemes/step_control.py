"""Macro-step control of the co-simulation schemes: short steps while an
exchanged contact is closed or about to close, a rejected step retried to
end at the located or predicted onset, and the interface error controller.

:class:`MacroStepControl` is a mixin of
:class:`~cosim.core.schemes.base.CoSimulationScheme`; its methods read the
macro loop's state (``_system``, ``_hist``, ``_f`` and the step-control
attributes the base class declares) and add no call to a step.
"""
from __future__ import annotations

import numpy as np

__all__ = ["MacroStepControl"]


class MacroStepControl:
    """The macro-step control methods of a co-simulation scheme."""

    def _predicted_end_forces(self, system, ratio):
        """Force each coupler contact is predicted to carry at the step's
        end: the extrapolated force at ``s = 1``.  (A hosted contact's
        prediction is the force its host saw at the step's end, against the
        partner's extrapolated motion; it is read after the step.)"""
        return np.sum(self._extrapolated(ratio), axis=0)

    def _error_control(self, f, predicted, h):
        """Interface error estimate (predictor against corrector): the
        largest difference between the force each exchanged contact was
        predicted to carry at the step's end and the force it carries,
        relative to the largest force it has carried so far.  Returns a
        shorter step to retry with when it exceeds ``interface_tolerance``,
        else None, and sets the next contact step from it (Schierz, Arnold
        and Clauss 2012: elementary controller on the extrapolation error,
        whose order is ``extrapolation_order + 1``).  The step in contact
        stays between ``contact_step / 64`` and ``contact_step``."""
        c = self._system.exchanged
        if self._f_scale is None:
            self._f_scale = np.zeros(self._system.n_rows)
        self._f_scale[c] = np.maximum(self._f_scale[c], np.abs(f[c]))
        scale = np.maximum(self._f_scale[c], 1e-300)
        err = float(np.max(np.abs(f[c] - predicted[c]) / scale)) if len(c) else 0.0
        if not np.any(self._f_scale[c] > 0):
            return None
        tol, p = self.interface_tolerance, self.extrapolation_order + 1
        fac = 2.0 if err == 0 else min(2.0, max(0.2, 0.9 * (tol / err) ** (1.0 / (p + 1))))
        floor = self.contact_step / 64.0
        if err > tol and h > floor * (1 + 1e-9):
            return max(fac * h, floor)
        # never above contact_step: an end-point estimate cannot see a
        # contact that opens and closes again inside a longer step
        self._h_adapt = min(max(fac * h, floor), self.contact_step)
        return None

    def _controlled_step(self, d, dd, f, remaining):
        """The next macro step: the onset found by a rejected step, else
        ``contact_step`` while a coupler contact is closed or would close
        within a long step (penetration predicted linearly), else
        ``macro_step``."""
        if self._h_next is not None:
            h, self._h_next = self._h_next, None
            return min(h, remaining)
        c = self._system.exchanged
        H = self.macro_step
        # short steps while a contact is closed, was closed a step ago (so the
        # extrapolation history is clear of force before the step grows), or
        # would close within a long step
        recent = len(self._hist) > 1 and np.any(self._hist[-2][c] != 0)
        normal = c[c < self._system.n_contacts]
        if np.any(self._system.in_touch(f)[self._system.row_contact[c]]) or recent \
                or np.any(d[normal] + H * dd[normal] > 0):
            h = self.contact_step
            if self.interface_tolerance and self._h_adapt is not None:
                h = self._h_adapt
            return min(h, remaining)
        self._h_adapt = None            # contacts open: start again from contact_step
        return min(H, remaining)

    def _onset(self, d0, dd0, d1, dd1, t, h):
        """Length of the step to retry after an exchanged contact closed
        inside a step of length ``h``, and whether it ends at the onset;
        None if no contact closed in the step.

        A hosted contact's onset was located by its host's integrator: the
        retried step ends there and is accepted.  For a coupler contact, the
        end state of the rejected step already holds the contact's response,
        so the onset is predicted from the free motion before it:
        ``d0 + dd0 tau + a tau^2 / 2 = 0``, the relative acceleration ``a``
        from the last two outputs (exact under a constant push).  When every
        closing contact has a root inside the step, the retried step ends
        at the earliest and is accepted as it is.  Otherwise (no history
        yet, or no root) it is half the step, or the earliest root if
        sooner, and it is checked again like any long step: a guess must
        not carry a contact through its onset with the force still at zero."""
        system = self._system
        hosted = [ts - t for c, (host, slot, _, _, _) in system.hosted.items()
                  for ts, j, on in system.subsystems[host].switch_log if j == slot and on]
        if hosted:
            return max(min(hosted), 1e-12 * h), True
        c = system.coupler
        closing = c[(d0[c] <= 0) & (d1[c] > 0)]
        if not len(closing):
            return None
        found, all_found = [], True
        for i in closing:
            a = 0.0
            if self._dd_prev is not None:
                a = (dd0[i] - self._dd_prev[i]) / self._h_prev_step
            roots = np.roots([0.5 * a, dd0[i], d0[i]]) if a else (
                [-d0[i] / dd0[i]] if dd0[i] > 0 else [])
            tau = [r.real for r in np.atleast_1d(roots) if abs(r.imag) < 1e-12 and
                   0 < r.real < h]
            found += tau
            all_found = all_found and bool(tau)
        if all_found:
            return max(min(found), 1e-12 * h), True
        return max(min([0.5 * h, *found]), 1e-12 * h), False

    def _touched(self, stepped) -> bool:
        """Whether a long step gave a coupler contact open at its start a
        force: the contact touched inside the step, though it may be open
        again at the end (Gauss-Seidel's force interpolated towards a partner
        that has stepped, an implicit iterate), and the step must be
        shortened like one over an onset."""
        r = self._system.coupler_rows
        return bool(np.any((self._f[r] == 0.0) & (stepped[r] != 0.0)))

    def _overshot(self, d0, d1, dd1, h):
        """Check a step aimed at a predicted coupler onset: the prediction
        (free motion with a constant relative acceleration) can fall late when
        a side vibrates, and the step then carries the contact closed with no
        force in it.  When a coupler contact closed more than ``contact_step``
        before the step's end (its penetration over its rate, the time since
        touch-down at that rate), returns half the step, to be checked again
        like any long step; else None."""
        c = self._system.coupler
        late = (d0[c] <= 0) & (d1[c] > np.maximum(dd1[c], 0.0) * self.contact_step)
        if np.any(late):
            return 0.5 * h, False
        return None

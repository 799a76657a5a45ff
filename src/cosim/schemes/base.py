"""Base classes of coupling schemes."""
from __future__ import annotations

import math
from abc import ABC, abstractmethod
from typing import Any, Callable, ClassVar, NamedTuple

import numpy as np

from .. import preflight
from ..connections import stiffest_normal
from ..errors import CouplingError, UnsafeStepError

__all__ = ["Option", "CouplingScheme", "CoSimulationScheme", "UnsafeStepError", "CouplingError",
           "extrapolation_coeffs"]


class Option(NamedTuple):
    """A scheme option: its type, default, check and the rule it states."""

    kind: type
    default: Any
    check: Callable[[Any], bool]
    rule: str


def _pos(v):
    return v > 0 and math.isfinite(v)




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


class CouplingScheme(ABC):
    """A way of advancing a :class:`~cosim.system.CoupledSystem` in time.

    Subclasses declare ``name`` and the option names they accept in
    ``options``; :meth:`run` fills a :class:`~cosim.recorder.Recorder` and
    returns the counters ``n_windows``, ``n_iterations``, ``n_rejected``.
    """

    name: ClassVar[str] = ""
    #: option name -> Option; the scene loader validates them.
    options: ClassVar[dict] = {}
    explicit: ClassVar[bool] = False

    def __init__(self, **opts):
        unknown = set(opts) - set(self.options)
        if unknown:
            raise TypeError(f"scheme `{self.name}` takes no options {sorted(unknown)}; "
                            f"valid options are {sorted(self.options)}")
        for key, opt in self.options.items():
            value = opts.get(key, opt.default)
            if value is not None and not opt.check(value):
                raise ValueError(f"`{key}` of scheme `{self.name}` must be {opt.rule}, "
                                 f"got {value!r}")
            setattr(self, key, value)

    @abstractmethod
    def run(self, system, t_end: float, recorder) -> dict:
        """Advance the system to ``t_end``, recording as it goes."""


class CoSimulationScheme(CouplingScheme):
    """Macro-step loop shared by the co-simulation schemes.

    Contacts placed ``coupler`` are exchanged as forces: at each
    communication point the scheme computes them from the subsystems'
    outputs and hands each side a force polynomial for the next step;
    :meth:`advance` decides which.
    """

    options: ClassVar[dict] = {
        "macro_step": Option(float, None, _pos, "> 0 s"),
        "extrapolation_order": Option(int, 0, lambda v: v in (0, 1, 2), "0, 1 or 2"),
        "max_energy_gain": Option(float, 0.01, lambda v: v >= 0 and math.isfinite(v), ">= 0"),
        "accept_unsafe_step": Option(bool, False, lambda v: True, "true or false"),
        "contact_step": Option(float, None, _pos, "> 0 s"),
    }

    def preflight(self, system) -> None:
        """Refuse a macro step that is too large for a contact's stiffness."""
        if not self.explicit or self.accept_unsafe_step:
            return
        H = self.contact_step or self.macro_step     # the step used while in contact
        for c in system.coupler:
            ln = system.links[c]
            n = ln.contact.normal
            mob = (system.subsystems[ln.sub_a].port_mobility(ln.port_a, n)
                   + system.subsystems[ln.sub_b].port_mobility(ln.port_b, n))
            if mob <= 0:
                continue
            m, (k, cd) = 1.0 / mob, stiffest_normal(ln)     # the law's, or a grasp's
            if not (math.isfinite(k) and math.isfinite(cd)):
                raise UnsafeStepError(
                    f"contact `{ln.contact.name}`: law `{ln.contact.law.name}` has no "
                    f"linearised stiffness, so the pre-flight check cannot judge macro step "
                    f"{H:.3g} s of scheme `{self.name}`; give the law a "
                    f"`reference_penetration`, use the `implicit` scheme, or set "
                    f"`scheme.accept_unsafe_step = true`")
            partner_first = self._partner_first(system, c)
            if preflight.is_safe(m, k, cd, H, self.extrapolation_order, self.max_energy_gain,
                                 partner_first):
                continue
            hmax = preflight.largest_safe_step(m, k, cd, H, self.extrapolation_order,
                                               self.max_energy_gain, partner_first)
            gain = preflight.contact_energy_gain(m, k, cd, H, self.extrapolation_order,
                                                 partner_first)
            raise UnsafeStepError(
                f"contact `{ln.contact.name}`: macro step {H:.3g} s is too large for scheme "
                f"`{self.name}` (extrapolation order {self.extrapolation_order}): contact "
                f"frequency omega = {math.sqrt(k / m):.4g} rad/s with reduced mass {m:.4g} kg; "
                f"one contact would change the energy by a factor {gain:.4g} "
                f"(allowed 1 + {self.max_energy_gain:g}). The largest safe macro step is "
                f"{hmax:.3g} s. Use a smaller `scheme.macro_step`, the `implicit` scheme, "
                f"or set `scheme.accept_unsafe_step = true` to run anyway.")

    def _partner_first(self, system, c) -> bool:
        return False

    @abstractmethod
    def advance(self, system, t: float, h: float, ratio: float) -> np.ndarray:
        """Step every subsystem over [t, t + h]; return the polynomial
        coefficients (order + 1, n_contacts) of the coupler forces applied to
        the contacts' side ``a``, for the impulse ledger."""

    def run(self, system, t_end, recorder):
        H = self.macro_step
        if H is None:
            raise ValueError(f"scheme `{self.name}` needs `macro_step` [s]")
        self.preflight(system)
        self._system = system
        self.n_iterations = 0
        nc = system.n_contacts
        coupler = system.coupler
        outs = system.outputs()
        d, dd = system.penetrations(outs)
        f = system.forces(d, dd)
        self._outs, self._f = outs, f
        self._hist = [f]
        impulse, diss = np.zeros(nc), np.zeros(nc)
        p_prev = system.dissipation_rates(f, d, dd)[coupler]
        recorder.record(0.0, d, dd, f, impulse, diss, self._internal(system))
        controlled = self.contact_step is not None and len(coupler) > 0
        n = max(1, math.ceil(t_end / H - 1e-9))
        h_prev = H
        k, t, n_rejected = 0, 0.0, 0
        while True:
            if controlled:
                if t_end - t <= 1e-12 * H:
                    break
                h = self._controlled_step(d, dd, f, t_end - t)
                saved = system.get_state()
            else:
                if k >= n:
                    break
                t = k * H
                h = min(H, t_end - t)
                if h <= 1e-12 * H:
                    break
            if system._followers:
                system.update_followers(self._outs)
            coeffs = self.advance(system, t, h, h / h_prev)
            outs = system.outputs()
            d1, dd1 = system.penetrations(outs)
            f = system.forces(d1, dd1)
            if controlled and h > self.contact_step and not self._aimed:
                onset = self._onset(d, dd, d1, dd1, h)
                if onset is not None:           # a contact closed inside a long step
                    system.set_state(saved)
                    n_rejected += 1
                    self._h_next, self._aimed = onset, True
                    self._outs = system.outputs()
                    continue
            self._aimed = False
            self._dd_prev, self._h_prev_step = dd.copy(), h
            d, dd = d1, dd1
            if system.connections is not None and system.switch_modes(t + h, d, dd):
                d, dd = system.penetrations(outs)       # a grasp moves the tangential anchor
                f = system.forces(d, dd)
            h_prev = h
            k += 1
            self._outs, self._f = outs, f
            self._hist = (self._hist + [f])[-3:]
            if len(coupler):
                j = np.arange(coeffs.shape[0])[:, None]
                impulse[coupler] += h * np.sum(coeffs[:, coupler] / (j + 1), axis=0)
                p_now = system.dissipation_rates(f, d, dd)[coupler]
                diss[coupler] += 0.5 * h * (p_prev + p_now)
                p_prev = p_now
            emb = system.embedded_quadratures()
            for c, (s, slot) in system.embedded.items():
                impulse[c], diss[c] = emb[c]
                sub = system.subsystems[s]
                rigid = system.links[c].contact.law.rigid
                for ts, j, on in sub.switch_log:
                    if j == slot and not rigid:
                        recorder.edge(c, ts, on)
                    elif j == slot and on:            # an impact is an instant
                        recorder.edge(c, ts, True)
                        recorder.edge(c, ts, False)
            for s in self._moving(system):
                recorder.impacts += getattr(system.subsystems[s], "impact_log", [])
            if not (np.all(np.isfinite(d)) and np.all(np.isfinite(dd))):
                raise CouplingError(f"non-finite state at t = {t + h:.6g} s")
            recorder.record(t + h, d, dd, f, impulse, diss, self._internal(system))
            if controlled:
                t = t + h
        return {"n_windows": k, "n_iterations": self.n_iterations, "n_rejected": n_rejected}

    _h_next = None
    _aimed = False          # the current step was aimed at an onset: accept it
    _dd_prev = None
    _h_prev_step = None

    def _controlled_step(self, d, dd, f, remaining):
        """The next macro step: the onset found by a rejected step, else
        ``contact_step`` while a coupler contact is closed or would close
        within a long step (penetration predicted linearly), else
        ``macro_step``."""
        if self._h_next is not None:
            h, self._h_next = self._h_next, None
            return min(h, remaining)
        c = self._system.coupler
        H = self.macro_step
        # short steps while a contact is closed, was closed a step ago (so the
        # extrapolation history is clear of force before the step grows), or
        # would close within a long step
        recent = len(self._hist) > 1 and np.any(self._hist[-2][c] > 0)
        if np.any(self._system.in_touch(f)[c]) or recent or np.any(d[c] + H * dd[c] > 0):
            return min(self.contact_step, remaining)
        return min(H, remaining)

    def _onset(self, d0, dd0, d1, dd1, h):
        """Length of step that ends where the first coupler contact closes, or
        None if none closed in the step.

        The end state of the rejected step already holds the contact's
        response, so the onset is predicted from the free motion before it:
        ``d0 + dd0 tau + a tau^2 / 2 = 0``, the relative acceleration ``a``
        from the last two outputs (exact under a constant push).  Without a
        root inside the step, half the step."""
        c = self._system.coupler
        closing = c[(d0[c] <= 0) & (d1[c] > 0)]
        if not len(closing):
            return None
        best = 0.5 * h
        for i in closing:
            a = 0.0
            if self._dd_prev is not None:
                a = (dd0[i] - self._dd_prev[i]) / self._h_prev_step
            roots = np.roots([0.5 * a, dd0[i], d0[i]]) if a else (
                [-d0[i] / dd0[i]] if dd0[i] > 0 else [])
            tau = [r.real for r in np.atleast_1d(roots) if abs(r.imag) < 1e-12 and
                   0 < r.real < h]
            if tau:
                best = min(best, min(tau)) if best != 0.5 * h else min(tau)
        return max(best, 1e-12 * h)

    @staticmethod
    def _internal(system):
        led = [s.ledger() for s in system.subsystems]
        return sum(a for a, _ in led), sum(b for _, b in led)

    def _extrapolated(self, ratio: float) -> np.ndarray:
        """Force polynomials for the next step.

        When the step grows (``ratio > 1``, as step control lengthens it after
        a release), a contact open at ``t`` is held at zero: extrapolating its
        falling force over the longer step would pull hard.  With equal steps
        the extrapolation is kept: its small overshoot into tension after
        release offsets its lag before, and holding it would double the
        rebound error of linear extrapolation."""
        co = extrapolation_coeffs(self._hist, self.extrapolation_order, ratio)
        if ratio > 1.0 + 1e-9:
            co[1:, self._hist[-1] == 0.0] = 0.0
        return co

    def _moving(self, system):
        return [s for s, sub in enumerate(system.subsystems) if not sub.rigid]

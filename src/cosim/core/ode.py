"""Time steppers that subsystems use inside a co-simulation step.

Each stepper advances ``y' = f(t, y)`` from ``t0`` to ``t1`` exactly (it lands
on the macro-step boundary) and, when given a switch function, locates the
instant a contact opens or closes inside a sub-step and restarts there, so a
penalty force's kink is never stepped over.
"""
from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Callable, ClassVar

import numpy as np

from cosim.core.hermite import hermite_value, substep_peaks
from cosim.core.registry import Registry

__all__ = ["TimeStepper", "RK4", "ScipyStepper", "INTEGRATORS", "get_integrator",
           "substep_peaks"]


@dataclass(frozen=True)
class TimeStepper(ABC):
    """Base class of fixed-step integrators.

    Parameters
    ----------
    max_step : float
        Largest sub-step [s]; a step of length ``h`` is cut into
        ``ceil(h / max_step)`` equal sub-steps.
    free_step : float, optional
        Largest sub-step [s] of a step that starts with every contact
        evaluated inside open (``integrate(..., coarse=True)``): free flight
        is smooth, so it may take longer sub-steps than a stiff contact.  A
        coarse sub-step over which a contact switches is redone, and the rest
        of the step taken, with ``max_step``, so contacts are always
        integrated at ``max_step``.  Default: ``max_step``.
    """

    max_step: float
    free_step: float | None = None
    order: ClassVar[int] = 0
    name: ClassVar[str] = ""

    def __post_init__(self):
        for key in ("max_step", "free_step"):
            v = getattr(self, key)
            if key == "free_step" and v is None:
                continue
            if not (isinstance(v, (int, float)) and not isinstance(v, bool)
                    and math.isfinite(v) and v > 0):
                raise ValueError(f"`{key}` must be > 0 s, got {v!r}")

    @abstractmethod
    def _single(self, f, t, y, h, k1):
        """One step of length ``h`` from ``(t, y)``; ``k1 = f(t, y)`` is given."""

    def integrate(self, f: Callable, t0: float, y0: np.ndarray, t1: float,
                  switch: Callable | None = None,
                  on_switch: Callable | None = None, coarse: bool = False,
                  probe: Callable | None = None, peak: np.ndarray | None = None) -> np.ndarray:
        """Advance ``y0`` from ``t0`` to ``t1``.

        Parameters
        ----------
        f : callable ``f(t, y) -> dy/dt``
        switch : callable ``switch(t, y) -> array`` or None
            Continuous functions whose sign changes mark a switch of the
            right-hand side (a contact opening or closing).  A sub-step over
            which a sign changes is redone in two pieces that meet at the
            switch, located on the cubic Hermite interpolant of the sub-step.
        on_switch : callable ``on_switch(t, index, positive, y)`` or None
            Told of each located switch: its time, the switch function's
            index, its new sign and the state there.  It may return a new
            state (an impact's jump of the velocities); the integration then
            goes on from it.
        coarse : bool
            The switch functions are positive where a contact is closed: if
            none is at ``t0``, sub-steps of ``free_step`` until one changes
            sign (see the class).
        probe : callable ``probe(t, y) -> (d, v)`` or None
            Quantities to watch (contacts' penetrations) and their rates at
            ``(t, y)``.  It is called only right after ``f(t, y)``, so it may
            return what that evaluation found.
        peak : (n,) float array or None
            With ``probe``: raised in place to the largest value of each
            watched quantity over the step, located on each accepted
            sub-step's cubic Hermite by :func:`~cosim.core.hermite.substep_peaks`.
        """
        t, y = t0, y0
        k1 = f(t, y)
        watch = probe is not None and peak is not None
        pv = probe(t, y) if watch else None
        s0 = None if switch is None else switch(t, y)
        step = self.max_step
        if coarse and self.free_step is not None and (s0 is None or not (s0 > 0).any()):
            step = self.free_step
        n = max(1, math.ceil((t1 - t0) / step - 1e-9))
        dt = (t1 - t0) / n
        i = 0
        while i < n:
            te = t1 if i == n - 1 else t0 + (i + 1) * dt
            h = te - t
            y1 = self._single(f, t, y, h, k1)
            k1n = f(te, y1)
            if s0 is not None:
                s1 = switch(te, y1)
                flipped = (s0 > 0) != (s1 > 0)
                if flipped.any() and step > self.max_step:
                    # a contact switches within a coarse sub-step: from its
                    # start, the rest of the step at max_step
                    step = self.max_step
                    t0, i = t, 0
                    n = max(1, math.ceil((t1 - t0) / step - 1e-9))
                    dt = (t1 - t0) / n
                    continue
                if flipped.any():
                    ts = self._locate(switch, t, y, k1, y1, k1n, h, s0, flipped)
                    if ts is not None:
                        y = self._single(f, t, y, ts - t, k1)
                        k1 = f(ts, y)
                        if watch:
                            pv = self._watch(probe, peak, pv, ts, y, ts - t)
                        t = ts
                        s_new = switch(t, y)
                        if on_switch is not None:
                            y, k1, s_new = self._notify(f, switch, on_switch, t, y, k1,
                                                        s0, s_new)
                            if watch:
                                pv = probe(t, y)      # after a jump of the rates
                        s0 = s_new
                        continue  # the rest of this sub-step, from the switch
                    if watch:
                        pv = self._watch(probe, peak, pv, te, y1, h)
                    if on_switch is not None:
                        y1, k1n, s1 = self._notify(f, switch, on_switch, te, y1, k1n, s0, s1)
                        if watch:
                            pv = probe(te, y1)
                elif watch:
                    pv = self._watch(probe, peak, pv, te, y1, h)
                s0 = s1
            elif watch:
                pv = self._watch(probe, peak, pv, te, y1, h)
            t, y, k1 = te, y1, k1n
            i += 1
        return y

    @staticmethod
    def _watch(probe, peak, pv, t, y, h):
        """One accepted sub-step ending at ``(t, y)``, just evaluated: raise
        ``peak`` over it (:func:`~cosim.core.hermite.substep_peaks`); the end's values."""
        d1, v1 = probe(t, y)
        substep_peaks(peak, pv[0], pv[1], d1, v1, h)
        return d1, v1

    @staticmethod
    def _notify(f, switch, on_switch, t, y, k, s_old, s_new):
        """Tell of each flipped switch; apply any jump it returns."""
        for j in np.flatnonzero((s_old > 0) != (s_new > 0)):
            jumped = on_switch(t, int(j), bool(s_new[j] > 0), y)
            if jumped is not None:
                y = jumped
                k = f(t, y)
                s_new = switch(t, y)
        return y, k, s_new

    @staticmethod
    def _locate(switch, t, y0, f0, y1, f1, h, s0, flipped):
        """Earliest switch time in (t, t + h) on the Hermite interpolant; the
        returned time lies just past the root (on the new side)."""
        lo, hi = 0.0, 1.0
        sign0 = s0 > 0
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            s = switch(t + mid * h, hermite_value(y0, f0, y1, f1, h, mid))
            if np.any(((s > 0) != sign0) & flipped):
                hi = mid
            else:
                lo = mid
            if (hi - lo) * h <= 1e-14 * max(1.0, abs(t)):
                break
        if hi >= 1.0 - 1e-12:
            return None  # the switch sits at the sub-step's end: nothing to split
        return t + hi * h


# no field of its own: TimeStepper's generated dataclass methods serve it as
# they are (decorating it again would only rebuild them at import)
class RK4(TimeStepper):
    """Classical fourth-order Runge-Kutta with fixed sub-steps."""

    order: ClassVar[int] = 4
    name: ClassVar[str] = "rk4"

    def _single(self, f, t, y, h, k1):
        k2 = f(t + 0.5 * h, y + 0.5 * h * k1)
        k3 = f(t + 0.5 * h, y + 0.5 * h * k2)
        k4 = f(t + h, y + h * k3)
        return y + (h / 6.0) * (k1 + 2.0 * (k2 + k3) + k4)


#: the methods :mod:`cosim.core.embedded_rk` integrates (scipy the others)
_PAIRS = ("RK45", "DOP853")


def _switched(sol, sign, t, y, switch, on_switch):
    """The switch signs and state after the earliest event of ``sol``
    (a solver run, :class:`_Run`, that stopped on one) at ``t``: its sign flipped,
    and ``on_switch(t, j, on, y)`` told, whose returned state (a jump)
    replaces ``y`` and sets every sign anew from ``switch(t, y)``."""
    j = min((i for i in range(len(sign)) if len(sol.t_events[i])),
            key=lambda i: sol.t_events[i][0])
    sign = sign.copy()
    sign[j] = not sign[j]
    if on_switch is not None:
        jumped = on_switch(t, j, bool(sign[j]), y)
        if jumped is not None:
            y = jumped
            sign = switch(t, y) > 0
    return sign, y


@dataclass(frozen=True)
class ScipyStepper(TimeStepper):
    """Adaptive integration over each step, ending exactly at its end: the
    explicit pairs (``RK45``, ``DOP853``) by :func:`cosim.core.embedded_rk.solve`,
    the implicit methods (``Radau``, ``BDF``) by
    :func:`scipy.integrate.solve_ivp` (imported only for them).

    A switch (a sign change of one of the ``switch`` functions) is a terminal
    event: located on the dense output, the integration restarts there, so no
    step of the adaptive method straddles a kink.

    Parameters
    ----------
    max_step : float
        Largest internal step [s] (``inf`` for none).
    rtol, atol : float
        Tolerances of the error control.
    """

    max_step: float = math.inf
    rtol: float = 1e-8
    atol: float = 1e-10
    method: ClassVar[str] = "RK45"

    def __post_init__(self):
        if not (isinstance(self.max_step, (int, float)) and self.max_step > 0):
            raise ValueError(f"`max_step` must be > 0 s, got {self.max_step!r}")
        for k in ("rtol", "atol"):
            v = getattr(self, k)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"`{k}` must be > 0, got {v!r}")
        if self.method in _PAIRS:       # loaded with the scene, not inside its first solve
            import cosim.core.embedded_rk  # noqa: F401

    def _single(self, f, t, y, h, k1):  # pragma: no cover - integrate() is overridden
        return self.integrate(f, t, y, t + h)

    def integrate(self, f, t0, y0, t1, switch=None, on_switch=None, coarse=False,
                  probe=None, peak=None, tree=None):
        """See :meth:`TimeStepper.integrate`; ``coarse`` is ignored (the
        error control chooses the steps); ``tree`` as in :meth:`_run`.  A
        watched quantity's maxima are non-terminal events (its rate falling
        through zero), located on the dense output; the values there are
        probed at the located states."""
        t, y = t0, y0
        sign = None if switch is None else switch(t, y) > 0
        n_watch = len(peak) if probe is not None and peak is not None else 0
        while t < t1:
            sol = self._run(f, t, y, t1, switch, sign, probe, n_watch, tree=tree)
            if sol.status == -1:
                raise RuntimeError(f"integrator {self.name} failed at t = {sol.t:.6g} s: "
                                   f"{sol.message}")
            t, y = sol.t, sol.y
            n_sw = 0 if sign is None else len(sign)
            for j in range(n_watch):
                for te, ye in zip(sol.t_events[n_sw + j], sol.y_events[n_sw + j]):
                    peak[j] = max(peak[j], float(probe(float(te), ye)[0][j]))
            if n_watch:
                d_end = probe(t, y)[0]
                for j in range(n_watch):
                    peak[j] = max(peak[j], float(d_end[j]))
            if sol.status != 1:
                break
            sign, y = _switched(sol, sign, t, y, switch, on_switch)
        return y

    def sample(self, f, t0: float, y0: np.ndarray, t_out: np.ndarray, switch, on_switch,
               probe, n_peaks: int, emit, probe_rows=None, tree=None) -> np.ndarray:
        """Integrate from ``t0`` through the output times ``t_out``
        (increasing, the last the end) without restarting at them: each
        output state is read from the solver's dense output (the last is
        the end state itself).

        Switches are terminal events as in :meth:`integrate`, and the
        integration restarts at each; a watched quantity's maxima (``probe``,
        ``n_peaks`` of them) are non-terminal events.  ``emit(i0, i1, Y, P)``
        receives the samples ``i0 .. i1 - 1`` in order: their states ``Y``
        (rows) and each watched quantity's largest value since the sample
        before, ``P`` (rows; at least 0: the peaks :meth:`integrate` raises
        from zero at each step, over the maxima located, the ends of the
        solver's runs and the sample itself).  Every sample before a switch
        is emitted before ``on_switch`` is told of it.  ``probe_rows(T, Y)``,
        where given, gives the watched quantities at many samples at once
        (rows; what ``probe`` gives one at a time); ``tree`` as in :meth:`_run`.
        Returns the end state.
        """
        t_out = np.asarray(t_out, float)
        t, y = t0, y0
        sign = None if switch is None else switch(t, y) > 0
        n_sw = 0 if sign is None else len(sign)
        watch = range(n_peaks) if probe else ()
        t1 = float(t_out[-1])
        i = 0                                  # the next sample to emit
        pk = np.zeros(n_peaks)                 # peaks since the last sample emitted
        while True:
            if t >= t1:                        # a switch at the last output time
                P = np.zeros((1, n_peaks))
                if watch:
                    d_s = probe(t, y)[0]
                    for q in range(n_peaks):
                        P[0, q] = max(pk[q], float(d_s[q]))
                emit(i, i + 1, y[None, :].copy(), P)
                return y
            sol = self._run(f, t, y, t1, switch, sign, probe if watch else None, len(watch),
                            t_out[i:], tree)
            t_seg = sol.t
            last = sol.status == 0
            # samples inside this run: before its end, or up to it when it
            # reached t1 (a sample at a switch takes the state after it)
            j = int(np.searchsorted(t_out, t_seg, side="right" if last else "left"))
            ev = [(float(te), ye) for k in range(len(watch))
                  for te, ye in zip(sol.t_events[n_sw + k], sol.y_events[n_sw + k])]
            ev_t = np.array([e[0] for e in ev])
            if j > i:
                ts = t_out[i:j]
                inner = ts < t_seg
                if inner.all():                   # the solver's rows as they are: no copy
                    Y = np.asarray(sol.at(ts), float)
                else:
                    Y = np.empty((j - i, len(y)))
                    Y[~inner] = sol.y             # the end itself, not its interpolant
                    if inner.any():
                        Y[inner] = sol.at(ts[inner])
                P = np.zeros((j - i, n_peaks))
                if watch:
                    # each sample's value, over the maxima located since the
                    # sample before (the first's since this run's start, and pk)
                    if probe_rows is not None:
                        probe_rows(ts, Y, P)
                    else:
                        for r in range(j - i):
                            P[r] = np.asarray(probe(float(ts[r]), Y[r])[0], float)[:n_peaks]
                    P[0] = np.maximum(P[0], pk)
                    for k in np.flatnonzero((ev_t > t) & (ev_t <= ts[-1])) if ev else ():
                        r = int(np.searchsorted(ts, ev_t[k], side="left"))
                        P[r] = np.maximum(P[r], np.asarray(probe(*ev[k])[0], float)[:n_peaks])
                pk = np.zeros(n_peaks)
                emit(i, j, Y, P)
                i = j
            if watch:                      # maxima after the last sample, and this run's end
                lo = t_out[i - 1] if i else t0
                for (te, ye) in (ev[k] for k in np.flatnonzero(ev_t > lo)):
                    d_ev = probe(te, ye)[0]
                    for q in range(n_peaks):
                        pk[q] = max(pk[q], float(d_ev[q]))
            if sol.status == -1:
                raise RuntimeError(f"integrator {self.name} failed at t = {t_seg:.6g} s: "
                                   f"{sol.message}")
            t, y = t_seg, sol.y
            if last:
                return y
            if watch:
                d_end = probe(t, y)[0]
                for q in range(n_peaks):
                    pk[q] = max(pk[q], float(d_end[q]))
            sign, y = _switched(sol, sign, t, y, switch, on_switch)

    def _run(self, f, t, y, t1, switch, sign, probe, n_watch, t_eval=None, tree=None):
        """One run of the solver from ``(t, y)`` towards ``t1``: each switch a
        terminal event in the direction away from its side ``sign``, the
        first ``n_watch`` rates of ``probe`` non-terminal events (falling);
        the states at the output times ``t_eval`` before where it stops are
        read from its dense output.  A :class:`_Run`.  ``tree`` (a compiled
        tree's pairs, ``cosim.sides._embedded_rk.TreeRK``, or None) runs the
        pair in C where ``f``, ``switch`` and ``probe`` are that tree's own."""
        n_sw = 0 if sign is None else len(sign)
        if tree is not None and self.method in _PAIRS:
            t, y, status, msg, t_ev, y_ev, y_out = tree.run(
                self.method, t, y, t1, self.rtol, self.atol, self.max_step, sign, n_watch, t_eval)
            return _Run(t, y, status, msg, t_ev, y_ev, lambda ts: y_out[:len(ts)])
        if self.method in _PAIRS:
            from cosim.core.embedded_rk import PAIRS, Events, solve   # loaded when built
            events = None
            if n_sw + n_watch:
                events = Events(_event_vector(switch if n_sw else None, probe, n_watch),
                                np.r_[np.where(sign, -1.0, 1.0) if n_sw else [], -np.ones(n_watch)],
                                np.r_[np.ones(n_sw, bool), np.zeros(n_watch, bool)])
            res = solve(PAIRS[self.method], f, t, y, t1, rtol=self.rtol, atol=self.atol,
                        max_step=self.max_step, events=events, t_eval=t_eval)
            return _Run(res.t, res.y, res.status, res.message, res.t_events, res.y_events,
                        lambda ts: res.y_eval[:len(ts)])
        from scipy.integrate import solve_ivp    # the implicit methods only: 0.5 s to import

        events = [_scalar_event(lambda tt, yy: switch(tt, yy), j, bool(sign[j]))
                  for j in range(n_sw)]
        events += [_scalar_event(lambda tt, yy: probe(tt, yy)[1], j, None)
                   for j in range(n_watch)]
        sol = solve_ivp(f, (t, t1), y, method=self.method, rtol=self.rtol, atol=self.atol,
                        max_step=self.max_step, events=events or None,
                        dense_output=t_eval is not None)
        return _Run(float(sol.t[-1]), sol.y[:, -1], sol.status, sol.message, sol.t_events,
                    sol.y_events, lambda ts: sol.sol(ts).T)


class _Run:
    """Where one solver run stopped (``t``, ``y``; ``status`` 0 at its end,
    1 on a terminal event, -1 failed, with ``message``), its events' times
    and states per event function, and ``at(ts)``: the states (rows) at the
    first output times, those before ``t``.  (A plain class: a dataclass
    costs its generated methods' ``exec`` at import.)"""

    __slots__ = ("t", "y", "status", "message", "t_events", "y_events", "at")

    def __init__(self, t, y, status, message, t_events, y_events, at):
        self.t, self.y, self.status, self.message = t, y, status, message
        self.t_events, self.y_events, self.at = t_events, y_events, at


def _event_vector(switch, probe, n_watch):
    """``g(t, y)``: the switch functions, then the first ``n_watch`` rates of
    ``probe``, in one array."""
    if probe is None or not n_watch:
        return lambda t, y: np.asarray(switch(t, y), float)
    if switch is None:
        return lambda t, y: np.asarray(probe(t, y)[1][:n_watch], float)
    return lambda t, y: np.concatenate((np.asarray(switch(t, y), float),
                                        np.asarray(probe(t, y)[1][:n_watch], float)))


def _scalar_event(fun, j, positive):
    """Component ``j`` of ``fun`` as a :func:`scipy.integrate.solve_ivp`
    event: a switch (terminal, away from its side ``positive``) or, with
    ``positive`` None, a watched rate (falling, non-terminal)."""
    def ev(t, y):
        return float(fun(t, y)[j])
    ev.terminal = positive is not None
    ev.direction = -1.0 if positive is None or positive else 1.0
    return ev


def _scipy(method_name: str, scipy_method: str, doc: str):
    # no field of its own: ScipyStepper's dataclass methods serve it as they are
    return type(f"Scipy{scipy_method}", (ScipyStepper,), {
        "__doc__": doc, "name": method_name, "method": scipy_method,
        "order": {"RK45": 5, "DOP853": 8, "Radau": 5, "BDF": 5}[scipy_method],
        "__annotations__": {}})


RK45 = _scipy("rk45", "RK45", "Adaptive explicit Dormand-Prince 5(4) "
              "(:mod:`cosim.core.embedded_rk`).")
DOP853 = _scipy("dop853", "DOP853", "Adaptive explicit Dormand-Prince 8(5,3) "
                "(:mod:`cosim.core.embedded_rk`).")
Radau = _scipy("radau", "Radau", "Implicit Radau IIA of order 5 (scipy), for stiff contacts.")
BDF = _scipy("bdf", "BDF", "Implicit backward differentiation, orders 1-5 (scipy).")

#: the robots' integrators by name; a name not here is looked for among
#: installed plug-ins (group ``cosim.integrators``, :mod:`cosim.core.plugins`)
INTEGRATORS: Registry = Registry({cls.name: cls for cls in (RK4, RK45, DOP853, Radau, BDF)},
                                 group="cosim.integrators")


def lookup(registry: dict, name, base: type, kind: str):
    """Resolve ``name`` in a registry; a subclass of ``base`` passes through.

    Raises
    ------
    ValueError
        For an unknown name, listing the valid ones.
    """
    if isinstance(name, type) and issubclass(name, base):
        return name
    try:
        return registry[name]
    except (KeyError, TypeError):
        raise ValueError(f"unknown {kind} {name!r}; valid {kind}s are "
                         f"{sorted(registry)}") from None


def get_integrator(name) -> type[TimeStepper]:
    """Resolve an integrator given by registry name or as a class."""
    return lookup(INTEGRATORS, name, TimeStepper, "integrator")

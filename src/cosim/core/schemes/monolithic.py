"""The monolithic reference: every subsystem stacked into one ODE."""
from __future__ import annotations

import math
from typing import ClassVar

import numpy as np

from .base import SOLVER_RTOL_RULE, CouplingError, CouplingScheme, Option, _pos, _solver_rtol

__all__ = ["Monolithic"]


def _connection_forces(system, d, dd, f_normal):
    """Row forces with connections: the located branch ``f_normal`` for open
    and released contacts, the grasp's springs while grasped, friction on
    the normal force."""
    from couplers.connection import GRASPED
    cs = system.connections
    f = np.zeros(system.n_rows)
    f[:system.n_contacts] = f_normal
    for c in cs.index:
        conn, r = cs.connections[c], system.tangent_row[c]
        e, de = (d[r], dd[r]) if r >= 0 else (0.0, 0.0)
        if cs.mode[c] == GRASPED:
            f[c] = conn.grasp.normal_force(d[c], dd[c])
            f[r] = conn.grasp.tangential_force(e, de)
        elif conn.friction is not None and f[c] > 0:
            f[r] = conn.friction.force(f[c], de)
    return f


def _python_rhs(system, active):
    """``contact_state(y)`` (the subsystems' states, and the rows'
    penetrations, rates and forces) and ``rhs(t, y)`` of the stacked ODE in
    Python: the reference, which :class:`cosim.core._stacked.StackedRHS`
    reproduces in compiled code.  ``active`` (bool per contact) is read at
    each call."""
    subs = system.subsystems
    off = system.stacked()
    nc = system.n_contacts
    laws = [ln.contact.law for ln in system.links]
    conns = system.connections

    def split(y):
        return [y[off[s]:off[s + 1]] for s in range(len(subs))]

    def contact_state(y):
        xs = split(y)
        outs = [sub.outputs(0.0, xs[s]) for s, sub in enumerate(subs)]
        if system.followers:      # surface points move with the point above them
            system.update_followers(outs, xs)
            outs = [sub.outputs(0.0, xs[s]) for s, sub in enumerate(subs)]
        d, dd = system.penetrations(outs)
        f = np.array([max(float(laws[c].force_active(d[c], dd[c])), 0.0) if active[c]
                      else 0.0 for c in range(nc)])
        if conns is not None:
            f = _connection_forces(system, d, dd, f)
        return xs, d, dd, f

    def py_rhs(t, y):
        xs, d, dd, f = contact_state(y)
        parts = [sub.derivatives(t, xs[s], system.port_forces(s, f))
                 for s, sub in enumerate(subs)]
        if conns is None:
            diss = [float(laws[c].dissipation_rate(f[c], d[c], dd[c])) for c in range(nc)]
        else:
            diss = system.dissipation_rates(f, d, dd)
        led = np.sum([sub.ledger_rates(t, xs[s]) for s, sub in enumerate(subs)], axis=0)
        work = -f[:nc] * dd[:nc]
        if system.n_rows > nc:      # tangential rows: force on a along t, times de
            np.add.at(work, system.row_contact[nc:], f[nc:] * dd[nc:])
        return np.concatenate(parts + [f[:nc], diss, work, led])

    return contact_state, py_rhs


def _compiled_rhs(system, active):
    """The stacked right-hand side in compiled code
    (:class:`cosim.core._stacked.StackedRHS`), or None where the Python one
    must run: a grasp or friction connection, a law the kernels do not
    know, a subsystem without a compiled face (``COSIM_KERNEL=numpy``, a
    kernel not built, a user's own subsystem), or a following contact on a
    side that cannot move its port."""
    from cosim.core.links import kernel_law
    if system.connections is not None:
        return None
    faces = _faces(system)
    laws = [kernel_law(ln.contact.law) for ln in system.links]
    if any(f is None for f in faces) or any(law is None for law in laws):
        return None
    if any(ln.follow and not faces[ln.sub_b].can_follow for ln in system.links):
        return None
    from cosim.core._stacked import StackedRHS
    contacts = [(ln.sub_a, ln.port_a, ln.sub_b, ln.port_b, *ln.contact.normal,
                 ln.contact.offset, *law, ln.follow) for ln, law in zip(system.links, laws)]
    return StackedRHS(faces, system.stacked(), contacts, active)


def _faces(system) -> list:
    """Each subsystem's compiled face, or None for one that has none."""
    return [getattr(sub, "compiled_face", lambda: None)() for sub in system.subsystems]


_METHODS = ("RK45", "RK23", "DOP853", "Radau", "BDF", "LSODA")
#: the methods :mod:`cosim.core.embedded_rk` integrates (scipy's solve_ivp the others)
_PAIRS = ("RK45", "DOP853")


class _Segment:
    """One solver run: where it stopped (``t``, ``y``; ``status`` 0 at the
    end, 1 on a terminal event, -1 failed, with ``message``), its events'
    times and states per event function, and ``at(ts)``: the states (rows)
    at the output times ``ts`` asked for, the first of those before ``t``."""

    __slots__ = ("t", "y", "status", "message", "t_events", "y_events", "at")

    def __init__(self, t, y, status, message, t_events, y_events, at):
        self.t, self.y, self.status, self.message = t, y, status, message
        self.t_events, self.y_events, self.at = t_events, y_events, at


class Monolithic(CouplingScheme):
    """All subsystems' model-exchange faces in one ODE, solved by cosim's
    own embedded Runge-Kutta pairs (:func:`cosim.core.embedded_rk.solve`)
    for ``DOP853`` (the default) and ``RK45``, and by
    :func:`scipy.integrate.solve_ivp` for ``RK23``, ``Radau``, ``BDF`` and
    ``LSODA`` (scipy is imported only then).

    Every contact switch (onset, release, including a Kelvin-Voigt force
    reaching zero before the penetration does) is an event located on the
    solver's dense output; the integration restarts there with the contact's
    branch switched, so no step straddles a kink.  Each contact's peak
    penetration is an event too.  The impulse and the dissipated energy of
    each contact are integrated as extra states.

    The right-hand side and the event values are evaluated in compiled code
    (:class:`cosim.core._stacked.StackedRHS`) where every subsystem hands out
    a compiled face (:meth:`cosim.core.subsystem.Subsystem.compiled_face`) and
    no contact has a grasp or friction connection; ``COSIM_KERNEL=numpy``
    runs the Python one (:func:`_python_rhs`), the reference it is tested
    against.  ``compiled`` tells which ran last.
    """

    name: ClassVar[str] = "monolithic"
    options: ClassVar[dict] = {
        "method": Option(str, "DOP853", lambda v: v in _METHODS,
                         "one of " + ", ".join(_METHODS)),
        "rtol": Option(float, 1e-10, _solver_rtol, SOLVER_RTOL_RULE),
        "atol": Option(float, 1e-12, _pos, "> 0"),
        "max_step": Option(float, math.inf, lambda v: v > 0, "> 0 s"),
        "output_interval": Option(float, None, _pos, "> 0 s"),
    }
    #: whether the last run evaluated its right-hand side in compiled code
    compiled: bool = False

    def run(self, system, t_end, recorder):
        subs = system.subsystems
        off = system.stacked()
        n_x = int(off[-1])
        nc = system.n_contacts
        laws = [ln.contact.law for ln in system.links]
        active = np.zeros(nc, dtype=bool)
        conns = system.connections

        contact_state, py_rhs = _python_rhs(system, active)

        # the same right-hand side and event values in compiled code where
        # every side has a compiled face; the Python one stays the reference
        stacked = _compiled_rhs(system, active)
        self.compiled = stacked is not None
        rhs = py_rhs if stacked is None else stacked.rhs

        t_next = [math.inf]                 # the next time trigger of a connection

        def contact_events(t, y):
            """Per contact its switch value, then its penetration rate: a
            new (2 nc,) array (the compiled object's own is overwritten by
            its next call, and the solver keeps the last step's values)."""
            if stacked is not None:
                return np.array(stacked.events(y))
            _, d, dd, _ = contact_state(y)
            g = np.empty(2 * nc)
            for c in range(nc):
                if conns is not None and system.links[c].connection is not None:
                    g[c] = float(conns.switch(c, d[c], dd[c]))   # none while grasped
                else:
                    g[c] = float(laws[c].switch(d[c], dd[c]))
                g[nc + c] = float(dd[c])
            return g

        def timer(t, y):
            return 1.0 if math.isinf(t_next[0]) else t - t_next[0]

        def all_events(t, y):
            return np.append(contact_events(t, y), timer(t, y))

        segment = self._segment_solver(rhs, t_end)
        y = np.concatenate([s.x for s in subs] + [np.zeros(3 * nc + 2)])
        dt_out = self.output_interval or t_end / 1000.0

        def record(t, yy):
            xs, d, dd, f = contact_state(yy)
            for s, sub in enumerate(subs):
                sub.x[...] = xs[s]
                sub.t = t
            recorder.record(t, d, dd, f, yy[n_x:n_x + nc], yy[n_x + nc:n_x + 2 * nc],
                            (yy[-2], yy[-1]), yy[n_x + 2 * nc:n_x + 3 * nc])

        # Contacts already closed at t = 0.
        _, d0, dd0, _ = contact_state(y)
        for c in range(nc):
            active[c] = float(laws[c].switch(d0[c], dd0[c])) > 0
            if active[c]:
                recorder.edge(c, 0.0, True)
        record(0.0, y)
        t = 0.0
        n_segments = self.n_windows = 0
        next_out = dt_out
        while t < t_end * (1 - 1e-14):
            # a switch away from the contact's branch (a rigid one is never
            # active), each peak a falling rate, a connection's time trigger
            direction = np.concatenate((np.where(active, -1.0, 1.0), -np.ones(nc)))
            terminal = np.arange(2 * nc) < nc
            timed = False
            if conns is not None:
                if self._switch_modes(system, t, y, contact_state, active, laws, False):
                    record(t, y)
                t_next[0] = conns.next_time(t)
                timed = True
                direction, terminal = np.append(direction, 1.0), np.append(terminal, True)
            sol = segment(t, y, all_events if timed else contact_events, direction, terminal,
                          np.arange(next_out, t_end, dt_out))
            n_segments += 1
            self.n_windows = n_segments
            if sol.status == -1:
                raise CouplingError(f"monolithic solver failed at t = {sol.t:.6g} s: "
                                    f"{sol.message}")
            t_seg = sol.t
            out_t = np.arange(next_out, t_seg, dt_out)
            out_t = out_t[out_t < t_seg - 1e-15]
            samples = [(tp, yp) for tp, yp in zip(out_t, sol.at(out_t))]
            for c in range(nc):
                for tp, yp in zip(sol.t_events[nc + c], sol.y_events[nc + c]):
                    if active[c]:
                        samples.append((tp, yp))
            samples.sort(key=lambda s: s[0])
            for tp, yp in samples:
                record(tp, yp)
            next_out = (math.floor(t_seg / dt_out + 1e-9) + 1) * dt_out
            y = np.array(sol.y)
            t = t_seg
            if sol.status == 1 and timed and len(sol.t_events[2 * nc]) and not any(
                    len(sol.t_events[i]) for i in range(nc)):       # a time trigger
                self._switch_modes(system, t, y, contact_state, active, laws, False)
                record(t, y)
            elif sol.status == 1:
                c = min(range(nc), key=lambda i: sol.t_events[i][0]
                        if len(sol.t_events[i]) else math.inf)
                record(t, y)
                if laws[c].rigid:
                    y = self._impact(system, c, t, y, off, n_x, nc, recorder)
                    record(t, y)
                else:
                    active[c] = not active[c]
                    recorder.edge(c, t, bool(active[c]))
                    if conns is not None and active[c] and conns.closes_on_touch(c):
                        self._switch_modes(system, t, y, contact_state, active, laws, c)
                        record(t, y)
            elif t >= t_end * (1 - 1e-14):
                record(t, y)
        return {"n_windows": n_segments, "n_iterations": 0, "n_rejected": 0}

    def prepare(self, system, t_end, recorder):
        # the modules of the sides' compiled faces (a face is asked for
        # here, the run builds its own at its start), of the compiled
        # right-hand side and of the solver, loaded before the clock
        faces = _faces(system)
        if system.connections is None and all(f is not None for f in faces):
            from cosim.core._stacked import StackedRHS  # noqa: F401
        if self.method in _PAIRS:
            import cosim.core.embedded_rk  # noqa: F401
        else:
            import scipy.integrate  # noqa: F401

    def _segment_solver(self, rhs, t_end):
        """``segment(t, y, g, direction, terminal, t_eval)``: one run of the
        solver from ``(t, y)`` towards ``t_end``, with the event functions
        ``g(t, y)`` (a vector; per component its ``direction`` and whether it
        is ``terminal``), a :class:`_Segment`.  The explicit pairs (``RK45``,
        ``DOP853``) by :func:`cosim.core.embedded_rk.solve`, evaluating every
        event in one call; the others by :func:`scipy.integrate.solve_ivp`,
        imported only for them."""
        opts = {"rtol": self.rtol, "atol": self.atol, "max_step": self.max_step}
        if self.method in _PAIRS:
            from cosim.core.embedded_rk import PAIRS, Events, solve
            pair = PAIRS[self.method]

            def segment(t, y, g, direction, terminal, t_eval):
                events = Events(g, direction, terminal) if len(direction) else None
                res = solve(pair, rhs, t, y, t_end, events=events, t_eval=t_eval, **opts)
                return _Segment(res.t, res.y, res.status, res.message, res.t_events,
                                res.y_events, lambda ts: res.y_eval[:len(ts)])
            return segment

        from scipy.integrate import solve_ivp

        def component(g, j, direction, terminal):
            def ev(t, y):
                return float(g(t, y)[j])
            ev.direction, ev.terminal = float(direction), bool(terminal)
            return ev

        def segment(t, y, g, direction, terminal, t_eval):
            events = [component(g, j, direction[j], terminal[j]) for j in range(len(direction))]
            sol = solve_ivp(rhs, (t, t_end), y, method=self.method, dense_output=True,
                            events=events, **opts)
            return _Segment(float(sol.t[-1]), sol.y[:, -1], sol.status, sol.message,
                            sol.t_events, sol.y_events,
                            lambda ts: sol.sol(ts).T if len(ts) else ())
        return segment

    @staticmethod
    def _switch_modes(system, t, y, contact_state, active, laws, touched) -> bool:
        """Switch connections at ``t``: grasp contact ``touched`` (its located
        onset; False at a time event), then the time and ``after`` triggers
        due.  A released contact goes on unilaterally from the state it is in."""
        from couplers.connection import GRASPED
        _, d, dd, _ = contact_state(y)
        log = system.connections.log
        n_log = len(log)
        if touched is not False:          # the located root, whatever side it fell on
            system.set_mode(touched, t, GRASPED, d, dd)
        if not system.switch_modes(t, d, dd, touch=False) and touched is False:
            return False
        for entry in log[n_log:]:
            if entry["to"] == "released":
                active[system.contact_names.index(entry["contact"])] = entry["closed"]
        return True

    @staticmethod
    def _impact(system, c, t, y, off, n_x, nc, recorder):
        """Apply rigid contact ``c``'s impact to the stacked state."""
        s, slot = system.embedded[c]
        sub = system.subsystems[s]
        sub.impact_log = []
        x_new = sub.rigid_impact(t, y[off[s]:off[s + 1]], slot)
        if x_new is None:
            return y
        y = y.copy()
        y[off[s]:off[s + 1]] = x_new
        for imp in sub.impact_log:          # one entry per contact taking part
            k = system.contact_names.index(imp["contact"])
            y[n_x + k] += imp["normal_impulse"]
            y[n_x + nc + k] += imp["energy_loss"]
            y[n_x + 2 * nc + k] -= imp["energy_loss"]
            recorder.impacts.append(imp)
            recorder.edge(k, t, True)
            recorder.edge(k, t, False)
        return y

"""The discrete state of a system's connections: modes, anchors, events.

A contact with a :class:`couplers.Connection` (a grasp, friction) has a
mode: ``open`` (its unilateral law, with friction if any), ``grasped``
(bilateral springs, see :mod:`couplers.connection`) or ``released`` (open
again, for good).  The modes, the tangential anchors set at grasp, the times
of the events that ``after`` conditions wait for, the log of switches and
the energy the switches released are one :class:`ConnectionSet`, owned by
the :class:`~cosim.core.system.CoupledSystem`.  Its :meth:`ConnectionSet.snapshot`
is part of ``system.get_state()``, so a repeated step (implicit iterations,
a rejected step of step control) restores the modes with the states.

Who switches:

- ``start``: the system, at construction;
- ``touch``: the monolithic scheme at the located onset; a contact embedded
  in a moving side, its integrator at the located onset; a contact the
  co-simulation exchanges, the scheme at the first communication point at
  which its law gives a force;
- ``time`` and ``after``: the monolithic scheme at a located time event; the
  co-simulation schemes at the first communication point at or after it.

A switch changes the stored elastic energy (a grasp closed at a penetration
``d`` stores ``k d^2 / 2`` in place of the law's ``V(d)``; a release frees
the grasp's springs).  The difference is booked as dissipated by the contact
(:attr:`ConnectionSet.lost`), so the ledger initial = final + dissipated
holds across switches.
"""
from __future__ import annotations

import math

import numpy as np

from couplers.connection import (GRASPED, MODES, OPEN, RELEASED, connection_forces,
                                 connection_potential, connection_power, connection_switch)

from cosim.core.preflight import stiffest_normal  # noqa: F401  (it lived here; the checks need it alone)

__all__ = ["ConnectionSet", "EmbeddedConnection", "stiffest_normal"]


class ConnectionSet:
    """Modes, anchors and events of the connections of a system.

    Parameters
    ----------
    names : list of str
        Contact names (all contacts of the system).
    laws : list of ContactLaw
    connections : list of Connection or None
        Per contact; None for a plain unilateral contact.
    """

    def __init__(self, names, laws, connections):
        self.names, self.laws, self.connections = list(names), list(laws), list(connections)
        n = len(self.names)
        self.index = [c for c, k in enumerate(self.connections) if k is not None]
        self.mode = np.zeros(n, dtype=int)
        self.anchor = np.zeros(n)
        #: "CONTACT.grasp" / "CONTACT.release" -> time [s]
        self.events: dict[str, float] = {}
        #: every switch: {"time", "contact", "from", "to", "closed"}; ``closed``
        #: tells whether the unilateral law carried force at that instant
        self.log: list[dict] = []
        #: energy released by switches, per contact [J]
        self.lost = np.zeros(n)

    # ------------------------------------------------------------ rollback
    def snapshot(self):
        return (self.mode.copy(), self.anchor.copy(), dict(self.events), len(self.log),
                self.lost.copy())

    def restore(self, snap) -> None:
        mode, anchor, events, n_log, lost = snap
        self.mode[:], self.anchor[:], self.lost[:] = mode, anchor, lost
        self.events = dict(events)
        del self.log[n_log:]

    # ------------------------------------------------------------ switching
    def set_mode(self, c: int, t: float, mode: int, d: float, dd: float, s: float) -> None:
        """Switch contact ``c`` to ``mode`` at time ``t``.

        ``d``, ``dd`` are its penetration and rate, ``s`` the tangential
        coordinate of ``x_a - x_b`` [m] at that instant (the new anchor on a
        grasp)."""
        law, conn, old = self.laws[c], self.connections[c], int(self.mode[c])
        before = connection_potential(law, conn, old, d, s - self.anchor[c])
        if mode == GRASPED:
            self.anchor[c] = s
        self.mode[c] = mode
        after = connection_potential(law, conn, mode, d, s - self.anchor[c])
        self.lost[c] += before - after
        event = {GRASPED: "grasp", RELEASED: "release"}[mode]
        self.events[f"{self.names[c]}.{event}"] = float(t)
        self.log.append({"time": float(t), "contact": self.names[c], "from": MODES[old],
                         "to": MODES[mode], "closed": float(law.switch(d, dd)) > 0})

    def closes_on_touch(self, c: int) -> bool:
        conn = self.connections[c]
        return (conn is not None and conn.grasp is not None and self.mode[c] == OPEN
                and conn.close.kind == "touch")

    def due(self, t: float, which=None) -> list[tuple[int, int]]:
        """Switches whose ``time`` or ``after`` trigger has come at ``t``:
        (contact, new mode) pairs, among the contacts ``which`` (all)."""
        out = []
        for c in self.index if which is None else which:
            conn = self.connections[c]
            if conn is None or conn.grasp is None:
                continue
            if self.mode[c] == OPEN and conn.close.due(t, self.events):
                out.append((c, GRASPED))
            elif (self.mode[c] == GRASPED and conn.release is not None
                  and conn.release.due(t, self.events)):
                out.append((c, RELEASED))
        return out

    def next_time(self, t: float) -> float:
        """Earliest time after ``t`` at which a trigger known now fires (inf if none)."""
        best = math.inf
        for c in self.index:
            conn = self.connections[c]
            if conn.grasp is None:
                continue
            trig = (conn.close if self.mode[c] == OPEN else
                    conn.release if self.mode[c] == GRASPED else None)
            at = None if trig is None else trig.at(self.events)
            if at is not None and at > t and not math.isclose(at, t, rel_tol=1e-12,
                                                              abs_tol=1e-15):
                best = min(best, at)
        return best

    # ------------------------------------------------------- forces (rows)
    def forces(self, c: int, d, dd, e, de):
        return connection_forces(self.laws[c], self.connections[c], int(self.mode[c]),
                                 d, dd, e, de)

    def power(self, c: int, fn, ft, d, dd, e, de):
        return connection_power(self.laws[c], self.connections[c], int(self.mode[c]),
                                fn, ft, d, dd, e, de)

    def potential(self, c: int, d, e):
        return connection_potential(self.laws[c], self.connections[c], int(self.mode[c]), d, e)

    def switch(self, c: int, d, dd):
        return connection_switch(self.laws[c], int(self.mode[c]), d, dd)

    def grasped(self, c: int) -> bool:
        return self.mode[c] == GRASPED


class EmbeddedConnection:
    """One connection as its moving side evaluates it inside its integrator.

    Kinematics come as complex numbers (``x + i y``) of this side's port
    relative to the (rigid) partner's port; ``own_side`` is +1 when this side
    is the contact's side ``a``, -1 when side ``b``.
    """

    def __init__(self, conns: ConnectionSet, c: int, normal, own_side: float):
        self.conns, self.c, self.side = conns, c, float(own_side)
        self.n = complex(normal[0], normal[1])
        self.t = 1j * self.n

    def tangential(self, dx: complex) -> float:
        """Tangential coordinate of ``x_a - x_b`` [m] (before the anchor)."""
        return self.side * (self.t.conjugate() * dx).real

    def evaluate(self, dx: complex, dv: complex, d: float, dd: float):
        """Force on this side's port (complex) [N], the normal force [N], the
        dissipated power [W] and the switch value."""
        cs, c = self.conns, self.c
        e = self.tangential(dx) - cs.anchor[c]
        de = self.tangential(dv)
        fn, ft = cs.forces(c, d, dd, e, de)
        return (self.side * (fn * self.n + ft * self.t), fn, cs.power(c, fn, ft, d, dd, e, de),
                cs.switch(c, d, dd))

    def on_switch(self, t: float, on: bool, dx: complex, d: float, dd: float) -> bool:
        """A located switch of the unilateral law: grasp if this is the touch
        that closes it.  True when the mode changed."""
        if on and self.conns.closes_on_touch(self.c):
            self.conns.set_mode(self.c, t, GRASPED, d, dd, self.tangential(dx))
            return True
        return False

    @property
    def has_friction(self) -> bool:
        return self.conns.connections[self.c].friction is not None


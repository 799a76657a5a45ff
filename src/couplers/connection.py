"""Connections beyond the unilateral contact: bilateral grasp, regularised
Coulomb friction, and the triggers that switch a connection's mode.

A :class:`Connection` adds to a :class:`~couplers.PointContact` (whose law
stays the unilateral one) what it does in its other modes:

- ``open``: the unilateral law along the normal; with :class:`Friction`, a
  tangential force opposing the sliding velocity;
- ``grasped``: a bilateral linear spring-damper along the normal (rest at
  zero penetration, so it may pull) and one along the tangent
  ``t = (-n_y, n_x)`` towards an anchor, the tangential coordinate of
  ``x_a - x_b`` at the instant of grasp;
- ``released``: as ``open``, for good (a connection grasps at most once).

Every function here is a pure function of the kinematics of one contact:
``d`` and ``dd`` its penetration and rate (as in :mod:`couplers.laws`), ``e``
the tangential coordinate of ``x_a - x_b`` from the anchor [m] and ``de`` its
rate [m/s].  Forces are those on side ``a``: ``f_n`` along ``+normal``,
``f_t`` along ``+t``; side ``b`` receives the opposite.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .checks import positive
from .laws import ContactLaw
from .modes import GRASPED, MODES, OPEN, RELEASED

__all__ = ["Grasp", "Friction", "Trigger", "Connection", "MODES", "OPEN", "GRASPED", "RELEASED",
           "TRIGGER_KINDS", "connection_forces", "connection_power", "connection_potential",
           "connection_switch"]

#: What can close (all) or release (``time`` and ``after`` only) a grasp.
TRIGGER_KINDS = ("start", "touch", "time", "after")
#: Events another connection's trigger may name with ``after``.
EVENTS = ("grasp", "release")


@dataclass(frozen=True)
class Grasp:
    """Bilateral linear spring-dampers of a closed gripper.

    Parameters
    ----------
    stiffness : float
        Normal stiffness [N/m], > 0.
    damping : float
        Normal damping [N s/m], >= 0.
    tangential_stiffness : float
        Tangential stiffness [N/m], >= 0.
    tangential_damping : float
        Tangential damping [N s/m], >= 0.
    """

    stiffness: float
    damping: float
    tangential_stiffness: float
    tangential_damping: float

    def __post_init__(self):
        object.__setattr__(self, "stiffness", positive(self.stiffness, "stiffness", "N/m"))
        for name, unit in (("damping", "N s/m"), ("tangential_stiffness", "N/m"),
                           ("tangential_damping", "N s/m")):
            object.__setattr__(self, name, positive(getattr(self, name), name, unit,
                                                     allow_zero=True))

    def normal_force(self, d, dd):
        """``k d + c dd`` [N]: pushes when pressed in, pulls when pulled out."""
        return self.stiffness * d + self.damping * dd

    def tangential_force(self, e, de):
        """``-(k_t e + c_t de)`` [N], towards the anchor."""
        return -(self.tangential_stiffness * e + self.tangential_damping * de)


@dataclass(frozen=True)
class Friction:
    """Regularised Coulomb friction of a sliding penalty contact.

    ``f_t = -mu f_n tanh(v_t / v_s)``: Coulomb's law with the sign function
    smoothed over the slip velocity ``v_s`` (Andersson, Soederberg and
    Bjoerklund 2007, eq. 1 with their tanh regularisation; reviewed by
    Pennestri et al. 2016, sec. 3).  It cannot stick: under a steady
    tangential load ``F < mu f_n`` the point creeps at
    ``v_s artanh(F / (mu f_n))``.

    Parameters
    ----------
    coefficient : float
        ``mu`` [-], > 0 (a contact without friction has no :class:`Friction`).
    slip_velocity : float
        ``v_s`` [m/s], > 0.

    References
    ----------
    S. Andersson, A. Soederberg, S. Bjoerklund, "Friction models for sliding
    dry, boundary and mixed lubricated contacts", Tribology International 40
    (2007) 580-587.  E. Pennestri, V. Rossi, P. Salvini, P. P. Valentini,
    "Review and comparison of dry friction force models", Nonlinear Dynamics
    83 (2016) 1785-1801.
    """

    coefficient: float
    slip_velocity: float

    def __post_init__(self):
        object.__setattr__(self, "coefficient", positive(self.coefficient, "coefficient", "(-)"))
        object.__setattr__(self, "slip_velocity",
                           positive(self.slip_velocity, "slip_velocity", "m/s"))

    def force(self, normal_force, de):
        """Tangential force [N] under normal force ``normal_force`` >= 0 and
        sliding velocity ``de``."""
        return -self.coefficient * normal_force * np.tanh(de / self.slip_velocity)


@dataclass(frozen=True)
class Trigger:
    """When a connection closes or releases.

    Parameters
    ----------
    kind : str
        ``"start"`` (at t = 0), ``"touch"`` (when the unilateral contact first
        closes), ``"time"`` (at ``time``) or ``"after"`` (``delay`` after
        ``event``, an event of a connection).
    time : float or None
        [s], for ``kind = "time"``.
    event : str or None
        ``"CONTACT.grasp"`` or ``"CONTACT.release"``, for ``kind = "after"``.
    delay : float
        [s], >= 0, for ``kind = "after"``.
    """

    kind: str
    time: float | None = None
    event: str | None = None
    delay: float = 0.0

    def __post_init__(self):
        if self.kind not in TRIGGER_KINDS:
            raise ValueError(f"`kind` must be one of {list(TRIGGER_KINDS)}, got {self.kind!r}")
        if self.kind == "time":
            object.__setattr__(self, "time", positive(self.time, "time", "s", allow_zero=True))
        elif self.time is not None:
            raise ValueError(f"`time` belongs to a trigger of kind `time`, not {self.kind!r}")
        if self.kind == "after":
            ev = self.event
            if not isinstance(ev, str) or ev.rpartition(".")[2] not in EVENTS \
                    or not ev.rpartition(".")[0]:
                raise ValueError(f"`after` must read CONTACT.grasp or CONTACT.release, "
                                 f"got {ev!r}")
        elif self.event is not None:
            raise ValueError(f"`after` belongs to a trigger of kind `after`, not {self.kind!r}")
        object.__setattr__(self, "delay", positive(self.delay, "delay", "s", allow_zero=True))

    def due(self, t: float, events: dict) -> bool:
        """True once the trigger's time or condition has come at time ``t``
        (``events`` maps ``"CONTACT.grasp"`` etc. to when they happened).
        ``start`` and ``touch`` are never due here: they are told apart by
        whoever locates them."""
        at = self.at(events)
        return at is not None and (t >= at or math.isclose(t, at, rel_tol=1e-12, abs_tol=1e-15))

    def at(self, events: dict) -> float | None:
        """The time at which a ``time`` or ``after`` trigger fires, if known."""
        if self.kind == "time":
            return self.time
        if self.kind == "after" and self.event in events:
            return events[self.event] + self.delay
        return None


@dataclass(frozen=True)
class Connection:
    """What a contact does beyond its unilateral law.

    Parameters
    ----------
    grasp : Grasp or None
    friction : Friction or None
        Acts while the contact is not grasped.
    close, release : Trigger or None
        When the grasp closes (needed with ``grasp``) and releases (never when
        None).
    """

    grasp: Grasp | None = None
    friction: Friction | None = None
    close: Trigger | None = None
    release: Trigger | None = None

    def __post_init__(self):
        if self.grasp is None and (self.close is not None or self.release is not None):
            raise ValueError("`close` and `release` need a `grasp`")
        if self.grasp is not None and self.close is None:
            raise ValueError("`close` is required with a `grasp`")
        if self.release is not None and self.release.kind not in ("time", "after"):
            raise ValueError(f"`release` must be a time or an `after` condition, got "
                             f"{self.release.kind!r}")

    @property
    def tangential(self) -> bool:
        """True when the contact has a tangential force row."""
        return self.grasp is not None or self.friction is not None


def connection_forces(law: ContactLaw, conn: Connection, mode: int, d, dd, e, de):
    """Normal and tangential force on side ``a`` [N] in ``mode``."""
    if mode == GRASPED:
        g = conn.grasp
        return float(g.normal_force(d, dd)), float(g.tangential_force(e, de))
    fn = float(law.force(d, dd))
    if conn.friction is None or fn == 0.0:
        return fn, 0.0
    return fn, float(conn.friction.force(fn, de))


def connection_power(law: ContactLaw, conn: Connection, mode: int, fn, ft, d, dd, e, de):
    """Power dissipated by the connection [W], >= 0."""
    if mode == GRASPED:
        g = conn.grasp
        return g.damping * dd * dd + g.tangential_damping * de * de
    return float(law.dissipation_rate(fn, d, dd)) - ft * de


def connection_potential(law: ContactLaw, conn: Connection, mode: int, d, e):
    """Elastic energy stored in the connection [J]."""
    if mode == GRASPED:
        g = conn.grasp
        return 0.5 * (g.stiffness * d * d + g.tangential_stiffness * e * e)
    return float(law.potential(d))


def connection_switch(law: ContactLaw, mode: int, d, dd):
    """Continuous function whose sign change is a kink of the normal force:
    the law's switch, except while grasped (smooth: no switch, 1)."""
    return 1.0 if mode == GRASPED else float(law.switch(d, dd))

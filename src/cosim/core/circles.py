"""The coupled system's side of circle contacts (a scene contact with
``radius``, hosted by a plane body: :mod:`cosim.sides.plane_circle`).

A circle's row is not a penetration along a fixed normal: its ``d`` is the
largest penetration of the boundary into the circle, its force the size of
the force on the circle ``|F|`` and its stored energy the spread penalty's
``V(q, c)``, all read from the host's state and the centre's port
(:func:`circle_rows` finds them with the rows, :func:`circle_forces` and
:func:`circle_potentials` give them back).  The force on the circle passes
through its centre, so it is applied to the partner's port as a vector:
after the host's step, :func:`circle_hosted_force` turns the step's vector
impulse and first moment into the linear force polynomial of the same
impulse and first moment projected on the impulse's direction, and turns
the partner's column of the port-force maps to that direction (the work
the partner received is then booked with the force as it was applied).
The part of the first moment across that direction (the force's turning
within one step) is not handed over: a coupling error of the order of the
turn per step, which the contact's ledger shows.
"""
from __future__ import annotations

import numpy as np

__all__ = ["circle_rows", "circle_forces", "circle_potentials", "circle_hosted_force"]


def _centre(system, c, outs):
    _, _, partner, port, _ = system.hosted[c]
    pos, vel = outs[partner]
    return np.asarray(pos[port], float), np.asarray(vel[port], float)


def circle_rows(system, outs, d, dd) -> None:
    """Put each circle's row (largest penetration and its rate) into ``d``,
    ``dd`` in place, from outputs ``outs`` and the hosts' present states, and
    keep its energy and force size for :func:`circle_potentials` and
    :func:`circle_forces`."""
    now = {}
    for c, (host, _, _, _, e) in system.circles.items():
        sub = system.subsystems[host]
        m = sub.n_modes
        q, dq = sub.x[:m], sub.x[m:2 * m]
        centre, velocity = _centre(system, c, outs)
        d[c], dd[c] = e.row_at(q, dq, centre, velocity)
        energy, _, on_circle = e.circle.evaluate(q, centre)
        now[c] = (energy, float(np.hypot(*on_circle)))
    system.circle_now = now


def circle_forces(system, f) -> None:
    """Each circle's force size [N] into ``f`` (indexed by contact) in place."""
    for c, (_, size) in getattr(system, "circle_now", {}).items():
        f[c] = size


def circle_potentials(system, out) -> None:
    """Each circle's stored energy ``V(q, c)`` [J] into ``out`` in place."""
    for c, (energy, _) in getattr(system, "circle_now", {}).items():
        out[c] = energy


def circle_hosted_force(system, c: int, h: float) -> np.ndarray:
    """The row force polynomial (coefficients (2,), lowest first) that the
    partner of circle ``c`` receives over the host's last step of length
    ``h``, its column of the port-force maps turned to the direction of the
    step's impulse on the circle."""
    _, _, partner, port, e = system.hosted[c]
    m0, m1 = e.quad[:2] / h, e.quad[2:] / h        # int F ds, int F s ds over s in [0, 1]
    size = float(np.hypot(*m0))
    if size == 0.0:
        return np.zeros(2)
    u = m0 / size
    system.set_port_column(partner, port, c, u)
    a0, a1 = 4.0 * m0 - 6.0 * m1, 12.0 * m1 - 6.0 * m0
    return np.array([a0 @ u, a1 @ u])

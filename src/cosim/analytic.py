"""Closed-form answers used by the verification suite and the tests.

They live here once (the library's ``cosim verify`` needs them as much as
the tests do).
"""
from __future__ import annotations

import math

__all__ = ["linear_contact", "kelvin_voigt_clipped", "held_force_rebound_factor"]


def linear_contact(mass: float, contact_stiffness: float) -> float:
    """Duration [s] of an undamped linear penalty contact, ``pi sqrt(m/k)``;
    the rebound speed equals the approach speed."""
    return math.pi * math.sqrt(mass / contact_stiffness)


def kelvin_voigt_clipped(mass: float, contact_stiffness: float, contact_damping: float):
    """Contact time [s] and restitution of a Kelvin-Voigt contact whose force
    is clipped at zero (never tensile).

    With ``omega = sqrt(k/m)``, ``zeta = c / (2 sqrt(k m))`` (``< 1``),
    ``omega_d = omega sqrt(1 - zeta^2)`` and ``beta = zeta omega``, the free
    response from ``d = 0, dd = v0`` is
    ``d = v0/omega_d exp(-beta t) sin(omega_d t)``.  The force
    ``k d + c dd`` reaches zero, before the penetration does, where
    ``tan(omega_d t) = -2 zeta sqrt(1-zeta^2) / (1 - 2 zeta^2)``, i.e.
    ``omega_d t_c = pi - 2 arcsin(zeta)``; there
    ``dd(t_c) = -v0 exp(-beta t_c)``, so the restitution is
    ``exp(-beta t_c)``.  The textbook ``exp(-zeta pi / sqrt(1 - zeta^2))``
    lets the force pull at the end of contact.

    References
    ----------
    Schwager, T., Poeschel, T. (2007). Coefficient of restitution and
    linear-dashpot model revisited. Granular Matter 9, 465-469.

    Returns
    -------
    t_c : float
        Duration of the contact force [s].
    restitution : float
    """
    omega = math.sqrt(contact_stiffness / mass)
    zeta = contact_damping / (2.0 * math.sqrt(contact_stiffness * mass))
    if not 0.0 <= zeta < 1.0:
        raise ValueError(f"`zeta` must be in [0, 1) for this closed form, got {zeta!r}")
    omega_d = omega * math.sqrt(1.0 - zeta * zeta)
    t_c = (math.pi - 2.0 * math.asin(zeta)) / omega_d
    return t_c, math.exp(-zeta * omega * t_c)


def held_force_rebound_factor(omega: float, macro_step: float) -> float:
    """Rebound speed over approach speed of an undamped penalty contact
    coupled explicitly with the force held over each macro step.

    Holding the force acts as a delay of ``H/2``; the delayed oscillator
    ``x'' = -omega^2 x(t - H/2)`` grows at the rate ``omega^2 H / 4``, so
    over one contact (``pi / omega``) the speed grows by
    ``exp(pi omega H / 4)``.
    """
    return math.exp(math.pi * omega * macro_step / 4.0)

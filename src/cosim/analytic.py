"""Closed-form answers used by the verification suite and the tests.

They live here once (the library's ``cosim verify`` needs them as much as
the tests do).
"""
from __future__ import annotations

import math

from scipy.special import beta as _beta

from couplers.restitution import (_checked, hunt_crossley_damping_for_restitution,
                                  hunt_crossley_restitution)

__all__ = ["linear_contact", "kelvin_voigt_clipped", "held_force_rebound_factor",
           "hertz_contact", "hunt_crossley_restitution", "hunt_crossley_damping_for_restitution"]


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


def hertz_contact(mass: float, contact_stiffness: float, impact_speed: float,
                  exponent: float = 1.5) -> tuple[float, float]:
    """Contact time and largest penetration of an elastic power-law contact
    ``f = k d^n`` struck by a mass ``m`` at speed ``v0``.

    With the length ``L = (m v0^2 / k)^(1/(n+1))`` and the time ``T = L / v0``
    the motion is ``x'' = -x^n``, ``x(0) = 0``, ``x'(0) = 1``; energy gives
    ``x_max = ((n+1)/2)^(1/(n+1))`` and
    ``t_c / T = 2 x_max B(1/(n+1), 1/2) / (n+1)`` (``B`` the beta function,
    from ``int_0^1 (1 - u^(n+1))^(-1/2) du``).  For ``n = 1`` this is
    ``pi sqrt(m/k)``; for Hertz's ``n = 3/2``,
    ``t_c = 3.21807 (m^2 / (k^2 v0))^(1/5)`` and ``t_c = 2.9433 d_max / v0``
    (Johnson rounds the latter to ``2.94``; ``2.94 x_max`` gives the often
    quoted ``3.2145``, 0.1 % short).  The rebound speed equals ``v0``.

    Parameters
    ----------
    mass : float
        ``m`` [kg].
    contact_stiffness : float
        ``k`` [N/m^n].
    impact_speed : float
        Approach speed ``v0`` [m/s].
    exponent : float
        ``n`` [-], ``> 0``.

    Returns
    -------
    t_c : float
        Duration of the contact [s].
    d_max : float
        Largest penetration [m].

    References
    ----------
    Johnson, K. L. (1985). Contact Mechanics. Cambridge University Press.
    """
    n = _checked(exponent, "exponent", "> 0")
    m, k, v0 = (_checked(x, nm, "> 0") for x, nm in
                ((mass, "mass"), (contact_stiffness, "contact_stiffness"),
                 (impact_speed, "impact_speed")))
    length = (m * v0 * v0 / k) ** (1.0 / (n + 1.0))
    x_max = (0.5 * (n + 1.0)) ** (1.0 / (n + 1.0))
    tau_c = 2.0 * x_max * float(_beta(1.0 / (n + 1.0), 0.5)) / (n + 1.0)
    return tau_c * length / v0, x_max * length

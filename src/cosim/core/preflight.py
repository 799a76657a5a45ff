"""Pre-flight stability check of explicit coupling on a contact.

The model problem is the contact itself: the reduced mass ``m`` of the two
ports along the normal against the law's linearised spring ``k`` and dashpot
``c``.  An explicit scheme hands each side a force extrapolated from past
communication points (held, linear or quadratic); the mass then moves exactly
under that polynomial.  One macro step is a linear map of
``z = [d, dd, f_{n-1}, f_{n-2}]``, so the whole contact (``N`` steps of a
half period ``pi / omega_d``) is ``A**N``.

Holding the force over a step acts like a delay of ``H/2``: undamped contact
then always gains energy, the rebound speed growing by about
``exp(pi omega H / 4)`` per impact; a damped one is stable in sustained
contact only while ``H < 2 c / k``.  A step is *safe* when the energy gained
over one contact, relative to the exact motion, stays below ``max_energy_gain``
and, with damping, the map's spectral radius does not exceed one.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["contact_time", "step_map", "contact_energy_gain", "is_safe", "largest_safe_step",
           "bisect_log",
           "advised_step",
           "partner_first", "stiffest_normal", "EXPLICIT_STABILITY", "stiffest_mode"]

#: the explicit Runge-Kutta methods of the monolithic scheme (RK45 and DOP853 by
#: :mod:`cosim.core.embedded_rk`, as a robot's ``rk45`` and ``dop853``; RK23 by
#: :func:`scipy.integrate.solve_ivp`: the same Butcher tables, so the same regions) ->
#: the farthest reach ``h |lambda|`` of their stability region along the real
#: or the imaginary axis, whichever is longer (from their Butcher tables:
#: RK23 2.51 real, 1.73 imaginary; RK45 3.31 real, 1.00 imaginary; DOP853
#: 6.39 real, 5.96 imaginary).  A mode of angular frequency ``omega`` keeps
#: their step below ``reach / omega`` however little it moves: the error
#: control sees it grow otherwise.  The implicit methods (Radau, BDF, LSODA)
#: have no such bound.
EXPLICIT_STABILITY = {"RK23": 2.51, "RK45": 3.31, "DOP853": 6.39}


def stiffest_mode(system) -> tuple[float, str]:
    """The highest angular frequency [rad/s] the coupled ``system`` holds in
    every state, and what it is: the highest kept mode of its structures
    (a contact's own frequency counts only while it is closed, so it is left
    out).  ``(0.0, "")`` without a structure."""
    best = (0.0, "")
    for sub in system.subsystems:
        if "modes" not in sub.capabilities or not np.size(sub.omega):
            continue
        w = float(np.max(sub.omega))
        if w > best[0]:
            best = (w, f"the highest kept mode of `{sub.name}`, {w / (2 * math.pi):.4g} Hz")
    return best


def contact_time(mass: float, stiffness: float, damping: float) -> float:
    """Duration [s] of one contact of a linear spring ``stiffness`` [N/m] and
    dashpot ``damping`` [N s/m] whose force is never tensile, for a reduced
    mass ``mass`` [kg]: ``pi / omega`` undamped, shortened by the dashpot
    (the closed form of :func:`cosim.studies.analytic.kelvin_voigt_clipped`,
    which uses this); ``pi / omega`` for a damping ratio of 1 or more, where
    that closed form ends.  ``cosim info`` quotes it at a contact's pose."""
    omega = math.sqrt(stiffness / mass)
    zeta = damping / (2.0 * math.sqrt(stiffness * mass))
    if not 0.0 < zeta < 1.0:
        return math.pi / omega
    return (math.pi - 2.0 * math.asin(zeta)) / (omega * math.sqrt(1.0 - zeta * zeta))


def partner_first(system, c, scheme: str, order: int) -> bool:
    """Whether scheme ``scheme`` hands contact ``c``'s force to a side after
    its partner has stepped, at extrapolation order ``order``: Gauss-Seidel
    does so only against a rigid partner (whose motion is known over the
    step) and with the stepping side's own motion extrapolated (order > 0).
    Between two moving sides the force is extrapolated as in Jacobi.  The
    schemes' pre-flight check and ``cosim info`` both ask here, so they give
    the same largest safe step."""
    ln = system.links[c]
    return (scheme == "gauss_seidel" and order > 0
            and (system.subsystems[ln.sub_a].rigid or system.subsystems[ln.sub_b].rigid))


def stiffest_normal(link) -> tuple[float, float]:
    """Linearised normal stiffness [N/m] and damping [N s/m] of a
    :class:`~cosim.core.system.ContactLink` for stability checks: its law's, or
    its grasp's when that is stiffer."""
    law, conn = link.contact.law, link.connection
    if conn is not None and conn.grasp is not None and conn.grasp.stiffness > law.stiffness:
        return conn.grasp.stiffness, conn.grasp.damping
    return law.stiffness, law.damping


def _poly_rows(order: int, gs_partner_first: bool, k: float, c: float, H: float):
    """Rows expressing force coefficients a0..a2 in z = [d, v, f1, f2]."""
    fn = np.array([k, c, 0.0, 0.0])
    f1 = np.array([0.0, 0.0, 1.0, 0.0])
    f2 = np.array([0.0, 0.0, 0.0, 1.0])
    zero = np.zeros(4)
    if order == 0:
        return fn, zero, zero
    if gs_partner_first:
        ftilde = np.array([k, k * H + c, 0.0, 0.0])
        return fn, ftilde - fn, zero
    if order == 1:
        return fn, fn - f1, zero
    return fn, (3 * fn - 4 * f1 + f2) / 2, (fn - 2 * f1 + f2) / 2


def step_map(m, k, c, H, order, gs_partner_first=False) -> np.ndarray:
    """One macro step of the model problem as a 4x4 matrix."""
    a0, a1, a2 = _poly_rows(order, gs_partner_first, k, c, H)
    imp = (a0 + a1 / 2 + a2 / 3) * H / m
    mom = (a0 / 2 + a1 / 6 + a2 / 12) * H * H / m
    A = np.zeros((4, 4))
    A[0] = np.array([1.0, H, 0, 0]) - mom
    A[1] = np.array([0.0, 1.0, 0, 0]) - imp
    A[2] = np.array([k, c, 0, 0])
    A[3] = np.array([0.0, 0, 1, 0])
    return A


def _exact_map(m, k, c, H):
    """``expm(A H)``, ``A = [[0, 1], [-k/m, -c/m]]``, in closed form: with
    ``mu = -c / (2 m)`` and ``d**2 = mu**2 - k/m``, ``expm(A H) = C I + S
    (A - mu I)``, ``C = e^(mu H) cosh(d H)`` and ``S = e^(mu H) sinh(d H) /
    d`` (``cos``, ``sin`` with ``|d|`` when ``d**2 < 0``; ``S = e^(mu H) H``
    when ``d = 0``).  Where ``d`` is real, over ``e^((mu -+ d) H)`` (``mu +
    d`` as ``(k/m) / (mu - d)``) and ``expm1(2 d H)``, so that nothing
    overflows or cancels.  A 2x2
    Pade ``expm`` called many times by a bisection (a refused step's
    advice) costs more than the whole choice of steps."""
    w2, z2 = k / m, c / m
    mu = -0.5 * z2
    d2 = mu * mu - w2
    if d2 > 0.0:                        # overdamped: two real rates
        d = math.sqrt(d2)
        slow = w2 / (mu - d)            # mu + d, without its cancellation
        low, high = math.exp((mu - d) * H), math.exp(slow * H)
        C = 0.5 * (high + low)
        S = (low * math.expm1(2.0 * d * H) if 2.0 * d * H < 1.0 else high - low) / (2.0 * d)
    elif d2 < 0.0:                      # underdamped
        wd = math.sqrt(-d2)
        e = math.exp(mu * H)
        C = e * math.cos(wd * H)
        S = e * math.sin(wd * H) / wd
    else:
        C = math.exp(mu * H)
        S = C * H
    return np.array([[C - S * mu, S], [-S * w2, C - S * (z2 + mu)]])


def contact_energy_gain(m, k, c, H, order, gs_partner_first=False) -> float:
    """Energy after one contact under the scheme, over the exact energy."""
    w = math.sqrt(k / m)
    zeta = c / (2 * math.sqrt(k * m))
    wd = w * math.sqrt(max(1.0 - zeta * zeta, 1e-12))
    n = max(1, round(math.pi / wd / H))
    zs = np.linalg.matrix_power(step_map(m, k, c, H, order, gs_partner_first), n) \
        @ np.array([0.0, 1.0, 0.0, 0.0])
    ze = np.linalg.matrix_power(_exact_map(m, k, c, H), n) @ np.array([0.0, 1.0])
    es = zs[1] ** 2 + (k / m) * zs[0] ** 2
    ee = ze[1] ** 2 + (k / m) * ze[0] ** 2
    return float(es / ee)


def is_safe(m, k, c, H, order, max_energy_gain, gs_partner_first=False) -> bool:
    gain = contact_energy_gain(m, k, c, H, order, gs_partner_first)
    if not math.isfinite(gain) or gain > 1.0 + max_energy_gain:
        return False
    if c > 0:
        rho = max(abs(np.linalg.eigvals(step_map(m, k, c, H, order, gs_partner_first))))
        return rho <= 1.0 + 1e-12
    return True


def bisect_log(safe, lo: float, hi: float, rounds: int = 50) -> float:
    """The largest step between ``lo`` (safe) and ``hi`` (not) that
    ``safe(step)`` accepts, by bisection in log step to 0.1 %."""
    for _ in range(rounds):
        mid = math.sqrt(lo * hi)
        if safe(mid):
            lo = mid
        else:
            hi = mid
        if hi / lo < 1.001:
            break
    return lo


def largest_safe_step(m, k, c, H, order, max_energy_gain, gs_partner_first=False) -> float:
    """Largest safe step below ``H`` (bisection in log H)."""
    def safe(h):
        return is_safe(m, k, c, h, order, max_energy_gain, gs_partner_first)
    lo = H * 1e-8
    if not safe(lo):
        return 0.0
    return bisect_log(safe, lo, H)


def advised_step(problems, H) -> float:
    """The step [s] a pre-flight refusal advises: safe for every contact of
    ``problems`` (``(m, k, c, order, max_energy_gain, gs_partner_first)``
    each, as :func:`is_safe` takes them) at the value as the message prints
    it (two significant digits, ``{:.2g}``), so that a user who sets the
    printed value passes the check.  It starts from the smallest
    :func:`largest_safe_step` below ``H`` [s], rounded down, and is lowered
    by a tenth at a time while a contact finds it unsafe (the energy gain
    need not fall monotonically with the step).  0.0 if a contact has no
    safe step or none is found within 40 tries."""
    if not problems:
        return H
    h = min(largest_safe_step(m, k, c, H, order, gain, pf) for m, k, c, order, gain, pf in problems)
    for _ in range(40):
        if not h > 0:
            return 0.0
        e = math.floor(math.log10(h)) - 1
        h = float(f"{math.floor(h / 10.0 ** e) * 10.0 ** e:.2g}")   # as printed, rounded down
        if h > 0 and all(is_safe(m, k, c, h, order, gain, pf)
                         for m, k, c, order, gain, pf in problems):
            return h
        h *= 0.9
    return 0.0

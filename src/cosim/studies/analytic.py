"""Closed-form answers used by the verification suite and the tests.

They live here once (the library's ``cosim verify`` needs them as much as
the tests do).
"""
from __future__ import annotations

import math

import numpy as np
from scipy.special import beta as _beta

from cosim.core.preflight import contact_time
from couplers.restitution import (_checked, hunt_crossley_damping_for_restitution,
                                  hunt_crossley_restitution)

__all__ = ["linear_contact", "kelvin_voigt_clipped", "held_force_rebound_factor",
           "hertz_contact", "hunt_crossley_restitution", "hunt_crossley_damping_for_restitution",
           "two_mass_oscillator", "mass_on_pinned_beam", "bounce_times", "zeno_time",
           "chatter_stop"]


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
    t_c = contact_time(mass, contact_stiffness, contact_damping)
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


def two_mass_oscillator(masses, stiffnesses, coupling_stiffness: float, preload: float,
                        q0, dq0, t):
    """Exact motion of two grounded masses coupled by a preloaded linear spring.

    Mass ``i`` moves along x at ``q_i``, tied to the ground by a spring of
    stiffness ``k_i`` (rest at 0).  The coupling spring pushes mass 1 by
    ``+k_c d`` and mass 2 by ``-k_c d``, with ``d = preload - q_1 + q_2``
    (a contact of normal +x, offset ``preload``, that stays closed):

    ``M q'' + K q = k_c preload (1, -1)``,
    ``M = diag(m_1, m_2)``,
    ``K = [[k_1 + k_c, -k_c], [-k_c, k_2 + k_c]]``.

    The motion is the static deflection ``q_s = K^-1 k_c preload (1, -1)``
    plus the free vibration about it, summed over the two modes of
    ``K phi = omega^2 M phi`` (mass-normalised, ``phi^T M phi = 1``):
    ``q(t) = q_s + sum_j phi_j (a_j cos(omega_j t) + b_j / omega_j sin(omega_j t))``,
    ``a_j = phi_j^T M (q0 - q_s)``, ``b_j = phi_j^T M dq0``.  This is the
    linear two-mass benchmark of co-simulation (Kuebler and Schiehlen 2000;
    Busch 2016).  It holds only while ``d > 0``; check ``d`` along the
    returned motion.

    Parameters
    ----------
    masses : (2,) sequence of float
        ``m_1, m_2`` [kg], > 0.
    stiffnesses : (2,) sequence of float
        Ground springs ``k_1, k_2`` [N/m], >= 0.
    coupling_stiffness : float
        ``k_c`` [N/m], > 0.
    preload : float
        Penetration at ``q = 0`` [m].
    q0, dq0 : (2,) sequence of float
        Initial positions [m] and velocities [m/s].
    t : float or array of float
        Times [s].

    Returns
    -------
    q, dq : ndarray, shape ``t.shape + (2,)``
        Positions [m] and velocities [m/s] at ``t``.
    omega : ndarray, shape (2,)
        Natural angular frequencies [rad/s], ascending.

    References
    ----------
    Kuebler, R., Schiehlen, W. (2000). Two methods of simulator coupling.
    Mathematical and Computer Modelling of Dynamical Systems 6, 93-113.
    Busch, M. (2016). Zur effizienten Kopplung von Simulationsprogrammen.
    Kassel University Press.
    """
    from scipy.linalg import eigh

    m = np.asarray(masses, float)
    k = np.asarray(stiffnesses, float)
    kc = float(coupling_stiffness)
    if m.shape != (2,) or np.any(m <= 0):
        raise ValueError(f"`masses` must be two values > 0 kg, got {masses!r}")
    if k.shape != (2,) or np.any(k < 0):
        raise ValueError(f"`stiffnesses` must be two values >= 0 N/m, got {stiffnesses!r}")
    if not kc > 0:
        raise ValueError(f"`coupling_stiffness` must be > 0 N/m, got {coupling_stiffness!r}")
    M = np.diag(m)
    K = np.array([[k[0] + kc, -kc], [-kc, k[1] + kc]])
    q_s = np.linalg.solve(K, kc * preload * np.array([1.0, -1.0]))
    omega2, phi = eigh(K, M)               # mass-normalised: phi^T M phi = I
    omega = np.sqrt(omega2)
    a = phi.T @ M @ (np.asarray(q0, float) - q_s)
    b = phi.T @ M @ np.asarray(dq0, float)
    wt = np.multiply.outer(np.asarray(t, float), omega)
    modal_q = a * np.cos(wt) + b / omega * np.sin(wt)
    modal_dq = -a * omega * np.sin(wt) + b * np.cos(wt)
    return q_s + modal_q @ phi.T, modal_dq @ phi.T, omega


def mass_on_pinned_beam(mass: float, contact_stiffness: float, impact_speed: float,
                        position: float, length: float, bending_stiffness: float,
                        mass_per_length: float, n_modes: int):
    """First contact of a point mass dropped on a simply supported beam at rest,
    through a linear penalty spring, by modal superposition of the continuum.

    The pinned-pinned Euler-Bernoulli beam has the modes
    ``phi_k(x) = sqrt(2 / (rho A L)) sin(k pi x / L)`` (mass-normalised) with
    ``omega_k = (k pi / L)^2 sqrt(EI / (rho A))`` (Blevins 1979; Timoshenko,
    Young and Weaver 1974).  Keep ``N`` of them, ``w(x, t) = sum_k phi_k(x)
    eta_k(t)``.  The mass ``m`` at height ``y`` meets the beam at ``x0``
    through a spring ``k``; the penetration is ``d = w(x0) - y``.  While
    ``d > 0`` the mass and the ``N`` modes are one linear system, with
    ``z = (sqrt(m) y, eta)`` (unit mass matrix) and
    ``K = [[k/m, -k r^T / sqrt(m)], [-k r / sqrt(m), diag(omega^2) + k r r^T]]``,
    ``r_k = phi_k(x0)``.  It is solved exactly by the eigen-decomposition of
    this ``(N + 1) x (N + 1)`` matrix, from ``y = 0``, ``y' = -v0``, the
    beam at rest: ``z(t) = sum_j psi_j (psi_j^T z'(0)) sin(w_j t) / w_j``.
    The contact ends at the first zero of ``d`` after the touch, located by
    Brent's method; no gravity acts.

    Parameters
    ----------
    mass : float
        ``m`` [kg].
    contact_stiffness : float
        ``k`` [N/m].
    impact_speed : float
        ``v0`` [m/s], > 0, downwards.
    position : float
        ``x0`` [m], in ``(0, L)``.
    length : float
        ``L`` [m].
    bending_stiffness : float
        ``EI`` [N m^2].
    mass_per_length : float
        ``rho A`` [kg/m].
    n_modes : int
        ``N``, the continuum modes kept.

    Returns
    -------
    dict
        ``duration`` [s] of the first contact, ``peak_penetration`` [m], and
        ``rebound_velocity`` [m/s] of the mass at the release (upwards > 0).

    References
    ----------
    Blevins, R. D. (1979). Formulas for Natural Frequency and Mode Shape.
    Van Nostrand Reinhold.
    Timoshenko, S. P., Young, D. H., Weaver, W. (1974). Vibration Problems in
    Engineering, 4th ed. Wiley.
    """
    from scipy.linalg import eigh
    from scipy.optimize import brentq, minimize_scalar

    m, k, v0, L, EI, rA = (_checked(x, nm, "> 0") for x, nm in (
        (mass, "mass"), (contact_stiffness, "contact_stiffness"),
        (impact_speed, "impact_speed"), (length, "length"),
        (bending_stiffness, "bending_stiffness"), (mass_per_length, "mass_per_length")))
    if not 0.0 < position < L:
        raise ValueError(f"`position` must be in (0, {L}) m, got {position!r}")
    if int(n_modes) < 1:
        raise ValueError(f"`n_modes` must be >= 1, got {n_modes!r}")
    kk = np.arange(1, int(n_modes) + 1)
    omega = (kk * math.pi / L) ** 2 * math.sqrt(EI / rA)
    r = math.sqrt(2.0 / (rA * L)) * np.sin(kk * math.pi * position / L)
    n = kk.size + 1
    K = np.zeros((n, n))
    K[0, 0] = k / m
    K[0, 1:] = K[1:, 0] = -k * r / math.sqrt(m)
    K[1:, 1:] = np.diag(omega ** 2) + k * np.outer(r, r)
    w2, psi = eigh(K)
    w = np.sqrt(w2)
    c = psi.T @ np.concatenate([[-v0 * math.sqrt(m)], np.zeros(n - 1)])
    sel = np.concatenate([[-1.0 / math.sqrt(m)], r])     # d = r . eta - y

    def pen(t):
        return float(sel @ (psi @ (c * np.sin(w * t) / w)))

    # the penetration is positive from t = 0+; scan for its first sign change
    dt = 0.25 / w.max()
    t_lo, t = dt, dt
    while pen(t) > 0.0:
        t_lo, t = t, t + dt
        if t > 1e3 * math.pi / w.min():
            raise RuntimeError("`mass_on_pinned_beam`: the contact never ended")
    t_c = brentq(pen, t_lo, t, xtol=1e-15, rtol=4 * np.finfo(float).eps)
    ts = np.linspace(0.0, t_c, 4001)
    i = int(np.argmax([pen(x) for x in ts]))
    peak = minimize_scalar(lambda x: -pen(x), bounds=(ts[max(i - 1, 0)], ts[min(i + 1, 4000)]),
                           method="bounded", options={"xatol": 1e-14}).fun
    y_dot = float(psi[0] @ (c * np.cos(w * t_c))) / math.sqrt(m)
    return {"duration": t_c, "peak_penetration": -float(peak), "rebound_velocity": y_dot}


def bounce_times(drop_height: float, gravity: float, restitution: float, n: int) -> np.ndarray:
    """The first ``n`` impact times [s] of a ball dropped from rest at
    ``drop_height`` [m] above a rigid floor with Poisson restitution ``e``.

    It strikes first at ``t1 = sqrt(2 h0 / g)`` with speed
    ``v1 = sqrt(2 g h0)``; each impact returns ``e`` times the approach
    speed and a flight that leaves at speed ``v`` lands after ``2 v / g``
    with speed ``v``, so the flight after impact ``j`` lasts
    ``2 v1 e^j / g`` and

        t_k = t1 + (2 v1 / g) e (1 - e^(k-1)) / (1 - e).

    References
    ----------
    The bouncing ball is the textbook Zeno execution of a hybrid system:
    K. H. Johansson, M. Egerstedt, J. Lygeros and S. Sastry, "On the
    regularization of Zeno hybrid automata", Systems & Control Letters 38
    (1999) 141-150; B. Brogliato, *Nonsmooth Mechanics*, 3rd ed., Springer
    (2016), on accumulations of impacts.
    """
    h0, g, e = float(drop_height), float(gravity), float(restitution)
    if not (h0 > 0 and g > 0 and 0 <= e < 1):
        raise ValueError(f"need drop_height > 0, gravity > 0 and 0 <= restitution < 1, got "
                         f"{h0!r}, {g!r}, {e!r}")
    t1, v1 = math.sqrt(2 * h0 / g), math.sqrt(2 * g * h0)
    k = np.arange(1, n + 1)
    return t1 + (2 * v1 / g) * e * (1 - e ** (k - 1.0)) / (1 - e)


def zeno_time(drop_height: float, gravity: float, restitution: float) -> float:
    """The time [s] at which the impacts of :func:`bounce_times` accumulate,

        t_inf = t1 + 2 v1 e / (g (1 - e)),

    the limit of ``t_k`` (a geometric series of flights); infinitely many
    impacts come before it."""
    h0, g, e = float(drop_height), float(gravity), float(restitution)
    bounce_times(h0, g, e, 1)                    # the checks
    v1 = math.sqrt(2 * g * h0)
    return math.sqrt(2 * h0 / g) + 2 * v1 * e / (g * (1 - e))


def chatter_stop(drop_height: float, gravity: float, restitution: float, switches: int,
                 window: float) -> tuple[int, float]:
    """The impact (its number ``k``, from 1, and its time [s]) at which the
    run guard's chatter rule stops the train of :func:`bounce_times`.

    An impact is a touch and a release at one instant, so ``switches``
    switches are the last ``m = ceil(switches / 2)`` impacts, and the rule
    trips at the first ``k`` whose span ``t_k - t_(k-m+1)`` is at most
    ``window``.  The span is the sum of ``m - 1`` flights,
    ``(2 v1 / g) e^(k-m+1) (1 - e^(m-1)) / (1 - e)``, computed so (not as a
    difference of times, which would cancel)."""
    h0, g, e = float(drop_height), float(gravity), float(restitution)
    bounce_times(h0, g, e, 1)
    m = -(-int(switches) // 2)
    v1 = math.sqrt(2 * g * h0)
    k = m
    while (2 * v1 / g) * e ** (k - m + 1) * (1 - e ** (m - 1)) / (1 - e) > window:
        k += 1
    return k, float(bounce_times(h0, g, e, k)[-1])

"""The largest macro step an explicit scheme runs a contact at, judged on
the coupled system rather than on the contact's reduced mass alone.

:mod:`cosim.core.preflight` judges a contact by its model problem: one mass,
the reduced mass of its ports, against the law's spring and dashpot.  That
misses what a flexible side does.  A structure's port is not a mass: each
kept mode ``i`` (angular frequency ``omega_i``, modal damping ``c_i``, mass
normalised) moves the port by ``r_i q_i``, and a force held or extrapolated
over a macro step lags each mode by a phase ``omega_i H / 2``.  The dashpot
then feeds a mode whose ``omega_i H`` is large with the wrong sign and pumps
energy into it although the reduced-mass model, whose one frequency is low,
is strongly damped.  Under Gauss-Seidel between two moving sides, the side
that steps second gets the force the law gives with its partner's new state,
not the force its partner got: the two impulses differ.  (A 1 kg pendulum on
a tensioned cable, ``tests/test_stable_step.py``: Gauss-Seidel at 0.9 times
the one-mass model's step is stopped by the guard within the first
contact.)

Here both sides are their port's modes, along the contact's normal: a
structure's kept modes (``r_i`` its mode shapes' rows at the port), a
multibody or an FMU side one free mode of its port mass (``omega = 0``,
``r = sqrt(mobility)``), a rigid side none.  With ``p`` the participations
signed by side (``-r`` for side ``a``, ``+r`` for side ``b``) the
penetration is ``d = p . q`` and every mode obeys
``q_i'' = -omega_i^2 q_i - c_i q_i' - p_i f``.  One macro step of a
scheme that hands both sides the force polynomial of
:func:`cosim.core.preflight._poly_rows` (held, linear or quadratic,
Gauss-Seidel's interpolation against a rigid partner) is then a linear map
of ``z = [q, q', f_{n-1}, f_{n-2}]``: each mode moves exactly under the
polynomial (the exponential of its 5 x 5 augmented matrix, Van Loan's
construction: C. F. Van Loan, "Computing integrals involving the matrix
exponential", IEEE Trans. Automat. Control 23 (1978) 395-404).  This is the
model problem of :mod:`cosim.core.preflight` (one free mode of mass
``m``) extended to the modes the run integrates; the analysis of the lag of
a held force is that of explicit co-simulation, e.g. M. Busch, "Continuous
approximation techniques for co-simulation methods: analysis of numerical
stability and local error", ZAMM 96 (2016) 1061-1081.

A step is *safe* when

- one contact (its linearised contact time, the side ``a`` or side ``b``
  port set moving at unit speed) creates at most ``max_energy_gain`` of
  the initial energy over what the exact coupled motion keeps, and
- with a dashpot, the map's spectral radius ``rho`` lets no motion of the
  coupled system grow by more than ``1 + max_energy_gain`` in energy over
  one contact time: ``rho ** (2 N) <= 1 + max_energy_gain`` for its ``N``
  steps.  (Without a dashpot, sustained contact always gains energy under a
  held force: only the first test applies.)  A contact held longer (a body
  resting on a structure) may still grow slowly, under Gauss-Seidel
  between two moving sides above all, whose sides receive different
  impulses: the run that confirms the step (:mod:`cosim.scene.stable_step`)
  is what sees that.

The largest safe step is found by scanning steps upward from well below the
fastest frequency and bisecting at the first unsafe one, so a safe island
beyond an unsafe step is never reported.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.linalg import expm

from cosim.core.preflight import _poly_rows, bisect_log, contact_time

__all__ = ["port_modes", "coupled_modes", "side_mask", "coupled_step_map", "is_safe_coupled",
           "largest_safe_step_coupled", "LINEAR_LAWS"]

#: the laws whose force is linear in the penetration and its rate: the
#: coupled map is exact for them; for any other the step is judged on the
#: linearisation only
LINEAR_LAWS = ("linear", "kelvin_voigt")

#: ratio of two steps of the upward scan
SCAN_RATIO = 1.25


def port_modes(sub, port: int, normal) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The modes by which side ``sub`` moves port ``port`` along ``normal``:
    angular frequencies [rad/s], modal damping coefficients [1/s] and
    participations ``r`` [1/sqrt(kg)] (the port moves by ``r . q``).

    A structure's kept modes; any other moving side one free mode of the
    port's mobility; a rigid side (or one whose mobility is not finite and
    positive) none."""
    empty = (np.zeros(0), np.zeros(0), np.zeros(0))
    if sub.rigid:
        return empty
    if "modes" in sub.capabilities:
        r = np.asarray(sub.port_participation(port, normal), float)
        w = np.asarray(sub.omega, float)
        cd = np.broadcast_to(np.asarray(sub.modal_damping, float), w.shape)
        return w, np.array(cd, float), r
    mob = sub.port_mobility(port, normal)
    if not (math.isfinite(mob) and mob > 0):
        return empty
    return np.zeros(1), np.zeros(1), np.array([math.sqrt(mob)])


def coupled_modes(system, c: int, mobility_a: float | None = None):
    """``(omega, damping, p)`` of contact ``c``'s coupled system: both
    sides' :func:`port_modes`, side ``a``'s participations negated.
    ``mobility_a`` replaces side ``a``'s port mobility when it is a free
    mode (the pose of a first touch)."""
    ln = system.links[c]
    n = ln.contact.normal
    wa, ca, ra = port_modes(system.subsystems[ln.sub_a], ln.port_a, n)
    wb, cb, rb = port_modes(system.subsystems[ln.sub_b], ln.port_b, n)
    if mobility_a is not None and len(ra) == 1 and wa[0] == 0.0 and mobility_a > 0:
        ra = np.array([math.sqrt(mobility_a)])
    return (np.concatenate([wa, wb]), np.concatenate([ca, cb]),
            np.concatenate([-ra, rb]))


def side_mask(system, c: int) -> np.ndarray:
    """Per coupled mode of :func:`coupled_modes`: True for side ``b``'s."""
    ln = system.links[c]
    n = ln.contact.normal
    na = len(port_modes(system.subsystems[ln.sub_a], ln.port_a, n)[2])
    nb = len(port_modes(system.subsystems[ln.sub_b], ln.port_b, n)[2])
    return np.concatenate([np.zeros(na, bool), np.ones(nb, bool)])


def _mode_responses(omega, damping, H: float) -> np.ndarray:
    """``(N, 2, 5)`` maps of the modes over a step: ``[q, q'](H)`` from
    ``[q, q', u0, u1, u2](0)`` for a unit modal force ``u0 + u1 t + u2 t^2/2``
    (Van Loan: the exponential of each augmented matrix)."""
    N = len(omega)
    A = np.zeros((N, 5, 5))
    A[:, 0, 1] = 1.0
    A[:, 1, 0], A[:, 1, 1], A[:, 1, 2] = -np.asarray(omega) ** 2, -np.asarray(damping), 1.0
    A[:, 2, 3] = 1.0
    A[:, 3, 4] = 1.0
    return _expm_batch(A * H)[:, :2]


def _expm_batch(X: np.ndarray) -> np.ndarray:
    """Exponentials of a stack of small matrices, each scaled to a 1-norm of
    at most 1/2, Taylor to the 18th power (remainder below 1e-22) and
    squared back."""
    norm = np.max(np.sum(np.abs(X), axis=-2), axis=-1)
    s = np.where(norm > 0.5, np.ceil(np.log2(np.maximum(norm, 0.5) / 0.5)), 0).astype(int)
    Y = X / (2.0 ** s)[:, None, None]
    eye = np.broadcast_to(np.eye(X.shape[-1]), X.shape)
    E = eye.copy()
    for j in range(18, 0, -1):          # Horner: I + Y/1 (I + Y/2 (I + ...))
        E = eye + (Y @ E) / j
    for i in range(int(s.max()) if len(s) else 0):
        more = s > i
        E[more] = E[more] @ E[more]
    return E


def coupled_step_map(omega, damping, p, k, c, H, order, gs_partner_first=False,
                     second=None):
    """One macro step of the coupled modes as a ``(2N + 2)`` square matrix on
    ``z = [q, q', f_{n-1}, f_{n-2}]`` (see the module's docstring).

    ``second`` marks the modes of a side that Gauss-Seidel steps after its
    partner (None: Jacobi, every side extrapolates);
    ``gs_partner_first`` marks them all (a rigid partner)."""
    N = len(p)
    Z = 2 * N + 2
    fn = np.zeros(Z)
    fn[:N], fn[N:2 * N] = k * p, c * p
    f1 = np.zeros(Z)
    f1[2 * N] = 1.0
    f2 = np.zeros(Z)
    f2[2 * N + 1] = 1.0
    second = (np.zeros(N, bool) if second is None else np.asarray(second, bool))
    if gs_partner_first:
        second = np.ones(N, bool)
    a0, a1, a2 = _rows(order, False, fn, f1, f2, k, H, p, N)
    R = _mode_responses(omega, damping, H)
    M = np.zeros((Z, Z))

    def advance(which, a0, a1, a2):
        # force a0 + a1 s + a2 s^2, s = t / H: u0 = a0, u1 = a1 / H, u2 = 2 a2 / H^2
        u = np.vstack([a0, a1 / H, 2.0 * a2 / (H * H)])
        idx = np.flatnonzero(which)
        for row, rows in ((0, idx), (1, N + idx)):
            M[rows, idx] += R[idx, row, 0]
            M[rows, N + idx] += R[idx, row, 1]
            M[rows] -= p[idx, None] * (R[idx, row, 2:] @ u)

    advance(~second, a0, a1, a2)
    if second.any():
        # Gauss-Seidel: the side that steps second gets the force interpolated
        # from f_n to the law's force with its partner's new state and its own
        # (moved on by H q' at order > 0)
        ft = np.zeros(Z)
        first = np.flatnonzero(~second)
        mine = np.flatnonzero(second)
        ft += k * (p[first] @ M[first]) + c * (p[first] @ M[N + first])
        ft[mine] += k * p[mine]
        ft[N + mine] += c * p[mine] + (k * H * p[mine] if order > 0 else 0.0)
        z = np.zeros(Z)
        advance(second, fn, ft - fn, z)
    M[2 * N] = fn
    M[2 * N + 1] = f1
    return M


def _rows(order, gs_partner_first, fn, f1, f2, k, H, p, N):
    """The force coefficients a0..a2 as rows on ``z`` (the one-mass rows of
    :func:`cosim.core.preflight._poly_rows`, with ``d = p . q``)."""
    if order == 0:
        z = np.zeros_like(fn)
        return fn, z, z
    if gs_partner_first:      # own position moved on by H q': k (d + H d') + c d'
        ftilde = fn.copy()
        ftilde[N:2 * N] += k * H * p
        return fn, ftilde - fn, np.zeros_like(fn)
    if order == 1:
        return fn, fn - f1, np.zeros_like(fn)
    return fn, (3 * fn - 4 * f1 + f2) / 2, (fn - 2 * f1 + f2) / 2


def _continuous(omega, damping, p, k, c) -> np.ndarray:
    N = len(p)
    C = np.zeros((2 * N, 2 * N))
    C[:N, N:] = np.eye(N)
    C[N:, :N] = -np.diag(omega ** 2) - k * np.outer(p, p)
    C[N:, N:] = -np.diag(damping) - c * np.outer(p, p)
    return C


def _energy(x, omega, p, k) -> float:
    N = len(p)
    q, v = x[:N], x[N:2 * N]
    return 0.5 * float(v @ v + (omega * q) @ (omega * q) + k * (p @ q) ** 2)


def _starts(p: np.ndarray) -> list:
    """Initial velocities ``q'`` of one contact: the port of each side
    moving at unit speed along its own modes' participations (a striker
    side ``a``, or a struck side ``b`` moving into it)."""
    out = []
    for mask in (p < 0, p > 0):
        v = np.where(mask, p, 0.0)
        s = float(v @ p)
        if s != 0.0:
            out.append(v / s)
    return out


def energy_created(omega, damping, p, k, c, H, order, gs_partner_first=False,
                   second=None) -> float:
    """Largest energy one contact creates under the scheme over the exact
    coupled motion, as a fraction of its initial energy."""
    m = 1.0 / float(p @ p)
    t_c = contact_time(m, k, c)
    n = max(1, round(t_c / H))
    N = len(p)
    A = coupled_step_map(omega, damping, p, k, c, H, order, gs_partner_first, second)
    An = np.linalg.matrix_power(A, n)
    E = expm(_continuous(omega, damping, p, k, c) * (n * H))
    worst = -math.inf
    for v in _starts(p):
        z0 = np.concatenate([np.zeros(N), v, [0.0, 0.0]])
        x0 = z0[:2 * N]
        e0 = _energy(x0, omega, p, k)
        es = _energy((An @ z0)[:2 * N], omega, p, k)
        ee = _energy(E @ x0, omega, p, k)
        worst = max(worst, (es - ee) / e0)
    return float(worst)


def is_safe_coupled(omega, damping, p, k, c, H, order, max_energy_gain,
                    gs_partner_first=False, t_end: float = math.inf, second=None) -> bool:
    """Whether step ``H`` is safe on the coupled modes (module docstring)."""
    if H <= 0:
        return True
    with np.errstate(all="ignore"):
        gain = energy_created(omega, damping, p, k, c, H, order, gs_partner_first, second)
        if not math.isfinite(gain) or gain > max_energy_gain:
            return False
        if c > 0:
            A = coupled_step_map(omega, damping, p, k, c, H, order, gs_partner_first, second)
            rho = float(max(abs(np.linalg.eigvals(A))))
            m = 1.0 / float(p @ p)
            steps = min(t_end, contact_time(m, k, c)) / H
            allowed = (1.0 + max_energy_gain) ** (0.5 / max(steps, 1.0))
            return math.isfinite(rho) and rho <= max(allowed, 1.0 + 1e-12)
    return True


def largest_safe_step_coupled(omega, damping, p, k, c, order, max_energy_gain,
                              gs_partner_first=False, t_end: float = math.inf,
                              second=None) -> float:
    """Largest safe step [s]: scanned upward by :data:`SCAN_RATIO` from a
    thousandth of the fastest period and bisected at the first unsafe step;
    0.0 when even the smallest is unsafe.  The scan ends at ten contact
    times, beyond which a contact is over in one step."""
    m = 1.0 / float(p @ p)
    w_top = max(math.sqrt(k / m), float(np.max(omega)) if len(omega) else 0.0)
    top = 10.0 * contact_time(m, k, c)
    H = 1e-3 / w_top

    def safe(h):
        return is_safe_coupled(omega, damping, p, k, c, h, order, max_energy_gain,
                               gs_partner_first, t_end, second)

    if not safe(H):
        return 0.0
    lo = H
    while lo < top:
        hi = min(lo * SCAN_RATIO, top)
        if not safe(hi):
            return bisect_log(safe, lo, hi, rounds=30)
        lo = hi
    return lo

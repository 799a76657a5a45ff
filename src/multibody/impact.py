"""Rigid impact laws for planar multibody systems in generalised coordinates.

Every law works at one configuration: the mass matrix ``M`` (n, n), the
pre-impact generalised velocity ``dq_minus`` (n,) and, per contact, a normal
Jacobian row ``Jn`` and a tangential row ``Jt`` with ``v_n = Jn @ dq``
(negative = approaching) and ``v_t = Jt @ dq``.  Impulses act as
``dq_plus = dq_minus + M^-1 (Jn^T Pn + Jt^T Pt)``, so the contact velocities
move by ``W @ P`` with the contact inverse inertia ``W = J M^-1 J^T``.

:func:`frictionless_impact` handles simultaneous frictionless contacts (two
LCPs), :func:`frictional_impact` one contact with Coulomb friction (Routh's
method); both use Poisson's kinetic restitution.

References
----------
Stronge, W. J. (2000). *Impact Mechanics*. Cambridge University Press.
Pfeiffer, F., Glocker, C. (1996). *Multibody Dynamics with Unilateral
Contacts*. Wiley.
Glocker, C., Pfeiffer, F. (1992). Dynamical systems with unilateral contacts.
*Nonlinear Dynamics* 3, 245-259.
Stronge, W. J. (1991). Unraveling paradoxical theories for rigid body
collisions. *J. Appl. Mech.* 58(4), 1049-1055.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .checks import unit_interval

__all__ = ["ImpactResult", "frictionless_impact", "frictional_impact", "kinetic_energy"]

MAX_CONTACTS = 12   # the LCP solver enumerates 2^k active sets
_RTOL = 1e-10       # relative tolerance of complementarity checks


@dataclass(frozen=True, eq=False)
class ImpactResult:
    """Outcome of a rigid impact; arrays are read-only, ``k`` = number of contacts.

    Attributes
    ----------
    dq_plus : (n,) ndarray
        Post-impact generalised velocity [m/s or rad/s per coordinate].
    normal_impulse, compression_impulse : (k,) ndarray
        Total normal impulse and that of the compression phase [N s].
    tangential_impulse : (k,) ndarray
        Friction impulse [N s]; zeros when frictionless.
    compression_velocity, normal_velocity : (k,) ndarray
        Normal velocity at the end of compression and after the impact
        (``Jn @ dq_plus``) [m/s], both ``>= 0``.
    kinetic_energy_before, kinetic_energy_after : float
        ``1/2 dq^T M dq`` before and after the impact [J].
    slip_history : tuple of (float, float, str)
        Frictional law only: phases ``(p_start, p_end, mode)`` in normal impulse
        [N s], ``mode`` in ``{"slip+", "slip-", "stick"}``; empty otherwise.
    slip_end : str or None
        Frictional law only: ``"slipping"`` (one slip direction throughout),
        ``"stuck"`` (ends sticking) or ``"reversed"`` (slip reversed, then slid);
        ``None`` for the frictionless law.
    """

    dq_plus: np.ndarray
    normal_impulse: np.ndarray
    compression_impulse: np.ndarray
    tangential_impulse: np.ndarray
    compression_velocity: np.ndarray
    normal_velocity: np.ndarray
    kinetic_energy_before: float
    kinetic_energy_after: float
    slip_history: tuple = ()
    slip_end: str | None = None

    def __post_init__(self):
        for name in ("dq_plus", "normal_impulse", "compression_impulse", "tangential_impulse",
                     "compression_velocity", "normal_velocity"):
            a = np.array(getattr(self, name), dtype=float)
            a.flags.writeable = False
            object.__setattr__(self, name, a)

    @property
    def energy_loss(self) -> float:
        """Kinetic energy dissipated by the impact [J] (negative = gained)."""
        return self.kinetic_energy_before - self.kinetic_energy_after


# ----------------------------------------------------------------- checks
def _mass_matrix(M) -> np.ndarray:
    M = np.asarray(M, dtype=float)
    if M.ndim != 2 or M.shape[0] != M.shape[1] or M.size == 0 or not np.all(np.isfinite(M)):
        raise ValueError(f"`M` must be a finite square (n, n) matrix, got shape {M.shape}")
    asym = float(np.max(np.abs(M - M.T)))
    if asym > 1e-10 * float(np.max(np.abs(M))):
        raise ValueError(f"`M` must be symmetric, got max |M - M^T| = {asym:g}")
    smallest = float(np.linalg.eigvalsh(M)[0])
    if smallest <= 0.0:
        raise ValueError(f"`M` must be positive definite, got smallest eigenvalue {smallest:.3g}")
    return 0.5 * (M + M.T)


def _vector(v, n: int, name: str) -> np.ndarray:
    v = np.asarray(v, dtype=float)
    if v.shape != (n,) or not np.all(np.isfinite(v)):
        raise ValueError(f"`{name}` must be {n} finite numbers, got shape {v.shape}")
    return v


def _rows(J, n: int, name: str) -> np.ndarray:
    J = np.asarray(J, dtype=float)
    J = J[None, :] if J.ndim == 1 else J
    if J.ndim != 2 or J.shape[1] != n or J.shape[0] == 0 or not np.all(np.isfinite(J)):
        raise ValueError(f"`{name}` must be a finite (n,) row or (k, n) array with n = {n}, "
                         f"got shape {J.shape}")
    zero = np.flatnonzero(~np.any(J != 0.0, axis=1))
    if zero.size:
        raise ValueError(f"`{name}` row {int(zero[0])} must be nonzero, got all zeros")
    return J


def _restitution(e, k: int) -> np.ndarray:
    arr = np.asarray(e, dtype=float)
    if arr.ndim == 0:
        arr = np.full(k, float(arr))
    if arr.shape != (k,):
        raise ValueError(f"`restitution` must be a number or {k} numbers, got shape {arr.shape}")
    return np.array([unit_interval(x, "restitution") for x in arr])


def kinetic_energy(M, dq) -> float:
    """Kinetic energy ``T = 1/2 dq^T M dq`` [J].

    ``M`` (n, n) symmetric positive definite mass matrix [SI], ``dq`` (n,)
    generalised velocity [m/s or rad/s]; ValueError on bad shapes.
    """
    M = _mass_matrix(M)
    dq = _vector(dq, M.shape[0], "dq")
    return 0.5 * float(dq @ M @ dq)


# ----------------------------------------------------------------- LCP
def _lcp_min_norm(W: np.ndarray, q: np.ndarray, scale: float) -> np.ndarray:
    """Least-norm ``z`` with ``z >= 0``, ``w = W z + q >= 0``, ``z_i w_i = 0``.

    ``W`` is symmetric positive semidefinite and ``q`` lies in its range plus
    the nonnegative orthant, so a solution exists and ``w`` is unique.  Every
    active set ``S`` is tried with the least-norm (pseudo-inverse) solve of
    ``W_SS z_S = -q_S``; the least-norm solution of the LCP has its support on
    some ``S`` and equals that solve there, so the smallest valid candidate is
    the least-norm solution.  Tolerances scale with ``scale`` [m/s].
    """
    k = q.size
    vtol = _RTOL * scale
    if scale == 0.0 or np.all(q >= -vtol):
        return np.zeros(k)
    ztol = vtol / float(np.max(np.diag(W)))
    best, best_norm, fallback, fallback_err = None, np.inf, None, np.inf
    for mask in range(1, 1 << k):
        S = np.array([(mask >> i) & 1 for i in range(k)], dtype=bool)
        zS = np.linalg.lstsq(W[np.ix_(S, S)], -q[S], rcond=1e-10)[0]
        z = np.zeros(k)
        z[S] = np.maximum(zS, 0.0)
        w = W @ z + q
        err = max(float(np.max(-zS)) / ztol, float(np.max(np.abs(w[S]))) / vtol,
                  float(np.max(-w[~S], initial=0.0)) / vtol)
        if err <= 1.0:
            if z @ z < best_norm:
                best, best_norm = z, float(z @ z)
        elif err < fallback_err:
            fallback, fallback_err = z, err
    if best is None and fallback_err > 1e4:   # rounding: take a near solution, not a wrong one
        raise RuntimeError(f"LCP enumeration found no solution (relative violation "
                           f"{fallback_err * _RTOL:.3g})")
    return fallback if best is None else best


# ----------------------------------------------------------------- laws
def frictionless_impact(M, dq_minus, Jn, restitution) -> ImpactResult:
    """Simultaneous frictionless impact with Poisson restitution.

    Two LCPs in the contact impulses (Pfeiffer and Glocker 1996; Glocker and
    Pfeiffer 1992).  With ``W = Jn M^-1 Jn^T`` and ``v_minus = Jn dq_minus``:

    * compression: ``vc = W Pc + v_minus``, ``Pc >= 0``, ``vc >= 0``,
      ``Pc_i vc_i = 0``;
    * expansion: ``Pe = e_i Pc_i + Pe'`` with ``ve = W Pe' + v*``,
      ``v* = vc + W (e Pc)``, ``Pe' >= 0``, ``ve >= 0``, ``Pe'_i ve_i = 0``:
      each contact returns ``e_i`` times its compression impulse and contacts
      that would then penetrate get the extra impulse ``Pe'``.

    Total normal impulse ``P = Pc + Pe``.  One contact gives the closed form
    ``Pc = -v_minus / W``, ``P = (1 + e) Pc``, ``v_n+ = -e v_minus``.

    Parameters
    ----------
    M : (n, n) array_like
        Symmetric positive definite mass matrix at the impact configuration [SI].
    dq_minus : (n,) array_like
        Pre-impact generalised velocity [m/s or rad/s].
    Jn : (n,) or (k, n) array_like
        Normal Jacobian rows, one per contact [m/m or m/rad], nonzero.
    restitution : float or (k,) array_like
        Poisson's kinetic coefficient ``e`` in [0, 1], shared or per contact [-].

    Returns
    -------
    ImpactResult
        ``tangential_impulse`` zero, ``slip_history`` empty, ``slip_end`` None.

    Raises
    ------
    ValueError
        Bad shapes, non-SPD ``M``, ``e`` outside [0, 1], over ``MAX_CONTACTS`` rows.

    Notes
    -----
    *Which contacts to pass*: all contacts that are closed (zero gap) at the
    impact configuration, approaching or not; every row takes part.  A contact
    with ``v_n >= 0`` gets zero impulse from the LCP unless the others' impulses
    would drive it into penetration, and then it gets just the impulse that
    keeps it closed.  Do not pass open contacts: they would be held closed.

    *Redundant contacts*: when the rows of ``Jn`` are linearly dependent ``W``
    is singular; the velocities ``vc``, ``dq_plus`` are still unique but the
    impulses are not (the ambiguity pointed out by Pfeiffer and Glocker: only
    ``Jn^T P`` is determined).  Each phase returns its least-Euclidean-norm
    impulse, e.g. an equal split between two identical contacts.  The solver
    enumerates the ``2^k`` active sets, hence ``k <= MAX_CONTACTS``.
    """
    M = _mass_matrix(M)
    n = M.shape[0]
    dq = _vector(dq_minus, n, "dq_minus")
    Jn = _rows(Jn, n, "Jn")
    k = Jn.shape[0]
    if k > MAX_CONTACTS:
        raise ValueError(f"`Jn` must have at most {MAX_CONTACTS} rows (contacts), got {k}")
    e = _restitution(restitution, k)
    MinvJ = np.linalg.solve(M, Jn.T)
    W = 0.5 * (Jn @ MinvJ + (Jn @ MinvJ).T)
    v_minus = Jn @ dq
    scale = float(np.max(np.abs(v_minus)))
    Pc = _lcp_min_norm(W, v_minus, scale)
    vc = W @ Pc + v_minus
    v_star = vc + W @ (e * Pc)
    Pe_extra = _lcp_min_norm(W, v_star, max(scale, float(np.max(np.abs(v_star)))))
    P = (1.0 + e) * Pc + Pe_extra
    dq_plus = dq + MinvJ @ P
    return ImpactResult(dq_plus=dq_plus, normal_impulse=P, compression_impulse=Pc,
                        tangential_impulse=np.zeros(k), compression_velocity=vc,
                        normal_velocity=Jn @ dq_plus,
                        kinetic_energy_before=0.5 * float(dq @ M @ dq),
                        kinetic_energy_after=0.5 * float(dq_plus @ M @ dq_plus))


def frictional_impact(M, dq_minus, Jn, Jt, restitution, friction) -> ImpactResult:
    """One contact with planar Coulomb friction and Poisson restitution.

    Routh's method in impulse space (Stronge 2000, ch. 3-4): the normal
    impulse ``p`` is the independent variable and the contact velocity
    ``u = (v_n, v_t)`` obeys ``du/dp = W @ (1, dPt/dp)`` with
    ``W = [Jn; Jt] M^-1 [Jn; Jt]^T``.  ``dPt/dp`` is constant within a phase,
    so each phase is solved exactly (``u`` linear in ``p``):

    * slip in direction ``s = sign(v_t)``: ``dPt/dp = -mu s``,
      ``du/dp = (Wnn - mu s Wnt, Wnt - mu s Wtt)``;
    * stick (``v_t = 0``), possible iff ``|r| <= mu`` with ``r = -Wnt/Wtt``:
      ``dPt/dp = r``, ``du/dp = (Wnn + r Wnt, 0)``; it then lasts to the end;
    * when ``v_t`` reaches 0 and ``|r| > mu``, slip reverses: the new direction
      is ``s = sign(Wnt)``, the only one along which ``v_t`` leaves 0 in the
      direction of slip.  The same rule decides an initial ``v_t = 0``: stick if
      ``|r| <= mu``, else slip with ``s = sign(Wnt)``.

    Compression ends where ``v_n = 0`` at ``p = pc``; the impact ends at
    ``p_final = (1 + e) pc`` (Poisson's hypothesis).  Unlike Newton's kinematic
    law, Poisson's never created energy in our tests, slip reversal included
    (cf. Stronge 1991).

    Parameters
    ----------
    M, dq_minus
        As in :func:`frictionless_impact`.
    Jn, Jt : (n,) array_like
        Normal and tangential Jacobian rows of the contact, linearly independent.
    restitution : float
        Poisson's kinetic coefficient ``e`` in [0, 1] [-].
    friction : float
        Coulomb coefficient ``mu >= 0`` [-]; ``mu = 0`` reproduces
        :func:`frictionless_impact`.

    Returns
    -------
    ImpactResult
        With (1,) impulse arrays, ``slip_history`` and ``slip_end``.  A contact
        that is not approaching (``v_n >= 0``) gets no impulse, an empty history
        and ``slip_end`` "stuck" if ``v_t = 0`` else "slipping".

    Raises
    ------
    ValueError
        On bad inputs, dependent ``Jn`` and ``Jt`` (use the frictionless law),
        or a Painleve-type jam: ``Wnn - mu s Wnt <= 0`` in a slip phase, where
        ``v_n`` would not increase and no rigid-body impulse exists.
    """
    M = _mass_matrix(M)
    n = M.shape[0]
    dq = _vector(dq_minus, n, "dq_minus")
    Jn, Jt = _rows(Jn, n, "Jn"), _rows(Jt, n, "Jt")
    if Jn.shape[0] != 1 or Jt.shape[0] != 1:
        raise ValueError(f"`Jn` and `Jt` must be single rows, got {Jn.shape[0]} and {Jt.shape[0]}")
    e = unit_interval(restitution, "restitution")
    mu = math.nan if isinstance(friction, bool) else float(friction)
    if not 0.0 <= mu < math.inf:
        raise ValueError(f"`friction` must be finite and >= 0, got {friction}")
    C = np.vstack([Jn, Jt])
    MinvC = np.linalg.solve(M, C.T)
    W = C @ MinvC
    Wnn, Wnt, Wtt = float(W[0, 0]), 0.5 * float(W[0, 1] + W[1, 0]), float(W[1, 1])
    if Wnn * Wtt - Wnt**2 <= 1e-12 * Wnn * Wtt:
        raise ValueError("`Jn` and `Jt` must be linearly independent, got parallel rows")
    vn, vt = (float(x) for x in C @ dq)
    T0 = 0.5 * float(dq @ M @ dq)
    ttol = 1e-12 * max(abs(vn), abs(vt))
    r = -Wnt / Wtt
    p, Pt, pc, p_final = 0.0, 0.0, None, None
    vc = max(vn, 0.0)           # compression-end velocity: 0 if approaching
    phases: list[tuple[float, float, str]] = []
    for _ in range(8):          # at most 3 slip modes, split by the end of compression
        if not (vn < 0.0 or (pc is not None and p < p_final)):
            break
        if abs(vt) > ttol:
            s = 1.0 if vt > 0 else -1.0
        elif abs(r) <= mu:
            s = 0.0
        else:
            s = 1.0 if Wnt > 0 else -1.0
        ratio = r if s == 0.0 else -mu * s
        dvn = Wnn + Wnt * ratio
        dvt = 0.0 if s == 0.0 else Wnt + Wtt * ratio
        if dvn <= 0.0:
            raise ValueError(f"`friction` = {mu:g} jams the contact (Painleve): "
                             f"Wnn - mu s Wnt = {dvn:.3g} <= 0 while slipping with s = {s:+.0f}")
        dp_n = -vn / dvn if pc is None else p_final - p
        dp_t = -vt / dvt if s != 0.0 and dvt * vt < 0.0 else math.inf
        dp = min(dp_n, dp_t)
        mode = "stick" if s == 0.0 else ("slip+" if s > 0 else "slip-")
        if phases and phases[-1][2] == mode:
            phases[-1] = (phases[-1][0], p + dp, mode)
        elif dp > 0.0:
            phases.append((p, p + dp, mode))
        p, Pt, vn, vt = p + dp, Pt + ratio * dp, vn + dvn * dp, vt + dvt * dp
        if dp_t <= dp_n:
            vt = 0.0
        if dp_n <= dp_t:
            if pc is None:
                vn, pc, p_final = 0.0, p, (1.0 + e) * p
            else:
                p = p_final
    else:
        raise RuntimeError("frictional impact did not finish in 8 phases")
    modes = [m for _, _, m in phases]
    if not modes:
        slip_end = "stuck" if vt == 0.0 else "slipping"
    elif modes[-1] == "stick":
        slip_end = "stuck"
    else:
        slip_end = "reversed" if modes[0] != "stick" and modes[-1] != modes[0] else "slipping"
    pc, p_final = (0.0, 0.0) if pc is None else (pc, p_final)
    dq_plus = dq + MinvC @ np.array([p_final, Pt])
    return ImpactResult(dq_plus=dq_plus, normal_impulse=[p_final], compression_impulse=[pc],
                        tangential_impulse=[Pt], compression_velocity=[vc],
                        normal_velocity=Jn @ dq_plus, kinetic_energy_before=T0,
                        kinetic_energy_after=0.5 * float(dq_plus @ M @ dq_plus),
                        slip_history=tuple(phases), slip_end=slip_end)

"""The Newmark family: :class:`Newmark` [1]_, :class:`CentralDifference`,
:class:`HHTAlpha` [2]_ and :class:`GeneralizedAlpha` [3]_, one algorithm (the
form of [3]_) with different parameters, its matrix factorised once per step
size.

References
----------
.. [1] N. M. Newmark, "A method of computation for structural dynamics", J. Eng.
   Mech. Div. ASCE 85(EM3), 67-94, 1959.
.. [2] H. M. Hilber, T. J. R. Hughes, R. L. Taylor, "Improved numerical dissipation
   for time integration algorithms in structural dynamics", Earthquake Eng. Struct.
   Dyn. 5, 283-292, 1977.
.. [3] J. Chung, G. M. Hulbert, "A time integration algorithm for structural dynamics
   with improved numerical dissipation: the generalized-alpha method", J. Appl.
   Mech. 60, 371-375, 1993.
.. [4] T. J. R. Hughes, "The Finite Element Method", Prentice-Hall, 1987, ch. 9.
"""
from __future__ import annotations

import math

from .checks import real
from .integrator_base import StructuralIntegrator, _factorize

__all__ = ["Newmark", "CentralDifference", "HHTAlpha", "GeneralizedAlpha"]


class _AlphaFamily(StructuralIntegrator):
    """Generalized-alpha form [3]_ of the Newmark-family schemes.

    With ``x_{n+1-alpha} = (1 - alpha) x_{n+1} + alpha x_n``, one step solves

    ``M a_{n+1-alpha_m} + C v_{n+1-alpha_f} + K u_{n+1-alpha_f} = f(t_n + (1-alpha_f) h)``,
    ``u_{n+1} = u_n + h v_n + h^2 ((1/2 - beta) a_n + beta a_{n+1})``,
    ``v_{n+1} = v_n + h ((1 - gamma) a_n + gamma a_{n+1})``

    for ``a_{n+1}`` with the effective matrix
    ``S = (1-alpha_m) M + (1-alpha_f) (gamma h C + beta h^2 K)``, factorised once per h.
    Newmark is ``alpha_m = alpha_f = 0``, HHT ``alpha_m = 0, alpha_f = -alpha``.
    """

    alpha_m = alpha_f = 0.0
    beta, gamma = 0.25, 0.5

    def _build(self, h):
        am, af = self.alpha_m, self.alpha_f
        S = (1 - am) * self.M + ((1 - af) * self.beta * h * h) * self.K
        if self.C is not None:
            S = S + ((1 - af) * self.gamma * h) * self.C
        return _factorize(S)

    def check_step(self, h) -> None:
        """Raise ValueError if ``h`` [s] exceeds :meth:`max_stable_step` (cached per h)."""
        if h in self._ops:
            return
        lim = self.max_stable_step()
        if h > lim:
            label = self.name.replace("_", "-")
            raise ValueError(f"`h` = {h:g} s exceeds the {label} stability limit "
                             f"{lim:g} s (omega_max = {self.omega_max():g} rad/s)")

    def step(self, u, v, a, h, F):
        F = self._load(F)
        self.check_step(h)
        solve = self._operator(h)
        am, af, beta, gamma = self.alpha_m, self.alpha_f, self.beta, self.gamma
        ut = u + h * v + (h * h * (0.5 - beta)) * a        # predictors
        vt = v + (h * (1 - gamma)) * a
        s = 1.0 - af
        rhs = F[0] + sum(F[j] * s ** j for j in range(1, len(F)))
        rhs = rhs - self.K @ ((1 - af) * ut + af * u)
        if am:
            rhs -= am * (self.M @ a)
        if self.C is not None:
            rhs -= self.C @ ((1 - af) * vt + af * v)
        a1 = solve(rhs)
        return ut + (beta * h * h) * a1, vt + (gamma * h) * a1, a1


class Newmark(_AlphaFamily):
    """Newmark's method [1]_; load evaluated at ``t + h``.

    Parameters
    ----------
    beta, gamma : float
        Newmark parameters; the default ``beta = 1/4, gamma = 1/2`` is the average
        acceleration (trapezoidal) rule: second order, unconditionally stable, no
        numerical damping, energy-conserving for undamped linear systems.

    Notes
    -----
    Second order only for ``gamma = 1/2`` (first order otherwise, ``order``
    refers to the default).  Unconditionally stable for ``2 beta >= gamma >= 1/2``;
    otherwise :meth:`step` refuses steps above :meth:`max_stable_step`.
    """

    order = 2
    name = "newmark"

    def __init__(self, M, C, K, *, beta=0.25, gamma=0.5):
        super().__init__(M, C, K)
        self.beta = real("beta", beta, 0.0, rule=">= 0")
        self.gamma = real("gamma", gamma, 0.5, rule=">= 1/2")

    def max_stable_step(self) -> float:
        """``Omega_crit / omega_max`` [s] with ``Omega_crit = (gamma/2 - beta)^(-1/2)``
        ([4]_, ch. 9; it ignores damping, which for ``gamma = 1/2`` leaves the
        limit unchanged and for ``gamma > 1/2`` raises it), ``math.inf`` if
        ``2 beta >= gamma``."""
        if 2 * self.beta >= self.gamma:
            return math.inf
        w = self.omega_max()
        return math.inf if w == 0 else 1.0 / math.sqrt(self.gamma / 2 - self.beta) / w


class CentralDifference(Newmark):
    """Explicit central difference: Newmark ``beta = 0, gamma = 1/2``.

    Second order, conditionally stable: ``h <= 2 / omega_max``.  The damping force is
    taken at ``t + h`` (matrix ``M + h C / 2``, explicit if M and C are diagonal), so
    the limit does not shrink with damping ([4]_, ch. 9; checked numerically); the
    ``(2/omega)(sqrt(1 + zeta^2) - zeta)`` limit belongs to the variant that lags the
    damping force by half a step.  :meth:`step` calls :meth:`check_step`.

    Notes
    -----
    For undamped free vibration the scheme conserves the modified energy
    ``energy(u, v) - (h^2 / 8) a^T M a`` (``M a = -K u``), not :meth:`energy`,
    which oscillates by about ``(omega h)^2 / 4`` relative.
    """

    order = 2
    name = "central_difference"

    def __init__(self, M, C, K):
        super().__init__(M, C, K, beta=0.0, gamma=0.5)


class HHTAlpha(_AlphaFamily):
    """Hilber-Hughes-Taylor alpha method [2]_; load at ``t + (1 + alpha) h``.

    ``M a_{n+1} + (1+alpha)(C v_{n+1} + K u_{n+1}) - alpha (C v_n + K u_n) = f``
    with ``beta = (1 - alpha)^2 / 4``, ``gamma = 1/2 - alpha``: second order,
    unconditionally stable, damping of the high frequencies growing with ``-alpha``.

    Parameters
    ----------
    alpha : float
        In ``[-1/3, 0]``; ``0`` is the average-acceleration rule.
    """

    order = 2
    name = "hht_alpha"

    def __init__(self, M, C, K, *, alpha=-0.05):
        super().__init__(M, C, K)
        self.alpha = real("alpha", alpha, -1 / 3, 0.0, "in [-1/3, 0]")
        self.alpha_m, self.alpha_f = 0.0, -self.alpha
        self.beta, self.gamma = (1 - self.alpha) ** 2 / 4, 0.5 - self.alpha


class GeneralizedAlpha(_AlphaFamily):
    """Chung-Hulbert generalized-alpha method [3]_; load at ``t + (1 - alpha_f) h``.

    ``alpha_m = (2 rho_inf - 1)/(rho_inf + 1)``, ``alpha_f = rho_inf/(rho_inf + 1)``,
    ``gamma = 1/2 - alpha_m + alpha_f``, ``beta = (1 - alpha_m + alpha_f)^2 / 4``:
    second order, unconditionally stable, optimal high-frequency dissipation.

    Parameters
    ----------
    rho_inf : float
        Spectral radius at infinite frequency, in ``[0, 1]``; ``1`` is
        non-dissipative (trapezoidal), ``0`` annihilates the highest modes in one step.

    Notes
    -----
    The carried ``a`` is the algorithmic acceleration, not ``M^{-1}(f - C v - K u)``.
    """

    order = 2
    name = "generalized_alpha"

    def __init__(self, M, C, K, *, rho_inf=0.8):
        super().__init__(M, C, K)
        r = self.rho_inf = real("rho_inf", rho_inf, 0.0, 1.0, "in [0, 1]")
        self.alpha_m, self.alpha_f = (2 * r - 1) / (r + 1), r / (r + 1)
        self.gamma = 0.5 - self.alpha_m + self.alpha_f
        self.beta = 0.25 * (1 - self.alpha_m + self.alpha_f) ** 2

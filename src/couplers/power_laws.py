"""The power laws ``f = k d^n (1 + chi dd)``: :class:`HertzLaw` (elastic),
:class:`HuntCrossleyLaw` (``chi`` given), :class:`LankaraniNikraveshLaw` and
:class:`FloresLaw` (``chi`` calibrated from a restitution at an impact
speed)."""
from __future__ import annotations

import math
import warnings
from abc import abstractmethod
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from .checks import positive
from .law_base import ContactLaw

__all__ = ["HertzLaw", "HuntCrossleyLaw", "LankaraniNikraveshLaw", "FloresLaw"]

# Largest |actual - requested| restitution ``for_restitution`` accepts silently.
_RESTITUTION_WARNING = 0.05


def _exponent(value) -> float:
    try:
        n = float(value)
    except (TypeError, ValueError):
        raise TypeError(f"`exponent` must be a number [-], got {value!r}") from None
    if not (math.isfinite(n) and n >= 1.0):
        raise ValueError(f"`exponent` must be >= 1, got {value!r}")
    return n


def _restitution(value, zero_allowed: bool) -> float:
    interval = "[0, 1]" if zero_allowed else "(0, 1]"
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)):
        raise TypeError(f"`restitution` must be a number in {interval}, got {value!r}")
    e = float(value)
    if not ((0.0 <= e if zero_allowed else 0.0 < e) and e <= 1.0):
        raise ValueError(f"`restitution` must be in {interval}, got {value!r}")
    return e


@dataclass(frozen=True)
class _PowerLaw(ContactLaw):
    """``f = k d^n (1 + chi dd)`` for ``d > 0``, clipped at zero: the part the
    power laws share.  Subclasses say where ``chi`` comes from."""

    contact_stiffness: float
    exponent: float
    reference_penetration: float | None = field(default=None, kw_only=True)

    def __post_init__(self):
        n = _exponent(self.exponent)
        object.__setattr__(self, "exponent", n)
        unit = "N/m" if n == 1.0 else f"N/m^{n:g}"
        object.__setattr__(self, "contact_stiffness",
                           positive(self.contact_stiffness, "contact_stiffness", unit))
        if self.reference_penetration is not None:
            object.__setattr__(self, "reference_penetration",
                               positive(self.reference_penetration, "reference_penetration", "m"))

    @abstractmethod
    def _chi(self) -> float:
        """Hysteresis damping ``chi`` [s/m]."""

    def hysteresis_chi(self) -> float:
        """Hysteresis damping ``chi`` [s/m] of ``k d^n (1 + chi dd)``, as the
        compiled kernels take it (:func:`cosim.core.links.kernel_law`)."""
        return self._chi()

    def force_active(self, d, dd):
        """``k d^n (1 + chi dd)`` [N]; ``d^n`` is read as 0 for ``d < 0``."""
        dp = np.maximum(d, 0.0)
        return self.contact_stiffness * dp ** self.exponent * (1.0 + self._chi() * dd)

    def potential(self, d):
        n = self.exponent
        if isinstance(d, float):        # one value (numpy's float64 too): no array calls
            return self.contact_stiffness * (d if d > 0.0 else 0.0) ** (n + 1.0) / (n + 1.0)
        return self.contact_stiffness * np.maximum(d, 0.0) ** (n + 1.0) / (n + 1.0)

    def evaluate(self, d, dd):
        # ContactLaw.evaluate's formulas on one value, without array calls
        chi = self._chi()
        slope = self.contact_stiffness * (d if d > 0.0 else 0.0) ** self.exponent
        if chi == 0.0:
            s = d
        else:
            a = d * (1.0 + chi * dd)
            s = d if d < a else a
        fa = slope * (1.0 + chi * dd)
        f = (fa if fa > 0.0 else 0.0) if s > 0.0 else 0.0
        return f, (f - slope) * dd, s

    def potential_slope(self, d):
        if isinstance(d, float):
            return self.contact_stiffness * (d if d > 0.0 else 0.0) ** self.exponent
        return self.contact_stiffness * np.maximum(d, 0.0) ** self.exponent

    def switch(self, d, dd):
        """``min(d, d (1 + chi dd))`` [m]: positive where ``d > 0`` and the
        hysteresis factor ``1 + chi dd`` is, i.e. exactly where the force is."""
        chi = self._chi()
        if chi == 0.0:
            return d
        return np.minimum(d, d * (1.0 + chi * dd))

    @property
    def stiffness(self) -> float:
        """Secant stiffness ``k d_ref^(n-1)`` [N/m] at the reference penetration.

        ``k`` itself when ``n = 1``.  Otherwise NaN when no
        ``reference_penetration`` is given: a nonlinear law has no stiffness
        of its own, and the explicit schemes' pre-flight stability check
        cannot judge such a contact.  Give ``reference_penetration`` (e.g.
        the expected largest penetration,
        :func:`cosim.studies.analytic.hertz_contact`) or accept the step explicitly
        (``scheme.accept_unsafe_step``).  The tangent stiffness at ``d_ref``
        is ``n`` times the secant one; the secant one is the stiffness of the
        linear spring storing the same force at ``d_ref``.
        """
        n = self.exponent
        if n == 1.0:
            return self.contact_stiffness
        if self.reference_penetration is None:
            return math.nan
        return self.contact_stiffness * self.reference_penetration ** (n - 1.0)

    @property
    def damping(self) -> float:
        """Linearised damping ``k chi d_ref^n`` [N s/m] at the reference
        penetration: 0 without hysteresis, NaN when it has hysteresis but no
        ``reference_penetration`` is given (see :attr:`stiffness`)."""
        chi = self._chi()
        if chi == 0.0:
            return 0.0
        if self.reference_penetration is None:
            return math.nan
        return self.contact_stiffness * chi * self.reference_penetration ** self.exponent

    def restitution_at(self, impact_speed: float) -> float:
        """Restitution of an impact at ``impact_speed`` [m/s]: a function of
        ``chi * impact_speed`` only, whatever the mass, ``k`` and ``n``
        (:func:`couplers.restitution.hunt_crossley_restitution`)."""
        from .restitution import hunt_crossley_restitution

        v = positive(impact_speed, "impact_speed", "m/s")
        return hunt_crossley_restitution(self._chi() * v, self.exponent)


# no field of its own: _PowerLaw's generated dataclass methods serve it as
# they are (decorating it again would only rebuild them at import)
class HertzLaw(_PowerLaw):
    """Elastic power law, ``f = k d^n`` for ``d > 0``.

    For two elastic spheres Hertz's theory gives ``n = 3/2`` and
    ``k = (4/3) E* sqrt(R)`` with the effective modulus ``E*`` and radius
    ``R`` (Johnson 1985); ``n = 1`` is :class:`LinearLaw`.  No energy is
    lost: the restitution is 1 and the contact time is
    :func:`cosim.studies.analytic.hertz_contact`.

    Parameters
    ----------
    contact_stiffness : float
        ``k`` [N/m^n], ``> 0``.
    exponent : float
        ``n`` [-], ``>= 1`` (1.5 for spheres).  Below 1 the tangent
        stiffness would be infinite at touch-down.
    reference_penetration : float, optional, keyword-only
        ``d_ref`` [m], ``> 0``, at which :attr:`stiffness` is taken for
        stability estimates; without it the stiffness is NaN unless ``n = 1``.

    References
    ----------
    Johnson, K. L. (1985). Contact Mechanics. Cambridge University Press.
    """

    name: ClassVar[str] = "hertz"

    def _chi(self) -> float:
        return 0.0

    @property
    def hysteresis_damping(self) -> float:
        """``chi`` [s/m]: none."""
        return 0.0


@dataclass(frozen=True)
class HuntCrossleyLaw(_PowerLaw):
    """Power law with hysteresis damping, ``f = k d^n (1 + chi dd)`` for
    ``d > 0`` (Hunt and Crossley 1975), clipped so it never pulls.

    The dissipated power is ``k chi d^n dd^2`` while the factor
    ``1 + chi dd`` is positive; where it is not (``dd < -1/chi``) the force is
    zero and the elastic energy is lost as the surface recovers.  A single
    impact never reaches that branch: the factor decays but stays positive, so
    the force and the penetration vanish together.  The restitution of an
    impact at ``v0`` depends on ``chi v0`` only
    (:func:`couplers.restitution.hunt_crossley_restitution`); to first order
    ``e = 1 - 2 chi v0 / 3``.  :meth:`for_restitution` sets ``chi`` from the
    exact relation.

    Parameters
    ----------
    contact_stiffness : float
        ``k`` [N/m^n], ``> 0``.
    exponent : float
        ``n`` [-], ``>= 1`` (1.5 for spheres).
    hysteresis_damping : float
        ``chi`` [s/m], ``>= 0``.
    reference_penetration : float, optional, keyword-only
        ``d_ref`` [m] for the linearised :attr:`stiffness` and
        :attr:`damping` (NaN without it).

    References
    ----------
    Hunt, K. H., Crossley, F. R. E. (1975). Coefficient of restitution
    interpreted as damping in vibroimpact. J. Appl. Mech. 42(2), 440-445.
    """

    hysteresis_damping: float
    name: ClassVar[str] = "hunt_crossley"

    def __post_init__(self):
        super().__post_init__()
        object.__setattr__(self, "hysteresis_damping",
                           positive(self.hysteresis_damping, "hysteresis_damping", "s/m", True))

    def _chi(self) -> float:
        return self.hysteresis_damping

    @classmethod
    def for_restitution(cls, contact_stiffness: float, exponent: float, restitution: float,
                        impact_speed: float, *, reference_penetration: float | None = None):
        """The law whose impact at ``impact_speed`` [m/s] has restitution
        ``restitution`` in (0, 1] exactly: ``chi = alpha(e) / v0`` from
        :func:`couplers.restitution.hunt_crossley_damping_for_restitution`.
        Other parameters as in the class."""
        from .restitution import hunt_crossley_damping_for_restitution

        e = _restitution(restitution, zero_allowed=False)
        n = _exponent(exponent)
        v = positive(impact_speed, "impact_speed", "m/s")
        chi = hunt_crossley_damping_for_restitution(e, n) / v
        return cls(contact_stiffness, n, chi, reference_penetration=reference_penetration)


@dataclass(frozen=True)
class _ImpactCalibratedLaw(_PowerLaw):
    """Hunt-Crossley law whose ``chi`` follows a published relation from a
    restitution and an impact speed, ``chi = alpha(e) / v_impact``."""

    restitution: float
    impact_speed: float
    _zero_restitution: ClassVar[bool] = True

    def __post_init__(self):
        super().__post_init__()
        object.__setattr__(self, "restitution",
                           _restitution(self.restitution, self._zero_restitution))
        object.__setattr__(self, "impact_speed",
                           positive(self.impact_speed, "impact_speed", "m/s"))

    @staticmethod
    @abstractmethod
    def damping_group(restitution: float) -> float:
        """The published ``alpha = chi v_impact`` [-] for a restitution."""

    def _chi(self) -> float:
        return self.damping_group(self.restitution) / self.impact_speed

    @property
    def hysteresis_damping(self) -> float:
        """``chi`` [s/m] from the published relation."""
        return self._chi()

    def calibration_warnings(self) -> list[dict]:
        """A warning of kind ``"restitution"`` when the restitution the law
        gives at ``impact_speed`` (exact, :meth:`restitution_at`) differs
        from the requested one by more than 0.05: ``requested``, ``actual``,
        ``impact_speed`` [m/s], the ``hysteresis_damping`` [s/m] of the
        Hunt-Crossley law that gives the requested one exactly (None for a
        restitution of 0, which none gives), and a ``message`` that quotes
        them."""
        from .restitution import hunt_crossley_damping_for_restitution

        e, v = self.restitution, self.impact_speed
        actual = self.restitution_at(v)
        if abs(actual - e) <= _RESTITUTION_WARNING:
            return []
        exact = hunt_crossley_damping_for_restitution(e, self.exponent) / v if e > 0 else None
        fix = (f"law `hunt_crossley` with `hysteresis_damping` = {exact:.6g} s/m gives it "
               f"exactly" if e > 0 else "no Hunt-Crossley damping gives 0")
        return [{"kind": "restitution", "requested": e, "actual": actual, "impact_speed": v,
                 "hysteresis_damping": exact,
                 "message": f"law `{self.name}` was asked for restitution {e:g} at impact speed "
                            f"{v:g} m/s, but its published damping gives {actual:.4f} there "
                            f"(|difference| > {_RESTITUTION_WARNING:g}); {fix}"}]

    @classmethod
    def for_restitution(cls, contact_stiffness: float, exponent: float, restitution: float,
                        impact_speed: float, *, reference_penetration: float | None = None):
        """The law with the published damping for ``restitution`` at
        ``impact_speed`` [m/s].  Warns (``UserWarning``) when the restitution
        it actually produces at that speed differs from the requested one by
        more than 0.05 (:meth:`calibration_warnings`)."""
        law = cls(contact_stiffness, exponent, restitution, impact_speed,
                  reference_penetration=reference_penetration)
        for w in law.calibration_warnings():
            warnings.warn(
                f"{cls.__name__}: requested restitution {w['requested']:g}, but its published "
                f"damping gives {w['actual']:.4f} at impact speed {w['impact_speed']:g} m/s "
                f"(|difference| > {_RESTITUTION_WARNING:g}); "
                f"HuntCrossleyLaw.for_restitution reaches it exactly",
                UserWarning, stacklevel=2)
        return law


# no field of its own: _ImpactCalibratedLaw's generated dataclass methods serve it as
# they are (decorating it again would only rebuild them at import)
class LankaraniNikraveshLaw(_ImpactCalibratedLaw):
    """Hunt-Crossley law with Lankarani and Nikravesh's damping,
    ``chi = 3 (1 - e^2) / (4 v_impact)``.

    The paper divides by the approach speed of each impact, which is history,
    not state.  Here it is a parameter: ``impact_speed``, the speed the law is
    tuned for.  The law is then exactly :class:`HuntCrossleyLaw` with that
    ``chi``; an impact at another speed ``v`` has the Hunt-Crossley
    restitution of ``chi v``.

    The relation equates the energy the damping would dissipate along the
    *undamped* path, ``(2/3) chi v0 m v0^2``, to the kinetic energy lost,
    ``(1 - e^2) m v0^2 / 2``: valid for ``e`` near 1.  The restitution it
    actually produces at ``impact_speed`` (exact, from
    :func:`couplers.restitution.hunt_crossley_restitution` of
    ``alpha = 3 (1 - e^2) / 4``) is higher than ``e``:

    ====================  =====  =====  =====  =====  =====  =====  =====
    requested ``e``       0.0    0.3    0.5    0.7    0.8    0.9    0.95
    actual                0.663  0.684  0.725  0.796  0.847  0.913  0.954
    ====================  =====  =====  =====  =====  =====  =====  =====

    It can never fall below 0.663 (``alpha <= 3/4``); the error exceeds 0.05
    for ``e < 0.793``, where :meth:`for_restitution` warns.  Independent of
    ``k``, the mass and ``n``.

    Parameters
    ----------
    contact_stiffness : float
        ``k`` [N/m^n], ``> 0``.
    exponent : float
        ``n`` [-], ``>= 1`` (1.5 for spheres).
    restitution : float
        ``e`` in [0, 1] in the published relation (see above for what it
        produces).
    impact_speed : float
        ``v_impact`` [m/s], ``> 0``, the approach speed the damping is set for.
    reference_penetration : float, optional, keyword-only
        ``d_ref`` [m] for the linearised :attr:`stiffness` and
        :attr:`damping` (NaN without it).

    References
    ----------
    Lankarani, H. M., Nikravesh, P. E. (1990). A contact force model with
    hysteresis damping for impact analysis of multibody systems. J. Mech.
    Des. 112(3), 369-376.
    """

    name: ClassVar[str] = "lankarani_nikravesh"

    @staticmethod
    def damping_group(restitution: float) -> float:
        """``alpha = 3 (1 - e^2) / 4`` [-]."""
        return 0.75 * (1.0 - restitution * restitution)


# no field of its own: _ImpactCalibratedLaw's generated dataclass methods serve it as
# they are (decorating it again would only rebuild them at import)
class FloresLaw(_ImpactCalibratedLaw):
    """Hunt-Crossley law with the damping of Flores et al. (2011),
    ``chi = 8 (1 - e) / (5 e v_impact)``, meant for the whole range of ``e``.

    As for :class:`LankaraniNikraveshLaw`, ``impact_speed`` is a parameter,
    the law is exactly :class:`HuntCrossleyLaw` with that ``chi``, and an
    impact at another speed ``v`` has the Hunt-Crossley restitution of
    ``chi v``.  At ``impact_speed`` the restitution produced is slightly
    *below* ``e`` (exact relation, any ``k``, mass and ``n``):

    ====================  =====  =====  =====  =====  =====  =====  =====
    requested ``e``       0.1    0.3    0.5    0.7    0.8    0.9    0.95
    actual                0.069  0.256  0.470  0.683  0.789  0.894  0.947
    ====================  =====  =====  =====  =====  =====  =====  =====

    The error is at most 0.046 (near ``e = 0.24``) over (0, 1], 0.044 over
    [0.3, 0.95] (at 0.3), and 0.006 for ``e >= 0.9``; :meth:`for_restitution` never
    warns.

    Parameters
    ----------
    contact_stiffness : float
        ``k`` [N/m^n], ``> 0``.
    exponent : float
        ``n`` [-], ``>= 1`` (1.5 for spheres).
    restitution : float
        ``e`` in (0, 1].
    impact_speed : float
        ``v_impact`` [m/s], ``> 0``, the approach speed the damping is set for.
    reference_penetration : float, optional, keyword-only
        ``d_ref`` [m] for the linearised :attr:`stiffness` and
        :attr:`damping` (NaN without it).

    References
    ----------
    Flores, P., Machado, M., Silva, M. T., Martins, J. M. (2011). On the
    continuous contact force models for soft materials in multibody
    dynamics. Multibody Syst. Dyn. 25, 357-375.
    """

    name: ClassVar[str] = "flores"
    _zero_restitution: ClassVar[bool] = False

    @staticmethod
    def damping_group(restitution: float) -> float:
        """``alpha = 8 (1 - e) / (5 e)`` [-]."""
        return 1.6 * (1.0 - restitution) / restitution

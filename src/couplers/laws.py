"""Penalty contact laws: the normal force as a function of penetration.

Every law maps the penetration ``d`` [m] (positive when the bodies overlap) and
its rate ``dd`` [m/s] to a normal force ``f >= 0`` [N].  It is never tensile.

Energy bookkeeping is the same for every law: the law's elastic part has the
potential ``V(d)`` (zero for ``d <= 0``), and whatever the force does beyond
the elastic part is dissipated at the rate ``P = (f - dV/dd) * dd >= 0``.
With this definition the ledger ``T + V + dissipated = const`` holds exactly,
including the clipped phase of a Kelvin-Voigt contact, where the force is
zero while ``d > 0`` and the spring's energy is lost as the surface recovers.

Each law also offers, for event location, a continuous ``switch(d, dd)`` that
is positive exactly where the force is, and ``force_active(d, dd)``, the smooth
expression of the force on the active branch (used between located events).
"""
from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

__all__ = ["ContactLaw", "LinearLaw", "KelvinVoigtLaw", "RigidLaw", "CONTACT_LAWS", "get_contact_law"]


def _positive(value, name: str, unit: str, allow_zero: bool = False) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise TypeError(f"`{name}` must be a number [{unit}], got {value!r}") from None
    ok = math.isfinite(v) and (v >= 0 if allow_zero else v > 0)
    if not ok:
        rule = ">= 0" if allow_zero else "> 0"
        raise ValueError(f"`{name}` must be {rule} {unit}, got {value!r}")
    return v


@dataclass(frozen=True)
class ContactLaw(ABC):
    """Base class of penalty laws.  Subclasses define the elastic potential
    and the force on the active branch."""

    name: ClassVar[str] = ""
    #: True for a law resolved by impulses instead of a force.
    rigid: ClassVar[bool] = False

    @abstractmethod
    def force_active(self, d, dd):
        """Force on the active branch, without clipping [N]."""

    @abstractmethod
    def potential(self, d):
        """Elastic potential energy ``V(d)`` [J]; zero for ``d <= 0``."""

    @abstractmethod
    def potential_slope(self, d):
        """``dV/dd`` [N]."""

    def switch(self, d, dd):
        """Continuous function, positive exactly where the force is [m]."""
        return d

    def force(self, d, dd):
        """Contact force [N], zero where the contact is open, never negative."""
        f = self.force_active(d, dd)
        return np.where(self.switch(d, dd) > 0.0, np.maximum(f, 0.0), 0.0)

    def dissipation_rate(self, f, d, dd):
        """Power dissipated [W] when the contact carries force ``f``."""
        return (f - self.potential_slope(d)) * dd

    @property
    @abstractmethod
    def stiffness(self) -> float:
        """Linearised stiffness [N/m] for stability estimates."""

    @property
    def damping(self) -> float:
        """Linearised damping [N s/m] for stability estimates."""
        return 0.0


@dataclass(frozen=True)
class LinearLaw(ContactLaw):
    """Unilateral linear spring, ``f = k d`` for ``d > 0``.

    Parameters
    ----------
    contact_stiffness : float
        ``k`` [N/m].
    """

    contact_stiffness: float
    name: ClassVar[str] = "linear"

    def __post_init__(self):
        object.__setattr__(self, "contact_stiffness",
                           _positive(self.contact_stiffness, "contact_stiffness", "N/m"))

    def force_active(self, d, dd):
        return self.contact_stiffness * d

    def potential(self, d):
        dp = np.maximum(d, 0.0)
        return 0.5 * self.contact_stiffness * dp * dp

    def potential_slope(self, d):
        return self.contact_stiffness * np.maximum(d, 0.0)

    @property
    def stiffness(self) -> float:
        return self.contact_stiffness


@dataclass(frozen=True)
class KelvinVoigtLaw(LinearLaw):
    """Spring and dashpot in parallel, clipped so it never pulls.

    ``f = max(k d + c dd, 0)`` for ``d > 0``.  The force starts with a jump
    ``c dd`` at touch-down and vanishes *before* the penetration does, when
    ``k d + c dd`` reaches zero; the restitution is then ``exp(-beta t_c)``,
    ``beta = c / (2 m)`` (see :func:`cosim.analytic.kelvin_voigt_clipped`).

    Parameters
    ----------
    contact_stiffness : float
        ``k`` [N/m].
    contact_damping : float
        ``c`` [N s/m], ``>= 0``.
    """

    contact_damping: float = 0.0
    name: ClassVar[str] = "kelvin_voigt"

    def __post_init__(self):
        super().__post_init__()
        object.__setattr__(self, "contact_damping",
                           _positive(self.contact_damping, "contact_damping", "N s/m", True))

    def force_active(self, d, dd):
        return self.contact_stiffness * d + self.contact_damping * dd

    def switch(self, d, dd):
        return np.minimum(d, d + (self.contact_damping / self.contact_stiffness) * dd)

    @property
    def damping(self) -> float:
        return self.contact_damping


@dataclass(frozen=True)
class RigidLaw(ContactLaw):
    """A rigid contact: no force and no penetration, an impulse at touch-down.

    The impact is resolved by the moving side's integrator with Poisson
    restitution and Coulomb friction (``multibody.impact``).  The law itself
    has no force, no potential, and its switch ``d`` marks touch-down.

    Parameters
    ----------
    restitution : float
        Poisson's kinetic coefficient, in [0, 1].
    friction : float
        Coulomb friction coefficient ``mu >= 0``.
    """

    restitution: float = 0.0
    friction: float = 0.0
    name: ClassVar[str] = "rigid"
    rigid: ClassVar[bool] = True

    def __post_init__(self):
        e = self.restitution
        if isinstance(e, bool) or not isinstance(e, (int, float)) or not 0.0 <= e <= 1.0:
            raise ValueError(f"`restitution` must be in [0, 1], got {e!r}")
        object.__setattr__(self, "restitution", float(e))
        object.__setattr__(self, "friction", _positive(self.friction, "friction", "", True))

    def force_active(self, d, dd):
        return 0.0 * d

    def potential(self, d):
        return 0.0 * d

    def potential_slope(self, d):
        return 0.0 * d

    @property
    def stiffness(self) -> float:
        return math.inf


CONTACT_LAWS: dict[str, type[ContactLaw]] = {
    LinearLaw.name: LinearLaw,
    KelvinVoigtLaw.name: KelvinVoigtLaw,
    RigidLaw.name: RigidLaw,
}


def get_contact_law(law) -> type[ContactLaw]:
    """Resolve a law given by registry name or as a class."""
    if isinstance(law, type) and issubclass(law, ContactLaw):
        return law
    try:
        return CONTACT_LAWS[law]
    except (KeyError, TypeError):
        raise ValueError(
            f"unknown contact law {law!r}; valid laws are {sorted(CONTACT_LAWS)}") from None

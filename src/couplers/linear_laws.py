"""The laws linear in the penetration: :class:`LinearLaw` (a spring),
:class:`KelvinVoigtLaw` (a spring and a dashpot, clipped at zero force) and
:class:`RigidLaw` (no penetration: resolved by impulses)."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from .checks import positive
from .law_base import ContactLaw

__all__ = ["LinearLaw", "KelvinVoigtLaw", "RigidLaw"]


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
                           positive(self.contact_stiffness, "contact_stiffness", "N/m"))

    def force_active(self, d, dd):
        return self.contact_stiffness * d

    def potential(self, d):
        if isinstance(d, float):        # one value (numpy's float64 too): no array calls
            dp = d if d > 0.0 else 0.0
        else:
            dp = np.maximum(d, 0.0)
        return 0.5 * self.contact_stiffness * dp * dp

    def potential_slope(self, d):
        if isinstance(d, float):
            return self.contact_stiffness * (d if d > 0.0 else 0.0)
        return self.contact_stiffness * np.maximum(d, 0.0)

    def evaluate(self, d, dd):
        # the spring stores all it takes: no dissipation
        return (self.contact_stiffness * d if d > 0.0 else 0.0), 0.0, d

    @property
    def stiffness(self) -> float:
        return self.contact_stiffness


@dataclass(frozen=True)
class KelvinVoigtLaw(LinearLaw):
    """Spring and dashpot in parallel, clipped so it never pulls.

    ``f = max(k d + c dd, 0)`` for ``d > 0``.  The force starts with a jump
    ``c dd`` at touch-down and vanishes *before* the penetration does, when
    ``k d + c dd`` reaches zero; the restitution is then ``exp(-beta t_c)``,
    ``beta = c / (2 m)`` (see :func:`cosim.studies.analytic.kelvin_voigt_clipped`).

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
                           positive(self.contact_damping, "contact_damping", "N s/m", True))

    def evaluate(self, d, dd):
        # ContactLaw.evaluate's formulas on one value, without array calls
        k, c = self.contact_stiffness, self.contact_damping
        a = d + (c / k) * dd
        s = d if d < a else a
        fa = k * d + c * dd
        f = (fa if fa > 0.0 else 0.0) if s > 0.0 else 0.0
        return f, (f - k * (d if d > 0.0 else 0.0)) * dd, s

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
    has no force and no potential.  Its switch is ``d`` while the point
    does not move away (``dd >= 0``) and ``min(d, T dd)`` with ``T`` = 1 s
    while it does: it marks touch-down, and it is negative again as soon as
    the impact has turned the point away, so a rebound shorter than the
    integrator's sub-step still ends in a located touch-down (with the
    switch ``d`` alone the point would leave and come back within one
    sub-step unseen, and fall through).  At touch-down ``d`` crosses 0 while
    ``dd > 0``: any positive ``T`` gives the same roots.

    Parameters
    ----------
    restitution : float
        Poisson's kinetic coefficient, in (0, 1]; required.  No value is a
        neutral default, and 0 is refused: the contact would stay closed
        after its impact, and a rigid law models impacts, not a resting
        contact (a penalty law does).
    friction : float
        Coulomb friction coefficient ``mu >= 0``.
    """

    restitution: float = field(metadata={
        "check": "in (0, 1]: 0 would leave the contact closed, which is not modelled",
        "required": "Poisson's coefficient sets the rebound of every impact and no value is "
                    "a neutral default (0 would leave the contact closed after its first "
                    "impact, which a rigid law does not model; a penalty law models a "
                    "resting contact); give a value in (0, 1]"})
    friction: float = 0.0
    name: ClassVar[str] = "rigid"
    rigid: ClassVar[bool] = True

    def __post_init__(self):
        e = self.restitution
        if isinstance(e, bool) or not isinstance(e, (int, float)) or not 0.0 <= e <= 1.0:
            raise ValueError(f"`restitution` must be in (0, 1], got {e!r}")
        if e == 0.0:
            raise ValueError(f"`restitution` must be in (0, 1], got {e!r}: the contact would "
                             f"stay closed after its first impact, and a rigid law does not model "
                             f"sustained contact; give a restitution above 0, or use a "
                             f"penalty law for a contact that comes to rest")
        object.__setattr__(self, "restitution", float(e))
        object.__setattr__(self, "friction", positive(self.friction, "friction", "", True))

    def evaluate(self, d, dd):
        return 0.0, 0.0, (d if dd >= 0.0 or d < dd else dd)  # switch(d, dd), floats

    def switch(self, d, dd):
        return np.where(dd >= 0.0, d, np.minimum(d, dd * 1.0))   # T = 1 s

    def force_active(self, d, dd):
        return 0.0 * d

    def potential(self, d):
        return 0.0 * d

    def potential_slope(self, d):
        return 0.0 * d

    @property
    def stiffness(self) -> float:
        return math.inf

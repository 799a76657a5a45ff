"""Hertz contact of an elastic sphere on a rigid flat, from material data: a
contact law of one's own, installed as a package (``pyproject.toml`` beside
this file declares it under the entry point ``cosim.laws``).

``f = (4/3) E/(1 - nu^2) sqrt(R) d^1.5``.  ``SphereOnFlat`` subclasses
``couplers.ContactLaw`` (the base class clips the force so it never pulls
and books the energy); a scene's ``law = { type = "sphere_on_flat", ... }``
then names it, and its fields are checked like any law's.
"""
import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from couplers import ContactLaw

__all__ = ["SphereOnFlat"]


@dataclass(frozen=True)
class SphereOnFlat(ContactLaw):
    """Hertz contact of a sphere (``youngs_modulus`` [Pa], ``poisson_ratio`` [-], ``radius``
    [m]) on a rigid flat: ``f = K d^1.5``, ``K = (4/3) E / (1 - nu^2) sqrt(R)`` [N/m^1.5]."""

    youngs_modulus: float
    poisson_ratio: float
    radius: float
    name: ClassVar[str] = "sphere_on_flat"

    def __post_init__(self):       # the loader turns a ValueError into a scene error at the key
        for key, ok, rule in (("youngs_modulus", self.youngs_modulus > 0, "> 0 Pa"),
                              ("poisson_ratio", -1 < self.poisson_ratio <= 0.5, "in (-1, 0.5]"),
                              ("radius", self.radius > 0, "> 0 m")):
            if not ok:
                raise ValueError(f"`{key}` must be {rule}, got {getattr(self, key)!r}")

    @property
    def hertz_constant(self) -> float:
        return 4 / 3 * self.youngs_modulus / (1 - self.poisson_ratio**2) * math.sqrt(self.radius)

    def force_active(self, d, dd):
        return self.hertz_constant * np.maximum(d, 0.0) ** 1.5

    def potential(self, d):
        return 0.4 * self.hertz_constant * np.maximum(d, 0.0) ** 2.5

    def potential_slope(self, d):
        return self.force_active(d, 0.0)

    @property
    def stiffness(self) -> float:
        return math.nan        # no linear stiffness: as the built-in `hertz` without a d_ref

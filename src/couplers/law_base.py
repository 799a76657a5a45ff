"""The base class of the penalty laws, :class:`ContactLaw`: the contract
every law keeps (force, potential, dissipated power, switch), stated in
:mod:`couplers.laws`."""
from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

__all__ = ["ContactLaw"]



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

    def evaluate(self, d: float, dd: float) -> tuple[float, float, float]:
        """Force [N], dissipated power [W] and switch value [m] at one state
        (scalars): what an integrator asks at every evaluation."""
        f = float(self.force(d, dd))
        return f, float(self.dissipation_rate(f, d, dd)), float(self.switch(d, dd))

    @property
    @abstractmethod
    def stiffness(self) -> float:
        """Linearised stiffness [N/m] for stability estimates."""

    @property
    def damping(self) -> float:
        """Linearised damping [N s/m] for stability estimates."""
        return 0.0

    def calibration_warnings(self) -> list[dict]:
        """Where the law does not give what its parameters ask for: one dict
        per warning, with ``kind`` and ``message`` and the numbers it quotes
        (a law calibrated from a restitution it cannot reach gives
        ``requested``, ``actual`` and ``impact_speed``).  None by default.
        A run carries them in its summary's ``warnings``."""
        return []

"""Elastic rod in axial motion (Saint-Venant), linear Lagrange elements.

The field is the axial displacement ``u(s)``, so ``direction = axis``:
the world position of material point ``s`` is ``origin + (s + u(s)) axis``.
The weak form ``int rho A u'' v ds + int E A u' v' ds = ...`` is assembled by
scikit-fem (``ElementLineP1`` on a ``MeshLine``), imported by ``assemble()``
only.

References
----------
.. [1] R. D. Blevins, *Formulas for Natural Frequency and Mode Shape*,
   Van Nostrand Reinhold, 1979: longitudinal vibration of straight beams,
   free-free ``omega_n = n pi c / L`` (``n = 0, 1, ...``), fixed-free
   ``omega_n = (2n - 1) pi c / (2 L)``, ``c = sqrt(E / rho)``.
.. [2] S. P. Timoshenko, D. H. Young, W. Weaver, *Vibration Problems in
   Engineering*, 4th ed., Wiley, 1974: longitudinal vibration of prismatic bars.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .checks import choice, count, positive
from .linear_structure import LineStructure, _assemble_line, _line_structure, _place

__all__ = ["Rod", "ROD_ENDS"]

#: End conditions of the rod.
ROD_ENDS = ("fixed", "free")


@dataclass(frozen=True)
class Rod:
    """Prismatic elastic rod in axial motion.

    Parameters
    ----------
    length : float
        ``L`` [m].
    youngs_modulus : float
        ``E`` [Pa].
    density : float
        ``rho`` [kg/m^3].
    area : float
        ``A`` [m^2].
    n_elements : int
        Number of equal P1 elements (>= 1).
    left, right : str
        ``"free"`` or ``"fixed"`` (u = 0) at ``s = 0`` and ``s = L``.
    origin : (2,) float
        World position of ``s = 0`` [m].
    axis : (2,) float
        Direction of the rod and of its displacement field (normalised).
    rayleigh : (a0, a1) or None
        Rayleigh damping ``C = a0 M + a1 K`` (a0 [1/s], a1 [s]).

    Notes
    -----
    A free-free rod has one rigid-body mode (``omega = 0``); ``modes`` and
    ``LinearStructure.rigid_body_modes`` report it, ``static_displacement``
    refuses it.  With consistent mass the discrete frequencies are
    ``(c/h) sqrt(6 (1 - cos k h)/(2 + cos k h))`` with the continuum's wave
    number ``k``: an ``O(h^2)`` overestimate.
    """

    length: float
    youngs_modulus: float
    density: float
    area: float
    n_elements: int
    left: str = "free"
    right: str = "free"
    origin: tuple = (0.0, 0.0)
    axis: tuple = (1.0, 0.0)
    rayleigh: tuple | None = None

    def __post_init__(self):
        put = object.__setattr__
        put(self, "length", positive(self.length, "length", "m"))
        put(self, "youngs_modulus", positive(self.youngs_modulus, "youngs_modulus", "Pa"))
        put(self, "density", positive(self.density, "density", "kg/m^3"))
        put(self, "area", positive(self.area, "area", "m^2"))
        put(self, "n_elements", count(self.n_elements, "n_elements"))
        put(self, "left", choice(self.left, "left", ROD_ENDS))
        put(self, "right", choice(self.right, "right", ROD_ENDS))
        _place(self, "origin", "axis", "rayleigh")

    @property
    def wave_speed(self) -> float:
        """``c = sqrt(E / rho)`` [m/s]."""
        return float(np.sqrt(self.youngs_modulus / self.density))

    def assemble(self) -> LineStructure:
        """Assemble ``M``, ``K`` (and ``C``) over the free nodes (DOFs ``u{j}``)."""
        x = np.linspace(0.0, self.length, self.n_elements + 1)
        m, g, _, dof_map = _assemble_line(x, hermite=False)
        constrained = ([dof_map[0, 0]] if self.left == "fixed" else []) + (
            [dof_map[-1, 0]] if self.right == "fixed" else [])
        cand = np.zeros((m.shape[0], 1))
        cand[dof_map[:, 0], 0] = 1.0
        return _line_structure(
            x=x, hermite=False, mass_full=self.density * self.area * m,
            stiffness_full=self.youngs_modulus * self.area * g, constrained=constrained,
            candidates=cand, dof_map_full=dof_map, dof_labels=("u",), origin=self.origin,
            axis=self.axis, direction=self.axis, rayleigh=self.rayleigh)

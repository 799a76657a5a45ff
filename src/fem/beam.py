"""Euler-Bernoulli beam (optionally tensioned: the cable) and the taut string.

Both carry the transverse displacement ``w(s)`` along ``direction`` of a
straight span from ``origin`` along ``axis``.  The weak form assembled by
scikit-fem on a ``MeshLine`` of ``n_elements`` equal elements is

.. math:: \\int \\rho A \\ddot w v \\,ds + \\int EI w'' v'' \\,ds
          + \\int T w' v' \\,ds = \\int q v \\,ds + \\sum P v(s_P),

with cubic Hermite elements (``ElementLineHermite``, DOFs ``w`` and
``dw/ds`` per node) for the beam and linear Lagrange elements
(``ElementLineP1``) for the string (``EI = 0``).  scikit-fem is imported by
``assemble()`` only.

References
----------
.. [1] R. D. Blevins, *Formulas for Natural Frequency and Mode Shape*,
   Van Nostrand Reinhold, 1979: straight beams (single-span beams,
   ``omega_n = (beta_n L)^2 / L^2 sqrt(EI / (rho A))``; pinned-pinned
   ``beta_n L = n pi``, clamped-free ``cos(beta L) cosh(beta L) = -1``), beams
   with axial load, and taut strings ``omega_n = (n pi / L) sqrt(T/(rho A))``.
.. [2] S. P. Timoshenko, D. H. Young, W. Weaver, *Vibration Problems in
   Engineering*, 4th ed., Wiley, 1974: lateral vibration of beams, effect of
   axial force (pinned-pinned: ``omega_n^2 = (n pi/L)^4 EI/(rho A)
   + (n pi/L)^2 T/(rho A)``).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from .checks import choice, count, positive
from .linear_structure import LineStructure, _assemble_line, _line_structure, _place

__all__ = ["Beam", "String", "Section", "rectangular_section", "circular_section",
           "BEAM_ENDS"]

#: End conditions of the beam and the nodal DOFs (``w``, ``dw/ds``) each fixes.
BEAM_ENDS = {"pinned": (0,), "clamped": (0, 1), "free": (), "sliding": (1,)}


class Section(NamedTuple):
    """Cross-section properties.

    Attributes
    ----------
    area : float
        Cross-section area ``A`` [m^2].
    second_moment : float
        Second moment of area ``I`` about the bending axis [m^4].
    """

    area: float
    second_moment: float


def rectangular_section(width: float, height: float) -> Section:
    """Solid rectangle bending about the axis parallel to ``width``.

    Parameters
    ----------
    width, height : float
        Section sides [m]; ``height`` is measured along the displacement
        direction.

    Returns
    -------
    Section
        ``A = b h`` [m^2], ``I = b h^3 / 12`` [m^4].

    Examples
    --------
    >>> sec = rectangular_section(0.04, 0.01)
    >>> beam = Beam(length=1.0, youngs_modulus=210e9, second_moment=sec.second_moment,
    ...             density=7850.0, area=sec.area, n_elements=20,
    ...             left="pinned", right="pinned")
    """
    b = positive(width, "width", "m")
    h = positive(height, "height", "m")
    return Section(area=b * h, second_moment=b * h ** 3 / 12.0)


def circular_section(diameter: float) -> Section:
    """Solid circle: ``A = pi d^2/4`` [m^2], ``I = pi d^4/64`` [m^4]."""
    d = positive(diameter, "diameter", "m")
    return Section(area=np.pi * d * d / 4.0, second_moment=np.pi * d ** 4 / 64.0)


@dataclass(frozen=True)
class Beam:
    """Euler-Bernoulli beam, optionally under axial tension (a cable).

    Parameters
    ----------
    length : float
        Span ``L`` [m].
    youngs_modulus : float
        ``E`` [Pa].
    second_moment : float
        ``I`` [m^4].
    density : float
        ``rho`` [kg/m^3].
    area : float
        ``A`` [m^2].
    n_elements : int
        Number of equal Hermite elements (>= 1).
    left, right : str
        End conditions at ``s = 0`` and ``s = L``: ``"pinned"`` (w = 0),
        ``"clamped"`` (w = 0, w' = 0), ``"free"``, ``"sliding"`` (w' = 0).
    tension : float
        Axial tension ``T`` [N] >= 0; adds the geometric stiffness
        ``T int w' v' ds``.
    origin : (2,) float
        World position of ``s = 0`` [m].
    axis : (2,) float
        Direction of the span (normalised).
    direction : (2,) float
        Direction of ``w`` (normalised; perpendicular to ``axis``).
    rayleigh : (a0, a1) or None
        Rayleigh damping ``C = a0 M + a1 K`` (a0 [1/s], a1 [s]).

    Notes
    -----
    Hermite cubics give frequency errors of order ``h^4``; a static solution
    is exact at the nodes (and in every element carrying no load) because the
    Green's function of a nodal load is piecewise cubic with kinks at nodes.

    Examples
    --------
    >>> s = Beam(1.0, 210e9, 3.33e-9, 7850.0, 4e-4, 16, "pinned", "pinned").assemble()
    >>> dofs, weights = s.point_operator(0.45)
    """

    length: float
    youngs_modulus: float
    second_moment: float
    density: float
    area: float
    n_elements: int
    left: str
    right: str
    tension: float = 0.0
    origin: tuple = (0.0, 0.0)
    axis: tuple = (1.0, 0.0)
    direction: tuple = (0.0, 1.0)
    rayleigh: tuple | None = None

    def __post_init__(self):
        put = object.__setattr__
        put(self, "length", positive(self.length, "length", "m"))
        put(self, "youngs_modulus", positive(self.youngs_modulus, "youngs_modulus", "Pa"))
        put(self, "second_moment", positive(self.second_moment, "second_moment", "m^4"))
        put(self, "density", positive(self.density, "density", "kg/m^3"))
        put(self, "area", positive(self.area, "area", "m^2"))
        put(self, "n_elements", count(self.n_elements, "n_elements"))
        put(self, "left", choice(self.left, "left", BEAM_ENDS))
        put(self, "right", choice(self.right, "right", BEAM_ENDS))
        put(self, "tension", positive(self.tension, "tension", "N", allow_zero=True))
        _place(self, "origin", "axis", "direction", "rayleigh")

    @property
    def bending_stiffness(self) -> float:
        """``EI`` [N m^2]."""
        return self.youngs_modulus * self.second_moment

    @property
    def mass_per_length(self) -> float:
        """``rho A`` [kg/m]."""
        return self.density * self.area

    def assemble(self) -> LineStructure:
        """Assemble ``M``, ``K`` (and ``C``) over the free DOFs.

        Returns
        -------
        LineStructure
            DOFs named ``w{j}`` (displacement [m]) and ``t{j}`` (slope
            ``dw/ds`` [rad]) for node ``j``; constrained DOFs removed.
        """
        x = np.linspace(0.0, self.length, self.n_elements + 1)
        m, g, b, dof_map = _assemble_line(x, hermite=True)
        stiffness = self.bending_stiffness * b + self.tension * g
        constrained = ([dof_map[0, k] for k in BEAM_ENDS[self.left]]
                       + [dof_map[-1, k] for k in BEAM_ENDS[self.right]])
        cand = np.zeros((m.shape[0], 2))
        cand[dof_map[:, 0], 0] = 1.0            # translation: w = 1
        cand[dof_map[:, 0], 1] = x              # rotation: w = s, w' = 1
        cand[dof_map[:, 1], 1] = 1.0
        if self.tension > 0.0:  # a rigid tilt stores T L theta^2 / 2: not zero-energy
            cand = cand[:, :1]
        return _line_structure(
            x=x, hermite=True, mass_full=self.mass_per_length * m, stiffness_full=stiffness,
            constrained=constrained, candidates=cand, dof_map_full=dof_map,
            dof_labels=("w", "t"), origin=self.origin, axis=self.axis,
            direction=self.direction, rayleigh=self.rayleigh)


@dataclass(frozen=True)
class String:
    """Taut string (no bending stiffness), both ends fixed, P1 elements.

    Parameters
    ----------
    length : float
        Span ``L`` [m].
    tension : float
        ``T`` [N] > 0.
    density : float
        ``rho`` [kg/m^3].
    area : float
        ``A`` [m^2].
    n_elements : int
        Number of equal linear elements (>= 2).
    origin, axis, direction, rayleigh
        As for :class:`Beam`.

    Notes
    -----
    With consistent mass the discrete frequencies are exactly
    ``omega_n = (c/h) sqrt(6 (1 - cos k h) / (2 + cos k h))``,
    ``k = n pi / L``, ``c = sqrt(T/(rho A))``: an ``O(h^2)`` overestimate of
    the string's ``n pi c / L`` [1]_.
    """

    length: float
    tension: float
    density: float
    area: float
    n_elements: int
    origin: tuple = (0.0, 0.0)
    axis: tuple = (1.0, 0.0)
    direction: tuple = (0.0, 1.0)
    rayleigh: tuple | None = None

    def __post_init__(self):
        put = object.__setattr__
        put(self, "length", positive(self.length, "length", "m"))
        put(self, "tension", positive(self.tension, "tension", "N"))
        put(self, "density", positive(self.density, "density", "kg/m^3"))
        put(self, "area", positive(self.area, "area", "m^2"))
        put(self, "n_elements", count(self.n_elements, "n_elements", minimum=2))
        _place(self, "origin", "axis", "direction", "rayleigh")

    @property
    def wave_speed(self) -> float:
        """``c = sqrt(T / (rho A))`` [m/s]."""
        return float(np.sqrt(self.tension / (self.density * self.area)))

    def assemble(self) -> LineStructure:
        """Assemble ``M``, ``K`` (and ``C``) over the interior nodes (DOFs ``w{j}``)."""
        x = np.linspace(0.0, self.length, self.n_elements + 1)
        m, g, _, dof_map = _assemble_line(x, hermite=False)
        return _line_structure(
            x=x, hermite=False, mass_full=self.density * self.area * m,
            stiffness_full=self.tension * g, constrained=[dof_map[0, 0], dof_map[-1, 0]],
            candidates=np.zeros((m.shape[0], 0)), dof_map_full=dof_map, dof_labels=("w",),
            origin=self.origin, axis=self.axis, direction=self.direction,
            rayleigh=self.rayleigh)

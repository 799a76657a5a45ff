"""A plane body as a subsystem: a :class:`~cosim.sides.fem.StructureSubsystem`
whose records are its modal coordinates and its ports, never the whole
field (a body of 38k DOFs would otherwise add 76k columns to every row of
the series).  The field is the kept modes times the recorded coordinates,
``u = Phi q``: :meth:`PlaneSubsystem.field` gives it back."""
from __future__ import annotations

import numpy as np

from cosim.sides.fem import StructureSubsystem
from cosim.sides.plane_circle import CircleHosting

__all__ = ["PlaneSubsystem"]


class PlaneSubsystem(CircleHosting, StructureSubsystem):
    """A :class:`fem.plane.PlaneStructure` reduced to the modes of its basis
    (same parameters as :class:`~cosim.sides.fem.StructureSubsystem`); it
    hosts circle contacts (:mod:`cosim.sides.plane_circle`)."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._names = [f"mode{i + 1}" for i in range(self.n_modes)]

    def named_values(self, X):
        """Modal coordinates of states ``X`` (..., 2 m): names, q, dq."""
        m = self.n_modes
        return self._names, X[..., :m], X[..., m:2 * m]

    def field(self, q) -> np.ndarray:
        """World displacement of every vertex for modal coordinates ``q``
        (..., m): shape (..., N, 2) [m]."""
        return self.structure.nodal_displacement(np.asarray(q, float) @ self.Phi.T)

"""Geometry of a unilateral point contact between two ports."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .laws import ContactLaw

__all__ = ["PointContact"]


@dataclass(frozen=True)
class PointContact:
    """A point of side ``a`` against a flat surface of side ``b``.

    The surface normal ``normal`` (world frame, unit, pointing from ``b``
    towards ``a``) is fixed.  The gap is ``g = normal . (x_a - x_b) - offset``;
    the penetration is ``d = -g``.  The force ``f = law(d, dd)`` acts on ``a``
    as ``+f normal`` and on ``b`` as ``-f normal`` (equal and opposite).

    Parameters
    ----------
    name : str
    law : ContactLaw
    normal : (2,) sequence of float
        Normalised on construction.
    offset : float
        Gap at which touch begins (a radius, a surface's thickness) [m].
    """

    name: str
    law: ContactLaw
    normal: tuple[float, float] = (0.0, 1.0)
    offset: float = 0.0

    def __post_init__(self):
        n = np.asarray(self.normal, dtype=float)
        norm = float(np.hypot(*n)) if n.shape == (2,) and np.all(np.isfinite(n)) else 0.0
        if norm == 0.0:
            raise ValueError(f"`normal` of contact `{self.name}` must be a non-zero 2-vector, "
                             f"got {self.normal!r}")
        object.__setattr__(self, "normal", (float(n[0] / norm), float(n[1] / norm)))

    def penetration(self, xa, va, xb, vb):
        """Penetration ``d`` [m] and its rate ``dd`` [m/s] (arrays of 2-vectors)."""
        n = np.asarray(self.normal)
        d = self.offset - (xa - xb) @ n
        dd = -((va - vb) @ n)
        return d, dd

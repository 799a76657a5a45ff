"""Geometry of a unilateral point contact between two ports."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .laws import ContactLaw

__all__ = ["PointContact", "penetrations", "penetration_c"]


def penetrations(normals, offsets, dx, dv):
    """Penetration [m] and its rate [m/s] of many contacts at once.

    Parameters
    ----------
    normals : (c, 2) array
        Unit normals, from side ``b`` towards side ``a``.
    offsets : (c,) array
        [m]
    dx, dv : (c, 2) arrays
        ``x_a - x_b`` [m] and ``v_a - v_b`` [m/s].

    Returns
    -------
    d, dd : (c,) arrays
        ``offset - n . dx`` and ``-n . dv``: positive when the sides overlap.
    """
    return (offsets - np.einsum("cx,cx->c", dx, normals),
            -np.einsum("cx,cx->c", dv, normals))


def penetration_c(normal: complex, offset, dx, dv):
    """:func:`penetrations` with planar vectors as complex numbers
    ``x + iy`` (scalars or arrays): ``n . z = Re(conj(n) z)``."""
    nc = normal.conjugate()
    return offset - (nc * dx).real, -(nc * dv).real


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
        dx, dv = np.subtract(xa, xb), np.subtract(va, vb)
        d, dd = penetrations(np.broadcast_to(self.normal, dx.shape).reshape(-1, 2),
                             np.full(dx.size // 2, self.offset), dx.reshape(-1, 2),
                             dv.reshape(-1, 2))
        return d.reshape(dx.shape[:-1]), dd.reshape(dv.shape[:-1])

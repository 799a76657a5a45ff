"""Discrete chain of point masses joined by linear springs along one line.

Pure numpy / scipy.sparse: importing or assembling a chain loads neither
scikit-fem nor meshio.

References
----------
.. [1] R. D. Blevins, *Formulas for Natural Frequency and Mode Shape*,
   Van Nostrand Reinhold, 1979: spring-mass systems.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .checks import positive
from .linear_structure import LinearStructure, _place

__all__ = ["Chain", "ChainStructure"]


def _entries(values, name: str, unit: str) -> tuple[float, ...]:
    try:
        items = list(values)
    except TypeError:
        raise TypeError(f"`{name}` must be a sequence of numbers [{unit}], got {values!r}") from None
    if not items:
        raise ValueError(f"`{name}` must hold at least one value, got {values!r}")
    return tuple(positive(v, f"{name}[{i}]", unit) for i, v in enumerate(items))


@dataclass(frozen=True)
class Chain:
    """Masses ``m_1..m_n`` listed top to bottom, joined by springs.

    Every DOF is the displacement of one mass along ``direction`` (up by
    default).  With ``ground_below=True`` (a chain standing on the ground)
    spring ``i`` joins mass ``i`` and mass ``i + 1`` and the last spring joins
    mass ``n`` to the fixed ground.  With ``ground_below=False`` (a chain
    hanging from a ceiling) the first spring joins the ceiling to mass 1 and
    spring ``i + 1`` joins mass ``i`` and mass ``i + 1``.  Either way there are
    ``n`` springs and no rigid-body mode.

    Parameters
    ----------
    masses : sequence of float
        ``m_1..m_n`` [kg], top to bottom.
    stiffnesses : sequence of float
        The ``n`` spring stiffnesses [N/m] in the order above.
    ground_below : bool
        Where the fixed support is (see above).
    spacing : float, optional
        Distance between consecutive masses [m]: mass ``k`` (0-based) sits at
        ``origin - k * spacing * direction``.  Give exactly one of
        ``spacing`` and ``positions``.
    positions : array_like, shape (n, 2), optional
        Reference world positions of the masses [m].
    origin : (2,) float
        Reference position of mass 1 when ``spacing`` is used [m].
    direction : (2,) float
        Direction of the displacements (normalised), the chain's "up".
    rayleigh : (a0, a1) or None
        Rayleigh damping ``C = a0 M + a1 K`` (a0 [1/s], a1 [s]).

    Examples
    --------
    >>> chain = Chain((0.15,) * 3, (1.6e5,) * 3, spacing=0.05)
    >>> s = chain.assemble()
    >>> s.dof_names
    ('m1', 'm2', 'm3')
    """

    masses: tuple
    stiffnesses: tuple
    ground_below: bool = True
    spacing: float | None = None
    positions: tuple | None = None
    origin: tuple = (0.0, 0.0)
    direction: tuple = (0.0, 1.0)
    rayleigh: tuple | None = None

    def __post_init__(self):
        put = object.__setattr__
        put(self, "masses", _entries(self.masses, "masses", "kg"))
        put(self, "stiffnesses", _entries(self.stiffnesses, "stiffnesses", "N/m"))
        n = len(self.masses)
        if len(self.stiffnesses) != n:
            raise ValueError(f"`stiffnesses` must have one entry per mass ({n}), "
                             f"got {len(self.stiffnesses)}")
        if not isinstance(self.ground_below, (bool, np.bool_)):
            raise TypeError(f"`ground_below` must be True or False, got {self.ground_below!r}")
        _place(self, "origin", "direction")
        if (self.spacing is None) == (self.positions is None):
            raise ValueError("give exactly one of `spacing` [m] and `positions` (n, 2) [m], got "
                             f"spacing={self.spacing!r}, positions={self.positions!r}")
        if self.spacing is not None:
            put(self, "spacing", positive(self.spacing, "spacing", "m"))
        else:
            p = np.asarray(self.positions, dtype=float)
            if p.shape != (n, 2) or not np.all(np.isfinite(p)):
                raise ValueError(f"`positions` must be a finite ({n}, 2) array [m], "
                                 f"got shape {p.shape}")
            put(self, "positions", tuple(map(tuple, p.tolist())))
        _place(self, "rayleigh")

    def reference_positions(self) -> np.ndarray:
        """Reference world positions of the masses, (n, 2) [m]."""
        if self.positions is not None:
            return np.array(self.positions, dtype=float)
        k = np.arange(len(self.masses), dtype=float)
        return np.asarray(self.origin) - np.outer(k * self.spacing, self.direction)

    def assemble(self) -> "ChainStructure":
        """Assemble the diagonal ``M``, tridiagonal ``K`` (and ``C``).

        Returns
        -------
        ChainStructure
            DOFs ``m1..mn``.
        """
        m = np.asarray(self.masses)
        k = np.asarray(self.stiffnesses)
        n = m.size
        if self.ground_below:   # spring i: (i, i+1), last: (n-1, ground)
            upper = np.arange(n)
            lower = np.append(np.arange(1, n), -1)
        else:                   # first: (ceiling, 0), spring i: (i-1, i)
            upper = np.append(-1, np.arange(n - 1))
            lower = np.arange(n)
        # dense: a chain is small, and a dense model needs no scipy.sparse
        stiffness = np.zeros((n, n))
        for a, b in ((upper, upper), (lower, lower), (upper, lower), (lower, upper)):
            ok = (a >= 0) & (b >= 0)
            np.add.at(stiffness, (a[ok], b[ok]), k[ok] if a is b else -k[ok])
        return ChainStructure(
            mass=np.diag(m), stiffness=stiffness,
            dof_names=tuple(f"m{i + 1}" for i in range(n)),
            positions=self.reference_positions(), direction=self.direction,
            inertia_load=m, rayleigh=self.rayleigh)


class ChainStructure(LinearStructure):
    """Assembled chain: material coordinate = mass index ``0..n-1``.

    ``origin`` is the reference position of mass 1 and ``axis`` is
    ``-direction`` (down the chain); the reference positions of all masses
    are ``nodes()`` (the ground is not a node).  A mass's world position is
    ``nodes()[k] + u[k] * direction``.
    """

    def __init__(self, *, positions, direction, **kwargs):
        self._positions = np.array(positions, dtype=float)
        self._positions.setflags(write=False)
        d = np.asarray(direction, dtype=float)
        super().__init__(origin=self._positions[0], axis=-d, direction=d, **kwargs)

    def _index(self, s) -> int:
        k = float(s)
        if not (k == int(k) and 0 <= k < self.n_dof):
            raise ValueError(f"`s` must be a mass index in 0..{self.n_dof - 1}, got {s!r}")
        return int(k)

    def point_operator(self, s):
        """``(array([k]), array([1.0]))`` for mass index ``k = s``."""
        return np.array([self._index(s)]), np.ones(1)

    def reference_position(self, s) -> np.ndarray:
        return self._positions[self._index(s)].copy()

    def nodes(self) -> np.ndarray:
        return self._positions.copy()

    def nodal_displacement(self, u) -> np.ndarray:
        return np.array(u, dtype=float)

"""A rigid circle pressed against the deformed boundary of a plane body,
its penalty spread over the boundary inside it.

A circle of centre ``c`` and radius ``R`` (world frame) penetrates the
body's boundary where a boundary point ``x(u)`` lies inside it; the
penetration there is

.. math:: g(x) = R - \\lVert x - c \\rVert \\quad (> 0 \\text{ inside}),

and the contact pressure is ``p = k g`` for ``g > 0``, with ``k`` the
penalty stiffness per unit area of boundary [Pa/m = N/m^3] (a Winkler
layer of modulus ``k`` on the boundary).  The pressure acts on the body
along the circle's outward radius ``n = (x - c) / |x - c|``.  The stored
energy is

.. math:: V(u, c) = t \\int_{\\Gamma} \\tfrac12 k \\langle g \\rangle^2 \\, dS_0,

over the reference arc length ``S_0`` of the boundary ``Gamma`` times the
thickness ``t``, evaluated by Gauss-Legendre quadrature on each boundary
segment at the deformed positions ``x_q = X_q + B_q u`` (``B_q`` the
trace of the element on the segment).  The generalized force is exactly
``-dV/du``,

.. math:: f = \\sum_q t\\, w_q\\, k\\, \\langle g_q \\rangle\\, B_q^T n_q,

and the force on the circle is ``-sum_q t w_q k <g_q> n_q`` (the
pressures' resultant, ``-dV/dc``); every pressure acts along a radius, so
the resultant passes through the centre: its moment about the centre is
zero and about a point ``o`` it is ``(c - o) x F``.  The tangent stiffness
``d^2 V/du^2`` is :meth:`CircleContact.stiffness`.

With a basis ``Phi`` (the kept modes, ``u = Phi q``) the same holds in the
modal coordinates, with ``B_q Phi`` computed once: a step costs two dense
products over the quadrature points, with no loop over them.

The pressure is the Winkler layer's, so it tends to the elastic contact's
(Hertz, for a cylinder on a half-space) as ``k a / E*`` grows (``a`` the
contact's half-width), and, spread over the boundary, it converges with
the mesh (``tests/test_plane_circle.py``).  The quadrature points must
resolve the contact's width (``parts``).  A circle much smaller than the
modes' wavelengths acts as a point contact whose law is the circle's on a
flat face (``tests/test_plane_circle_strike.py``).

References
----------
.. [1] K. L. Johnson, *Contact Mechanics*, Cambridge University Press,
   1985, sec. 4.2 and 5.2: the contact of cylinders (``a = sqrt(4 P' R /
   (pi E*))``, ``p0 = 2 P' / (pi a)``).
"""
from __future__ import annotations

import numpy as np

__all__ = ["CircleContact", "hertz_cylinder"]


def hertz_cylinder(load_per_length: float, radius: float, youngs_modulus: float,
                   poisson_ratio: float, model: str = "plane_strain") -> tuple[float, float]:
    """Johnson's half-width ``a`` [m] and peak pressure ``p0`` [Pa] of a rigid
    cylinder of radius ``radius`` [m] pressed into an elastic half-space by
    ``load_per_length`` [N/m] (``P' = P / t``).

    ``E* = E / (1 - nu^2)`` in plane strain (``E`` in plane stress, the
    thin plate's), ``a = sqrt(4 P' R / (pi E*))``, ``p0 = 2 P' / (pi a)``.
    """
    e_star = youngs_modulus / (1.0 - poisson_ratio ** 2) if model == "plane_strain" \
        else youngs_modulus
    a = np.sqrt(4.0 * load_per_length * radius / (np.pi * e_star))
    return float(a), float(2.0 * load_per_length / (np.pi * a))


def _trace(xi: np.ndarray, quadratic: bool) -> np.ndarray:
    """Shape functions of a segment's trace at ``xi`` in [0, 1]: (n, 2 or 3)."""
    if quadratic:
        return np.column_stack([(1 - xi) * (1 - 2 * xi), xi * (2 * xi - 1), 4 * xi * (1 - xi)])
    return np.column_stack([1 - xi, xi])


class CircleContact:
    """The penalty of a circle against a plane body's boundary.

    Parameters
    ----------
    structure : PlaneStructure
        The assembled body.
    radius : float
        ``R`` [m].
    stiffness : float
        ``k`` [Pa/m]: the contact pressure per metre of penetration.
    basis : ndarray, shape (n_dof, m), optional
        Modes ``Phi``: the coordinates given to the methods are then the
        modal ``q`` (``u = Phi q``), else the free DOFs ``u``.
    groups : iterable of str, optional
        The boundary groups the circle may touch (all the boundary when
        not given).
    gauss : int
        Gauss-Legendre points per part of a segment.
    parts : int
        Equal parts each segment is cut into for the quadrature: the
        points must resolve the contact's width, ``2 sqrt(2 R g_max)`` for a
        small circle on a flat face.
    """

    def __init__(self, structure, radius: float, stiffness: float, basis=None, groups=None,
                 gauss: int = 4, parts: int = 1):
        radius, stiffness = float(radius), float(stiffness)
        if not (np.isfinite(radius) and radius > 0.0):
            raise ValueError(f"`radius` must be > 0 m and finite, got {radius!r}")
        if not (np.isfinite(stiffness) and stiffness > 0.0):
            raise ValueError(f"`stiffness` must be > 0 Pa/m and finite, got {stiffness!r}")
        if not isinstance(gauss, (int, np.integer)) or not 1 <= gauss <= 20:
            raise ValueError(f"`gauss` must be an integer in [1, 20], got {gauss!r}")
        if not isinstance(parts, (int, np.integer)) or parts < 1:
            raise ValueError(f"`parts` must be an integer >= 1, got {parts!r}")
        self.structure, self.radius, self.stiffness = structure, radius, stiffness
        ends, scalar = structure.boundary_segments(groups)
        p = structure.mesh.points
        xi, w = np.polynomial.legendre.leggauss(int(gauss))
        xi = ((np.arange(int(parts))[:, None] + 0.5 * (xi + 1.0)) / parts).ravel()
        w = np.tile(0.5 * w / parts, int(parts))
        shape = _trace(xi, scalar.shape[1] == 3)                  # (g, s)
        n_seg, n_g = ends.shape[0], xi.size
        length = np.hypot(*(p[ends[:, 1]] - p[ends[:, 0]]).T)     # reference [m]
        local = (p[ends[:, 0], None, :] * (1 - xi)[None, :, None]
                 + p[ends[:, 1], None, :] * xi[None, :, None]).reshape(-1, 2)
        rot = structure.rotation
        #: reference world positions of the quadrature points, (n_q, 2) [m]
        self.points = structure.origin + local @ rot.T
        #: ``t w_q |segment|``: each point's share of the boundary's area [m^2]
        self.weights = (structure.plane.thickness * np.outer(length, w)).ravel()
        self.segment = np.repeat(np.arange(n_seg), n_g)
        # B: world displacement of the points from the free DOFs, rows 2 q + i
        q_idx = np.arange(n_seg * n_g).reshape(n_seg, n_g)
        rows, cols, vals = [], [], []
        for i in range(2):                  # world component (a loop of two, once)
            for j in range(2):              # mesh component
                free = structure.dof_map[2 * scalar + j]                     # (k, s)
                r = np.broadcast_to(2 * q_idx[:, :, None] + i, (n_seg, n_g, shape.shape[1]))
                c = np.broadcast_to(free[:, None, :], r.shape)
                v = np.broadcast_to(rot[i, j] * shape[None, :, :], r.shape)
                keep = (c >= 0) & (v != 0.0)
                rows.append(r[keep]), cols.append(c[keep]), vals.append(v[keep])
        from scipy import sparse
        b = sparse.csr_matrix((np.concatenate(vals), (np.concatenate(rows),
                                                      np.concatenate(cols))),
                              shape=(2 * n_seg * n_g, structure.n_dof))
        self._b = b if basis is None else np.ascontiguousarray(b @ np.asarray(basis))
        self.n_coordinates = self._b.shape[1]

    @property
    def trace(self):
        """``B``: the world displacement of the quadrature points from the
        coordinates, rows ``2 q + i`` (sparse without a basis, dense with one)."""
        return self._b

    def positions(self, u) -> np.ndarray:
        """Deformed world positions of the quadrature points, (n_q, 2) [m]."""
        return self.points + (self._b @ np.asarray(u, dtype=float)).reshape(-1, 2)

    def penetration(self, u, centre) -> np.ndarray:
        """``g_q = R - |x_q - c|`` at every quadrature point [m] (> 0 inside)."""
        d = self.positions(u) - np.asarray(centre, dtype=float)
        return self.radius - np.hypot(d[:, 0], d[:, 1])

    def _state(self, u, centre):
        d = self.positions(u) - np.asarray(centre, dtype=float)
        r = np.hypot(d[:, 0], d[:, 1])
        g = self.radius - r
        on = g > 0.0
        n = d[on] / r[on, None]
        return on, g[on], n, r[on]

    def evaluate(self, u, centre):
        """Energy, generalized force and the force on the circle.

        Parameters
        ----------
        u : ndarray, shape (n,)
            The body's coordinates (free DOFs, or modal with a basis).
        centre : (2,) float
            The circle's centre, world [m].

        Returns
        -------
        energy : float
            ``V`` [J].
        force : ndarray, shape (n,)
            ``-dV/du``: the contact's load on the coordinates [N].
        on_circle : ndarray, shape (2,)
            ``-dV/dc``: the force on the circle [N] (through its centre).
        """
        on, g, n, _ = self._state(u, centre)
        kg = self.stiffness * g * self.weights[on]                 # [N] per point
        energy = 0.5 * float(kg @ g)
        traction = np.zeros((self.weights.size, 2))
        traction[on] = kg[:, None] * n
        force = self._b.T @ traction.ravel()
        return energy, force, -traction[on].sum(axis=0)

    def stiffness_matrix(self, u, centre):
        """``d^2 V / du^2`` (sparse without a basis, dense with one): the
        contact's tangent stiffness [N/m] for a Newton solve.

        Per point, ``t w k [n n^T - (g / |x - c|)(I - n n^T)]`` between
        the traces ``B_q`` (the second term is the circle's curvature).
        """
        on, g, n, r = self._state(u, centre)
        c = self.stiffness * self.weights[on]
        nn = n[:, :, None] * n[:, None, :]
        blocks = c[:, None, None] * (nn - (g / r)[:, None, None] * (np.eye(2) - nn))
        idx = np.flatnonzero(on)
        from scipy import sparse
        r2 = np.stack([2 * idx, 2 * idx + 1], axis=1)
        rows = np.repeat(r2, 2, axis=1).ravel()
        cols = np.tile(r2, (1, 2)).ravel()
        d = sparse.csr_matrix((blocks.ravel(), (rows, cols)),
                              shape=(2 * self.weights.size,) * 2)
        out = self._b.T @ (d @ self._b)
        return out

    def pressure(self, u, centre) -> np.ndarray:
        """Contact pressure ``k <g_q>`` at every quadrature point [Pa]."""
        return self.stiffness * np.maximum(self.penetration(u, centre), 0.0)

"""The closed boundary chain of a plane body that a following point slides
along: the loop of the mesh's boundary facets through a port's segment,
and the point of that loop, deformed, closest to a world point.

Node-to-segment on the deformed boundary: each segment's deformed trace is
``x(xi) = X(xi) + u(xi)`` (straight for P1/Q1, a parabola for P2/Q2, whose
edge DOF sits at the midpoint), and the point ``p`` is projected on it by
Newton's method on ``x'(xi) . (x(xi) - p) = 0``.  At an interior closest
point the normal is the deformed tangent turned outwards; where the
closest point is a vertex (``p`` in a corner's fan, outside a convex
corner or inside a reflex one) it is the unit vector from the vertex to
``p``, turned outwards.  Either way ``p - x = g n``: the signed gap ``g``
has gradient ``n`` in ``p`` and ``-n`` through the material point's
displacement, so a force ``f n`` on the point and ``-f n`` on the material
point (its consistent nodal load) do exactly the work ``f dg/dt``, and the
sliding point, the turning normal and the crossing from one segment to the
next over a corner do none.  (Inside a convex corner the closest segment
changes on the bisector, where both give the same gap: the gap is
continuous there, its normal turns at once.)
"""
from __future__ import annotations

import numpy as np

from .mesh import MeshError

__all__ = ["BoundaryLoop"]

#: Newton steps of the projection on a segment's parabola (from the chord's
#: projection; the deformation bends a segment by far less than its length,
#: so two steps reach round-off, the rest are spare)
_NEWTON = 6


class BoundaryLoop:
    """The closed chain of boundary segments of ``structure`` (a
    :class:`fem.plane.PlaneStructure`) through the segment that holds the
    point ``(group, s)``, oriented the way that group runs there.

    Attributes
    ----------
    name : str
        The chain's name among the structure's chains (a point on it is
        ``(name, arc)``, as on a group).
    pairs : ndarray of int, shape (K, 2)
        Directed vertex pairs, in order round the loop.
    arc : ndarray, shape (K + 1,)
        Arc length at each segment's start, and the loop's length [m].
    normals : ndarray, shape (K, 2)
        Reference outward normals (world).
    """

    def __init__(self, structure, group: str, s: float):
        self.structure = st = structure
        if s is None:
            raise ValueError(f"a point that slides along the boundary needs an arc length "
                             f"`s` along {group!r}, not the group's average")
        start = st.boundary_point(group, s)
        pairs0, _ = st.chain(group)
        a0, b0 = (int(v) for v in pairs0[start.segment])
        facets = st.boundary_facets()
        nxt: dict = {}
        for a, b in facets.tolist():
            nxt.setdefault(a, []).append(b)
            nxt.setdefault(b, []).append(a)
        if any(len(v) != 2 for v in nxt.values()):
            raise MeshError(f"{st.mesh.source}: the boundary touches itself at a vertex; a "
                            f"point that follows needs each boundary vertex on two segments")
        order, prev, cur = [a0, b0], a0, b0
        while True:
            prev, cur = cur, next(v for v in nxt[cur] if v != prev)
            if cur == a0:
                break
            order.append(cur)
        self.pairs = np.array([order, order[1:] + order[:1]], dtype=np.int64).T
        p = st.mesh.points
        seg = np.hypot(*(p[self.pairs[:, 1]] - p[self.pairs[:, 0]]).T)
        self.arc = np.concatenate([[0.0], np.cumsum(seg)])
        self.name = f"<boundary through {group} at {s:g}>"
        st.add_chain(self.name, self.pairs, self.arc)
        K = self.pairs.shape[0]
        self.normals = np.array([st.segment_point(self.pairs, k, 0.5).normal for k in range(K)])
        # each segment's ends and edge DOF: reference world positions and the
        # modal rows of their world displacements, filled by :meth:`set_modes`
        self.quadratic = st.plane.element in ("P2", "Q2")
        self.X = st.origin + np.stack([p[self.pairs[:, 0]], p[self.pairs[:, 1]]], 1) \
            @ st.rotation.T                                     # (K, 2, 2): end, xy
        self._rows = None

    def set_modes(self, Phi) -> None:
        """The modal rows of each segment's nodes (world displacement per
        modal coordinate) for the mode shapes ``Phi`` (n_dof, m)."""
        st, m = self.structure, Phi.shape[1]
        K = self.pairs.shape[0]
        rows = np.zeros((K, 3 if self.quadratic else 2, 2, m))
        for k in range(K):
            # the ends, and the midpoint, where the trace is the edge DOF's
            pt = [st.segment_point(self.pairs, k, xi) for xi in (0.0, 1.0, 0.5)]
            for j in range(rows.shape[1]):
                rows[k, j] = pt[j].rows @ Phi[pt[j].dofs]
        self._rows = rows

    def deformed(self, q) -> tuple:
        """Power coefficients of each deformed segment in its local
        coordinate ``xi``: ``x(xi) = c0 + c1 xi + c2 xi^2``, (K, 2) each."""
        nodes = np.einsum("kjxm,m->kjx", self._rows, q)
        xa = self.X[:, 0] + nodes[:, 0]
        xb = self.X[:, 1] + nodes[:, 1]
        if not self.quadratic:
            return xa, xb - xa, np.zeros_like(xa)
        xc = 0.5 * (self.X[:, 0] + self.X[:, 1]) + nodes[:, 2]
        return xa, 4.0 * xc - 3.0 * xa - xb, 2.0 * (xa + xb) - 4.0 * xc

    def project(self, point, q) -> tuple:
        """The closest point of the deformed loop to ``point`` for modal
        coordinates ``q``: ``(k, xi, normal, gap)`` -- its segment, local
        coordinate in [0, 1], outward unit normal and signed distance
        (positive outside) [m]."""
        p = np.asarray(point, float)
        c0, c1, c2 = self.deformed(q)
        chord = c1 + c2
        d0 = p - c0
        xi = np.minimum(np.maximum((d0 * chord).sum(1) / (chord * chord).sum(1), 0.0), 1.0)
        x = c0 + xi[:, None] * chord
        dist = np.hypot(*(p - x).T)
        if self.quadratic:
            # a parabola strays from its chord by at most |c2| / 4: only the
            # segments whose chord comes that close to the nearest are
            # projected on their parabola
            bend = 0.5 * np.hypot(*c2.T)
            near = dist <= dist.min() + 2.0 * bend.max()
            a0, a1, a2, t = c0[near], c1[near], c2[near], xi[near]
            for _ in range(_NEWTON):
                r = a0 + t[:, None] * (a1 + t[:, None] * a2) - p
                tan = a1 + 2.0 * t[:, None] * a2
                f = (tan * r).sum(1)
                fp = (tan * tan).sum(1) + 2.0 * (a2 * r).sum(1)
                step = f / np.where(fp > 0.0, fp, 1.0)
                t = np.minimum(np.maximum(t - step, 0.0), 1.0)
                if not np.any(np.abs(step) > 1e-15):
                    break
            xi[near] = t
            x[near] = a0 + t[:, None] * (a1 + t[:, None] * a2)
            dist = np.where(near, np.hypot(*(p - x).T), np.inf)
        k = int(np.argmin(dist))
        a, diff = float(xi[k]), p - x[k]
        if 0.0 < a < 1.0:                   # inside the segment: the deformed normal
            n = self.tangent_normal(k, c1[k] + 2.0 * a * c2[k])
        else:                               # at a vertex: towards the point, outwards
            n = self.vertex_normal(k, a, diff)
        return k, a, n, float(n @ diff)

    def tangent_normal(self, k: int, tangent) -> np.ndarray:
        """The outward unit normal of segment ``k`` deformed to ``tangent``
        (``dx/dxi`` there): the tangent turned a quarter, outwards."""
        n = np.array([tangent[1], -tangent[0]]) / np.hypot(*tangent)
        return n if n @ self.normals[k] >= 0.0 else -n

    def vertex_normal(self, k: int, xi: float, diff) -> np.ndarray:
        """The outward normal at the vertex ``xi`` (0 or 1) of segment ``k``
        for a point ``diff`` away from it: ``diff`` turned to the side of the
        two segments' mean outward normal (that mean where ``diff`` is 0)."""
        K = self.pairs.shape[0]
        other = (k - 1) % K if xi == 0.0 else (k + 1) % K
        mean = self.normals[k] + self.normals[other]
        size = float(np.hypot(*diff))
        if size == 0.0:
            return mean / np.hypot(*mean)
        n = diff / size
        return n if n @ mean >= 0.0 else -n

    def modal_rows(self, k: int, xi: float) -> np.ndarray:
        """World displacement of the point ``xi`` of segment ``k`` per modal
        coordinate, (2, m): the element's trace on the segment."""
        if self.quadratic:
            shape = ((1.0 - xi) * (1.0 - 2.0 * xi), xi * (2.0 * xi - 1.0), 4.0 * xi * (1.0 - xi))
        else:
            shape = (1.0 - xi, xi)
        rows = self._rows[k]
        return sum(w * rows[j] for j, w in enumerate(shape))

    def point_row(self, k: int, xi: float, direction) -> tuple:
        """``(dofs, w)``: the free DOFs of segment ``k`` and the row of the
        displacement of its point ``xi`` along the unit ``direction``
        (world) on them, as the structure's ``boundary_point`` gives it (the
        segment's nodal rows kept from the first call)."""
        nodal = self.__dict__.setdefault("_nodal", {})
        if k not in nodal:
            pts = [self.structure.segment_point(self.pairs, k, x)
                   for x in ((0.0, 1.0, 0.5) if self.quadratic else (0.0, 1.0))]
            nodal[k] = (pts[0].dofs, np.array([pt.rows for pt in pts]))
        dofs, rows = nodal[k]
        if self.quadratic:
            shape = ((1.0 - xi) * (1.0 - 2.0 * xi), xi * (2.0 * xi - 1.0), 4.0 * xi * (1.0 - xi))
        else:
            shape = (1.0 - xi, xi)
        return dofs, np.asarray(direction, float) @ np.tensordot(shape, rows, axes=1)

    def position(self, k: int, xi: float) -> np.ndarray:
        """Reference world position of the point ``xi`` of segment ``k`` [m]."""
        return (1.0 - xi) * self.X[k, 0] + xi * self.X[k, 1]

    def coordinate(self, k: int, xi: float) -> float:
        """Arc length [m] along the loop of the point ``xi`` of segment ``k``."""
        return float(self.arc[k] + xi * (self.arc[k + 1] - self.arc[k]))

"""The assembled plane body: matrices over the free DOFs and the operators
of points on its boundary.

A point of a plane body is named by a boundary group and an arc length
``s`` along it: ``(group, s)``.  Its displacement is a 2-vector,
``rows @ u[dofs]`` with the trace of the element on the boundary segment
holding it (linear for P1/Q1, quadratic for P2/Q2: the two end vertices'
and the edge's DOFs).  A contact reads it projected on the segment's
outward normal: :meth:`PlaneStructure.point_operator` gives that row, in the
same form as a beam's (``dofs``, ``weights``), so that everything built on a
point's row (modal participation, static correction, the compiled kernels'
modal rows) takes a plane body's point as it takes a beam's.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..linear_structure import LinearStructure, _reduce, _rigid_candidates
from .mesh import MeshError

__all__ = ["PlaneStructure", "BoundaryPoint"]


class BoundaryPoint(NamedTuple):
    """A point on a boundary group, in the reference configuration.

    Attributes
    ----------
    dofs : ndarray of int
        Free DOFs the point's displacement depends on.
    rows : ndarray, shape (2, k)
        World displacement ``(ux, uy) = rows @ u[dofs]`` [m].
    normal : ndarray, shape (2,)
        Outward unit normal of the segment, world frame.
    tangent : ndarray, shape (2,)
        Unit tangent along increasing ``s``, world frame.
    position : ndarray, shape (2,)
        Reference world position [m].
    segment : int
        Index of the segment along the group's chain.
    """

    dofs: np.ndarray
    rows: np.ndarray
    normal: np.ndarray
    tangent: np.ndarray
    position: np.ndarray
    segment: int


def _rotation(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s], [s, c]])


class PlaneStructure(LinearStructure):
    """A plane elastic body over its free DOFs (built by :meth:`Plane.assemble`).

    DOF ``2 i + c`` of the full numbering is component ``c`` (x, y, in the
    mesh's frame) of scikit-fem's scalar DOF ``i``; the vertices come first
    (scalar DOF ``i`` is vertex ``i``), then the edges' and the cells'.

    Attributes
    ----------
    plane : Plane
        The model.
    mesh : PlaneMesh
        The checked mesh (mesh frame, metres).
    rotation : ndarray, shape (2, 2)
        Mesh frame -> world.
    dof_map : ndarray of int, shape (n_full,)
        Free index of each full DOF, ``-1`` where fixed.
    """

    def __init__(self, *, plane, mesh, skmesh, scalar_basis, mass_full, stiffness_full,
                 angle, origin, rayleigh):
        self.plane, self.mesh = plane, mesh
        self.rotation = _rotation(angle)
        n_full = mass_full.shape[0]
        self._sbasis, self._skmesh = scalar_basis, skmesh
        fixed = np.unique(np.concatenate([self._group_dofs(groups, c)
                                          for c, groups in plane.supports.items()]))
        full_map = np.arange(n_full)
        free, dof_map = _reduce(full_map, fixed)
        if free.size == 0:
            raise MeshError(f"{mesh.source}: the supports fix every DOF")
        self.dof_map = dof_map
        self.free = free
        locs = scalar_basis.doflocs                   # (2, n_scalar), mesh frame
        cand = np.zeros((n_full, 3))
        cand[0::2, 0] = 1.0
        cand[1::2, 1] = 1.0
        centre = locs.mean(axis=1, keepdims=True)
        cand[0::2, 2] = -(locs[1] - centre[1])
        cand[1::2, 2] = locs[0] - centre[0]
        self._m_full = mass_full
        names = np.empty(n_full, dtype=object)
        names[0::2] = [f"ux{i}" for i in range(n_full // 2)]
        names[1::2] = [f"uy{i}" for i in range(n_full // 2)]
        super().__init__(mass=mass_full[free][:, free], stiffness=stiffness_full[free][:, free],
                         dof_names=tuple(names[free]), origin=origin, axis=(1.0, 0.0),
                         direction=(0.0, 0.0), inertia_load=np.zeros(free.size),
                         rayleigh=rayleigh, rigid_modes=_rigid_candidates(cand, free))
        self._chains: dict = {}

    # -- groups ---------------------------------------------------------------
    def _group_dofs(self, groups, component=None) -> np.ndarray:
        """Full DOFs of ``component`` (0: x, 1: y, None: both) on the
        segments of curve groups and at the vertices of point groups."""
        out = [np.zeros(0, dtype=np.int64)]
        for name in groups:
            if name in self.mesh.point_groups:
                scalar = self.mesh.vertices(name)       # vertex i is scalar DOF i
            else:
                facets = self._facets(self.mesh.group(name))
                scalar = self._sbasis.get_dofs(facets=facets).all()
            out += [2 * scalar + c for c in ((0, 1) if component is None else (component,))]
        return np.unique(np.concatenate(out))

    def _facets(self, pairs: np.ndarray) -> np.ndarray:
        index = self.__dict__.get("_facet_index")
        if index is None:                           # facets: (2, nf) sorted vertex pairs
            index = {(int(a), int(b)): i for i, (a, b) in enumerate(self._skmesh.facets.T)}
            self._facet_index = index
        return np.array([index[tuple(sorted((int(a), int(b))))] for a, b in pairs],
                        dtype=np.int64)

    def chain(self, group: str):
        """The segments of ``group`` in order of arc length.

        Returns
        -------
        pairs : ndarray of int, shape (k, 2)
            Directed vertex pairs, end to start.
        s : ndarray, shape (k + 1,)
            Arc length at each segment's start, and the group's length [m].

        The arc length starts at the free end of the group's first line
        cell in the file (a closed group: at that cell's first vertex) and
        runs the way the cells run.

        Raises
        ------
        MeshError
            If the group is not one chain of boundary segments.
        """
        if group in self._chains:
            return self._chains[group]
        src, pairs = self.mesh.source, self.mesh.group(group)
        facets = self._facets(pairs)
        if (self._skmesh.f2t[1, facets] >= 0).any():
            raise MeshError(f"{src}: the group {group!r} runs inside the body; a point needs "
                            f"a boundary curve")
        nxt: dict = {}
        for a, b in pairs.tolist():
            nxt.setdefault(a, []).append(b)
            nxt.setdefault(b, []).append(a)
        if any(len(v) > 2 for v in nxt.values()):
            raise MeshError(f"{src}: the group {group!r} branches; a point's group must be one "
                            f"chain of curves")
        a0, b0 = (int(v) for v in pairs[0])
        closed = all(len(v) == 2 for v in nxt.values())
        if closed:
            order, prev, cur = [a0, b0], a0, b0
        else:
            # walk back from the first cell's start to the chain's end
            prev, cur = b0, a0
            while len(nxt[cur]) == 2:
                prev, cur = cur, next(v for v in nxt[cur] if v != prev)
            order, prev = [cur], None
        while True:
            options = [v for v in nxt[cur] if v != prev]
            if not options:
                break
            prev, cur = cur, options[0]
            order.append(cur)
            if closed and cur == a0:
                break
        out = np.array([order[:-1], order[1:]], dtype=np.int64).T
        if out.shape[0] != pairs.shape[0]:
            raise MeshError(f"{src}: the group {group!r} is not connected; a point's group must "
                            f"be one chain of curves")
        p = self.mesh.points
        seg = np.hypot(*(p[out[:, 1]] - p[out[:, 0]]).T)
        s = np.concatenate([[0.0], np.cumsum(seg)])
        self._chains[group] = (out, s)
        return out, s

    def boundary_facets(self) -> np.ndarray:
        """Vertex pairs of the mesh's boundary facets (a facet of one cell),
        shape (k, 2), in no order."""
        sk = self._skmesh
        return sk.facets[:, sk.f2t[1] < 0].T

    def add_chain(self, name: str, pairs: np.ndarray, arc: np.ndarray) -> None:
        """Name a chain of boundary segments (directed vertex pairs ``pairs``
        and the arc length ``arc`` at their starts and end, as :meth:`chain`
        gives them), so that ``(name, s)`` is a point on it."""
        self._chains[name] = (np.asarray(pairs, np.int64), np.asarray(arc, float))

    def segment_point(self, pairs, k: int, xi: float) -> BoundaryPoint:
        """The point at local coordinate ``xi`` in [0, 1] of segment ``k``
        of the chain ``pairs`` (see :class:`BoundaryPoint`)."""
        return self._segment_point(pairs, k, xi)

    def group_length(self, group: str) -> float:
        """Arc length of the group [m]."""
        return float(self.chain(group)[1][-1])

    def boundary_segments(self, groups=None):
        """The segments of the body's boundary and the scalar DOFs of their traces.

        Parameters
        ----------
        groups : iterable of str, optional
            Boundary groups to take the segments of; all the boundary's
            segments when not given.

        Returns
        -------
        ends : ndarray of int, shape (k, 2)
            The segments' end vertices.
        scalar : ndarray of int, shape (k, 2) or (k, 3)
            Scalar DOFs of each segment's trace: its two end vertices, then
            its edge DOF for P2 and Q2 (at the segment's midpoint); DOF
            ``2 i + c`` of the full numbering is component ``c`` of scalar
            DOF ``i`` (:attr:`dof_map` gives its free index).
        """
        sk = self._skmesh
        if groups is None:
            facets = np.asarray(sk.boundary_facets(), dtype=np.int64)
        else:
            facets = np.unique(np.concatenate(
                [self._facets(self.mesh.group(g)) for g in groups]))
            if (sk.f2t[1, facets] >= 0).any():
                raise MeshError(f"{self.mesh.source}: a group of {list(groups)!r} runs inside "
                                f"the body; a contact needs boundary curves")
        ends = np.ascontiguousarray(sk.facets[:, facets].T, dtype=np.int64)
        if self.plane.element in ("P2", "Q2"):
            scalar = np.column_stack([ends, self._sbasis.facet_dofs[0, facets]])
        else:
            scalar = ends.copy()
        return ends, scalar

    # -- points ---------------------------------------------------------------
    def boundary_point(self, group: str, s: float | None) -> BoundaryPoint:
        """The point at arc length ``s`` [m] along ``group`` (see :class:`BoundaryPoint`).

        At a vertex between two segments the later segment holds the point
        (the last one at the group's end).  ``s = None`` is the group's
        average: the rows ``(1/L) int N ds`` over its segments (consistent
        weights: a force on it is a uniform traction), at its mid-length
        point, ``segment = -1``; the group must be straight.
        """
        if s is None:
            return self._average(group)
        pairs, arc = self.chain(group)
        s = float(s)
        tol = 1e-12 * arc[-1]
        if not (-tol <= s <= arc[-1] + tol):
            raise ValueError(f"`s` must be in [0, {arc[-1]:.6g}] m along {group!r}, got {s!r}")
        k = int(np.clip(np.searchsorted(arc, s, side="right") - 1, 0, pairs.shape[0] - 1))
        xi = min(max((s - arc[k]) / (arc[k + 1] - arc[k]), 0.0), 1.0)
        return self._segment_point(pairs, k, xi)

    def _segment_point(self, pairs, k: int, xi: float) -> BoundaryPoint:
        """The point at local coordinate ``xi`` in [0, 1] of segment ``k``."""
        a, b = (int(v) for v in pairs[k])
        facet = int(self._facets(pairs[k:k + 1])[0])
        scalar = [a, b]
        shape = [1.0 - xi, xi]
        if self.plane.element in ("P2", "Q2"):
            mid = int(self._sbasis.facet_dofs[0, facet])
            loc = self._sbasis.doflocs[:, mid]
            if not np.allclose(loc, 0.5 * (self.mesh.points[a] + self.mesh.points[b])):
                raise RuntimeError("scikit-fem's edge DOF is not at the edge's midpoint")
            scalar.append(mid)
            shape = [(1.0 - xi) * (1.0 - 2.0 * xi), xi * (2.0 * xi - 1.0), 4.0 * xi * (1.0 - xi)]
        full = np.array([[2 * i, 2 * i + 1] for i in scalar]).ravel()
        local = np.zeros((2, full.size))
        local[0, 0::2] = shape
        local[1, 1::2] = shape
        rows = self.rotation @ local
        free = self.dof_map[full]
        keep = free >= 0
        p = self.mesh.points
        tan = (p[b] - p[a]) / np.hypot(*(p[b] - p[a]))
        cell = int(self._skmesh.f2t[0, facet])
        centre = p[self.mesh.cells[cell]].mean(axis=0)
        normal = np.array([tan[1], -tan[0]])
        if normal @ (0.5 * (p[a] + p[b]) - centre) < 0.0:
            normal = -normal
        position = self.origin + self.rotation @ ((1.0 - xi) * p[a] + xi * p[b])
        return BoundaryPoint(dofs=free[keep], rows=rows[:, keep],
                             normal=self.rotation @ normal, tangent=self.rotation @ tan,
                             position=position, segment=k)

    def _average(self, group: str) -> BoundaryPoint:
        pairs, arc = self.chain(group)
        length = arc[-1]
        # Simpson's rule is exact on a segment for the traces (of degree <= 2)
        nodes, weights = (0.0, 0.5, 1.0), (1.0 / 6.0, 4.0 / 6.0, 1.0 / 6.0)
        n_free = self.n_dof
        total = np.zeros((2, n_free))
        normal = None
        for k in range(pairs.shape[0]):
            h = arc[k + 1] - arc[k]
            for xi, w in zip(nodes, weights):
                pt = self._segment_point(pairs, k, xi)
                if normal is None:
                    normal = pt.normal
                elif float(pt.normal @ normal) < 1.0 - 1e-9:
                    raise MeshError(f"{self.mesh.source}: the group {group!r} is not straight; "
                                    f"its average needs one normal (give `s`)")
                np.add.at(total.T, pt.dofs, (w * h / length) * pt.rows.T)
        dofs = np.flatnonzero(np.any(total != 0.0, axis=0))
        mid = self.boundary_point(group, 0.5 * length)
        return BoundaryPoint(dofs=dofs, rows=total[:, dofs], normal=normal,
                             tangent=mid.tangent, position=mid.position, segment=-1)

    def point_operator(self, s):
        """Row of the outward normal displacement at the point ``s = (group, arc)``.

        Returns ``(dofs, weights)`` with ``u_n = weights @ u[dofs]`` [m]; the
        consistent load of a force ``P`` [N] along the outward normal is
        ``P * weights`` on ``dofs`` (see :meth:`LinearStructure.point_operator`).
        """
        group, arc = s
        pt = self.boundary_point(group, arc)
        return pt.dofs, pt.normal @ pt.rows

    def port_direction(self, s) -> np.ndarray:
        """The direction the point ``s = (group, arc)`` moves along: its
        segment's outward normal (world), (2,)."""
        group, arc = s
        return self.boundary_point(group, arc).normal

    def reference_position(self, s) -> np.ndarray:
        group, arc = s
        return self.boundary_point(group, arc).position

    def position(self, s, u) -> np.ndarray:
        """World position of the boundary point ``s = (group, arc)`` for the DOFs ``u``."""
        group, arc = s
        pt = self.boundary_point(group, arc)
        return pt.position + pt.rows @ np.asarray(u, dtype=float)[pt.dofs]

    # -- the whole field -------------------------------------------------------
    def nodes(self) -> np.ndarray:
        """Reference world positions of the mesh's vertices, (N, 2) [m]."""
        return self.origin + self.mesh.points @ self.rotation.T

    def nodal_displacement(self, u) -> np.ndarray:
        """World displacement of every vertex, shape (..., N, 2) [m], zero where fixed."""
        u = np.asarray(u, dtype=float)
        n_v = self.mesh.points.shape[0]
        full = np.zeros(u.shape[:-1] + (self.dof_map.size,))
        free = self.dof_map >= 0
        full[..., free] = u[..., self.dof_map[free]]
        local = full[..., :2 * n_v].reshape(u.shape[:-1] + (n_v, 2))
        return local @ self.rotation.T

    def translation(self, velocity) -> np.ndarray:
        """The free DOFs of a uniform world vector ``velocity`` (2,) over the
        body (zero where fixed): a rigid translation's velocity."""
        local = self.rotation.T @ np.asarray(velocity, dtype=float)
        full = np.zeros(self.dof_map.size)
        full[0::2], full[1::2] = local
        return full[self.free]

    def gravity_load(self, g_vec) -> np.ndarray:
        """Consistent load of the body's weight over the free DOFs [N]."""
        g = np.asarray(g_vec, dtype=float)
        if g.shape != (2,) or not np.all(np.isfinite(g)):
            raise ValueError(f"`g_vec` must be a finite 2-vector [m/s^2], got {g_vec!r}")
        acc = np.zeros(self.dof_map.size)
        acc[0::2], acc[1::2] = self.rotation.T @ g
        return (self._m_full @ acc)[self.free]

"""A plane mesh read from a file (through meshio) and checked for the traps
of a mesh pipeline before anything is assembled.

cosim reads the cells and the named boundary groups itself: the 2-D cells
(first-order triangles or quadrangles, one kind), the line cells of every
Gmsh physical curve (``gmsh:physical`` cell data, names from
``field_data``) and nothing else.  It never leaves a named boundary to a
library's silent fallback: a group the scene asks for either is found, with
line cells that are edges of the mesh, or is refused by name.

Every refusal is a :class:`MeshError` naming the file, what is wrong and
the fix.
"""
from __future__ import annotations

import contextlib
import io
import os
from dataclasses import dataclass, field

import numpy as np

__all__ = ["MeshError", "PlaneMesh", "read_mesh", "dof_count", "outline", "MAX_DOF", "CELL_KINDS"]

#: Most degrees of freedom a plane body may have (its memory bound): a
#: sparse factorisation of 500k DOF of P2 elasticity needs several GB.
MAX_DOF = 500_000

#: element name -> the cell kind it is built on
CELL_KINDS = {"P1": "triangle", "P2": "triangle", "Q1": "quad", "Q2": "quad"}

_SECOND_ORDER = ("triangle6", "triangle7", "quad8", "quad9", "line3")
_THREE_D = ("tetra", "hexahedron", "wedge", "pyramid", "tetra10", "hexahedron20",
            "hexahedron27", "wedge15", "pyramid13")


class MeshError(ValueError):
    """A mesh file cosim cannot use; the message names the file and the fix."""


@dataclass(eq=False)
class PlaneMesh:
    """First-order 2-D cells and named boundary groups, in metres.

    Attributes
    ----------
    points : ndarray, shape (N, 2)
        Vertex coordinates [m] (``scale`` applied), every one used by a cell.
    cells : ndarray of int, shape (n, 3) or (n, 4)
        Counter-clockwise corner indices of the triangles or quadrangles.
    kind : str
        ``"triangle"`` or ``"quad"``.
    groups : dict
        Group name -> ndarray (k, 2) of directed vertex pairs (the line
        cells of a physical curve, in the file's order and direction).
    source : str
        What the mesh came from (a file name), for messages.
    digest : str
        SHA-256 of the file's bytes ("" for a mesh built in code).
    point_groups : dict
        Group name -> ndarray (k,) of vertices (a Gmsh physical point).
    """

    points: np.ndarray
    cells: np.ndarray
    kind: str
    groups: dict = field(default_factory=dict)
    source: str = "<mesh built in code>"
    digest: str = ""
    point_groups: dict = field(default_factory=dict)

    def __post_init__(self):
        self.points = np.ascontiguousarray(self.points, dtype=float)
        self.cells = np.ascontiguousarray(self.cells, dtype=np.int64)
        self.groups = {str(k): np.asarray(v, dtype=np.int64).reshape(-1, 2)
                       for k, v in self.groups.items()}
        self.point_groups = {str(k): np.asarray(v, dtype=np.int64).ravel()
                             for k, v in self.point_groups.items()}
        _check_cells(self)
        _check_groups(self)

    def vertices(self, name: str) -> np.ndarray:
        """The vertices of a point group, or of a curve group's segments.

        Raises
        ------
        MeshError
            If the mesh has no such group, or it is empty.
        """
        if name in self.point_groups:
            if self.point_groups[name].size == 0:
                raise MeshError(f"{self.source}: the point group {name!r} holds no vertex; "
                                f"give its physical point a meshed point")
            return self.point_groups[name]
        return np.unique(self.group(name))

    def group(self, name: str) -> np.ndarray:
        """The directed vertex pairs of group ``name``.

        Raises
        ------
        MeshError
            If the mesh has no such group, or the group has no line cells.
        """
        if name not in self.groups:
            have = ", ".join(repr(g) for g in sorted(self.groups)) or "none"
            if name in self.point_groups:
                raise MeshError(f"{self.source}: {name!r} is a point group; a boundary point "
                                f"needs a curve group (its curve groups: {have})")
            if self.point_groups:
                have += "; point groups: " + ", ".join(repr(g)
                                                       for g in sorted(self.point_groups))
            raise MeshError(f"{self.source}: no boundary group {name!r} (its groups: {have}); "
                            f"name a Physical Curve of the mesh, e.g. in Gmsh "
                            f"`Physical Curve(\"{name}\") = {{...}};`")
        pairs = self.groups[name]
        if pairs.shape[0] == 0:
            raise MeshError(f"{self.source}: the boundary group {name!r} holds no line cells "
                            f"(its physical curve names no meshed curve); give it the curves "
                            f"of that boundary and mesh again")
        return pairs


def dof_count(mesh: PlaneMesh, element: str) -> int:
    """Degrees of freedom (both components, before supports) of ``element``
    on ``mesh``, counted from its cells without assembling anything."""
    n_v = mesh.points.shape[0]
    if element in ("P1", "Q1"):
        return 2 * n_v
    n_e = _edges(mesh.cells).shape[0]
    n_c = mesh.cells.shape[0] if element == "Q2" else 0
    return 2 * (n_v + n_e + n_c)


def outline(cells: np.ndarray) -> list:
    """The boundary of a mesh of counter-clockwise ``cells``: its closed
    loops (the outer one and each hole's), each an array of vertex indices
    in the order the cells run, its first vertex repeated at its end.

    A boundary edge is an edge of one cell only; each such directed edge
    leads to the next, since every boundary vertex of a plane mesh (a
    manifold with holes) starts exactly one.
    """
    cells = np.asarray(cells, dtype=np.int64)
    k = cells.shape[1]
    directed = np.stack([cells, np.roll(cells, -1, axis=1)], axis=2).reshape(-1, 2)
    key = np.sort(directed, axis=1)
    _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    edges = directed[counts[inverse.ravel()] == 1]
    if k not in (3, 4) or edges.size == 0:
        return []
    nxt = dict(zip(edges[:, 0].tolist(), edges[:, 1].tolist()))
    loops, left = [], set(nxt)
    while left:
        start = min(left)
        loop = [start]
        cur = nxt[start]
        left.discard(start)
        while cur != start:
            loop.append(cur)
            left.discard(cur)
            cur = nxt[cur]
        loops.append(np.array(loop + [start], dtype=np.int64))
    return loops


def _edges(cells: np.ndarray) -> np.ndarray:
    k = cells.shape[1]
    e = np.concatenate([cells[:, [i, (i + 1) % k]] for i in range(k)])
    return np.unique(np.sort(e, axis=1), axis=0)


def _signed_areas(points: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """Twice the signed area at each corner, (n, k): positive counter-clockwise."""
    k = cells.shape[1]
    out = np.empty(cells.shape)
    for i in range(k):
        a, b, c = (points[cells[:, (i + j) % k]] for j in (-1, 0, 1))
        u, v = b - a, c - b
        out[:, i] = u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]
    return out


def _check_cells(mesh: PlaneMesh, entity=None) -> None:
    """Orient the cells counter-clockwise, refuse degenerate or inverted ones."""
    src, p, t = mesh.source, mesh.points, mesh.cells
    if p.ndim != 2 or p.shape[1] != 2 or not np.all(np.isfinite(p)):
        raise MeshError(f"{src}: the points must be finite (N, 2) coordinates")
    if t.ndim != 2 or t.shape[1] not in (3, 4) or t.shape[0] == 0:
        raise MeshError(f"{src}: the mesh must have 2-D cells of 3 or 4 corners")
    if t.min() < 0 or t.max() >= p.shape[0]:
        raise MeshError(f"{src}: a cell names a point the mesh does not have")
    mesh.kind = "triangle" if t.shape[1] == 3 else "quad"
    corners = _signed_areas(p, t)
    size = float(np.ptp(p, axis=0).max()) ** 2
    tiny = 1e-12 * size
    lo, hi = corners.min(axis=1), corners.max(axis=1)
    bad = np.flatnonzero((np.abs(corners) <= tiny).any(axis=1) | ((lo < 0) & (hi > 0)))
    if bad.size:
        raise MeshError(f"{src}: {bad.size} cell(s) are degenerate or self-crossing (the first "
                        f"is cell {bad[0]}, corners {p[t[bad[0]]].tolist()}); mesh again "
                        f"(Gmsh: check the curve loops, `Mesh.Optimize = 1`)")
    clockwise = hi < 0
    entity = np.zeros(t.shape[0], dtype=np.int64) if entity is None else entity
    for e in np.unique(entity):
        mine = entity == e
        flipped = clockwise[mine]
        if flipped.any() and not flipped.all():
            first = np.flatnonzero(mine & (clockwise != (2 * flipped.sum() > flipped.size)))[0]
            raise MeshError(f"{src}: {min(flipped.sum(), (~flipped).sum())} cell(s) are "
                            f"inverted against their neighbours (the first is cell {first}); "
                            f"the mesh is tangled: mesh again (Gmsh: `Mesh.Optimize = 1`, "
                            f"or fewer curve points where the surface folds)")
    # a surface drawn clockwise is an orientation, not an error: reverse it
    t[clockwise] = t[clockwise][:, ::-1]


def _check_groups(mesh: PlaneMesh) -> None:
    """Refuse a group whose line cells are not edges of the 2-D cells."""
    edges = {tuple(e) for e in _edges(mesh.cells).tolist()}
    for name, verts in mesh.point_groups.items():
        if verts.size and ((verts < 0).any() or (verts >= mesh.points.shape[0]).any()):
            raise MeshError(f"{mesh.source}: the point group {name!r} names a point that is no "
                            f"vertex of the 2-D cells; put its physical point on the body")
    for name, pairs in mesh.groups.items():
        if pairs.size and ((pairs < 0).any() or
                           any(tuple(sorted(e)) not in edges for e in pairs.tolist())):
            raise MeshError(f"{mesh.source}: the boundary group {name!r} has line cells that "
                            f"are not edges of the 2-D cells; mesh the curves and the surface "
                            f"together (Gmsh: the curves must bound the Physical Surface)")


def _gmsh_groups(msh, dim: int) -> dict:
    """Physical groups of dimension ``dim`` (1: curves, 0: points): name ->
    the cells' vertices in the file's numbering, (k, 2) or (k,)."""
    kind, width = ("line", 2) if dim == 1 else ("vertex", 1)
    names = {int(v[0]): k for k, v in (msh.field_data or {}).items()
             if len(v) > 1 and int(v[1]) == dim}
    groups = {k: [] for k in names.values()}
    tags = (msh.cell_data or {}).get("gmsh:physical")
    for block, tag in zip(msh.cells, tags if tags is not None else ()):
        if block.type != kind:
            continue
        tag = np.asarray(tag)
        for t in np.unique(tag):
            if int(t) in names:
                groups[names[int(t)]].append(np.asarray(block.data)[tag == t])
    return {k: (np.concatenate(v) if v else np.zeros((0, width), np.int64)).astype(np.int64)
            .reshape(-1, width) for k, v in groups.items()}


def read_mesh(path, scale: float = 1.0, element: str = "P2", max_dof: int = MAX_DOF,
              where: str | None = None) -> PlaneMesh:
    """Read and check a plane mesh file.

    Parameters
    ----------
    path : path-like
        A file meshio reads: Gmsh ``.msh`` (2.2 or 4.1), ``.xdmf``, ``.vtu``.
    scale : float
        Factor from the file's length unit to metres (``1e-3`` for mm).
    element : str
        ``"P1"``, ``"P2"`` (triangles), ``"Q1"`` or ``"Q2"`` (quadrangles):
        the DOF bound is counted for it, and the cell kind must fit it.
    max_dof : int
        Largest number of degrees of freedom accepted.
    where : str, optional
        How messages name the file (default: the path).

    Returns
    -------
    PlaneMesh

    Raises
    ------
    MeshError
        On any trap: an unreadable file, no 2-D cells (or physical curves
        without a Physical Surface), mixed, second-order, 3-D or unsupported
        cells, a z coordinate not zero, degenerate or inverted cells, a
        group's line cells that are not edges of the mesh, or more DOFs than
        ``max_dof``.
    """
    import hashlib

    src = str(path) if where is None else where
    if element not in CELL_KINDS:
        raise MeshError(f"{src}: `element` must be one of P1, P2, Q1, Q2, got {element!r}")
    scale = float(scale)
    if not (np.isfinite(scale) and scale > 0.0):
        raise MeshError(f"{src}: `scale` must be a number > 0, got {scale!r}")
    try:
        with open(path, "rb") as fh:
            digest = hashlib.sha256(fh.read()).hexdigest()
    except OSError as exc:
        raise MeshError(f"{src}: cannot read the mesh file ({exc.strerror or exc})") from None
    msh = _meshio_read(path, src)
    types = {b.type for b in msh.cells}
    two_d = types & {"triangle", "quad"}
    if types & set(_THREE_D):
        raise MeshError(f"{src}: holds 3-D cells ({', '.join(sorted(types & set(_THREE_D)))}); "
                        f"a plane body needs a 2-D mesh (Gmsh: `Mesh 2`, in the plane z = 0)")
    if types & set(_SECOND_ORDER):
        raise MeshError(f"{src}: holds second-order cells "
                        f"({', '.join(sorted(types & set(_SECOND_ORDER)))}); mesh with "
                        f"first-order cells (Gmsh: `Mesh.ElementOrder = 1`): cosim raises the "
                        f"order itself with element = \"P2\" or \"Q2\"")
    other = types - {"triangle", "quad", "line", "vertex"}
    if other:
        raise MeshError(f"{src}: holds cells cosim does not support ({', '.join(sorted(other))}); "
                        f"give first-order triangles or quadrangles")
    if not two_d:
        curves = [k for k, v in (msh.field_data or {}).items() if len(v) > 1 and int(v[1]) == 1]
        if curves:
            raise MeshError(f"{src}: holds physical curves ({', '.join(sorted(curves))}) but no "
                            f"2-D cells: Gmsh saves only the cells of physical groups once any "
                            f"is defined; add a `Physical Surface` of the body and mesh again")
        raise MeshError(f"{src}: holds no 2-D cells (triangles or quadrangles); mesh the "
                        f"surface (Gmsh: `Mesh 2`)")
    if len(two_d) > 1:
        raise MeshError(f"{src}: mixes triangles and quadrangles; mesh with one kind (Gmsh: "
                        f"`Mesh.RecombineAll = 1` for quadrangles only, 0 for triangles)")
    kind = two_d.pop()
    if CELL_KINDS[element] != kind:
        fits = "P1 or P2" if kind == "triangle" else "Q1 or Q2"
        raise MeshError(f"{src}: element = {element!r} needs {CELL_KINDS[element]} cells but the "
                        f"mesh has {kind} cells; choose {fits}")
    points = np.asarray(msh.points, dtype=float)
    if points.ndim != 2 or points.shape[1] not in (2, 3):
        raise MeshError(f"{src}: the points are not 2-D or 3-D coordinates")
    if points.shape[1] == 3:
        extent = max(float(np.ptp(points[:, :2], axis=0).max()), 1e-300)
        z = np.abs(points[:, 2])
        if z.max() > 1e-12 * extent:
            raise MeshError(f"{src}: z is not zero (up to {z.max():.6g}): a plane body lies in "
                            f"the plane z = 0; draw it there")
    blocks = [b for b in msh.cells if b.type == kind]
    cells = np.concatenate([np.asarray(b.data, dtype=np.int64) for b in blocks])
    geo = (msh.cell_data or {}).get("gmsh:geometrical")
    entity = None
    if geo is not None:
        entity = np.concatenate([np.asarray(g, dtype=np.int64)
                                 for b, g in zip(msh.cells, geo) if b.type == kind])
    groups, point_groups = _gmsh_groups(msh, 1), _gmsh_groups(msh, 0)
    used = np.unique(cells)
    renumber = np.full(points.shape[0], -1, dtype=np.int64)
    renumber[used] = np.arange(used.size)
    mesh = PlaneMesh.__new__(PlaneMesh)
    mesh.points = np.ascontiguousarray(points[used, :2] * scale)
    mesh.cells = renumber[cells]
    mesh.source, mesh.digest, mesh.kind = src, digest, kind
    mesh.groups = {name: (renumber[pairs] if pairs.size else pairs).reshape(-1, 2)
                   for name, pairs in groups.items()}
    mesh.point_groups = {name: (renumber[v] if v.size else v).ravel()
                         for name, v in point_groups.items()}
    _check_cells(mesh, entity)
    _check_groups(mesh)
    n = dof_count(mesh, element)
    if n > max_dof:
        raise MeshError(f"{src}: element {element} on this mesh has {n} degrees of freedom, over "
                        f"the bound of {max_dof}; mesh coarser, or choose "
                        f"{'P1' if kind == 'triangle' else 'Q1'}")
    return mesh


def _meshio_read(path, src: str):
    import meshio

    if not os.path.isfile(path):
        raise MeshError(f"{src}: no such mesh file; give a path relative to the scene")
    quiet = io.StringIO()
    try:
        # meshio prints what it failed to read and exits; the message is ours
        with contextlib.redirect_stdout(quiet), contextlib.redirect_stderr(quiet):
            return meshio.read(path)
    except SystemExit:
        raise MeshError(f"{src}: meshio cannot read it as any format its name suggests; give "
                        f"a Gmsh .msh (2.2 or 4.1), .xdmf or .vtu file") from None
    except meshio.ReadError as exc:
        raise MeshError(f"{src}: meshio cannot read it ({exc}); give a Gmsh .msh (2.2 or 4.1), "
                        f".xdmf or .vtu file") from None
    except (ValueError, KeyError, IndexError, TypeError, OSError) as exc:
        raise MeshError(f"{src}: meshio cannot read it ({type(exc).__name__}: {exc}); give a "
                        f"Gmsh .msh (2.2 or 4.1), .xdmf or .vtu file") from None

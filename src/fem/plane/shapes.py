"""Plane meshes built in code: a structured quadrilateral region with its
four sides as named groups (for tests, twins of the 1-D structures, and
bodies too simple to need Gmsh)."""
from __future__ import annotations

import numpy as np

from .mesh import PlaneMesh

__all__ = ["quad_region", "rectangle", "grid"]


def quad_region(corners, nx: int, ny: int, kind: str = "triangle",
                name: str = "<quad region>") -> PlaneMesh:
    """A structured mesh of the quadrilateral with ``corners`` (counter-clockwise,
    from the first) mapped bilinearly from ``nx`` x ``ny`` cells.

    The groups ``bottom`` (corner 0 -> 1), ``right`` (1 -> 2), ``top``
    (3 -> 2) and ``left`` (0 -> 3) run from the first corner's side, so the
    arc length along ``bottom`` and ``top`` grows with the first
    coordinate.  ``kind = "triangle"`` cuts each cell along its diagonal.
    """
    c = np.asarray(corners, dtype=float).reshape(4, 2)
    a, b = np.meshgrid(np.linspace(0.0, 1.0, nx + 1), np.linspace(0.0, 1.0, ny + 1),
                       indexing="ij")
    a, b = a.ravel(), b.ravel()
    p = (np.outer((1 - a) * (1 - b), c[0]) + np.outer(a * (1 - b), c[1])
         + np.outer(a * b, c[2]) + np.outer((1 - a) * b, c[3]))

    def v(i, j):
        return i * (ny + 1) + j

    i, j = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    i, j = i.ravel(), j.ravel()
    q = np.stack([v(i, j), v(i + 1, j), v(i + 1, j + 1), v(i, j + 1)], axis=1)
    cells = q if kind == "quad" else np.concatenate([q[:, [0, 1, 2]], q[:, [0, 2, 3]]])
    k = np.arange(nx)
    m = np.arange(ny)
    groups = {"bottom": np.stack([v(k, 0), v(k + 1, 0)], axis=1),
              "top": np.stack([v(k, ny), v(k + 1, ny)], axis=1),
              "left": np.stack([v(0, m), v(0, m + 1)], axis=1),
              "right": np.stack([v(nx, m), v(nx, m + 1)], axis=1)}
    return PlaneMesh(p, cells, kind, groups, source=name)


def rectangle(length: float, height: float, nx: int, ny: int, kind: str = "triangle",
              name: str = "<rectangle>") -> PlaneMesh:
    """The rectangle ``[0, length] x [-height/2, height/2]`` (see :func:`quad_region`)."""
    h = 0.5 * height
    return quad_region([(0.0, -h), (length, -h), (length, h), (0.0, h)], nx, ny, kind, name)


def grid(x, y, kind: str = "quad", name: str = "<grid>") -> PlaneMesh:
    """The tensor-product mesh of the increasing coordinates ``x`` and ``y``
    [m]: a rectangle graded as the coordinates are (finer under a contact),
    with the groups of :func:`quad_region` (``bottom`` at ``y[0]``, ``top``
    at ``y[-1]``, ``left`` at ``x[0]``, ``right`` at ``x[-1]``)."""
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    if x.ndim != 1 or y.ndim != 1 or x.size < 2 or y.size < 2 \
            or not (np.all(np.diff(x) > 0) and np.all(np.diff(y) > 0)):
        raise ValueError("`x` and `y` must be increasing arrays of two or more coordinates")
    m = quad_region([(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)], x.size - 1, y.size - 1,
                    kind, name)
    i = np.rint(m.points[:, 0] * (x.size - 1)).astype(int)
    j = np.rint(m.points[:, 1] * (y.size - 1)).astype(int)
    return PlaneMesh(np.column_stack([x[i], y[j]]), m.cells, kind, m.groups, source=name)

"""Plane elastic bodies from a mesh: read through meshio and checked
(:mod:`.mesh`), assembled by scikit-fem (:mod:`.body`, :mod:`.structure`),
reduced to modes with a static correction per visited boundary segment
(:mod:`.reduce`) and their modal bases cached on disk (:mod:`.cache`); a
circle's penalty spread over the boundary (:mod:`.circle`).

Importing this package loads numpy only; meshio is imported when a file is
read, scikit-fem when a body is assembled.
"""
from .body import PLANE_ELEMENTS, PLANE_MODELS, Plane, lame
from .circle import CircleContact, hertz_cylinder
from .mesh import MAX_DOF, MeshError, PlaneMesh, dof_count, outline, read_mesh
from .shapes import grid, quad_region, rectangle
from .structure import BoundaryPoint, PlaneStructure

__all__ = ["Plane", "PlaneStructure", "PlaneMesh", "BoundaryPoint", "MeshError", "read_mesh",
           "dof_count", "outline", "MAX_DOF", "PLANE_MODELS", "PLANE_ELEMENTS", "lame",
           "quad_region", "rectangle", "grid", "CircleContact", "hertz_cylinder"]

"""A plane elastic body: the model as a scene gives it (:class:`Plane`) and
its assembled matrices over the free DOFs (:class:`PlaneStructure`).

The weak form of linear small-deformation elasticity in the plane,

.. math:: t \\int \\rho\\, \\ddot u \\cdot v \\,dA
          + t \\int (2\\mu\\, \\varepsilon(u) : \\varepsilon(v)
          + \\lambda\\, \\mathrm{tr}\\,\\varepsilon(u)\\, \\mathrm{tr}\\,\\varepsilon(v)) \\,dA
          = \\ldots

is assembled by scikit-fem (``ElementVector`` of ``ElementTriP1``,
``ElementTriP2``, ``ElementQuad1`` or ``ElementQuad2``) with the Lame
constants ``mu = E / (2 (1 + nu))`` and ``lambda = E nu / ((1 + nu)(1 - 2 nu))``
in plane strain, ``lambda* = E nu / (1 - nu^2)`` in plane stress.  scikit-fem
is imported by ``assemble()`` only.

References
----------
.. [1] S. P. Timoshenko, J. N. Goodier, *Theory of Elasticity*, 3rd ed.,
   McGraw-Hill, 1970: plane stress and plane strain.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..checks import choice, positive, real, vector
from ..linear_structure import _rayleigh
from .mesh import CELL_KINDS, MAX_DOF, MeshError, PlaneMesh, dof_count, read_mesh
from .structure import PlaneStructure

__all__ = ["Plane", "PLANE_MODELS", "PLANE_ELEMENTS", "lame"]

PLANE_MODELS = ("plane_stress", "plane_strain")
PLANE_ELEMENTS = tuple(CELL_KINDS)


def lame(youngs_modulus: float, poisson_ratio: float, model: str) -> tuple[float, float]:
    """The in-plane Lame constants ``(lambda, mu)`` [Pa] of ``model``."""
    e, nu = youngs_modulus, poisson_ratio
    mu = e / (2.0 * (1.0 + nu))
    if model == "plane_stress":
        return e * nu / (1.0 - nu * nu), mu
    return e * nu / ((1.0 + nu) * (1.0 - 2.0 * nu)), mu


@dataclass(frozen=True)
class Plane:
    """A plane elastic body of uniform thickness and material.

    Parameters
    ----------
    mesh : path-like or PlaneMesh
        The mesh: a file meshio reads (see :func:`read_mesh`) or a mesh
        built in code.
    thickness : float
        ``t`` [m] (out of the plane).
    youngs_modulus, poisson_ratio, density : float
        ``E`` [Pa], ``nu`` (``0 <= nu < 0.5``), ``rho`` [kg/m^3].
    model : str
        ``"plane_stress"`` (a thin plate) or ``"plane_strain"``.
    element : str
        ``"P2"`` (default), ``"P1"`` (triangles), ``"Q1"``, ``"Q2"`` (quadrangles).
    fixed : str or tuple of str
        Groups (curves or points) whose displacement is zero; none for a
        free body.
    fixed_x, fixed_y : str or tuple of str
        Groups whose displacement along the mesh's x (y) is zero: a roller,
        or a pin at a point group.
    scale : float
        File length unit in metres (``1e-3`` for a millimetre mesh).
    origin : (2,) float
        World position of the mesh's origin [m].
    angle : float
        Rotation of the mesh into the world [rad].
    rayleigh : (a0, a1) or None
        Rayleigh damping ``C = a0 M + a1 K``.
    max_dof : int
        The memory bound on the degrees of freedom, checked from the file.

    Notes
    -----
    P1 triangles lock in bending (the clamped 1 m x 0.1 m strip's first
    frequency is 1.6 % high with four rows through the thickness); use P2
    or Q2 for slender parts.
    """

    mesh: object
    thickness: float
    youngs_modulus: float
    poisson_ratio: float
    density: float
    model: str = "plane_stress"
    element: str = "P2"
    fixed: tuple = ()
    fixed_x: tuple = ()
    fixed_y: tuple = ()
    scale: float = 1.0
    origin: tuple = (0.0, 0.0)
    angle: float = 0.0
    rayleigh: tuple | None = None
    max_dof: int = MAX_DOF

    def __post_init__(self):
        put = object.__setattr__
        put(self, "thickness", positive(self.thickness, "thickness", "m"))
        put(self, "youngs_modulus", positive(self.youngs_modulus, "youngs_modulus", "Pa"))
        put(self, "poisson_ratio", real("poisson_ratio", self.poisson_ratio, 0.0,
                                        0.5 - 1e-9, "in [0, 0.5)"))
        put(self, "density", positive(self.density, "density", "kg/m^3"))
        put(self, "model", choice(self.model, "model", PLANE_MODELS))
        put(self, "element", choice(self.element, "element", PLANE_ELEMENTS))
        put(self, "scale", positive(self.scale, "scale", "m per mesh unit"))
        put(self, "origin", vector(self.origin, "origin", unit=False))
        put(self, "angle", real("angle", self.angle))
        put(self, "rayleigh", _rayleigh(self.rayleigh))
        for key in ("fixed", "fixed_x", "fixed_y"):
            value = getattr(self, key)
            groups = (value,) if isinstance(value, str) else tuple(value)
            if not all(isinstance(g, str) and g for g in groups):
                raise ValueError(f"`{key}` must name mesh groups, got {value!r}")
            put(self, key, groups)

    @property
    def supports(self) -> dict:
        """Component (``None`` for both, 0 for x, 1 for y) -> the groups it holds."""
        return {None: self.fixed, 0: self.fixed_x, 1: self.fixed_y}

    def read(self) -> PlaneMesh:
        """The checked mesh (read from the file once, or the one given)."""
        known = self.__dict__.get("_mesh_read")
        if known is None:
            known = self._read()
            object.__setattr__(self, "_mesh_read", known)
        return known

    def _read(self) -> PlaneMesh:
        if isinstance(self.mesh, PlaneMesh):
            n = dof_count(self.mesh, self.element)
            if CELL_KINDS[self.element] != self.mesh.kind:
                raise MeshError(f"{self.mesh.source}: element = {self.element!r} needs "
                                f"{CELL_KINDS[self.element]} cells, the mesh has "
                                f"{self.mesh.kind} cells")
            if n > self.max_dof:
                raise MeshError(f"{self.mesh.source}: {n} degrees of freedom, over the bound "
                                f"of {self.max_dof}")
            if self.scale != 1.0:
                return PlaneMesh(self.mesh.points * self.scale, self.mesh.cells,
                                 self.mesh.kind, self.mesh.groups, self.mesh.source,
                                 self.mesh.digest)
            return self.mesh
        return read_mesh(self.mesh, self.scale, self.element, self.max_dof)

    def dof_bound(self) -> int:
        """Degrees of freedom before the supports, from the mesh's cells."""
        return dof_count(self.read(), self.element)

    def assemble(self, mesh: PlaneMesh | None = None) -> PlaneStructure:
        """Assemble ``M``, ``K`` (and ``C``) over the free DOFs.

        Parameters
        ----------
        mesh : PlaneMesh, optional
            The mesh :meth:`read` returned, when the caller has it already.
        """
        import skfem
        from skfem.helpers import ddot, dot, sym_grad, trace

        mesh = self.read() if mesh is None else mesh
        for groups in self.supports.values():
            for name in groups:
                mesh.vertices(name)            # refuses a missing or empty group
        cls = skfem.MeshTri if mesh.kind == "triangle" else skfem.MeshQuad
        sk = cls(mesh.points.T.copy(), mesh.cells.T.copy())
        scalar = {"P1": skfem.ElementTriP1, "P2": skfem.ElementTriP2,
                  "Q1": skfem.ElementQuad1, "Q2": skfem.ElementQuad2}[self.element]()
        sbasis = skfem.Basis(sk, scalar)
        vbasis = skfem.Basis(sk, skfem.ElementVector(scalar))
        if not (np.array_equal(vbasis.doflocs[:, 0::2], sbasis.doflocs)
                and np.array_equal(vbasis.doflocs[:, 1::2], sbasis.doflocs)
                and np.array_equal(sbasis.nodal_dofs[0], np.arange(mesh.points.shape[0]))):
            raise RuntimeError("scikit-fem numbered the vector DOFs other than 2 i + c")
        lam, mu = lame(self.youngs_modulus, self.poisson_ratio, self.model)
        t, rho = self.thickness, self.density

        @skfem.BilinearForm
        def stiffness(u, v, _):
            eu, ev = sym_grad(u), sym_grad(v)
            return t * (2.0 * mu * ddot(eu, ev) + lam * trace(eu) * trace(ev))

        @skfem.BilinearForm
        def mass(u, v, _):
            return rho * t * dot(u, v)

        k_full = stiffness.assemble(vbasis).tocsr()
        m_full = mass.assemble(vbasis).tocsr()
        return PlaneStructure(plane=self, mesh=mesh, skmesh=sk, scalar_basis=sbasis,
                              mass_full=m_full, stiffness_full=k_full,
                              angle=self.angle, origin=self.origin, rayleigh=self.rayleigh)

    def describe(self) -> dict:
        """What the structure's modes depend on besides the mesh file (a
        cache key's part)."""
        return {"thickness": self.thickness, "youngs_modulus": self.youngs_modulus,
                "poisson_ratio": self.poisson_ratio, "density": self.density,
                "model": self.model, "element": self.element, "fixed": list(self.fixed),
                "fixed_x": list(self.fixed_x), "fixed_y": list(self.fixed_y),
                "scale": self.scale}


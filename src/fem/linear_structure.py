"""The common face of every linear structure: matrices over the free DOFs,
point evaluation, consistent point loads, reference geometry.

A linear structure here carries ONE scalar displacement field ``w`` along a
fixed world direction ``direction`` (transverse for the beam, the string and
the chain, axial for the rod).  Its equations of motion over the free degrees
of freedom ``u`` (boundary conditions already eliminated) are

.. math:: M \\ddot u + C \\dot u + K u = f,

with ``C`` present only when Rayleigh coefficients were given.  A material
point is addressed by a coordinate ``s``: the arc length from the start of a
line structure [m], or the mass index ``0..n-1`` of the chain.  Its
displacement is ``w(s) = weights @ u[dofs]`` with ``(dofs, weights) =
point_operator(s)``, and the consistent nodal load of a point force ``P`` [N]
acting there along ``direction`` is ``P * weights`` scattered onto ``dofs``
(the two are transposes of each other: virtual work).

This module imports neither scikit-fem nor meshio; the mesh-based models
import scikit-fem inside their ``assemble()`` only.
"""
from __future__ import annotations

import math
from abc import ABC, abstractmethod

import numpy as np

from .checks import choice, count, positive, vector

__all__ = ["LinearStructure", "LineStructure"]


def _place(obj, *names: str) -> None:
    """Check and normalise a frozen model's placement fields in place:
    ``origin`` (a point), ``axis`` and ``direction`` (unit vectors, mutually
    perpendicular when both are given) and ``rayleigh``."""
    for name in names:
        if name == "rayleigh":
            value = _rayleigh(obj.rayleigh)
        else:
            value = vector(getattr(obj, name), name, unit=name != "origin")
        object.__setattr__(obj, name, value)
    if "axis" in names and "direction" in names:
        _perpendicular(obj.axis, obj.direction)


def _perpendicular(axis, direction) -> None:
    if abs(axis[0] * direction[0] + axis[1] * direction[1]) > 1e-9:
        raise ValueError("`direction` must be perpendicular to `axis` for a transverse "
                         f"field, got axis={axis!r}, direction={direction!r}")


def _rayleigh(value):
    """Return ``None`` or a pair ``(a0, a1)`` of finite floats >= 0."""
    if value is None:
        return None
    try:
        a0, a1 = (float(x) for x in value)
    except (TypeError, ValueError):
        raise ValueError("`rayleigh` must be a pair (a0 [1/s], a1 [s]) of numbers >= 0, "
                         f"got {value!r}") from None
    if not (math.isfinite(a0) and math.isfinite(a1) and a0 >= 0.0 and a1 >= 0.0):
        raise ValueError("`rayleigh` must be a pair (a0 [1/s], a1 [s]) of numbers >= 0, "
                         f"got {value!r}")
    return (a0, a1)


def _as_matrix(a):
    """A scipy.sparse matrix as CSR, anything else as a dense float array."""
    if hasattr(a, "tocsr"):
        return a.tocsr().astype(float)
    return np.array(a, dtype=float)


def _mass_orthonormal(vectors: np.ndarray, mass) -> np.ndarray:
    """Columns of ``vectors`` made M-orthonormal (same span)."""
    if vectors.shape[1] == 0:
        return vectors
    gram = vectors.T @ (mass @ vectors)
    chol = np.linalg.cholesky(gram)
    return np.linalg.solve(chol, vectors.T).T


# --------------------------------------------------------------------------
# The interface.
# --------------------------------------------------------------------------
class LinearStructure(ABC):
    """A linear structure reduced to its free degrees of freedom.

    Concrete models (``Chain``, ``Beam``, ``String``, ``Rod``) build one with
    their ``assemble()`` method.  Treat instances as immutable.

    Attributes
    ----------
    mass : scipy.sparse.csr_matrix
        Mass matrix ``M`` over the free DOFs, shape (n_dof, n_dof) [kg, kg m, kg m^2].
    stiffness : scipy.sparse.csr_matrix
        Stiffness matrix ``K`` over the free DOFs [N/m, N, N m].
    damping : scipy.sparse.csr_matrix or None
        ``C = a0 M + a1 K`` when ``rayleigh = (a0, a1)`` was given, else None.
    rayleigh : tuple of float or None
        The Rayleigh coefficients ``(a0 [1/s], a1 [s])`` or None.
    dof_names : tuple of str
        One name per free DOF.
    origin : ndarray, shape (2,)
        World position of the material point ``s = 0`` in the reference
        configuration [m].
    axis : ndarray, shape (2,)
        Unit vector along the structure: the reference position of ``s`` is
        ``origin + s * axis`` for a line structure.
    direction : ndarray, shape (2,)
        Unit vector of the displacement field ``w``.
    """

    def __init__(self, *, mass, stiffness, dof_names, origin, axis, direction,
                 inertia_load, rayleigh=None, rigid_modes=None):
        # a sparse model (a mesh) stays sparse CSR; a small dense one (a
        # chain) stays a dense array, and needs no scipy.sparse
        self.mass = _as_matrix(mass)
        self.stiffness = _as_matrix(stiffness)
        self.dof_names = tuple(dof_names)
        n = self.mass.shape[0]
        if self.mass.shape != (n, n) or self.stiffness.shape != (n, n) or len(self.dof_names) != n:
            raise ValueError("`mass`, `stiffness` and `dof_names` must agree in size, got "
                             f"{self.mass.shape}, {self.stiffness.shape}, {len(self.dof_names)}")
        self.rayleigh = _rayleigh(rayleigh)
        self.damping = (None if self.rayleigh is None else
                        _as_matrix(self.rayleigh[0] * self.mass
                                   + self.rayleigh[1] * self.stiffness))
        self.origin = np.array(origin, dtype=float)
        self.axis = np.array(axis, dtype=float)
        self.direction = np.array(direction, dtype=float)
        self._inertia_load = np.asarray(inertia_load, dtype=float)
        rigid = np.zeros((n, 0)) if rigid_modes is None else np.asarray(rigid_modes, float)
        self._rigid = _mass_orthonormal(rigid.reshape(n, -1), self.mass)
        self._lu = None
        for a in (self.origin, self.axis, self.direction, self._inertia_load):
            a.setflags(write=False)

    # -- sizes ---------------------------------------------------------------
    @property
    def n_dof(self) -> int:
        """Number of free degrees of freedom."""
        return self.mass.shape[0]

    def with_stiffness(self, stiffness) -> "LinearStructure":
        """A copy of this structure whose stiffness matrix is ``stiffness``
        (same DOFs, points and mass; the Rayleigh damping made anew): how a
        model adds a term (an elastic foundation, a spring to the ground) to
        a structure it assembled from another.

        Raises
        ------
        ValueError
            If ``stiffness`` is not ``(n_dof, n_dof)``.
        """
        import copy
        k = _as_matrix(stiffness)
        if k.shape != self.mass.shape:
            raise ValueError(f"`stiffness` must be {self.mass.shape}, got {k.shape}")
        out = copy.copy(self)
        out.stiffness = k
        out.damping = (None if self.rayleigh is None else
                       _as_matrix(self.rayleigh[0] * self.mass + self.rayleigh[1] * k))
        out._lu = None
        return out

    # -- point evaluation ----------------------------------------------------
    @abstractmethod
    def point_operator(self, s) -> tuple[np.ndarray, np.ndarray]:
        """Evaluation weights of ``w`` at material coordinate ``s``.

        Parameters
        ----------
        s : float
            Arc length from the start [m] (line structures) or mass index
            (chain).

        Returns
        -------
        dofs : ndarray of int
            Free DOFs the point depends on (constrained ones dropped).
        weights : ndarray of float
            ``w(s) = weights @ u[dofs]`` [m]; the consistent load of a point
            force ``P`` [N] along ``direction`` is ``P * weights`` on ``dofs``.
        """

    @abstractmethod
    def nodes(self) -> np.ndarray:
        """Reference world positions of every node (constrained ones too), (N, 2) [m]."""

    @abstractmethod
    def nodal_displacement(self, u) -> np.ndarray:
        """Field ``w`` at every node, shape (..., N) [m], zero where constrained.

        Parameters
        ----------
        u : array_like, shape (..., n_dof)
            Free DOFs; leading axes (e.g. time) are kept.
        """

    def position(self, s, u) -> np.ndarray:
        """World position of material point ``s`` for the DOFs ``u``, (2,) [m]."""
        dofs, weights = self.point_operator(s)
        w = float(weights @ np.asarray(u, dtype=float)[dofs])
        return self.reference_position(s) + w * self.direction

    def reference_position(self, s) -> np.ndarray:
        """World position of material point ``s`` in the reference state, (2,) [m]."""
        return self.origin + float(s) * self.axis

    def point_load(self, s, force: float) -> np.ndarray:
        """Consistent load vector (free DOFs) of a point force at ``s`` [N]."""
        dofs, weights = self.point_operator(s)
        f = np.zeros(self.n_dof)
        np.add.at(f, dofs, float(force) * weights)
        return f

    # -- loads and statics ---------------------------------------------------
    def gravity_load(self, g_vec) -> np.ndarray:
        """Consistent load vector of the structure's own weight.

        Parameters
        ----------
        g_vec : array_like, shape (2,)
            Gravity acceleration in the world frame [m/s^2], e.g. ``(0, -9.81)``.

        Returns
        -------
        ndarray, shape (n_dof,)
            ``f = (g . direction) M_full r`` restricted to the free DOFs [N, N m],
            where ``r`` is the unit translation along ``direction``: only the
            component of gravity along the field direction loads the structure.
        """
        g = np.asarray(g_vec, dtype=float)
        if g.shape != (2,) or not np.all(np.isfinite(g)):
            raise ValueError(f"`g_vec` must be a finite 2-vector [m/s^2], got {g_vec!r}")
        return float(g @ self.direction) * self._inertia_load

    def rigid_body_modes(self) -> np.ndarray:
        """Zero-energy motions allowed by the supports, M-orthonormal, (n_dof, r).

        ``r = 0`` for a supported structure; a free-free rod has one
        (translation), a free-free beam two (translation and rotation).
        """
        return self._rigid.copy()

    def static_displacement(self, load) -> np.ndarray:
        """Solve ``K u = load`` (sparse LU, factorised once and kept).

        Parameters
        ----------
        load : array_like, shape (n_dof,)
            Load vector over the free DOFs [N, N m].

        Returns
        -------
        ndarray, shape (n_dof,)
            Static displacement [m, rad].

        Raises
        ------
        ValueError
            If the structure has rigid-body modes (no static equilibrium),
            its stiffness matrix is singular to working precision (a spring
            or support too weak to hold the load: the displacement is not
            finite) or the load has the wrong size.
        """
        f = np.asarray(load, dtype=float)
        if f.shape != (self.n_dof,):
            raise ValueError(f"`load` must have shape ({self.n_dof},), got {f.shape}")
        if self._rigid.shape[1]:
            raise ValueError(f"the structure has {self._rigid.shape[1]} rigid-body mode(s) and "
                             "no static equilibrium; support it to solve for a static state")
        if self._lu is None:
            if isinstance(self.stiffness, np.ndarray):
                K = self.stiffness
                self._lu = lambda b: np.linalg.solve(K, b)
            else:
                from scipy.sparse.linalg import splu
                try:
                    self._lu = splu(self.stiffness.tocsc()).solve
                except RuntimeError:                # exactly singular
                    self._lu = lambda b: np.full_like(b, np.nan)
        try:
            u = self._lu(f)
        except np.linalg.LinAlgError:               # exactly singular
            u = np.full_like(f, np.nan)
        if not np.all(np.isfinite(u)):
            raise ValueError("the stiffness matrix is singular to working precision: a spring "
                             "or support is too weak to hold the load (no finite static "
                             "displacement)")
        return u


class LineStructure(LinearStructure):
    """A structure meshed along a straight line of 2-node elements.

    Built by ``Beam.assemble``, ``String.assemble`` and ``Rod.assemble``;
    ``hermite=True`` means cubic Hermite elements (DOFs ``w`` and ``dw/ds``
    per node), else linear Lagrange (P1, DOF ``w`` per node).

    Attributes
    ----------
    length : float
        Length of the structure [m].
    node_coordinates : ndarray, shape (N,)
        Material coordinate ``s`` of each node [m].
    dof_map : ndarray of int, shape (N, k)
        Free-DOF index of each nodal DOF (``k = 2`` for Hermite: ``w``,
        ``dw/ds``; ``k = 1`` for P1), ``-1`` where constrained.
    hermite : bool
        Element family.
    """

    def __init__(self, *, node_coordinates, dof_map, hermite, **kwargs):
        super().__init__(**kwargs)
        self.node_coordinates = np.asarray(node_coordinates, dtype=float)
        self.dof_map = np.asarray(dof_map, dtype=np.int64)
        self.hermite = bool(hermite)
        self.length = float(self.node_coordinates[-1] - self.node_coordinates[0])
        self.node_coordinates.setflags(write=False)
        self.dof_map.setflags(write=False)

    def _locate(self, s) -> tuple[int, float, float]:
        x = self.node_coordinates
        s = float(s)
        tol = 1e-12 * self.length
        if not (x[0] - tol <= s <= x[-1] + tol):
            raise ValueError(f"`s` must be in [0, {self.length}] m, got {s!r}")
        e = int(np.clip(np.searchsorted(x, s, side="right") - 1, 0, x.size - 2))
        h = x[e + 1] - x[e]
        return e, min(max((s - x[e]) / h, 0.0), 1.0), h

    def _gather(self, e: int, shape: np.ndarray):
        if self.hermite:
            dofs = self.dof_map[e:e + 2].ravel()  # w_e, t_e, w_e+1, t_e+1
        else:
            dofs = self.dof_map[e:e + 2, 0]
        keep = dofs >= 0
        return dofs[keep], shape[keep]

    def point_operator(self, s):
        """Evaluation weights of ``w`` at arc length ``s`` [m].

        Hermite: the cubic shape functions of the element holding ``s``,
        ``N1 = 1 - 3x^2 + 2x^3``, ``N2 = h (x - 2x^2 + x^3)``,
        ``N3 = 3x^2 - 2x^3``, ``N4 = h (x^3 - x^2)`` with ``x = (s - s_e)/h``,
        exact at any ``s``.  P1: ``(1 - x, x)``.  See
        :meth:`LinearStructure.point_operator`.
        """
        e, x, h = self._locate(s)
        if self.hermite:
            x2, x3 = x * x, x * x * x
            shape = np.array([1 - 3 * x2 + 2 * x3, h * (x - 2 * x2 + x3),
                              3 * x2 - 2 * x3, h * (x3 - x2)])
        else:
            shape = np.array([1.0 - x, x])
        return self._gather(e, shape)

    def slope_operator(self, s):
        """Evaluation weights of ``dw/ds`` at ``s`` [m] (same form as
        :meth:`point_operator`; the weights have units 1/m on ``w`` DOFs).

        For P1 the slope is constant per element; at a node the element to
        the right is used (to the left at the last node).
        """
        e, x, h = self._locate(s)
        if self.hermite:
            shape = np.array([(6 * x * x - 6 * x) / h, 1 - 4 * x + 3 * x * x,
                              (6 * x - 6 * x * x) / h, 3 * x * x - 2 * x])
        else:
            shape = np.array([-1.0 / h, 1.0 / h])
        return self._gather(e, shape)

    def nodes(self) -> np.ndarray:
        return self.origin + np.outer(self.node_coordinates, self.axis)

    def nodal_displacement(self, u) -> np.ndarray:
        u = np.asarray(u, dtype=float)
        idx = self.dof_map[:, 0]
        out = np.zeros(u.shape[:-1] + idx.shape)
        free = idx >= 0
        out[..., free] = u[..., idx[free]]
        return out


def _assemble_line(x: np.ndarray, hermite: bool):
    """Unit-coefficient matrices on the line mesh with nodes ``x``.

    Returns ``(mass, laplace, bending, dof_map)``: the full-DOF matrices of
    ``int w v``, ``int w' v'`` and ``int w'' v''`` (None for P1), and the
    nodal DOF numbering (N, k).  scikit-fem is imported here, not before.
    """
    import skfem
    from skfem.helpers import dd, ddot, dot, grad

    mesh = skfem.MeshLine(x)
    element = skfem.ElementLineHermite() if hermite else skfem.ElementLineP1()
    basis = skfem.Basis(mesh, element)

    @skfem.BilinearForm
    def mass(u, v, _):
        return u * v

    @skfem.BilinearForm
    def laplace(u, v, _):
        return dot(grad(u), grad(v))

    m = mass.assemble(basis).tocsr()
    g = laplace.assemble(basis).tocsr()
    b = None
    if hermite:
        @skfem.BilinearForm
        def bending(u, v, _):
            return ddot(dd(u), dd(v))

        b = bending.assemble(basis).tocsr()
    if not np.allclose(mesh.p[0], x):
        raise RuntimeError("scikit-fem reordered the line mesh nodes")
    return m, g, b, np.asarray(basis.nodal_dofs).T


def _reduce(full_dof_map: np.ndarray, constrained) -> tuple[np.ndarray, np.ndarray]:
    """Free-DOF numbering: (free full indices, dof_map with -1 where constrained)."""
    n_full = int(full_dof_map.max()) + 1
    is_free = np.ones(n_full, dtype=bool)
    is_free[np.asarray(list(constrained), dtype=np.int64)] = False
    new = np.full(n_full, -1, dtype=np.int64)
    free = np.flatnonzero(is_free)
    new[free] = np.arange(free.size)
    return free, new[full_dof_map]


def _rigid_candidates(candidates: np.ndarray, free: np.ndarray) -> np.ndarray:
    """Combinations of zero-energy full vectors that vanish on constrained
    DOFs, restricted to the free DOFs."""
    if candidates.shape[1] == 0:
        return candidates[free]
    mask = np.ones(candidates.shape[0], dtype=bool)
    mask[free] = False
    rows = candidates[mask]
    if rows.shape[0] == 0:
        null = np.eye(candidates.shape[1])
    else:
        _, sv, vt = np.linalg.svd(rows)
        rank = int(np.sum(sv > 1e-12 * max(1.0, sv.max(initial=0.0))))
        null = vt[rank:].T
    return candidates[free] @ null


def _line_structure(*, x, hermite, mass_full, stiffness_full, constrained, candidates,
                    dof_map_full, dof_labels, origin, axis, direction, rayleigh):
    """Eliminate the constrained DOFs and wrap everything in a LineStructure."""
    free, dof_map = _reduce(dof_map_full, constrained)
    if free.size == 0:
        raise ValueError(f"`n_elements` must leave a free DOF, got {x.size - 1} "
                         "element(s) with every DOF constrained")
    translation = np.zeros(mass_full.shape[0])
    translation[dof_map_full[:, 0]] = 1.0
    inertia = (mass_full @ translation)[free]
    names_full = np.empty(mass_full.shape[0], dtype=object)
    for k, label in enumerate(dof_labels):
        names_full[dof_map_full[:, k]] = [f"{label}{j}" for j in range(x.size)]
    rigid = _rigid_candidates(candidates, free)
    return LineStructure(
        mass=mass_full[free][:, free], stiffness=stiffness_full[free][:, free],
        dof_names=tuple(names_full[free]), origin=origin, axis=axis, direction=direction,
        inertia_load=inertia, rayleigh=rayleigh, rigid_modes=rigid,
        node_coordinates=x, dof_map=dof_map, hermite=hermite)

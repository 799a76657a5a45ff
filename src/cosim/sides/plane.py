"""A plane body as a subsystem: a :class:`~cosim.sides.fem.StructureSubsystem`
whose records are its modal coordinates and its ports, never the whole
field (a body of 38k DOFs would otherwise add 76k columns to every row of
the series).  The field is the kept modes times the recorded coordinates,
``u = Phi q``: :meth:`PlaneSubsystem.field` gives it back."""
from __future__ import annotations

import numpy as np

from cosim.sides.fem import StructureSubsystem
from cosim.sides.plane_circle import CircleHosting

__all__ = ["PlaneSubsystem"]


class PlaneSubsystem(CircleHosting, StructureSubsystem):
    """A :class:`fem.plane.PlaneStructure` reduced to the modes of its basis
    (same parameters as :class:`~cosim.sides.fem.StructureSubsystem`); its
    ports slide along its boundary (:meth:`slide_port`), and it hosts circle
    contacts (:mod:`cosim.sides.plane_circle`)."""

    #: its ports slide in Python (:meth:`slide_port`), never by the compiled face
    #: of a line structure
    capabilities = (StructureSubsystem.capabilities - {"compiled_follow"}) | {"sliding_ports"}

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._names = [f"mode{i + 1}" for i in range(self.n_modes)]

    def named_values(self, X):
        """Modal coordinates of states ``X`` (..., 2 m): names, q, dq."""
        m = self.n_modes
        return self._names, X[..., :m], X[..., m:2 * m]

    def sliding_loop(self, port: int):
        """The closed boundary chain ``port`` slides along
        (:class:`fem.plane.boundary.BoundaryLoop`), made on the first call
        from the port's first point.

        Raises
        ------
        fem.plane.MeshError
            If the boundary touches itself at a vertex.
        """
        from fem.plane.boundary import BoundaryLoop

        loops = self.__dict__.setdefault("_loops", {})
        loop = loops.get(port)
        if loop is None:
            group, s = self.port_coordinates[port]
            loop = BoundaryLoop(self.structure, group, s)
            loop.set_modes(self.Phi)
            loops[port] = loop
        return loop

    def slide_port(self, port: int, point, x) -> np.ndarray:
        """Move ``port`` to the point of the deformed boundary closest to the
        world ``point`` for the state ``x`` (node-to-segment over the
        closed boundary chain through the port's first segment,
        :class:`fem.plane.boundary.BoundaryLoop`, across corners onto the
        next segment), and return the outward unit normal there.

        The port's row becomes the displacement of that material point
        projected on that normal, and it moves along the normal: its
        position's component along the normal is the deformed boundary's,
        so the gap ``n . (p - x_b)`` a contact reads is the signed distance
        to the deformed boundary, whose rate is ``n . (v_p - v_b)`` exactly.
        A contact this side hosts at the port turns its normal with it."""
        loop = self.sliding_loop(port)
        m = self.n_modes
        k, xi, n, _ = loop.project(point, np.asarray(x, float)[:m])
        row = n @ loop.modal_rows(k, xi)
        if np.array_equal(row, self._R[port]) and np.array_equal(n, self._dirs[port]):
            return n
        self._R[port] = row
        self._ref[port] = loop.position(k, xi)
        self._dirs[port] = n              # in place: the compiled kernel reads it
        self._dirc[port] = complex(n[0], n[1])
        self.port_coordinates[port] = (loop.name, loop.coordinate(k, xi))
        for j, e in enumerate(self._embedded):
            if e.port == port:
                e.normal = complex(n[0], n[1])
                if self._kernel:
                    self._kernel.set_normal(j, e.normal)
        if any(e.port == port for e in self._embedded):
            self._bases = {}            # the springs' modes hang on the port's row
        if self._kernel:
            self._kernel.forget_bases()
        return n

    def field(self, q) -> np.ndarray:
        """World displacement of every vertex for modal coordinates ``q``
        (..., m): shape (..., N, 2) [m]."""
        return self.structure.nodal_displacement(np.asarray(q, float) @ self.Phi.T)

"""A structure's ports as material points: moving one along the structure
(a contact that follows a point), the deformed surface's tangent there, and
the material coordinate below a world point.  A mixin of
:class:`cosim.sides.fem.StructureSubsystem`, which holds the structure, the
mode shapes ``Phi``, the ports' shape rows ``_R`` and reference positions
``_ref``, and their coordinates."""
from __future__ import annotations

import numpy as np

__all__ = ["StructurePorts"]


class StructurePorts:
    """The port geometry of :class:`cosim.sides.fem.StructureSubsystem`."""

    def move_port(self, port: int, s: float) -> float:
        """Move a port to material coordinate ``s`` (clipped to the structure)
        and return the coordinate it took.

        The state is modal, so only the port's shape row changes; a contact
        that follows a moving point uses this between steps (and the
        monolithic reference at every evaluation)."""
        st = self.structure
        length = getattr(st, "length", None)
        s = float(s)
        if length is not None:
            s = min(max(s, 0.0), float(length))
        if s == self.port_coordinates[port]:
            return s
        dofs, w = st.point_operator(s)
        self._R[port] = w @ self.Phi[dofs]
        self._ref[port] = st.reference_position(s)
        self.port_coordinates[port] = s
        if any(e.port == port for e in self._embedded):
            self._bases = {}            # the springs' modes hang on the port's shape row
        if self._kernel:
            # the kernel keeps every port's row in each set's modes
            self._kernel.forget_bases()
        return s

    def surface_tangent(self, port: int, x) -> np.ndarray:
        """``dx/ds`` of the deformed structure at a port for state ``x``:
        ``e + w'(s) r`` (axis ``e``, deflection direction ``r``), (2,).
        Structures without a slope operator (a rod's axial field) give ``e``."""
        st = self.structure
        axis = np.asarray(st.axis, float)
        slope = getattr(st, "slope_operator", None)
        if slope is None:
            return axis
        dofs, w = slope(self.port_coordinates[port])
        return axis + float((w @ self.Phi[dofs]) @ x[:self.n_modes]) * self._dirs[port]

    def material_coordinate(self, point) -> float:
        """Material coordinate ``s`` of the structure below a world point."""
        return float((np.asarray(point, float) - self.structure.origin) @ self.structure.axis)

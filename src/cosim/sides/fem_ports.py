"""A structure's ports as material points: moving one along the structure
(a contact that follows a point), the deformed surface's tangent there, and
the material coordinate below a world point.  A mixin of
:class:`cosim.sides.fem.StructureSubsystem`, which holds the structure, the
mode shapes ``Phi``, the ports' shape rows ``_R`` and reference positions
``_ref``, and their coordinates."""
from __future__ import annotations

import numpy as np

from cosim.sides.kernel import compiled_module

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
        self.port_moved(port, s)
        return s

    def port_moved(self, port: int, s: float) -> None:
        """Take note that port ``port``'s shape row and reference position
        were moved to material coordinate ``s`` in place (by :meth:`move_port`,
        or by the compiled face of :meth:`follow_face`, which shares them)."""
        self.port_coordinates[port] = s
        if any(e.port == port for e in self._embedded):
            self._bases = {}            # the springs' modes hang on the port's shape row
        if self._kernel:
            # the kernel keeps every port's row in each set's modes
            self._kernel.forget_bases()

    def line_geometry(self):
        """``(node_coordinates, dof_map, hermite, Phi, origin, axis,
        port_coordinates)`` of a structure meshed along a line, whose ports
        can then follow a point in compiled code; None for another structure."""
        st = self.structure
        if not all(hasattr(st, a) for a in ("node_coordinates", "dof_map", "hermite", "length")):
            return None
        return (st.node_coordinates, st.dof_map, st.hermite, self.Phi, st.origin, st.axis,
                self.port_coordinates)

    def follow_face(self):
        """The compiled face (``cosim.sides._modal_face.ModalFace``) whose
        ``follow`` moves this structure's own ports in place: the shape rows
        and reference positions its compiled step reads.  After each move the
        caller calls :meth:`port_moved`.  None where the face is not built or
        the structure is not meshed along a line."""
        line = self.line_geometry()
        module = compiled_module("_modal_face") if line is not None else None
        if module is None:
            return None
        return module.ModalFace(self._R, self._ref, self._dir, self.omega, self.modal_damping,
                                self._g_modal, line, shared=True)

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

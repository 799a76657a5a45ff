"""The sides' compiled model-exchange faces (``Subsystem.compiled_face``):
what the monolithic reference's compiled right-hand side
(``cosim.core._stacked.StackedRHS``) calls instead of each side's Python
``derivatives`` and ``outputs``.  Each is None where the side's compiled
kernel is not built or not chosen (``COSIM_KERNEL=numpy``), or does not
cover the side (a user's own drive or integrator): the Python right-hand
side, the reference, then runs."""
from __future__ import annotations

from cosim.sides.kernel import compiled_module

__all__ = ["TreeFaceMixin", "ModalFaceMixin"]


class TreeFaceMixin:
    """``compiled_face`` of a :class:`cosim.sides.multibody.MultibodySubsystem`:
    the tree's kernel (``cosim.sides._multibody_step.TreeFace``)."""

    def compiled_face(self):
        kernel = self._compiled()
        if kernel is None or not self._kernel_steps:    # its joint effects are not loaded
            return None
        return kernel.face()


class ModalFaceMixin:
    """``compiled_face`` of a :class:`cosim.sides.fem.StructureSubsystem`
    (``cosim.sides._modal_face.ModalFace``), at its ports' present rows; a
    structure meshed along a line can move them under a point."""

    def compiled_face(self):
        module = compiled_module("_modal_face")
        if module is None:
            return None
        st = self.structure
        line = None
        if all(hasattr(st, a) for a in ("node_coordinates", "dof_map", "hermite", "length")):
            line = (st.node_coordinates, st.dof_map, st.hermite, self.Phi, st.origin, st.axis,
                    self.port_coordinates)
        return module.ModalFace(self._R, self._ref, self._dir, self.omega, self.modal_damping,
                                self._g_modal, line)

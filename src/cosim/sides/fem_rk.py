"""The compiled RK4 of a structure that hosts penalty contacts the closed form
does not take (:mod:`cosim.sides._structure_rk`), as
:class:`~cosim.sides.fem.StructureSubsystem` builds it."""
from __future__ import annotations

from cosim.core.links import kernel_law
from cosim.core.subsystem import StepInput
from cosim.sides.kernel import compiled_module

__all__ = ["build_structure_rk", "ContactRK"]

#: the interface of ``cosim.sides._structure_rk`` these sources call
RK_API = 1


def build_structure_rk(sub):
    """The compiled RK4 of structure subsystem ``sub`` (a
    ``cosim.sides._structure_rk.StructureRK``), or None where the numpy
    reference must step: not built or not chosen, built from other sources,
    no hosted contact, more than the kernel takes, or a law the kernels do
    not know (a user's) or a rigid one."""
    if not sub._embedded:
        return None
    module = compiled_module("_structure_rk")
    if module is None or getattr(module, "RK_API", None) != RK_API:
        return None
    contacts = []
    for e in sub._embedded:
        law = kernel_law(e.law)
        if law is None or law[0] == 3:
            return None
        contacts.append((e.port, e.side, e.normal, e.offset) + tuple(law))
    try:
        return module.StructureRK(sub.omega, sub.modal_damping, sub._R, sub._ref, sub._dirs,
                                  sub._g_modal, contacts)
    except ValueError:          # more hosted contacts than the kernel takes
        return None


class ContactRK:
    """The compiled RK4 of a structure subsystem with hosted contacts (a
    mixin of :class:`~cosim.sides.fem.StructureSubsystem`)."""

    #: the compiled RK4 (:func:`build_structure_rk`), built on the first step
    #: that asks for it; False where the reference steps
    _rk = None

    def _rk_built(self) -> bool:
        """Whether the compiled RK4 takes this side's contact phases."""
        if self._rk is None:
            self._rk = build_structure_rk(self) or False
        return bool(self._rk)

    def loop_kernel(self, inputs):
        """:meth:`LoopFace.loop_kernel`; where the closed form's kernel gives
        none, the compiled RK4, whose C face takes the steps that start with
        a hosted contact closed (and declines the others, which the side's
        own exact step takes), for a side stepped exactly between contacts."""
        kern = super().loop_kernel(inputs)
        if kern is not None or self._ts is not None or not self._face_faithful() \
                or not self._rk_built():
            return kern
        self._rk.configure_rk(self._rk4.max_step)
        return self._rk

    def _rk_step(self, t, h, inputs):
        """That compiled RK4 loaded with the step ``[t, t + h]`` under
        ``inputs`` and the partners' present motion, or None."""
        if not self._rk_built() or (inputs is not None and type(inputs) is not StepInput):
            return None
        try:
            self._rk.set_step(t, h, inputs, self._embedded)
        except ValueError:      # a load or a motion of a degree beyond the kernel's
            return None
        return self._rk

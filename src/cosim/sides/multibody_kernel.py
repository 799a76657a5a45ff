"""The contact laws and joint effects of a multibody side as the compiled
kernel ``cosim.sides._multibody_step`` takes them: plain tuples of kinds and
parameters, built once when the kernel is built, or None where the kernel
does not know the law or effect (the numpy reference then steps); and the
tree's compiled model-exchange face (:class:`TreeFaceMixin`)."""
from __future__ import annotations

from typing import TYPE_CHECKING

from cosim.core.links import kernel_law     # the numbering every kernel shares

if TYPE_CHECKING:
    from multibody import JointEffects

__all__ = ["kernel_law", "kernel_effects", "TreeFaceMixin"]


def kernel_effects(effects: JointEffects | None):
    """Joint effects as the compiled kernel takes them:
    ``(stiffness, rest, damping, drives)``, or None for no effects; raises
    ``TypeError`` for a drive or reference the kernel does not know."""
    if effects is None:
        return None
    # where a tree has effects, multibody.effects is loaded already (a scene built them)
    from multibody.effects import (ConstantTorque, MinimumJerk, PDTracking, Sinusoid, Table,
                                   TorqueTable)
    drives = []
    for d in effects.drives:
        ref_kind, ref_par, ts, vs = 0, (0.0,) * 4, (), ()
        if type(d) is ConstantTorque:
            kind, gains = 0, (d.torque, 0.0, 0.0)
        elif type(d) is TorqueTable:
            kind, gains, ts, vs = 1, (0.0,) * 3, d.torque.times, d.torque.values
        elif type(d) is PDTracking:
            kind, gains, r = 2, (d.kp, d.kd, d.max_torque), d.reference
            if type(r) is Table:
                ts, vs = r.times, r.values
            elif type(r) is MinimumJerk:
                ref_kind, ref_par = 1, (r.start, r.end, r.t_start, r.t_end)
            elif type(r) is Sinusoid:
                ref_kind, ref_par = 2, (r.amplitude, r.frequency, r.phase, r.offset)
            else:
                raise TypeError(f"reference {type(r).__name__}")
        else:
            raise TypeError(f"drive {type(d).__name__}")
        drives.append((d.joint, kind, gains, ref_kind, ref_par, ts, vs))
    return effects.stiffness, effects.rest, effects.damping, drives


class TreeFaceMixin:
    """``compiled_face`` of a :class:`cosim.sides.multibody.MultibodySubsystem`
    (:meth:`cosim.core.subsystem.Subsystem.compiled_face`): the tree's kernel
    (``cosim.sides._multibody_step.TreeFace``), or None where the kernel is
    not built or not chosen (``COSIM_KERNEL=numpy``) or does not step the
    side (a user's own drive or integrator: its joint effects are not
    loaded), or was built from older sources without a face."""

    def compiled_face(self):
        kernel = self._compiled()
        if kernel is None or not self._kernel_steps or not hasattr(kernel, "face"):
            return None
        return kernel.face()

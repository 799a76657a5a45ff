"""The contact laws and joint effects of a multibody side as the compiled
kernel ``cosim.sides._multibody_step`` takes them: plain tuples of kinds and
parameters, built once when the kernel is built, or None where the kernel
does not know the law or effect (the numpy reference then steps); and the
side's C face for a scheme that steps it from compiled code."""
from __future__ import annotations

from typing import TYPE_CHECKING

from couplers.laws import (FloresLaw, HertzLaw, HuntCrossleyLaw, KelvinVoigtLaw,
                           LankaraniNikraveshLaw, LinearLaw, RigidLaw)

from cosim.core.ode import RK4

if TYPE_CHECKING:
    from multibody import JointEffects

__all__ = ["kernel_law", "kernel_effects", "CompiledFace"]


def kernel_law(law):
    """``(kind, k, c_or_chi, exponent)`` of a penalty law for the compiled
    kernel (``cosim.sides._multibody_step``), or None for a law it does not know
    (a user's own law is stepped by the reference)."""
    kind = type(law)
    if kind is LinearLaw:
        return (0, law.contact_stiffness, 0.0, 1.0)
    if kind is KelvinVoigtLaw:
        return (1, law.contact_stiffness, law.contact_damping, 1.0)
    if kind in (HertzLaw, HuntCrossleyLaw, LankaraniNikraveshLaw, FloresLaw):
        return (2, law.contact_stiffness, law._chi(), law.exponent)
    if kind is RigidLaw:
        return (3, 0.0, 0.0, 1.0)
    return None


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


class CompiledFace:
    """:meth:`compiled_side` of :class:`cosim.sides.multibody.MultibodySubsystem`."""

    def compiled_side(self):
        """The compiled kernel, whose ``side_face()`` is its C face
        (:mod:`cosim.core._side_face`), for a scheme that steps this side from
        compiled code, or None where
        the kernel does not step it, where its integrator is not RK4, or where
        a contact is embedded here (its switches call back into Python).  The
        scheme records each such step with :meth:`took_compiled_step`."""
        kernel = self._compiled_step(None)
        integ = self.integrator
        if (kernel is None or self._embedded or type(integ) is not RK4
                or not hasattr(kernel, "configure_side")):     # built before the C face
            return None
        kernel.configure_side(integ.max_step, integ.free_step or 0.0)
        return kernel

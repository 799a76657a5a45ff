"""The contact laws as the compiled kernels take them: a kind and three
parameters, the numbering the kernels share (the multibody side's step,
``cosim.sides._multibody_step``, and the monolithic reference's right-hand
side, ``cosim.core._stacked``)."""
from __future__ import annotations

from couplers.laws import (FloresLaw, HertzLaw, HuntCrossleyLaw, KelvinVoigtLaw,
                           LankaraniNikraveshLaw, LinearLaw, RigidLaw)

__all__ = ["kernel_law"]


def kernel_law(law):
    """``(kind, k, c_or_chi, exponent)`` of a penalty law for the compiled
    kernels, or None for a law they do not know (a user's own law is
    evaluated by the reference)."""
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

"""How a contact is wired into a coupled system: the two ports it links,
where its law is evaluated (:data:`PLACEMENTS`), for a contact hosted by one
side against a moving partner the host's view of it, and its law as the
compiled kernels take it (:func:`kernel_law`)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, NamedTuple

from cosim.core.subsystem import EmbeddedContact

if TYPE_CHECKING:
    from couplers import Connection, PointContact

__all__ = ["ContactLink", "HostedContact", "PLACEMENTS", "kernel_law"]

#: Where a contact's penalty law is evaluated in a co-simulation.
PLACEMENTS = ("embedded", "coupler")


class HostedContact(NamedTuple):
    """A contact evaluated inside one side's integrator against a moving partner."""

    #: index of the subsystem whose integrator evaluates the contact
    host: int
    #: the contact's slot among the host's embedded contacts (its ``aux`` block)
    slot: int
    #: index of the partner subsystem, and its port
    partner: int
    partner_port: int
    #: the host's view of the contact (the partner's motion over the step)
    embedded: EmbeddedContact


@dataclass(frozen=True)
class ContactLink:
    """A contact between port ``port_a`` of subsystem ``sub_a`` (the point)
    and port ``port_b`` of subsystem ``sub_b`` (the surface).

    ``placement`` is ``"embedded"`` (evaluated inside one side's integrator:
    the moving side against a rigid partner, or the side ``host`` against the
    other side's port moving as the scheme extrapolates or interpolates it)
    or ``"coupler"`` (the coupling scheme exchanges the force).
    """

    contact: PointContact
    sub_a: int
    port_a: int
    sub_b: int
    port_b: int
    placement: str
    follow: bool = False
    host: int | None = None
    #: grasp and friction beyond the unilateral law (None: a plain contact)
    connection: Connection | None = None


def kernel_law(law):
    """``(kind, k, c_or_chi, exponent)`` of a penalty law for the compiled
    kernels (the multibody side's step, ``cosim.sides._multibody_step``, and
    the monolithic reference's right-hand side, ``cosim.core._stacked``,
    number the kinds alike), or None for a law they do not know (a user's
    own law is evaluated by the reference)."""
    from couplers.laws import (FloresLaw, HertzLaw, HuntCrossleyLaw, KelvinVoigtLaw,
                               LankaraniNikraveshLaw, LinearLaw, RigidLaw)
    kind = type(law)
    if kind is LinearLaw:
        return (0, law.contact_stiffness, 0.0, 1.0)
    if kind is KelvinVoigtLaw:
        return (1, law.contact_stiffness, law.contact_damping, 1.0)
    if kind in (HertzLaw, HuntCrossleyLaw, LankaraniNikraveshLaw, FloresLaw):
        return (2, law.contact_stiffness, law.hysteresis_chi(), law.exponent)
    if kind is RigidLaw:
        return (3, 0.0, 0.0, 1.0)
    return None

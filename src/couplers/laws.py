"""Penalty contact laws: the normal force as a function of penetration.

Every law maps the penetration ``d`` [m] (positive when the bodies overlap) and
its rate ``dd`` [m/s] to a normal force ``f >= 0`` [N].  It is never tensile.

Energy bookkeeping is the same for every law: the law's elastic part has the
potential ``V(d)`` (zero for ``d <= 0``), and whatever the force does beyond
the elastic part is dissipated at the rate ``P = (f - dV/dd) * dd >= 0``.
With this definition the ledger ``T + V + dissipated = const`` holds exactly,
including the clipped phase of a Kelvin-Voigt contact, where the force is
zero while ``d > 0`` and the spring's energy is lost as the surface recovers.

The power laws (:class:`HertzLaw`, :class:`HuntCrossleyLaw`,
:class:`LankaraniNikraveshLaw`, :class:`FloresLaw`) are one family,
``f = k d^n (1 + chi dd)`` clipped at zero, with ``V = k d^(n+1) / (n+1)``;
they differ in how the hysteresis damping ``chi`` [s/m] is given.  The
restitution of an impact at speed ``v0`` depends on ``chi v0`` alone
(:func:`couplers.restitution.hunt_crossley_restitution`).

Each law also offers, for event location, a continuous ``switch(d, dd)`` that
is positive exactly where the force is, and ``force_active(d, dd)``, the smooth
expression of the force on the active branch (used between located events).

The base class is in :mod:`couplers.law_base`, the linear laws in
:mod:`couplers.linear_laws`, the power laws in :mod:`couplers.power_laws`;
this module names them all and holds the registry :data:`CONTACT_LAWS`.
"""
from __future__ import annotations

from .law_base import ContactLaw
from .linear_laws import KelvinVoigtLaw, LinearLaw, RigidLaw
from .power_laws import FloresLaw, HertzLaw, HuntCrossleyLaw, LankaraniNikraveshLaw

__all__ = ["ContactLaw", "LinearLaw", "KelvinVoigtLaw", "RigidLaw", "HertzLaw", "HuntCrossleyLaw",
           "LankaraniNikraveshLaw", "FloresLaw", "CONTACT_LAWS", "get_contact_law"]


CONTACT_LAWS: dict[str, type[ContactLaw]] = {
    LinearLaw.name: LinearLaw,
    KelvinVoigtLaw.name: KelvinVoigtLaw,
    RigidLaw.name: RigidLaw,
    HertzLaw.name: HertzLaw,
    HuntCrossleyLaw.name: HuntCrossleyLaw,
    LankaraniNikraveshLaw.name: LankaraniNikraveshLaw,
    FloresLaw.name: FloresLaw,
}


def get_contact_law(law) -> type[ContactLaw]:
    """Resolve a law given by registry name or as a class."""
    if isinstance(law, type) and issubclass(law, ContactLaw):
        return law
    try:
        return CONTACT_LAWS[law]
    except (KeyError, TypeError):
        raise ValueError(
            f"unknown contact law {law!r}; valid laws are {sorted(CONTACT_LAWS)}") from None

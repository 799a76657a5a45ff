"""Contact geometry and penalty laws: pure functions of kinematics, no time stepping."""
from .contact import PointContact
from .laws import (CONTACT_LAWS, ContactLaw, FloresLaw, HertzLaw, HuntCrossleyLaw, KelvinVoigtLaw,
                   LankaraniNikraveshLaw, LinearLaw, RigidLaw, get_contact_law)

__all__ = ["PointContact", "CONTACT_LAWS", "ContactLaw", "KelvinVoigtLaw", "LinearLaw", "RigidLaw",
           "HertzLaw", "HuntCrossleyLaw", "LankaraniNikraveshLaw", "FloresLaw", "get_contact_law"]

"""Contact geometry and penalty laws: pure functions of kinematics, no time stepping."""
from .contact import PointContact
from .laws import CONTACT_LAWS, ContactLaw, KelvinVoigtLaw, LinearLaw, RigidLaw, get_contact_law

__all__ = ["PointContact", "CONTACT_LAWS", "ContactLaw", "KelvinVoigtLaw", "LinearLaw", "RigidLaw",
           "get_contact_law"]

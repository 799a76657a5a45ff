"""Contact geometry and penalty laws: pure functions of kinematics, no time stepping."""
from .connection import (MODES, Connection, Friction, Grasp, Trigger, connection_forces,
                         connection_potential, connection_power, connection_switch)
from .contact import PointContact
from .laws import (CONTACT_LAWS, ContactLaw, FloresLaw, HertzLaw, HuntCrossleyLaw, KelvinVoigtLaw,
                   LankaraniNikraveshLaw, LinearLaw, RigidLaw, get_contact_law)

__all__ = ["PointContact", "CONTACT_LAWS", "ContactLaw", "KelvinVoigtLaw", "LinearLaw", "RigidLaw",
           "HertzLaw", "HuntCrossleyLaw", "LankaraniNikraveshLaw", "FloresLaw", "get_contact_law",
           "Connection", "Grasp", "Friction", "Trigger", "MODES", "connection_forces",
           "connection_power", "connection_potential", "connection_switch"]

"""Contact geometry and penalty laws: pure functions of kinematics, no time stepping.

Grasp and friction connections (:mod:`couplers.connection`) are imported when
one of their names is first asked for (``from couplers import Grasp`` works as
before), so contacts without them do not pay for defining them.
"""
from .contact import PointContact
from .laws import (CONTACT_LAWS, ContactLaw, FloresLaw, HertzLaw, HuntCrossleyLaw, KelvinVoigtLaw,
                   LankaraniNikraveshLaw, LinearLaw, RigidLaw, get_contact_law)
from .modes import MODES

__all__ = ["PointContact", "CONTACT_LAWS", "ContactLaw", "KelvinVoigtLaw", "LinearLaw", "RigidLaw",
           "HertzLaw", "HuntCrossleyLaw", "LankaraniNikraveshLaw", "FloresLaw", "get_contact_law",
           "Connection", "Grasp", "Friction", "Trigger", "MODES", "connection_forces",
           "connection_power", "connection_potential", "connection_switch"]

#: public name -> the submodule that defines it, imported on first use
_LAZY = dict.fromkeys(("Connection", "Grasp", "Friction", "Trigger", "connection_forces",
                       "connection_power", "connection_potential", "connection_switch"),
                      "connection")


def __getattr__(name: str):
    if name not in _LAZY:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    # the import statement's machinery, which `python -X importtime` reports
    value = getattr(__import__(f"{__name__}.{_LAZY[name]}", fromlist=[name]), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(__all__))

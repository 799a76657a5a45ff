"""Planar tree-like multibody systems in joint coordinates.

Joint effects (:mod:`multibody.effects`) and rigid impacts
(:mod:`multibody.impact`) are imported when one of their names is first asked
for (``from multibody import JointSpring`` works as before), so a tree without
drives, springs, dampers or rigid contacts does not pay for defining them.
"""
from .tree import JOINT_KINDS, Body, Frames, Joint, PointKinematics, TreeModel

__all__ = ["Body", "Joint", "TreeModel", "Frames", "PointKinematics", "JOINT_KINDS",
           "JointEffects", "JointSpring", "JointDamper", "ConstantTorque", "TorqueTable",
           "PDTracking", "Table", "MinimumJerk", "Sinusoid", "TRAJECTORIES", "ImpactResult",
           "frictionless_impact", "frictional_impact", "kinetic_energy"]

#: public name -> the submodule that defines it, imported on first use
_LAZY = {**dict.fromkeys(("JointEffects", "JointSpring", "JointDamper", "ConstantTorque",
                          "TorqueTable", "PDTracking", "Table", "MinimumJerk", "Sinusoid",
                          "TRAJECTORIES"), "effects"),
         **dict.fromkeys(("ImpactResult", "frictionless_impact", "frictional_impact",
                          "kinetic_energy"), "impact")}


def __getattr__(name: str):
    if name not in _LAZY:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    # the import statement's machinery, which `python -X importtime` reports
    value = getattr(__import__(f"{__name__}.{_LAZY[name]}", fromlist=[name]), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(__all__))

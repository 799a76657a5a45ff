"""Planar tree-like multibody systems in joint coordinates."""
from .effects import (TRAJECTORIES, ConstantTorque, JointDamper, JointEffects, JointSpring,
                      MinimumJerk, PDTracking, Sinusoid, Table, TorqueTable)
from .impact import ImpactResult, frictional_impact, frictionless_impact, kinetic_energy
from .tree import JOINT_KINDS, Body, Frames, Joint, PointKinematics, TreeModel

__all__ = ["Body", "Joint", "TreeModel", "Frames", "PointKinematics", "JOINT_KINDS",
           "JointEffects", "JointSpring", "JointDamper", "ConstantTorque", "TorqueTable",
           "PDTracking", "Table", "MinimumJerk", "Sinusoid", "TRAJECTORIES", "ImpactResult",
           "frictionless_impact", "frictional_impact", "kinetic_energy"]

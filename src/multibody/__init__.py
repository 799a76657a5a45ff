"""Planar tree-like multibody systems in joint coordinates."""
from .tree import JOINT_KINDS, Body, Frames, Joint, PointKinematics, TreeModel

__all__ = ["Body", "Joint", "TreeModel", "Frames", "PointKinematics", "JOINT_KINDS"]

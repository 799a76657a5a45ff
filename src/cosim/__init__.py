"""cosim: co-simulation of impacts between robots and vibrating structures.

The orchestra: the subsystem protocol, the coupling schemes, the scene
loader, the recorder and the command line.  The only package that imports
``multibody``, ``fem`` and ``couplers``.
"""
from .errors import CouplingError, SimulationError, UnsafeStepError
from .integrators import INTEGRATORS, RK4, TimeStepper
from .result import SimulationResult, write_outputs
from .run import run_scene, simulate
from .scene import Scene, SceneError, load_scene
from .schemes import COUPLING_SCHEMES
from .subsystem import RigidReference, StepInput, Subsystem

__all__ = ["Subsystem", "RigidReference", "StepInput", "SimulationResult", "write_outputs",
           "simulate", "run_scene", "Scene", "SceneError", "load_scene", "COUPLING_SCHEMES",
           "CouplingError", "SimulationError", "UnsafeStepError", "INTEGRATORS", "RK4", "TimeStepper"]

"""cosim: co-simulation of impacts between robots and vibrating structures.

The orchestra: the subsystem protocol, the coupling schemes, the scene
loader, the recorder and the command line.  The only package that imports
``multibody``, ``fem`` and ``couplers``.

Importing this package defines nothing heavy: each public name, and each
submodule (``cosim.scene.run``, ``cosim.plot``, ...), is imported when it is first
asked for (``from cosim import simulate`` and ``cosim.load_scene`` work as
before), so ``cosim --help`` or ``cosim plot`` do not pay for the schemes and
``cosim run`` pays only for what its scene uses.
"""
#: the release, read by setuptools for the package metadata (pyproject.toml) and shown by
#: ``cosim --version``
__version__ = "0.13.0"

from cosim.errors import CouplingError, FMUError, SimulationError, UnsafeStepError

__all__ = ["Subsystem", "RigidReference", "StepInput", "SimulationResult", "write_outputs",
           "simulate", "run_scene", "Scene", "SceneError", "load_scene", "COUPLING_SCHEMES",
           "CouplingError", "FMUError", "SimulationError", "UnsafeStepError", "INTEGRATORS", "RK4",
           "TimeStepper"]

#: public name -> the submodule that defines it, imported on first use
_LAZY = {**dict.fromkeys(("INTEGRATORS", "RK4", "TimeStepper"), "core.ode"),
         **dict.fromkeys(("SimulationResult", "write_outputs"), "core.result"),
         **dict.fromkeys(("simulate", "run_scene"), "api"),
         **dict.fromkeys(("Scene", "SceneError", "load_scene"), "scene.load"),
         "COUPLING_SCHEMES": "core.schemes",
         **dict.fromkeys(("RigidReference", "StepInput", "Subsystem"), "core.subsystem")}


def __getattr__(name: str):
    if name in _LAZY:
        # the import statement's machinery, which `python -X importtime` reports
        value = getattr(__import__(f"{__name__}.{_LAZY[name]}", fromlist=[name]), name)
        globals()[name] = value
        return value
    if not name.startswith("__"):         # a submodule: ``cosim.scene.run``, ``cosim.plot``, ...
        try:
            return __import__(f"{__name__}.{name}", fromlist=["__name__"])
        except ModuleNotFoundError as exc:
            if exc.name != f"{__name__}.{name}":
                raise                     # the submodule exists but misses a dependency
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(__all__))

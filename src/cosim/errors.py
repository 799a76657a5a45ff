"""Errors of a run (the scene loader's SceneError lives in cosim.scene)."""

__all__ = ["SimulationError", "CouplingError", "UnsafeStepError", "OutputExistsError"]


class SimulationError(RuntimeError):
    """A run cannot go on; the message names the time and the cause."""


class CouplingError(SimulationError):
    """The coupling failed during a run (an implicit step did not converge)."""


class UnsafeStepError(ValueError):
    """The macro step is too large for a contact's stiffness."""


class OutputExistsError(FileExistsError):
    """The output directory already holds a run, and overwriting was not asked for."""

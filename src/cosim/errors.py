"""Errors of a run (the scene loader's SceneError lives in cosim.scene.checks)."""

__all__ = ["SimulationError", "CouplingError", "UnsafeStepError", "OutputExistsError",
           "OutputError", "OutputBusyError", "SignalStop"]


class SimulationError(RuntimeError):
    """A run cannot go on; the message names the time and the cause."""


class CouplingError(SimulationError):
    """The coupling failed during a run (an implicit step did not converge)."""


class UnsafeStepError(ValueError):
    """The macro step is too large for a contact's stiffness."""


class OutputExistsError(FileExistsError):
    """The output directory already holds a run, and overwriting was not asked for."""


class OutputError(OSError):
    """A run's folder or one of its files cannot be written (a full disk, a
    read-only place, a file where a folder should be); the message names the
    path and the reason."""


class OutputBusyError(OutputError):
    """Another run holds the lock on the output folder."""


class SignalStop(KeyboardInterrupt):
    """A signal other than SIGINT (SIGTERM, SIGHUP) stops a run as Ctrl-C does.

    ``cosim run`` installs handlers that raise it; a run stopped by it ends
    with status ``interrupted`` and a message naming the signal.

    Attributes
    ----------
    signum : int
    signal_name : str
        ``SIGTERM``, ``SIGHUP``.
    """

    def __init__(self, signum: int):
        import signal
        self.signum = int(signum)
        self.signal_name = signal.Signals(signum).name
        super().__init__(self.signal_name)

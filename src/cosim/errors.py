"""Errors of a run (the scene loader's SceneError lives in cosim.scene.checks)."""

__all__ = ["SimulationError", "CouplingError", "FMUError", "UnsafeStepError", "OutputExistsError",
           "shown", "OutputError", "OutputBusyError", "SignalStop", "PluginError",
           "KernelBuildError"]


class SimulationError(RuntimeError):
    """A run cannot go on; the message names the time and the cause."""


class CouplingError(SimulationError):
    """The coupling failed during a run (an implicit step did not converge)."""


class FMUError(SimulationError):
    """An FMU failed during a run: an FMI call returned an error, or the
    process that hosts the FMU crashed (a segfault, an abort).  The run ends
    ``failed`` with its data up to the last communication point, and its
    summary's ``fmu_failure`` holds what its ``details()`` returns.

    Attributes
    ----------
    fmu : str
        The FMU file's name.
    subsystem : str
    function : str or None
        The FMI function that failed or was running (``fmi2DoStep``), None
        when not known.
    status : str
        What happened: the FMI status returned (``fmi2Error``) or how the
        host process ended (``its host process was killed by signal SIGSEGV``).
    t : float
        Simulation time of the call [s] (the communication point a step
        started from).
    """

    def __init__(self, message: str, *, fmu: str, subsystem: str, function: str | None,
                 status: str, t: float):
        super().__init__(message)
        self.fmu, self.subsystem, self.function = fmu, subsystem, function
        self.status, self.t = status, float(t)

    def details(self) -> dict:
        """What ``summary.json`` records of the failure."""
        return {"subsystem": self.subsystem, "fmu": self.fmu, "function": self.function,
                "status": self.status, "time": self.t}


class UnsafeStepError(ValueError):
    """The macro step is too large for a contact's stiffness."""


class PluginError(ValueError):
    """An installed plug-in (a class a package declares under an entry point
    of cosim's) that cannot be used: it fails to import, is not a class of
    its group, or its name clashes; the message names the distribution and
    the entry point (:mod:`cosim.core.plugins`)."""


class KernelBuildError(RuntimeError):
    """A compiled kernel was built but cannot be loaded with the modules it
    was built against (a kernel rebuilt after a change of a shared ``.pxd``
    without its partners, or against another numpy): a broken build, which
    is never run past on the numpy reference; the message names the module,
    the cause and the command that rebuilds every kernel
    (:func:`cosim.sides.kernel.import_kernel`)."""


class OutputExistsError(FileExistsError):
    """The output directory already holds a run, and overwriting was not asked for.

    Its text says what to do in Python's terms (``out=``, ``overwrite=True``);
    :meth:`for_command_line` says it in the command line's (``--out``,
    ``--overwrite``), so neither reader meets the other's spelling.
    """

    def __init__(self, what: str, remedy: str = "", command_line_remedy: str = ""):
        super().__init__(what + (f"; {remedy}" if remedy else ""))
        self.what, self.command_line_remedy = what, command_line_remedy

    def for_command_line(self) -> str:
        """The message as `cosim run` prints it."""
        if not self.command_line_remedy:
            return str(self)
        return f"{self.what}; {self.command_line_remedy}"


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


#: longest text of an input's value that a message echoes [characters]
SHOWN_LIMIT = 200

#: control characters (ANSI escapes, carriage returns, line breaks, bidirectional
#: overrides) and how a message shows them: escaped, never raw
_ESCAPES = {c: f"\\x{c:02x}" for c in (*range(32), *range(127, 160))}
_ESCAPES.update({9: "\\t", 10: "\\n", 13: "\\r"})
_ESCAPES.update({c: f"\\u{c:04x}" for c in (0x2028, 0x2029, 0x200E, 0x200F,
                                            *range(0x202A, 0x202F), *range(0x2066, 0x206A))})


def shown(value, limit: int = SHOWN_LIMIT) -> str:
    """``value`` (text or anything else read from an input file) made safe to
    put in a message: control characters escaped (a line break shows as
    ``\\n``, so an input cannot start a line of its own or drive the
    terminal), and at most ``limit`` characters of it, the rest summarised by
    its length.

    Strings are shown as they are, not quoted; any other value by its
    ``repr``, which a huge container never builds in full.
    """
    if isinstance(value, str):
        text = value
    else:
        import reprlib
        r = reprlib.Repr()
        r.maxstring = r.maxother = max(limit, 16)
        r.maxlist = r.maxtuple = r.maxdict = r.maxset = 16
        r.maxlevel = 4
        text = r.repr(value)
    n = len(text)
    text = text[:limit].translate(_ESCAPES)
    if len(text) > limit:
        text = text[:limit]
    if n > limit:
        text += f"... ({n} characters)"
    return text

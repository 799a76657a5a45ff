"""The run guard's error, in a module of its own: the guard
(:mod:`cosim.core.guard`) and its check of many samples at once
(:mod:`cosim.core.guard_block`) both raise it, and neither imports the other
for it (``cosim.core.guard.GuardError`` is this class)."""
from __future__ import annotations

from cosim.errors import SimulationError

__all__ = ["GuardError"]


class GuardError(SimulationError):
    """The run guard stopped a run.

    Attributes
    ----------
    t : float
        Time of the step that tripped the guard [s].
    contact : str or None
        The contact named responsible (None when none is).
    cause : str
        ``"non-finite"``, ``"energy growth"`` or ``"chatter"``.
    reason : str
        What tripped the guard; the message is ``run stopped at t = T s:
        REASON``.  In a run ``t`` lies after the last sample kept (the guard refuses
        the sample it trips on, or trips at a switch inside the step before
        it); the run's message then opens with the time of that last sample
        (:func:`cosim.simulate`), which is the summary's ``t_end``.
    """

    #: the index of the refused sample in a block (:meth:`cosim.core.guard.Guard.check_block`), else None
    sample: int | None = None

    def __init__(self, reason: str, t: float, contact: str | None, cause: str):
        super().__init__(f"run stopped at t = {t:.6g} s: {reason}")
        self.t, self.contact, self.cause, self.reason = t, contact, cause, reason

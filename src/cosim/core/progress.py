"""How far a run is: :class:`Progress`, in a module of its own so that the
recorder (:mod:`cosim.core.recorder`) and its block path
(:mod:`cosim.core.recorder_block`) both hand it to a progress callback
without importing each other (``cosim.core.recorder.Progress`` is this class)."""
from __future__ import annotations

from typing import NamedTuple

__all__ = ["Progress"]


class Progress(NamedTuple):
    """How far a run is, as handed to a progress callback.

    Attributes
    ----------
    t : float
        Simulated time reached [s].
    t_end : float
        Simulated time the run ends at [s].
    contacts : int
        Contact intervals begun so far, all contacts together.
    elapsed_s : float
        Wall-clock time since recording began [s].
    """

    t: float
    t_end: float
    contacts: int
    elapsed_s: float

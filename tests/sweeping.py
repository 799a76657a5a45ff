"""Shared pieces of the sweep tests: a progress callback that keeps what it
is told, and the processes a finished ``cosim`` left behind."""
from __future__ import annotations

import os
import time


class Events:
    """A progress callback that keeps what it is told."""

    def __init__(self):
        self.events = []

    def __call__(self, ev):
        self.events.append(ev)

    @property
    def ran(self):
        return sorted(e.point.name for e in self.events if not e.skipped)

    @property
    def skipped(self):
        return sorted(e.point.name for e in self.events if e.skipped)

    @property
    def notes(self):
        return {e.point.name: e.note for e in self.events if e.note}


def leftovers(session: int) -> list:
    """Processes still alive in the session of a finished ``cosim``."""
    import psutil
    time.sleep(0.5)
    out = []
    for p in psutil.process_iter(["pid", "status"]):
        try:
            if os.getsid(p.pid) == session and p.info["status"] != psutil.STATUS_ZOMBIE:
                out.append(p)
        except (ProcessLookupError, PermissionError, psutil.NoSuchProcess):
            pass
    return out

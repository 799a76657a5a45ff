"""How a run stops on a signal: SIGTERM and SIGHUP end it as Ctrl-C does,
with its outputs written up to then, and the exit status says which signal."""
from __future__ import annotations

__all__ = ["STOP_SIGNALS"]


#: signals that stop a run as Ctrl-C does (a scheduler's stop, `timeout`, a closed terminal)
STOP_SIGNALS = ("SIGTERM", "SIGHUP")


class _StopOnSignals:
    """While in effect, SIGTERM and SIGHUP raise :class:`cosim.errors.SignalStop`
    (a KeyboardInterrupt) once, as SIGINT raises KeyboardInterrupt: the run
    writes its outputs up to then.  Repeats of them are ignored meanwhile, so
    that the outputs are written whole; the previous handlers come back on
    exit."""

    def __enter__(self):
        import signal
        self._old = {}
        for name in STOP_SIGNALS:
            num = getattr(signal, name, None)
            if num is not None:
                try:
                    self._old[num] = signal.signal(num, self._handler)
                except ValueError:                   # not the main thread: leave them be
                    break
        return self

    def _handler(self, signum, frame):
        import signal
        from cosim.errors import SignalStop
        for num in self._old:
            signal.signal(num, signal.SIG_IGN)       # once; the run is stopping
        raise SignalStop(signum)

    def __exit__(self, *exc):
        import signal
        for num, old in self._old.items():
            signal.signal(num, old)


def _stop_code(exc: BaseException) -> int:
    """Exit status of a run stopped by ``exc``: 128 + the signal (130 for Ctrl-C)."""
    return 128 + getattr(exc, "signum", 2)

"""What `cosim` shows on the terminal besides its messages: the run's
progress line, and streams that escape control characters so that nothing
read from a scene file can drive the terminal."""
from __future__ import annotations

import sys

__all__ = ["PROGRESS_DELAY_S"]


#: wall-clock time a run goes on before its progress line appears [s]
PROGRESS_DELAY_S = 1.0


class _ProgressLine:
    """Renders :class:`cosim.core.recorder.Progress` on one carriage-return line of
    ``stream``: done fraction, simulated time, rate (simulated seconds per
    wall second), contact intervals begun, and the time left.  Nothing shows
    for a run shorter than :data:`PROGRESS_DELAY_S`; :meth:`close` wipes the
    line so the summary starts clean."""

    def __init__(self, stream):
        self.stream = stream
        self._width = 0

    def __call__(self, p) -> None:
        if p.elapsed_s < PROGRESS_DELAY_S:
            return
        rate = p.t / p.elapsed_s if p.elapsed_s > 0 else 0.0
        frac = min(max(p.t / p.t_end, 0.0), 1.0) if p.t_end > 0 else 1.0
        left = f"~{(p.t_end - p.t) / rate:.0f} s left" if rate > 0 else "time left unknown"
        line = (f"{100 * frac:3.0f}% [{'#' * int(20 * frac):<20}] t {p.t:.4g}/{p.t_end:.4g} s, "
                f"{rate:.3g} s/s, contacts {p.contacts}, {left}")
        self.stream.write("\r" + line.ljust(self._width))
        self.stream.flush()
        self._width = len(line)

    def close(self) -> None:
        if self._width:
            self.stream.write("\r" + " " * self._width + "\r")
            self.stream.flush()


class _FrameProgress:
    """An animation's progress, ``progress(done, total)`` frames: a tqdm bar
    on stderr as a sweep shows its points, else a carriage-return line."""

    def __init__(self, stream):
        self.stream, self._bar, self._shown = stream, None, False

    def __call__(self, done: int, total: int) -> None:
        if self._bar is None and not self._shown:
            try:
                from tqdm import tqdm
                self._bar = tqdm(total=total, unit="frame", desc="animation", file=self.stream)
            except ImportError:
                pass
        self._shown = True
        if self._bar is not None:
            self._bar.update(done - self._bar.n)
        else:
            self.stream.write(f"\ranimation: {done}/{total} frames")
            self.stream.flush()

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()
        elif self._shown:
            self.stream.write("\n")
            self.stream.flush()


def _frame_progress(quiet: bool):
    """An animation's progress renderer, or None when quiet or not talking to
    a terminal."""
    if quiet or not _on_terminal():
        return None
    return _FrameProgress(_raw(sys.stderr))


def _on_terminal() -> bool:
    return sys.stdout.isatty() and sys.stderr.isatty()


def _progress_line(quiet: bool):
    """A progress renderer, or None when quiet or not talking to a terminal."""
    if quiet or not _on_terminal():
        return None
    return _ProgressLine(_raw(sys.stderr))


#: control characters (ANSI escapes, carriage returns, bidirectional overrides) and
#: how the terminal is shown them: escaped, never raw
_CONTROL = {c: f"\\x{c:02x}" for c in (*range(32), *range(127, 160)) if c not in (9, 10)}
_CONTROL.update({c: f"\\u{c:04x}" for c in (0x200E, 0x200F, *range(0x202A, 0x202F),
                                            *range(0x2066, 0x206A))})


class _Printable:
    """A text stream that shows control characters escaped (``\\x1b``), so no
    name, path or message from a scene file can drive the terminal.  ``raw``
    is the stream itself, for the progress line's own carriage returns."""

    def __init__(self, stream):
        self.raw = stream

    def write(self, text: str) -> int:
        return self.raw.write(text.translate(_CONTROL))

    def __getattr__(self, name):
        return getattr(self.raw, name)


def _raw(stream):
    return getattr(stream, "raw", stream) if isinstance(stream, _Printable) else stream


def _quiet_pipes() -> None:
    """After a reader closed our pipe: point stdout and stderr at the null
    device, so that nothing else (not even the interpreter's flush at exit)
    fails on it."""
    import os
    devnull = os.open(os.devnull, os.O_WRONLY)
    for stream in (sys.__stdout__, sys.__stderr__):
        try:
            os.dup2(devnull, stream.fileno())
        except (OSError, ValueError, AttributeError):
            pass
    os.close(devnull)

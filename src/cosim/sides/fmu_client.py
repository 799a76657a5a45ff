"""The parent's side of an FMU's host process (:mod:`cosim.sides.fmu_host`).

:class:`FMUHost` starts the child, sends it requests and reads its replies.
It waits for a reply in slices of :data:`POLL_S`, so that Ctrl-C and SIGTERM
(whose handlers raise a ``KeyboardInterrupt`` in this, the main, thread)
stop the wait at once; the child is then ended (SIGTERM, then SIGKILL after
:data:`KILL_AFTER_S`) and the interrupt goes on.  A child that dies (a
segfault, an abort, an exit) or an FMI call that returns an error raises
:class:`cosim.errors.FMUError`, naming the FMU, the subsystem, the FMI
function, how it failed and the simulation time.
"""
from __future__ import annotations

import json
import os
import select
import signal
import struct
import subprocess
import sys

from cosim.sides import fmu_host as proto

__all__ = ["FMUHost", "POLL_S", "KILL_AFTER_S"]

#: how long the parent waits on the pipe before it looks again [s]
POLL_S = 0.1
#: how long a child asked to stop (SIGTERM) has before it is killed (SIGKILL) [s]
KILL_AFTER_S = 0.5
#: how long ``close`` waits for the FMU to terminate [s]
CLOSE_WAIT_S = 5.0
#: starts the host by its file path, without the current folder on ``sys.path``
_BOOT = ("import sys, runpy; del sys.path[0], sys.argv[0]; "
         "runpy.run_path(sys.argv[0], run_name='__main__')")


def _ended(code: int) -> str:
    """How a child process ended, from its return code."""
    if code < 0:
        try:
            return f"was killed by signal {signal.Signals(-code).name}"
        except ValueError:
            return f"was killed by signal {-code}"
    return f"exited with status {code}"


class FMUHost:
    """An FMU instance in a child process.

    Parameters
    ----------
    fmu : str
        The FMU file's name, for messages.
    subsystem : str
        The subsystem's name, for messages.
    fmi_version : 2 or 3
    n_forces, n_outputs : int
        How many input forces each step sets and outputs it reads.
    interpolates_inputs : bool
        Whether each step sends the forces' first two time derivatives too.

    Attributes
    ----------
    cpu_time : float
        The child's CPU time so far [s], as of its last reply.
    """

    def __init__(self, fmu: str, subsystem: str, fmi_version: int, n_forces: int,
                 n_outputs: int, interpolates_inputs: bool):
        import mmap
        import tempfile
        self.fmu, self.subsystem, self.version = fmu, subsystem, fmi_version
        self.n_forces, self.n_outputs = n_forces, n_outputs
        self.interpolates = interpolates_inputs
        self.cpu_time = 0.0
        self._frees: list[int] = []
        self._busy = False
        self.proc = None
        cell = tempfile.TemporaryFile()
        try:
            cell.write(bytes([proto.IDLE]))
            cell.flush()
            self._cell = mmap.mmap(cell.fileno(), 1)
            request_r, self._request_w = os.pipe()
            self._reply_r, reply_w = os.pipe()
            try:
                self.proc = subprocess.Popen(
                    [sys.executable, "-c", _BOOT, proto.__file__, str(request_r), str(reply_w),
                     str(cell.fileno()), str(os.getpid())],
                    pass_fds=(request_r, reply_w, cell.fileno()), stdin=subprocess.DEVNULL,
                    stdout=sys.__stderr__.fileno() if sys.__stderr__ else subprocess.DEVNULL,
                    process_group=0)        # Ctrl-C on a terminal is this process's to handle
            finally:
                os.close(request_r)
                os.close(reply_w)
        finally:
            cell.close()

    # ------------------------------------------------------------- requests
    def start(self, config: dict) -> bytes:
        """Load, instantiate and initialise the FMU; its outputs (float64 bytes)."""
        return self._request(proto.OP_INIT, json.dumps(config).encode("utf-8"), 0.0)

    def step(self, t: float, h: float, u0, du, ddu):
        """Set the forces (and their derivatives), take the step, read the
        outputs: one round trip.  Returns the outputs, float64 bytes."""
        parts = [struct.pack("<dd", t, h)]
        if self.n_forces:
            parts.append(u0.tobytes())
            if self.interpolates:
                parts += [du.tobytes(), ddu.tobytes()]
        return self._request(proto.OP_STEP, b"".join(parts), t)

    def get(self, vrs, t: float) -> bytes:
        """The values of variables ``vrs`` (float64 bytes)."""
        return self._request(proto.OP_GET, struct.pack(f"<{len(vrs)}I", *vrs), t)

    def get_state(self, t: float) -> int:
        """Save the FMU's state in the child; its handle."""
        return struct.unpack("<Q", self._request(proto.OP_GET_STATE, b"", t))[0]

    def set_state(self, handle: int, t: float) -> None:
        self._request(proto.OP_SET_STATE, struct.pack("<Q", handle), t)

    def free_state(self, handle: int) -> None:
        """Free a saved state (no reply awaited; sent before the next request
        when one is under way, e.g. from a finalizer)."""
        if not self.alive:
            return
        self._frees.append(handle)
        if not self._busy:
            self._send_frees()

    @property
    def alive(self) -> bool:
        return self.proc is not None and self.proc.returncode is None

    def close(self) -> None:
        """Terminate and free the FMU, and end the child; a child that does
        not answer within :data:`CLOSE_WAIT_S` is killed.  Never raises."""
        if self.proc is None:
            return
        if self.alive and not self._busy:
            try:
                self._send_frees()
                proto.write_message(self._request_w, proto.OP_CLOSE)
                ready, _, _ = select.select([self._reply_r], [], [], CLOSE_WAIT_S)
                if ready:
                    self.proc.wait(CLOSE_WAIT_S)
            except (OSError, subprocess.TimeoutExpired, ValueError):
                pass
        self._stop()

    # ------------------------------------------------------------ machinery
    def _send_frees(self) -> None:
        while self._frees:
            handle = self._frees.pop()
            try:
                proto.write_message(self._request_w, proto.OP_FREE_STATE, struct.pack("<Q", handle))
            except OSError:
                return

    def _request(self, code: int, payload: bytes, t: float) -> bytes:
        from cosim.errors import FMUError
        if not self.alive:
            raise FMUError(f"subsystem `{self.subsystem}`: FMU {self.fmu} was called at "
                           f"t = {t:.6g} s after its host process ended", fmu=self.fmu,
                           subsystem=self.subsystem, function=None,
                           status="host process ended", t=t)
        self._send_frees()
        self._busy = True
        done = False
        try:
            try:
                proto.write_message(self._request_w, code, payload)
            except BrokenPipeError:
                raise self._crashed(t) from None
            reply, body = self._read(t)
            done = True
        finally:
            self._busy = False
            if not done:                      # interrupted, crashed: the child cannot go on
                self._stop()
        if reply == proto.REPLY_OK:
            self.cpu_time = struct.unpack_from("<d", body)[0]
            return body[8:]
        raise self._refused(reply, body, t)

    def _read(self, t: float) -> tuple[int, bytes]:
        head = self._read_exact(proto.HEADER.size, t)
        reply, size = proto.HEADER.unpack(head)
        if size > proto.MAX_PAYLOAD:
            raise self._crashed(t, f"host process sent a reply of {size} bytes")
        return reply, self._read_exact(size, t) if size else b""

    def _read_exact(self, n: int, t: float) -> bytes:
        chunks = []
        while n > 0:
            ready, _, _ = select.select([self._reply_r], [], [], POLL_S)
            if not ready:
                if self.proc.poll() is not None:
                    raise self._crashed(t)
                continue
            chunk = os.read(self._reply_r, n)
            if not chunk:
                raise self._crashed(t)
            chunks.append(chunk)
            n -= len(chunk)
        return b"".join(chunks)

    def _call_name(self, index: int) -> str | None:
        names = proto.CALLS[self.version]
        return names[index] if 0 <= index < len(names) else None

    def _crashed(self, t: float, why: str | None = None):
        """The error of a child that died (or broke the protocol) during a request."""
        from cosim.errors import FMUError
        call = self._call_name(self._cell[0])
        if why is None:
            try:
                code = self.proc.wait(2.0)
            except subprocess.TimeoutExpired:        # closed its pipe but lives on
                self._stop()
                code = self.proc.returncode
            why = f"host process {_ended(code)}"
        self._stop()
        where = f"in {call}" if call else "between FMI calls"
        return FMUError(f"subsystem `{self.subsystem}`: FMU {self.fmu} crashed {where} at "
                        f"t = {t:.6g} s (its {why})", fmu=self.fmu, subsystem=self.subsystem,
                        function=call, status=why, t=t)

    def _refused(self, reply: int, body: bytes, t: float):
        """The error of a request the child answered with a failure."""
        from cosim.errors import FMUError, shown
        if reply == proto.REPLY_FMI_FAILED and len(body) == 5:
            index, status = struct.unpack("<Bi", body)
            call = self._call_name(index)
            what = proto.status_name(self.version, status)
            text = f"{call} returned {what}"
        elif reply == proto.REPLY_STOPPED and len(body) == 9:
            last, terminate = struct.unpack("<dB", body)
            call = self._call_name(proto.DO_STEP)
            what = "terminated" if terminate else "returned early"
            text = (f"{call} {what} inside the step (reached t = {last:.6g} s, "
                    f"terminate = {bool(terminate)})")
        else:
            call = self._call_name(body[0]) if body else None
            what = shown(body[1:].decode("utf-8", "replace"), limit=300)
            text = f"{call or 'the host'} failed: {what}"
        return FMUError(f"subsystem `{self.subsystem}`: FMU {self.fmu}: {text} at "
                        f"t = {t:.6g} s", fmu=self.fmu, subsystem=self.subsystem,
                        function=call, status=what, t=t)

    def _stop(self) -> None:
        """End the child (SIGTERM, SIGKILL if it lingers) and close the pipes."""
        proc = self.proc
        if proc is not None and proc.returncode is None:
            try:
                proc.terminate()
                proc.wait(KILL_AFTER_S)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        for fd in ("_request_w", "_reply_r"):
            num = getattr(self, fd, None)
            if isinstance(num, int) and num >= 0:
                try:
                    os.close(num)
                except OSError:
                    pass
                setattr(self, fd, -1)

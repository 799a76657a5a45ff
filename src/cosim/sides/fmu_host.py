"""The host process of an FMU: it loads the FMU's shared library with FMPy and
answers the requests of :class:`cosim.sides.fmu_client.FMUHost` over a pipe.

An FMU is native code from a supplier.  Run inside cosim, a segfault or an
abort in ``doStep`` would end cosim with it and a ``doStep`` that never
returns would hold it past Ctrl-C.  In a process of its own its crash or hang
is its own failure: cosim sees the pipe close (or no answer), ends the child,
names the FMI function that was running and keeps the run's data.

This file is the child's program and the protocol both sides share.  It
imports nothing of cosim (only the standard library, and FMPy in the
child), so that the parent can start it by its file path: the child runs
the very file the parent has loaded, whatever ``sys.path`` holds, and does
not pay for importing cosim.  It is started with ``subprocess`` (a fresh
interpreter, ``sys.executable``) rather than ``multiprocessing``: a spawned
``multiprocessing`` child re-imports the parent's ``__main__`` (a user's
script) and pickles what passes through its pipes, while this host needs
neither; and ``subprocess`` reports how the child ended (the signal of a
crash) directly.

Protocol
--------
Every message is ``<BI`` (a one-byte code, the payload's length in bytes)
then the payload.  A request's code is one of the ``OP_*`` below; a reply's
code is one of the ``REPLY_*``.  Numbers travel as little-endian float64 and
uint32/uint64 arrays; the only text is the parent's start-up configuration
(JSON, parent to child) and the child's description of an exception that is
not an FMI call's (``REPLY_FAILED``), which the parent shows escaped.
Nothing is unpickled.  One macro step is one round trip: ``OP_STEP`` sets
the inputs (and their derivatives), calls ``doStep`` and returns the
outputs.  Every ``REPLY_OK`` payload begins with the child's CPU time so far
[s].  ``OP_FREE_STATE`` has no reply.

Before each FMI call the child writes the call's index (:data:`CALLS`) into a
byte of memory shared with the parent, so that the parent can name the call
a crash happened in.
"""
from __future__ import annotations

import json
import os
import struct
import sys

#: request codes (parent to child)
OP_INIT, OP_STEP, OP_GET, OP_GET_STATE, OP_SET_STATE, OP_FREE_STATE, OP_CLOSE = range(1, 8)
#: reply codes (child to parent)
REPLY_OK, REPLY_FMI_FAILED, REPLY_STOPPED, REPLY_FAILED = range(4)
#: the header of every message: code, payload length
HEADER = struct.Struct("<BI")
#: the largest payload either side accepts [bytes]
MAX_PAYLOAD = 1 << 26

#: the FMI calls the host makes, by index; each name has ``{v}`` for the
#: version's prefix where FMI 2.0 and 3.0 differ only in it
LOAD, INSTANTIATE, SETUP, SET_REAL, ENTER_INIT, EXIT_INIT, SET_DERIVATIVES, DO_STEP, \
    GET_REAL, GET_STATE, SET_STATE, FREE_STATE, TERMINATE, FREE_INSTANCE = range(14)
CALLS = {
    2: ("loading its shared library", "fmi2Instantiate", "fmi2SetupExperiment", "fmi2SetReal",
        "fmi2EnterInitializationMode", "fmi2ExitInitializationMode",
        "fmi2SetRealInputDerivatives", "fmi2DoStep", "fmi2GetReal", "fmi2GetFMUstate",
        "fmi2SetFMUstate", "fmi2FreeFMUstate", "fmi2Terminate", "fmi2FreeInstance"),
    3: ("loading its shared library", "fmi3InstantiateCoSimulation", "(no call)",
        "fmi3SetFloat64", "fmi3EnterInitializationMode", "fmi3ExitInitializationMode",
        "(no call)", "fmi3DoStep", "fmi3GetFloat64", "fmi3GetFMUState", "fmi3SetFMUState",
        "fmi3FreeFMUState", "fmi3Terminate", "fmi3FreeInstance"),
}
#: the byte of the shared cell when no FMI call is running
IDLE = 255
#: FMI status codes, by value (the same in FMI 2.0 and 3.0)
STATUS = ("OK", "Warning", "Discard", "Error", "Fatal", "Pending")


def status_name(version: int, status: int) -> str:
    """``fmi2Error``, ``fmi3Discard``, ... for a status code."""
    if 0 <= status < len(STATUS):
        return f"fmi{version}{STATUS[status]}"
    return f"status {status} (not an FMI status)"


def read_exact(fd: int, n: int) -> bytes | None:
    """``n`` bytes from ``fd`` (blocking), or None at end of file."""
    chunks = []
    while n > 0:
        chunk = os.read(fd, n)
        if not chunk:
            return None
        chunks.append(chunk)
        n -= len(chunk)
    return b"".join(chunks)


def write_message(fd: int, code: int, payload: bytes = b"") -> None:
    """One message, in one write (a finalizer cannot slip its own into it)."""
    data = HEADER.pack(code, len(payload)) + payload
    view = memoryview(data)
    while view:
        view = view[os.write(fd, view):]


# ------------------------------------------------------------------ the child
class _Host:
    """The FMU instance and the states it saved, in the child."""

    def __init__(self, reply_fd: int, cell):
        self.reply_fd, self.cell = reply_fd, cell
        self.fmu = None
        self.states: dict[int, object] = {}
        self.next_state = 1

    def call(self, index: int) -> None:
        self.cell[0] = index

    # -------------------------------------------------------------- requests
    def init(self, payload: bytes) -> bytes:
        import ctypes
        cfg = json.loads(payload.decode("utf-8"))
        self.version = cfg["fmi_version"]
        self.call(LOAD)
        if self.version == 3:
            from fmpy.fmi3 import FMU3Slave as cls
        else:
            from fmpy.fmi2 import FMU2Slave as cls
        fmu = cls(guid=cfg["token"], unzipDirectory=cfg["unzipped"],
                  modelIdentifier=cfg["model_identifier"], instanceName=cfg["instance"],
                  libraryPath=cfg["library"])
        self.call(INSTANTIATE)
        fmu.instantiate()
        self.fmu = fmu
        if self.version == 2:
            self.call(SETUP)
            fmu.setupExperiment(startTime=0.0)
        vrs, values = cfg["parameter_vrs"], [float(v) for v in cfg["parameter_values"]]
        if vrs:
            self.call(SET_REAL)
            (fmu.setFloat64 if self.version == 3 else fmu.setReal)(vrs, values)
        self.call(ENTER_INIT)
        if self.version == 3:
            fmu.enterInitializationMode(startTime=0.0)
        else:
            fmu.enterInitializationMode()
        self.call(EXIT_INIT)
        fmu.exitInitializationMode()
        # the arrays of the hot path, made once
        vr_t = ctypes.c_uint32
        self.out_vr = (vr_t * len(cfg["output_vrs"]))(*cfg["output_vrs"])
        self.out = (ctypes.c_double * len(self.out_vr))()
        self.force_vr = (vr_t * len(cfg["force_vrs"]))(*cfg["force_vrs"])
        n = len(self.force_vr)
        self.n_force = n
        self.force = (ctypes.c_double * n)()
        self.interpolates = bool(cfg["interpolates_inputs"])
        self.orders = [(ctypes.c_int * n)(*([k] * n)) for k in (1, 2)]
        self.derivative = (ctypes.c_double * n)()
        if self.version == 3:
            self._set = lambda vr, n, v: fmu.fmi3SetFloat64(fmu.component, vr, n, v, n)
            self._get = lambda vr, n, v: fmu.fmi3GetFloat64(fmu.component, vr, n, v, n)
        else:
            self._set = lambda vr, n, v: fmu.fmi2SetReal(fmu.component, vr, n, v)
            self._get = lambda vr, n, v: fmu.fmi2GetReal(fmu.component, vr, n, v)
        return self.outputs()

    def outputs(self) -> bytes:
        if len(self.out_vr):
            self.call(GET_REAL)
            self._get(self.out_vr, len(self.out_vr), self.out)
        return bytes(self.out)

    def step(self, payload: bytes) -> tuple[int, bytes]:
        import ctypes
        n = self.n_force
        t, h = struct.unpack_from("<dd", payload)
        if n:
            ctypes.memmove(self.force, payload[16:16 + 8 * n], 8 * n)
            self.call(SET_REAL)
            self._set(self.force_vr, n, self.force)
            if self.interpolates:
                self.call(SET_DERIVATIVES)
                for k in (1, 2):
                    off = 16 + 8 * n * k
                    ctypes.memmove(self.derivative, payload[off:off + 8 * n], 8 * n)
                    self.fmu.fmi2SetRealInputDerivatives(self.fmu.component, self.force_vr, n,
                                                         self.orders[k - 1], self.derivative)
        self.call(DO_STEP)
        if self.version == 3:
            _, terminate, early, last = self.fmu.doStep(currentCommunicationPoint=t,
                                                        communicationStepSize=h)
            if terminate or early:
                return REPLY_STOPPED, struct.pack("<dB", last, bool(terminate))
        else:
            self.fmu.doStep(currentCommunicationPoint=t, communicationStepSize=h)
        return REPLY_OK, self.outputs()

    def get(self, payload: bytes) -> bytes:
        import ctypes
        n = len(payload) // 4
        vr = (ctypes.c_uint32 * n).from_buffer_copy(payload)
        values = (ctypes.c_double * n)()
        self.call(GET_REAL)
        self._get(vr, n, values)
        return bytes(values)

    def get_state(self) -> bytes:
        self.call(GET_STATE)
        state = self.fmu.getFMUState()
        key, self.next_state = self.next_state, self.next_state + 1
        self.states[key] = state
        return struct.pack("<Q", key)

    def set_state(self, payload: bytes) -> bytes:
        (key,) = struct.unpack("<Q", payload)
        self.call(SET_STATE)
        self.fmu.setFMUState(self.states[key])
        return b""

    def free_state(self, payload: bytes) -> None:
        (key,) = struct.unpack("<Q", payload)
        state = self.states.pop(key, None)
        if state is not None:
            self.call(FREE_STATE)
            try:
                self.fmu.freeFMUState(state)
            except Exception:             # noqa: BLE001 - nobody waits for this answer
                pass
            self.call(IDLE)

    def close(self) -> bytes:
        if self.fmu is not None:
            fmu, self.fmu = self.fmu, None
            self.call(TERMINATE)
            fmu.terminate()
            self.call(FREE_INSTANCE)
            fmu.freeInstance()
        return b""

    # ------------------------------------------------------------------ loop
    def serve(self, request_fd: int) -> None:
        import time
        handlers = {OP_INIT: self.init, OP_GET: self.get, OP_SET_STATE: self.set_state}
        while True:
            head = read_exact(request_fd, HEADER.size)
            if head is None:
                return                              # the parent is gone
            code, size = HEADER.unpack(head)
            if size > MAX_PAYLOAD:
                return
            payload = read_exact(request_fd, size) if size else b""
            if payload is None:
                return
            if code == OP_FREE_STATE:
                self.free_state(payload)
                continue
            try:
                if code == OP_STEP:
                    reply, body = self.step(payload)
                elif code == OP_GET_STATE:
                    reply, body = REPLY_OK, self.get_state()
                elif code == OP_CLOSE:
                    reply, body = REPLY_OK, self.close()
                else:
                    reply, body = REPLY_OK, handlers[code](payload)
            except Exception as exc:                # noqa: BLE001 - each goes to the parent
                reply, body = _failure(exc, self.cell[0])
            self.call(IDLE)
            if reply == REPLY_OK:
                body = struct.pack("<d", time.process_time()) + body
            write_message(self.reply_fd, reply, body)
            if code == OP_CLOSE:
                return


def _failure(exc: Exception, call: int) -> tuple[int, bytes]:
    """The reply to a request that raised ``exc`` while call ``call`` ran."""
    status = getattr(exc, "status", None)
    if type(exc).__name__ == "FMICallException" and isinstance(status, int):
        return REPLY_FMI_FAILED, struct.pack("<Bi", call, status)
    text = f"{type(exc).__name__}: {exc}"
    return REPLY_FAILED, struct.pack("<B", call) + text[:2000].encode("utf-8", "replace")


def _watch_parent(parent: int) -> None:
    """End this process when its parent is gone, even while an FMI call
    hangs (ctypes releases the interpreter lock during a foreign call)."""
    import threading
    import time

    def watch():
        while os.getppid() == parent:
            time.sleep(0.5)
        os._exit(3)

    threading.Thread(target=watch, daemon=True).start()


def main(argv) -> None:
    """The child: ``argv`` holds the request pipe's read end, the reply
    pipe's write end, the shared cell's file descriptor and the parent's pid."""
    import mmap
    import signal
    signal.signal(signal.SIGINT, signal.SIG_IGN)          # the parent decides when to stop
    request_fd, reply_fd, cell_fd, parent = (int(a) for a in argv[:4])
    _watch_parent(parent)
    cell = mmap.mmap(cell_fd, 1)
    os.close(cell_fd)
    _Host(reply_fd, cell).serve(request_fd)
    # leave without running FMPy's or the FMU's exit handlers twice
    sys.stdout.flush()
    os._exit(0)


if __name__ == "__main__":
    main(sys.argv[1:])

"""The address a sweep is given with ``--scheduler``, checked before Dask
sees it: the whole handshake (name lookup, connect, TLS, a first exchange in
Dask's framing, the start of the sweep's client) is bounded by
:data:`CONNECT_TIMEOUT_S`, every read is bounded in size, and what does not
answer as a Dask scheduler (a silent port, an HTTP or TLS server) is refused
by what it answered like (a :class:`SweepError`).  A scheduler that speaks
Dask is trusted to run the points.
"""
from __future__ import annotations

import socket
import struct
import threading
import time

from cosim.errors import shown

__all__ = ["SweepError", "CONNECT_TIMEOUT_S"]


class SweepError(ValueError):
    """A sweep that cannot start: a scheduler address that is malformed or
    cannot be reached.  Nothing has run, nothing is written."""


#: seconds ``--scheduler ADDRESS`` may take in all to connect, to greet and be
#: greeted as a Dask scheduler, and to start the sweep's client
CONNECT_TIMEOUT_S = 10.0

#: the most bytes a scheduler's greeting may announce (Dask's is under 100)
_GREETING_LIMIT = 1 << 16


def _scheduler_endpoint(address: str) -> tuple[str, str, int]:
    """``(scheme, host, port)`` of a scheduler address, as Dask reads it (a
    bare ``HOST:PORT`` is ``tcp``); a :class:`SweepError` for anything but a
    ``tcp://`` or ``tls://`` address with a port."""
    from distributed.comm.addressing import parse_address, parse_host_port

    try:
        scheme, loc = parse_address(address)
        if scheme not in ("tcp", "tls"):
            raise ValueError(f"the scheme {scheme}:// is not one a sweep can reach")
        host, port = parse_host_port(loc)
        if not (host and 0 < port < 65536):
            raise ValueError("a host and a port from 1 to 65535 are needed")
    except (ValueError, TypeError) as exc:
        raise SweepError(f"`--scheduler` must be `local` or a Dask scheduler's address "
                         f"(tcp://HOST:PORT or tls://HOST:PORT), got '{shown(address)}': "
                         f"{shown(str(exc))}") from None
    return scheme, host, port


def _greeting() -> bytes:
    """The first message a Dask client sends a scheduler it has connected to
    (its comm options), in Dask's framing: the byte count of what follows,
    the number of frames and the byte count of each (unsigned 64-bit
    integers in the machine's order, as Dask writes them), then the frames;
    here one frame, a msgpack map.  The map ends in an entry Dask ignores
    whose text is a blank line, so that a server of a line-based protocol
    (HTTP above all) has a whole request to answer instead of waiting for
    the rest of a line."""
    import pickle
    import sys

    import msgpack

    body = msgpack.dumps({"compression": None, "python": list(sys.version_info[:3]),
                          "pickle-protocol": pickle.HIGHEST_PROTOCOL,
                          "cosim-probe": "\r\n\r\n"}, use_bin_type=True)
    return struct.pack("QQQ", 16 + len(body), 1, len(body)) + body


def _not_dask(first: bytes) -> str:
    """What a peer that does not speak Dask answered like, from its first bytes."""
    if first.startswith(b"HTTP/"):
        status_line = first.split(b"\r\n")[0][:60]
        return f"it answered like an HTTP server ({status_line!r})"
    if first.lstrip().lower().startswith((b"<!doctype html", b"<html")):
        return "it answered like an HTTP server (an HTML page)"
    if first[:1] == b"\x15" and first[1:2] == b"\x03":
        return "it answered like a TLS server (give its tls:// address)"
    return f"its first bytes {first[:32]!r} are not a Dask message"


def _probe_scheduler(address: str, timeout: float = CONNECT_TIMEOUT_S) -> None:
    """Check that a Dask scheduler answers at ``address`` before Dask's client
    is given it, within ``timeout`` seconds in all.

    The check connects, sends the greeting a Dask client sends, and reads
    the scheduler's greeting with bounded reads: a Dask scheduler greets each
    connection at once, in Dask's framing (see :func:`_greeting`).  Dask's
    own client reads the first eight bytes as a byte count and waits for
    that many, without a limit in time or size, so a port that accepts and
    never answers would hold it forever and an HTTP server's answer
    (``HTTP/1.1`` read as a count) would make it allocate exabytes.

    Raises
    ------
    SweepError
        If the address is malformed, cannot be reached, gives no answer in
        time, or answers in anything but a Dask greeting.  Nothing is sent
        past the greeting.
    """
    scheme, host, port = _scheduler_endpoint(address)
    deadline = time.monotonic() + timeout
    where = f"`--scheduler` '{shown(address)}'"

    def left() -> float:
        remaining = deadline - time.monotonic()
        if remaining <= 0:
            raise socket.timeout
        return remaining

    def recv_exactly(sock, n: int) -> bytes:
        data = bytearray()
        while len(data) < n:
            sock.settimeout(left())
            chunk = sock.recv(min(n - len(data), 1 << 16))
            if not chunk:
                break
            data += chunk
        return bytes(data)

    try:
        sock = _connect(host, port, left)
    except socket.timeout:
        raise SweepError(f"{where} cannot be reached: no connection within "
                         f"{timeout:g} s") from None
    except OSError as exc:
        raise SweepError(f"{where} cannot be reached: {exc}") from None
    try:
        if scheme == "tls":
            sock = _tls_wrap(sock, host, left(), where)
        sock.settimeout(left())
        sock.sendall(_greeting())
        head = recv_exactly(sock, 8)
        if not head:
            raise SweepError(f"{where} is not a Dask scheduler: it closed the connection "
                             f"without a greeting")
        if len(head) < 8:
            raise SweepError(f"{where} is not a Dask scheduler: {_not_dask(head)}")
        (size,) = struct.unpack("Q", head)
        if not 16 <= size <= _GREETING_LIMIT:
            raise SweepError(f"{where} is not a Dask scheduler: "
                             f"{_not_dask(head + _peek(sock))}")
        body = recv_exactly(sock, size)
    except socket.timeout:
        raise SweepError(f"{where}: no answer within {timeout:g} s (a Dask scheduler "
                         f"greets a client at once)") from None
    except ConnectionResetError:
        raise SweepError(f"{where} is not a Dask scheduler: it reset the connection when "
                         f"greeted" + (" (a TLS server does: is it a tls:// address?)"
                                       if scheme == "tcp" else "")) from None
    except OSError as exc:
        raise SweepError(f"{where} cannot be reached: {exc}") from None
    finally:
        sock.close()
    problem = _greeting_problem(body, size)
    if problem:
        raise SweepError(f"{where} is not a Dask scheduler: {problem}")


def _connect(host: str, port: int, left):
    """A TCP socket connected to ``host:port`` within the time ``left()``
    gives, the name lookup included (the resolver's own time limits can add
    up to far more): ``socket.timeout`` past it."""
    box: dict = {}

    def lookup():
        try:
            box["found"] = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)
        except OSError as exc:
            box["error"] = exc

    thread = threading.Thread(target=lookup, name="cosim-dask-lookup", daemon=True)
    thread.start()
    thread.join(left())
    if thread.is_alive():
        raise socket.timeout
    if "error" in box:
        raise box["error"]
    error: OSError = OSError(f"no address found for {shown(host)}")
    for family, kind, proto, _, sockaddr in box["found"]:
        sock = socket.socket(family, kind, proto)
        try:
            sock.settimeout(left())
            sock.connect(sockaddr)
            return sock
        except socket.timeout:
            sock.close()
            raise
        except OSError as exc:
            sock.close()
            error = exc
    raise error


def _peek(sock) -> bytes:
    """Up to 56 more bytes that have already come, to show what answered."""
    try:
        sock.settimeout(0.2)
        return sock.recv(56)
    except OSError:
        return b""


def _greeting_problem(body: bytes, size: int) -> str | None:
    """What is wrong with a greeting announced as ``size`` bytes: too short,
    frame counts that do not add up, or a first frame that is not a msgpack
    map; ``None`` for a well-formed greeting."""
    import msgpack

    if len(body) < size:
        return f"its greeting announced {size} bytes and closed after {len(body)}"
    (nframes,) = struct.unpack_from("Q", body)
    if not 1 <= nframes <= 64 or 8 * (1 + nframes) > size:
        return f"its greeting announced {nframes} frames in {size} bytes"
    lengths = struct.unpack_from(f"{nframes}Q", body, 8)
    start = 8 * (1 + nframes)
    if start + sum(lengths) != size:
        return "the frame lengths of its greeting do not add up"
    try:
        first = msgpack.loads(body[start:start + lengths[0]], raw=False)
    except Exception:                               # noqa: BLE001 - any malformed msgpack
        first = None
    if not isinstance(first, dict):
        return "its greeting is not a msgpack map"
    return None


def _tls_wrap(sock, host: str, timeout: float, where: str):
    """``sock`` after a TLS handshake with the client certificate of Dask's
    ``distributed.comm.tls.*`` configuration, within ``timeout`` seconds."""
    import ssl

    from distributed.security import Security

    ctx = Security().get_connection_args("client").get("ssl_context")
    if ctx is None:
        sock.close()
        raise SweepError(f"{where}: a tls:// scheduler needs the cluster's certificates in "
                         f"Dask's distributed.comm.tls.* configuration, and none is set")
    sock.settimeout(timeout)
    try:
        return ctx.wrap_socket(sock, server_hostname=host if ctx.check_hostname else None)
    except ssl.SSLError as exc:
        sock.close()
        raise SweepError(f"{where}: the TLS handshake failed: {exc}") from None


def _connect_client(address: str, timeout: float):
    """Dask's ``Client`` of a scheduler that :func:`_probe_scheduler` found,
    given ``timeout`` seconds to start.  Dask bounds each of its steps but
    one, the greeting of each connection, so the client is started in a
    thread of its own and given up on (a :class:`SweepError`) when it has
    not started in time; if it starts later, it is closed at once."""
    from distributed import Client

    lock = threading.Lock()
    box: dict = {}

    def start():
        try:
            client = Client(address, timeout=CONNECT_TIMEOUT_S)
        except Exception as exc:                     # noqa: BLE001 - reported below
            box["error"] = exc
            return
        with lock:
            if box.get("abandoned"):
                client.close()
            else:
                box["client"] = client

    thread = threading.Thread(target=start, name="cosim-dask-connect", daemon=True)
    thread.start()
    interrupted = True
    try:
        thread.join(timeout)
        interrupted = False
    finally:                                    # given up, or Ctrl-C: no client is kept
        with lock:
            client = box.pop("client", None)
            box["abandoned"] = True
        if interrupted and client is not None:
            client.close()
    if client is not None:
        return client
    where = f"`--scheduler` '{shown(address)}'"
    exc = box.get("error")
    if exc is None:
        raise SweepError(f"{where}: the Dask client did not start within {timeout:g} s")
    if isinstance(exc, OSError):
        raise SweepError(f"{where} cannot be reached: {shown(str(exc))}")
    raise SweepError(f"{where}: the Dask client could not start: "
                     f"{type(exc).__name__}: {shown(str(exc))}")

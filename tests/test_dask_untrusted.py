"""A sweep's Dask side meets what it cannot trust: an address where no Dask
scheduler answers, and a local cluster whose workers must be stoppable.

- ``--scheduler ADDRESS`` at a port that accepts and never answers, or at an
  HTTP server, or at anything that answers in another framing, ends within
  the connection's time limit with a message that names the address and
  what was wrong (exit 2, nothing written); a real scheduler is accepted.
- ``--scheduler local`` without the ``cryptography`` package (its workers
  would be threads, which cannot be stopped) refuses ``--timeout``; with it,
  a point past the time limit has its worker process stopped, so the next
  point runs on a fresh one.
- the local cluster's scratch space is removed at the end, also after Ctrl-C:
  nothing is left in ``$TMPDIR``.
"""
import csv
import http.server
import os
import signal
import socket
import socketserver
import struct
import subprocess
import sys
import threading
import time

import pytest

from conftest import CASES, ROOT
from sweeping import leftovers

pytest.importorskip("dask")
pytest.importorskip("distributed")
psutil = pytest.importorskip("psutil")

from cosim.studies.sweep import backends, scheduler  # noqa: E402 - after the skips
from cosim.studies.sweep.backends import CONNECT_TIMEOUT_S, SweepError  # noqa: E402

SPRING_DROP = CASES / "spring_drop.toml"
#: what a test waits for a `cosim sweep` at most [s]; the product's bound is 10 s
LIMIT = 60


def cosim(*args, env=None):
    return subprocess.run([sys.executable, "-m", "cosim.cli", *map(str, args)],
                          capture_output=True, text=True, cwd=ROOT, timeout=LIMIT, env=env)


def with_tmpdir(tmp):
    """The inherited environment with ``TMPDIR`` set to ``tmp``."""
    tmp.mkdir(exist_ok=True)
    return {**os.environ, "TMPDIR": str(tmp)}


# ------------------------------------------------------------ listeners
@pytest.fixture
def silent_listener():
    """A port on 127.0.0.1 that accepts connections and never writes."""
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(8)
    held = []

    def accept():
        while True:
            try:
                held.append(server.accept()[0])
            except OSError:
                return
    threading.Thread(target=accept, daemon=True).start()
    yield server.getsockname()[1]
    server.close()
    for conn in held:
        conn.close()


class _Quiet(http.server.SimpleHTTPRequestHandler):
    def log_message(self, *args):
        pass


class _Http10(_Quiet):
    default_request_version = "HTTP/1.0"        # a status line even for a bad request


@pytest.fixture(params=[_Quiet, _Http10], ids=["bare-html", "status-line"])
def http_listener(request, tmp_path):
    """An HTTP server on 127.0.0.1, in a thread: Python's own, which answers a
    request it cannot parse with a bare HTML page, and one that answers
    with a status line first, as most servers do."""
    handler = request.param
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    server.daemon_threads = True
    threading.Thread(target=server.serve_forever, daemon=True).start()
    yield server.server_port
    server.shutdown()
    server.server_close()


def replying_listener(replies):
    """A port whose ``k``-th connection gets ``replies[k]`` (bytes; None to
    say nothing and hold the connection until the end; "reset" to reset it)
    once it has received anything; the last reply is repeated."""
    held = []

    class Handler(socketserver.BaseRequestHandler):
        count = 0

        def handle(self):
            k = min(Handler.count, len(replies) - 1)
            Handler.count += 1
            self.request.settimeout(5)
            try:
                self.request.recv(4096)
            except OSError:
                return
            if replies[k] is None:
                held.append(self.request)
                time.sleep(LIMIT)
                return
            if replies[k] == "reset":              # close with a RST
                self.request.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER,
                                        struct.pack("ii", 1, 0))
                self.request.close()               # now, before the server's FIN
                return
            self.request.sendall(replies[k])

    server = socketserver.ThreadingTCPServer(("127.0.0.1", 0), Handler)
    server.daemon_threads = True
    threading.Thread(target=server.serve_forever, daemon=True).start()
    return server, held


def close(server, held):
    server.shutdown()
    server.server_close()
    for conn in held:
        try:
            conn.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass


# ------------------------------------------------------------ --scheduler ADDRESS
def test_a_port_that_never_answers_is_refused_in_time(tmp_path, silent_listener):
    address = f"tcp://127.0.0.1:{silent_listener}"
    out = tmp_path / "sw"
    t0 = time.monotonic()
    proc = cosim("sweep", SPRING_DROP, "--set", "t_end=0.001", "--scheduler", address,
                 "--no-plot", "--out", out)
    took = time.monotonic() - t0
    assert proc.returncode == 2, proc.stderr
    assert (f"error: `--scheduler` '{address}': no answer within {CONNECT_TIMEOUT_S:g} s"
            in proc.stderr), proc.stderr
    assert "Traceback" not in proc.stderr
    assert took >= CONNECT_TIMEOUT_S                 # it waited its time, then gave up
    assert not out.exists()


def test_an_http_server_is_not_a_dask_scheduler(tmp_path, http_listener):
    address = f"tcp://127.0.0.1:{http_listener}"
    out = tmp_path / "sw"
    proc = cosim("sweep", SPRING_DROP, "--set", "t_end=0.001", "--scheduler", address,
                 "--no-plot", "--out", out)
    assert proc.returncode == 2, proc.stderr
    assert (f"error: `--scheduler` '{address}' is not a Dask scheduler: it answered like "
            f"an HTTP server" in proc.stderr), proc.stderr
    assert "Traceback" not in proc.stderr and "MemoryError" not in proc.stderr
    assert not out.exists()


def _frame(*frames: bytes, size=None) -> bytes:
    """Bytes in Dask's framing (see ``scheduler._greeting``)."""
    lengths = [len(f) for f in frames]
    body = struct.pack(f"Q{len(frames)}Q", len(frames), *lengths) + b"".join(frames)
    return struct.pack("Q", len(body) if size is None else size) + body


@pytest.mark.parametrize("reply,essence", [
    (b"", "is not a Dask scheduler: it closed the connection without a greeting"),
    ("reset", "is not a Dask scheduler: it reset the connection when greeted (a TLS server "
              "does: is it a tls:// address?)"),
    (b"HTTP/1.1 400 Bad Request\r\n\r\n",
     "is not a Dask scheduler: it answered like an HTTP server (b'HTTP/1.1 400 Bad Request')"),
    (b"SSH-2.0-OpenSSH_9.6\r\n", "is not a Dask scheduler: its first bytes b'SSH-2.0-"),
    (b"\x15\x03\x03\x00\x02\x02\x46", "is not a Dask scheduler: it answered like a TLS server"),
    (b"\xff" * 8, "is not a Dask scheduler: its first bytes b'\\xff"),
    (struct.pack("Q", 100) + b"\x00" * 10,
     "is not a Dask scheduler: its greeting announced 100 bytes and closed after 10"),
    (_frame(b"\x83\xa1a\x01", size=999999999),
     "is not a Dask scheduler: its first bytes"),
    (struct.pack("QQQ", 16, 1, 500), "the frame lengths of its greeting do not add up"),
    (struct.pack("QQQ", 16, 10**6, 0), "its greeting announced 1000000 frames in 16 bytes"),
    (_frame(b"\x93\x01\x02\x03"), "is not a Dask scheduler: its greeting is not a msgpack map"),
    (_frame(b"\xc1"), "is not a Dask scheduler: its greeting is not a msgpack map"),
])
def test_what_does_not_greet_as_dask_is_named(reply, essence):
    """Each way of not being a Dask scheduler, with the probe's bounded reads:
    no frame length is trusted beyond a greeting's size."""
    server, held = replying_listener([reply])
    address = f"tcp://127.0.0.1:{server.server_address[1]}"
    try:
        with pytest.raises(SweepError) as exc:
            scheduler._probe_scheduler(address, 10.0)
    finally:
        close(server, held)
    assert str(exc.value).startswith(f"`--scheduler` '{address}'")
    assert essence in str(exc.value), str(exc.value)


@pytest.mark.parametrize("address", ["tcp://127.0.0.1", "inproc://127.0.0.1:5",
                                     "tcp://127.0.0.1:0", "tcp://:8786"])
def test_an_address_the_sweep_cannot_reach_is_malformed(address):
    with pytest.raises(SweepError, match=r"^`--scheduler` must be `local` or a Dask "
                                         r"scheduler's address"):
        scheduler._probe_scheduler(address, 10.0)


def scratch(tmp_path) -> dict:
    """A test's own cluster keeps its scratch space in the test's folder."""
    return {"local_directory": str(tmp_path),
            "scheduler_kwargs": {"local_directory": str(tmp_path)}}


def test_a_dask_scheduler_passes_the_probe(tmp_path):
    """A real scheduler greets the probe as the sweep's client expects (the
    sweeps on one in ``test_sweep.py`` run through it too)."""
    from distributed import LocalCluster

    with LocalCluster(n_workers=0, processes=False, protocol="tcp://", host="127.0.0.1",
                      dashboard_address=None, **scratch(tmp_path)) as cluster:
        scheduler._probe_scheduler(cluster.scheduler_address, 10.0)


def test_a_client_that_cannot_start_is_given_up_in_time(monkeypatch):
    """A port that greets the probe as Dask does, then never answers Dask's
    own client: the client's start is bounded too (Dask leaves its greeting
    read unbounded)."""
    monkeypatch.setattr(backends, "CONNECT_TIMEOUT_S", 3.0)
    server, held = replying_listener([scheduler._greeting(), None])
    address = f"tcp://127.0.0.1:{server.server_address[1]}"
    t0 = time.monotonic()
    try:
        with pytest.raises(SweepError, match=r"the Dask client did not start within"):
            with backends._Runner(1, address):
                pass
    finally:
        took = time.monotonic() - t0
        close(server, held)
    assert took < 3.0 + 5.0


# ------------------------------------------------------------ --scheduler local
def test_without_cryptography_a_local_timeout_is_refused(tmp_path):
    """Without ``cryptography`` the local cluster's workers are threads, which
    no time limit can stop: `--timeout` is refused before anything runs."""
    hide = tmp_path / "hide" / "cryptography"
    hide.mkdir(parents=True)
    (hide / "__init__.py").write_text('raise ImportError("hidden by the test")\n')
    env = with_tmpdir(tmp_path / "tmp")
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(hide.parent),
                                                    os.environ.get("PYTHONPATH")) if p)
    out = tmp_path / "sw"
    proc = cosim("sweep", SPRING_DROP, "--set", "t_end=0.001", "--scheduler", "local",
                 "--timeout", "5", "--no-plot", "--out", out, env=env)
    assert proc.returncode == 2, proc.stderr
    assert ("error: `--timeout` with `--scheduler local` needs the local cluster's workers "
            "to be processes, which needs the `cryptography` package "
            '(pip install "cosim[dask]")' in proc.stderr), proc.stderr
    assert "Traceback" not in proc.stderr
    assert not out.exists()
    assert list((tmp_path / "tmp").iterdir()) == []


def test_the_dask_extra_brings_cryptography():
    """The extra that `--scheduler` asks for installs what the local cluster
    needs to run processes."""
    import tomllib
    extras = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"][
        "optional-dependencies"]
    for extra in ("dask", "test"):
        assert any(req.startswith("cryptography") for req in extras[extra]), extra


def test_a_point_past_the_limit_has_its_worker_stopped(tmp_path):
    """One worker: the point that runs past `--timeout` comes first, the short
    one after it.  The short one can only run if the first one's worker was
    stopped (a thread would hold the only worker for hours), and the
    cluster's scratch space is gone at the end."""
    pytest.importorskip("cryptography")
    tmp = tmp_path / "tmp"
    out = tmp_path / "sw"
    proc = subprocess.Popen(
        [sys.executable, "-m", "cosim.cli", "sweep", str(SPRING_DROP), "--set",
         "t_end=1000,0.001", "--scheduler", "local", "--workers", "1", "--timeout", "5",
         "--no-plot", "--quiet", "--out", str(out)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT,
        env=with_tmpdir(tmp), start_new_session=True)
    try:
        _, stderr = proc.communicate(timeout=LIMIT + 60)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 1, stderr
    with open(out / "sweep.csv", newline="") as fh:
        rows = {r["point"]: r for r in csv.DictReader(fh)}
    assert rows["undamped,t_end=1000"]["status"] == "timeout"
    assert rows["undamped,t_end=1000"]["message"] == (
        "ran past the time limit of 5 s (wall clock); its task was cancelled and its "
        "worker restarted")
    assert rows["undamped,t_end=0.001"]["status"] == "finished"
    assert leftovers(proc.pid) == []
    assert list(tmp.iterdir()) == []


def test_ctrl_c_removes_the_scratch_space(tmp_path):
    """Ctrl-C while the local cluster runs a point: the sweep ends as
    interrupted, and its scratch space goes with it."""
    tmp = tmp_path / "tmp"
    proc = subprocess.Popen(
        [sys.executable, "-m", "cosim.cli", "sweep", str(SPRING_DROP), "--set", "t_end=1000",
         "--scheduler", "local", "--workers", "1", "--no-plot", "--quiet",
         "--out", str(tmp_path / "sw")],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT,
        env=with_tmpdir(tmp), start_new_session=True)
    try:
        end = time.monotonic() + LIMIT
        while not list(tmp.rglob("worker-*")):
            assert proc.poll() is None, proc.communicate()
            assert time.monotonic() < end, "the local cluster did not start"
            time.sleep(0.2)
        time.sleep(1.0)                      # the point is sent to the worker
        proc.send_signal(signal.SIGINT)
        _, stderr = proc.communicate(timeout=LIMIT)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 130, stderr
    assert leftovers(proc.pid) == []
    assert list(tmp.iterdir()) == []


def test_a_tls_scheduler_is_probed_with_the_configured_certificate(tmp_path):
    """Over tls://, the probe's TLS handshake uses Dask's configured
    certificate: without one it says what is missing, with the cluster's it
    reads the greeting."""
    pytest.importorskip("cryptography")
    import dask
    from distributed import LocalCluster
    from distributed.security import Security

    security = Security.temporary()
    with LocalCluster(n_workers=0, processes=False, protocol="tls://", host="127.0.0.1",
                      security=security, dashboard_address=None,
                      **scratch(tmp_path / "scratch")) as cluster:
        address = cluster.scheduler_address
        with pytest.raises(SweepError, match=r"a tls:// scheduler needs the cluster's "
                                             r"certificates in Dask's distributed\.comm\.tls"):
            scheduler._probe_scheduler(address, 10.0)
        files = {}
        for key, pem in (("ca-file", security.tls_ca_file),
                         ("client.cert", security.tls_client_cert),
                         ("client.key", security.tls_client_key)):
            files[f"distributed.comm.tls.{key}"] = str(tmp_path / key)
            (tmp_path / key).write_text(pem)
        with dask.config.set(files):
            scheduler._probe_scheduler(address, 10.0)


def test_an_echoed_address_is_escaped_and_capped():
    """The address is echoed in every message: its control characters are
    escaped and a long one is cut, so it can neither fake a line of output
    nor flood the terminal."""
    address = "tcp://x\nerror: all clear" + "a" * 100_000
    with pytest.raises(SweepError) as exc:
        scheduler._probe_scheduler(address, 10.0)
    text = str(exc.value)
    assert "\n" not in text and "x\\nerror: all clear" in text
    assert len(text) < 1000, len(text)

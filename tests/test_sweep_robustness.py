"""A sweep on a shared machine: a point that hangs, a worker process that dies,
a scheduler's SIGTERM, a bad or unreachable scheduler, a bad study file.

Each case runs ``cosim sweep`` as a user types it, in a fresh process with a
time limit of its own (a regression fails, it does not hang the suite), and
checks the exit status, the message, the table and the point folders, and
that no worker process is left behind.  The long point is spring_drop run to
1000 s (hours of work): it only ever ends by the limit, a kill or a signal.
"""
import csv
import signal
import subprocess
import sys
import time

import psutil
import pytest

from conftest import CASES, ROOT
from sweeping import leftovers

SPRING_DROP = CASES / "spring_drop.toml"
#: what the sweep of the tests waits for at most [s]
LIMIT = 120


def cosim(*args, cwd=ROOT):
    return subprocess.run([sys.executable, "-m", "cosim.cli", *map(str, args)],
                          capture_output=True, text=True, cwd=cwd, timeout=LIMIT)


def start(*args):
    """``cosim`` in a session of its own, so that any process it leaves
    behind is found by :func:`leftovers` (orphans keep their session)."""
    return subprocess.Popen([sys.executable, "-m", "cosim.cli", *map(str, args)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            cwd=ROOT, start_new_session=True)


def table(out):
    with open(out / "sweep.csv", newline="") as fh:
        return {r["point"]: r for r in csv.DictReader(fh)}


def pool_workers(pid):
    """The sweep's worker processes (started by multiprocessing's spawn)."""
    try:
        kids = psutil.Process(pid).children(recursive=True)
    except psutil.NoSuchProcess:
        return []
    out = []
    for k in kids:
        try:
            if any("spawn_main" in part for part in k.cmdline()):
                out.append(k)
        except psutil.NoSuchProcess:
            pass
    return out


def busy_worker(proc, cpu_s=2.5):
    """Wait until one worker has run ``cpu_s`` of CPU past its start-up (it is
    deep in the long point) and return it."""
    end = time.monotonic() + LIMIT / 2
    while time.monotonic() < end:
        assert proc.poll() is None, proc.communicate()
        for w in pool_workers(proc.pid):
            try:
                if w.cpu_times().user > cpu_s:
                    return w
            except psutil.NoSuchProcess:
                pass
        time.sleep(0.2)
    proc.kill()
    raise AssertionError("no worker got busy")


def gone(p: psutil.Process) -> bool:
    try:
        return not p.is_running() or p.status() == psutil.STATUS_ZOMBIE
    except psutil.NoSuchProcess:
        return True


def test_a_hanging_point_ends_at_the_time_limit_and_the_others_finish(tmp_path):
    out = tmp_path / "sw"
    t0 = time.monotonic()
    proc = start("sweep", SPRING_DROP, "--set", "t_end=0.001,1000", "--workers", "2",
                 "--timeout", "10", "--no-plot", "--quiet", "--out", out)
    stdout, stderr = proc.communicate(timeout=LIMIT)
    assert time.monotonic() - t0 < LIMIT
    assert proc.returncode == 1, stderr
    assert leftovers(proc.pid) == []
    rows = table(out)
    short, long = rows["undamped,t_end=0.001"], rows["undamped,t_end=1000"]
    assert short["status"] == "finished"
    assert long["status"] == "timeout"
    assert long["message"] == ("ran past the time limit of 10 s (wall clock); its process "
                               "was stopped")
    assert "undamped,t_end=1000                      timeout" in stdout
    # the timed-out point has its record, no outputs
    assert (out / "undamped,t_end=1000" / "point.json").exists()
    assert not (out / "undamped,t_end=1000" / "summary.json").exists()
    assert (out / "undamped,t_end=0.001" / "summary.json").exists()


def test_a_worker_that_dies_costs_its_point_alone(tmp_path):
    out = tmp_path / "sw"
    proc = start("sweep", SPRING_DROP, "--set", "t_end=1000,0.001", "--workers", "1",
                 "--timeout", "100", "--no-plot", "--quiet", "--out", out)
    worker = busy_worker(proc)
    worker.kill()                                   # SIGKILL: the OOM killer's way
    stdout, stderr = proc.communicate(timeout=LIMIT)
    assert proc.returncode == 1, stderr
    rows = table(out)
    dead = rows["undamped,t_end=1000"]
    assert dead["status"] == "error"
    assert dead["message"] == ("its worker process died while running it (killed by SIGKILL); "
                               "the other points ran on")
    assert rows["undamped,t_end=0.001"]["status"] == "finished"
    assert "1 of 2 point(s) finished" in stdout
    assert leftovers(proc.pid) == []


@pytest.mark.parametrize("sig,code", [(signal.SIGTERM, 143), (signal.SIGHUP, 129),
                                      (signal.SIGINT, 130)])
def test_a_stopped_sweep_ends_its_workers_and_writes_what_finished(tmp_path, sig, code):
    out = tmp_path / "sw"
    proc = start("sweep", SPRING_DROP, "--set", "t_end=0.001,1000,0.002", "--workers", "1",
                 "--timeout", "100", "--no-plot", "--quiet", "--out", out)
    worker = busy_worker(proc)
    t0 = time.monotonic()
    proc.send_signal(sig)
    stdout, stderr = proc.communicate(timeout=LIMIT)
    assert time.monotonic() - t0 < 30
    assert proc.returncode == code, stderr
    assert stderr.strip().endswith(
        f"error: the sweep was stopped ({sig.name}); the points that had not ended are "
        f"`interrupted` in {out / 'sweep.csv'}; sweep again to run them"), stderr
    assert "Traceback" not in stderr
    rows = table(out)
    assert [r["status"] for r in rows.values()] == ["finished", "interrupted", "interrupted"]
    assert rows["undamped,t_end=1000"]["message"] == (f"the sweep was stopped ({sig.name}) "
                                                      f"before this point ended")
    assert gone(worker), "the worker process outlived the sweep"
    assert leftovers(proc.pid) == []
    assert not (out / "undamped,t_end=0.002").exists()       # never started
    # sweeping again runs what was interrupted, and skips what finished
    again = cosim("sweep", SPRING_DROP, "--set", "t_end=0.001,0.002", "--no-plot", "--quiet",
                  "--out", out)
    assert again.returncode == 0, again.stderr
    assert "1 done before (not run again)" in again.stdout


def test_a_sweep_in_this_process_stops_on_sigterm_too(tmp_path):
    """Without a time limit and with one worker, the points run in the sweep's
    own process: SIGTERM stops the point as Ctrl-C would."""
    out = tmp_path / "sw"
    proc = start("sweep", SPRING_DROP, "--set", "t_end=1000", "--workers", "1", "--no-plot",
                 "--quiet", "--out", out)
    p = psutil.Process(proc.pid)
    while p.cpu_times().user < 3.0:
        assert proc.poll() is None
        time.sleep(0.2)
    proc.send_signal(signal.SIGTERM)
    _, stderr = proc.communicate(timeout=LIMIT)
    assert proc.returncode == 143, stderr
    assert [r["status"] for r in table(out).values()] == ["interrupted"]


@pytest.mark.parametrize("address,essence", [
    ("foo", "error: `--scheduler` must be `local` or a Dask scheduler's address "
            "(tcp://HOST:PORT or tls://HOST:PORT), got 'foo'"),
    ("tcp://127.0.0.1:1", "error: `--scheduler` 'tcp://127.0.0.1:1' cannot be reached: "),
])
def test_a_bad_or_unreachable_scheduler_is_refused(tmp_path, address, essence):
    pytest.importorskip("distributed")
    out = tmp_path / "sw"
    t0 = time.monotonic()
    proc = cosim("sweep", SPRING_DROP, "--set", "t_end=0.001", "--scheduler", address,
                 "--no-plot", "--out", out)
    assert time.monotonic() - t0 < 60
    assert proc.returncode == 2, proc.stderr
    assert essence in proc.stderr and "Traceback" not in proc.stderr
    assert not out.exists()


@pytest.mark.parametrize("text,essence", [
    ('scene = "s.toml"\n[x]\nscale = "abc"\n', "`x.scale` must be a number, got a string 'abc'"),
    ('scene = "s.toml"\ntimeout = -1\n', "`timeout` must be > 0 s, got -1.0"),
    ('scene = 3\n', "`scene` must be a string, got an integer 3"),
    ('scene = "s.toml"\n[x]\nkey = 1\n', "`x.key` must be a string, got an integer 1"),
    ('scene = "s.toml"\ntitle = "' + "[" * 5000 + '"\ncontact = ' + "[" * 5000 + "\n",
     "must nest at most 32 levels"),
])
def test_a_bad_study_file_is_a_message(tmp_path, text, essence):
    study = tmp_path / "study.toml"
    study.write_text(text)
    proc = cosim("sweep", "--study", study, "--no-plot", cwd=tmp_path)
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.startswith(f"error: {study}: ") and essence in proc.stderr, proc.stderr
    assert "Traceback" not in proc.stderr
    assert not (tmp_path / "runs").exists()


def test_a_study_timeout_applies_and_the_option_overrides_it(tmp_path):
    study = tmp_path / "study.toml"
    study.write_text(f'scene = "{SPRING_DROP.as_posix()}"\ntimeout = 1e-9\n'
                     '[set]\nt_end = [0.001]\n')
    proc = cosim("sweep", "--study", study, "--no-plot", "--quiet", "--out", tmp_path / "a",
                 cwd=tmp_path)
    assert proc.returncode == 1
    assert [r["status"] for r in table(tmp_path / "a").values()] == ["timeout"]
    proc = cosim("sweep", "--study", study, "--timeout", "100", "--no-plot", "--quiet",
                 "--out", tmp_path / "b", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert [r["status"] for r in table(tmp_path / "b").values()] == ["finished"]


@pytest.mark.parametrize("value", ["0", "-3", "nan", "inf"])
def test_a_bad_timeout_option_is_refused(tmp_path, value):
    proc = cosim("sweep", SPRING_DROP, "--timeout", value, "--out", tmp_path / "sw")
    assert proc.returncode == 2
    assert f"error: `--timeout` must be > 0 s, got" in proc.stderr
    assert not (tmp_path / "sw").exists()


# ------------------------------------------------------------------- Dask
def test_the_local_dask_cluster_is_private():
    """`--scheduler local` listens on 127.0.0.1 with TLS and a certificate made
    for this cluster alone: a client without it, or with another, is turned
    away; the sweep's own client runs tasks.  The cluster runs in a process of
    its own: late in a whole suite, distributed's threads in a test worker that
    earlier tests had used took the worker down with them now and then, where
    the same test alone never failed."""
    pytest.importorskip("cryptography")
    pytest.importorskip("distributed")
    proc = subprocess.run([sys.executable, "-c", _CLUSTER, _OUTSIDER], capture_output=True,
                          text=True, timeout=400)
    assert proc.returncode == 0, (proc.returncode, proc.stdout[-2000:], proc.stderr[-4000:])
    address, own, *outsiders = proc.stdout.split()
    assert address.startswith("tls://127.0.0.1:") and own == "2", proc.stdout
    # each outsider tried while the cluster was up, in a process of its own
    assert outsiders == ["none:refused", "another:refused", "plain:refused"], proc.stdout


#: the cluster, its address and its own client's answer, then each outsider
#: (the script in argv[1]) tried while the cluster is still up
_CLUSTER = """
import subprocess, sys
import distributed
from cosim.studies.sweep.backends import _private_cluster
with _private_cluster(1) as cluster:
    address = cluster.scheduler_address
    with distributed.Client(cluster) as own:
        print(address, own.submit(abs, -2).result(timeout=60), flush=True)
    for kind in ("none", "another", "plain"):
        out = subprocess.run([sys.executable, "-c", sys.argv[1], address, kind],
                             capture_output=True, text=True, timeout=120).stdout.strip()
        print(f"{kind}:{out or 'nothing'}", flush=True)
"""


#: a client from outside the cluster: without a certificate, with one of its
#: own, or over plain TCP.  Each tries in a process of its own: in this one, a
#: refused Client collected in distributed's loop thread while the next one
#: starts its loop can deadlock the two (seen here: Client.__del__ stopping
#: the loop runner that the next Client waits on), which would hang the test
#: instead of failing it
_OUTSIDER = """
import sys
import distributed
from distributed.security import Security
address, kind = sys.argv[1], sys.argv[2]
kw = {"security": Security.temporary()} if kind == "another" else {}
if kind == "plain":
    address = address.replace("tls://", "tcp://")
try:
    client = distributed.Client(address, timeout=5, **kw)
except AssertionError as exc:
    # distributed's own `assert` on the comm it never got: the same refusal,
    # raised inside distributed
    import traceback
    where = traceback.extract_tb(exc.__traceback__)[-1].filename
    print("refused" if "distributed" in where else f"assert in {where}")
except Exception:
    print("refused")              # an error of the connection (TLS, a timeout)
else:
    print("connected")
"""


def test_without_cryptography_the_local_cluster_has_no_socket(monkeypatch):
    distributed = pytest.importorskip("distributed")
    from distributed.security import Security

    from cosim.studies.sweep.backends import _private_cluster

    def missing(*a, **k):
        raise ImportError("no cryptography")
    monkeypatch.setattr(Security, "temporary", classmethod(missing))
    with _private_cluster(1) as cluster:
        assert cluster.scheduler_address.startswith("inproc://")
        with distributed.Client(cluster) as client:
            assert client.submit(abs, -3).result(timeout=60) == 3


def test_a_hanging_point_on_dask_ends_at_the_time_limit(tmp_path):
    pytest.importorskip("distributed")
    out = tmp_path / "sw"
    proc = start("sweep", SPRING_DROP, "--set", "t_end=0.001,1000", "--scheduler", "local",
                 "--workers", "2", "--timeout", "15", "--no-plot", "--quiet", "--out", out)
    stdout, stderr = proc.communicate(timeout=LIMIT + 60)
    assert proc.returncode == 1, stderr
    rows = table(out)
    assert rows["undamped,t_end=0.001"]["status"] == "finished"
    long = rows["undamped,t_end=1000"]
    assert long["status"] == "timeout"
    assert long["message"].startswith("ran past the time limit of 15 s (wall clock); its "
                                      "task was cancelled")
    assert leftovers(proc.pid) == []

"""What a run writes, and what it does when the operating system or another
process gets in the way: every file stays in the run folder, no planted link
is followed, no file the run did not write is replaced, a second run into a
busy folder is refused, SIGTERM and SIGHUP stop a run as Ctrl-C does, an
unwritable folder or a full disk is a message (exit 2) and nothing is left
half-written, and a closed pipe ends the command quietly.

Each case runs `cosim` as a user types it, in a fresh process, and looks at
the file system afterwards."""
import json
import os
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest

from conftest import CASES, ROOT
import cosim
from cosim.errors import OutputBusyError, OutputError
from cosim.io.rundir import LOCK_NAME, RunLock

SPRING_DROP = CASES / "spring_drop.toml"
SHORT = ("--set", "t_end=0.002")
RUN_FILES = ["scene.toml", "series.npz", "summary.json"]


def cosim_cli(*args, cwd, **kw):
    return subprocess.run([sys.executable, "-m", "cosim.cli", *map(str, args)],
                          capture_output=True, text=True, cwd=cwd, timeout=300, **kw)


def python(code, *args, cwd):
    """``python -c CODE ARGS...`` in a fresh process (fault injection)."""
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code), *map(str, args)],
                          capture_output=True, text=True, cwd=cwd, timeout=300)


def tree(root):
    return sorted(str(p.relative_to(root)) for p in root.rglob("*"))


def snapshot(folder):
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir()) if p.is_file()}


def summary(out):
    return json.loads((out / "summary.json").read_text())


def whole(out):
    """The folder holds one whole run: its three files, nothing hidden left."""
    assert sorted(p.name for p in out.iterdir()) == RUN_FILES, list(out.iterdir())
    with np.load(out / "series.npz") as npz:
        t = npz["t"]
        assert all(len(npz[k]) == len(t) for k in npz.files)
    assert summary(out)["t_end"] == pytest.approx(t[-1])


def long_run(out, cwd):
    """A run that goes on until stopped, once it has started stepping."""
    proc = subprocess.Popen([sys.executable, "-m", "cosim.cli", "run",
                             str(CASES / "three_mass.toml"), "--variant", "f100",
                             "--set", "t_end=500", "--out", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=cwd)
    spool = out / ".series.npz.spool"
    deadline = time.monotonic() + 120
    while not spool.exists() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)
    assert spool.exists(), "the run never started"
    time.sleep(0.5)
    return proc


# ------------------------------------------------------------ planted links
def test_a_link_planted_at_the_spool_is_not_followed(tmp_path):
    victim = tmp_path / "victim.txt"
    victim.write_text("precious")
    out = tmp_path / "run"
    out.mkdir()
    (out / ".series.npz.spool").symlink_to(victim)
    proc = cosim_cli("run", SPRING_DROP, *SHORT, "--out", out, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert victim.read_text() == "precious"
    whole(out)


def test_links_planted_at_the_outputs_are_replaced_not_written_through(tmp_path):
    victim = tmp_path / "victim.txt"
    victim.write_text("precious")
    out = tmp_path / "run"
    out.mkdir()
    for name in ("summary.json", "series.npz"):
        (out / name).symlink_to(victim)
    proc = cosim_cli("run", SPRING_DROP, *SHORT, "--out", out, cwd=tmp_path)
    assert proc.returncode == 2                          # they look like a run: kept
    assert "already holds a run (summary.json, series.npz)" in proc.stderr
    proc = cosim_cli("run", SPRING_DROP, *SHORT, "--out", out, "--overwrite", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert victim.read_text() == "precious"
    assert not any(p.is_symlink() for p in out.iterdir())
    whole(out)


def test_a_link_planted_at_the_lock_is_refused(tmp_path):
    victim = tmp_path / "victim.txt"
    victim.write_text("precious")
    out = tmp_path / "run"
    out.mkdir()
    (out / LOCK_NAME).symlink_to(victim)
    proc = cosim_cli("run", SPRING_DROP, *SHORT, "--out", out, cwd=tmp_path)
    assert proc.returncode == 2
    assert proc.stderr == (f"error: cannot lock {out / LOCK_NAME}: it is a symbolic link (a "
                           f"run never follows one); remove it\n")
    assert victim.read_text() == "precious" and tree(out) == [LOCK_NAME]


def test_exports_stay_in_the_run_folder_and_replace_links_only_with_overwrite(tmp_path):
    pytest.importorskip("meshio")
    victim = tmp_path / "victim.txt"
    victim.write_text("precious")
    out = tmp_path / "run"
    out.mkdir()
    (out / "chain.xdmf").symlink_to(victim)
    args = ("run", CASES / "three_mass.toml", "--set", "t_end=0.01", "--set",
            'output.export=["chain"]', "--out", out)
    proc = cosim_cli(*args, cwd=tmp_path)
    assert proc.returncode == 2
    assert proc.stderr == (f"error: {out} already holds chain.xdmf, which this run would "
                           f"replace; choose another --out, or pass --overwrite "
                           f"to replace it\n")
    proc = cosim_cli(*args, "--overwrite", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert f"wrote {out / 'chain.xdmf'} (open in ParaView)" in proc.stdout
    assert victim.read_text() == "precious" and not (out / "chain.xdmf").is_symlink()
    assert tree(tmp_path) == ["run", *(f"run/{n}" for n in ["chain.xdmf", *RUN_FILES]),
                              "victim.txt"]


# -------------------------------------------------- the user's scene file
def test_out_dot_in_the_scenes_own_folder_never_replaces_it(tmp_path):
    text = SPRING_DROP.read_text().replace("t_end = 0.02 ", "t_end = 0.002")
    (tmp_path / "scene.toml").write_text(text)
    for extra in ([], ["--overwrite"]):
        proc = cosim_cli("run", "scene.toml", "--out", ".", *extra, cwd=tmp_path)
        assert proc.returncode == 2, proc.stderr
        assert proc.stderr == ("error: scene.toml was not written by a run (it may be your "
                               "scene file), and a run writes its scene.toml there: choose "
                               "another --out (--overwrite does not replace it)\n")
        assert tree(tmp_path) == ["scene.toml"] and (tmp_path / "scene.toml").read_text() == text


def test_out_dot_beside_a_scene_of_another_name_writes_the_run_there(tmp_path):
    text = SPRING_DROP.read_text()
    (tmp_path / "drop.toml").write_text(text)
    proc = cosim_cli("run", "drop.toml", *SHORT, "--out", ".", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert tree(tmp_path) == ["drop.toml", *RUN_FILES]
    assert (tmp_path / "drop.toml").read_text() == text
    # the run's own scene.toml runs again into its folder, replacing the run
    proc = cosim_cli("run", "scene.toml", "--out", ".", "--overwrite", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / "drop.toml").read_text() == text


# ----------------------------------------------------------------- the lock
def test_a_second_run_into_a_busy_folder_is_refused(tmp_path):
    out = tmp_path / "run"
    first = long_run(out, tmp_path)
    try:
        before = {p.name for p in out.iterdir()}
        scene = (out / "scene.toml").read_bytes()
        for extra in ([], ["--overwrite"]):
            proc = cosim_cli("run", SPRING_DROP, *SHORT, "--out", out, *extra, cwd=tmp_path)
            assert proc.returncode == 2
            assert proc.stderr == (f"error: {out} is in use by another run (process "
                                   f"{first.pid}); wait for it to end, or choose another "
                                   f"--out\n")
            assert {p.name for p in out.iterdir()} == before
            assert (out / "scene.toml").read_bytes() == scene
            assert first.poll() is None                       # the first run goes on
    finally:
        first.send_signal(signal.SIGINT)
        first.communicate(timeout=120)
    assert first.returncode == 130
    assert summary(out)["scene"] == "three_mass"
    whole(out)


def test_a_run_killed_outright_leaves_no_lock_that_blocks_the_next(tmp_path):
    out = tmp_path / "run"
    first = long_run(out, tmp_path)
    first.kill()
    first.communicate(timeout=60)
    assert (out / LOCK_NAME).exists()                  # the file stays, its lock does not
    proc = cosim_cli("run", SPRING_DROP, *SHORT, "--out", out, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    whole(out)


def test_the_lock_from_python(tmp_path):
    with RunLock(tmp_path / "a") as lock:
        assert lock.created and (tmp_path / "a" / LOCK_NAME).read_text() == f"{os.getpid()}\n"
        with pytest.raises(OutputBusyError, match=f"in use by another run \\(process "
                                                  f"{os.getpid()}\\)"):
            RunLock(tmp_path / "a").acquire()
        with pytest.raises(OutputBusyError):
            cosim.simulate(cosim.load_scene(SPRING_DROP), out=tmp_path / "a")
    assert tree(tmp_path) == ["a"]                     # released and removed
    cosim.simulate(cosim.load_scene(SPRING_DROP, overrides=["t_end=0.001"]), out=tmp_path / "a")
    whole(tmp_path / "a")


# ------------------------------------------------------------------ signals
@pytest.mark.parametrize("sig,code", [(signal.SIGTERM, 143), (signal.SIGHUP, 129)])
def test_sigterm_and_sighup_stop_a_run_as_ctrl_c_does(tmp_path, sig, code):
    out = tmp_path / "run"
    proc = long_run(out, tmp_path)
    proc.send_signal(sig)
    stdout, stderr = proc.communicate(timeout=120)
    assert proc.returncode == code, stderr
    assert "Traceback" not in stderr
    name = signal.Signals(sig).name
    s = summary(out)
    assert s["status"] == "interrupted"
    assert s["message"].startswith(f"interrupted ({name}) at t = ")
    assert f"error: the run did not finish (interrupted): interrupted ({name}) at t = " in stderr
    assert f"are in {out}" in stderr and "status interrupted" in stdout
    assert 0 < s["t_end"] < 1000
    whole(out)


def test_sigterm_before_the_run_starts_exits_143(tmp_path):
    """A signal while the scene is read: no run, no folder, exit 128 + 15."""
    proc = python("""
        import os, signal, sys
        from cosim import cli
        from cosim.scene import load as scene
        load = scene.load_scene
        def slow(*a, **k):
            os.kill(os.getpid(), signal.SIGTERM)
            return load(*a, **k)
        scene.load_scene = slow
        sys.exit(cli.main(sys.argv[1:]))
        """, "run", SPRING_DROP, "--out", tmp_path / "o", cwd=tmp_path)
    assert proc.returncode == 143, proc.stderr
    assert proc.stderr == "error: interrupted (SIGTERM)\n"
    assert tree(tmp_path) == []


# ------------------------------------------------------- unwritable places
@pytest.mark.parametrize("where,reason", [
    ("FILE", "it exists and is not a folder"),
    ("FILE/run", "Not a directory"),
    ("/proc/cosim-run", "No such file or directory"),
    ("/proc/self", "a link"),
])
def test_an_unwritable_out_is_a_message_and_exit_2(tmp_path, where, reason):
    (tmp_path / "FILE").write_text("mine")
    out = where.replace("FILE", str(tmp_path / "FILE"))
    proc = cosim_cli("run", SPRING_DROP, *SHORT, "--out", out, cwd=tmp_path)
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr and proc.stdout == ""
    if reason == "a link":
        assert proc.stderr.startswith(f"error: cannot write into {out}: it is a symbolic link")
    else:
        assert proc.stderr == f"error: cannot make the output folder {out}: {reason}\n"
    assert tree(tmp_path) == ["FILE"] and (tmp_path / "FILE").read_text() == "mine"


def inject(patch: str) -> str:
    """A ``cosim`` process whose ``patch`` makes a write fail with ENOSPC (``full()``)."""
    return "\n".join([textwrap.dedent("""
        import errno, sys
        import numpy as np
        from cosim import cli
        def full(*a, **k):
            raise OSError(errno.ENOSPC, "No space left on device")
        """), textwrap.dedent(patch), "sys.exit(cli.main(sys.argv[1:]))"])


def test_a_full_disk_when_the_series_is_written_is_a_message_and_exit_2(tmp_path):
    out = tmp_path / "run"
    proc = python(inject("np.lib.format.write_array_header_1_0 = full"),
                  "run", SPRING_DROP, "--out", out, cwd=tmp_path)
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr
    assert proc.stderr.endswith(
        f"error: cannot write {out / 'series.npz'}: No space left on device; the run ended "
        f"(finished at t = 0.02 s) but wrote no series or summary (in {out})\n")
    assert tree(tmp_path) == ["run", "run/scene.toml"]          # nothing half-written


def test_a_full_disk_when_the_summary_is_written_leaves_no_series_alone(tmp_path):
    out = tmp_path / "run"
    proc = python(inject("import json; json.dump = full"),
                  "run", SPRING_DROP, "--out", out, cwd=tmp_path)
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.endswith(
        f"error: cannot write {out / 'summary.json'}: No space left on device; the run ended "
        f"(finished at t = 0.02 s) but wrote no summary, so its series.npz is removed too "
        f"(in {out})\n")
    assert tree(tmp_path) == ["run", "run/scene.toml"]


def test_a_full_disk_during_the_run_stops_it_with_a_message(tmp_path):
    """The spool fills chunk by chunk (64 rows here); its second write fails."""
    out = tmp_path / "run"
    proc = python(inject("""
    from cosim.core import series
    series.CHUNK_BYTES = 1
    opened = series._open_spool
    class Full:
        def __init__(self, fh):
            self.fh, self.writes = fh, 0
        def write(self, data):
            self.writes += 1
            if self.writes == 2:
                full()
            return self.fh.write(data)
        def __getattr__(self, name):
            return getattr(self.fh, name)
    series._open_spool = lambda path: Full(opened(path))
    """), "run", SPRING_DROP, "--out", out, cwd=tmp_path)
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr
    # the time is the last sample recorded when the write failed: 0.012 s in
    # the Python loop (sample by sample), the end of the block that holds it
    # on the sampled path (spring_drop's touch, 0.0131 s), before the run's end
    head = (f"error: cannot write {out / '.series.npz.spool'}: No space left on device; "
            f"the run stopped at t = ")
    assert proc.stderr.startswith(head)
    stopped = float(proc.stderr[len(head):].split(" s ", 1)[0])
    assert 0.012 <= stopped < 0.02
    assert proc.stderr.endswith(f" s and wrote no series or summary (in {out})\n")
    assert tree(tmp_path) == ["run", "run/scene.toml"]


#: a spool on a disk that fills: the file system takes ``ROOM`` bytes, written
#: through the spool's own buffer, then refuses the rest (a partial write, then
#: ENOSPC), so the bytes left in the buffer fail again when it is closed
SMALL_DISK = """
import io, os
from cosim.core import series
series.CHUNK_BYTES = 1
ROOM = int(os.environ["SPOOL_ROOM"])
class Disk(io.FileIO):
    def write(self, data):
        room = ROOM - os.lseek(self.fileno(), 0, os.SEEK_CUR)
        if room <= 0:
            full()
        return super().write(bytes(memoryview(data).cast("B")[:room]))
opened = series._open_spool
def small(path):
    raw = opened(path).detach()
    fd = os.dup(raw.fileno())
    raw.close()
    return io.BufferedRandom(Disk(fd, "r+"))
series._open_spool = small
"""


@pytest.mark.parametrize("room,when", [(3000, "stopped at t = 0.0"),
                                       (12_000, "ended (finished at t = 0.02 s)")])
def test_a_disk_that_fills_while_spooling_leaves_no_spool_and_no_open_file(tmp_path, room,
                                                                           when):
    """The disk fills with the spool's buffer half written: during the run
    (3 kB: spring_drop's chunks of 64 rows are 4 kB) or when the run ends
    (12 kB: the spool's 12.9 kB fit but for the last chunk).  Either way:
    exit 2 and the message, the spool closed (no ResourceWarning, which
    ``-X dev`` shows) and removed, and the folder holds what it held before
    and ``scene.toml``."""
    out = tmp_path / "run"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    proc = subprocess.run(
        [sys.executable, "-X", "dev", "-c", inject(SMALL_DISK), "run", SPRING_DROP,
         "--out", out], capture_output=True, text=True, cwd=tmp_path, timeout=300,
        env={**os.environ, "SPOOL_ROOM": str(room)})
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr
    assert "unclosed" not in proc.stderr and "ResourceWarning" not in proc.stderr
    assert proc.stderr.startswith(f"error: cannot write {out / '.series.npz.spool'}: No space "
                                  f"left on device; the run {when}")
    assert proc.stderr.endswith(f"wrote no series or summary (in {out})\n")
    assert proc.stderr.count("\n") == 1
    assert tree(tmp_path) == ["run", "run/notes.txt", "run/scene.toml"]
    assert (out / "notes.txt").read_text() == "mine"


@pytest.fixture
def full_tmpfs(tmp_path):
    """A 40 kB tmpfs (a real file system that fills), or a skip where
    mounting is not permitted (not root, no CAP_SYS_ADMIN, not Linux)."""
    import shutil
    mnt = tmp_path / "disk"
    mnt.mkdir()
    if sys.platform != "linux" or shutil.which("mount") is None:
        pytest.skip("mounting a tmpfs needs Linux and mount(8)")
    mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=40k", "tmpfs", str(mnt)],
                             capture_output=True, text=True, timeout=30)
    if mounted.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {mounted.stderr.strip()}")
    try:
        yield mnt
    finally:
        subprocess.run(["umount", str(mnt)], capture_output=True, timeout=30)


@pytest.mark.parametrize("chunk", ["1", "series.CHUNK_BYTES"])
def test_a_full_tmpfs_leaves_no_spool_and_no_open_file(full_tmpfs, chunk):
    """The same on a real file system: three_mass f100 (0.25 s) spools about
    150 kB, which a 40 kB tmpfs cannot hold, in chunks of 64 rows (the disk
    fills during the run) or in one chunk of 1 MB (it fills at the end)."""
    out = full_tmpfs / "run"
    code = f"from cosim.core import series; series.CHUNK_BYTES = {chunk}"
    proc = subprocess.run(
        [sys.executable, "-X", "dev", "-c", inject(code), "run", CASES / "three_mass.toml",
         "--variant", "f100", "--out", out], capture_output=True, text=True,
        cwd=full_tmpfs.parent, timeout=300)
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr
    assert "unclosed" not in proc.stderr and "ResourceWarning" not in proc.stderr
    assert proc.stderr.startswith(f"error: cannot write {out / '.series.npz.spool'}: No space "
                                  f"left on device; the run "), proc.stderr
    assert tree(full_tmpfs) == ["run", "run/scene.toml"]


def test_output_errors_from_python_are_oserrors_naming_the_path(tmp_path, monkeypatch):
    import errno
    (tmp_path / "FILE").write_text("")
    with pytest.raises(OutputError, match="cannot make the output folder .*FILE/x: Not a dir") as e:
        cosim.simulate(cosim.load_scene(SPRING_DROP), out=tmp_path / "FILE" / "x")
    assert isinstance(e.value, OSError) and e.value.errno == errno.ENOTDIR


# ------------------------------------------------------------- closed pipes
def test_a_reader_that_went_away_ends_the_command_quietly(tmp_path):
    out = tmp_path / "run"
    proc = subprocess.Popen([sys.executable, "-m", "cosim.cli", "run", str(SPRING_DROP),
                             "--out", str(out)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, cwd=tmp_path)
    proc.stdout.close()                      # `| head -0`: gone before anything is printed
    stderr = proc.communicate(timeout=300)[1].decode()
    assert proc.returncode == 141
    assert "Traceback" not in stderr and "BrokenPipe" not in stderr and "error" not in stderr
    assert summary(out)["status"] == "finished"
    whole(out)


def test_cosim_run_piped_into_head(tmp_path):
    out = tmp_path / "run"
    cmd = (f'"{sys.executable}" -m cosim.cli run "{SPRING_DROP}" --out "{out}" | head -1; '
           f'echo "exit ${{PIPESTATUS[0]}}" >&2')
    proc = subprocess.run(["bash", "-c", cmd], capture_output=True, text=True, cwd=tmp_path,
                          timeout=300, env={**os.environ, "PYTHONPATH": os.pathsep.join(
                              [str(ROOT / "src"), os.environ.get("PYTHONPATH", "")])})
    assert proc.stdout == "scene spring_drop  scheme gauss_seidel  status finished\n"
    assert proc.stderr.splitlines()[-1] in ("exit 0", "exit 141")   # 141 when head left first
    assert "Traceback" not in proc.stderr and "BrokenPipe" not in proc.stderr
    whole(out)


def test_a_folder_made_for_a_lock_that_fails_is_removed(tmp_path, monkeypatch):
    import errno
    import fcntl

    def broken(fd, op):
        raise OSError(errno.EIO, "Input/output error")
    monkeypatch.setattr(fcntl, "flock", broken)
    with pytest.raises(OutputError, match=f"cannot lock {tmp_path}/new/{LOCK_NAME}: "
                                          f"Input/output error"):
        cosim.simulate(cosim.load_scene(SPRING_DROP), out=tmp_path / "new")
    assert tree(tmp_path) == []

"""An FMU runs in a host process of its own (cosim.sides.fmu_host,
cosim.sides.fmu_client) and is unpacked bounded (cosim.sides.fmu_unpack).

Hostile FMUs are built at test time from ``examples/fmu/arm2.c`` with the
machine's C compiler, as ``tests/test_fmu.py`` builds the arm: the same arm
whose ``doStep`` segfaults, aborts, exits, hangs (ignoring SIGTERM) or
returns an error once the step starts at ``FAIL_AT``, or whose ``GetReal``
then fails.  Each is run by ``cosim run`` in a subprocess whose ``TMPDIR`` is
the test's own, so that the unpacked folders it leaves (none) can be counted.
"""
from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import numpy as np
import pytest
from conftest import load_fmu_build

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES = ROOT / "examples"
FMU_SCENE = EXAMPLES / "fmu" / "arm_on_beam.toml"
#: the communication point whose step misbehaves [s] (a multiple of the
#: scene's macro step, 50 us)
FAIL_AT = 0.005
T_END = 0.01

#: mode -> the C that runs in place of the step once t >= FAIL_AT
MODES = {
    "segfault": "volatile int *p = 0; *p = 1;",
    "abort": "abort();",
    "exit": "exit(3);",
    "hang": "signal(SIGTERM, SIG_IGN); volatile int spin = 1; while (spin) {}",
    "error": "return 0;",
    "getreal": "a->fail_get = 1;",
}


def _hostile_source(mode: str) -> str:
    """arm2.c whose step misbehaves (``MODES[mode]``) from FAIL_AT on."""
    text = (EXAMPLES / "fmu" / "arm2.c").read_text()
    head = "static int step(Arm *a, double t, double h) {"
    assert text.count(head) == 1
    wrapper = (f"static int step_ok(Arm *a, double t, double h);\n"
               f"{head}\n"
               f"    if (t >= {FAIL_AT!r} - 1e-12) {{ {MODES[mode]} }}\n"
               f"    return step_ok(a, t, h);\n}}\n"
               f"static int step_ok(Arm *a, double t, double h) {{")
    text = text.replace(head, wrapper)
    # GetReal fails once the flag is set (the arm's state grows a field for it)
    text = text.replace("    double du[2][2];      /* input derivatives: [order - 1][fx, fy] */",
                        "    double du[2][2];\n    int fail_get;")
    text = text.replace("static int get_reals(Arm *a, const unsigned int *vr, size_t n, "
                        "double *value) {",
                        "static int get_reals(Arm *a, const unsigned int *vr, size_t n, "
                        "double *value) {\n    if (a->fail_get) return 0;")
    return "#include <signal.h>\n#include <stdio.h>\n" + text


@pytest.fixture(scope="session")
def hostile(fmu_build, tmp_path_factory):
    """``{(mode, fmi_version): path}`` of the hostile FMUs, built on demand."""
    _, cc = fmu_build
    build = load_fmu_build("fmu_build_hostile")     # its SOURCE is changed below
    out = tmp_path_factory.mktemp("hostile")
    made = {}

    def get(mode: str, version: int = 2) -> Path:
        if (mode, version) not in made:
            src = out / f"{mode}.c"
            src.write_text(_hostile_source(mode))
            build.SOURCE = src              # this module's own copy of build.py
            made[mode, version] = build.build_fmu(out, version, True, cc,
                                                  name=f"{mode}_fmi{version}")
        return made[mode, version]
    return get


def _env(tmp: Path, **extra) -> dict:
    tmp.mkdir(exist_ok=True)
    return {**os.environ, "TMPDIR": str(tmp), **extra}


def _cosim(*args):
    return [sys.executable, "-m", "cosim.cli", *args]


def _run_args(fmu: Path, out: Path, *extra):
    return _cosim("run", str(FMU_SCENE), "--set", f"subsystems.arm.path={fmu}",
                  "--set", f"t_end={T_END}", "--out", str(out), *extra)


def _assert_kept(out: Path, tmp: Path, status: str, t_last: float):
    """The run's data up to ``t_last`` are readable, and nothing is left over."""
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == status
    with np.load(out / "series.npz") as series:
        t = series["t"]
        assert t[-1] == pytest.approx(t_last, abs=1e-12)
        assert np.all(np.isfinite(series["q/arm/q1"]))
    assert summary["t_end"] == pytest.approx(t_last, abs=1e-12)
    assert sorted(p.name for p in out.iterdir()) == ["scene.toml", "series.npz",
                                                     "summary.json"]
    assert not list(tmp.glob("cosim-fmu-*"))
    return summary


# ------------------------------------------------------------- crashes
@pytest.mark.parametrize("mode, version, how", [
    ("segfault", 2, "was killed by signal SIGSEGV"),
    ("abort", 2, "was killed by signal SIGABRT"),
    ("exit", 2, "exited with status 3"),
    ("segfault", 3, "was killed by signal SIGSEGV"),
])
def test_a_crashing_fmu_fails_the_run_and_keeps_its_data(hostile, tmp_path, mode, version,
                                                         how):
    """The host process dies inside doStep: `cosim run` ends the run
    `failed` (exit 1), naming the FMU, the subsystem, the FMI function, how
    the host ended and the time; the series reach the step's start."""
    fmu = hostile(mode, version)
    out, tmp = tmp_path / "run", tmp_path / "tmp"
    done = subprocess.run(_run_args(fmu, out), capture_output=True, text=True,
                          env=_env(tmp), timeout=120)
    assert done.returncode == 1, done.stderr
    call = f"fmi{version}DoStep"
    assert (f"subsystem `arm`: FMU {fmu.name} crashed in {call} at t = {FAIL_AT:g} s "
            f"(its host process {how})") in done.stderr
    assert "Traceback" not in done.stderr and "bug of cosim" not in done.stderr
    summary = _assert_kept(out, tmp, "failed", FAIL_AT)
    failure = summary["fmu_failure"]
    assert failure.pop("time") == pytest.approx(FAIL_AT, abs=1e-12)
    assert failure == {"subsystem": "arm", "fmu": fmu.name, "function": call,
                       "status": f"host process {how}"}


@pytest.mark.parametrize("mode, call, status", [
    ("error", "fmi2DoStep", "fmi2Error"),
    ("getreal", "fmi2GetReal", "fmi2Error"),
])
def test_an_fmi_call_that_fails_ends_the_run_cleanly(hostile, tmp_path, mode, call, status):
    """doStep returning fmi2Error, GetReal failing: a clean error naming the
    FMU, subsystem, function, status and time; exit 1, the data kept."""
    fmu = hostile(mode)
    out, tmp = tmp_path / "run", tmp_path / "tmp"
    done = subprocess.run(_run_args(fmu, out), capture_output=True, text=True,
                          env=_env(tmp), timeout=120)
    assert done.returncode == 1, done.stderr
    assert (f"subsystem `arm`: FMU {fmu.name}: {call} returned {status} at "
            f"t = {FAIL_AT:g} s") in done.stderr
    assert "Traceback" not in done.stderr and "FMICallException" not in done.stderr
    summary = _assert_kept(out, tmp, "failed", FAIL_AT)
    assert summary["fmu_failure"]["function"] == call
    assert summary["fmu_failure"]["status"] == status
    assert summary["fmu_failure"]["time"] == pytest.approx(FAIL_AT, abs=1e-12)


# ------------------------------------------------------------- hangs
@pytest.mark.parametrize("sig, code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)],
                         ids=["SIGINT", "SIGTERM"])
def test_a_hanging_fmu_yields_to_sigint_and_sigterm(hostile, tmp_path, sig, code):
    """doStep never returns (and ignores SIGTERM): the signal ends the run
    within seconds, the host is killed, the data up to the hang are kept."""
    fmu = hostile("hang")
    out, tmp = tmp_path / "run", tmp_path / "tmp"
    proc = subprocess.Popen(_run_args(fmu, out), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=_env(tmp))
    try:
        # wait until the run is past FAIL_AT: the progress is not shown off a
        # terminal, so watch for the host that spins (its CPU time grows)
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and not _spinning_child(proc.pid):
            time.sleep(0.2)
        host = _spinning_child(proc.pid)
        assert host, "the FMU never started to hang"
        t0 = time.monotonic()
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=20)
        took = time.monotonic() - t0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == code, err
    assert took < 10, f"the run took {took:.1f} s to stop"
    assert f"interrupted ({sig.name if sig != signal.SIGINT else 'Ctrl-C'})" in err
    _assert_kept(out, tmp, "interrupted", FAIL_AT)
    assert not Path(f"/proc/{host}").exists(), "the FMU's host process outlived the run"


def _spinning_child(pid: int) -> int | None:
    """The child of ``pid`` that has spent more than 2 s of CPU time, if any
    (the host of a hanging FMU; its start-up and the steps before the hang
    take a fraction of that)."""
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) != pid:                       # the parent's pid
            continue
        ticks = int(fields[11]) + int(fields[12])        # utime + stime
        if ticks / os.sysconf("SC_CLK_TCK") > 2.0:
            return int(stat.parent.name)
    return None


# ------------------------------------------------------------- unpacking
def _bomb(path: Path, fmu: Path, size: int) -> Path:
    """``fmu`` plus a member of ``size`` zero bytes (it compresses to almost nothing)."""
    with zipfile.ZipFile(fmu) as src, zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        for m in src.infolist():
            z.writestr(m, src.read(m))
        with z.open("resources/filler.bin", "w", force_zip64=True) as fh:
            block = bytes(1 << 20)
            for _ in range(size >> 20):
                fh.write(block)
    return path


def test_an_fmu_that_unpacks_past_the_limit_is_refused(hostile, tmp_path):
    """A member far larger than its file (64 MiB of zeros in a file of about
    70 kB) against a limit of 8 MiB: refused before anything is written,
    exit 2, naming the limit and the variable that raises it; with the limit
    raised, the same FMU runs."""
    bomb = _bomb(tmp_path / "bomb.fmu", hostile("error"), 64 << 20)
    assert bomb.stat().st_size < 1 << 20
    out, tmp = tmp_path / "run", tmp_path / "tmp"
    done = subprocess.run(_run_args(bomb, out), capture_output=True, text=True,
                          env=_env(tmp, COSIM_FMU_UNPACK_LIMIT="8M"), timeout=120)
    assert done.returncode == 2, done.stderr
    assert re.search(r"`subsystems.arm.path` subsystem `arm`: FMU bomb.fmu cannot be unpacked: "
                     r"unpacks to 64(\.\d+)? MiB \(its members' declared sizes\), more than the "
                     r"limit of 8 MiB \(set the environment variable COSIM_FMU_UNPACK_LIMIT to "
                     r"raise the limit\)", done.stderr), done.stderr
    assert not out.exists() and not list(tmp.iterdir())
    done = subprocess.run(_run_args(bomb, out, "--set", "t_end=0.001"), capture_output=True,
                          text=True, env=_env(tmp, COSIM_FMU_UNPACK_LIMIT="80M"), timeout=120)
    assert done.returncode == 0, done.stderr
    assert not list(tmp.iterdir())


def test_a_member_larger_than_it_declares_stops_the_unpacking(tmp_path, monkeypatch):
    """The header can lie: the bytes actually written are counted too, and
    the folder goes when they pass the limit."""
    import io
    from cosim.sides import fmu_unpack
    monkeypatch.setattr("tempfile.tempdir", str(tmp_path))
    fmu = tmp_path / "liar.fmu"
    with zipfile.ZipFile(fmu, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("modelDescription.xml", "<x/>")
        z.writestr("binaries/big.bin", bytes(3 << 20))
    monkeypatch.setenv(fmu_unpack.UNPACK_LIMIT_ENV, "4M")
    real_open = zipfile.ZipFile.open

    def lying_open(self, member, *a, **k):  # hands out three times what was declared
        data = real_open(self, member, *a, **k).read()
        return io.BytesIO(data * 3)
    monkeypatch.setattr(zipfile.ZipFile, "open", lying_open)
    with pytest.raises(ValueError, match=r"unpacks to more than the limit of 4 MiB \(its "
                                         r"member 'binaries/big.bin' holds more than it "
                                         r"declares\)"):
        fmu_unpack.unpacked(fmu)
    assert not list(tmp_path.glob("cosim-fmu-*"))


@pytest.mark.parametrize("name", ["../evil.so", "/etc/evil", "binaries/../../x", "a\\b",
                                  "c:/x"])
def test_a_member_that_leaves_the_folder_is_refused(tmp_path, monkeypatch, name):
    from cosim.sides import fmu_unpack
    monkeypatch.setattr("tempfile.tempdir", str(tmp_path))
    fmu = tmp_path / "escape.fmu"
    with zipfile.ZipFile(fmu, "w") as z:
        z.writestr("modelDescription.xml", "<x/>")
        z.writestr(zipfile.ZipInfo(name), b"payload")
    with pytest.raises(ValueError, match=r"would be written outside the folder"):
        fmu_unpack.unpacked(fmu)
    assert not list(tmp_path.glob("cosim-fmu-*"))
    assert not (tmp_path.parent / "evil.so").exists()


def test_a_link_in_the_archive_is_written_as_a_plain_file(tmp_path, monkeypatch):
    from cosim.sides import fmu_unpack
    monkeypatch.setattr("tempfile.tempdir", str(tmp_path))
    fmu = tmp_path / "link.fmu"
    link = zipfile.ZipInfo("binaries/link.so")
    link.external_attr = (0o120777 << 16)         # a symbolic link, as zip stores one
    with zipfile.ZipFile(fmu, "w") as z:
        z.writestr(link, str(tmp_path / "victim"))
    folder = fmu_unpack.unpacked(fmu)
    made = folder / "binaries" / "link.so"
    assert made.is_file() and not made.is_symlink()
    assert fmu_unpack.unpacked(fmu) == folder             # once per content and process


def test_stale_folders_of_dead_processes_go_on_the_next_load(hostile, tmp_path):
    """A `cosim-fmu-PID-*` folder of a process that is gone is removed when
    an FMU is next loaded; one of a live process stays."""
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    stale = tmp / f"cosim-fmu-{dead.pid}-abc123"
    (stale / "binaries").mkdir(parents=True)
    (stale / "binaries" / "lib.so").write_bytes(b"x")
    live = tmp / f"cosim-fmu-{os.getpid()}-def456"
    live.mkdir()
    other = tmp / "cosim-fmu-notapid"
    other.mkdir()
    out = tmp_path / "run"
    done = subprocess.run(_run_args(hostile("error"), out, "--set", "t_end=0.001"),
                          capture_output=True, text=True, env=_env(tmp), timeout=120)
    assert done.returncode == 0, done.stderr
    assert not stale.exists()
    assert live.is_dir() and other.is_dir()


def test_the_unpack_limit_variable_is_checked(monkeypatch):
    from cosim.sides import fmu_unpack
    monkeypatch.delenv(fmu_unpack.UNPACK_LIMIT_ENV, raising=False)
    assert fmu_unpack.unpack_limit() == 1 << 30             # docs/fmu.md: 1 GiB
    monkeypatch.setenv(fmu_unpack.UNPACK_LIMIT_ENV, "2G")
    assert fmu_unpack.unpack_limit() == 2 << 30
    monkeypatch.setenv(fmu_unpack.UNPACK_LIMIT_ENV, "lots")
    with pytest.raises(ValueError, match=r"COSIM_FMU_UNPACK_LIMIT must be a positive size in "
                                         r"bytes \(e.g. 2147483648 or 2G\), got 'lots'"):
        fmu_unpack.unpack_limit()


def test_a_sweep_removes_the_folder_of_a_worker_it_kills_on_timeout(hostile, tmp_path):
    """The one point hangs; the sweep kills its worker at the time limit (no
    exit handler runs there) and removes the FMU folder the worker left."""
    tmp = tmp_path / "tmp"
    done = subprocess.run(_cosim("sweep", str(FMU_SCENE), "--set",
                                 f"subsystems.arm.path={hostile('hang')}", "--set",
                                 f"t_end={T_END}", "--timeout", "8", "--out",
                                 str(tmp_path / "sweep")),
                          capture_output=True, text=True, env=_env(tmp), timeout=120)
    assert done.returncode == 1, done.stderr
    assert "timeout" in done.stdout and "ran past the time limit of 8 s" in done.stdout
    assert not list(tmp.glob("cosim-fmu-*"))
    # the killed worker's FMU host (hung in doStep, deaf to SIGTERM) ends on its own
    deadline = time.monotonic() + 10
    while _processes_with(f"TMPDIR={tmp}") and time.monotonic() < deadline:
        time.sleep(0.2)
    assert not _processes_with(f"TMPDIR={tmp}")


def _processes_with(entry: str) -> list[int]:
    """The live processes whose environment holds ``entry``."""
    found = []
    for env in Path("/proc").glob("[0-9]*/environ"):
        try:
            if entry.encode() in env.read_bytes().split(b"\0"):
                state = (env.parent / "stat").read_text().rsplit(")", 1)[1].split()[0]
                if state != "Z":
                    found.append(int(env.parent.name))
        except OSError:
            continue
    return found

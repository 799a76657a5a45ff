"""A sweep's folder and arguments as a hostile or careless user leaves them:
links planted where the sweep writes, two sweeps into one folder, point
folders whose inputs changed or whose files are damaged, grids of a million
points, and arguments that repeat or overflow.

The points are spring_drop run for 1 ms (before the mass reaches the wall):
a few milliseconds each.
"""
import csv
import io
import json
import signal
import subprocess
import sys
import time
import tracemalloc
import zipfile

import numpy as np
import pytest

from conftest import CASES, ROOT
from sweeping import Events
from cosim import cli
from cosim.studies import sweep as sw

SPRING_DROP = CASES / "spring_drop.toml"
EXAMPLES = ROOT / "examples"
#: the points of most tests: spring_drop for 1 and 2 ms
SHORT = {"t_end": [0.001, 0.002]}
#: what a test waits for a `cosim` process at most [s]
LIMIT = 120


def table(out):
    with open(out / sw.TABLE, newline="") as fh:
        return {r["point"]: r for r in csv.DictReader(fh)}


_STARTED: list = []


def cosim(*args, **kw):
    proc = subprocess.Popen([sys.executable, "-m", "cosim.cli", *map(str, args)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            cwd=ROOT, **kw)
    _STARTED.append(proc)
    return proc


@pytest.fixture(autouse=True)
def _no_process_outlives_its_test():
    """A test that fails while its sweep still runs (a timeout) kills it, so
    that it does not eat a core under the tests that follow."""
    yield
    while _STARTED:
        proc = _STARTED.pop()
        if proc.poll() is None:
            proc.kill()
            proc.communicate()


def many(first: int, n: int, exponent: int) -> str:
    """``n`` distinct numbers ``first e-exponent``, ``first+1 e-exponent``,
    ... as one ``--set`` value list."""
    return ",".join(f"{first + i}e-{exponent}" for i in range(n))


# ------------------------------------------------------------ planted links
def test_links_planted_at_the_table_and_the_figure_are_replaced_not_followed(tmp_path, capsys):
    pytest.importorskip("matplotlib")
    out, victims = tmp_path / "sw", tmp_path / "victims"
    out.mkdir()
    victims.mkdir()
    for name in (sw.PLOT, sw.TABLE):
        (victims / name).write_text("keep me")
        (out / name).symlink_to(victims / name)
    missing = victims / "new.png"
    code = cli.main(["sweep", str(SPRING_DROP), "--set", "t_end=0.001", "--workers", "1",
                     "--quiet", "--out", str(out)])
    assert code == 0, capsys.readouterr()
    for name in (sw.PLOT, sw.TABLE):
        assert (victims / name).read_text() == "keep me"
        assert not (out / name).is_symlink()
    assert (out / sw.PLOT).read_bytes()[:4] == b"\x89PNG"
    assert list(table(out)) == ["undamped,t_end=0.001"]
    assert not missing.exists()


def test_a_point_folder_planted_as_a_link_is_refused_and_its_target_untouched(tmp_path,
                                                                               capsys):
    out, victim = tmp_path / "sw", tmp_path / "victim"
    out.mkdir()
    victim.mkdir()
    (out / "undamped,t_end=0.001").symlink_to(victim)
    # and in a real point folder, links planted at the files a point writes
    planted = out / "undamped,t_end=0.002"
    planted.mkdir()
    for name in ("point.json", "scene.toml", "series.npz", "summary.json"):
        (victim.parent / f"victim-{name}").write_text("keep me")
        (planted / name).symlink_to(victim.parent / f"victim-{name}")
    code = cli.main(["sweep", str(SPRING_DROP), "--set", "t_end=0.001,0.002", "--workers", "1",
                     "--quiet", "--no-plot", "--out", str(out)])
    text = capsys.readouterr().out
    assert code == 1, text
    assert list(victim.iterdir()) == []
    assert (out / "undamped,t_end=0.001").is_symlink()
    rows = table(out)
    refused = rows["undamped,t_end=0.001"]
    assert refused["status"] == "error"
    assert "is a symbolic link or not a folder" in refused["message"], refused
    assert rows["undamped,t_end=0.002"]["status"] == "finished"
    for name in ("point.json", "scene.toml", "series.npz", "summary.json"):
        assert (victim.parent / f"victim-{name}").read_text() == "keep me"
        assert not (planted / name).is_symlink()
    assert json.loads((planted / "point.json").read_text())["status"] == "finished"


def test_a_second_sweep_into_a_folder_in_use_is_refused(tmp_path, capsys):
    """A sweep holds its folder's lock from its first point to its figure; a
    second sweep (here this test holding the lock) is refused before it runs
    anything."""
    from cosim.io.rundir import OutputFolder
    out = tmp_path / "sw"
    with OutputFolder(out):
        code = cli.main(["sweep", str(SPRING_DROP), "--set", "t_end=0.001", "--workers", "1",
                         "--quiet", "--no-plot", "--out", str(out)])
        err = capsys.readouterr().err
        assert code == 2
        assert "is in use by another run" in err and "Traceback" not in err
        assert sorted(p.name for p in out.iterdir()) == [".run.lock"]


# ----------------------------------------------------------------- resume
def test_a_point_that_ran_with_another_cosim_runs_again(tmp_path, monkeypatch):
    import cosim
    old = cosim.__version__
    sw.sweep(SPRING_DROP, grid=SHORT, out=tmp_path)
    same = Events()
    sw.sweep(SPRING_DROP, grid=SHORT, out=tmp_path, progress=same)
    assert len(same.skipped) == 2 and not same.ran
    monkeypatch.setattr(cosim, "__version__", "99.0.0")
    newer = Events()
    sw.sweep(SPRING_DROP, grid=SHORT, out=tmp_path, progress=newer)
    assert len(newer.ran) == 2 and not newer.skipped
    assert set(newer.notes.values()) == {f"run again: it ran with cosim {old}, this is 99.0.0"}
    assert json.loads((tmp_path / newer.ran[0] / "point.json").read_text())["cosim"] == "99.0.0"


@pytest.fixture(scope="module")
def two_fmus(fmus):
    """Two builds of the example arm FMU (with and without FMU state): two
    different files that the same scene accepts."""
    return fmus[(2, True)], fmus[(2, False)]


def test_a_point_whose_fmu_changed_runs_again(tmp_path, two_fmus, capsys):
    """The scene file is the same, the FMU it names is another: the point's
    old numbers are not reused."""
    first, other = two_fmus
    scene = tmp_path / "arm.toml"
    scene.write_text((EXAMPLES / "fmu" / "arm_on_beam.toml").read_text())
    (tmp_path / "arm2_fmi2.fmu").write_bytes(first.read_bytes())
    out = tmp_path / "sw"
    args = ["sweep", str(scene), "--set", "t_end=0.0005", "--workers", "1", "--no-plot",
            "--out", str(out)]
    assert cli.main(args) == 0, capsys.readouterr()
    capsys.readouterr()
    assert cli.main(args) == 0
    assert "1 done before (not run again)" in capsys.readouterr().out
    (tmp_path / "arm2_fmi2.fmu").write_bytes(other.read_bytes())
    assert cli.main(args) == 0
    captured = capsys.readouterr()
    assert "done before" not in captured.out
    assert "1 run again (their inputs changed or their folders were damaged)" in captured.out
    assert "run again: subsystems.arm.path = arm2_fmi2.fmu changed since it ran" in captured.err
    point = json.loads((out / "t_end=0.0005" / "point.json").read_text())
    digest = __import__("hashlib").sha256(other.read_bytes()).hexdigest()
    assert point["inputs"] == [["subsystems.arm.path = arm2_fmi2.fmu", digest]]


def _npz(members: dict, compress=zipfile.ZIP_STORED) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compress) as zf:
        for name, data in members.items():
            zf.writestr(f"{name}.npy", data)
    return buf.getvalue()


def _npy(a: np.ndarray, shape=None) -> bytes:
    buf = io.BytesIO()
    np.lib.format.write_array(buf, a, version=(1, 0))
    data = buf.getvalue()
    if shape is not None:                    # a header that claims another size
        data = data.replace(repr(a.shape).encode(), repr(shape).encode().ljust(
            len(repr(a.shape))), 1)
    return data


T = np.linspace(0.0, 1e-3, 11)
DAMAGE = {
    "series not a zip": ("series.npz", b"not a zip at all"),
    "series cut short": ("series.npz", None),
    "series member compressed": ("series.npz", _npz({"t": _npy(T), "dq/body/x": _npy(T)},
                                                    zipfile.ZIP_DEFLATED)),
    "series header claims 10**12 values": ("series.npz", _npz(
        {"t": _npy(T, (10 ** 12,)), "dq/body/x": _npy(T)})),
    "series 2-D t": ("series.npz", _npz({"t": _npy(np.zeros((3, 3))),
                                          "dq/body/x": _npy(T)})),
    "summary a list": ("summary.json", b"[]"),
    "summary a string": ("summary.json", b'"x"'),
    "summary contacts a string": ("summary.json", b'{"status": "finished", "contacts": "zzz"}'),
    "summary nested deep": ("summary.json", b"[" * 100_000 + b"]" * 100_000),
    "summary missing": ("summary.json", ...),
    "point a list": ("point.json", b"[]"),
    "point a string": ("point.json", b'"x"'),
    "point not JSON": ("point.json", b"{"),
}


@pytest.mark.parametrize("case", list(DAMAGE))
def test_a_damaged_point_folder_runs_again(tmp_path, case):
    name, data = DAMAGE[case]
    sw.sweep(SPRING_DROP, grid=SHORT, out=tmp_path)
    point = tmp_path / "undamped,t_end=0.001"
    target = point / name
    if data is None:
        target.write_bytes(target.read_bytes()[:200])
    elif data is ...:
        target.unlink()
    else:
        target.write_bytes(data)
    again = Events()
    rows = sw.sweep(SPRING_DROP, grid=SHORT, out=tmp_path, progress=again)
    assert again.ran == [point.name] and again.skipped == ["undamped,t_end=0.002"]
    assert [r["status"] for r in rows] == ["finished", "finished"]
    assert again.notes[point.name].startswith(f"run again: its {name} "), again.notes
    # mended: the next sweep reads it back
    third = Events()
    sw.sweep(SPRING_DROP, grid=SHORT, out=tmp_path, progress=third)
    assert not third.ran


# ------------------------------------------------------------ large grids
def test_a_grid_is_made_one_point_at_a_time():
    """A million points cost what their values cost: the grid is a product,
    and point i is made from i when asked for."""
    tracemalloc.start()
    try:
        grid = sw.grid_points(["a", "b"], {"x": list(range(1000)), "y": list(range(500))})
        assert len(grid) == 1_000_000
        last = grid[-1]
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 2_000_000, peak          # a million points built would take ~500 MB
    assert (last.index, last.variant, last.params) == (999_999, "b", (("x", 999), ("y", 499)))
    assert grid[1234].params == (("x", 2), ("y", 234))
    assert [p.index for p in grid[:3]] == [0, 1, 2]
    with pytest.raises(ValueError, match="a sweep runs at most"):
        sw.grid_points(None, {"x": list(range(100_000)), "y": list(range(100_000))})


def test_a_grid_of_a_million_points_needs_yes(tmp_path):
    out = tmp_path / "sw"
    proc = cosim("sweep", SPRING_DROP, "--set", f"t_end={many(1000, 1000, 6)}",
                 "--set", f"scheme.macro_step={many(1000, 1000, 7)}", "--out", out)
    stdout, stderr = proc.communicate(timeout=LIMIT)
    assert proc.returncode == 2, stderr
    assert stderr.startswith("error: the sweep has 1000000 points, more than 10000"), stderr
    assert "--yes" in stderr and "Traceback" not in stderr
    assert not out.exists()


def test_a_grid_of_a_million_points_starts_at_once_and_stops_on_ctrl_c(tmp_path):
    out = tmp_path / "sw"
    proc = cosim("sweep", SPRING_DROP, "--set", f"t_end={many(1000, 1000, 6)}",
                 "--set", f"scheme.macro_step={many(1000, 1000, 7)}", "--yes", "--workers",
                 "1", "--quiet", "--no-plot", "--out", out)
    first = proc.stdout.readline()
    assert "1000000 point(s)" in first, first + proc.stderr.read()
    t0 = time.monotonic()
    while not any(out.glob("*/point.json")):       # points run: none waits for the others
        assert time.monotonic() - t0 < 60 and proc.poll() is None, proc.stderr.read()
        time.sleep(0.1)
    time.sleep(1.0)
    proc.send_signal(signal.SIGINT)
    t0 = time.monotonic()
    stdout, stderr = proc.communicate(timeout=LIMIT)
    assert time.monotonic() - t0 < 20, "the sweep took long to stop"
    assert proc.returncode == 130, stderr
    assert "Traceback" not in stderr
    rows = table(out)
    finished = [r for r in rows.values() if r["status"] == "finished"]
    assert finished and len(rows) < 10_000
    assert set(r["status"] for r in rows.values()) <= {"finished", "interrupted"}
    assert f"({1_000_000 - len(rows)} never started are left out)" in stderr, stderr


# ----------------------------------------------------------- arguments
@pytest.mark.parametrize("args,essence", [
    (["--set", "t_end=0.001,0.001"], "grid key `t_end` repeats the value 0.001"),
    (["--set", "t_end=1e-3,0.001"], "grid key `t_end` repeats the value 0.001"),
    (["--set", "t_end=1,1.0"], "grid key `t_end` repeats the value 1.0"),
    (["--set", 'contacts.wall.law.type="linear",linear'], "repeats the value linear"),
    (["--variants", "undamped,undamped"], "`variants` repeats a name: 'undamped'"),
    (["--timeout", "1e300"], "`--timeout` must be at most 1e+06 s (11.6 days), got 1e+300"),
    (["--timeout", "0"], "`--timeout` must be > 0 s, got 0.0"),
    (["--timeout", "-1"], "`--timeout` must be > 0 s, got -1.0"),
    (["--timeout", "nan"], "`--timeout` must be > 0 s, got nan"),
    (["--workers", "0"], "`--workers` must be a whole number >= 1, got 0"),
    (["--workers", "-3"], "`--workers` must be a whole number >= 1, got -3"),
])
def test_a_bad_sweep_argument_is_refused(tmp_path, capsys, args, essence):
    out = tmp_path / "sw"
    code = cli.main(["sweep", str(SPRING_DROP), "--no-plot", "--out", str(out), *args])
    err = capsys.readouterr().err
    assert code == 2
    assert err.startswith("error: ") and essence in err, err
    assert not out.exists()


@pytest.mark.parametrize("text,essence", [
    ('variants = ["undamped", "undamped"]\n', "`variants` repeats 'undamped'"),
    ('[set]\nt_end = [0.001, 0.001]\n', "`set.t_end` repeats the value 0.001"),
    ('timeout = 1e300\n', "`timeout` must be at most 1e+06 s"),
])
def test_a_study_that_repeats_or_overflows_is_refused(tmp_path, capsys, text, essence):
    study = tmp_path / "study.toml"
    study.write_text(f'scene = "{SPRING_DROP.as_posix()}"\n{text}')
    code = cli.main(["sweep", "--study", str(study), "--no-plot", "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert code == 2
    assert err.startswith(f"error: {study}: ") and essence in err, err
    assert not (tmp_path / "o").exists()


def test_the_library_refuses_bad_workers_and_timeouts(tmp_path):
    for kw, match in (({"workers": 0}, "`workers` must be a whole number >= 1"),
                      ({"workers": 2.5}, "`workers` must be a whole number >= 1"),
                      ({"timeout": 1e300}, "`timeout` must be at most"),
                      ({"timeout": float("nan")}, "`timeout` must be > 0 s")):
        with pytest.raises(ValueError, match=match):
            sw.sweep(SPRING_DROP, grid=SHORT, out=tmp_path / "o", **kw)
    assert not (tmp_path / "o").exists()

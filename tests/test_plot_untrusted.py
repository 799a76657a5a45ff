"""`cosim plot` on a run folder from someone else: damaged or hostile files
give a clear error (exit 2, the file and what is wrong) with memory bounded
before anything is unpacked; links planted where plot writes are replaced,
never followed; and animating never loads the code of an FMU the run's
scene names.

Each damaged folder is a copy of one real run, damaged here."""
from __future__ import annotations

import importlib.util
import io
import shutil
import subprocess
import sys
import zipfile

import numpy as np
import pytest

from conftest import CASES, ROOT
from cosim import cli

pytest.importorskip("matplotlib")

PNG = b"\x89PNG\r\n\x1a\n"
FIGURES = ("penetration", "force", "joint_velocity", "energy")


@pytest.fixture(scope="module")
def spring_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("runs") / "spring_drop"
    assert cli.main(["run", str(CASES / "spring_drop.toml"), "--variant", "kelvin_voigt",
                     "--out", str(out), "--quiet"]) == 0
    return out


@pytest.fixture
def run(spring_run, tmp_path):
    """A copy of the run, to damage."""
    return shutil.copytree(spring_run, tmp_path / "run")


def _series(run) -> dict:
    with np.load(run / "series.npz") as npz:      # the run's own file, written by cosim
        return {k: npz[k] for k in npz.files}


def _npy(a) -> bytes:
    buf = io.BytesIO()
    np.lib.format.write_array(buf, np.asanyarray(a), allow_pickle=True)
    return buf.getvalue()


def _write_npz(path, members: dict, compression=zipfile.ZIP_STORED) -> None:
    """``members``: name -> array, or raw .npy bytes."""
    with zipfile.ZipFile(path, "w", compression) as zf:
        for name, value in members.items():
            zf.writestr(f"{name}.npy", value if isinstance(value, bytes) else _npy(value))


def _replace(run, **changed) -> None:
    """Rewrite the run's series.npz with some arrays changed (``gap__wall``
    for ``gap/wall``)."""
    series = _series(run)
    series.update({k.replace("__", "/"): v for k, v in changed.items()})
    _write_npz(run / "series.npz", series)


def _refused(capsys, run, essence, *more):
    """`cosim plot RUN` ends with exit 2 and one error line naming the file
    and the essence, and writes no figure."""
    assert cli.main(["plot", str(run), *more]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and essence in err, err
    assert len(err.strip().splitlines()) == 1, err
    assert not any(run.glob("*.png")), sorted(run.iterdir())
    return err


# ------------------------------------------------------------ series.npz
def test_corrupt_deflate_stream(run, capsys):
    series = _series(run)
    _write_npz(run / "series.npz", series, zipfile.ZIP_DEFLATED)
    raw = bytearray((run / "series.npz").read_bytes())
    with zipfile.ZipFile(run / "series.npz") as zf:
        info = zf.getinfo("t.npy")
    start = info.header_offset + 30 + len(info.filename) + len(info.extra)
    middle = start + info.compress_size // 2
    raw[middle:middle + 64] = b"\xff" * 64           # the deflate stream breaks mid-member
    (run / "series.npz").write_bytes(bytes(raw))
    _refused(capsys, run, "series.npz: array `t` is damaged and cannot be unpacked")


def test_zero_dimensional_member(run, capsys):
    _replace(run, gap__wall=np.array(0.5))
    _refused(capsys, run, "series.npz: array `gap/wall` must be a one-dimensional array "
                          "(one value per sample), got shape ()")


def test_two_dimensional_time(run, capsys):
    t = _series(run)["t"]
    _replace(run, t=np.stack([t, t]))
    _refused(capsys, run, "series.npz: array `t` must be a one-dimensional array")


def test_string_time(run, capsys):
    _replace(run, t=np.array(["a", "b", "c"]))
    _refused(capsys, run, "series.npz: array `t` holds values of type <U1; a series holds "
                          "numbers")


def _header(descr: str, shape: tuple) -> bytes:
    """A hand-made .npy 1.0 header (magic, length, dictionary), padded."""
    text = f"{{'descr': '{descr}', 'fortran_order': False, 'shape': {shape!r}, }}"
    text += " " * (63 - (10 + len(text)) % 64) + "\n"
    return b"\x93NUMPY\x01\x00" + len(text).to_bytes(2, "little") + text.encode("latin1")


def test_header_declaring_a_trillion_values(run, capsys):
    series = _series(run)
    series["t"] = _header("<f8", (10 ** 12,)) + series["t"].tobytes()
    _write_npz(run / "series.npz", series)
    _refused(capsys, run, "array `t` declares 1000000000000 values (7.28 TiB), but its "
                          "member holds")


def test_compression_bomb_is_refused_before_unpacking(run, capsys):
    """A member of 256 MiB of zeros deflates to a quarter of a MiB: its
    declared size is refused against the archive's before it is unpacked."""
    n = 32 * 2**20                                    # float64 zeros: 256 MiB
    with zipfile.ZipFile(run / "series.npz", "w", zipfile.ZIP_DEFLATED) as zf:
        info = zipfile.ZipInfo("t.npy")
        info.compress_type = zipfile.ZIP_DEFLATED
        with zf.open(info, "w", force_zip64=True) as fh:
            fh.write(_header("<f8", (n,)))
            zeros = bytes(2**22)
            for _ in range(n * 8 // len(zeros)):
                fh.write(zeros)
        zf.writestr("gap/wall.npy", _npy(np.zeros(3)))
    size = (run / "series.npz").stat().st_size
    assert size < 2**20
    err = _refused(capsys, run, "series.npz: its members declare 256 MiB unpacked, more "
                                "than the")
    assert "a plot unpacks from an archive of" in err


def test_series_npz_that_is_not_a_zip(run, capsys):
    (run / "series.npz").write_bytes(b"\x80\x04K\x01." + b"not an archive" * 10)
    err = _refused(capsys, run, "series.npz: is not a zip archive")
    assert "allow_pickle" not in err


def test_pickled_member_is_never_unpickled(run, capsys, tmp_path):
    """An object array's member names its type and is refused; the pickle
    it carries (which would create a file when loaded) is not loaded."""
    marker = tmp_path / "unpickled"
    series = _series(run)
    series["gap/wall"] = _npy(np.array([_Opens(marker)] * 3, dtype=object))
    _write_npz(run / "series.npz", series)
    _refused(capsys, run, "array `gap/wall` holds values of type object")
    assert not marker.exists()
    np.load(io.BytesIO(series["gap/wall"]), allow_pickle=True)   # it would have
    assert marker.exists()


class _Opens:
    """Unpickled, opens (creates) a file."""

    def __init__(self, path):
        self.path = str(path)

    def __reduce__(self):
        return (open, (self.path, "w"))


def test_values_that_are_not_finite_are_left_out(run, capsys):
    s = _series(run)
    gap, energy = s["gap/wall"].copy(), s["energy/total"].copy()
    gap[5], gap[7], energy[3] = np.inf, -np.inf, np.nan
    _replace(run, gap__wall=gap, energy__total=energy)
    assert cli.main(["plot", str(run)]) == 0
    out = capsys.readouterr().out
    assert "note: 2 series hold values that are not finite, left out of the lines drawn: " \
           "gap/wall, energy/total" in out
    for name in FIGURES:
        assert (run / f"{name}.png").read_bytes()[:8] == PNG


def test_time_that_is_not_finite_is_refused(run, capsys):
    t = _series(run)["t"].copy()
    t[4] = np.nan
    _replace(run, t=t)
    _refused(capsys, run, "series.npz: array `t` must hold finite times [s], got nan at "
                          "sample 4")


def test_many_contacts_and_tex_in_names(run, capsys):
    """Four hundred contacts draw a figure of twelve panels, not an image too
    large to make; a name holding `$` is text, not a formula to parse."""
    s = _series(run)
    for k in range(400):
        s[f"gap/c{k}"], s[f"force/c{k}"] = s["gap/wall"], s["force/wall"]
    s["gap/$\\frac{"], s["force/$\\frac{"] = s["gap/wall"], s["force/wall"]
    _write_npz(run / "series.npz", s)
    (run / "summary.json").unlink()
    assert cli.main(["plot", str(run)]) == 0
    from cosim import plot
    from cosim.plot import figures
    fig = figures._force_figure(plot.load_run(run))
    assert len(fig.get_axes()) == 12
    assert "(12 of 402 shown)" in fig._suptitle.get_text()
    assert (run / "force.png").read_bytes()[:8] == PNG


# ---------------------------------------------------------- summary.json
@pytest.mark.parametrize("text, essence", [
    ("[]", "`the top level` must be an object, got an array []"),
    ('"x"', "`the top level` must be an object, got a string 'x'"),
    ('{"contacts": "zzz"}', "`contacts` must be an object, got a string 'zzz'"),
    ('{"contacts": {"wall": {"peak_penetration": "zzz"}}}',
     "`contacts.wall.peak_penetration` must be a number or null, got a string 'zzz'"),
    ('{"contacts": {"wall": {"intervals": [[0.01, "x"]]}}}',
     "`contacts.wall.intervals` must be an array of [start, end] finite times [s]"),
    ('{"energy": {"max_abs_drift": [1]}}', "`energy.max_abs_drift` must be a number or null"),
    ("[" * 100_000 + "]" * 100_000, "is nested too deep to be a run's summary"),
    ('{"status": "fin', "is not JSON"),
], ids=["list", "string", "contacts-string", "peak-string", "interval", "drift", "deep",
        "cut"])
def test_bad_summary(run, capsys, text, essence):
    (run / "summary.json").write_text(text)
    _refused(capsys, run, f"summary.json: {essence}")


# ------------------------------------------------------------ arguments
def test_out_naming_a_file_or_a_missing_parent(run, capsys, tmp_path):
    afile = tmp_path / "afile"
    afile.write_text("keep")
    assert cli.main(["plot", str(run), "--out", str(afile)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and f"{afile}: it exists and is not a folder" in err
    assert afile.read_text() == "keep"
    deep = tmp_path / "missing" / "parent" / "pictures"
    assert cli.main(["plot", str(run), "--out", str(deep)]) == 0
    assert (deep / "force.png").read_bytes()[:8] == PNG


@pytest.mark.parametrize("option, value, essence", [
    ("--frames", "0", "argument --frames: must be at least 2"),
    ("--frames", "-3", "argument --frames: must be at least 2"),
    ("--magnify", "nan", "argument --magnify: must be a finite number > 0, got 'nan'"),
    ("--magnify", "inf", "argument --magnify: must be a finite number > 0, got 'inf'"),
    ("--magnify", "-1", "argument --magnify: must be a finite number > 0, got '-1'"),
])
def test_animation_options_out_of_range(run, capsys, option, value, essence):
    with pytest.raises(SystemExit) as exc:
        cli.main(["plot", str(run), "--animate", option, value])
    assert exc.value.code == 2
    assert essence in capsys.readouterr().err
    assert not any(run.glob("*.png")) and not any(run.glob("animation.*"))


def test_library_animation_checks_its_options(spring_run):
    from cosim.plot import animate_run
    for kw, essence in (({"max_frames": 0}, "`max_frames` must be a whole number >= 2"),
                        ({"magnify": float("nan")}, "`magnify` must be a finite number > 0"),
                        ({"fps": 0}, "`fps` must be a whole number from 1 to 1000")):
        with pytest.raises(ValueError, match=essence):
            animate_run(spring_run, **kw)


# ---------------------------------------------------------- planted links
def _writer_available():
    from matplotlib import animation
    return animation.writers.is_available("pillow") or animation.writers.is_available("ffmpeg")


def test_links_planted_where_plot_writes_are_replaced(run, capsys, tmp_path):
    """A link at every name plot writes, to a victim file or to a file not
    there yet: each is replaced by the figure, no victim is touched, no new
    file is made through a link."""
    animate = _writer_available()
    names = [f"{n}.png" for n in FIGURES] + (["animation.gif", "animation.mp4"]
                                             if animate else [])
    victims = {}
    for k, name in enumerate(names):
        if k % 2:                                         # a link to a file not there yet
            target = tmp_path / f"new-{name}"
        else:
            target = tmp_path / f"victim-{name}"
            target.write_text(f"victim {k}")
        (run / name).symlink_to(target)
        victims[name] = target
    assert cli.main(["plot", str(run), *(["--animate", "--frames", "4"] if animate else [])]
                    ) == 0
    out = capsys.readouterr().out
    for k, (name, target) in enumerate(victims.items()):
        if k % 2:
            assert not target.exists(), name
        else:
            assert target.read_text() == f"victim {k}", name
        if f"wrote {run / name}" in out:                  # a file plot wrote
            assert not (run / name).is_symlink() and (run / name).is_file(), name
            assert (run / name).read_bytes()[:3] in (PNG[:3], b"GIF"), name
    written = [n for n in names if f"wrote {run / n}" in out]
    assert set(written) >= {f"{n}.png" for n in FIGURES}
    assert not animate or "animation.gif" in written or "animation.mp4" in written
    assert not list(run.glob(".*.tmp")) and not (run / ".run.lock").exists()


def test_out_folder_that_is_a_link_is_refused(run, capsys, tmp_path):
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (tmp_path / "pictures").symlink_to(elsewhere)
    assert cli.main(["plot", str(run), "--out", str(tmp_path / "pictures")]) == 2
    assert "it is a symbolic link" in capsys.readouterr().err
    assert list(elsewhere.iterdir()) == []


def test_plot_holds_the_folders_lock(run, capsys):
    """A folder a run is writing into (its lock held) is not written."""
    from cosim.io.rundir import RunLock
    with RunLock(run):
        assert cli.main(["plot", str(run)]) == 2
    assert "is in use by another run" in capsys.readouterr().err
    assert not any(run.glob("*.png"))


# ------------------------------------------------------- no code of a side
def _fmu_build():
    spec = importlib.util.spec_from_file_location("fmu_build",
                                                  ROOT / "examples" / "fmu" / "build.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


_CONSTRUCTOR = r"""
#include <stdio.h>
__attribute__((constructor)) static void planted(void) {
    FILE *f = fopen("%s", "w");
    if (f) { fputs("ran", f); fclose(f); }
}
"""


def _hostile_fmu(fmu, dest, marker, cc):
    """A copy of ``fmu`` whose binary is a library with a constructor that
    writes ``marker`` when loaded."""
    src = dest.parent / "planted.c"
    src.write_text(_CONSTRUCTOR % marker)
    lib = dest.parent / "planted.so"
    subprocess.run([cc, "-shared", "-fPIC", str(src), "-o", str(lib)], check=True,
                   capture_output=True)
    with zipfile.ZipFile(fmu) as zin, zipfile.ZipFile(dest, "w") as zout:
        for info in zin.infolist():
            data = zin.read(info)
            if info.filename.startswith("binaries/"):
                data = lib.read_bytes()
            zout.writestr(info, data)
    return lib


def test_animating_never_loads_the_fmu_a_run_names(tmp_path):
    """A run folder whose scene.toml names an FMU (relative to the folder)
    whose library runs code when loaded: plotting and animating draw the
    recorded series and the sides cosim computes, and the code never runs."""
    pytest.importorskip("fmpy", reason="FMPy is not installed (the `fmi` extra)")
    pytest.importorskip("skfem", reason="the beam needs scikit-fem (the `fem` extra)")
    build = _fmu_build()
    cc = build.find_compiler()
    if cc is None:
        pytest.skip("no C compiler found: the test FMU cannot be built")
    fmu = build.build_fmu(tmp_path / "fmu", 2, True, cc)
    run = tmp_path / "run"
    proc = subprocess.run([sys.executable, "-m", "cosim.cli", "run",
                           str(ROOT / "examples" / "fmu" / "arm_on_beam.toml"),
                           "--set", f"subsystems.arm.path={fmu}", "--set", "t_end=0.0155",
                           "--out", str(run), "--quiet", "--no-estimate"], capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    marker = tmp_path / "constructor-ran"
    lib = _hostile_fmu(fmu, run / "arm.fmu", marker, cc)
    text = (run / "scene.toml").read_text()
    assert f'path = "{fmu}"' in text
    (run / "scene.toml").write_text(text.replace(f'path = "{fmu}"', 'path = "arm.fmu"'))

    proc = subprocess.run([sys.executable, "-m", "cosim.cli", "plot", str(run), "--animate",
                           "--frames", "4", "--out", str(tmp_path / "pictures")],
                          capture_output=True, text=True, timeout=300)
    assert not marker.exists(), f"the FMU's library was loaded: {proc.stderr}"
    assert proc.returncode == 0, proc.stderr
    written = {p.name for p in (tmp_path / "pictures").iterdir()}
    assert {"penetration.png", "structure.png"} <= written
    assert written & {"animation.gif", "animation.mp4"} or not _writer_available()

    from cosim import plot
    from cosim.plot.scene_geometry import scene_geometry
    geo = scene_geometry(plot.load_run(run).scene, run / "scene.toml")
    assert geo.names == ("arm", "beam") and geo.not_drawn == ("arm",)
    assert geo.subsystems[0] is None and geo.subsystems[1].structure is not None
    assert [(ln.name, ln.port_a, ln.port_b) for ln in geo.links] == [("C", None, 0)]

    # the library is hostile indeed: loaded, it writes the marker
    subprocess.run([sys.executable, "-c", f"import ctypes; ctypes.CDLL({str(lib)!r})"],
                   check=True, timeout=60)
    assert marker.read_text() == "ran"

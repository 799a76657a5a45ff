"""Scene files and values that used to crash or hang the loader, and sizes the
limits allow but the machine cannot hold (issue 19).

Every case runs ``cosim`` as a user types it, in a fresh process with a time
limit of its own (a regression fails here, it does not hang the suite), and
checks the exit status, the whole message, and that nothing was written.
"""
import os
import re
import subprocess
import sys
import time

import numpy as np
import pytest

from conftest import CASES, ROOT
from cosim.io import tomlread
from cosim.scene.load import MAX_MEMORY, SceneError, load_scene, structure_memory

SPRING_DROP = CASES / "spring_drop.toml"
#: a refusal takes well under a second of its own; the process's start-up is
#: most of this bound, on a busy machine
QUICK_S = 20


def cosim(*args, timeout=QUICK_S * 3):
    t0 = time.monotonic()
    proc = subprocess.run([sys.executable, "-m", "cosim.cli", *map(str, args)],
                          capture_output=True, text=True, cwd=ROOT, timeout=timeout)
    proc.seconds = time.monotonic() - t0
    return proc


def refused(tmp_path, scene, essence, *more):
    """``cosim run SCENE`` (and ``cosim info SCENE``) end with exit 2, one line
    naming the file and the rule, in time, and write nothing."""
    out = tmp_path / "out"
    for command in (["run", scene, "--out", out, *more], ["info", scene, *more]):
        proc = cosim(*command)
        assert proc.returncode == 2, proc.stderr
        assert proc.seconds < QUICK_S
        line = proc.stderr.strip()
        assert "\n" not in line and "Traceback" not in line, proc.stderr
        assert line.startswith(f"error: {scene}: ") and essence in line, line
        assert proc.stdout == ""
    assert not out.exists()
    return line


# ------------------------------------------------------------- what is read
def test_latin1_scene(tmp_path):
    scene = tmp_path / "latin1.toml"
    scene.write_bytes(SPRING_DROP.read_bytes().replace(b'name = "spring_drop"',
                                                       b'name = "caf\xe9"'))
    line = refused(tmp_path, scene, "must be UTF-8 text (TOML is), got byte 0xe9 at line 4, "
                                    "column 12")
    assert line == (f"error: {scene}: must be UTF-8 text (TOML is), got byte 0xe9 at line 4, "
                    f"column 12")


def test_random_bytes(tmp_path):
    scene = tmp_path / "noise.toml"
    scene.write_bytes(np.random.default_rng(19).integers(0, 256, 4000, np.uint8).tobytes())
    refused(tmp_path, scene, "must be UTF-8 text (TOML is), got byte 0x")


@pytest.mark.parametrize("opening,closing", [("[", "]"), ("{x = ", "}")])
def test_nesting_thousands_deep(tmp_path, opening, closing):
    scene = tmp_path / "deep.toml"
    scene.write_text("t_end = 1.0\nname = " + opening * 5000 + "1" + closing * 5000 + "\n")
    refused(tmp_path, scene, "must nest at most 32 levels of tables and arrays "
                             "(`cosim.io.tomlread.MAX_DEPTH`), got more than 32 nested arrays or "
                             "inline tables at line 2")


def test_a_dotted_key_of_20000_parts(tmp_path):
    """40 KB that took tomllib 6 s and 1.6 GB."""
    scene = tmp_path / "dotted.toml"
    scene.write_text("t_end = 1.0\n" + "x" + ".x" * 20000 + " = 1\n")
    assert scene.stat().st_size > 40_000
    refused(tmp_path, scene, "must nest at most 32 levels of tables and arrays "
                             "(`cosim.io.tomlread.MAX_DEPTH`), got a dotted key of more than 32 "
                             "parts at line 2")


def test_a_table_header_of_many_parts(tmp_path):
    scene = tmp_path / "header.toml"
    scene.write_text("t_end = 1.0\n[" + ".".join(["a"] * 1000) + "]\nb = 1\n")
    refused(tmp_path, scene, "got a table header of more than 32 parts at line 2")


def test_too_many_keys(tmp_path):
    scene = tmp_path / "keys.toml"
    scene.write_text("".join(f"k{i} = {i}\n" for i in range(20_000)))
    refused(tmp_path, scene, "must hold at most 10000 keys (`cosim.io.tomlread.MAX_KEYS`; each "
                             "part of a dotted key counts), got more by line 10001")


def test_inline_tables_whose_dotted_keys_nest_deeper_than_the_brackets(tmp_path):
    """Brackets and key parts each within the limit, their product not: the
    parsed tables are walked for the depth they really have."""
    key = ".".join(["a"] * 20)
    scene = tmp_path / "deep_keys.toml"
    scene.write_text(f"t_end = 1.0\nname = {{ {key} = {{ {key} = 1 }} }}\n")
    line = refused(tmp_path, scene, "must nest at most 32 levels of tables and arrays "
                                    "(`cosim.io.tomlread.MAX_DEPTH`), got deeper")
    assert f"error: {scene}: `name.{key}.a.a.a.a.a.a.a.a.a.a.a" in line


def test_dev_zero(tmp_path):
    refused(tmp_path, "/dev/zero", "must be a regular file, got a character device")


def test_a_fifo_does_not_hang(tmp_path):
    fifo = tmp_path / "scene.toml"
    os.mkfifo(fifo)
    refused(tmp_path, fifo, "must be a regular file, got a named pipe (FIFO)")


def test_a_directory(tmp_path):
    refused(tmp_path, tmp_path, "must be a regular file, got a directory")


def test_a_file_over_the_size_limit(tmp_path):
    scene = tmp_path / "huge.toml"
    with open(scene, "wb") as fh:                   # sparse: no disk is used
        fh.truncate(tomlread.MAX_BYTES + 1)
    refused(tmp_path, scene, f"must hold at most {tomlread.MAX_BYTES} bytes (64 MiB, "
                             f"`cosim.io.tomlread.MAX_BYTES`), got more")


def test_a_file_at_the_size_limit_is_read(tmp_path):
    scene = tmp_path / "padded.toml"
    text = SPRING_DROP.read_text()
    scene.write_text(text + "#" * (2**20 - len(text.encode())) + "\n")
    assert load_scene(scene).name == "spring_drop"


# ------------------------------------------------------------- --set values
@pytest.mark.parametrize("override,essence", [
    ("name=" + "[" * 5000, "`name` given with --set must nest at most 32 levels of tables and "
                           "arrays (`cosim.io.tomlread.MAX_DEPTH`), got more than 32 nested arrays "
                           "or inline tables at line 1"),
    ("x" + ".x" * 20000 + "=1", "a --set key must have at most 32 parts "
                                "(`cosim.io.tomlread.MAX_DEPTH`), got 20001"),
    ("name={" + ", ".join(f"k{i} = 1" for i in range(10_001)) + "}",
     "`name` given with --set must hold at most 10000 keys"),
], ids=["deep value", "long key", "many keys"])
def test_set_values(tmp_path, override, essence):
    out = tmp_path / "out"
    proc = cosim("run", SPRING_DROP, "--set", override, "--out", out)
    assert proc.returncode == 2 and proc.seconds < QUICK_S
    assert proc.stderr.startswith(f"error: {SPRING_DROP}: {essence}"), proc.stderr[:400]
    assert "Traceback" not in proc.stderr and not out.exists()


def test_an_override_reaching_too_deep_names_the_key():
    key = ".".join(["a"] * 20)
    with pytest.raises(SceneError, match=re.escape(
            f"`{key}.a.a.a.a.a.a.a.a.a.a.a.a.a` must nest at most 32 levels")):
        load_scene(SPRING_DROP, overrides=[f"{key}={{ {key} = 1 }}"])


# ------------------------------------------------------------------ the scan
@pytest.mark.parametrize("text", [
    'a = "[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[["',
    "a = '''\n" + "{" * 100 + "\n'''",
    'a = """\n' + "[" * 100 + '\\"""\n"""',
    "# " + "[" * 100 + "\na = 1",
    '"' + "." * 100 + '" = 1',
    "a = 1.5\nb = [1.5, 2.5, {c.d = 1.5}]\n[[e.f]]\ng = 1\n[[e.f]]\ng = 2\n",
])
def test_strings_comments_and_numbers_are_not_structure(text):
    tomlread.check_text(text)


def test_every_shipped_scene_and_study_is_within_the_limits():
    """Well within: 7 levels and 300 keys (the README says so)."""
    for path in sorted(CASES.glob("*.toml")) + sorted((ROOT / "studies").glob("*.toml")):
        tomlread.read_toml(path)
        text = path.read_text()
        tomlread.check_text(text, max_depth=7, max_keys=300)
        tomlread.check_depth(tomlread.loads(text), max_depth=7)


# ------------------------------------------------------------- what it needs
def test_a_chain_of_20000_masses_is_refused_before_it_is_built(tmp_path):
    """It built dense 20000 x 20000 matrices: a MemoryError traceback."""
    scene = tmp_path / "long_chain.toml"
    text = (CASES / "three_mass.toml").read_text()
    n = 20_000
    text = re.sub(r"(?m)^masses = \[.*$", "masses = [" + ", ".join(["0.15"] * n) + "]", text)
    text = re.sub(r"(?m)^stiffnesses = \[.*$",
                  "stiffnesses = [" + ", ".join(["1.6e5"] * n) + "]", text)
    scene.write_text(text)
    line = refused(tmp_path, scene, "`subsystems.chain.masses` makes a structure of 20000 DOFs "
                                    "whose model and modes need about 29.8 GiB (dense 20000 x "
                                    "20000 matrices), more than the 4 GiB a scene may use "
                                    "(`cosim.scene.load.MAX_MEMORY`)")
    assert line.endswith("(`cosim.scene.load.MAX_MEMORY`)")


def test_a_fine_beam_keeping_every_mode_is_refused_with_the_advice(tmp_path):
    proc = cosim("run", CASES / "beam_impact.toml", "--set", "subsystems.beam.elements=20000",
                 "--set", "subsystems.beam.modes={}", "--out", tmp_path / "o")
    assert proc.returncode == 2
    assert proc.stderr == (
        f"error: {CASES / 'beam_impact.toml'}: `subsystems.beam.elements` makes a structure of "
        f"40002 DOFs whose model and modes need about 119 GiB (dense 40002 x 40002 matrices "
        f"(every mode is kept: give `modes.count` or `modes.cutoff_hz`)), more than the 4 GiB "
        f"a scene may use (`cosim.scene.load.MAX_MEMORY`)\n")
    assert not (tmp_path / "o").exists()


def test_the_estimate_follows_the_measured_footprint():
    """Measured peak growth while building (`ru_maxrss`, three_mass with an n-mass
    chain): 287 MB at n = 2000; the estimate stays above it, within 2x."""
    n, nbytes, _ = structure_memory("chain", 2000, None, None)
    assert n == 2000 and 287e6 < nbytes < 2 * 287e6
    # a sparse solve of a few modes of a fine beam is cheap; so is a coarse one
    n, nbytes, why = structure_memory("beam", 20_000, 10, None)
    assert n == 40_002 and nbytes < 100e6 and why == "10 Lanczos vectors of 40002 DOFs"
    assert structure_memory("rod", 160, None, None)[1] < 30e6
    assert MAX_MEMORY == 4 * 2**30


def test_a_chain_keeping_a_few_of_its_modes_builds():
    """A chain of more than 400 masses (the dense eigensolver's limit) with
    `modes.count` went to the sparse solver with dense matrices: AttributeError."""
    n = 450
    system, _ = load_scene(CASES / "three_mass.toml", overrides=[
        f"subsystems.chain.masses=[{', '.join(['0.15'] * n)}]",
        f"subsystems.chain.stiffnesses=[{', '.join(['1.6e5'] * n)}]",
        "subsystems.chain.modes.count=4"]).build()
    chain = next(s for s in system.subsystems if s.name == "chain")
    assert chain.basis.kept == 4 and chain.basis.dropped == n - 4


def test_a_long_drive_table_is_converted_once(tmp_path):
    """Converted on every call, a table of a million points made 4 ms of
    simulated time take over two minutes.  Here 200 000 points over 30 ms
    (12 000 calls): converted on every call, about 0.02 s each, four minutes;
    converted once, seconds.  The limit of the process is a hang guard, far
    above what the run takes now and far below what it took."""
    n = 200_000
    times = np.linspace(0.0, 1.0, n)
    torques = 0.1 * np.sin(2 * np.pi * times)
    text = SPRING_DROP.read_text().replace(
        'joint = { name = "x", type = "prismatic", parent = "ground", axis = [1.0, 0.0], '
        'q0 = 0.01, dq0 = -1.0 }',
        '[subsystems.body.bodies.mass.joint]\nname = "x"\ntype = "prismatic"\n'
        'parent = "ground"\naxis = [1.0, 0.0]\nq0 = 0.01\ndq0 = -1.0\n'
        'drive = { type = "table", times = [' + ", ".join(map(repr, times.tolist()))
        + '], torques = [' + ", ".join(map(repr, torques.tolist())) + "] }")
    scene = tmp_path / "drive_table.toml"
    scene.write_text(text)
    out = tmp_path / "out"
    proc = cosim("run", scene, "--set", "t_end=0.03", "--out", out, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert "status finished" in proc.stdout
    assert (out / "summary.json").exists() and (out / "series.npz").exists()


def test_plot_reads_a_run_whose_scene_file_is_hostile(tmp_path):
    """`cosim plot` reads the run's scene.toml for its end time only: one that
    is not UTF-8 or nests thousands deep is passed over, not a traceback."""
    pytest.importorskip("matplotlib")
    out = tmp_path / "run"
    proc = cosim("run", SPRING_DROP, "--set", "t_end=0.012", "--out", out)
    assert proc.returncode == 0, proc.stderr
    for bad in (b"t_end = \xe9\n", b"t_end = " + b"[" * 5000 + b"\n"):
        (out / "scene.toml").write_bytes(bad)
        proc = cosim("plot", out, "--out", tmp_path / "pictures")
        assert proc.returncode == 0, proc.stderr
        assert "Traceback" not in proc.stderr
        assert any((tmp_path / "pictures").iterdir())

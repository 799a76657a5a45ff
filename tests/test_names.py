"""Names that become paths or keys (a scene's `name`, subsystems, contacts,
joints, variants) are plain words, checked when the scene is read; nothing a
scene names escapes the run folder, and nothing it holds drives the terminal.

Each case runs `cosim` as a user types it, in a fresh process, and looks at
the file system afterwards."""
import re
import subprocess
import sys
import tomllib

import pytest

from conftest import CASES, ROOT
from cosim.io.rundir import NAME_MAX, inside, name_problem
from cosim.errors import OutputError
from cosim.scene.load import SceneError, load_scene
from cosim.studies.sweep import load_study, point_name
from cosim.io.tomlwrite import dumps

SPRING_DROP = tomllib.loads((CASES / "spring_drop.toml").read_text())


def cosim(*args, cwd):
    return subprocess.run([sys.executable, "-m", "cosim.cli", *map(str, args)],
                          capture_output=True, text=True, cwd=cwd, timeout=300)


def tree(root):
    """Every path under ``root``, relative, as text."""
    return sorted(str(p.relative_to(root)) for p in root.rglob("*"))


def scene_file(folder, table, name="scene.toml"):
    path = folder / name
    path.write_text(dumps(table))
    return path


def spring_drop(**changes):
    table = tomllib.loads(dumps(SPRING_DROP))
    for key, value in changes.items():
        table[key] = value
    return table


def test_every_shipped_scene_variant_and_study_keeps_its_names():
    for path in sorted(CASES.glob("*.toml")):
        variants = tomllib.loads(path.read_text()).get("variants", {})
        for variant in [None, *variants]:
            load_scene(path, variant)
    for path in sorted((ROOT / "studies").glob("*.toml")):
        study = load_study(path)
        for variant in study.variants:
            assert name_problem(variant) is None
            load_scene(study.scene, variant)
    for name in ("mu0.03", "kA1e6", "ms0.05", "kelvin_voigt", "f100", "q10", "x" * NAME_MAX):
        assert name_problem(name) is None, name


@pytest.mark.parametrize("bad", ["../../../x", "/tmp/abs", "", "..", ".hidden", "a/b",
                                 "a..b", "-rf", "x" * (NAME_MAX + 1), "tab\tname"])
def test_a_scene_name_that_is_not_a_plain_word_is_refused(tmp_path, bad):
    work = tmp_path / "work"
    (work / "runs").mkdir(parents=True)
    path = scene_file(work, spring_drop(name=bad))
    before = tree(tmp_path)
    proc = cosim("run", path, cwd=work)
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.startswith(f"error: {path}: `name` must ")
    assert "Traceback" not in proc.stderr
    assert tree(tmp_path) == before                       # nothing written anywhere


def test_the_file_stem_is_held_to_the_rule_when_the_scene_gives_no_name(tmp_path):
    table = spring_drop()
    del table["name"]
    path = scene_file(tmp_path, table, "my scene.toml")
    proc = cosim("run", path, cwd=tmp_path)
    assert proc.returncode == 2
    assert proc.stderr == (f"error: {path}: `name` (a run folder's default name; the file's "
                           f"name when the scene gives none) must be a plain name (a name is "
                           f"1 to {NAME_MAX} of the characters A-Z a-z 0-9 _ . + -, does not "
                           f"start with . + or -, and holds no `..`), got 'my scene'\n")
    assert tree(tmp_path) == ["my scene.toml"]


def test_an_exported_structure_named_with_a_path_is_refused(tmp_path):
    table = tomllib.loads((CASES / "three_mass.toml").read_text())
    table["subsystems"]["../../outside"] = table["subsystems"].pop("chain")
    table["output"] = {"export": ["../../outside"]}
    path = scene_file(tmp_path, table)
    out = tmp_path / "deep" / "er" / "run"
    proc = cosim("run", path, "--out", out, cwd=tmp_path)
    assert proc.returncode == 2
    assert proc.stderr == (f"error: {path}: `subsystems` names a subsystem that must be a "
                           f"plain name (a name is 1 to {NAME_MAX} of the characters A-Z a-z "
                           f"0-9 _ . + -, does not start with . + or -, and holds no `..`), "
                           f"got '../../outside'\n")
    assert tree(tmp_path) == ["scene.toml"]


def test_a_joint_name_with_a_path_is_refused_before_it_becomes_a_zip_member(tmp_path):
    table = spring_drop()
    table["subsystems"]["body"]["bodies"]["mass"]["joint"]["name"] = "../../x"
    path = scene_file(tmp_path, table)
    proc = cosim("run", path, "--out", tmp_path / "o", cwd=tmp_path)
    assert proc.returncode == 2
    assert proc.stderr.startswith(
        f"error: {path}: `subsystems.body.bodies.mass.joint.name` must be a plain name")
    assert tree(tmp_path) == ["scene.toml"]


def test_a_variant_named_dot_dot_is_refused(tmp_path):
    table = spring_drop()
    table["variants"][".."] = {"t_end": 0.01}
    path = scene_file(tmp_path, table)
    proc = cosim("run", path, "--variant", "undamped", "--out", tmp_path / "o", cwd=tmp_path)
    assert proc.returncode == 2
    assert proc.stderr.startswith(f"error: {path}: `variants` names a variant that must be a "
                                  f"plain name")
    assert proc.stderr.rstrip().endswith("got '..'")
    assert tree(tmp_path) == ["scene.toml"]


def test_a_sweep_point_never_lands_outside_the_sweep_folder(tmp_path):
    """A scene whose variants are named `..` and `.` (names the loader
    refuses): each point is refused, and its folder is a plain name inside
    the sweep's folder.  (A name of `--variants` that the scene does not
    have at all is refused before any point: tests/test_cli_edges.py.)"""
    table = spring_drop()
    table["variants"][".."] = table["variants"]["."] = {"t_end": 0.01}
    path = scene_file(tmp_path, table)
    out = tmp_path / "sweep"
    proc = cosim("sweep", path, "--variants", "..,.", "--set",
                 "t_end=0.001", "--workers", "1", "--no-plot", "--out", out, cwd=tmp_path)
    assert proc.returncode == 1, proc.stderr
    assert "Traceback" not in proc.stderr
    assert {p.split("/")[0] for p in tree(tmp_path)} == {"scene.toml", "sweep"}
    points = sorted(p.name for p in out.iterdir() if p.is_dir())
    assert len(points) == 2 and all(re.fullmatch(r"_\.?,t_end=0\.001-[0-9a-f]{10}", p)
                                    for p in points), points
    assert all((out / p / "point.json").exists() for p in points)
    assert point_name("..", ()) != ".." and not point_name(".x", ()).startswith(".")


def test_control_characters_never_reach_the_terminal_raw(tmp_path):
    table = spring_drop()
    table["contacts"]["\x1b[2J\x1b[31mwall"] = table["contacts"].pop("wall")
    table["subsystems"]["\x1b]0;title\x07"] = {"type": "rigid", "points": {"p": [0.0, 1.0]}}
    path = scene_file(tmp_path, table, "s\x1b[1mcene.toml")
    proc = cosim("run", path, "--out", tmp_path / "o\x1b[5m", cwd=tmp_path)
    assert proc.returncode == 2
    assert "\x1b" not in proc.stderr + proc.stdout and "\x07" not in proc.stderr
    assert proc.stderr.startswith(r"error: " + str(tmp_path) + r"/s\x1b[1mcene.toml: ")
    assert r"'\x1b]0;title\x07'" in proc.stderr
    # and an unknown key in the file, a value, an override and a bad --variant
    table = spring_drop()
    table["\x1b[31mzz"] = 1
    path = scene_file(tmp_path, table, "b.toml")
    for extra in ([], ["--variant", "\x1b[31m"], ["--set", "t_end=\x1b[31m"],
                  ["--set", "\x1b[31m.x=1"]):
        proc = cosim("run", path, *extra, cwd=tmp_path)
        assert proc.returncode == 2, proc.stderr
        assert "\x1b" not in proc.stderr + proc.stdout and r"\x1b[31m" in proc.stderr


def test_the_summary_prints_names_of_a_finished_run_plainly(tmp_path):
    proc = cosim("run", CASES / "spring_drop.toml", "--set", "t_end=0.001", "--out",
                 tmp_path / "o", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert "scene spring_drop  scheme gauss_seidel  status finished" in proc.stdout
    assert f"wrote {tmp_path / 'o' / 'summary.json'}" in proc.stdout


def test_inside_is_the_last_check_before_a_write(tmp_path):
    assert inside(tmp_path, "summary.json") == tmp_path / "summary.json"
    for bad in ["", ".", "..", "../x", "a/b", "/etc/passwd", "x\x00", "x\ny"]:
        with pytest.raises(OutputError, match="writes only plain file names inside"):
            inside(tmp_path, bad)


def test_names_are_checked_from_python_too(tmp_path):
    path = scene_file(tmp_path, spring_drop(name="../x"))
    with pytest.raises(SceneError, match=re.escape(f"{path}: `name` must be a plain name")):
        load_scene(path)
    with pytest.raises(SceneError, match=r"`name` must be a plain name .*got 'a/b'"):
        load_scene(CASES / "spring_drop.toml", overrides=['name="a/b"'])


def test_scene_toml_keeps_any_text_readable(tmp_path):
    """Found by the names fuzz: JSON wrote characters beyond the BMP as
    surrogate pairs, which TOML refuses, so such a scene's scene.toml could
    not be read back."""
    text = "drop \U0001F600 \x7f \x1b[31m \u2028 end"
    path = scene_file(tmp_path, spring_drop(description=text))
    proc = cosim("run", path, "--set", "t_end=0.001", "--out", tmp_path / "o", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    again = tomllib.loads((tmp_path / "o" / "scene.toml").read_text())
    assert again["description"] == text
    load_scene(tmp_path / "o" / "scene.toml")


def test_a_subsystem_name_holds_no_dot(tmp_path):
    table = spring_drop()
    table["subsystems"]["wall.x"] = table["subsystems"].pop("wall")
    path = scene_file(tmp_path, table)
    with pytest.raises(SceneError, match=re.escape(
            f"{path}: `subsystems` names a subsystem 'wall.x': a subsystem's name holds no "
            f"`.`, which separates it from the point in SUBSYSTEM.POINT")):
        load_scene(path)

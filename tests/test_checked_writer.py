"""The one writer every cosim output goes through (cosim.io.rundir.OutputFolder):
checked names, no link followed, temp file and rename, the folder locked."""
from __future__ import annotations

from pathlib import Path

import pytest

from cosim.cli import main
from cosim.errors import OutputBusyError, OutputError, shown
from cosim.io.rundir import OutputFolder, atomic_write

SCENE = str(Path(__file__).resolve().parents[1] / "cases" / "spring_drop.toml")


def _victim(tmp_path, text="precious"):
    victim = tmp_path / "victim.txt"
    victim.write_text(text)
    return victim


def _leftovers(folder):
    return sorted(p.name for p in folder.iterdir() if p.name.endswith(".tmp"))


def test_a_link_planted_at_a_name_is_replaced_never_followed(tmp_path):
    victim = _victim(tmp_path)
    out = tmp_path / "out"
    out.mkdir()
    (out / "table.csv").symlink_to(victim)
    (out / "new.png").symlink_to(tmp_path / "created-through-the-link")
    with OutputFolder(out) as folder:
        folder.write("table.csv", lambda fh: fh.write("a,b\n"), "w")
        folder.write("new.png", lambda fh: fh.write(b"\x89PNG"), "wb")
    assert victim.read_text() == "precious"
    assert not (tmp_path / "created-through-the-link").exists()
    assert not (out / "table.csv").is_symlink() and (out / "table.csv").read_text() == "a,b\n"
    assert not (out / "new.png").is_symlink()
    assert _leftovers(out) == [] and not (out / ".run.lock").exists()


def test_the_writer_by_path_replaces_a_planted_link_too(tmp_path):
    victim = _victim(tmp_path)
    out = tmp_path / "out"
    out.mkdir()
    (out / "anim.gif").symlink_to(victim)
    with OutputFolder(out) as folder:
        path = folder.write_by_path("anim.gif", lambda p: p.write_bytes(b"GIF89a"))
    assert path == out / "anim.gif" and path.read_bytes() == b"GIF89a"
    assert victim.read_text() == "precious"
    assert sorted(p.name for p in out.iterdir()) == ["anim.gif"]


def test_a_folder_planted_as_a_link_is_refused(tmp_path):
    target = tmp_path / "elsewhere"
    target.mkdir()
    (tmp_path / "out").symlink_to(target, target_is_directory=True)
    with pytest.raises(OutputError, match="symbolic link"):
        OutputFolder(tmp_path / "out").open()
    real = tmp_path / "real"
    real.mkdir()
    (real / "k=1").symlink_to(target, target_is_directory=True)
    with OutputFolder(real) as folder, pytest.raises(OutputError, match="symbolic link"):
        folder.folder("k=1")
    assert list(target.iterdir()) == []


def test_a_subfolder_is_made_and_written_without_following_links(tmp_path):
    with OutputFolder(tmp_path / "sweep") as folder:
        with folder.folder("k=1") as point:
            point.write("summary.json", lambda fh: fh.write("{}"), "w")
        assert folder.exists("k=1") and not folder.exists("k=2")
    assert (tmp_path / "sweep" / "k=1" / "summary.json").read_text() == "{}"


@pytest.mark.parametrize("name", ["", ".", "..", "../x", "a/b", "x\ny", "x\x00"])
def test_names_that_are_not_plain_file_names_are_refused(tmp_path, name):
    with OutputFolder(tmp_path) as folder, pytest.raises(OutputError, match="plain file"):
        folder.write(name, lambda fh: fh.write("x"), "w")
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_a_failed_writer_leaves_the_old_file_and_no_temporary(tmp_path):
    (tmp_path / "summary.json").write_text("old")

    def fail(fh):
        fh.write("half")
        raise RuntimeError("the disk is gone")
    with OutputFolder(tmp_path) as folder, pytest.raises(RuntimeError):
        folder.write("summary.json", fail, "w")
    assert (tmp_path / "summary.json").read_text() == "old"
    assert _leftovers(tmp_path) == []


def test_a_folder_at_the_name_is_an_output_error(tmp_path):
    (tmp_path / "table.csv").mkdir()
    with pytest.raises(OutputError, match="table.csv"):
        atomic_write(tmp_path / "table.csv", lambda fh: fh.write("x"), "w")
    assert _leftovers(tmp_path) == []


def test_the_folder_is_locked_while_open(tmp_path):
    with OutputFolder(tmp_path / "out"):
        with pytest.raises(OutputBusyError, match="in use"):
            OutputFolder(tmp_path / "out").open()
    with OutputFolder(tmp_path / "out"):       # free again
        pass


def test_a_filesystem_root_is_refused():
    with pytest.raises(OutputError, match="filesystem root"):
        OutputFolder("/").open()


def test_cosim_run_out_root_is_refused(capsys):
    assert main(["run", SCENE, "--out", "/", "--quiet"]) == 2
    assert "filesystem root" in capsys.readouterr().err


def test_cosim_run_into_a_linked_folder_is_refused(tmp_path, capsys):
    target = tmp_path / "elsewhere"
    target.mkdir()
    (tmp_path / "run").symlink_to(target, target_is_directory=True)
    code = main(["run", SCENE, "--out", str(tmp_path / "run"), "--quiet"])
    assert code == 2 and "symbolic link" in capsys.readouterr().err
    assert list(target.iterdir()) == []


def test_shown_escapes_control_characters_and_caps_the_length():
    assert shown("a\nb\x1b[31m\u202e") == "a\\nb\\x1b[31m\\u202e"
    long = shown("x" * 120_000)
    assert len(long) < 250 and long.endswith("(120000 characters)")
    assert "\n" not in shown({"k": "v\n" * 1000}) and len(shown(list(range(10**5)))) < 250


def test_the_trust_section_states_the_limits_the_code_holds():
    """docs/troubleshooting.md's "Files from elsewhere" quotes the limits
    that cosim applies to untrusted inputs: each stands in the code."""
    from cosim.sides.fmu_description import DESCRIPTION_MAX_BYTES
    from cosim.sides.fmu_unpack import DEFAULT_UNPACK_LIMIT, UNPACK_LIMIT_ENV
    from cosim.studies.sweep.backends import CONNECT_TIMEOUT_S
    from cosim.studies.sweep.grid import LARGE_GRID
    root = Path(__file__).resolve().parents[1]
    text = " ".join((root / "docs" / "troubleshooting.md").read_text().split())
    start = text.index("## Files from elsewhere")
    section = text[start:text.index("## The run guard", start)]
    for printed in (f"at most {DESCRIPTION_MAX_BYTES >> 20} MiB",
                    f"more than the {DESCRIPTION_MAX_BYTES} bytes cosim reads",
                    f"within {CONNECT_TIMEOUT_S:g} s",
                    f"at most {DEFAULT_UNPACK_LIMIT >> 30} GiB (`{UNPACK_LIMIT_ENV}` raises it)",
                    f"more than {LARGE_GRID} points asks for `--yes`"):
        assert printed in section, printed

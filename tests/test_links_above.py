"""A symbolic link above the folder cosim writes into -- a ``runs`` that is a
link, ``--out link/sub``, a sweep's ``--out link/sweep`` -- is refused as a
link at the folder's own place is: exit 2, a message that names the link and
the folder it leads to (the path to give instead), and nothing written on
either side of it.  One implementation (:func:`cosim.io.rundir.open_folder`)
serves run, sweep, bench and plot outputs and the library's writer."""
import os
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import CASES
from cosim.errors import OutputError
from cosim.io.rundir import OutputFolder, RunLock, atomic_write, fresh_folder

SPRING_DROP = CASES / "spring_drop.toml"
SHORT = ("--set", "t_end=0.001")


def cosim_cli(*args, cwd):
    return subprocess.run([sys.executable, "-m", "cosim.cli", *map(str, args)],
                          capture_output=True, text=True, cwd=cwd, timeout=300)


@pytest.fixture
def linked(tmp_path):
    """``real/`` (an empty folder) and ``lnk -> real`` in ``tmp_path``."""
    (tmp_path / "real").mkdir()
    (tmp_path / "lnk").symlink_to("real", target_is_directory=True)
    return tmp_path


def refused(proc, shown, link, leads_to, said=""):
    """``proc`` refused to write into ``shown`` because of ``link``, naming
    where it leads; ``said`` is what it printed before."""
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr and proc.stdout == said
    assert proc.stderr == (f"error: cannot write into {shown}: {link} is a symbolic link (cosim "
                           f"never writes through one); give the folder it leads to, "
                           f"{leads_to}, or remove the link\n")


@pytest.mark.parametrize("out", ["lnk/sub", "lnk/a/b", "ABS/lnk/sub"])
def test_run_into_a_folder_below_a_link_is_refused(linked, out):
    out = out.replace("ABS", str(linked))
    link = out[:out.index("lnk") + 3]
    proc = cosim_cli("run", SPRING_DROP, *SHORT, "--no-estimate", "--out", out, cwd=linked)
    refused(proc, out, link, linked.resolve() / "real" / out[len(link) + 1:])
    assert os.listdir(linked / "real") == []


def test_the_default_runs_folder_as_a_link_is_refused(linked):
    (linked / "runs").symlink_to("real", target_is_directory=True)
    proc = cosim_cli("run", SPRING_DROP, *SHORT, "--no-estimate", cwd=linked)
    refused(proc, "runs/spring_drop-undamped", "runs",
            linked.resolve() / "real" / "spring_drop-undamped")
    assert os.listdir(linked / "real") == []
    # the way out the message gives: the folder the link leads to
    proc = cosim_cli("run", SPRING_DROP, *SHORT, "--no-estimate", "--out",
                     linked / "real" / "spring_drop-undamped", cwd=linked)
    assert proc.returncode == 0, proc.stderr
    assert (linked / "real" / "spring_drop-undamped" / "summary.json").is_file()


def test_a_sweep_into_a_folder_below_a_link_is_refused(linked):
    proc = cosim_cli("sweep", SPRING_DROP, "--set", "t_end=0.001,0.002", "--no-plot",
                     "--out", "lnk/sw", cwd=linked)
    refused(proc, "lnk/sw", "lnk", linked.resolve() / "real" / "sw",
            f"sweep {SPRING_DROP}: 2 point(s) on 2 process(es), into lnk/sw\n")
    assert os.listdir(linked / "real") == []


def test_a_bench_into_a_folder_below_a_link_is_refused(linked):
    proc = cosim_cli("bench", SPRING_DROP, "--set", "t_end=0.012", "--out", "lnk/b", cwd=linked)
    refused(proc, "lnk/b", "lnk", linked.resolve() / "real" / "b")
    assert os.listdir(linked / "real") == []


def test_a_plot_into_a_folder_below_a_link_is_refused(linked):
    run = linked / "run"
    assert cosim_cli("run", SPRING_DROP, *SHORT, "--no-estimate", "--out", run,
                     cwd=linked).returncode == 0
    proc = cosim_cli("plot", run, "--out", "lnk/pics", cwd=linked)
    refused(proc, "lnk/pics", "lnk", linked.resolve() / "real" / "pics")
    assert os.listdir(linked / "real") == []


def test_the_library_writer_refuses_a_link_above_its_folder(linked):
    """Every way a file is written (the writer, a lock, a fresh run folder,
    one file written whole) reaches its folder through the same check."""
    def opened():
        with OutputFolder(linked / "lnk" / "sub"):
            pass

    def locked():
        with RunLock(linked / "lnk" / "sub"):
            pass

    for attempt in (opened, locked,
                    lambda: fresh_folder(linked / "lnk" / "sub", "run"),
                    lambda: atomic_write(linked / "lnk" / "t.csv", lambda fh: fh.write("a"), "w")):
        with pytest.raises(OutputError, match="symbolic link") as err:
            attempt()
        assert str(linked / "lnk") in str(err.value) and str(linked / "real") in str(err.value)
    # a link two levels up, and a link to a folder outside
    (linked / "real" / "inner").mkdir()
    with pytest.raises(OutputError, match="lnk is a symbolic link"):
        OutputFolder(linked / "lnk" / "inner" / "x").open()
    assert sorted(os.listdir(linked / "real")) == ["inner"]
    assert os.listdir(linked / "real" / "inner") == []


def test_a_path_without_links_is_made_as_before(tmp_path):
    """``..``, ``.`` and missing parents: made, and the folder is the one asked."""
    (tmp_path / "w").mkdir()
    os.chdir(tmp_path / "w")
    try:
        with OutputFolder("../a/./b/c") as folder:
            folder.write("f.txt", lambda fh: fh.write("x"), "w")
            assert folder.created
        assert (tmp_path / "a" / "b" / "c" / "f.txt").read_text() == "x"
        assert fresh_folder("../a/b", "c") == Path("../a/b/c-2")
        assert (tmp_path / "a" / "b" / "c-2").is_dir()
    finally:
        os.chdir(tmp_path)

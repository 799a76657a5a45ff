"""The `cosim` command's own entry (:func:`cosim.cli.console`): :func:`main`,
then the process's objects frozen for a cheaper exit.  What it must keep: the
exit status, every file whole, and a caller's process untouched by ``main``."""
import gc
import json
import subprocess
import sys
import tomllib

import numpy as np

from conftest import CASES, ROOT
from cosim import cli


def test_the_console_script_and_python_m_are_console():
    scripts = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
    assert scripts["cosim"] == "cosim.cli:console"
    assert "sys.exit(console())" in (ROOT / "src" / "cosim" / "cli" / "__main__.py").read_text()


def test_console_returns_mains_status_and_freezes(tmp_path):
    before = gc.get_freeze_count()
    try:
        assert cli.console(["run", str(CASES / "spring_drop.toml"), "--out",
                            str(tmp_path / "run"), "--quiet", "--set", "t_end=0.01"]) == 0
        assert gc.get_freeze_count() > before
        assert cli.console(["run", str(tmp_path / "no_such_scene.toml")]) == 2
    finally:
        gc.unfreeze()              # this test process goes on: give its objects back


def test_main_leaves_the_collector_alone(tmp_path):
    gc.unfreeze()
    assert cli.main(["run", str(CASES / "spring_drop.toml"), "--out", str(tmp_path / "run"),
                     "--quiet", "--set", "t_end=0.01"]) == 0
    assert gc.get_freeze_count() == 0


def test_a_run_by_the_command_is_whole_after_its_process_ends(tmp_path):
    """``python -m cosim.cli run``: the status, the summary and the series as
    the process left them, nothing half-written."""
    out = tmp_path / "run"
    proc = subprocess.run([sys.executable, "-m", "cosim.cli", "run",
                           str(CASES / "three_mass.toml"), "--variant", "f100", "--out",
                           str(out), "--quiet", "--set", "t_end=0.05"],
                          capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert proc.returncode == 0, proc.stderr
    s = json.loads((out / "summary.json").read_text())
    assert s["status"] == "finished" and s["t_end"] == 0.05
    with np.load(out / "series.npz") as z:
        assert z["t"][-1] == 0.05
        assert all(len(z[k]) == len(z["t"]) for k in z.files)
    assert tomllib.loads((out / "scene.toml").read_text())["name"] == "three_mass"
    assert not list(out.glob("*.tmp")) and not list(out.glob(".*.tmp"))
    bad = subprocess.run([sys.executable, "-m", "cosim.cli", "run", str(tmp_path / "none.toml")],
                         capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert bad.returncode == 2 and "error:" in bad.stderr


def test_temporary_names_are_random_and_distinct(tmp_path):
    from cosim.io.rundir import OutputFolder

    folder = OutputFolder(tmp_path)
    names = {folder._temp_name("summary.json") for _ in range(50)}
    assert len(names) == 50
    for n in names:
        head, token, tail = n.rsplit(".", 2)
        assert head == ".summary.json" and tail == "tmp"
        assert len(token) == 12 and int(token, 16) >= 0

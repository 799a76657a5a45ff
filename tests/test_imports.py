"""Start-up: a command imports only what its scene needs (issue 12).

Each case runs the command line in a fresh interpreter and reads back the set
of modules it loaded: a behaviour, not a timing.  scikit-fem, meshio,
matplotlib and dask are heavy and optional; scipy's submodules load where
first used, so a chain or a rigid ground needs none of scipy.
"""
import json
import subprocess
import sys

import pytest

from conftest import CASES, ROOT

HEAVY = ("skfem", "meshio", "matplotlib", "dask", "distributed")

SCRIPT = """
import atexit, json, sys
out = sys.argv[1]
def dump():
    with open(out, "w") as fh:
        json.dump(sorted(sys.modules), fh)
atexit.register(dump)
from cosim.cli import main
sys.exit(main(sys.argv[2:]))
"""


def loaded(tmp_path, *argv):
    out = tmp_path / "modules.json"
    proc = subprocess.run([sys.executable, "-c", SCRIPT, str(out), *argv], cwd=ROOT,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode in (0, 1), proc.stderr
    return set(json.loads(out.read_text()))


def packages(mods, names):
    return sorted(m for m in mods if m.split(".")[0] in names)


def test_help_imports_nothing_heavy(tmp_path):
    mods = loaded(tmp_path, "--help")
    assert not packages(mods, HEAVY + ("scipy",))


@pytest.mark.parametrize("scene,variant", [("spring_drop", None), ("three_mass", "f1")])
def test_rigid_ground_and_chain_scenes_need_no_scipy(tmp_path, scene, variant):
    argv = ["run", str(CASES / f"{scene}.toml"), "--out", str(tmp_path / "run"), "--quiet",
            "--set", "t_end=0.01"]
    if variant:
        argv += ["--variant", variant]
    mods = loaded(tmp_path, *argv)
    assert "cosim.run" in mods
    if scene == "three_mass":
        assert "fem.chain" in mods          # the chain was built, without scipy
    assert not packages(mods, HEAVY + ("scipy",)), packages(mods, HEAVY + ("scipy",))


def test_scipy_loads_where_first_used(tmp_path):
    """The monolithic scheme integrates with scipy: scipy.integrate is loaded
    then, and still nothing of the structures' or the plots' packages."""
    mods = loaded(tmp_path, "run", str(CASES / "spring_drop.toml"), "--scheme", "monolithic",
                  "--out", str(tmp_path / "run"), "--quiet")
    assert "scipy.integrate" in mods
    assert not packages(mods, HEAVY)


def test_a_beam_scene_loads_scikit_fem_but_not_meshio_or_plots(tmp_path):
    mods = loaded(tmp_path, "run", str(CASES / "beam_impact.toml"), "--out",
                  str(tmp_path / "run"), "--quiet", "--set", "t_end=0.002")
    assert "skfem" in mods
    assert not packages(mods, ("meshio", "matplotlib", "dask", "distributed"))

"""Helpers of the plug-in tests: an example package pip-installed into a
folder of its own, bare distributions made of metadata, and a child
`cosim` that sees them."""
import os
from pathlib import Path
import shutil
import subprocess
import sys
import textwrap

import pytest

from conftest import ROOT


def child_env(*paths):
    """The environment of a child `cosim`: ``paths``, then this tree's src
    where this process runs cosim from it (an editable install); a regular
    install (CI's ``pip install .``) is left to the child as it is, with its
    compiled kernels, which the src tree does not hold."""
    import cosim
    env = dict(os.environ)
    ours = Path(cosim.__file__).resolve().parents[1] == (ROOT / "src").resolve()
    env["PYTHONPATH"] = os.pathsep.join([*map(str, paths), *([str(ROOT / "src")] if ours else [])])
    return env


def run_cosim(args, env, cwd, timeout=300):
    return subprocess.run([sys.executable, "-m", "cosim.cli", *map(str, args)],
                          capture_output=True, text=True, env=env, cwd=cwd, timeout=timeout)


def pip_install(package, tmp, module_file):
    """``package`` (an example's folder) installed by pip into ``tmp/site``
    (no dependencies, no build isolation); returns that folder."""
    import setuptools
    if tuple(map(int, setuptools.__version__.split(".")[:2])) < (70, 1):
        pytest.importorskip("wheel", reason="setuptools < 70.1 builds a wheel only with the "
                                            "`wheel` package, which the test extra installs")
    src = tmp / "src"
    shutil.copytree(package, src)              # pip builds in the tree: not in ours
    target = tmp / "site"
    proc = subprocess.run([sys.executable, "-m", "pip", "install", "--no-deps",
                           "--no-build-isolation", "--no-index", "--quiet", "--target",
                           str(target), str(src)], capture_output=True, text=True,
                          timeout=600, env=child_env())
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert (target / module_file).exists()
    return target


def bare_dist(site, name, group, entries, module=None, code=""):
    """A bare installed distribution: its metadata and entry points, and
    optionally a module of its own."""
    info = site / f"{name.replace('-', '_')}-1.0.dist-info"       # as installers name it
    info.mkdir(parents=True)
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {name}\nVersion: 1.0\n")
    lines = "".join(f"{k} = {v}\n" for k, v in entries.items())
    (info / "entry_points.txt").write_text(f"[{group}]\n{lines}")
    if module:
        (site / f"{module}.py").write_text(textwrap.dedent(code))
    return site

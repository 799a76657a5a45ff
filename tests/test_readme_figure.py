"""The README's figure is what the commands beside it draw: they are run as
the README prints them, and the figure they draw is compared with the one
shipped (docs/three_mass_f100_penetration.png), pixel by pixel."""
import re
import shlex
import subprocess
import sys

import numpy as np
import pytest

from conftest import ROOT

FIGURE = ROOT / "docs" / "three_mass_f100_penetration.png"


def _commands():
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    block = text.split("The figure is drawn by\n\n```bash\n")[1].split("```")[0]
    return [shlex.split(line) for line in block.strip().splitlines()]


def test_the_readme_figure_is_what_its_commands_draw(tmp_path):
    pytest.importorskip("matplotlib")
    Image = pytest.importorskip("PIL.Image")
    (run, plot) = _commands()
    assert run[:2] == ["cosim", "run"] and plot[:2] == ["cosim", "plot"]
    assert "docs/three_mass_f100_penetration.png" in (ROOT / "README.md").read_text()
    (tmp_path / "cases").symlink_to(ROOT / "cases")     # the README's paths, from here
    for argv in (run, plot):
        proc = subprocess.run([sys.executable, "-m", "cosim.cli", *argv[1:]], cwd=tmp_path,
                              capture_output=True, text=True, timeout=600)
        assert proc.returncode == 0, proc.stderr
    out = plot[2]
    summary = (tmp_path / out / "summary.json").read_text()
    assert re.search(r'"macro_steps": 25\d\d', summary)   # a sample every 0.1 ms, not 2 ms
    with Image.open(tmp_path / out / "penetration.png") as a, Image.open(FIGURE) as b:
        assert a.size == b.size
        drawn = np.asarray(a.convert("RGB"), dtype=int)
        shipped = np.asarray(b.convert("RGB"), dtype=int)
    # the same pixels but for a little text antialiasing (another FreeType, say)
    differ = np.any(np.abs(drawn - shipped) > 32, axis=-1).mean()
    assert differ < 0.005, differ

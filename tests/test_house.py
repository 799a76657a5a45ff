"""The house's sizes and doors: no module of the coupling core, the sides,
the command line, the plots or the model packages grows past about 500 lines
(split it by concern instead), and the console script named in pyproject.toml
is the command line's ``main``."""
from __future__ import annotations

import importlib
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SRC = ROOT / "src"
#: the folders whose modules are held to the limit (the scene loader and the
#: studies are split on their own schedule)
HELD = ("cosim/core", "cosim/sides", "cosim/cli", "cosim/plot", "multibody", "fem", "couplers")
MAX_LINES = 500


def _held_modules():
    for folder in HELD:
        yield from sorted((SRC / folder).rglob("*.py"))


@pytest.mark.parametrize("path", list(_held_modules()), ids=lambda p: str(p.relative_to(SRC)))
def test_no_module_over_about_500_lines(path):
    n = len(path.read_text().splitlines())
    assert n <= MAX_LINES, f"{path.relative_to(SRC)} has {n} lines (> {MAX_LINES}): split it by concern"


def test_the_console_script_is_the_command_lines_main():
    """The console script and ``python -m cosim.cli`` are :func:`cosim.cli.console`,
    :func:`cosim.cli.main` in a process of its own (``tests/test_console.py``)."""
    scripts = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
    module, _, name = scripts["cosim"].partition(":")
    cli = importlib.import_module("cosim.cli")
    assert getattr(importlib.import_module(module), name) is cli.console
    assert importlib.import_module("cosim.cli.__main__").console is cli.console

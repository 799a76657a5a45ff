"""The table of documented numbers: its shared pieces.

Every number in README.md and docs/ that a command produces (timings
excepted: they name their machine) is a :class:`Claim`: the page, the text as
the page prints it, the command that produces it, the value and the
tolerance of the comparison.  A test asserts both halves: the printed text
stands on the page (so page and table cannot drift apart) and the command,
run now, gives the value within the tolerance (so the page is true).
"""
from __future__ import annotations

import importlib.util
import math
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


@dataclass(frozen=True)
class Claim:
    """One documented number.

    page : the file relative to the repository root ("docs/structures.md")
    printed : the text exactly as the page prints it ("8.98 rad/s")
    command : what produces it, as a user would type it
    value : the number the text states, in the unit ``measured`` is given in
    rel, abs : the tolerance, relative or absolute (the printed digits' half
        unit is the usual choice; say why where it is wider)
    """

    page: str
    printed: str
    command: str
    value: float
    rel: float = 0.0
    abs: float = 0.0

    @property
    def id(self) -> str:
        return f"{Path(self.page).stem}:{self.printed}"


def assert_printed(claim: Claim) -> None:
    """The claim's text stands on its page, as printed (spaces and line
    breaks of the Markdown source count as one space)."""
    text = " ".join((ROOT / claim.page).read_text(encoding="utf-8").split())
    assert " ".join(claim.printed.split()) in text, \
        f"{claim.page} no longer prints {claim.printed!r}: update the page and the table together"


def assert_reproduced(claim: Claim, measured: float) -> None:
    """``measured`` (what the command gives now) is the printed value within
    the claim's tolerance."""
    assert math.isfinite(measured), (claim.id, measured)
    assert measured == pytest.approx(claim.value, rel=claim.rel, abs=claim.abs), \
        f"{claim.page} prints {claim.printed!r} ({claim.value}); `{claim.command}` gives {measured}"


def load_script(path: Path, name: str):
    """A benchmark script (not a package module) imported as ``name``."""
    spec = importlib.util.spec_from_file_location(name, path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def page_section(page: str, heading: str) -> str:
    """The text of ``page`` (relative to the root) under the level-2
    heading ``heading``, up to the next one."""
    text = (ROOT / page).read_text(encoding="utf-8")
    return text.split(f"## {heading}\n", 1)[1].split("\n## ", 1)[0]


def flat(text: str) -> str:
    """``text`` with every run of white space one space (prose wraps)."""
    return " ".join(text.split())

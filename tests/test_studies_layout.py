"""The studies' house: each module holds one concern and stays
short enough to read in one sitting.  The layering itself (no study imports
cosim.cli or cosim.plot) is tests/test_layers.py's."""
from pathlib import Path

import pytest

STUDIES = Path(__file__).resolve().parents[1] / "src" / "cosim" / "studies"

#: the most lines a module of cosim.studies may hold
MAX_LINES = 500


@pytest.mark.parametrize("path", sorted(STUDIES.rglob("*.py")),
                         ids=lambda p: str(p.relative_to(STUDIES)))
def test_no_studies_module_is_over_500_lines(path):
    n = len(path.read_text().splitlines())
    assert n <= MAX_LINES, f"{path.relative_to(STUDIES)} has {n} lines, more than {MAX_LINES}"


def test_the_sweep_is_a_package_split_by_concern():
    names = {p.stem for p in (STUDIES / "sweep").glob("*.py")}
    assert {"grid", "backends", "resume", "table", "plot", "study", "driver"} <= names
    # no submodule may be called `sweep`: it would hide the function
    # `cosim.studies.sweep.sweep` behind a module of that name
    assert "sweep" not in names
    from cosim.studies import sweep
    assert callable(sweep.sweep) and sweep.sweep.__module__ == "cosim.studies.sweep.driver"

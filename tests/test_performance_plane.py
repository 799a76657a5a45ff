"""docs/performance.md's plane-body section held to its published runs
(``benchmarks/results/plane_setup``: the run the tables show, and one before
it under heavy load that the prose quotes): the tables are what the script's
formatter prints from the file, the section names the run, and the prose's
numbers are the files' (half a unit of the printed digit)."""
from __future__ import annotations

import json

import pytest

from documented import ROOT, Claim, assert_printed, assert_reproduced, flat, page_section

PAGE = "docs/performance.md"
HEADING = "Plane bodies: set-up and step"
CMD = "python benchmarks/plane_setup.py"
FOLDER = ROOT / "benchmarks" / "results" / "plane_setup"


def _data() -> dict:
    return json.loads((FOLDER / "plane_setup.json").read_text(encoding="utf-8"))


def _script():
    import importlib.util
    import sys
    key = "plane_setup_bench"
    if key not in sys.modules:
        spec = importlib.util.spec_from_file_location(key, ROOT / "benchmarks" / "plane_setup.py")
        mod = importlib.util.module_from_spec(spec)
        sys.modules[key] = mod
        spec.loader.exec_module(mod)
    return sys.modules[key]


def _size(label: str, data=None) -> dict:
    (p,) = [p for p in (data or _data())["setup"] if p["label"] == label]
    return p


def test_the_tables_are_the_published_run_as_formatted():
    data = _data()
    section = page_section(PAGE, HEADING)
    assert _script().table(data) in section, (
        f"{PAGE}'s tables differ from `{CMD} --table benchmarks/results/plane_setup`")
    text = flat(section)
    assert CMD in text and "benchmarks/results/plane_setup/" in text
    assert "The run" in text and data["date"] in text
    # three sizes of about 8k, 33k and 130k DOFs, and two mode counts for the step
    assert [p["label"] for p in data["setup"]] == ["8k", "33k", "130k"]
    assert [round(p["dofs"], -3) // 1000 for p in data["setup"]] == [8, 33, 130]
    assert sorted({p["modes"] for p in data["step"]}) == [16, 48]


def _setup_33k(data=None) -> float:
    p = _size("33k", data)
    return p["read"][0] + p["assemble"][0] + p["modes50"][0]


def _ratio(key: str, modes: int) -> float:
    by = {(p["structure"], p["modes"]): p for p in _data()["step"]}
    return by["plane", modes][key] / by["beam", modes][key]


def _loaded() -> dict:
    return json.loads((FOLDER / "plane_setup_loaded.json").read_text(encoding="utf-8"))


def _kept_over_one(label: str, which: str) -> float:
    p = _size(label)
    return p["modes50_keep"][0] / p[which][0]


_LOADED = "python benchmarks/plane_setup.py (the run under heavy load)"
CLAIMS = [
    (Claim(PAGE, "set-up at 33k DOFs with 50 modes 2.2 s (at most 15 s)", CMD, 2.2, abs=0.05),
     _setup_33k),
    (Claim(PAGE, "its cached re-run 0.49 s (at most 1 s", CMD, 0.49, abs=0.005),
     lambda: _size("33k")["cached_rerun"][0]),
    (Claim(PAGE, "1.9 s at 130k DOFs, mostly assembly", CMD, 1.9, abs=0.05),
     lambda: _size("130k")["cached_rerun"][0]),
    (Claim(PAGE, "solve per macro step 0.54 and 0.79 times the beam's", CMD, 0.54, abs=0.005),
     lambda: _ratio("solve_per_step_s", 16)),
    (Claim(PAGE, "solve per macro step 0.54 and 0.79 times the beam's", CMD, 0.79, abs=0.005),
     lambda: _ratio("solve_per_step_s", 48)),
    (Claim(PAGE, "its own steps 1.02 and 0.54 times (at most 1.5)", CMD, 1.02, abs=0.005),
     lambda: _ratio("structure_per_step_s", 16)),
    (Claim(PAGE, "its own steps 1.02 and 0.54 times (at most 1.5)", CMD, 0.54, abs=0.005),
     lambda: _ratio("structure_per_step_s", 48)),
    (Claim(PAGE, "load average 2.3 to 3.0", CMD, 2.3, abs=0.05),
     lambda: min(_data()["load_average"])),
    (Claim(PAGE, "load average 2.3 to 3.0", CMD, 3.0, abs=0.05),
     lambda: max(_data()["load_average"])),
    (Claim(PAGE, "the threads kept cost 2.4 to 3.0 times at 8k DOFs", CMD, 2.4, abs=0.05),
     lambda: min(_kept_over_one("8k", k) for k in ("modes50", "modes50_again"))),
    (Claim(PAGE, "the threads kept cost 2.4 to 3.0 times at 8k DOFs", CMD, 3.0, abs=0.05),
     lambda: max(_kept_over_one("8k", k) for k in ("modes50", "modes50_again"))),
    (Claim(PAGE, "under heavy load (4.4 to 5.1", _LOADED, 4.4, abs=0.05),
     lambda: min(_loaded()["load_average"])),
    (Claim(PAGE, "under heavy load (4.4 to 5.1", _LOADED, 5.1, abs=0.05),
     lambda: max(_loaded()["load_average"])),
    (Claim(PAGE, "they took 9.9 s at 33k DOFs", _LOADED, 9.9, abs=0.05),
     lambda: _size("33k", _loaded())["modes50_keep"][0]),
    (Claim(PAGE, "against 2.8 s and 4.7 s on one thread before and after", _LOADED, 2.8,
           abs=0.05), lambda: _size("33k", _loaded())["modes50"][0]),
    (Claim(PAGE, "against 2.8 s and 4.7 s on one thread before and after", _LOADED, 4.7,
           abs=0.05), lambda: _size("33k", _loaded())["modes50_again"][0]),
    (Claim(PAGE, "56.1 s at 130k against 16.1 and 15.6 s", _LOADED, 56.1, abs=0.05),
     lambda: _size("130k", _loaded())["modes50_keep"][0]),
    (Claim(PAGE, "56.1 s at 130k against 16.1 and 15.6 s", _LOADED, 16.1, abs=0.05),
     lambda: _size("130k", _loaded())["modes50"][0]),
    (Claim(PAGE, "56.1 s at 130k against 16.1 and 15.6 s", _LOADED, 15.6, abs=0.05),
     lambda: _size("130k", _loaded())["modes50_again"][0]),
]


@pytest.mark.parametrize("claim, measure", CLAIMS, ids=[c.id for c, _ in CLAIMS])
def test_the_prose_numbers_are_the_published_runs(claim, measure):
    assert_printed(claim)
    assert_reproduced(claim, float(measure()))


def test_no_steady_difference_above_8k_in_the_published_run():
    """"made no steady difference above": at 33k and 130k DOFs the threads
    kept lie within 0.75 and 1.5 times the one-thread runs beside them."""
    for label in ("33k", "130k"):
        p = _size(label)
        one = (p["modes50"][0], p["modes50_again"][0])
        assert 0.75 * min(one) <= p["modes50_keep"][0] <= 1.5 * max(one), label


def test_the_targets_are_met_in_the_published_run():
    """The issue's targets: set-up at 33k DOFs and 50 modes at most 15 s, a
    cached re-run at most 1 s, the step at most 1.5 times the beam's; the
    loaded run met the set-up targets too."""
    for data in (_data(), _loaded()):
        assert _setup_33k(data) <= 15.0
        assert _size("33k", data)["cached_rerun"][0] <= 1.0
    for key in ("solve_per_step_s", "structure_per_step_s"):
        assert max(_ratio(key, m) for m in (16, 48)) <= 1.5
    assert "met" in flat(page_section(PAGE, HEADING))
    assert _script().table(_loaded())          # the loaded run's file is whole


def test_the_smallest_size_is_the_published_one_run_again(tmp_path):
    """The timings are the machine's; what they are timings of is re-run:
    the 8k strip has the published DOFs, lowest frequency and 50th
    frequency (the same modes), and its second set-up reads the cache."""
    p = _script().setup_point("8k", 100, 10, tmp_path, threads=False)
    published = _size("8k")
    assert p["dofs"] == published["dofs"] == 8400
    for key in ("f1_hz", "modes20_top_hz", "modes50_top_hz"):
        assert p[key] == pytest.approx(published[key], rel=1e-9), key
    # Timoshenko's clamped strip: f1 82.894 Hz; this mesh's P2 is within 0.3 %
    assert p["f1_hz"] == pytest.approx(82.894, rel=3e-3)


def test_the_step_clock_is_size_scalings_and_times_the_structures_steps():
    # the clock of the step-cost table: the structure's own steps, in the
    # Python macro loop, which it sets for the block and gives back after
    import os
    import cosim
    before = os.environ.get("COSIM_DRIVER")
    with _script()._StructureClock() as clock:
        assert os.environ["COSIM_DRIVER"] == "python"
        scene = cosim.load_scene(ROOT / "cases" / "beam_impact.toml", overrides=["t_end=0.02"])
        cosim.simulate(scene, estimate=False)
    assert type(clock).__module__ == "size_scaling_bench"
    assert clock.total > 0.0
    assert os.environ.get("COSIM_DRIVER") == before

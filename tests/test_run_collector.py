"""A run keeps its set-up out of the garbage collector's passes during its
solve (:func:`cosim.scene.run._setup_out_of_collection`): what exists when
the solve starts is frozen (:func:`gc.freeze`), and handed back after it
however the solve ends.  A collection of the young generations that set-up
fills (tens of thousands of objects, about a millisecond) then never falls
inside the window a first run's ``cpu_time_s`` measures
(``benchmarks/scenes.py --first-run``).  Behaviours, not timings: the
collector's frozen count inside the solve and after the run.
"""
from __future__ import annotations

import gc
import warnings

import pytest

from conftest import CASES

import cosim
from cosim.core.recorder import Recorder
from cosim.scene import run as run_module


def _load(name, variant=None):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return cosim.load_scene(CASES / f"{name}.toml", variant)


def _spy(monkeypatch):
    """The frozen count at each sample the solve records."""
    seen = []
    record = Recorder.record

    def recorded(self, *args, **kw):
        seen.append(gc.get_freeze_count())
        return record(self, *args, **kw)
    monkeypatch.setattr(Recorder, "record", recorded)
    return seen


@pytest.mark.parametrize("name,variant", [("manipulator_wall", "mu0.03"),
                                          ("three_mass", "f100")])
def test_the_solve_runs_with_its_set_up_frozen_and_gives_it_back(monkeypatch, name, variant):
    gc.unfreeze()
    seen = _spy(monkeypatch)
    res = cosim.simulate(_load(name, variant), estimate=False)
    assert res.summary["status"] == "finished"
    assert seen and min(seen) > 0          # the set-up was frozen while the solve ran
    assert gc.get_freeze_count() == 0      # and handed back


def test_a_process_that_froze_objects_itself_is_left_as_it_was(monkeypatch):
    gc.unfreeze()
    gc.freeze()
    try:
        mine = gc.get_freeze_count()
        assert mine > 0
        seen = _spy(monkeypatch)
        res = cosim.simulate(_load("manipulator_wall", "mu0.03"), estimate=False)
        assert res.summary["status"] == "finished"
        # (the count falls as frozen objects die, never rises but by a freeze:
        # the scene loaded since would have been frozen with it)
        assert seen and max(seen) <= mine            # nothing more frozen for the solve
        assert 0 < gc.get_freeze_count() <= mine     # nothing of the caller's unfrozen
    finally:
        gc.unfreeze()


def test_a_collector_turned_off_stays_off_and_nothing_is_frozen():
    gc.unfreeze()
    gc.disable()
    try:
        with run_module._setup_out_of_collection():
            assert gc.get_freeze_count() == 0
        assert not gc.isenabled()
    finally:
        gc.enable()


def test_a_solve_that_raises_gives_its_set_up_back():
    gc.unfreeze()
    with pytest.raises(RuntimeError, match="the solve failed"):
        with run_module._setup_out_of_collection():
            assert gc.get_freeze_count() > 0
            raise RuntimeError("the solve failed")
    assert gc.get_freeze_count() == 0

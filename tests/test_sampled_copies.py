"""The sampled path hands a block's states on without copying them: the rows
the adaptive pair samples (``ScipyStepper._run``'s ``at``) are the rows the
recorder receives as ``x`` (where the moving side's states are the system's),
read in place through :meth:`ScipyStepper.sample
<cosim.core.ode.ScipyStepper.sample>`, the side's ``_samples`` and the
emitter.  Each copy was a block of fresh memory that a process's first run
faulted in inside its solve window (``benchmarks/scenes.py --first-run``).
A behaviour, not a timing: whether the arrays share memory.

manipulator_wall mu0.03 (DOP853, the wall a rigid side without states) takes
the sampled path with the compiled pair; its first solver run stops at the
impact, so none of its samples is that run's end.
"""
from __future__ import annotations

import warnings

import numpy as np
import pytest

from conftest import CASES

import cosim
from cosim.core import ode
from cosim.core.recorder import Recorder
from cosim.sides.kernel import kernel_choice


@pytest.mark.skipif(kernel_choice() != "compiled", reason="the compiled pair samples in C")
def test_sampled_states_reach_the_recorder_uncopied(monkeypatch):
    rows, blocks = [], []
    run = ode.ScipyStepper._run

    def solver_run(self, *args, **kw):
        sol = run(self, *args, **kw)
        at = sol.at

        def sampled(ts):
            got = at(ts)
            rows.append(got)
            return got
        sol.at = sampled
        return sol

    record_block = Recorder.record_block

    def recorded(self, *args, x, **kw):
        blocks.append(np.asarray(x))
        return record_block(self, *args, x=x, **kw)

    monkeypatch.setattr(ode.ScipyStepper, "_run", solver_run)
    monkeypatch.setattr(Recorder, "record_block", recorded)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = cosim.load_scene(CASES / "manipulator_wall.toml", "mu0.03")
    res = cosim.simulate(scene, estimate=False)
    assert res.summary["status"] == "finished"
    assert rows and blocks
    # the first block: the samples before the impact, all inside the solver's run
    assert np.shares_memory(blocks[0], rows[0])
    n = blocks[0].shape[1]
    np.testing.assert_array_equal(blocks[0], rows[0][:len(blocks[0]), :n])

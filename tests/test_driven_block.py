"""The compiled macro loop's samples in blocks
(:mod:`cosim.core.schemes.driven_block`) against the same loop booking one
step at a time (``driven_block.ENABLED = False``, the reference).

Both take the same steps with the same compiled loop from the same states:
the rows, forces, ledgers, states and energies handed to the recorder are
the same numbers.  What differs is the recorder's and the guard's arithmetic
(:func:`~cosim.core.recorder_block.record_block` on arrays against
:meth:`~cosim.core.recorder.Recorder.record` one sample at a time), so the
series and summaries are bounded to 1e-12 relative (round-off of sums taken
in another order), and the discrete outcomes (counts, statuses, the sample a
guard stops at, its message) are asserted equal.
"""
from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from conftest import CASES

import cosim
from cosim.core.guard import Guard, GuardError
from cosim.core.schemes import driven_block, _driver_block
from cosim.scene.run import RunInterrupted
from test_sampled import _scene, series_distance

TOL = 1e-12
#: shipped scenes the compiled loop runs (short t_end where the scene is long)
DRIVEN = [("three_mass", "f1", ()), ("three_mass", "f100", ()), ("three_mass", "ms0.1", ()),
          ("beam_impact", None, ()), ("rod_impact", None, ()),
          ("beam_impact_2d", None, ("t_end=0.01",)), ("beam_with_holes", None, ("t_end=0.01",))]


def run(monkeypatch, name, variant=None, on=True, overrides=()):
    monkeypatch.setattr(driven_block, "ENABLED", on)
    return cosim.simulate(_scene(name, variant, overrides), estimate=False)


_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"


def same_message(a: str, b: str, rel: float = 1e-9) -> None:
    """Two stop messages say the same: the same words, and each number within
    ``rel`` (the block path's energies are numpy's over rows, the step path's
    over one: SIMD may round them an ulp apart)."""
    import re
    assert re.sub(_NUMBER, "#", a) == re.sub(_NUMBER, "#", b), (a, b)
    for x, y in zip(re.findall(_NUMBER, a), re.findall(_NUMBER, b)):
        assert float(x) == pytest.approx(float(y), rel=rel, abs=1e-300), (a, b)


def same_outcome(a, b):
    sa, sb = a.summary, b.summary
    assert (sa["status"], sa["macro_steps"]) == (sb["status"], sb["macro_steps"])
    assert sa["t_end"] == pytest.approx(sb["t_end"], rel=TOL)
    assert sa.get("counters") == sb.get("counters")
    for c, ca in sa["contacts"].items():
        cb = sb["contacts"][c]
        assert ca["count"] == cb["count"], c
        np.testing.assert_allclose(ca["intervals"], cb["intervals"], rtol=0,
                                   atol=TOL * sa["t_end"])
        for key in ("peak_penetration", "impulse", "dissipated", "work"):
            assert cb[key] == pytest.approx(ca[key], rel=TOL, abs=1e-15), (c, key)
    for key in ("max_drift", "max_created"):
        ea, eb = sa["energy"].get(key), sb["energy"].get(key)
        if ea is not None:
            assert eb == pytest.approx(ea, rel=1e-9, abs=1e-15), key


@pytest.mark.parametrize("name, variant, overrides", DRIVEN)
def test_blocks_give_the_step_by_step_run(monkeypatch, name, variant, overrides):
    calls = []
    fill = _driver_block.fill
    monkeypatch.setattr(_driver_block, "fill", lambda *a: calls.append(1) or fill(*a))
    path = run(monkeypatch, name, variant, True, overrides)
    assert path.status == "finished"
    steps = path.summary["macro_steps"]
    # the loop returned to Python once a block, not once a step
    assert len(calls) == math.ceil((steps + 1) / driven_block.BLOCK)
    monkeypatch.setattr(_driver_block, "fill", fill)
    ref = run(monkeypatch, name, variant, False, overrides)
    assert series_distance(ref, path) <= TOL
    same_outcome(ref, path)


@pytest.mark.parametrize("block", [8, 9])
def test_a_run_whose_steps_fill_its_last_block_exactly(monkeypatch, block):
    """three_mass f100 to 0.016 s takes 8 macro steps of 2 ms, which fill a
    block of 8 exactly: the loop then comes back once more with no row (the
    run's end), which records nothing; a block of 9 ends at the run's end."""
    monkeypatch.setattr(driven_block, "BLOCK", block)
    path = run(monkeypatch, "three_mass", "f100", True, ("t_end=0.016",))
    ref = run(monkeypatch, "three_mass", "f100", False, ("t_end=0.016",))
    assert path.status == ref.status == "finished"
    assert path.summary["macro_steps"] == 8
    assert series_distance(ref, path) <= TOL
    same_outcome(ref, path)


def test_the_four_scenes_take_a_block_path():
    """three_mass and beam_impact run the compiled loop (in blocks);
    ground_multicontact and manipulator_wall, whose partners are rigid, the
    sampled path, which integrates across the samples in blocks already."""
    from cosim.core.recorder import Recorder
    from cosim.scene.build import build_system
    for name, variant, loop in [("three_mass", "f100", "compiled"),
                                ("beam_impact", None, "compiled"),
                                ("ground_multicontact", None, "sampled"),
                                ("manipulator_wall", "mu0.03", "sampled")]:
        scene = _scene(name, variant, ["t_end=0.01"])
        system, sch = build_system(scene)
        sch.loop_stats = None
        sch.run(system, scene.t_end, Recorder(system, scene.name, sch.name, scene.t_end))
        st = sch.loop_stats
        assert st["loop"] == loop, name
        assert 0.0 < st["compiled_cpu_s"] <= st["run_cpu_s"], name


# ------------------------------------------------------------ guard stops
GUARD_STOPS = [
    # energy growth (at sample 240 of 300)
    ("beam_impact", None, ["guard.energy_growth=1e-5", "guard.energy_floor=0.0"]),
    # chatter: of an exchanged contact (its edges found by the recorder), of
    # an embedded one (its edges located by its side, reported with the rows)
    ("three_mass", "f100", ["guard.chatter_switches=6", "guard.chatter_window=1.0"]),
    ("three_mass", "f100", ["guard.chatter_switches=10", "guard.chatter_window=1.0"]),
    ("beam_impact", None, ["guard.chatter_switches=2", "guard.chatter_window=1.0"])]


@pytest.mark.parametrize("name, variant, overrides", GUARD_STOPS)
def test_a_guard_stop_is_the_step_by_step_one(monkeypatch, name, variant, overrides):
    monkeypatch.setattr(driven_block, "BLOCK", 64)      # several blocks before the stop
    ref = run(monkeypatch, name, variant, False, overrides)
    path = run(monkeypatch, name, variant, True, overrides)
    assert ref.status == path.status == "failed"
    same_message(path.message, ref.message)
    assert path.summary["t_end"] == ref.summary["t_end"]
    assert path.summary["macro_steps"] == ref.summary["macro_steps"]
    assert path.summary.get("counters") == ref.summary.get("counters")
    assert len(path.t) == len(ref.t)
    assert series_distance(ref, path) <= TOL
    # the state reported is the last sample kept's, not the loop's past it
    assert path.summary["final_state"] == ref.summary["final_state"]


def test_the_energy_stop_falls_inside_a_block(monkeypatch):
    """The first stop above is a sample in the middle of a block: the
    guard's block check names it, not the block's edge."""
    seen = []
    check = Guard.check_block

    def spy(self, t, *args, **kw):
        try:
            check(self, t, *args, **kw)
        except GuardError as exc:
            seen.append((exc.sample, len(t)))
            raise
    monkeypatch.setattr(Guard, "check_block", spy)
    monkeypatch.setattr(driven_block, "BLOCK", 64)
    res = run(monkeypatch, *GUARD_STOPS[0][:2], True, GUARD_STOPS[0][2])
    assert res.status == "failed" and "energy" in res.message and res.summary["t_end"] < 0.12
    (sample, rows), = seen
    assert 0 < sample < rows - 1


def _at_call(monkeypatch, n, act):
    """Make the chain's ``outputs`` (which the compiled loop calls inside
    each step) do ``act(side)`` at its ``n``-th call."""
    from cosim.sides.fem import StructureSubsystem
    outputs = StructureSubsystem.outputs
    calls = [0]

    def counted(self, t, x):
        calls[0] += 1
        if calls[0] == n:
            act(self)
        return outputs(self, t, x)
    monkeypatch.setattr(StructureSubsystem, "outputs", counted)


def test_a_non_finite_state_stops_as_step_by_step(monkeypatch):
    """A side whose state turns non-finite mid-run: the run stops at the
    first non-finite sample with the same message, the samples before kept."""
    results = []

    def poison(side):
        side.x[0] = math.nan
    for on in (False, True):
        _at_call(monkeypatch, 150, poison)          # inside the third block of 64
        monkeypatch.setattr(driven_block, "BLOCK", 64)
        results.append(run(monkeypatch, "three_mass", "f100", on))
    ref, path = results
    assert ref.status == path.status == "failed"
    same_message(path.message, ref.message)
    assert "is nan" in path.message
    assert path.summary["t_end"] == ref.summary["t_end"]
    assert path.summary["macro_steps"] == ref.summary["macro_steps"]
    assert len(path.t) == len(ref.t) > 64


def test_an_interrupted_run_keeps_whole_samples(monkeypatch):
    """Ctrl-C inside a block (here raised inside a step, as a signal's
    KeyboardInterrupt would be): the samples before it are kept, as step by
    step, and the interrupt is raised again."""
    results = []

    def interrupt(side):
        raise KeyboardInterrupt
    for on in (False, True):
        _at_call(monkeypatch, 100, interrupt)
        with pytest.raises(RunInterrupted) as exc:
            run(monkeypatch, "three_mass", "f100", on)
        results.append(exc.value.result)
    ref, path = results
    assert ref.status == path.status == "interrupted"
    assert len(path.t) == len(ref.t) > 50
    assert path.summary["t_end"] == ref.summary["t_end"]
    assert path.summary["macro_steps"] == ref.summary["macro_steps"]
    assert path.summary["final_state"] == ref.summary["final_state"]
    assert series_distance(ref, path) <= TOL


def test_counts_hold_under_a_nudge(monkeypatch):
    """three_mass f100's contact counts, in blocks, are the step-by-step
    run's and the same with the robot's height nudged by 2 ulps either way."""
    y0 = 0.09994114
    base = None
    for y in (y0, y0 + 2 * math.ulp(y0), y0 - 2 * math.ulp(y0)):
        over = [f"subsystems.robot.bodies.slider_y.joint.q0={y!r}"]
        path = run(monkeypatch, "three_mass", "f100", True, over)
        counts = {c: v["count"] for c, v in path.summary["contacts"].items()}
        base = counts if base is None else base
        assert counts == base
        if y == y0:
            ref = run(monkeypatch, "three_mass", "f100", False, over)
            assert counts == {c: v["count"] for c, v in ref.summary["contacts"].items()}
    assert sum(base.values()) >= 3


def test_progress_is_told_of_every_sample_when_asked(monkeypatch):
    """``progress_interval = 0`` asks for every sample: in blocks too, each
    sample's time once, increasing, to the end."""
    calls = []
    monkeypatch.setattr(driven_block, "ENABLED", True)
    res = cosim.simulate(_scene("three_mass", "f100"), estimate=False, progress=calls.append,
                         progress_interval=0.0)
    t = np.array([p.t for p in calls])
    assert len(t) == len(res.t) and np.all(np.diff(t) > 0)
    np.testing.assert_array_equal(t, res.t)


def test_the_recorders_crossing_is_hermite_points():
    """The recorder locates a crossing with :func:`cosim.core.hermite.hermite_point`'s
    formulas, its coefficients formed once (its C-free twin): the bisection
    on the module's function finds the same time, within 2 ulps of it."""
    from cosim.core import hermite
    from cosim.core.recorder import Recorder
    from cosim.scene.build import build_system
    system, sch = build_system(_scene("three_mass", "f100"))
    rec = Recorder(system, "three_mass", sch.name, 0.25)
    rng = np.random.default_rng(7)
    for _ in range(200):
        c = int(rng.integers(system.n_contacts))
        law, t0, h = system.links[c].contact.law, float(rng.uniform(0, 0.2)), 1e-4
        d0, d1 = sorted(rng.uniform(-1e-5, 1e-5, 2))
        if rng.random() < 0.5:
            d0, d1 = d1, d0
        v0, v1 = rng.uniform(-0.2, 0.2, 2)
        was = bool(d0 > 0)
        lo, hi = 0.0, 1.0
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            p, dp = hermite.hermite_point(d0, v0, d1, v1, h, mid)
            lo, hi = (mid, hi) if (float(law.switch(p, dp)) > 0) == was else (lo, mid)
        want = t0 + 0.5 * (lo + hi) * h
        got = rec._crossing(c, t0, d0, v0, t0 + h, d1, v1, was)
        assert abs(got - want) <= 2 * math.ulp(want)


def test_the_blocks_crossings_are_the_recorders():
    """record_block locates the crossings of a law that switches on the
    penetration itself on arrays, with the recorder's formulas in their order:
    the times agree with :meth:`Recorder._crossing` within 2 ulps."""
    from cosim.core.recorder import Recorder
    from cosim.core.recorder_block import _crossings
    from cosim.scene.build import build_system
    system, sch = build_system(_scene("three_mass", "f100"))
    rec = Recorder(system, "three_mass", sch.name, 0.25)
    rng = np.random.default_rng(11)
    m, nc = 50, system.n_contacts
    t = np.cumsum(rng.uniform(1e-5, 1e-3, m + 1))
    d = rng.uniform(-1e-5, 1e-5, (m + 1, nc))
    dd = rng.uniform(-0.2, 0.2, (m + 1, nc))
    active = d > 0
    flip = active[1:] != active[:-1]
    got = _crossings(rec, flip, t[:-1], d[:-1], dd[:-1], t[1:], d[1:], dd[1:], active[:-1])
    assert len(got) == int(flip.sum()) > 10         # three_mass's laws are all linear
    for (j, c), tc in got.items():
        want = rec._crossing(c, t[j], d[j, c], dd[j, c], t[j + 1], d[j + 1, c], dd[j + 1, c],
                             active[j, c])
        assert abs(tc - want) <= 2 * math.ulp(want)


def test_the_compiled_crossings_are_the_array_bisections(monkeypatch):
    """The compiled bisection (`_driver_block.crossings`) and the numpy one it
    replaces where the kernels are built: the same formulas in the same order,
    each operation rounded once (contraction off), so within 2 ulps on
    random flips, among them one a few ulps from each end of its step."""
    from cosim.core import recorder_block
    from cosim.core.recorder import Recorder
    from cosim.scene.build import build_system
    assert recorder_block._compiled is not None
    system, sch = build_system(_scene("three_mass", "f100"))
    rec = Recorder(system, "three_mass", sch.name, 0.25)
    rng = np.random.default_rng(5)
    m, nc = 60, system.n_contacts
    t = np.cumsum(rng.uniform(1e-6, 1e-3, m + 1))
    d = rng.uniform(-1e-5, 1e-5, (m + 1, nc))
    d[1, 0], d[2, 0] = 1e-300, -4 * math.ulp(0.0)       # a crossing at the very end
    dd = rng.uniform(-0.2, 0.2, (m + 1, nc))
    active = d > 0
    flip = active[1:] != active[:-1]
    args = (rec, flip, t[:-1], d[:-1], dd[:-1], t[1:], d[1:], dd[1:], active[:-1])
    got = recorder_block._crossings(*args)
    monkeypatch.setattr(recorder_block, "_compiled", None)
    monkeypatch.setattr(recorder_block, "ARRAY_CROSSINGS", 1)
    want = recorder_block._crossings(*args)
    assert got.keys() == want.keys() and len(got) == int(flip.sum()) > 10
    for key, tc in got.items():
        assert abs(tc - want[key]) <= 2 * math.ulp(want[key]), key

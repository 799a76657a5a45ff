"""The implicit scheme's macro loop in compiled code, its samples in blocks
(:mod:`cosim.core.schemes.implicit_block`), against the Python loop of
:meth:`CoSimulationScheme.run <cosim.core.schemes.base.CoSimulationScheme.run>`
(``implicit_block.ENABLED = False``, the reference).

Both call the same compiled iterations, the force history formed by the
same formulas in the same order (the rows and forces of the coupler
contacts, the extrapolation).  What differs is the order of some sums: a
structure's ports (BLAS in the Python loop, its C face here), the exchanged
forces' work (``mom @ G``), the energy (the sides' over the rows of a
block), and the recorder's and guard's arithmetic on arrays
(:meth:`~cosim.core.recorder.Recorder.record_block`).  The run carries an
ulp of difference on as it carries an ulp's change of its start, so the
series and ledgers are bounded to 1e-10 relative (measured 5e-12 on
brachiation) or, where larger, twice the Python loop's own distance to its
copies started 1 ulp off (quadratic extrapolation: 7e-10), and the discrete outcomes
(steps, iterations, counts, switches, the sample a guard stops at, its
message) are asserted equal, for the scene and copies moved by +-1 and
+-2 ulps.
"""
from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

import cosim
from cosim.core.recorder import Recorder
from cosim.core.schemes import implicit_block
from cosim.scene.build import build_system
from cosim.scene.run import RunInterrupted
from cosim.studies.roundoff import spread
from roundoff import COPIES
from test_driven_block import same_message
from test_sampled import _scene, series_distance

pytest.importorskip("cosim.core.schemes._implicit_block",
                    reason="the compiled implicit loop is not built here")

TOL = 1e-10
#: runs the block loop takes: brachiation under its implicit scheme (every
#: side compiled, the grasps exchanged), and other shipped scenes with their
#: contacts exchanged (`placement = "coupler"`) under the implicit scheme
_COUPLER = ['contacts.A.placement="coupler"', 'contacts.B.placement="coupler"',
            'contacts.C.placement="coupler"']
CASES_RUN = [
    ("scene 0.05 s", "brachiation", None, ["t_end=0.05"]),
    ("short last step", "brachiation", None, ["t_end=0.0505"]),     # its ratio 0.5
    ("order 0", "brachiation", None, ["scheme.extrapolation_order=0", "t_end=0.9"]),
    ("scene", "brachiation", None, []),     # grasp at the touch, release 50 ms after
    ("aitken", "brachiation", None, ['scheme.acceleration="aitken"', "t_end=0.9"]),
    ("order 2", "brachiation", None, ["scheme.extrapolation_order=2", "t_end=0.9"]),
    ("kelvin_voigt", "brachiation", None, [
        'contacts.gripper2.law={ type = "kelvin_voigt", contact_stiffness = 1e5, '
        'contact_damping = 50.0 }', "t_end=0.9"]),
    # a `time` trigger: gripper 1 lets go at 0.3 s, on a step's end give or take round-off
    ("release at a time", "brachiation", None, ['contacts.gripper1.grasp.release={ time = 0.3 }',
                                                "t_end=0.5"]),
    # a point mass against a rigid wall, linear and Kelvin-Voigt
    ("spring_drop", "spring_drop", "undamped", ['contacts.wall.placement="coupler"',
                                                'scheme.name="implicit"']),
    ("spring_drop kv", "spring_drop", "kelvin_voigt", ['contacts.wall.placement="coupler"',
                                                       'scheme.name="implicit"']),
    # the robot on the ground striking the chain: three exchanged contacts
    ("three_mass", "three_mass", "f100", ['scheme={ name = "implicit", macro_step = 3e-5 }',
                                          "t_end=0.05", *_COUPLER]),
]


def run(monkeypatch, scene, on=True):
    monkeypatch.setattr(implicit_block, "ENABLED", on)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")       # aitken ignores `reuse`
        return cosim.simulate(scene, estimate=False)


def switches(res):
    return [(s["contact"], s["to"], s["time"]) for s in res.summary["switches"]]


def same_outcome(a, b, tol=TOL):
    sa, sb = a.summary, b.summary
    assert (sa["status"], sa["macro_steps"], sa["iterations"], sa["rejected_steps"]) == \
        (sb["status"], sb["macro_steps"], sb["iterations"], sb["rejected_steps"])
    assert sa["t_end"] == pytest.approx(sb["t_end"], rel=1e-12)
    assert switches(a) == switches(b)
    for c, ca in sa["contacts"].items():
        cb = sb["contacts"][c]
        assert ca["count"] == cb["count"], c
        np.testing.assert_allclose(ca["intervals"], cb["intervals"], rtol=0,
                                   atol=tol * sa["t_end"])
        for key in ("peak_penetration", "impulse", "dissipated", "work"):
            assert cb[key] == pytest.approx(ca[key], rel=tol, abs=1e-15), (c, key)
    # the drift is a difference of energies of the size of the initial one:
    # bounded relative to that
    scale = abs(sa["energy"]["initial"])
    for key in ("max_abs_drift", "final", "dissipated", "supplied"):
        assert sb["energy"][key] == pytest.approx(sa["energy"][key], rel=tol,
                                                  abs=tol * scale + 1e-15), key


@pytest.mark.parametrize("case, name, variant, overrides", CASES_RUN,
                         ids=[c[0] for c in CASES_RUN])
def test_blocks_give_the_python_loop(monkeypatch, case, name, variant, overrides):
    scene = _scene(name, variant, overrides)
    blocks = []                 # the rows of each block recorded
    record = implicit_block._Rows.record
    monkeypatch.setattr(implicit_block._Rows, "record",
                        lambda self, system, rec, b: blocks.append(b) or record(self, system,
                                                                                rec, b))
    path = run(monkeypatch, scene, True)
    assert path.status == "finished", path.message
    steps = path.summary["macro_steps"]
    # the loop returned to Python once a block, or at a step a connection may switch at
    n_sw = len(switches(path))
    assert sum(blocks) == steps and len(blocks) <= math.ceil(steps / implicit_block.BLOCK) \
        + 2 * n_sw + 1
    ref = run(monkeypatch, scene, False)
    # the ports of the cable are summed by BLAS in the Python loop, by a
    # loop in C here: an ulp apart, which the run carries on as it carries a
    # 1-ulp change of its start (quadratic extrapolation: 7e-10 by t = 0.9 s)
    nudged = [run(monkeypatch, c, False) for c in spread(scene, 3)[1:]]
    tol = max(TOL, 2 * max(series_distance(ref, r) for r in nudged))
    assert tol <= 2e-9
    assert series_distance(ref, path) <= tol
    same_outcome(ref, path, tol)
    assert sum(v["count"] for v in path.summary["contacts"].values()) >= 1
    if name == "brachiation" and not overrides:
        assert [s[:2] for s in switches(path)] == [("gripper1", "grasped"),
                                                   ("gripper2", "grasped"),
                                                   ("gripper1", "released")]


def test_the_loop_is_compiled_and_says_why_not():
    """brachiation takes the compiled loop (its CPU inside it counted);
    with step control, the rigid cable (no exchanged contact is left), or
    the loop switched off, the Python loop runs, with the reason stated."""
    def stats(variant, overrides):
        scene = _scene("brachiation", variant, overrides)
        system, sch = build_system(scene)
        sch.run(system, scene.t_end, Recorder(system, scene.name, sch.name, scene.t_end))
        return sch.loop_stats
    st = stats(None, ["t_end=0.02"])
    assert st["loop"] == "compiled" and st["refusal"] is None and st["macro_steps"] == 20
    assert 0.0 < st["compiled_cpu_s"] <= st["run_cpu_s"]
    st = stats(None, ["t_end=0.02", "scheme.contact_step=1e-3"])
    assert st["loop"] == "python" and "controlled" in st["refusal"]
    st = stats("rigid_cable", ["t_end=0.002"])
    assert st is None or st["loop"] != "compiled"
    from cosim.core.schemes import driver
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv(driver.DRIVER_ENV, "python")
        st = stats(None, ["t_end=0.002"])
    assert st["loop"] == "python" and driver.DRIVER_ENV in st["refusal"]
    try:
        implicit_block.ENABLED = False
        st = stats(None, ["t_end=0.002"])
    finally:
        implicit_block.ENABLED = True
    assert st["loop"] == "python" and "ENABLED" in st["refusal"]


def test_a_wrapped_advance_runs_the_python_loop(monkeypatch):
    """A test or a user that wraps the implicit step must see it called:
    the Python loop runs and says so."""
    from cosim.core.schemes.implicit import Implicit
    seen = []
    original = Implicit._advance_compiled

    def spy(self, *args):
        seen.append(args[1])
        return original(self, *args)
    monkeypatch.setattr(Implicit, "_advance_compiled", spy)
    scene = _scene("brachiation", None, ["t_end=0.005"])
    system, sch = build_system(scene)
    sch.run(system, scene.t_end, Recorder(system, scene.name, sch.name, scene.t_end))
    assert len(seen) == 5 and "replaced" in sch.loop_stats["refusal"]


def close_nested(a, b, key=""):
    """Nested dicts of numbers: the same keys, each number within TOL of
    the other, relative, or absolute (SI states of order 1e-3 to 1, whose
    series agree within TOL of their largest value)."""
    if isinstance(b, dict):
        assert sorted(a) == sorted(b), key
        for k in b:
            close_nested(a[k], b[k], f"{key}/{k}")
    elif isinstance(b, (int, float, list, tuple)) and not isinstance(b, bool):
        np.testing.assert_allclose(np.asarray(a, float), np.asarray(b, float), rtol=TOL,
                                   atol=TOL, err_msg=key)
    else:
        assert a == b, key


# ------------------------------------------------------------ guard stops
GUARD_STOPS = [
    # energy growth: at sample 11, inside the first block
    ["guard.energy_growth=2e-7", "guard.energy_floor=0.0"],
    # energy growth at the grasp: the first sample after a switch
    ["guard.energy_growth=1e-5", "guard.energy_floor=0.0"],
    # chatter at the release (a grasp and a release), and after it
    ["guard.chatter_switches=2", "guard.chatter_window=1.0"],
    ["guard.chatter_switches=3", "guard.chatter_window=1.0"]]


@pytest.mark.parametrize("overrides", GUARD_STOPS)
def test_a_guard_stop_is_the_python_loops(monkeypatch, overrides):
    monkeypatch.setattr(implicit_block, "BLOCK", 64)      # several blocks before the stop
    scene = _scene("brachiation", None, overrides)
    ref = run(monkeypatch, scene, False)
    path = run(monkeypatch, scene, True)
    assert ref.status == path.status == "failed"
    same_message(path.message, ref.message)
    assert path.summary["t_end"] == ref.summary["t_end"]
    assert path.summary["macro_steps"] == ref.summary["macro_steps"]
    assert path.summary["iterations"] == ref.summary["iterations"]
    assert len(path.t) == len(ref.t)
    assert series_distance(ref, path) <= TOL
    # the state reported is the last sample kept's, not the loop's past it
    close_nested(path.summary["final_state"], ref.summary["final_state"])


def _at_call(monkeypatch, n, act):
    """Make the cable's ``took_compiled_step`` (which both loops call after
    each step's iterations) do ``act(side)`` at its ``n``-th call."""
    from cosim.core.subsystem import Subsystem
    took = Subsystem.took_compiled_step
    calls = [0]

    def counted(self, t, h, pm):
        took(self, t, h, pm)
        if self.name == "cable":
            calls[0] += 1
            if calls[0] == n:
                act(self)
    monkeypatch.setattr(Subsystem, "took_compiled_step", counted)


def test_a_non_finite_state_stops_as_the_python_loop(monkeypatch):
    """A side whose state turns non-finite mid-run: the run stops at the
    same step with the same message, the samples before it kept."""
    results = []

    def poison(side):
        side.x[0] = math.nan
    for on in (False, True):
        _at_call(monkeypatch, 150, poison)          # inside the third block of 64
        monkeypatch.setattr(implicit_block, "BLOCK", 64)
        results.append(run(monkeypatch, _scene("brachiation", None, ["t_end=0.3"]), on))
    ref, path = results
    assert ref.status == path.status == "failed"
    same_message(path.message, ref.message)
    assert "nan" in path.message
    assert path.summary["t_end"] == ref.summary["t_end"]
    assert path.summary["macro_steps"] == ref.summary["macro_steps"] == 150
    assert len(path.t) == len(ref.t) == 150


def test_an_interrupted_run_keeps_whole_samples(monkeypatch):
    """Ctrl-C inside a block (raised inside a step, as a signal's
    KeyboardInterrupt would be): the samples before it are kept, as in the
    Python loop, and the interrupt is raised again."""
    results = []

    def interrupt(side):
        raise KeyboardInterrupt
    for on in (False, True):
        _at_call(monkeypatch, 100, interrupt)
        monkeypatch.setattr(implicit_block, "BLOCK", 64)
        with pytest.raises(RunInterrupted) as exc:
            run(monkeypatch, _scene("brachiation", None, ["t_end=0.3"]), on)
        results.append(exc.value.result)
    ref, path = results
    assert ref.status == path.status == "interrupted"
    assert len(path.t) == len(ref.t) == 100
    assert path.summary["t_end"] == ref.summary["t_end"]
    assert path.summary["macro_steps"] == ref.summary["macro_steps"]
    assert series_distance(ref, path) <= TOL


def test_an_unconverged_step_fails_as_in_the_python_loop(monkeypatch):
    """Two iterations cannot settle the grasps' first step: the same error."""
    scene = _scene("brachiation", None, ["t_end=0.01", "scheme.max_iterations=2"])
    ref, path = run(monkeypatch, scene, False), run(monkeypatch, scene, True)
    assert ref.status == path.status == "failed"
    assert path.message == ref.message
    assert "did not converge" in path.message
    assert path.summary["macro_steps"] == ref.summary["macro_steps"]
    assert path.summary["iterations"] == ref.summary["iterations"]


def test_counts_hold_under_a_nudge(monkeypatch):
    """The hand-over's counts, steps, iterations and switch times in
    blocks are the Python loop's, for the scene and its copies moved by +-1
    and +-2 ulps."""
    scene = _scene("brachiation", None, ["t_end=0.9"])
    base = None
    for copy in spread(scene, COPIES):
        path = run(monkeypatch, copy, True)
        ref = run(monkeypatch, copy, False)
        counts = {c: v["count"] for c, v in path.summary["contacts"].items()}
        assert counts == {c: v["count"] for c, v in ref.summary["contacts"].items()}
        assert switches(path) == switches(ref)
        assert path.summary["iterations"] == ref.summary["iterations"]
        got = (counts, [s[:2] for s in switches(path)])
        base = got if base is None else base
        assert got == base
    assert len(base[1]) == 3


def test_progress_is_told_of_every_sample_when_asked(monkeypatch):
    """``progress_interval = 0`` asks for every sample: in blocks too, each
    sample's time once, increasing, to the end."""
    calls = []
    monkeypatch.setattr(implicit_block, "ENABLED", True)
    res = cosim.simulate(_scene("brachiation", None, ["t_end=0.9"]), estimate=False,
                         progress=calls.append, progress_interval=0.0)
    t = np.array([p.t for p in calls])
    assert len(t) == len(res.t) and np.all(np.diff(t) > 0)
    np.testing.assert_array_equal(t, res.t)


def test_next_trigger_is_below_every_due_time():
    """The time the compiled loop returns at for a ``time`` or ``after``
    trigger lies below the earliest at which :meth:`Trigger.due` says due
    (within its tolerance), and above it by no more than that tolerance:
    the loop never steps past a switch, and returns for it once."""
    scene = _scene("brachiation", None, ["t_end=0.9"])
    system, _ = build_system(scene)
    cs = system.connections
    assert implicit_block.next_trigger(system) == math.inf      # gripper 2 not grasped yet
    cs.events["gripper2.grasp"] = 0.837
    at = 0.837 + 0.05
    lo = implicit_block.next_trigger(system)
    conn = cs.connections[system.contact_names.index("gripper1")]
    assert lo < at and at - lo < 1e-11
    assert conn.release.due(at * (1 - 1e-12), cs.events)     # due within its tolerance ...
    assert lo < at * (1 - 1e-12)                             # ... and the loop stops before
    assert not conn.release.due(lo * (1 - 1e-12), cs.events)

"""The sampled path's RK4 kernel keeps the switches it locates in rows and
goes on integrating (:meth:`MultibodyStep.sample_steps
<cosim.sides._multibody_step.MultibodyStep.sample_steps>`): a penalty law's
touch or release no longer ends its call; a rigid law's impact (resolved in
Python), a full buffer, a non-finite state, a signal and the end still do.

The macro loop is the reference (``sampled.ENABLED = False``), with the
bounds of ``tests/test_sampled.py``: the RK4 steps are the loop's, from the
same states, so the series agree to round-off (1e-10 of each series'
largest value) and the counts, the stops and their messages are equal.
"""
from __future__ import annotations

import math
import signal

import numpy as np
import pytest

import cosim
from cosim.core.schemes import sampled
from cosim.scene.run import RunInterrupted
from cosim.sides import multibody_kernel
from test_sampled import _scene, run, same_outcome, series_distance

STRIKE_Q0 = 0.09994114       # ground_multicontact_strike's body height [m]


@pytest.fixture
def emits(monkeypatch):
    """The calls of the path's emitter: one per return of the side's kernel
    that brought samples."""
    calls = []
    call = sampled._Emitter.__call__

    def spy(self, smp, switch_row, located=()):
        calls.append((len(smp.t), switch_row, len(located)))
        return call(self, smp, switch_row, located)
    monkeypatch.setattr(sampled._Emitter, "__call__", spy)
    return calls


@pytest.mark.parametrize("name", ["ground_multicontact", "ground_multicontact_strike"])
def test_penalty_switches_stay_in_the_kernel(monkeypatch, emits, name):
    """Both scenes (fewer macro steps than a block) take one call of the
    kernel, their touches and releases kept in its rows, and give the
    loop's run."""
    loop = run(monkeypatch, name, on=False)
    emits.clear()
    path = run(monkeypatch, name, on=True)
    edges = sum(len(v["intervals"]) for v in loop.summary["contacts"].values())
    assert edges >= 3
    assert len(emits) == 1 and emits[0][2] >= edges, emits
    assert series_distance(loop, path) <= 1e-10
    same_outcome(loop, path, 1e-10)


def test_a_full_buffer_hands_the_rest_to_the_host(monkeypatch, emits):
    """With room for one switch a call, the next goes to the host's log and
    ends the call after its step: the same run, in more calls."""
    monkeypatch.setattr(multibody_kernel, "LOCATED", 1)
    loop = run(monkeypatch, "ground_multicontact", on=False)
    emits.clear()
    path = run(monkeypatch, "ground_multicontact", on=True)
    assert len(emits) >= 3 and all(n <= 1 for *_, n in emits)
    assert any(row is not None for _, row, _ in emits)
    assert series_distance(loop, path) <= 1e-10
    same_outcome(loop, path, 1e-10)


def test_a_rigid_impact_still_returns_to_python(monkeypatch, emits):
    """manipulator_wall under RK4: its rigid tip's impact is resolved in
    Python (a return after the impact's step); the run is the loop's,
    impact record included."""
    over = ['subsystems.robot.integrator={method="rk4", max_step=5e-5}']
    loop = run(monkeypatch, "manipulator_wall", "mu0.03", on=False, overrides=over)
    emits.clear()
    path = run(monkeypatch, "manipulator_wall", "mu0.03", on=True, overrides=over)
    assert len(loop.summary["impacts"]) == 1
    assert sum(row is not None for _, row, _ in emits) == 1, emits
    assert series_distance(loop, path) <= 1e-10
    same_outcome(loop, path, 1e-10)


@pytest.mark.parametrize("switches, t_stop", [(3, 0.0377), (5, 0.134)])
def test_a_chatter_stop_inside_the_block_is_the_loops(monkeypatch, emits, switches, t_stop):
    """A's third (fifth) switch trips the guard's chatter rule at a switch
    the kernel kept in the middle of its one block: the same message, time,
    steps and samples as the loop."""
    over = [f"guard.chatter_switches={switches}", "guard.chatter_window=1.0"]
    loop = run(monkeypatch, "ground_multicontact", on=False, overrides=over)
    emits.clear()
    path = run(monkeypatch, "ground_multicontact", on=True, overrides=over)
    assert loop.status == path.status == "failed"
    assert "contact `A` chatters" in path.message and path.message == loop.message
    assert path.summary["t_end"] == loop.summary["t_end"] == pytest.approx(t_stop, abs=1e-4)
    assert path.summary["macro_steps"] == loop.summary["macro_steps"]
    assert len(path.t) == len(loop.t)
    assert len(emits) == 1 and emits[0][0] > len(path.t)     # stopped inside the block
    assert series_distance(loop, path) <= 1e-10


@pytest.mark.parametrize("ulps", [-2, 2])
def test_strike_counts_hold_under_a_nudge(monkeypatch, ulps):
    """ground_multicontact_strike's contact counts (A twice, B and C once)
    on both paths with its body's height nudged by 2 ulps either way."""
    y = STRIKE_Q0 + ulps * math.ulp(STRIKE_Q0)
    over = [f"subsystems.robot.bodies.slider_y.joint.q0={y!r}"]
    loop = run(monkeypatch, "ground_multicontact_strike", on=False, overrides=over)
    path = run(monkeypatch, "ground_multicontact_strike", on=True, overrides=over)
    counts = {c: v["count"] for c, v in path.summary["contacts"].items()}
    assert counts == {c: v["count"] for c, v in loop.summary["contacts"].items()}
    assert counts == {"A": 2, "B": 1, "C": 1}


def test_an_interrupt_keeps_whole_samples_and_their_switches(monkeypatch):
    """Ctrl-C inside the kernel's block once it has kept two switches in
    whole steps (SIGALRM every 5 ms; its handler raises KeyboardInterrupt
    from the kernel's look at the signals): the run keeps the whole macro steps
    before, each with the uninterrupted run's state, and the switches
    located in them."""
    H = 1e-4
    slow = ["subsystems.robot.integrator.max_step=2e-8", "t_end=0.006"]
    ref = run(monkeypatch, "ground_multicontact_strike", on=True, overrides=slow)
    kernels = []
    build = multibody_kernel.SampledSteps.sample_steps

    def keep(self, *args):
        kernels.append(self._compiled())
        return build(self, *args)
    monkeypatch.setattr(multibody_kernel.SampledSteps, "sample_steps", keep)

    armed = []              # the rows filled when the second switch was kept

    def alarm(signum, frame):
        if not kernels or kernels[-1].n_located < 2:
            return
        if not armed:
            armed.append(kernels[-1].n_sampled)
        elif kernels[-1].n_sampled > armed[0]:      # its step is whole
            signal.setitimer(signal.ITIMER_REAL, 0)
            raise KeyboardInterrupt
    old = signal.signal(signal.SIGALRM, alarm)
    signal.setitimer(signal.ITIMER_REAL, 0.005, 0.005)
    try:
        with pytest.raises(RunInterrupted) as info:
            run(monkeypatch, "ground_multicontact_strike", on=True, overrides=slow)
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)
    res = info.value.result
    assert res.status == "interrupted"
    t = np.asarray(res.t)
    m = len(t)
    assert 2 <= m < len(ref.t)
    assert np.allclose(np.diff(t), H, rtol=1e-9, atol=0)
    for k in res.series:        # the same steps from the same states
        a, b = np.asarray(res.series[k], float), np.asarray(ref.series[k], float)[:m]
        scale = max(float(np.max(np.abs(b))), 1e-300)
        assert np.max(np.abs(a - b)) <= 1e-12 * scale, k
    # every switch located before the last kept sample, and none after
    t_last, edges = t[-1], 0
    for c, v in ref.summary["contacts"].items():
        got = res.summary["contacts"][c]["intervals"]
        want = [iv for iv in v["intervals"] if iv[0] <= t_last]
        assert len(got) == len(want), c
        for (a0, a1), (b0, b1) in zip(got, want):
            assert a0 == pytest.approx(b0, rel=1e-12, abs=1e-15), c
            edges += a0 > 0
            if b1 <= t_last:
                assert a1 == pytest.approx(b1, rel=1e-12), c
                edges += 1
    assert edges >= 2


def test_penetrations_at_many_states_are_those_at_each():
    """The kernel's batch of penetrations (an adaptive side's samples) runs
    the formulas of its one-state ``penetrations`` on each row: within an
    ulp of the largest magnitude (the same operations; bounded, not bit
    for bit, as two calls)."""
    system, _ = _scene("manipulator_wall", "mu0.03").build()
    side = next(s for s in system.subsystems if not s.rigid)
    kernel = side._compiled()
    kernel.set_step(0.0, 1e-3, None, side._embedded)
    rng = np.random.default_rng(7)
    n2 = side.x.size
    Y = side.x[None, :] + 0.3 * rng.standard_normal((50, n2))
    T = np.linspace(0.0, 1e-3, 50)
    D = np.full((50, len(side._embedded)), np.nan)
    kernel.sample_penetrations(T, Y, D)
    one = np.array([kernel.penetrations(t, y)[0] for t, y in zip(T, Y)])
    assert np.all(np.abs(D - one) <= np.spacing(np.max(np.abs(one))))
    assert len(np.unique(np.sign(one))) == 2        # both sides of the wall


def test_a_spool_that_fails_inside_the_block_stops_where_the_loop_does(monkeypatch, tmp_path):
    """spring_drop's whole run is one block: its spool's second chunk (64
    rows) cannot be written; the run stopped at the sample whose store
    failed, the loop's message word for word."""
    import errno
    from cosim.core import series
    from cosim.errors import OutputError
    monkeypatch.setattr(series, "CHUNK_BYTES", 1)
    opened = series._open_spool

    class Full:
        def __init__(self, fh):
            self.fh, self.writes = fh, 0

        def write(self, data):
            self.writes += 1
            if self.writes == 2:
                raise OSError(errno.ENOSPC, "No space left on device")
            return self.fh.write(data)

        def __getattr__(self, name):
            return getattr(self.fh, name)
    monkeypatch.setattr(series, "_open_spool", lambda path: Full(opened(path)))
    said = []
    for on in (False, True):
        monkeypatch.setattr(sampled, "ENABLED", on)
        out = tmp_path / f"run{on:d}"
        with pytest.raises(OutputError) as info:
            cosim.simulate(_scene("spring_drop"), out=out)
        said.append(str(info.value).replace(str(out), "DIR"))
    assert said[0] == said[1]
    assert "the run stopped at t = 0.0127 s" in said[1]


def test_the_general_penetrations_give_the_same_run(monkeypatch):
    """The emitter's penetrations from every side's ports (kept for a
    contact whose ports are not one on the moving side, one on a rigid
    partner) agree with its shortcut's, and with the loop."""
    init = sampled._Emitter.__init__

    def general(self, *args):
        init(self, *args)
        assert self.split           # every shipped scene's contacts are split
        self.split = False
    loop = run(monkeypatch, "ground_multicontact", on=False)
    fast = run(monkeypatch, "ground_multicontact", on=True)
    monkeypatch.setattr(sampled._Emitter, "__init__", general)
    slow = run(monkeypatch, "ground_multicontact", on=True)
    assert series_distance(fast, slow) <= 1e-12
    assert series_distance(loop, slow) <= 1e-10
    same_outcome(loop, slow, 1e-10)

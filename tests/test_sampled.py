"""The macro loop's sampled path (:mod:`cosim.core.schemes.sampled`) against
the loop itself, and the recorder's and the guard's blocks
(:meth:`Recorder.record_block`, :meth:`Guard.check_block`) against their
sample-by-sample twins.

The loop is the reference: ``sampled.ENABLED = False`` keeps a run in it.

- RK4 sides take the same steps from the same states on both paths; only
  the penetrations, forces and energies are evaluated on arrays instead of
  one sample at a time, so the series agree to round-off: within 1e-10 of
  each series' largest value.
- An adaptive side (manipulator_wall's DOP853, rtol 1e-10) no longer
  restarts at each output point, so its steps differ: the two paths agree
  within the integrator's own error.  Bounded two ways: the series within
  100 rtol of their largest value, and the distance between the paths no
  larger than twice the sum of each path's distance to its own run at
  tolerances 100 times tighter (the triangle inequality through the exact
  solution, each path's error estimated by its tighter run).
- ``record_block`` and ``record`` on the same samples are the same
  computation: the stored series and the summaries are equal.
"""
from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from conftest import CASES

import cosim
from cosim.core.guard import Guard, GuardError, GuardOptions
from cosim.core.recorder import Recorder
from cosim.core.schemes import driven_block, sampled

RK4_RUNS = [("spring_drop", "undamped"), ("spring_drop", "kelvin_voigt"),
            ("ground_multicontact", "kA1e6"), ("ground_multicontact", "kA4e6"),
            ("ground_multicontact", "kA16e6"), ("ground_multicontact_strike", "kA1e6"),
            ("ground_multicontact_strike", "kA16e6")]
ADAPTIVE_RUNS = [("manipulator_wall", v) for v in ("mu0", "mu0.03", "mu0.15", "mu0.35",
                                                   "penalty")]
RTOL = 1e-10          # manipulator_wall's DOP853


def _scene(name, variant=None, overrides=()):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return cosim.load_scene(CASES / f"{name}.toml", variant, overrides=list(overrides))


def run(monkeypatch, name, variant=None, on=True, overrides=()):
    monkeypatch.setattr(sampled, "ENABLED", on)
    return cosim.simulate(_scene(name, variant, overrides), estimate=False)


def series_distance(a, b) -> float:
    """Largest difference of any series, relative to its largest value."""
    assert set(a.series) == set(b.series)
    worst = 0.0
    for k in a.series:
        x, y = np.asarray(a.series[k], float), np.asarray(b.series[k], float)
        assert x.shape == y.shape, k
        scale = np.max(np.abs(x)) if x.size else 0.0
        if scale > 0:
            worst = max(worst, float(np.max(np.abs(x - y)) / scale))
    return worst


def same_outcome(a, b, tol):
    """Counts, statuses, impacts equal; times and amounts within ``tol``
    (relative to the run's length, or to the amount)."""
    sa, sb = a.summary, b.summary
    assert (sa["status"], sa["macro_steps"]) == (sb["status"], sb["macro_steps"])
    assert sa["t_end"] == pytest.approx(sb["t_end"], rel=1e-12)
    for c, ca in sa["contacts"].items():
        cb = sb["contacts"][c]
        assert ca["count"] == cb["count"], c
        np.testing.assert_allclose(ca["intervals"], cb["intervals"], rtol=0,
                                   atol=tol * sa["t_end"] + 1e-15)
        for key in ("peak_penetration", "impulse", "dissipated", "work"):
            assert cb[key] == pytest.approx(ca[key], rel=tol, abs=1e-15), (c, key)
    assert len(sa["impacts"]) == len(sb["impacts"])
    for ia, ib in zip(sa["impacts"], sb["impacts"]):
        assert (ia["contact"], ia["slip_end"]) == (ib["contact"], ib["slip_end"])
        assert [m for *_, m in ia["slip_history"]] == [m for *_, m in ib["slip_history"]]
        assert ib["time"] == pytest.approx(ia["time"], rel=tol)
        for key in ("normal_impulse", "tangential_impulse"):
            assert ib[key] == pytest.approx(ia[key], rel=tol, abs=tol * ia["normal_impulse"])
    assert [w["kind"] for w in sa["warnings"]] == [w["kind"] for w in sb["warnings"]]


# ----------------------------------------------------------- which runs
@pytest.mark.parametrize("name, variant", RK4_RUNS + ADAPTIVE_RUNS)
def test_scenes_with_only_rigid_partners_take_the_path(name, variant):
    system, sch = _scene(name, variant).build()
    assert sampled.refusal(sch, system) is None


@pytest.mark.parametrize("name, why", [
    ("three_mass", "exchanged between moving sides"),
    ("beam_impact", "exchanged between moving sides"),
    ("brachiation", "iterates"),
    ("rod_impact", "cannot integrate across output points")])
def test_the_others_say_why_not(name, why):
    system, sch = _scene(name).build()
    assert why in sampled.refusal(sch, system)


def test_the_numpy_reference_keeps_the_loop(monkeypatch):
    monkeypatch.setenv("COSIM_KERNEL", "numpy")
    system, sch = _scene("ground_multicontact").build()
    assert "numpy reference" in sampled.refusal(sch, system)


def test_the_switch_keeps_the_loop(monkeypatch):
    monkeypatch.setattr(sampled, "ENABLED", False)
    system, sch = _scene("spring_drop").build()
    assert "switched off" in sampled.refusal(sch, system)


# -------------------------------------------------- the path against the loop
@pytest.mark.parametrize("name, variant", RK4_RUNS)
def test_rk4_sides_give_the_loops_run(monkeypatch, name, variant):
    loop = run(monkeypatch, name, variant, on=False)
    path = run(monkeypatch, name, variant, on=True)
    assert series_distance(loop, path) <= 1e-10
    same_outcome(loop, path, 1e-10)


def test_contact_counts_agree_under_a_nudge(monkeypatch):
    """ground_multicontact's contact counts are the same on both paths with
    its body's height nudged by 4 ulps either way."""
    y0 = 0.09994114
    for y in (y0 + 4 * math.ulp(y0), y0 - 4 * math.ulp(y0)):
        over = [f"subsystems.robot.bodies.slider_y.joint.q0={y!r}", "t_end=0.12"]
        loop = run(monkeypatch, "ground_multicontact", on=False, overrides=over)
        path = run(monkeypatch, "ground_multicontact", on=True, overrides=over)
        counts = {c: v["count"] for c, v in path.summary["contacts"].items()}
        assert counts == {c: v["count"] for c, v in loop.summary["contacts"].items()}
        assert sum(counts.values()) >= 3


@pytest.mark.parametrize("name, variant", ADAPTIVE_RUNS)
def test_an_adaptive_side_agrees_within_its_tolerance(monkeypatch, name, variant):
    loop = run(monkeypatch, name, variant, on=False)
    path = run(monkeypatch, name, variant, on=True)
    assert series_distance(loop, path) <= 100 * RTOL
    same_outcome(loop, path, 100 * RTOL)


@pytest.mark.parametrize("variant", ["mu0.03", "penalty"])
def test_the_adaptive_difference_is_the_integrators_error(monkeypatch, variant):
    tight = ["subsystems.robot.integrator.rtol=1e-12", "subsystems.robot.integrator.atol=1e-14"]
    loop = run(monkeypatch, "manipulator_wall", variant, on=False)
    path = run(monkeypatch, "manipulator_wall", variant, on=True)
    loop_t = run(monkeypatch, "manipulator_wall", variant, on=False, overrides=tight)
    path_t = run(monkeypatch, "manipulator_wall", variant, on=True, overrides=tight)
    between = series_distance(loop, path)
    errors = series_distance(loop, loop_t) + series_distance(path, path_t)
    assert between <= 2 * errors, (between, errors)


# ------------------------------------------------------------ guard stops
@pytest.mark.parametrize("name, variant, overrides", [
    # energy growth: the kelvin_voigt wall's round-off, caught mid-contact
    ("spring_drop", "kelvin_voigt", ["guard.energy_growth=5e-11", "guard.energy_floor=0.0"]),
    ("spring_drop", "kelvin_voigt", ["guard.energy_growth=1e-15", "guard.energy_floor=0.0"]),
    # chatter at the release, and at a rigid impact (its touch and release)
    ("spring_drop", "undamped", ["guard.chatter_switches=2", "guard.chatter_window=1.0"]),
    ("manipulator_wall", "mu0.03", ["guard.chatter_switches=2", "guard.chatter_window=1.0"])])
def test_a_guard_stop_is_the_loops(monkeypatch, name, variant, overrides):
    loop = run(monkeypatch, name, variant, on=False, overrides=overrides)
    path = run(monkeypatch, name, variant, on=True, overrides=overrides)
    assert loop.status == path.status == "failed"
    assert path.message == loop.message
    assert path.summary["t_end"] == loop.summary["t_end"]
    assert path.summary["macro_steps"] == loop.summary["macro_steps"]
    assert len(path.t) == len(loop.t)
    tol = 100 * RTOL if name == "manipulator_wall" else 1e-10
    assert series_distance(loop, path) <= tol


def test_the_energy_stop_falls_inside_a_block(monkeypatch):
    """The stop of the first case above is a sample in the middle of a
    block: the guard's block check names it, not the block's edge."""
    seen = []
    check = Guard.check_block

    def spy(self, t, *args, **kw):
        try:
            check(self, t, *args, **kw)
        except GuardError as exc:
            seen.append((exc.sample, len(t)))
            raise
    monkeypatch.setattr(Guard, "check_block", spy)
    res = run(monkeypatch, "spring_drop", "kelvin_voigt",
              overrides=["guard.energy_growth=5e-11", "guard.energy_floor=0.0"])
    assert res.status == "failed" and "energy grew" in res.message
    (sample, rows), = seen
    assert 0 < sample < rows - 1


def test_a_kernel_failure_keeps_the_samples_before(monkeypatch):
    """A rigid impact that raises inside the kernel's block: the samples
    before it are kept and the run fails as in the loop."""
    from cosim.sides.multibody import MultibodySubsystem

    def refusing(self, t, y, slot):
        raise cosim.SimulationError(f"refused at t = {t:.6g} s")
    monkeypatch.setattr(MultibodySubsystem, "rigid_impact", refusing)
    loop = run(monkeypatch, "manipulator_wall", "mu0", on=False)
    path = run(monkeypatch, "manipulator_wall", "mu0", on=True)
    assert loop.status == path.status == "failed"
    assert path.summary["t_end"] == loop.summary["t_end"] == pytest.approx(0.39)
    assert path.summary["macro_steps"] == loop.summary["macro_steps"]
    assert len(path.t) == len(loop.t)


# --------------------------------------------- record_block against record
def _captured(monkeypatch, name, variant, overrides=()):
    """A loop run's samples as ``record`` received them, with the states,
    peaks and energies it read from the system."""
    rows = []
    record = Recorder.record

    def spy(self, t, d, dd, f, impulse, dissipated, internal=(0.0, 0.0), work=None):
        sysm = self.system
        peaks = np.zeros(sysm.n_contacts)       # what take_peaks will give
        for c, (h, k) in sysm.embedded.items():
            if not sysm.links[c].contact.law.rigid:
                peaks[c] = sysm.subsystems[h].peak[k]
        rows.append((t, d.copy(), dd.copy(), f.copy(), impulse.copy(), np.array(dissipated),
                     np.array(internal, float), None if work is None else np.array(work),
                     np.concatenate([s.x for s in sysm.subsystems]), peaks))
        record(self, t, d, dd, f, impulse, dissipated, internal, work)
    monkeypatch.setattr(Recorder, "record", spy)
    # the compiled loop books one step at a time (in blocks it calls record_block)
    monkeypatch.setattr(driven_block, "ENABLED", False)
    res = run(monkeypatch, name, variant, on=False, overrides=overrides)
    monkeypatch.setattr(Recorder, "record", record)
    return res, rows


def _replay(scene, rows, block: bool, every: int, guard: bool, sizes=(7, 1, 40)):
    system, sch = scene.build()
    auto = [c not in system.embedded for c in range(system.n_contacts)]
    rec = Recorder(system, scene.name, sch.name, scene.t_end, every=every, auto_edges=auto,
                   guard=Guard(system, scene.guard) if guard else None)
    off = system.stacked()
    stopped = None
    try:
        if not block:
            for (t, d, dd, f, imp, diss, internal, work, x, pk) in rows:
                for s, sub in enumerate(system.subsystems):
                    sub.x[...] = x[off[s]:off[s + 1]]
                    sub.peak[...] = 0.0
                for c, (h, k) in system.embedded.items():
                    system.subsystems[h].peak[k] = pk[c]
                rec.record(t, d, dd, f, imp, diss, internal, work)
        else:
            i, n = 0, 0
            while i < len(rows):
                part = rows[i:i + sizes[n % len(sizes)]]
                cols = list(zip(*part))
                rec.record_block(np.array(cols[0]), *(np.array(c) for c in cols[1:7]),
                                 None if cols[7][0] is None else np.array(cols[7]),
                                 x=np.array(cols[8]), peaks=np.array(cols[9]))
                i, n = i + len(part), n + 1
            for s, sub in enumerate(system.subsystems):    # where a side that sampled is
                sub.x[...] = rows[-1][8][off[s]:off[s + 1]]
    except GuardError as exc:
        stopped = str(exc)
    res = rec.finish("finished" if stopped is None else "failed", stopped or "", 0.0, {})
    return res, stopped


@pytest.mark.parametrize("name, variant, every, overrides", [
    ("ground_multicontact", "kA1e6", 1, ["t_end=0.12"]),
    ("ground_multicontact", "kA1e6", 3, ["t_end=0.12"]),
    # a contact exchanged by the scheme: onsets and peaks located between samples
    ("three_mass", "f10", 2, ["t_end=0.15", 'contacts.C.placement="coupler"',
                             "scheme.accept_unsafe_step=true"]),
    # a guard stop part-way
    ("spring_drop", "kelvin_voigt", 1, ["guard.energy_growth=5e-11",
                                        "guard.energy_floor=0.0"])])
def test_record_block_stores_what_record_stores(monkeypatch, name, variant, every, overrides):
    _, rows = _captured(monkeypatch, name, variant, overrides)
    scene = _scene(name, variant, overrides)
    one, stop_one = _replay(scene, rows, False, every, True)
    many, stop_many = _replay(scene, rows, True, every, True)
    if name == "three_mass":        # the recorder located C's touches itself
        assert many.summary["contacts"]["C"]["count"] >= 1
    assert stop_one == stop_many
    assert set(one.series) == set(many.series)
    for k in one.series:
        assert np.array_equal(np.asarray(one.series[k]), np.asarray(many.series[k])), k
    assert one.summary == many.summary


def test_check_block_raises_where_check_would():
    """A block whose created energy crosses the bound at sample 5; sample 2
    passes only on the slow path's second look (which raises the scale), and
    sample 4 only under the raised scale."""
    scene = _scene("spring_drop")
    system, _ = scene.build()
    d0, _ = system.penetrations(system.outputs())
    m = 8
    t = np.arange(1, m + 1) * 1e-4
    d, dd, f = np.zeros((m, 1)), np.zeros((m, 1)), np.zeros((m, 1))
    # the wall stores 2 J at every sample: the first check above the start's
    # bound (0.1 of 0.5 J) raises the scale to 2 J, and the bound to 0.2 J
    d[:] = 2e-3
    created = np.array([0.0, 0.01, 0.08, 0.02, 0.12, 0.3, 0.0, 0.0])
    supplied, diss = np.zeros(m), np.zeros((m, 1))

    def verdict(block):
        g = Guard(system, GuardOptions(energy_growth=0.1, energy_floor=0.0))
        g.check(0.0, d0, np.zeros(1), np.zeros(1), 0.0, 0.0, np.zeros(1))
        try:
            if block:
                g.check_block(t, d, dd, f, created, supplied, diss)
            else:
                for j in range(m):
                    g.check(t[j], d[j], dd[j], f[j], created[j], supplied[j], diss[j])
        except GuardError as exc:
            return exc.t, exc.cause, str(exc), exc.sample, g.scale
        return None

    one, many = verdict(False), verdict(True)
    assert one[:3] == many[:3] and one[4] == many[4]
    assert many[3] == 5 and one[0] == pytest.approx(6e-4)

"""The structure's compiled RK4 with hosted nonlinear contacts
(``cosim.sides._structure_rk``) against the numpy reference.

A structure that hosts a Hertz, Hunt-Crossley, Lankarani-Nikravesh or Flores
contact integrates each step over which the contact is, or becomes, closed by
RK4 (:meth:`cosim.sides.fem.StructureSubsystem._step_impl`).  The kernel takes
the same sub-steps with the same right-hand side, switch location and peak
location; its sums run in another order (``R q`` by rows, the modal force
port by port), so each right-hand side differs by a few ulp of its largest
term and the runs differ by round-off carried over some thousand sub-steps:
the bounds below are 1e-9 relative (times: 1e-9 s), some 10^6 ulp, and six
decades below any physical difference (a contact count, a sub-step).  The
counts must also hold with the initial state nudged by 2 ulp either way.
"""
import numpy as np
import pytest

import cosim
from conftest import CASES, ROOT
from cosim.core.schemes import driver
from cosim.scene.build import build_system
from cosim.sides.fem import StructureSubsystem

SCENES = ROOT / "benchmarks" / "results" / "bench_ratio" / "scenes"
#: just past the first strike of each generated scene (its touch at about 4-7 ms)
#: and the joint nudged in ulps
GENERATED = {"gen0-007": (0.012, "subsystems.robot.bodies.link1.joint.dq0", -0.818987284250423),
             "gen0-036": (0.012, "subsystems.robot.bodies.link1.joint.dq0", -0.0445063211451408)}
HERTZ = ['contacts.C.law={type = "hertz", contact_stiffness = 1e9, exponent = 1.5}',
         "t_end=0.106"]
RTOL = 1e-9


def _run(monkeypatch, path, over, kernel="compiled", loop="compiled"):
    monkeypatch.setenv("COSIM_KERNEL", kernel)
    monkeypatch.setenv("COSIM_DRIVER", loop)
    run = cosim.simulate(cosim.load_scene(path, overrides=over), estimate=False)
    assert run.success, run.message
    return run


def _no_reference(*args):
    raise AssertionError("the numpy reference's right-hand side was called")


def _intervals(run):
    return [(e["contact"], e["t_on"], e["t_off"]) for e in run.contact_events]


def _assert_same(ref, com):
    """Counts and intervals equal (times within 1e-9 s), the contacts' peaks,
    impulses, dissipation and work and the final states within RTOL."""
    a, b = _intervals(ref), _intervals(com)
    assert len(a) == len(b) and a, (a, b)
    for (ca, ta, ua), (cb, tb, ub) in zip(a, b):
        assert ca == cb
        assert abs(ta - tb) <= 1e-9 and (ua is None) == (ub is None)
        assert ua is None or abs(ua - ub) <= 1e-9
    for name, c in ref.summary["contacts"].items():
        d = com.summary["contacts"][name]
        assert d["count"] == c["count"] and c["count"] >= 1
        for key in ("peak_penetration", "impulse", "dissipated", "work", "in_touch_time"):
            assert abs(d[key] - c[key]) <= RTOL * max(abs(c[key]), 1e-12), (name, key)
    for key in ref.series:
        x, y = np.asarray(ref.series[key], float), np.asarray(com.series[key], float)
        assert np.max(np.abs(x - y), initial=0.0) <= RTOL * max(np.max(np.abs(x)), 1e-12), key


def test_the_kernel_is_built_on_the_tree_laws():
    """CI fails, not falls back, when it did not build; its laws are the
    multibody kernel's (one evaluation of each law for every side)."""
    from cosim.sides import _multibody_tree, _structure_rk
    assert _structure_rk.StructureRK.__mro__[1] is _multibody_tree.TreeDynamics
    assert _structure_rk.RK_API == 1


@pytest.mark.parametrize("name", sorted(GENERATED))
def test_generated_strike_matches_the_reference(monkeypatch, name):
    """A generated scene whose chain hosts a nonlinear law: the compiled
    step against the numpy reference, and the compiled loop takes the run."""
    t_end, key, v = GENERATED[name]
    over = [f"t_end={t_end}"]
    ref = _run(monkeypatch, SCENES / f"{name}.toml", over, kernel="numpy", loop="python")
    with monkeypatch.context() as m:        # every contact phase in the kernel
        m.setattr(StructureSubsystem, "_rhs", _no_reference)
        com = _run(monkeypatch, SCENES / f"{name}.toml", over)
    _assert_same(ref, com)
    system, scheme = build_system(cosim.load_scene(SCENES / f"{name}.toml", overrides=over))
    assert driver.refusal(scheme, system) is None
    # the count is no accident of round-off: 2 ulp either way of a joint rate
    for ulps in (-2, 2):
        w = v
        for _ in range(abs(ulps)):
            w = np.nextafter(w, np.inf if ulps > 0 else -np.inf)
        nudged = _run(monkeypatch, SCENES / f"{name}.toml", over + [f"{key}={float(w)!r}"])
        assert len(_intervals(nudged)) == len(_intervals(com)), ulps


def test_the_compiled_loop_matches_the_python_loop(monkeypatch):
    """The compiled loop, which takes such a run now, against the Python loop,
    both with the compiled step."""
    over = ["t_end=0.012"]
    a = _run(monkeypatch, SCENES / "gen0-007.toml", over, loop="python")
    b = _run(monkeypatch, SCENES / "gen0-007.toml", over, loop="compiled")
    _assert_same(a, b)


def test_hertz_strike_on_the_beam_matches_the_reference(monkeypatch):
    """beam_impact with C a Hertz contact (28 modes, the beam hosting C)."""
    ref = _run(monkeypatch, CASES / "beam_impact.toml", HERTZ, kernel="numpy", loop="python")
    com = _run(monkeypatch, CASES / "beam_impact.toml", HERTZ)
    _assert_same(ref, com)
    system, scheme = build_system(cosim.load_scene(CASES / "beam_impact.toml", overrides=HERTZ))
    assert driver.refusal(scheme, system) is None


def _damped_chain_hunt_crossley(rows):
    """Two 0.1 kg masses on 1e5 N/m springs with stiffness-proportional damping, the top one
    rising at 1 m/s towards a point 0.1 mm above it, a Hunt-Crossley contact
    (k 1e9, n 1.5): a touch and a release inside one 3 ms step under a port
    force polynomial of ``rows`` coefficients."""
    import fem
    from couplers import HuntCrossleyLaw, PointContact
    from cosim.core.subsystem import StepInput
    s = fem.Chain((0.1, 0.1), (1e5, 1e5), spacing=0.05, rayleigh=(0.0, 2e-5)).assemble()
    sub = StructureSubsystem("chain", s, fem.modes(s), {"top": 0}, v0=np.ones(2),
                             contact_step=1e-6)
    law = HuntCrossleyLaw(1e9, 1.5, 0.3)
    sub.embed_contact(PointContact("c", law, (0.0, 1.0)), 0, -1.0, (0.0, 1e-4))
    coeffs = np.zeros((rows, 1, 2))
    coeffs[:2, 0, 1] = (-20.0, 35.0)
    coeffs[2:, 0, 1] = 10.0
    return sub, StepInput(0.0, 3e-3, coeffs)


@pytest.mark.parametrize("rows", [2, 3])
def test_one_step_of_a_damped_chain_matches_the_reference(monkeypatch, rows):
    """One step with a touch and a release, value by value (a linear and a
    quadratic port load)."""
    subs = {}
    for kernel in ("numpy", "compiled"):
        monkeypatch.setenv("COSIM_KERNEL", kernel)
        sub, inp = _damped_chain_hunt_crossley(rows)
        sub.step(0.0, 3e-3, inp)
        subs[kernel] = sub
    ref, com = subs["numpy"], subs["compiled"]
    assert bool(com._rk) and not ref._rk
    assert [(j, on) for _, j, on in ref.switch_log] == [(0, True), (0, False)]
    assert [(j, on) for _, j, on in com.switch_log] == [(0, True), (0, False)]
    np.testing.assert_allclose([t for t, _, _ in com.switch_log],
                               [t for t, _, _ in ref.switch_log], rtol=0, atol=1e-12)
    for a, b in [(ref.x, com.x), (ref.aux, com.aux), (ref.port_moments, com.port_moments),
                 (ref.peak, com.peak)]:
        assert np.abs(a).max() > 0
        np.testing.assert_allclose(b, a, rtol=0, atol=1e-9 * np.abs(a).max())
    assert ref.aux[-2] > 0 and ref.aux[1] > 0       # damping and the law both dissipate


def test_the_compiled_loop_steps_the_contact_phases_through_the_face(monkeypatch):
    """In the compiled loop, the structure's steps that start with the
    contact closed go through the RK4 kernel's C face with no Python call,
    the others through its Python step (exact in free flight); the robot's
    all through its face."""
    from cosim.core.recorder import Recorder
    monkeypatch.setenv("COSIM_KERNEL", "compiled")
    monkeypatch.setenv("COSIM_DRIVER", "compiled")
    scene = cosim.load_scene(SCENES / "gen0-007.toml", overrides=["t_end=0.012"])
    system, sch = build_system(scene)
    sch.run(system, scene.t_end, Recorder(system, scene.name, sch.name, scene.t_end))
    stats = sch.loop_stats
    assert stats["loop"] == "compiled"
    steps = stats["macro_steps"] + sch.n_rejected
    assert stats["face_steps"] + stats["python_side_steps"] == 2 * steps
    assert steps < stats["face_steps"] < 2 * steps      # the robot's, and some of the chain's

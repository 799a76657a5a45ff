"""The compiled macro loop steps its sides through their C faces
(:mod:`cosim.core.schemes._driver_faces`, :mod:`cosim.core._side_face`).

three_mass f100 (a structure hosting a contact against the moving robot,
the robot's RK4 with two ground contacts embedded; and C hosted by the
robot instead) and beam_impact (the beam's contact follows the arm) take every side step through a face
(``face_steps``, ``python_side_steps`` of the scheme's ``loop_stats``), and
agree with the Python loop (``COSIM_DRIVER=python``, the reference) for the
scenes and for copies moved by one and two ulps
(:func:`cosim.studies.roundoff.spread`): the same contact counts, macro
steps and rejected tries, and intervals, peaks and series within bounds.

The bounds: the faces evaluate the Python steps' formulas in the same
order, and a side's Python ``outputs`` is its kernel's (the bits the face
reads); but the Python loop moves beam_impact's following contact point in
numpy (``CoupledSystem.update_followers``) where the compiled loop moves it
in C (:mod:`cosim.core.schemes._follow`), an ulp apart at times.  Measured
here: three_mass identical but for the order of the energy's sum (3e-16 of
its largest magnitude); beam_impact's located switch times within 6e-16 s,
peaks within 2e-15 relative, series within 2e-12 of their largest
magnitude.  Bounded at 1e-12 s (a thousand times the largest seen, 1e-7 of
the contact step), 1e-12 relative, and the 1e-10 of ``tests/test_driver.py``.
"""
from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

import cosim
from cosim.core.recorder import Recorder
from cosim.core.schemes import driven_block, driver
from cosim.scene.build import build_system
from cosim.sides.kernel import kernel_choice, retired
from cosim.studies.roundoff import spread

CASES = Path(__file__).resolve().parents[1] / "cases"
#: (scene, variant, overrides): C hosted by the chain, by the robot (its face
#: takes the partner's motion), and beam_impact's following C
SCENES = [("three_mass", "f100", ()), ("three_mass", "f100", ('contacts.C.host="robot"',)),
          ("beam_impact", None, ())]
#: located switch times [s], peaks (relative), series (of their largest magnitude)
INTERVAL_TOL, PEAK_REL, SERIES_REL = 1e-12, 1e-12, 1e-10

pytestmark = pytest.mark.skipif(kernel_choice() == "numpy",
                                reason="the C faces are the compiled kernels'")


def _scene(name, variant, overrides=()):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return cosim.load_scene(CASES / f"{name}.toml", variant, overrides=overrides)


def _stats(scene, before_run=None):
    """The scheme's ``loop_stats`` of a run of ``scene`` (``before_run(system,
    recorder)`` first)."""
    system, sch = build_system(scene)
    rec = Recorder(system, scene.name, sch.name, scene.t_end)
    if before_run is not None:
        before_run(system, rec)
    sch.run(system, scene.t_end, rec)
    return sch.loop_stats, sch, system


@pytest.mark.parametrize("name,variant,overrides", SCENES)
def test_every_side_step_goes_through_a_face(name, variant, overrides):
    stats, sch, system = _stats(_scene(name, variant, overrides))
    assert stats["loop"] == "compiled"
    moving = sum(not sub.rigid for sub in system.subsystems)
    assert stats["python_side_steps"] == 0
    assert stats["face_steps"] == moving * (stats["macro_steps"] + sch.n_rejected) > 0


def _run(scene, loop, monkeypatch):
    monkeypatch.setenv(driver.DRIVER_ENV, loop)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return cosim.simulate(scene, estimate=False)


def _assert_agree(ref, got):
    sr, sg = ref.summary, got.summary
    assert (sg["status"], sg["macro_steps"], sg["rejected_steps"]) == (
        sr["status"], sr["macro_steps"], sr["rejected_steps"])
    cr, cg = sr["contacts"], sg["contacts"]
    assert {n: c["count"] for n, c in cg.items()} == {n: c["count"] for n, c in cr.items()}
    for n, c in cr.items():
        a, b = np.asarray(c["intervals"], float), np.asarray(cg[n]["intervals"], float)
        assert a.shape == b.shape and np.max(np.abs(a - b), initial=0.0) <= INTERVAL_TOL, n
        assert cg[n]["peak_penetration"] == pytest.approx(c["peak_penetration"], rel=PEAK_REL)
    for key in ref.series:
        a, b = np.asarray(ref.series[key], float), np.asarray(got.series[key], float)
        assert a.shape == b.shape, key
        scale = float(np.max(np.abs(a), initial=0.0))
        assert np.max(np.abs(a - b), initial=0.0) <= SERIES_REL * scale, key


@pytest.mark.parametrize("name,variant,overrides", SCENES)
def test_the_faces_agree_with_the_python_loop_under_round_off(name, variant, overrides,
                                                              monkeypatch):
    """Counts equal, intervals, peaks and series within the module's bounds,
    for the scene and its copies moved by +-1 and +-2 ulps."""
    counts = set()
    for scene in spread(_scene(name, variant, overrides), 5):
        ref, got = _run(scene, "python", monkeypatch), _run(scene, "compiled", monkeypatch)
        _assert_agree(ref, got)
        counts.add(tuple(sorted((n, c["count"]) for n, c in got.summary["contacts"].items())))
    assert len(counts) == 1, counts


def test_a_renewed_kernel_takes_one_python_step_then_its_new_face(monkeypatch):
    """A side that drops its kernel between two blocks (as a plane body
    does when a spring's stiffness changes): the face's generation changes,
    the side's next step is its Python step (which builds the new kernel),
    and the steps after go through the new kernel's face; the run is the
    undisturbed run's."""
    monkeypatch.setattr(driven_block, "BLOCK", 64)
    scene = _scene("three_mass", "f100")
    plain, _, plain_system = _stats(scene)
    dropped = []

    def drop_after_first_block(system, rec):
        chain = system.subsystems[0]
        record = rec.record_block

        def record_then_drop(*args, **kwargs):
            record(*args, **kwargs)
            if not dropped:
                dropped.append(chain._kernel)
                chain._kernel = retired(chain._kernel)
        rec.record_block = record_then_drop
    stats, sch, system = _stats(scene, drop_after_first_block)
    assert dropped and system.subsystems[0]._kernel not in (None, False, dropped[0])
    assert stats["python_side_steps"] == 1
    assert stats["face_steps"] == plain["face_steps"] - 1
    assert stats["macro_steps"] == plain["macro_steps"]
    # the same formulas on the same state (the new kernel is built as the first was)
    for sub, ref in zip(system.subsystems, plain_system.subsystems):
        assert np.allclose(sub.x, ref.x, rtol=1e-12, atol=1e-12 * np.max(np.abs(ref.x),
                                                                      initial=0.0)), sub.name


def test_a_stalled_structure_step_is_declined_by_the_face(monkeypatch):
    """The structure step the compiled kernel stalls in (three_mass f100 at
    contact steps of 100 us without landing, ``tests/test_kernel_structure.py``)
    is declined by the face, changing nothing, and taken by the side's Python
    step, which hands it to the reference; every other step goes through the
    faces, and the run agrees with the Python loop's."""
    scene = _scene("three_mass", "f100", ("scheme.contact_step=1e-4",
                                          "scheme.land_onsets=false"))
    stats, sch, system = _stats(scene)
    assert stats["loop"] == "compiled" and stats["python_side_steps"] == 1
    moving = sum(not sub.rigid for sub in system.subsystems)
    assert stats["face_steps"] == moving * (stats["macro_steps"] + sch.n_rejected) - 1
    _assert_agree(_run(scene, "python", monkeypatch), _run(scene, "compiled", monkeypatch))


def test_a_side_whose_outputs_are_replaced_offers_no_face(monkeypatch):
    """The face stands in for the side's ``outputs``, step and switch
    handler: where one is replaced (a subclass, a test's patch) the side
    offers no face and the loop takes its Python methods."""
    from cosim.core.subsystem import StepInput
    from cosim.sides.fem import StructureSubsystem
    system, _ = build_system(_scene("three_mass", "f100"))
    chain = system.subsystems[0]
    inp = StepInput.zero(0.0, 1e-3, chain.n_ports)
    assert chain.loop_kernel(inp) is chain.compiled_step(inp) is not None
    monkeypatch.setattr(StructureSubsystem, "outputs", lambda self, t, x: (None, None))
    assert chain.loop_kernel(inp) is None
    monkeypatch.undo()
    assert chain.loop_kernel(inp) is not None
    chain.reference_step = lambda t, h, inputs: None
    assert chain.loop_kernel(inp) is None
    robot = system.subsystems[system.names.index("robot")]
    assert robot.loop_kernel(StepInput.zero(0.0, 1e-3, robot.n_ports)) is not None
    robot._on_switch = lambda t, j, on, y: None         # a switch handler of its own
    assert robot.loop_kernel(StepInput.zero(0.0, 1e-3, robot.n_ports)) is None


def test_a_trees_energies_are_taken_in_one_compiled_call():
    """The recorder's energies of a multibody side's states (each block's
    rows) are the kernel's ``energy`` of each row, evaluated in one call:
    the same function on the same rows (bounded at 1e-14 of the largest)."""
    from cosim.core.subsystem import Subsystem
    system, _ = build_system(_scene("three_mass", "f100"))
    robot = system.subsystems[system.names.index("robot")]
    rng = np.random.default_rng(3)
    X = robot.x + 0.1 * rng.standard_normal((50, robot.x.size))
    one = robot.energies(X[:, :])
    rows = Subsystem.energies(robot, X)
    assert one.shape == rows.shape == (50,)
    assert np.max(np.abs(one - rows)) <= 1e-14 * np.max(np.abs(rows))

"""The compiled macro loop (``cosim.core.schemes._driver``) against the Python
loop it mirrors (:meth:`cosim.core.schemes.base.CoSimulationScheme.run`).

Every shipped scene and variant runs both ways over the same compiled
sides (``COSIM_DRIVER=python`` forces the Python loop), and so do a few
configurations no scene ships but the compiled loop covers: contacts
exchanged as forces (``placement = "coupler"``) against a rigid and against
a moving partner, under Jacobi and Gauss-Seidel, at extrapolation orders 0,
1 and 2, with and without macro-step control.  Both runs must give the same
contact counts and status, and every series must agree within 1e-10 of its
largest magnitude: the two loops evaluate the same formulas in the same
order, so they differ at most by round-off, which no shipped scene here
amplifies beyond that bound.

Which scenes take the compiled loop is stated here (:data:`TAKES_DRIVER`),
with the reason each other one gives.  With ``COSIM_KERNEL=compiled`` (the
default) the compiled loop must be built: a missing module fails
:func:`test_the_compiled_loop_is_built_and_taken`, it is not skipped.
"""
from __future__ import annotations

import importlib
import tomllib
import warnings
from pathlib import Path

import numpy as np
import pytest

import cosim
from cosim.core.recorder import Recorder
from cosim.core.schemes import driver
from cosim.scene.build import build_system
from cosim.sides.kernel import kernel_choice

CASES = Path(__file__).resolve().parents[1] / "cases"

#: scene -> (variants that take the compiled loop: "all" or a set, the
#: reason the others give)
TAKES_DRIVER = {
    "three_mass": ("all", None),
    "spring_drop": ("all", None),
    "rod_impact": ("all", None),
    "ground_multicontact": ("all", None),
    "ground_multicontact_strike": ("all", None),
    "beam_impact": ("all", None),
    "brachiation": (set(), "scheme `implicit` is not an explicit scheme the compiled loop knows"),
    "manipulator_wall": (set(), "side `robot` is integrated by ScipyDOP853, not RK4"),
}

#: a shorter run where a scene is long (the loop's work per step is what is compared)
SHORT = {"ground_multicontact": ("t_end=0.05",)}

#: configurations that no scene ships: (scene, variant, overrides)
EXTRA = [
    # a contact exchanged against a rigid partner, with and without step control
    ("spring_drop", "undamped", ('contacts.wall.placement="coupler"', "scheme.macro_step=5e-6")),
    ("spring_drop", "kelvin_voigt", ('contacts.wall.placement="coupler"',
                                     "scheme.extrapolation_order=1", "scheme.contact_step=2e-6")),
    ("spring_drop", "undamped", ('contacts.wall.placement="coupler"', 'scheme.name="jacobi"',
                                 "scheme.extrapolation_order=2", "scheme.contact_step=2e-6")),
    # an onset no linear prediction sees (a constant push): rolled back, landed on
    ("spring_drop", "undamped", ('contacts.wall.placement="coupler"', "scheme.macro_step=5e-3",
                                 "scheme.contact_step=1.25e-5", "scheme.accept_unsafe_step=true",
                                 'subsystems.body.bodies.mass.joint.drive={type="constant", '
                                 'torque=-2000.0}', "subsystems.body.bodies.mass.joint.dq0=0.5")),
    ("spring_drop", "undamped", ('contacts.wall.placement="coupler"', "scheme.macro_step=5e-3",
                                 "scheme.contact_step=1.25e-5", "scheme.accept_unsafe_step=true",
                                 'scheme.name="jacobi"', "scheme.extrapolation_order=2",
                                 'subsystems.body.bodies.mass.joint.drive={type="constant", '
                                 'torque=-500.0}', "subsystems.body.bodies.mass.joint.dq0=-0.5")),
    # the run guard stops a lagging coupling: at the same sample both ways
    ("spring_drop", "undamped", ('contacts.wall.placement="coupler"',
                                 "scheme.accept_unsafe_step=true", "scheme.extrapolation_order=0")),
    # the hosted contact under Jacobi (partner motion extrapolated, never Hermite)
    ("three_mass", "f10", ('scheme.name="jacobi"',)),
    ("three_mass", "f10", ("scheme.extrapolation_order=0",)),
    ("three_mass", "f10", ("scheme.extrapolation_order=2",)),
    # a predicted onset that shortens the step only within its horizon
    ("three_mass", "f100", ("scheme.approach_horizon=5e-4",)),
    ("spring_drop", "undamped", ('contacts.wall.placement="coupler"', "scheme.macro_step=1e-3",
                                 "scheme.contact_step=1.25e-5", "scheme.accept_unsafe_step=true",
                                 "scheme.approach_horizon=1e-4")),
    # a structure step the compiled kernel stalls in, taken by the reference
    ("three_mass", "f100", ("scheme.contact_step=1e-4", "scheme.accept_unsafe_step=true")),
    # a contact exchanged between two moving sides
    ("three_mass", "f1", ('contacts.C.placement="coupler"', "scheme.accept_unsafe_step=true")),
    ("three_mass", "f1", ('contacts.C.placement="coupler"', "scheme.accept_unsafe_step=true",
                          'scheme.name="jacobi"', "scheme.extrapolation_order=2")),
    ("three_mass", "f1", ('contacts.C.placement="coupler"', "scheme.accept_unsafe_step=true",
                          'scheme.sequence=["robot", "chain"]')),
]


def _variants(name):
    spec = tomllib.loads((CASES / f"{name}.toml").read_text())
    return [None] + list(spec.get("variants", {}))


def _shipped():
    return [(name, v) for name in sorted(TAKES_DRIVER) for v in _variants(name)]


def _load(name, variant, overrides=()):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return cosim.load_scene(CASES / f"{name}.toml", variant,
                                overrides=SHORT.get(name, ()) + tuple(overrides))


def _refusal(name, variant, overrides=()):
    system, sch = build_system(_load(name, variant, overrides))
    return driver.refusal(sch, system)


def _both_ways(name, variant, overrides, monkeypatch):
    out = []
    for loop in ("python", "compiled"):
        monkeypatch.setenv(driver.DRIVER_ENV, loop)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            out.append(cosim.simulate(_load(name, variant, overrides), estimate=False))
    return out


def _assert_same(ref, got):
    assert got.status == ref.status, (got.status, got.message, ref.message)
    assert got.message == ref.message
    cr, cg = ref.summary["contacts"], got.summary["contacts"]
    assert {k: v["count"] for k, v in cg.items()} == {k: v["count"] for k, v in cr.items()}
    assert got.summary["macro_steps"] == ref.summary["macro_steps"]
    assert got.summary["rejected_steps"] == ref.summary["rejected_steps"]
    assert set(got.series) == set(ref.series)
    for key in ref.series:
        a, b = np.asarray(ref.series[key], float), np.asarray(got.series[key], float)
        assert a.shape == b.shape, key
        scale = float(np.max(np.abs(a))) if a.size else 0.0
        assert np.max(np.abs(a - b), initial=0.0) <= 1e-10 * scale, key


needs_compiled = pytest.mark.skipif(kernel_choice() == "numpy",
                                    reason="COSIM_KERNEL=numpy runs the Python loop only")


@needs_compiled
@pytest.mark.parametrize("name, variant", _shipped())
def test_which_scenes_take_the_compiled_loop(name, variant):
    takes, reason = TAKES_DRIVER[name]
    why = _refusal(name, variant)
    if takes == "all" or variant in takes:
        assert why is None
    else:
        assert why == reason


@needs_compiled
@pytest.mark.parametrize("name, variant", [(n, v) for n, v in _shipped()
                                           if TAKES_DRIVER[n][0] == "all"])
def test_every_shipped_scene_matches_the_python_loop(name, variant, monkeypatch):
    ref, got = _both_ways(name, variant, (), monkeypatch)
    _assert_same(ref, got)


@needs_compiled
@pytest.mark.parametrize("name, variant, overrides", EXTRA)
def test_covered_configurations_match_the_python_loop(name, variant, overrides, monkeypatch):
    assert _refusal(name, variant, overrides) is None
    ref, got = _both_ways(name, variant, overrides, monkeypatch)
    _assert_same(ref, got)


@needs_compiled
def test_a_guard_stop_is_the_python_loops(monkeypatch):
    """The guard stops the held force of a step too long for the wall at the
    same sample both ways, and the run's final state is the last sample kept."""
    ref, got = _both_ways("spring_drop", "undamped", EXTRA[5][2], monkeypatch)
    assert ref.status == "failed" and "the guard tripped at t = 0.0126 s" in ref.message
    _assert_same(ref, got)
    fr, fg = ref.summary["final_state"], got.summary["final_state"]
    for side, coords in fr.items():
        for name, qv in coords.items():
            assert fg[side][name] == pytest.approx(qv, rel=1e-10, abs=1e-300)


def test_the_compiled_loop_is_built_and_taken(monkeypatch):
    """Built wherever the compiled kernels are chosen (a missing module is an
    error here, not a skip), and taken by three_mass f100 for its whole run,
    every macro step of it; ``COSIM_KERNEL=numpy`` and ``COSIM_DRIVER=python``
    run the Python loop."""
    if kernel_choice() == "numpy":
        assert _refusal("three_mass", "f100") == ("the numpy reference was asked for "
                                                  "(`COSIM_KERNEL=numpy`)")
        return
    importlib.import_module("cosim.core.schemes._driver")
    scene = _load("three_mass", "f100")
    system, sch = build_system(scene)
    sch.run(system, scene.t_end, Recorder(system, scene.name, sch.name, scene.t_end))
    assert sch.loop_refusal is None
    stats = sch.loop_stats
    assert stats["loop"] == "compiled"
    assert stats["macro_steps"] == sch.n_windows > 0
    assert 0.0 < stats["compiled_cpu_s"] <= stats["run_cpu_s"]
    monkeypatch.setenv(driver.DRIVER_ENV, "python")
    assert _refusal("three_mass", "f100") == "the Python loop was asked for (`COSIM_DRIVER=python`)"


@needs_compiled
def test_a_replaced_advance_runs_the_python_loop(monkeypatch):
    """A scheme whose ``advance`` was wrapped (as tests that inject a fault
    do) runs the Python loop, which calls it."""
    from cosim.core.schemes.explicit import GaussSeidel
    original = GaussSeidel.advance
    calls = []

    def wrapped(self, system, t, h, ratio):
        calls.append(t)
        return original(self, system, t, h, ratio)

    monkeypatch.setattr(GaussSeidel, "advance", wrapped)
    assert _refusal("spring_drop", None) == "the `advance` of scheme `gauss_seidel` is replaced"
    res = cosim.simulate(_load("spring_drop", None), estimate=False)   # its advances counted
    assert len(calls) == res.n_windows > 0


def test_a_wrong_loop_choice_is_refused(monkeypatch):
    monkeypatch.setenv(driver.DRIVER_ENV, "fast")
    with pytest.raises(ValueError, match=r"`COSIM_DRIVER` must be one of \['compiled', "
                                         r"'python'\], got 'fast'"):
        driver.driver_choice()

"""Following contacts (``follow = true``) in the compiled macro loop
(``cosim.core.schemes._follow``) against the Python loop, which stays the
reference (``COSIM_DRIVER=python``).

A following contact moves side b's surface point under side a's point
before every macro step: the port's shape row and reference position, the
deformed surface's slope in the penetration rate and side a's force turned
to ``n - sigma e`` (``CoupledSystem.update_followers``).  The compiled loop
does the same in C, through the structure's compiled face.  The two loops
are not bit-equal: the Python loop forms the port's row as numpy's product of
the four shape weights with the mode shapes, the compiled face as a sum in
element order, so the rows differ by an ulp or so each step, and the strikes
amplify that round-off along the run (observed at most 1.5e-11 of a series'
largest magnitude over the configurations below, 1.2e-13 for the shipped
scene; one, whose reference itself amplifies round-off more, has its own
bound).  Hence the bounds: every series within :data:`RTOL` of its largest
magnitude, every contact interval's ends within :data:`DT` [s], every ledger
entry within :data:`RTOL` of the energy scale, and the same contact counts,
macro steps and rejected tries, also for copies of the scene moved by a few
ulps.  The runs are the shipped scene's own 0.13 s (two strikes of C, the
robot drifting under it as it slides): over seconds the bouncing robot
turns round-off into other contact counts in either loop (a 2-ulp copy of
beam_impact at ``t_end = 10`` has 78, 80 or 79 touches of A), so a long run
compares nothing a short one does not.
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
from roundoff import outcomes

CASES = Path(__file__).resolve().parents[1] / "cases"

#: a series, or a ledger entry, of the two loops within this of its scale
RTOL = 1e-9
#: a contact interval's ends within this [s] (the contact step is 50 us)
DT = 1e-10

#: configurations of the shipped scene that follows, each covered by the compiled
#: loop, with the bound of its series and ledger (the scale's fraction)
FOLLOWING = [
    ("beam_impact", None, (), RTOL),        # Gauss-Seidel, C hosted by the beam, beam first
    ("beam_impact", None, ('scheme.name="jacobi"',), RTOL),
    ("beam_impact", None, ('scheme.sequence=["robot", "beam"]',), RTOL),   # robot first: Hermite
    # C left of the beam: its point clipped to the pinned end, where s no longer moves
    ("beam_impact", None, ("subsystems.beam.origin=[0.5, 0.0]",), RTOL),
    # exchanged as forces: side a's map turned to the surface's normal
    ("beam_impact", None, ('contacts.C.placement="coupler"', "scheme.accept_unsafe_step=true"),
     RTOL),
    # Jacobi's quadratic extrapolation amplifies round-off most: the Python loop
    # itself moves by 1.2e-8 of a series under a 1-ulp copy of the scene (the
    # two loops differ by 2.3e-10), so it is held to 1e-7
    ("beam_impact", None, ('scheme.name="jacobi"', "scheme.extrapolation_order=2"), 1e-7),
]

needs_compiled = pytest.mark.skipif(kernel_choice() == "numpy",
                                    reason="COSIM_KERNEL=numpy runs the Python loop only")


def _load(name, variant=None, overrides=()):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return cosim.load_scene(CASES / f"{name}.toml", variant, overrides=tuple(overrides))


def _following_scenes():
    """Every shipped scene and variant with a following contact."""
    out = []
    for path in sorted(CASES.glob("*.toml")):
        spec = tomllib.loads(path.read_text())
        for variant in [None] + list(spec.get("variants", {})):
            text = str(spec.get("contacts", {})) + str(spec.get("variants", {}).get(variant, {}))
            if "follow" not in text:
                continue            # no scene follows without saying `follow`
            system, _ = build_system(_load(path.stem, variant))
            if system.followers:
                out.append((path.stem, variant))
    return out


def _both_ways(name, variant, overrides, monkeypatch):
    out = []
    for loop in ("python", "compiled"):
        monkeypatch.setenv(driver.DRIVER_ENV, loop)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            out.append(cosim.simulate(_load(name, variant, overrides), estimate=False))
    return out


def assert_bounded_equal(ref, got, rtol=RTOL):
    """The compiled run ``got`` against the Python loop's ``ref``: the same
    discrete outcomes, the rest within ``rtol`` of its scale (intervals
    within :data:`DT`)."""
    def _close(a, b, scale):
        return abs(a - b) <= rtol * scale

    assert got.status == ref.status == "finished", (got.message, ref.message)
    for key in ("macro_steps", "rejected_steps"):
        assert got.summary[key] == ref.summary[key], key
    cr, cg = ref.summary["contacts"], got.summary["contacts"]
    assert {k: v["count"] for k, v in cg.items()} == {k: v["count"] for k, v in cr.items()}
    for k, v in cr.items():
        a, b = np.asarray(v["intervals"], float), np.asarray(cg[k]["intervals"], float)
        assert a.shape == b.shape and np.max(np.abs(a - b), initial=0.0) <= DT, k
    assert set(got.series) == set(ref.series)
    for key in ref.series:
        a, b = np.asarray(ref.series[key], float), np.asarray(got.series[key], float)
        assert a.shape == b.shape, key
        scale = float(np.max(np.abs(a), initial=0.0))
        assert np.max(np.abs(a - b), initial=0.0) <= rtol * scale, key
    # the ledger: the energy and each contact's impulse, work and coupling error
    er, eg = ref.summary["energy"], got.summary["energy"]
    scale = abs(er["initial"])
    for key in ("final", "max_abs_drift", "dissipated", "supplied"):
        assert _close(eg[key], er[key], scale), key
    for k, v in cr.items():
        for key in ("work", "coupling_error", "dissipated"):
            assert _close(cg[k][key], v[key], scale), (k, key)
        assert _close(cg[k]["impulse"], v["impulse"], max(abs(v["impulse"]), 1.0)), k
        assert _close(cg[k]["peak_penetration"], v["peak_penetration"],
                      abs(v["peak_penetration"])), k


@needs_compiled
def test_every_shipped_following_scene_takes_the_compiled_loop():
    found = _following_scenes()
    assert found == [("beam_impact", None)]
    for name, variant in found:
        system, sch = build_system(_load(name, variant))
        assert driver.refusal(sch, system) is None


@needs_compiled
@pytest.mark.parametrize("name, variant, overrides, rtol", FOLLOWING)
def test_following_contacts_match_the_python_loop(name, variant, overrides, rtol, monkeypatch):
    system, sch = build_system(_load(name, variant, overrides))
    assert system.followers and driver.refusal(sch, system) is None
    ref, got = _both_ways(name, variant, overrides, monkeypatch)
    assert_bounded_equal(ref, got, rtol)
    assert ref.summary["contacts"]["C"]["count"] >= 1       # C strikes


def test_the_follow_module_is_built():
    """Built wherever the compiled kernels are chosen: a missing module is an
    error here, not a skip (the compiled loop imports it)."""
    if kernel_choice() != "numpy":
        importlib.import_module("cosim.core.schemes._follow")
        importlib.import_module("cosim.sides._multibody_tree")


def _counts(result):
    return {k: v["count"] for k, v in result.summary["contacts"].items()}


@needs_compiled
def test_the_counts_hold_for_copies_moved_by_round_off(monkeypatch):
    """Both loops give the scene and its copies moved by +-1 and +-2 ulps the
    same contact counts."""
    scene = _load("beam_impact")
    seen = []
    for loop in ("python", "compiled"):
        monkeypatch.setenv(driver.DRIVER_ENV, loop)
        seen += outcomes(scene, _counts)
    assert all(s == {"A": 2, "B": 1, "C": 2} for s in seen), seen


def _run(scene, loop, monkeypatch):
    monkeypatch.setenv(driver.DRIVER_ENV, loop)
    system, sch = build_system(scene)
    sch.run(system, scene.t_end, Recorder(system, scene.name, sch.name, scene.t_end))
    return system, sch


@needs_compiled
def test_the_compiled_loop_takes_every_step_and_moves_the_port(monkeypatch):
    """The driver's counters: every macro step in the compiled loop; and the
    beam's struck point ends where the Python loop leaves it, away from
    where it started (the robot drifted while C slid)."""
    scene = _load("beam_impact")
    runs = {loop: _run(scene, loop, monkeypatch) for loop in ("python", "compiled")}
    system, sch = runs["compiled"]
    stats = sch.loop_stats
    assert stats["loop"] == "compiled" and stats["refusal"] is None
    assert stats["macro_steps"] == sch.n_windows == runs["python"][1].n_windows
    assert 0.0 < stats["compiled_cpu_s"] <= stats["run_cpu_s"]
    assert runs["python"][1].loop_stats["loop"] == "python"
    ln = system.links[system.contact_names.index("C")]
    s_got = system.subsystems[ln.sub_b].port_coordinates[ln.port_b]
    ref_system = runs["python"][0]
    s_ref = ref_system.subsystems[ln.sub_b].port_coordinates[ln.port_b]
    assert abs(s_got - 0.45) > 1e-3
    assert abs(s_got - s_ref) <= RTOL * 1.0          # [m], the beam is 1 m long
    # the shape row the compiled face wrote is the Python reference's at that point
    beam = system.subsystems[ln.sub_b]
    row = np.array(beam._R[ln.port_b])
    beam.port_coordinates[ln.port_b] = -1.0          # forces move_port to write the row
    beam.move_port(ln.port_b, s_got)
    assert np.max(np.abs(row - beam._R[ln.port_b])) <= 8 * np.finfo(float).eps * np.max(
        np.abs(beam._R[ln.port_b]))


@needs_compiled
def test_a_side_that_cannot_move_its_ports_in_c_keeps_the_python_loop(monkeypatch):
    """Where side b does not declare ``compiled_follow`` the run takes the
    Python loop, and says why."""
    scene = _load("beam_impact")
    system, sch = build_system(scene)
    beam = system.subsystems[system.names.index("beam")]
    monkeypatch.setattr(type(beam), "capabilities", beam.capabilities - {"compiled_follow"})
    why = driver.refusal(sch, system)
    assert why == ("contact `C` follows a point along side `beam`, which cannot move its "
                   "ports in compiled code")
    sch.run(system, scene.t_end, Recorder(system, scene.name, sch.name, scene.t_end))
    assert sch.loop_stats["loop"] == "python" and sch.loop_stats["refusal"] == why

"""What the choice of ``cosim run --accuracy`` costs before the run, counted
(builds of the scene, never seconds), and that building less chooses what
building every candidate chose."""
import math
import warnings
from pathlib import Path

import pytest

import cosim
import cosim.scene.build as build_module
from cosim.core.preflight import stiffest_normal
from cosim.scene.info import first_touch
from cosim.studies import choose as ch
from cosim.studies.companion import contact_omega
from cosim.studies.reach import check_omega

CASES = Path(__file__).resolve().parents[1] / "cases"

#: impacts whose strike the model covers: exchanged (three_mass, beam_impact) and
#: hosted by a multibody's rk4 (spring_drop)
SCENES = [("three_mass", "f10"), ("three_mass", "f100"), ("three_mass", "f1000"),
          ("beam_impact", None), ("spring_drop", None)]


def _load(name, variant=None, overrides=()):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return cosim.load_scene(CASES / f"{name}.toml", variant, list(overrides))


@pytest.fixture
def builds(monkeypatch):
    """The scene builds made (:func:`cosim.scene.build.build_system` calls)."""
    calls = []
    real = build_module.build_system

    def counted(scene, *args, **kw):
        calls.append(scene.scheme)
        return real(scene, *args, **kw)
    monkeypatch.setattr(build_module, "build_system", counted)
    return calls


@pytest.mark.parametrize("name, variant", SCENES)
def test_the_choice_builds_once_and_once_per_candidate_it_checks(builds, name, variant):
    """One build for the first touch and the frequencies, then one per
    candidate checked, cheapest first, until one passes: every candidate
    refused by its build or pre-flight check, and the chosen one.  Before,
    each candidate was built, and the first touch built its own."""
    choice = ch.choose(_load(name, variant), 0.01)
    checked = [c for c in choice.candidates
               if "pre-flight" in c.get("refused", "") or
               ("refused" not in c and "unchecked" not in c)]
    assert len(builds) == 1 + len(checked)
    assert sum("refused" not in c and "unchecked" not in c for c in choice.candidates) == 1
    assert len(builds) < 2 + len(choice.candidates)


@pytest.mark.parametrize("name, variant", SCENES)
def test_building_the_cheapest_first_chooses_what_building_every_candidate_chose(name, variant):
    """Each candidate the choice left unbuilt, built and checked now: the
    one chosen is still the cheapest that passes (the rule of the choice
    when every candidate was built)."""
    from cosim.errors import UnsafeStepError
    from cosim.scene.checks import SceneError
    scene = _load(name, variant)
    choice = ch.choose(scene, 0.01)
    passing = []
    for c in choice.candidates:
        if "refused" in c:
            continue
        s = ch._load(scene, c["overrides"], c["scheme"])
        try:
            system, sch = s.build()
            sch.preflight(system)
        except (UnsafeStepError, SceneError):
            continue
        passing.append(c)
    best = min(passing, key=lambda c: (c["scheme"] == "monolithic", c["predicted_cpu_s"],
                                       c["scheme"] != scene.scheme))
    assert (best["scheme"], best["step"]) == (choice.scheme, choice.step)
    assert choice.scene is not None and choice.scene.scheme == choice.scheme


@pytest.fixture(scope="module")
def generated(tmp_path_factory):
    """Scenes no one chose (:mod:`cosim.studies.generate`, seed 1): a
    revolute arm strikes, so a contact's mobility moves with the pose."""
    from cosim.studies.generate import write_scenes
    return write_scenes(tmp_path_factory.mktemp("generated"), 6, 1)


def _frequencies_agree(scene):
    k = ch.knob(scene)
    system, _ = scene.build()                     # fresh: at the initial pose
    c = system.contact_names.index(k.contact)
    assert math.isclose(k.check_omega, check_omega(system, c), rel_tol=4e-16)
    touches, _ = first_touch(scene, contacts={k.contact})
    mob = touches[c][1] if c in touches else system.contact_mobility(c)
    omega = math.sqrt(stiffest_normal(system.links[c])[0] * mob)
    assert math.isclose(k.omega, omega, rel_tol=4e-16)
    if c not in touches:        # closed from the start: the initial pose's frequency
        assert math.isclose(k.omega, contact_omega(system, c), rel_tol=4e-16)
    return k, system, c


@pytest.mark.parametrize("name, variant", SCENES)
def test_the_frequencies_read_on_the_one_build_are_those_of_fresh_builds(name, variant):
    """The knob's build is run to the first touch; what it reads at the
    initial pose is read before, and the touch it finds is the touch a
    build of its own finds: the same operations on the same state, so
    within an ulp (no bit identity asserted between two builds)."""
    _frequencies_agree(_load(name, variant))


def test_on_generated_scenes_too_and_the_pose_matters_there(generated):
    """The same on generated scenes, where reading the initial pose's
    frequency after the first-touch run would give another number: the
    arm's mobility at the touch differs from the start's on some scene by
    more than round-off (else the test could not tell the two apart)."""
    moved = 0
    for path in generated:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            scene = cosim.load_scene(path)
        k, system, c = _frequencies_agree(scene)
        moved += abs(k.omega / contact_omega(system, c) - 1) > 1e-6
    assert moved >= 1

"""`cosim info`'s largest stable macro step is a step that runs (issue 36).

A 1 kg pendulum struck a tensioned cable: the step info printed, judged on
the contact's reduced mass alone, was stopped by the guard.  The step is now
judged on the coupled system's port modes (:mod:`cosim.core.stability`) and
confirmed by a run of the scene (:mod:`cosim.scene.stable_step`); where no
run confirms it, the line says "necessary bound only".  These tests run the
scene at 0.9 times the printed step, for the scene and copies moved by
round-off (tests/roundoff.py), and ask that the guard does not stop it.
"""
import math
import warnings

import pytest

from conftest import CASES
import stable_scenes
from cosim import load_scene
from cosim.scene.info import scene_info
from cosim.scene.stable_step import NECESSARY, RUNS
from roundoff import assert_robust

EXPLICIT = ("jacobi", "gauss_seidel")

#: copies (the scene and ulp-moved ones) every 0.9 x run must finish for
COPIES = 3


def _at(path, variant, overrides, scheme, step):
    with warnings.catch_warnings():     # switching scheme drops options: expected here
        warnings.simplefilter("ignore")
        scene = load_scene(path, variant, overrides, scheme=scheme)
        over = [f"scheme.macro_step={step!r}"]
        if "contact_step" in scene.data.get("scheme", {}):
            over.append(f"scheme.contact_step={step!r}")
        return load_scene(path, variant, list(overrides) + over, scheme=scheme)


def _finished(res):
    return res.status


def check_runs_at_090(path, variant=None, overrides=(), budget=None) -> dict:
    """Every explicit scheme's printed step of every contact: `runs` ->
    a run at 0.9 x it finishes (scene and copies); `necessary bound only`
    -> says why; None -> the contact is resolved inside a side against a
    rigid partner.  Returns {(contact, scheme): kind}."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = load_scene(path, variant, list(overrides))
    from cosim.scene.stable_step import CONFIRM_STEPS
    info = scene_info(scene, budget_s=0, confirm_steps=budget or CONFIRM_STEPS)
    system, _ = scene.build()
    kinds, tried = {}, set()
    for name, c in info["contacts"].items():
        if "max_macro_step_s" not in c:
            continue
        ln = system.links[system.contact_names.index(name)]
        for s in EXPLICIT:
            step, kind = c["max_macro_step_s"][s], c["max_macro_step_kind"][s]
            kinds[name, s] = kind
            if step is None:
                rigid = (system.subsystems[ln.sub_a].rigid or system.subsystems[ln.sub_b].rigid)
                assert ln.placement == "embedded" and rigid, (name, s)
                continue
            assert step > 0 and kind in (RUNS, NECESSARY)
            if kind == NECESSARY:
                assert c["max_macro_step_why"][s]
                continue
            if (s, step) in tried:
                continue
            tried.add((s, step))
            assert_robust(_at(path, variant, overrides, s, 0.9 * step), _finished,
                          "finished", copies=COPIES)
    return kinds


@pytest.mark.parametrize("k, c, t_end", [(1e4, 22.0, 0.02), (1e7, 22.0, 0.005),
                                         (1e6, 221.0, 0.02)])
def test_pendulum_on_cable_runs_at_090_of_the_printed_step(tmp_path, k, c, t_end):
    """The finding's scene (Kelvin-Voigt, exchanged), at a stiffness and at
    one a thousand times larger: both explicit schemes' steps are confirmed
    and a run at 0.9 x them is not stopped."""
    path = stable_scenes.write(tmp_path, "pendulum", "cable", "kelvin_voigt", "coupler", k, c,
                               t_end=t_end)
    kinds = check_runs_at_090(path)
    assert kinds == {("hit", "jacobi"): RUNS, ("hit", "gauss_seidel"): RUNS}


def test_the_reduced_mass_step_of_the_finding_is_stopped(tmp_path):
    """What info printed before: the step of the one-mass model (the
    pre-flight check's, `preflight_step_s`) lets Gauss-Seidel, whose sides
    receive different impulses, create a tenth of the energy scale within
    the first contact; the printed step is smaller."""
    path = stable_scenes.write(tmp_path, "pendulum", "cable", "kelvin_voigt", "coupler", 1e6,
                               221.0, t_end=0.02)
    c = scene_info(load_scene(path), budget_s=0)["contacts"]["hit"]
    old = c["preflight_step_s"]["gauss_seidel"]
    assert c["max_macro_step_s"]["gauss_seidel"] < 0.5 * old
    assert_robust(_at(path, None, (), "gauss_seidel", 0.9 * old),
                  lambda r: (r.status, r.summary["contacts"]["hit"]["count"]), ("failed", 1),
                  copies=COPIES)


def test_a_hosted_contact_is_never_not_limited_under_an_explicit_scheme(tmp_path):
    """Hosted by the pendulum, the contact still hands its force to the
    cable a step late: the explicit schemes get a step, and it runs."""
    path = stable_scenes.write(tmp_path, "pendulum", "cable", "kelvin_voigt", "host_arm", 1e6,
                               221.0, t_end=0.02)
    kinds = check_runs_at_090(path)
    assert set(kinds.values()) == {RUNS}


def test_an_unconfirmed_step_says_necessary_bound_only(tmp_path, capsys):
    """No run to confirm it (a zero budget): the model's bound, marked, in
    the JSON and on the line."""
    from cosim import cli
    path = stable_scenes.write(tmp_path, "pendulum", "cable", "kelvin_voigt", "coupler", 1e6,
                               221.0, t_end=0.02)
    c = scene_info(load_scene(path), budget_s=0, confirm_steps=0)["contacts"]["hit"]
    assert c["max_macro_step_kind"] == {"monolithic": None, "jacobi": NECESSARY,
                                        "gauss_seidel": NECESSARY, "implicit": None}
    assert c["max_macro_step_why"]["jacobi"] == "no run was made to confirm it"
    assert cli.main(["info", str(path)]) == 0
    out = capsys.readouterr().out
    line = next(ln for ln in out.splitlines() if "largest stable macro step" in ln)
    assert "jacobi" in line and ("(runs)" in line or "(necessary bound only)" in line)


#: the varied scenes the fast sweep runs (indices into stable_scenes.VARIED):
#: every structure, law and placement at least once
FAST_VARIED = (2, 5, 7, 10)


@pytest.mark.parametrize("i", FAST_VARIED)
def test_varied_scenes_run_at_090_of_the_printed_step(tmp_path, i):
    path = stable_scenes.write(tmp_path, *stable_scenes.VARIED[i])
    kinds = check_runs_at_090(path)
    assert set(kinds.values()) == {RUNS}


@pytest.mark.parametrize("scene, variant, overrides", [
    ("three_mass", None, ()),
    ("three_mass", None, ['contacts.C.placement="coupler"']),
    ("spring_drop", None, ['contacts.wall.placement="coupler"']),
    ("manipulator_wall", "penalty", ()),
])
def test_shipped_scenes_run_at_090_of_the_printed_step(scene, variant, overrides):
    kinds = check_runs_at_090(CASES / f"{scene}.toml", variant, overrides)
    assert NECESSARY not in kinds.values()


@pytest.mark.slow
@pytest.mark.parametrize("i", [i for i in range(len(stable_scenes.VARIED))
                               if i not in FAST_VARIED])
def test_every_varied_scene_runs_at_090_of_the_printed_step(tmp_path, i):
    path = stable_scenes.write(tmp_path, *stable_scenes.VARIED[i])
    check_runs_at_090(path, budget=4e5)


@pytest.mark.slow
def test_every_shipped_scene_runs_at_090_of_the_printed_step():
    from cosim.scene.shipped import scene_variants
    for f in sorted(CASES.glob("*.toml")):
        variants, default = scene_variants(f)
        for v in [None] + [x for x in variants if x != default]:
            check_runs_at_090(f, v)


def test_the_coupled_map_of_one_free_mode_is_the_preflight_model():
    """One free mode of mass m against the spring: the coupled step map
    reduces to the pre-flight check's one-mass map (same energy gain over a
    contact), so a rigid partner's bound is unchanged."""
    import numpy as np
    from cosim.core import preflight, stability
    m, k = 1.3, 1e6
    p = np.array([1.0 / math.sqrt(m)])
    for H in (1e-6, 1e-5, 4e-5):
        gain = preflight.contact_energy_gain(m, k, 0.0, H, 0)
        created = stability.energy_created(np.zeros(1), np.zeros(1), p, k, 0.0, H, 0)
        assert created == pytest.approx(gain - 1.0, rel=1e-9, abs=1e-12)


# ------------------------------------------------ the numbers the pages print
from documented import Claim, assert_printed, assert_reproduced  # noqa: E402

SC, CM = "docs/schemes.md", "docs/commands.md"


def test_the_pages_numbers_of_the_stable_step(tmp_path):
    from cosim.scene import stable_step
    halvings = Claim(SC, "halved while the guard stops it (at most 8 times)",
                     "cosim.scene.stable_step.HALVINGS", 8.0)
    budget = Claim(CM, "at most `cosim.scene.stable_step.CONFIRM_STEPS`, 5e4, integrator steps "
                       "per scheme", "cosim.scene.stable_step.CONFIRM_STEPS", 5e4)
    zeta = Claim(SC, "damping ratio 0.5 against the cable's local mass",
                 "cosim info (the pendulum-on-cable scene of tests/stable_scenes.py)", 0.5,
                 abs=0.05)
    factor = Claim(SC, "Gauss-Seidel at 0.9 times the one-mass model's step",
                   "tests/test_stable_step.py", 0.9)
    for c in (halvings, budget, zeta, factor):
        assert_printed(c)
    assert_reproduced(halvings, stable_step.HALVINGS)
    assert_reproduced(budget, stable_step.CONFIRM_STEPS)
    path = stable_scenes.write(tmp_path, "pendulum", "cable", "kelvin_voigt", "coupler", 1e6,
                               221.0, t_end=0.02)
    c = scene_info(load_scene(path), budget_s=0, confirm_steps=0)["contacts"]["hit"]
    assert_reproduced(zeta, c["damping"] / (2 * math.sqrt(c["stiffness"] * c["reduced_mass"])))
    assert_reproduced(factor, 0.9)       # the factor test_the_reduced_mass_step... runs at


@pytest.mark.parametrize("scheme", EXPLICIT)
def test_not_limited_means_the_macro_step_does_not_limit_it(scheme):
    """spring_drop's wall is resolved inside the body's integrator: info says
    "not limited", and runs at 10 and 100 times the scene's macro step (the
    longest: half the run) finish with the one contact."""
    c = scene_info(load_scene(CASES / "spring_drop.toml"), budget_s=0)["contacts"]["wall"]
    assert c["max_macro_step_s"][scheme] is None
    for step in (1e-3, 1e-2):
        assert_robust(_at(CASES / "spring_drop.toml", None, (), scheme, step),
                      lambda r: (r.status, r.summary["contacts"]["wall"]["count"]),
                      ("finished", 1), copies=COPIES)

"""`cosim info`: what a run will meet, as numbers a script can read."""
import json
import math
import warnings

import pytest

from conftest import CASES
import cosim
from cosim import cli, load_scene
from cosim.scene.info import scene_info


def test_spring_drop_contact_frequency_and_limits():
    info = scene_info(load_scene(CASES / "spring_drop.toml"))
    assert info["subsystems"]["body"]["dofs"] == 1
    assert info["subsystems"]["body"]["coordinates"] == ["x"]
    c = info["contacts"]["wall"]
    assert c["reduced_mass"] == pytest.approx(1.0)
    assert c["frequency_hz"] == pytest.approx(1000 / (2 * math.pi))
    assert c["contact_time_s"] == pytest.approx(math.pi / 1000)
    # embedded: no macro-step limit, the integrator's own limit instead
    assert set(c["max_macro_step_s"].values()) == {None}
    # the step the build accepts, half RK4's stability limit (omega dt = sqrt 2)
    assert c["max_integrator_step_s"]["rk4"] == pytest.approx(math.sqrt(2) / 1000)


def test_the_printed_integrator_step_builds_and_runs():
    """cosim info's largest stable integrator step is one the build accepts
    and that runs: 0.9 times it builds and finishes, 1.01 times it is refused
    (it printed RK4's stability limit, twice what the build accepts): both
    read :func:`cosim.scene.build.embedded_step_limit`."""
    from cosim import SceneError
    from cosim.scene.run import simulate
    for scene_name, contact, k in [
            ("spring_drop", "wall", "subsystems.body.integrator.max_step"),
            ("beam_impact", "A", "subsystems.robot.integrator.max_step")]:
        c = scene_info(load_scene(scene_name), confirm_steps=0)["contacts"][contact]
        h = c["max_integrator_step_s"]["rk4"]
        res = simulate(load_scene(scene_name, None, [f"{k}={0.9 * h!r}"]))
        assert res.status == "finished"
        with pytest.raises(SceneError, match="too large for contact"):
            load_scene(scene_name, None, [f"{k}={1.01 * h!r}"]).build()


def test_coupler_contact_reports_the_preflight_limit():
    info = scene_info(load_scene(CASES / "spring_drop.toml",
                                 overrides=['contacts.wall.placement="coupler"']))
    steps = info["contacts"]["wall"]["max_macro_step_s"]
    # 1 % energy per contact with the force held: 2 ln(1.01) / (pi omega)
    assert steps["jacobi"] == pytest.approx(2 * math.log(1.01) / (math.pi * 1000), rel=0.01)
    assert steps["implicit"] is None and steps["monolithic"] is None


def test_rigid_contact_reports_its_law():
    info = scene_info(load_scene(CASES / "manipulator_wall.toml", "mu0.03"))
    assert info["contacts"]["tip"] == {"law": "rigid", "placement": "embedded",
                                       "between": ["robot", "wall"], "restitution": 0.5,
                                       "friction": 0.03}
    assert info["subsystems"]["robot"]["dofs"] == 10


def test_cli_info_json_and_text(capsys):
    assert cli.main(["info", str(CASES / "spring_drop.toml"), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["scene"] == "spring_drop"
    assert cli.main(["info", str(CASES / "spring_drop.toml")]) == 0
    out = capsys.readouterr().out
    assert "contact wall: linear (embedded)" in out and "frequency 159.2 Hz" in out


def test_info_and_the_preflight_check_give_the_same_limit_between_moving_sides():
    """Issue 18: `cosim info` gave 1.0e-5 s for Gauss-Seidel on three_mass f1000
    with C exchanged (the formula for a rigid partner), the scheme refused above
    2.9e-6 s.  Both now ask `preflight.partner_first`: the step info gives runs,
    1 % more is refused."""
    from cosim.errors import UnsafeStepError
    over = ['contacts.C.placement="coupler"']
    info = scene_info(load_scene(CASES / "three_mass.toml", "f1000", overrides=over),
                      confirm_steps=0)
    limits = info["contacts"]["C"]["preflight_step_s"]
    # the step info prints (judged on the coupled modes, issue 36) is no larger
    for scheme in ("gauss_seidel", "jacobi"):
        assert info["contacts"]["C"]["max_macro_step_s"][scheme] <= limits[scheme]
    assert limits["gauss_seidel"] == pytest.approx(2.87e-6, rel=1e-2)
    for scheme in ("gauss_seidel", "jacobi"):
        for factor, refused in ((0.999, False), (1.01, True)):
            scene = load_scene(CASES / "three_mass.toml", "f1000", scheme=scheme, overrides=over + [
                f"scheme.contact_step={limits[scheme] * factor!r}"])
            system, sch = scene.build()
            if refused:
                with pytest.raises(UnsafeStepError, match=r"contact `C`: macro step .* The "
                                                          r"largest safe macro step is "):
                    sch.preflight(system)
            else:
                sch.preflight(system)


def test_info_says_when_sampling_is_too_coarse_to_draw_a_contact():
    """spring_drop's contact lasts pi sqrt(m/k) = 3.14 ms: sampled every
    0.1 ms (the default) it is drawn by 31 samples; every 5 ms, by none."""
    c = scene_info(load_scene(CASES / "spring_drop.toml"))["contacts"]["wall"]
    assert c["sampling_interval_s"] == pytest.approx(1e-4)
    assert c["samples_per_contact"] == pytest.approx(math.pi / 1000 / 1e-4)
    assert "sampling_note" not in c
    coarse = scene_info(load_scene(CASES / "spring_drop.toml",
                                   overrides=["scheme.macro_step=5e-3"]))["contacts"]["wall"]
    assert coarse["samples_per_contact"] == pytest.approx(math.pi / 1000 / 5e-3)
    assert coarse["sampling_note"].startswith(
        "the series sample contact `wall` every 0.005 s, 0.628 times in its contact time of "
        "0.00314 s: too coarse to draw it.")
    assert "at most every 0.000785 s (`scheme.macro_step`)" in coarse["sampling_note"]


def test_info_sampling_follows_contact_step_every_and_the_monolithic_interval():
    # three_mass: C is hosted, so step control samples it every contact_step
    c = scene_info(load_scene(CASES / "three_mass.toml"), confirm_steps=0)["contacts"]["C"]
    assert c["sampling_interval_s"] == pytest.approx(3e-5)
    # keeping one sample in 50 makes it too coarse, and the note names both keys
    c = scene_info(load_scene(CASES / "three_mass.toml",
                              overrides=["output.every=50"]),
                   confirm_steps=0)["contacts"]["C"]
    assert c["sampling_interval_s"] == pytest.approx(1.5e-3)
    assert "(`scheme.contact_step` or `output.every`)" in c["sampling_note"]
    # the monolithic scheme samples every output_interval (t_end / 1000 by default)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")     # monolithic ignores macro_step
        scene = load_scene(CASES / "spring_drop.toml", scheme="monolithic",
                           overrides=["t_end=10"])
    c = scene_info(scene)["contacts"]["wall"]
    assert c["sampling_interval_s"] == pytest.approx(0.01)
    assert "(its switch and peak events are sampled too)" in c["sampling_note"]
    assert "`scheme.monolithic.output_interval`" in c["sampling_note"]


def test_cli_info_prints_the_sampling_note(tmp_path):
    import subprocess
    import sys

    from conftest import ROOT
    proc = subprocess.run([sys.executable, "-m", "cosim.cli", "info",
                           str(CASES / "spring_drop.toml"), "--set", "scheme.macro_step=5e-3"],
                          capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert "output sampling every 0.005 s: 0.628 samples per contact" in proc.stdout
    assert "note: the series sample contact `wall` every 0.005 s" in proc.stdout


# ------------------------------------------------- the pose of the first touch
@pytest.mark.parametrize("path,variant,contact,t_touch", [
    ("manipulator_wall.toml", "penalty", "tip", 0.390),
    ("three_mass.toml", "f100", "C", 0.1027),
])
def test_info_gives_the_contact_time_a_run_measures(path, variant, contact, t_touch):
    """The reduced mass depends on the pose: manipulator_wall's tip has 0.303 kg
    at the start and 1.363 kg where it strikes (0.39 s), so the contact time
    info gave at the start (1.73 ms) was half the measured one (3.17 ms).
    Evaluated at the first touch, info's contact time of the linearised
    spring and dashpot matches the run's first contact interval within 1 %:
    the one-DOF model leaves out the other DOFs' motion during the contact
    (observed: 0.1 % for the tip, 0.5 % for C against the chain)."""
    scene = load_scene(CASES / path, variant)
    c = scene_info(scene, confirm_steps=0)["contacts"][contact]
    assert c["pose"]["at"] == "first touch"
    assert c["pose"]["t"] == pytest.approx(t_touch, abs=1e-3)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = cosim.simulate(scene)
    t_on, t_off = res.summary["contacts"][contact]["intervals"][0]
    assert t_on == pytest.approx(c["pose"]["t"], abs=1e-3)
    assert c["contact_time_s"] == pytest.approx(t_off - t_on, rel=0.01)
    assert c["initial_pose"]["reduced_mass"] != c["reduced_mass"]


def test_manipulator_wall_penalty_strikes_with_the_reduced_mass_its_damping_was_tuned_for():
    """The scene's dashpot (596 N s/m) gives restitution 0.5 for the tip's
    reduced mass at the impact, 1.3628 kg (manipulator_wall.toml): info finds
    that mass, where the initial pose gave 0.303 kg."""
    c = scene_info(load_scene(CASES / "manipulator_wall.toml", "penalty"))["contacts"]["tip"]
    assert c["reduced_mass"] == pytest.approx(1.3628, rel=2e-3)
    assert c["initial_pose"]["reduced_mass"] == pytest.approx(0.3028, rel=1e-3)
    # the robot's DOP853 sets its own step by its error control: no fixed-step limit
    assert c["max_integrator_step_s"] == {"dop853": None}


def test_info_says_which_pose_it_used(capsys):
    assert cli.main(["info", str(CASES / "manipulator_wall.toml"), "--variant", "penalty"]) == 0
    out = capsys.readouterr().out
    assert ("reduced mass 1.364 kg, frequency 136.3 Hz, contact time 0.003171 s, at its first "
            "touch, t = 0.39 s") in out
    assert "at the initial pose: reduced mass 0.3028 kg" in out
    # contacts closed at the start: their first touch is the initial pose
    assert cli.main(["info", str(CASES / "three_mass.toml"), "--variant", "f100"]) == 0
    out = capsys.readouterr().out
    assert "contact time 0.004769 s, at its first touch, t = 0 s" in out
    assert "at its first touch, t = 0.102739 s" in out
    # a run that ends before the contact closes: the initial pose, and why
    assert cli.main(["info", str(CASES / "spring_drop.toml"), "--set", "t_end=0.005"]) == 0
    out = capsys.readouterr().out
    assert ("contact time 0.003142 s, at the initial pose (the run to t_end = 0.005 s did not "
            "close it)") in out


def test_info_without_the_run_uses_the_initial_pose():
    c = scene_info(load_scene(CASES / "manipulator_wall.toml", "penalty"),
                   budget_s=0)["contacts"]["tip"]
    assert c["pose"] == {"at": "initial", "t": 0.0,
                         "why": "no run was made to find where it closes"}
    assert c["reduced_mass"] == pytest.approx(0.3028, rel=1e-3)
    assert "initial_pose" not in c


def test_the_contact_time_of_a_spring_and_dashpot():
    """Undamped: pi / omega; damped: the clipped Kelvin-Voigt closed form."""
    from cosim.scene.info import contact_time
    from cosim.studies.analytic import kelvin_voigt_clipped, linear_contact
    assert contact_time(1.0, 1e6, 0.0) == linear_contact(1.0, 1e6)
    assert contact_time(1.3628, 1e6, 596.0) == pytest.approx(
        kelvin_voigt_clipped(1.3628, 1e6, 596.0)[0], rel=1e-14)


def test_info_where_the_scheme_refuses_to_run_uses_the_initial_pose():
    """C exchanged by Jacobi at a step the pre-flight check refuses: no run,
    the initial pose, and the reason."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")     # jacobi ignores `sequence`
        scene = load_scene(CASES / "three_mass.toml", "f1000", scheme="jacobi",
                           overrides=['contacts.C.placement="coupler"'])
    c = scene_info(scene, confirm_steps=0)["contacts"]["C"]
    assert c["pose"]["at"] == "initial"
    assert c["pose"]["why"].startswith("the pre-flight check refuses the scheme's step")
    assert c["preflight_step_s"]["jacobi"] == pytest.approx(2.873e-6, rel=2e-3)

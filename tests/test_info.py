"""`cosim info`: what a run will meet, as numbers a script can read."""
import json
import math
import warnings

import pytest

from conftest import CASES
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
    assert c["max_integrator_step_s"]["rk4"] == pytest.approx(2 * math.sqrt(2) / 1000)


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
    info = scene_info(load_scene(CASES / "three_mass.toml", "f1000", overrides=over))
    limits = info["contacts"]["C"]["max_macro_step_s"]
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
    c = scene_info(load_scene(CASES / "three_mass.toml"))["contacts"]["C"]
    assert c["sampling_interval_s"] == pytest.approx(3e-5)
    # keeping one sample in 50 makes it too coarse, and the note names both keys
    c = scene_info(load_scene(CASES / "three_mass.toml",
                              overrides=["output.every=50"]))["contacts"]["C"]
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

"""`cosim info`: what a run will meet, as numbers a script can read."""
import json
import math

import pytest

from conftest import CASES
from cosim import cli, load_scene
from cosim.info import scene_info


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

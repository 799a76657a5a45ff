"""A following contact (``follow = true``) and the side that hosts it.

A following contact moves side b's surface point along its line structure
under side a's point; only the structure's integrator applies the force
along the surface's slope that this brings, so an embedded following contact
between two moving sides is hosted by b's structure.  Left to itself, the
builder chose the side with the larger port mobility ("the lighter side"),
and a structure heavier at the port than the robot (a longer, or a thicker,
beam) ended in a ValueError traceback.  Now the structure hosts it when the
scene names no host, and a ``host`` naming point a's side is refused at load.
"""
import json

import pytest

import cosim
from conftest import CASES
from cosim import cli
from cosim.scene.load import SceneError, load_scene
from roundoff import assert_robust, cli_copies

BEAM_IMPACT = CASES / "beam_impact.toml"
#: the beam of the reported run: 25 m, 8 elements; its port is heavier than
#: the arm's point (mobility 0.178 against 0.194 1/kg)
LONG = ["subsystems.beam.elements=8", "subsystems.beam.length=25"]
#: a beam 0.4 m x 50 mm: at 0.45 m it is heavier still (0.084 1/kg), stiff
#: enough that C strikes it as in the case
THICK = ["subsystems.beam.section={width=0.4, height=0.05}"]


def _sets(overrides):
    return [a for o in overrides for a in ("--set", o)]


def _host_of_c(scene):
    system, _ = scene.build()
    c = system.contact_names.index("C")
    return system.names[system.embedded[c][0]]


@pytest.mark.parametrize("overrides", [LONG, THICK])
def test_the_robot_is_the_lighter_side_yet_the_beam_hosts(overrides):
    scene = load_scene(BEAM_IMPACT, overrides=overrides)
    system, _ = scene.build()
    ln = system.links[system.contact_names.index("C")]
    robot, beam = system.subsystems[ln.sub_a], system.subsystems[ln.sub_b]
    # the rule for a contact that does not follow would pick the robot
    assert (robot.port_mobility(ln.port_a, ln.contact.normal)
            > beam.port_mobility(ln.port_b, ln.contact.normal))
    assert _host_of_c(scene) == "beam"


def test_the_reported_run_finishes_and_its_ledger_closes(tmp_path, capsys):
    """The 25 m beam sags 0.2 km under its weight in the linear model, so C
    never touches; A and B carry the robot.  The run ends at t_end and the
    contacts' coupling errors add up to the energy drift (RK4 at 0.1 ms
    in A and B: observed 4.6e-8 J of the 55 kJ the sag stores).  Finished,
    and C's count, hold for the round-off copies."""
    scene = load_scene(BEAM_IMPACT, overrides=LONG)
    for i, extra in enumerate(cli_copies(scene)):
        out = tmp_path / f"run{i}"
        code = cli.main(["run", str(BEAM_IMPACT), *_sets(LONG), *extra, "--out", str(out)])
        err = capsys.readouterr().err
        assert code == 0 and "Traceback" not in err, err
        s = json.loads((out / "summary.json").read_text())
        assert s["status"] == "finished"
        assert s["t_end"] == pytest.approx(0.13, rel=1e-12)
        assert s["contacts"]["C"]["count"] == 0
        e = s["energy"]
        total = sum(c["coupling_error"] for c in s["contacts"].values())
        assert total == pytest.approx(e["final"] - e["initial"], abs=1e-6)
        assert abs(e["final"] - e["initial"]) < 1e-6


def test_info_of_the_reported_scene_names_the_beam_as_host(capsys):
    assert cli.main(["info", str(BEAM_IMPACT), *_sets(LONG), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["contacts"]["C"]["host"] == "beam"


#: the monolithic reference of the THICK beam (placement `coupler`, DOP853 at
#: the case's rtol 1e-9, atol 1e-12; 33 s of CPU, so stored): C's one contact
#: [0.1027429076, 0.1058627419] s, peak penetration, impulse, and the arm's
#: rate at the end; computed at commit 461f1dd
MONOLITHIC_THICK = {"peak": 0.005870134301, "impulse": 18.66971763, "arm_dq": 18.70374}


def test_the_beam_hosted_following_strike_agrees_with_the_monolithic_reference():
    """The automatic host on the thick beam, against the monolithic reference:
    the case's own agreement is 2e-5 on the peak and the arm's exit rate;
    observed here 1.1e-5 (peak, impulse) and 3.2e-5 (arm).  The band, 1e-4,
    is well below what a wrong host or a lost slope force would change."""
    res = cosim.simulate(load_scene(BEAM_IMPACT, overrides=THICK), estimate=False)
    assert res.success, res.message
    s = res.summary
    c = s["contacts"]["C"]
    assert c["placement"] == "embedded"
    assert c["peak_penetration"] == pytest.approx(MONOLITHIC_THICK["peak"], rel=1e-4)
    assert c["impulse"] == pytest.approx(MONOLITHIC_THICK["impulse"], rel=1e-4)
    assert s["final_state"]["robot"]["arm"]["dq"] == pytest.approx(MONOLITHIC_THICK["arm_dq"],
                                                                   rel=1e-4)
    # the ledger closes: C's coupling error is the run's drift (A and B carry
    # the RK4 error, 2e-8 J), and the drift is small against the 45 J
    e = s["energy"]
    total = sum(v["coupling_error"] for v in s["contacts"].values())
    assert total == pytest.approx(e["final"] - e["initial"], abs=1e-6)
    assert abs(e["final"] - e["initial"]) < 1e-4 * e["initial"]


def test_the_thick_beam_is_struck_once_under_round_off():
    scene = load_scene(BEAM_IMPACT, overrides=THICK)
    assert_robust(scene, lambda r: (r.status, r.summary["contacts"]["C"]["count"]),
                  ("finished", 1))


def test_naming_the_beam_as_host_is_the_automatic_choice():
    """The same computation twice (host named, host chosen): bit identical."""
    auto = cosim.simulate(load_scene(BEAM_IMPACT, overrides=THICK), estimate=False).summary
    named = cosim.simulate(load_scene(BEAM_IMPACT, overrides=THICK + [
        'contacts.C.host="beam"']), estimate=False).summary
    assert named["contacts"] == auto["contacts"]
    assert named["final_state"] == auto["final_state"]


@pytest.mark.parametrize("command", ["run", "info"])
@pytest.mark.parametrize("overrides", [[], LONG])
def test_a_host_that_contradicts_follow_is_refused_at_load(command, overrides, tmp_path,
                                                            capsys):
    args = [command, str(BEAM_IMPACT), *_sets(overrides + ['contacts.C.host="robot"'])]
    if command == "run":
        args += ["--out", str(tmp_path / "x")]
    assert cli.main(args) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err
    assert err.startswith(f"error: {BEAM_IMPACT}: `contacts.C.host` must be 'beam'"), err
    assert "got 'robot'" in err and "follow = true" in err
    assert not (tmp_path / "x").exists()


def test_the_refusal_comes_from_the_loader():
    with pytest.raises(SceneError, match=r"`contacts\.C\.host` must be 'beam', the structure "
                                         r"whose surface a following contact"):
        load_scene(BEAM_IMPACT, overrides=['contacts.C.host="robot"'])

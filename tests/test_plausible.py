"""Plausibility warnings (cosim.scene.plausible): a unit slip that passes the
loader's checks is said in the summary's ``warnings`` and on the terminal,
naming the key and the likely slip; no shipped scene or variant warns.

Each verdict (warn or not) is checked for the scene and for copies moved by
a few ulps: the numbers a warning judges (the slipped value itself, and the
run's initial state, ``tests/roundoff.py``) are nudged and the verdict must
not move.
"""
import json
import re
import subprocess
import sys
import tomllib
import warnings

import pytest

import cosim
from conftest import CASES
from documented import ROOT, flat
from roundoff import COPIES, outcomes
from cosim.scene import plausible
from cosim.scene.load import SceneError
from cosim.studies.roundoff import OFFSETS, nudge, spread

KINDS = {"static_deflection", "frequency", "section", "contact_gap"}
SCENES = sorted(CASES.glob("*.toml"))


def _variants(path):
    return [None] + sorted(tomllib.loads(path.read_text()).get("variants", {}))


def _quiet_load(*args, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return cosim.load_scene(*args, **kw)


def _before(scene):
    """The warnings judged on the built system, before a run."""
    system, _ = scene.build()
    return plausible.structure_warnings(scene, system)


def _nudged(key: str, value: float) -> list[list[str]]:
    """``--set`` overrides of ``key`` at ``value`` and at a few ulps from it."""
    return [[f"{key}={nudge(value, k)!r}"] for k in (0,) + OFFSETS[:COPIES - 1]]


def _kinds(res) -> list:
    return sorted((w["kind"], w["key"]) for w in res.summary["warnings"] if w["kind"] in KINDS)


# ------------------------------------------------------------ shipped scenes
@pytest.mark.parametrize("path,variant", [(p, v) for p in SCENES for v in _variants(p)],
                         ids=lambda x: getattr(x, "stem", x))
def test_no_shipped_scene_or_variant_warns(path, variant):
    """Neither before the run (built system) nor after it (the contacts'
    gaps), for the scene and its copies moved by a few ulps."""
    scene = _quiet_load(path, variant)
    for copy in spread(scene, COPIES):
        assert _before(copy) == []
    assert outcomes(scene, _kinds) == [[]] * COPIES


# ------------------------------------------------------------ the unit slips
def test_youngs_modulus_in_gpa_written_as_pa_warns_with_the_key_and_the_slip():
    """beam_impact with `youngs_modulus = 210`: the beam sags 573 km under its
    weight (static state), so contact C never closes; both say so."""
    for ov in _nudged("subsystems.beam.youngs_modulus", 210.0):
        scene = _quiet_load(CASES / "beam_impact.toml", overrides=ov)
        (w,) = _before(scene)
        assert w["kind"] == "static_deflection"
        assert w["key"] == "subsystems.beam.youngs_modulus"
        assert re.search(r"`subsystems\.beam\.youngs_modulus` = 210 Pa: a static deflection "
                         r"of 573 km under gravity on a 1 m beam", w["message"]), w["message"]
        assert "was it 210e9 (GPa written as Pa)?" in w["message"]
    scene = _quiet_load(CASES / "beam_impact.toml",
                        overrides=["subsystems.beam.youngs_modulus=210"])
    seen = outcomes(scene, _kinds)
    assert seen == [[("contact_gap", "contacts.C"),
                     ("static_deflection", "subsystems.beam.youngs_modulus")]] * COPIES


def test_the_sag_is_the_static_solution():
    """The quoted deflection is K u = f under gravity: a pinned-pinned beam's
    midspan sag 5 q L^4 / (384 E I) (q = rho A g), read back from the text."""
    E, L, w, h, rho, g = 210.0, 1.0, 0.04, 0.01, 7850.0, 9.81
    scene = _quiet_load(CASES / "beam_impact.toml",
                        overrides=[f"subsystems.beam.youngs_modulus={E}"])
    (warn,) = _before(scene)
    sag_km = float(re.search(r"deflection of ([0-9.]+) km", warn["message"])[1])
    exact = 5 * rho * w * h * g * L ** 4 / (384 * E * w * h ** 3 / 12)
    assert sag_km == pytest.approx(exact / 1e3, rel=5e-3)     # 3 digits printed


def test_mpa_written_as_pa_is_told_apart():
    scene = _quiet_load(CASES / "beam_impact.toml",
                        overrides=["subsystems.beam.youngs_modulus=210000"])
    (w,) = _before(scene)
    assert "was it 210000e6 (MPa written as Pa)?" in w["message"], w["message"]


def test_a_plausible_soft_beam_does_not_warn():
    """A tenth of the steel's modulus (a polymer's 21 GPa) sags 5.7 mm: no warning."""
    for ov in _nudged("subsystems.beam.youngs_modulus", 21e9):
        assert _before(_quiet_load(CASES / "beam_impact.toml", overrides=ov)) == []


def test_a_cable_with_no_static_state_is_judged_too():
    """The deflection is judged whether or not the scene starts from it."""
    scene = _quiet_load(CASES / "beam_impact.toml",
                        overrides=["subsystems.beam.youngs_modulus=210",
                                   "subsystems.beam.static_equilibrium=false"])
    assert [w["kind"] for w in _before(scene)] == ["static_deflection"]


@pytest.mark.parametrize("value,side,found", [
    (210.0, "below 0.1 Hz", "was it 210e9 (GPa written as Pa)?"),
    (2.1e20, "above 1e+06 Hz", "check its unit (Pa)")])
def test_a_rod_whose_lowest_frequency_is_implausible_warns(value, side, found):
    """rod_impact (no gravity, so no deflection to judge): the rod's lowest
    frequency, 2.59 kHz at 210 GPa, goes as the square root of the modulus."""
    for ov in _nudged("subsystems.rod.youngs_modulus", value):
        # the scheme, not the rod's RK4, evaluates the wall: a rod that stiff is
        # built then (the RK4 would refuse its contact step first)
        ov += ['contacts.wall.placement="coupler"']
        (w,) = _before(_quiet_load(CASES / "rod_impact.toml", overrides=ov))
        assert w["kind"] == "frequency" and w["key"] == "subsystems.rod.youngs_modulus"
        assert side in w["message"] and found in w["message"], w["message"]


def test_a_section_in_millimetres_warns():
    """beam_impact's 40 x 10 mm section written as 40 x 10 (metres), its
    cutoff raised so that it builds: a section 40 m wide on a 1 m beam."""
    for ov in _nudged("subsystems.beam.section.width", 40.0):
        scene = _quiet_load(CASES / "beam_impact.toml", overrides=ov + [
            "subsystems.beam.section.height=10", "subsystems.beam.modes.cutoff_hz=1e5"])
        (w,) = _before(scene)
        assert w["kind"] == "section" and w["key"] == "subsystems.beam.section.width"
        assert "was it 0.04 (millimetres written as metres)?" in w["message"], w["message"]


def test_a_rod_area_in_square_millimetres_warns():
    (w,) = _before(_quiet_load(CASES / "rod_impact.toml", overrides=[
        "subsystems.rod.area=400", "subsystems.rod.modes.count=8"]))
    assert w["kind"] == "section" and w["key"] == "subsystems.rod.area"
    assert "(mm^2 written as m^2)" in w["message"]


def test_the_cutoff_advice_names_the_millimetre_section_first():
    """A section in millimetres puts every mode above the scene's 20 kHz
    cutoff; the refusal names the section (and the slip) before it advises a
    higher cutoff, which would run a beam 1e6 times too stiff."""
    with pytest.raises(SceneError) as info:
        _quiet_load(CASES / "beam_impact.toml",
                    overrides=["subsystems.beam.section={width = 40, height = 10}"]).build()
    msg = str(info.value)
    assert "`subsystems.beam.modes.cutoff_hz` keeps no mode" in msg
    assert "Check the units first: `subsystems.beam.section.width` = 40 m" in msg
    assert msg.index("millimetres") < msg.index("give a cutoff above it")


def test_a_cutoff_below_a_plausible_beam_keeps_its_plain_advice():
    with pytest.raises(SceneError) as info:
        _quiet_load(CASES / "beam_impact.toml",
                    overrides=["subsystems.beam.modes.cutoff_hz=10"]).build()
    msg = str(info.value)
    assert msg.endswith("give a cutoff above it") and "units" not in msg, msg


def test_the_terminal_and_the_summary_show_the_warnings(tmp_path):
    out = tmp_path / "run"
    proc = subprocess.run([sys.executable, "-m", "cosim.cli", "run", "beam_impact", "--set",
                           "subsystems.beam.youngs_modulus=210", "--out", str(out),
                           "--no-estimate"], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert ("warning: `subsystems.beam.youngs_modulus` = 210 Pa: a static deflection of 573 km "
            "under gravity on a 1 m beam") in proc.stdout
    assert "warning: contact `C` never closed" in proc.stdout
    # the line docs/scenes.md quotes, and the troubleshooting page's row, are the run's
    page = (ROOT / "docs" / "scenes.md").read_text(encoding="utf-8")
    quoted = re.search(r"```text\n(warning: .*?)\n```", page)[1]
    assert quoted in [line.strip() for line in proc.stdout.splitlines()]
    assert quoted[len("warning: "):] in flat(
        (ROOT / "docs" / "troubleshooting.md").read_text(encoding="utf-8"))
    summary = json.loads((out / "summary.json").read_text())
    assert {w["kind"] for w in summary["warnings"]} == {"static_deflection", "contact_gap"}
    assert all(set(w) >= {"kind", "contact", "key", "message"} for w in summary["warnings"])


def test_cosim_info_warns_before_a_run(capsys):
    """`cosim info` shows the structures' warnings (the same as the run's,
    before anything runs), on its terminal; --json holds them under
    `warnings`, empty for the scene as shipped (both over 10 ms: info runs
    the scene).  The slip keeps the soft beam's three lowest modes: the
    warning is one static solve with the beam's whole stiffness, whichever
    modes are kept (the same line), while info's stable-step model of
    contact C over all 64 of its modes took most of the test's time."""
    from cosim import cli
    slip = ["--set", "subsystems.beam.youngs_modulus=210", "--set", "t_end=0.01",
            "--set", "subsystems.beam.modes.cutoff_hz=0.01"]
    assert cli.main(["info", "beam_impact", *slip]) == 0
    assert ("  warning: `subsystems.beam.youngs_modulus` = 210 Pa: a static deflection of 573 km "
            "under gravity on a 1 m beam") in capsys.readouterr().out
    assert cli.main(["info", "beam_impact", "--json", "--set", "t_end=0.01"]) == 0
    assert json.loads(capsys.readouterr().out)["warnings"] == []


def test_the_gap_is_judged_against_the_scene_size():
    """The rule itself: a contact that never closed warns only past 100 times
    the scene's size; one that closed, never."""
    series = {"gap/C": [150.0, 120.0, 101.0]}
    never = {"contacts": {"C": {"count": 0, "peak_penetration": 0.0}}}
    assert [w["key"] for w in plausible.gap_warnings(never, series, 1.0)] == ["contacts.C"]
    assert plausible.gap_warnings(never, series, 1.02) == []
    closed = {"contacts": {"C": {"count": 1, "peak_penetration": 1e-3}}}
    assert plausible.gap_warnings(closed, series, 1.0) == []

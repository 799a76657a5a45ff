"""An FMU's model description is checked before anything of the FMU runs
(cosim.sides.fmu_description, cosim.scene.fmu), and `cosim info` reads it
without running the FMU's code.

The FMUs are the two-link arm of ``examples/fmu/arm2.c``, built at test time
by ``examples/fmu/build.py``; the hostile ones are copies whose
``modelDescription.xml`` is rewritten here, or whose library carries a
constructor that leaves a mark when it is loaded.  The tests skip, saying
why, where FMPy or a C compiler is missing.
"""
from __future__ import annotations

import json
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from cosim import SceneError, load_scene

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES = ROOT / "examples"
FMU_SCENE = EXAMPLES / "fmu" / "arm_on_beam.toml"
#: the line a hostile description tries to print on a line of its own
FAKE = "contact FAKE: all checks passed, safe to run"


@pytest.fixture(scope="module")
def build(fmu_build):
    """``(examples/fmu/build.py as a module, the C compiler)``."""
    return fmu_build


@pytest.fixture(scope="module")
def arm(fmus):
    """The arm FMU (FMI 2.0, with state)."""
    return fmus[(2, True)]


def _marker_source(folder: Path, marker: Path) -> Path:
    """A C file whose constructor writes ``marker`` when its library is loaded."""
    src = folder / "marker.c"
    src.write_text('#include <stdio.h>\n'
                   '__attribute__((constructor)) static void cosim_test_mark(void) {\n'
                   f'    FILE *f = fopen({json.dumps(str(marker))}, "w");\n'
                   '    if (f) { fputs("loaded\\n", f); fclose(f); }\n'
                   '}\n')
    return src


def _variant(fmu: Path, out: Path, edit) -> Path:
    """A copy of ``fmu`` at ``out`` whose modelDescription.xml is ``edit(text)``."""
    with zipfile.ZipFile(fmu) as src, zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as dst:
        for item in src.infolist():
            data = src.read(item.filename)
            if item.filename == "modelDescription.xml":
                new = edit(data.decode())
                assert new != data.decode(), "the edit changed nothing"
                data = new.encode()
            dst.writestr(item, data)
    return out


def _cli(*args, timeout=120):
    """``cosim ARGS`` as a process: the cosim under test, environment inherited."""
    return subprocess.run([sys.executable, "-m", "cosim.cli", *map(str, args)],
                          capture_output=True, text=True, timeout=timeout)


def _scene(fmu, text=None, tmp_path=None, overrides=()):
    path = FMU_SCENE
    if text is not None:
        path = tmp_path / "scene.toml"
        path.write_text(text)
    return load_scene(path, None, [f"subsystems.arm.path={fmu}", *overrides])


def _coupler_text() -> str:
    """The arm on the beam with the contact exchanged by the coupler, so that
    the pre-flight check weighs the FMU's port mass."""
    return (FMU_SCENE.read_text().replace('host = "beam"', "")
            .replace('placement = "embedded"', 'placement = "coupler"'))


# ------------------------------------------------------ the modelIdentifier
def test_model_identifier_outside_the_fmu_runs_nothing(build, arm, tmp_path):
    """A modelIdentifier that climbs out of the unpacked FMU to a library
    elsewhere is refused when the scene loads: neither `cosim run` nor
    `cosim info` loads that library (its constructor would leave the mark)."""
    module, cc = build
    outside = tmp_path / "outside"
    outside.mkdir()
    marker = tmp_path / "MARKER"
    lib = outside / "evil.so"
    subprocess.run([cc, "-shared", "-fPIC", str(_marker_source(tmp_path, marker)), "-o",
                    str(lib)], check=True, capture_output=True)
    climb = "../" * 40 + str(outside.relative_to(outside.anchor)) + "/evil"
    evil = _variant(arm, tmp_path / "evil.fmu", lambda t: t.replace(
        'modelIdentifier="arm2"', f'modelIdentifier="{climb}"'))
    for args in (["run", FMU_SCENE, "--set", "t_end=0.001", "--out", tmp_path / "run"],
                 ["info", FMU_SCENE], ["info", FMU_SCENE, "--run-fmu"]):
        done = _cli(*args, "--set", f"subsystems.arm.path={evil}")
        assert not marker.exists(), f"`cosim {args[0]}` loaded the library outside the FMU"
        assert done.returncode == 2, done.stderr
        assert "Traceback" not in done.stderr
        assert (f"{FMU_SCENE}: `subsystems.arm.path`" in done.stderr
                and "has a `modelIdentifier` that is not a C identifier" in done.stderr
                and "../../" in done.stderr), done.stderr
    assert not (tmp_path / "run").exists()
    with pytest.raises(SceneError, match=r"`modelIdentifier` that is not a C identifier"):
        _scene(_variant(arm, tmp_path / "space.fmu", lambda t: t.replace(
            'modelIdentifier="arm2"', 'modelIdentifier="arm 2"')))


def test_the_library_is_the_one_in_the_fmus_binaries_folder(arm, tmp_path):
    """With a C identifier, FMPy loads ``binaries/PLATFORM/IDENTIFIER.so`` of
    the unpacked FMU: the file the zip holds there, and no other."""
    import fmpy
    from fmpy.fmi2 import FMU2Slave
    from cosim.sides.fmu_description import read_fmu_variables
    md, _ = read_fmu_variables(arm)
    unzipped = Path(fmpy.extract(str(arm), str(tmp_path / "unzipped")))
    slave = FMU2Slave(guid=md.guid, unzipDirectory=str(unzipped),
                      modelIdentifier=md.coSimulation.modelIdentifier, instanceName="arm")
    try:
        path = Path(slave.dll._name).resolve()
        member = f"binaries/{fmpy.platform}/arm2{fmpy.sharedLibraryExtension}"
        assert path == unzipped.resolve() / member
        with zipfile.ZipFile(arm) as z:
            assert path.read_bytes() == z.read(member)
    finally:
        slave.freeLibrary()


# ------------------------------------------------------- info runs nothing
def test_info_does_not_load_the_fmu(build, tmp_path):
    """`cosim info` of the shipped FMU scene reads modelDescription.xml alone:
    the library's constructor never runs, and info says what it did not
    evaluate.  `--run-fmu` (the opt-in) loads it: the mark appears."""
    module, cc = build
    marker = tmp_path / "MARKER"
    fmu = module.build_fmu(tmp_path, 2, True, cc, name="marked",
                           extra_sources=[_marker_source(tmp_path, marker)])
    done = _cli("info", FMU_SCENE, "--set", f"subsystems.arm.path={fmu}")
    assert done.returncode == 0, done.stderr
    assert not marker.exists(), "`cosim info` loaded the FMU's library"
    assert "FMU code not run: read from modelDescription.xml alone" in done.stdout
    assert ("    not evaluated: reduced mass, frequency, contact time and stable steps: the "
            "mass of port `tip` is FMU marked.fmu's output `mass_y`, which the FMU reports "
            "only when it runs") in done.stdout
    assert "    port tip: mass unknown until the FMU runs (output mass_y)" in done.stdout
    js = _cli("info", FMU_SCENE, "--json", "--set", f"subsystems.arm.path={fmu}")
    assert not marker.exists(), "`cosim info --json` loaded the FMU's library"
    info = json.loads(js.stdout)
    assert info["fmu_code_run"] is False
    assert info["contacts"]["C"]["pose"]["why"].startswith("finding where it closes would run "
                                                           "the FMU's code")
    run = _cli("info", FMU_SCENE, "--run-fmu", "--set", f"subsystems.arm.path={fmu}")
    assert run.returncode == 0, run.stderr
    assert marker.exists()
    assert "FMU code run (--run-fmu)" in run.stdout
    assert "--run-fmu" in _cli("info", "--help").stdout


def test_info_evaluates_a_declared_port_mass_without_the_fmu(arm):
    """A numeric port mass is known from the scene: info evaluates the
    contact at the initial pose, as the run's checks would, without the FMU."""
    from cosim.scene.info import scene_info
    scene = _scene(arm, overrides=["subsystems.arm.ports.tip.port_mass=0.25"])
    info = scene_info(scene)
    c = info["contacts"]["C"]
    assert info["fmu_code_run"] is False and "not_evaluated" not in c
    assert c["pose"]["at"] == "initial"
    system = scene.build()[0]
    beam = system.subsystems[1].port_mobility(0, (0.0, 1.0))
    assert c["reduced_mass"] == pytest.approx(1.0 / (1.0 / 0.25 + beam), rel=1e-12)
    assert info["subsystems"]["arm"]["fmu"]["port_mass"] == {"tip": {"kg": 0.25,
                                                                     "variable": None}}


def _mass_start(start):
    """An edit giving the arm's `mass_y` output the start value ``start``."""
    def edit(text):
        head, _, rest = text.partition('name="mass_y"')
        line, _, tail = rest.partition("</ScalarVariable>")
        line = line.replace('initial="calculated"><Real/>',
                            f'initial="exact"><Real start="{start}"/>')
        return head + 'name="mass_y"' + line + "</ScalarVariable>" + tail
    return edit


def test_info_takes_a_port_mass_from_its_start_value(arm, tmp_path):
    """A port mass named by an output with a start value: info uses the start
    value without running the FMU; an unfit one leaves the contact
    not evaluated, saying why."""
    from cosim.scene.info import scene_info
    good = _variant(arm, tmp_path / "start.fmu", _mass_start("0.17"))
    info = scene_info(_scene(good))
    assert info["subsystems"]["arm"]["fmu"]["port_mass"]["tip"] == {"kg": 0.17,
                                                                    "variable": "mass_y"}
    c = info["contacts"]["C"]
    assert "not_evaluated" not in c and c["reduced_mass"] < 0.17
    bad = _variant(arm, tmp_path / "zero.fmu", _mass_start("0.0"))
    c = scene_info(_scene(bad))["contacts"]["C"]
    assert c["not_evaluated"].endswith(
        "(its model description gives it the start value 0.0, which must be finite and > 0 "
        "kg, got 0.0); `cosim info --run-fmu` runs the FMU to evaluate them")


# ------------------------------------------------------- output injection
def test_info_escapes_what_the_description_says(arm, tmp_path):
    """Line breaks, carriage returns and bidirectional overrides in a model
    description's names, descriptions, units, start values, model name and
    generation tool show escaped; a long text is capped."""
    def hostile(t):
        t = t.replace('description="force on the tip, x [N]"',
                      f'description="force&#10;{FAKE}"')
        t = t.replace('modelName="arm2"', f'modelName="arm2&#13;{FAKE}&#x202E;"')
        t = t.replace('generationTool="cosim examples/fmu/build.py"',
                      f'generationTool="tool&#10;{FAKE}" description="{"x" * 100_000}"')
        t = t.replace('name="l1"', f'name="l1&#10;{FAKE}"')
        return t.replace('<Real start="0.2"/>', f'<Real start="0.2&#10;{FAKE}" unit="m&#10;'
                                                f'{FAKE}"/>')
    fmu = _variant(arm, tmp_path / "hostile.fmu", hostile)
    for args in ([], ["--run-fmu"]):
        done = _cli("info", FMU_SCENE, *args, "--set", f"subsystems.arm.path={fmu}")
        assert done.returncode == 0, done.stderr
        lines = done.stdout.splitlines()
        assert not [ln for ln in lines if ln.lstrip().startswith("contact FAKE")], done.stdout
        assert "\r" not in done.stdout and "\u202e" not in done.stdout
        assert f"force\\n{FAKE}" in done.stdout and f"l1\\n{FAKE}" in done.stdout
        assert f"model arm2\\r{FAKE}\\u202e, generated by tool\\n{FAKE}: xxx" in done.stdout
        assert max(map(len, lines)) < 1000
        assert f"{'x' * 200}... (100000 characters)" in done.stdout
    info = json.loads(_cli("info", FMU_SCENE, "--json", "--set",
                           f"subsystems.arm.path={fmu}").stdout)
    fmu_info = info["subsystems"]["arm"]["fmu"]
    texts = [fmu_info["model_name"], fmu_info["generation_tool"], fmu_info["description"]]
    for v in fmu_info["variables"]:
        texts += [v["name"], v["description"], v["start"], v["unit"]]
    assert not [t for t in texts if t is not None and ("\n" in t or "\r" in t)]
    assert max(len(t) for t in texts if t) < 300


# ------------------------------------------------- names checked at load
@pytest.mark.parametrize("name", ["../../x", "", "a/b", "q\n1"])
def test_coordinate_names_are_checked_at_load(arm, tmp_path, name):
    """A coordinate's name becomes a series key: held to the rule of names
    when the scene loads, not when the run writes series.npz at its end."""
    text = FMU_SCENE.read_text().replace('coordinates = { q1 = ["q1", "dq1"], q2 = ',
                                         f'coordinates = {{ {json.dumps(name)} = ["q1", '
                                         f'"dq1"], q2 = ')
    with pytest.raises(SceneError, match=r"`subsystems.arm.coordinates` names a coordinate "
                                         r"that must (be a plain name|not be empty)") as info:
        _scene(arm, text, tmp_path)
    assert str(info.value).startswith(str(tmp_path / "scene.toml"))
    assert "\n" not in str(info.value)


def test_duplicate_variable_names_in_the_description_are_refused(arm, tmp_path):
    fmu = _variant(arm, tmp_path / "twice.fmu", lambda t: t.replace(
        "  </ModelVariables>", '    <ScalarVariable name="x" valueReference="99" '
                               'causality="output" variability="continuous" '
                               'initial="calculated"><Real/></ScalarVariable>\n'
                               "  </ModelVariables>"))
    with pytest.raises(SceneError, match=r"`subsystems.arm.path` '.*twice.fmu' declares the "
                                         r"variable 'x' twice"):
        _scene(fmu)


@pytest.mark.parametrize("overrides, match", [
    (['subsystems.arm.ports.tip.force=["fx", "fx"]'],
     r"`subsystems.arm.ports.tip.force` must name 2 different variables, got \['fx', 'fx'\]"),
    (['subsystems.arm.ports.tip.position=["y", "y"]'],
     r"`subsystems.arm.ports.tip.position` must name 2 different variables"),
    (['subsystems.arm.ports.tip.velocity=["x", "vy"]'],
     r"`subsystems.arm.ports.tip.velocity` names 'x', the same variable of arm2_fmi2.fmu as "
     r"'x' of `subsystems.arm.ports.tip.position`; they must differ"),
    (['subsystems.arm.coordinates.q1=["q1", "q1"]'],
     r"`subsystems.arm.coordinates.q1` must name 2 different variables"),
    (['subsystems.arm.ports.tip2={position = ["x", "y"], velocity = ["vx", "vy"], '
      'force = ["fy", "fx"], port_mass = 1.0}'],
     r"`subsystems.arm.ports.tip2.force` sets arm2_fmi2.fmu's variable 'fy', which "
     r"`subsystems.arm.ports.tip.force` sets already"),
])
def test_port_lists_name_different_variables(arm, overrides, match):
    with pytest.raises(SceneError, match=match):
        _scene(arm, overrides=overrides)


def test_value_references_cosim_sets_must_differ(arm, tmp_path):
    """An input or parameter that shares its value reference with another
    that cosim sets (an alias) would be set twice: refused."""
    fy_as_fx = _variant(arm, tmp_path / "alias.fmu", lambda t: t.replace(
        'name="fy" valueReference="17"', 'name="fy" valueReference="16"'))
    with pytest.raises(SceneError, match=r"`subsystems.arm.ports.tip.force` sets "
                                         r"alias.fmu's variable 'fy' \(its value reference 16 "
                                         r"is that of 'fx'\), which `subsystems.arm.ports.tip."
                                         r"force` sets already"):
        _scene(fy_as_fx)
    g_as_fx = _variant(arm, tmp_path / "alias_g.fmu", lambda t: t.replace(
        'name="g" valueReference="10"', 'name="g" valueReference="16"'))
    with pytest.raises(SceneError, match=r"`subsystems.arm.parameters.g` sets alias_g.fmu's "
                                         r"variable 'g' \(its value reference 16 is that of "
                                         r"'fx'\)"):
        _scene(g_as_fx, overrides=["subsystems.arm.parameters.g=9.81"])
    # outputs may alias: reading one value twice harms nothing
    y_as_x = _variant(arm, tmp_path / "alias_q.fmu", lambda t: t.replace(
        'name="q2" valueReference="23"', 'name="q2" valueReference="22"'))
    _scene(y_as_x)


# --------------------------------------------------------------- port mass
@pytest.mark.parametrize("parameters, value", [
    ({"q1_start": 0.0}, "0.0"),
    ({"q1_start": -0.5}, "-0.5"),
    ({"q1_start": 1e-320}, "1e-320"),
    ({"m1": 0.0, "m2": 0.0, "I1": 0.0, "I2": 0.0}, "nan"),       # the arm's mass_y: 0/0
    ({"m1": 1e-300, "m2": 1e-300, "I1": 1e-300, "I2": 1e-300}, "0.0"),   # underflows
])
def test_an_fmu_reported_port_mass_is_checked(arm, tmp_path, parameters, value):
    """`port_mass` naming an FMU output is held to the rule of a numeric one
    once the FMU is initialised: a clear error names the FMU, the variable
    and the value, where the pre-flight check divided by zero."""
    variable = "q1" if "q1_start" in parameters else "mass_y"
    over = [f"subsystems.arm.ports.tip.port_mass=\"{variable}\""]
    over += [f"subsystems.arm.parameters.{k}={v!r}" for k, v in parameters.items()]
    scene = _scene(arm, _coupler_text(), tmp_path, over)
    with pytest.raises(SceneError, match=rf"`subsystems.arm.ports.tip.port_mass` names output "
                                         rf"`{variable}` of FMU arm2_fmi2.fmu, which reports "
                                         rf"{value} kg after its initialisation: a port mass "
                                         rf"must be finite and > 0 kg"):
        scene.build()


def test_port_mass_errors_from_the_command_line(arm, tmp_path):
    """`cosim run` and `cosim info --run-fmu` of a port mass the FMU reports
    as 0: exit 2 and the message, no traceback; `cosim info` without the FMU
    cannot know it and says so."""
    scene = tmp_path / "coupler.toml"
    scene.write_text(_coupler_text())
    over = ["--set", f"subsystems.arm.path={arm}", "--set",
            'subsystems.arm.ports.tip.port_mass="q1"']
    for args in (["run", scene, "--out", tmp_path / "run", "--set", "t_end=0.001"],
                 ["info", scene, "--run-fmu"]):
        done = _cli(*args, *over)
        assert done.returncode == 2, done.stderr
        assert "Traceback" not in done.stderr
        assert ("`subsystems.arm.ports.tip.port_mass` names output `q1` of FMU arm2_fmi2.fmu, "
                "which reports 0.0 kg after its initialisation" in done.stderr), done.stderr
    done = _cli("info", scene, *over)
    assert done.returncode == 0, done.stderr
    assert ("the mass of port `tip` is FMU arm2_fmi2.fmu's output `q1`, which the FMU reports "
            "only when it runs (its model description gives it no start value)") in done.stdout


def test_a_declared_port_mass_with_no_finite_inverse_is_refused(arm):
    """1e-320 kg is > 0 but its inverse overflows: the pre-flight check
    divided by zero on it."""
    with pytest.raises(SceneError, match=r"`subsystems.arm.ports.tip.port_mass` must be finite "
                                         r"and > 0 kg with a finite inverse, got 1e-320"):
        _scene(arm, overrides=["subsystems.arm.ports.tip.port_mass=1e-320"])


# ------------------------------------------------------------ the file
def test_an_fmi_1_fmu_is_named_as_such(tmp_path):
    pytest.importorskip("fmpy", reason="FMPy is not installed (the `fmi` extra)")
    fmu = tmp_path / "old.fmu"
    with zipfile.ZipFile(fmu, "w") as z:
        z.writestr("modelDescription.xml",
                   '<?xml version="1.0" encoding="UTF-8"?>\n'
                   '<fmiModelDescription fmiVersion="1.0" modelName="old" '
                   'modelIdentifier="old" guid="{0}">\n<ModelVariables>\n'
                   '<ScalarVariable name="x" valueReference="0" causality="output"><Real/>'
                   '</ScalarVariable>\n</ModelVariables>\n<Implementation>'
                   '<CoSimulation_StandAlone><Capabilities/></CoSimulation_StandAlone>'
                   '</Implementation>\n</fmiModelDescription>\n')
    with pytest.raises(SceneError, match=r"`subsystems.arm.path` '.*old.fmu' is an FMI 1.0 FMU; "
                                         r"cosim supports co-simulation FMUs of FMI 2.0 and "
                                         r"3.0$"):
        _scene(fmu)


def test_a_path_naming_a_directory_says_so(tmp_path):
    pytest.importorskip("fmpy", reason="FMPy is not installed (the `fmi` extra)")
    (tmp_path / "arm2.fmu").mkdir()
    with pytest.raises(SceneError, match=r"`subsystems.arm.path` must name an .fmu file "
                                         r"\(relative to the scene file\), got '.*arm2.fmu': "
                                         r".*arm2.fmu is a directory"):
        _scene(tmp_path / "arm2.fmu")


def test_a_huge_model_description_is_refused_before_it_is_parsed(tmp_path, monkeypatch):
    """A small FMU may hold a huge, highly compressed modelDescription.xml
    that FMPy would parse whole: its declared size is checked first."""
    pytest.importorskip("fmpy", reason="FMPy is not installed (the `fmi` extra)")
    from cosim.sides import fmu_description
    monkeypatch.setattr(fmu_description, "DESCRIPTION_MAX_BYTES", 1 << 16)
    parsed = []
    monkeypatch.setattr(fmu_description.fmpy_module(), "read_model_description",
                        lambda *a, **k: parsed.append(a))
    fmu = tmp_path / "bomb.fmu"
    with zipfile.ZipFile(fmu, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("modelDescription.xml", '<?xml version="1.0"?>\n<fmiModelDescription '
                   'fmiVersion="2.0">' + " " * (1 << 17) + "</fmiModelDescription>")
    assert fmu.stat().st_size < 4096
    with pytest.raises(SceneError, match=r"holds a modelDescription.xml of 131\d+ bytes, more "
                                         r"than the 65536 bytes cosim reads"):
        _scene(fmu)
    assert parsed == []

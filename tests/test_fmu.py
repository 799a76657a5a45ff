"""FMI: a co-simulation FMU as a subsystem (cosim.sides.fmu, cosim.scene.fmu).

The FMU under test is the two-link arm of ``examples/fmu/arm2.c``, compiled at
test time with the machine's C compiler against FMPy's FMI headers (FMI 2.0
and 3.0, with and without ``canGetAndSetFMUstate``).  The tests skip, saying
why, where FMPy or a C compiler is missing.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
from conftest import load_fmu_build

from cosim import SceneError, load_scene, simulate

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES = ROOT / "examples"
FMU_SCENE = EXAMPLES / "fmu" / "arm_on_beam.toml"
MB_SCENE = EXAMPLES / "fmu" / "arm_on_beam_multibody.toml"
#: end of the runs the agreement test compares: the tip touches at 15.0 ms
#: and leaves at 16.0 ms
T_END = 0.018
#: the monolithic reference's tolerance (the scene's 1e-9 costs 4x the time;
#: at 1e-8 C's interval and peak move by less than 1e-9 s and 1e-4 N)
REFERENCE = ["scheme.monolithic.rtol=1e-8"]


def _scene(fmu, *, variant=None, overrides=(), scheme=None, path=FMU_SCENE):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")     # options other schemes ignore (`sequence`)
        return load_scene(path, variant, [f"subsystems.arm.path={fmu}", *overrides], scheme)


def _write(tmp_path, text, name="scene.toml"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_every_fmu_key_of_the_table_is_accepted(fmus):
    """The rows of the FMU sections of the table of keys are the keys the FMU
    scene reaches (tests/test_scene_keys.py walks every other section)."""
    from cosim.scene import keys
    from cosim.scene.checks import record_keys
    with record_keys() as found:
        _scene(fmus[(2, True)])
    covered = {(sid, name) for sid, name, _ in found if sid and sid.startswith("fmu")}
    rows = {(sid, k.name) for sid, sec in keys.SECTIONS.items()
            if sid == "fmu" or sid.startswith("fmu.") for k in sec.keys}
    assert covered <= rows
    assert not rows - covered - {("fmu", "type")}, sorted(rows - covered)


# ------------------------------------------------------------ the subsystem
@pytest.mark.parametrize("version", [2, 3])
def test_rollback_repeats_a_step_exactly(fmus, version):
    """get_state/set_state through the FMU's own state: a step taken again
    from a saved state ends where it ended the first time, and the saved
    state's outputs are those before the step."""
    from cosim.core.subsystem import StepInput
    from cosim.sides.fmu import FMUPort, FMUSubsystem
    port = FMUPort(("x", "y"), ("vx", "vy"), ("fx", "fy"), 0.2)
    sub = FMUSubsystem("arm", fmus[version, True], {"tip": port}, energy="energy",
                       coordinates={"q1": ("q1", "dq1"), "q2": ("q2", "dq2")})
    push = StepInput(0.0, 1e-3, np.array([[[3.0, -50.0]], [[1.0, 20.0]]]))
    before = sub.x.copy()
    saved = sub.get_state()
    sub.step(0.0, 1e-3, push)
    first = sub.x.copy()
    assert not np.allclose(first, before)
    sub.set_state(saved)
    np.testing.assert_array_equal(sub.x, before)
    assert sub.t == 0.0
    sub.step(0.0, 1e-3, push)
    np.testing.assert_array_equal(sub.x, first)
    sub.close()


@pytest.mark.parametrize("version", [2, 3])
def test_rollback_refused_without_fmu_state(fmus, version):
    from cosim.sides.fmu import FMUPort, FMUSubsystem
    port = FMUPort(("x", "y"), ("vx", "vy"), ("fx", "fy"), 0.2)
    sub = FMUSubsystem("arm", fmus[version, False], {"tip": port})
    assert not sub.can_get_set_state
    with pytest.raises(RuntimeError, match=r"subsystem `arm`: FMU arm2_fmi\d_nostate.fmu cannot "
                                           r"get and set its state \(`canGetAndSetFMU"
                                           + ("S" if version == 3 else "s") + r"tate` is "
                                           r"false\)"):
        sub.get_state()


def test_fmu_conserves_the_arm_energy_and_reports_port_mass(fmus):
    """Free swing: the FMU's energy output stays put (RK4 sub-steps of
    10 us), and the port mass read from its `mass_y` variable is the tip's
    effective mass 1 / (e_y^T J M^-1 J^T e_y) that the multibody tree gives."""
    from cosim.sides.fmu import FMUPort, FMUSubsystem
    port = FMUPort(("x", "y"), ("vx", "vy"), ("fx", "fy"), "mass_y")
    sub = FMUSubsystem("arm", fmus[2, True], {"tip": port}, energy="energy")
    mb = load_scene(MB_SCENE).build()[0].subsystems[0]
    assert sub.port_mobility(0, (0.0, 1.0)) == pytest.approx(mb.port_mobility(0, (0.0, 1.0)),
                                                             rel=1e-12)
    e0 = sub.energy()
    assert e0 == pytest.approx(mb.energy(), rel=1e-12)
    for k in range(10):
        sub.step(k * 1e-3, 1e-3)
    assert abs(sub.energy() - e0) < 1e-9 * e0


# ------------------------------------------------------------ the scene
def test_scene_refuses_monolithic(fmus):
    with pytest.raises(SceneError, match=r"`scheme.name` is `monolithic`.*subsystem `arm` is a "
                                         r"co-simulation FMU with no model-exchange face"):
        _scene(fmus[2, True], scheme="monolithic").build()


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("how", ["implicit", "controlled"])
def test_scene_refuses_rollback_without_fmu_state(fmus, version, how):
    scene = _scene(fmus[version, False], variant="controlled" if how == "controlled" else None,
                   scheme="implicit" if how == "implicit" else None)
    what = "the `implicit` scheme" if how == "implicit" else r"macro-step control \(`scheme."
    flag = "canGetAndSetFMUState" if version == 3 else "canGetAndSetFMUstate"
    with pytest.raises(SceneError, match=r"`subsystems.arm.path` names an FMU that cannot get "
                                         rf"and set its state \(`{flag}` is false\).*" + what):
        scene.build()


def test_contacts_stay_out_of_the_fmu(fmus, tmp_path):
    """An FMU cannot host a contact: the scene that asks is refused, one that
    leaves the host open gets the other side as host."""
    with pytest.raises(SceneError, match=r"`contacts.C.host` names `arm`, but subsystem `arm` "
                                         r"is an FMU, a black box"):
        # (`follow = false`: a following contact hosted by point a's side is
        # refused at load for its own reason, tests/test_following_host.py)
        _scene(fmus[2, True], overrides=["contacts.C.host=arm", "contacts.C.follow=false"]).build()
    text = FMU_SCENE.read_text().replace('host = "beam"', "")
    system, _ = _scene(fmus[2, True], path=_write(tmp_path, text)).build()
    assert system.links[0].host == system.names.index("beam")
    ground = text + ('\n[subsystems.ground]\ntype = "rigid"\npoints = { surface = [0.0, 0.0] }\n'
                     '\n[contacts.G]\na = "arm.tip"\nb = "ground.surface"\n'
                     'normal = [0.0, 1.0]\nlaw = { type = "linear", contact_stiffness = 1e6 }\n')
    with pytest.raises(SceneError, match=r"`contacts.G.placement` is `embedded`, but subsystem "
                                         r"`arm` is an FMU.*set `placement = \"coupler\"`"):
        _scene(fmus[2, True], path=_write(tmp_path, ground, "ground.toml")).build()
    system, _ = _scene(fmus[2, True], path=_write(tmp_path, ground, "ground.toml"),
                       overrides=["contacts.G.placement=coupler"]).build()
    assert system.links[1].placement == "coupler"


@pytest.mark.parametrize("key, value, match", [
    ("subsystems.arm.ports.tip.position", '["x", "height"]',
     r"`subsystems.arm.ports.tip.position` names no variable of arm2_fmi2.fmu: 'height'; its "
     r"outputs are \['dq1', 'dq2', 'energy', 'mass_y', 'q1', 'q2', 'vx', 'vy', 'x', 'y'\]"),
    ("subsystems.arm.ports.tip.force", '["fx", "y"]',
     r"`subsystems.arm.ports.tip.force` must name a real input of arm2_fmi2.fmu, got 'y' "
     r"\(output Real\)"),
    ("subsystems.arm.ports.tip.velocity", '["vx"]',
     r"`subsystems.arm.ports.tip.velocity` must be an array of 2 variable names, got \['vx'\]"),
    ("subsystems.arm.ports.tip.port_mass", "-1.0",
     r"`subsystems.arm.ports.tip.port_mass` must be > 0 kg, got -1.0"),
    ("subsystems.arm.parameters.stiffness", "1.0",
     r"`subsystems.arm.parameters.stiffness` names no variable of arm2_fmi2.fmu"),
    ("subsystems.arm.energy", '"fx"',
     r"`subsystems.arm.energy` must name a real output of arm2_fmi2.fmu, got 'fx' \(input"),
    ("subsystems.arm.coordinates.q3", '["q3", "dq3"]',
     r"`subsystems.arm.coordinates.q3` names no variable of arm2_fmi2.fmu: 'q3'"),
    ("subsystems.arm.ports.tip.torque", '"tau"',
     r"`subsystems.arm.ports.tip.torque` is not a known key"),
])
def test_scene_errors_name_file_key_and_value(fmus, key, value, match):
    with pytest.raises(SceneError, match=match) as info:
        _scene(fmus[2, True], overrides=[f"{key}={value}"])
    assert str(info.value).startswith(str(FMU_SCENE))


def test_scene_path_is_relative_to_the_scene_file(fmus, tmp_path):
    scene_file = tmp_path / "arm.toml"
    scene_file.write_text(FMU_SCENE.read_text())
    with pytest.raises(SceneError, match=r"arm.toml: `subsystems.arm.path` must name an .fmu "
                                         r"file \(relative to the scene file\), got "
                                         r"'arm2_fmi2.fmu'"):
        load_scene(scene_file)
    (tmp_path / "arm2_fmi2.fmu").write_bytes(fmus[2, True].read_bytes())
    scene = load_scene(scene_file, overrides=["t_end=0.001"])
    assert scene.subsystems[0]["path"] == str(tmp_path / "arm2_fmi2.fmu")
    # the run folder's scene.toml names the FMU where it was found: it rebuilds from there
    simulate(scene, out=tmp_path / "run")
    again = load_scene(tmp_path / "run" / "scene.toml")
    assert again.subsystems[0]["path"] == str(tmp_path / "arm2_fmi2.fmu")
    (tmp_path / "arm2_fmi2.fmu").write_text("not a zip")
    with pytest.raises(SceneError, match=r"`subsystems.arm.path` 'arm2_fmi2.fmu' is not an FMU "
                                         r"that FMPy can read"):
        load_scene(scene_file)


def test_energy_variable_required_while_the_guard_checks_energy(fmus, tmp_path):
    path = _write(tmp_path, FMU_SCENE.read_text().replace('energy = "energy"', ""))
    with pytest.raises(SceneError, match=r"`subsystems.arm.energy` is required while the run "
                                         r"guard checks energy"):
        _scene(fmus[2, True], path=path).build()
    system, _ = _scene(fmus[2, True], path=path, overrides=["guard.energy_check=false"]).build()
    assert system.subsystems[0].energy() == 0.0


def test_missing_fmpy_names_the_extra(fmus, monkeypatch):
    monkeypatch.setitem(sys.modules, "fmpy", None)        # import fmpy now raises ImportError
    with pytest.raises(SceneError, match=r"`subsystems.arm.type` an `fmu` subsystem needs FMPy, "
                                         r"which is not installed: pip install \"cosim\[fmi\]\""):
        _scene(fmus[2, True])


def test_fmpy_is_not_imported_without_an_fmu():
    code = ("import sys; from cosim import load_scene, simulate; "
            f"simulate(load_scene({str(ROOT / 'cases' / 'spring_drop.toml')!r})); "
            "print('fmpy' in sys.modules)")
    env = {**os.environ, "PYTHONPATH": str(ROOT / "src")}
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env,
                          check=True)
    assert done.stdout.strip() == "False"


@pytest.mark.parametrize("port_mass", [0.25, 2.5])
def test_preflight_uses_the_declared_port_mass(fmus, tmp_path, port_mass):
    """A coupler contact between the FMU and the beam: the explicit schemes'
    pre-flight check takes the FMU's side of the reduced mass from
    `port_mass` (a number here), and refuses a step too long for it."""
    from cosim.errors import UnsafeStepError
    text = FMU_SCENE.read_text().replace('host = "beam"', "").replace(
        'placement = "embedded"', 'placement = "coupler"')
    over = [f"subsystems.arm.ports.tip.port_mass={port_mass}", "scheme.macro_step=1e-4"]
    system, scheme = _scene(fmus[2, True], path=_write(tmp_path, text), overrides=over,
                            scheme="jacobi").build()
    assert system.links[0].placement == "coupler"
    beam = system.subsystems[1].port_mobility(0, (0.0, 1.0))
    m = 1.0 / (1.0 / port_mass + beam)
    with pytest.raises(UnsafeStepError, match=rf"reduced mass {m:.4g} kg"):
        scheme.preflight(system)


def test_info_lists_the_fmu_variables(fmus):
    """With the FMU run (`run_fmu`, `cosim info --run-fmu`): its variables,
    and its port mass where the contact first touches
    (tests/test_fmu_description.py: what info tells without running it)."""
    from cosim.scene.info import scene_info
    info = scene_info(_scene(fmus[3, False]), run_fmu=True)
    arm = info["subsystems"]["arm"]
    assert arm["dofs"] == 2 and arm["coordinates"] == ["q1", "q2"]
    assert arm["fmu"]["fmi_version"] == "3.0" and arm["fmu"]["can_get_set_state"] is False
    by_name = {v["name"]: v for v in arm["fmu"]["variables"]}
    assert by_name["fx"]["causality"] == "input"
    assert by_name["mass_y"]["causality"] == "output"
    assert float(by_name["dq1_start"]["start"]) == -3.0
    tip = info["contacts"]["C"]
    beam = _scene(fmus[3, False]).build()[0].subsystems[1].port_mobility(0, (0.0, 1.0))
    fmu = _scene(fmus[3, False]).build()[0].subsystems[0]
    # the FMU's port mass and the beam's mobility at the start (the values at
    # the first touch, where info evaluates them, come from the arm's pose then)
    assert tip["pose"]["at"] == "first touch" and tip["pose"]["t"] > 0
    assert tip["initial_pose"]["reduced_mass"] == pytest.approx(
        1.0 / (fmu.port_mobility(0, (0.0, 1.0)) + beam), rel=1e-9)


def test_cli_runs_and_lists_the_fmu(fmus, tmp_path):
    env = {**os.environ, "PYTHONPATH": str(ROOT / "src")}
    run = [sys.executable, "-m", "cosim.cli"]
    for scheme in ("jacobi", "gauss_seidel", "implicit"):
        out = tmp_path / scheme
        subprocess.run([*run, "run", str(FMU_SCENE), "--scheme", scheme, "--set",
                        f"subsystems.arm.path={fmus[2, True]}", "--set", f"t_end={T_END}",
                        "--out", str(out), "--no-estimate"], check=True, capture_output=True,
                       env=env)
        summary = json.loads((out / "summary.json").read_text())
        assert summary["scheme"] == scheme and summary["contacts"]["C"]["count"] == 1
        assert set(summary["final_state"]["arm"]) == {"q1", "q2"}
    done = subprocess.run([*run, "info", str(FMU_SCENE), "--set",
                           f"subsystems.arm.path={fmus[2, False]}"], check=True,
                          capture_output=True, text=True, env=env)
    assert "FMU arm2_fmi2_nostate.fmu (FMI 2.0), get/set state no, variables:" in done.stdout
    assert "      fx = 0.0: input continuous Real, force on the tip, x [N]" in done.stdout


# ------------------------------------------------------------ agreement
def _contact(scene, scheme):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")     # options other schemes ignore (`sequence`)
        r = simulate(scene, scheme=scheme, estimate=False)
    assert r.success, r.message
    c = r.summary["contacts"]["C"]
    return np.array(c["intervals"], float), float(np.max(r.series["force/C"]))


@pytest.fixture(scope="module")
def multibody_runs():
    """The multibody arm on the beam: the monolithic reference and each
    co-simulation scheme at 50 us steps (the scene's)."""
    over = [f"t_end={T_END}"]
    out = {"monolithic": _contact(load_scene(MB_SCENE, None, over + REFERENCE), "monolithic")}
    for scheme in ("jacobi", "gauss_seidel", "implicit"):
        out[scheme] = _contact(load_scene(MB_SCENE, None, over), scheme)
    out["controlled"] = _contact(load_scene(MB_SCENE, "controlled", over), "gauss_seidel")
    return out


@pytest.fixture(scope="module")
def fmu_contacts(fmus):
    """``(version, state, variant, scheme) -> _contact(...)`` of the FMU arm
    scene to ``T_END``, each run once per worker: the agreement test and the
    stateless FMU's test ask for the same runs of the FMU with state."""
    done = {}

    def contact(version, state, variant, scheme):
        key = (version, state, variant, scheme)
        if key not in done:
            done[key] = _contact(_scene(fmus[version, state], variant=variant,
                                        overrides=[f"t_end={T_END}"]), scheme)
        return done[key]
    return contact


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("scheme", ["jacobi", "gauss_seidel", "controlled", "implicit"])
def test_fmu_and_multibody_arm_agree_to_the_coupling_error(fmu_contacts, multibody_runs,
                                                           version, scheme):
    """The same arm as FMU and as multibody tree strikes beam_impact's beam.

    The yardstick is the coupling error at this macro step, as `cosim bench`
    measures it: the multibody scene's Jacobi run against the monolithic
    reference, in C's contact interval [s] and its peak force [N] (measured
    here: 4.6e-6 s and 0.89 N of 511 N).  The FMU integrates the arm's
    equations with the multibody side's RK4 sub-steps, so what the FMI
    interface changes must stay within it (factor 1): an FMI 2.0 FMU that
    interpolates its inputs receives the same force polynomial as the tree
    (and agrees to round-off, asserted below); an FMI 3.0 FMU holds each
    step's mean force, an error of the kind Jacobi's held force makes.
    """
    run = "gauss_seidel" if scheme == "controlled" else scheme
    got = fmu_contacts(version, True, "controlled" if scheme == "controlled" else None, run)
    ref, mine = multibody_runs["monolithic"], multibody_runs[scheme]
    jac = multibody_runs["jacobi"]
    assert got[0].shape == mine[0].shape == ref[0].shape == (1, 2)
    tol_t = float(np.max(np.abs(jac[0] - ref[0])))
    tol_f = abs(jac[1] - ref[1])
    assert tol_t > 0 and tol_f > 0
    dt, df = float(np.max(np.abs(got[0] - mine[0]))), abs(got[1] - mine[1])
    assert dt <= tol_t, f"contact interval differs by {dt:.3g} s, coupling error {tol_t:.3g} s"
    assert df <= tol_f, f"peak force differs by {df:.3g} N, coupling error {tol_f:.3g} N"
    if version == 2:
        # the scheme's own error against the reference, a thousandth of it
        own_t = float(np.max(np.abs(mine[0] - ref[0])))
        own_f = abs(mine[1] - ref[1])
        assert dt <= 1e-3 * own_t and df <= 1e-3 * own_f, (dt, own_t, df, own_f)


def test_fmu_without_state_runs_the_explicit_schemes(fmu_contacts):
    for version in (2, 3):
        for scheme in ("jacobi", "gauss_seidel"):
            got = fmu_contacts(version, False, None, scheme)
            with_state = fmu_contacts(version, True, None, scheme)
            # the two FMUs are one C source built with the same flags but the
            # state flag, and these schemes take the same steps with either
            # (none rolls back here): the same computation, bit for bit
            np.testing.assert_array_equal(got[0], with_state[0])
            assert got[1] == with_state[1]


def test_no_compiler_is_found_on_an_empty_path(monkeypatch):
    """Where no C compiler is found the FMU tests skip (the `fmus` fixture)."""
    monkeypatch.delenv("CC", raising=False)
    monkeypatch.setenv("PATH", "")
    assert load_fmu_build().find_compiler() is None


def test_example_runs(fmus):
    """examples/fmu_arm_on_beam.py builds the FMU and runs the four couplings."""
    env = {**os.environ, "PYTHONPATH": str(ROOT / "src")}
    done = subprocess.run([sys.executable, str(EXAMPLES / "fmu_arm_on_beam.py"), "--t-end",
                           "0.0165"], capture_output=True, text=True, env=env, check=True)
    lines = done.stdout.splitlines()
    assert lines[0] == "built arm2_fmi2.fmu"
    for label in ("jacobi", "gauss_seidel", "implicit", "gauss_seidel, controlled"):
        assert sum(ln.startswith(f"{label:26s} ") for ln in lines) == 2, done.stdout

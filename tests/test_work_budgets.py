"""A run's work is counted before it starts: sub-steps, implicit iterations,
contact steps and the monolithic solver's stiffest mode; a count above
`guard.max_steps` is refused, a large one said first.  Also: a tolerance
float64 cannot meet, a capped echo of a long or forged value, a non-finite
entry of a drive table, a modal cutoff that keeps no mode."""
from __future__ import annotations

import math
import subprocess
import sys
import time
import warnings

import numpy as np
import pytest

from conftest import CASES
from cosim.core.schemes.base import MIN_RELATIVE_TOLERANCE
from cosim.scene.checks import MAX_STEPS, SceneError
from cosim.scene.load import load_scene
from cosim.scene.work import WARN_STEPS, estimate_work

THREE_MASS = CASES / "three_mass.toml"
ROD = CASES / "rod_impact.toml"
SPRING_DROP = CASES / "spring_drop.toml"
DRIVE = "subsystems.body.bodies.mass.joint.drive"


def cosim(*args, cwd, timeout=60):
    """``cosim ARGS`` in a subprocess; (exit status, stdout, stderr, wall time [s])."""
    t0 = time.monotonic()
    p = subprocess.run([sys.executable, "-m", "cosim.cli", *map(str, args)],
                       capture_output=True, text=True, cwd=cwd, timeout=timeout)
    return p.returncode, p.stdout, p.stderr, time.monotonic() - t0


def load(path, *overrides, scheme=None):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return load_scene(path, overrides=list(overrides), scheme=scheme)


# ------------------------------------------------------------ the budgets
@pytest.mark.parametrize("args,key,how", [
    # a billion sub-steps per macro step passed the old macro-step check and never advanced
    (["--set", "scheme.substeps={robot=1000000000}"], "scheme.substeps",
     "robot 1e+09 in 1e+09 sub-steps"),
    # up to a billion iterations of every macro step
    (["--scheme", "implicit", "--set", "scheme.max_iterations=1000000000"],
     "scheme.max_iterations", "x at most 1000000000 iterations (`scheme.max_iterations`)"),
])
def test_a_cosimulation_over_the_budget_is_refused_before_it_starts(tmp_path, args, key, how):
    code, out, err, wall = cosim("run", THREE_MASS, *args, "--out", tmp_path / "run",
                                 "--quiet", cwd=tmp_path)
    assert code == 2, err
    assert f"`{key}` is " in err and "the run would take at most" in err, err
    assert how in err, err
    assert f"more than the {MAX_STEPS:.3g} a run may take (`guard.max_steps`)" in err
    assert "Traceback" not in err and not (tmp_path / "run").exists()
    assert wall < 30, wall                      # refused at once, not after a long run


def test_a_long_monolithic_run_is_refused_with_its_stiffest_mode(tmp_path):
    """The monolithic solver's steps are counted from its explicit method's
    stability and the rod's highest kept mode: at least t_end omega / 6.39."""
    code, out, err, wall = cosim("run", ROD, "--set", "t_end=1e9", "--scheme", "monolithic",
                                 "--out", tmp_path / "run", "--quiet", cwd=tmp_path)
    assert code == 2, err
    assert "`t_end` is 1e+09 s: the run would take at least" in err, err
    assert "DOP853 is explicit" in err and "the highest kept mode of `rod`" in err, err
    assert "Traceback" not in err and not (tmp_path / "run").exists()
    assert wall < 30, wall
    scene = load(ROD, "t_end=1e9", "guard.max_steps=1e20", scheme="monolithic")
    system, _ = scene.build()
    est = scene.work(system=system)
    omega = max(float(np.max(s.omega)) for s in system.subsystems if hasattr(s, "omega"))
    assert est.steps == pytest.approx(1e9 * omega / 6.39, rel=1e-12)
    assert est.bound == "at least" and est.key == "t_end"


def test_raising_the_limit_runs_and_a_large_count_says_so_first(tmp_path):
    """Implicit iterations counted at most: 200 macro steps x 1e7 iterations x
    10 rk4 steps = 2e10, above the limit until `guard.max_steps` is raised; the
    run then warns with the count, before its progress, and converges in a
    few iterations."""
    args = ["run", SPRING_DROP, "--scheme", "implicit", "--set",
            "scheme.max_iterations=10000000", "--quiet"]
    code, _, err, _ = cosim(*args, "--out", tmp_path / "a", cwd=tmp_path)
    assert code == 2 and "`scheme.max_iterations` is 10000000" in err, err
    code, out, err, _ = cosim(*args, "--set", "guard.max_steps=1e11", "--out", tmp_path / "b",
                              cwd=tmp_path)
    assert code == 0, err
    assert ("warning: " + str(SPRING_DROP) + ": a long run ahead: at most 2e+10 integrator "
            "steps (200 macro steps of 0.0001 s") in err, err
    assert "status finished" in out


def test_info_shows_the_count():
    code, out, err, _ = cosim("info", THREE_MASS, cwd=CASES)
    assert code == 0, err
    # 0.25 s in contact steps of 30 us; the chain steps its closed contact in
    # closed form, one step per macro step
    assert ("  work: at most 1.67e+04 integrator steps (8334 macro steps of 3e-05 s "
            "(`scheme.contact_step`, t_end 0.25 s) x (chain 1 + robot 1) steps each)"
            in out.splitlines()), out


#: three_mass with a damped chain: its closed contact is stepped by RK4 at
#: the chain's `contact_step` (1 us), 30 steps in a macro step of 30 us
DAMPED = "subsystems.chain.rayleigh=[0.0, 1e-6]"


def test_the_count_adds_sub_steps_iterations_and_contact_steps():
    base = load(THREE_MASS, DAMPED).work()
    assert base.steps == 8334 * (30 + 1)
    multirate = load(THREE_MASS, DAMPED, "scheme.substeps={robot=7}").work()
    assert multirate.steps == 8334 * (30 + 7)
    implicit = load(THREE_MASS, DAMPED, scheme="implicit").work()
    assert implicit.steps == 8334 * 50 * (30 + 1)    # max_iterations defaults to 50
    assert implicit.steps > WARN_STEPS / 10
    free = load(THREE_MASS, DAMPED, "subsystems.chain.integrator.contact_step=3e-5").work()
    assert free.steps == 8334 * (1 + 1)
    assert load(THREE_MASS).work().steps == 8334 * (1 + 1)     # undamped: closed form


@pytest.mark.parametrize("limit,refused", [(1900, True), (2100, False)])
def test_the_verdict_holds_a_few_ulps_from_the_limit(limit, refused):
    """spring_drop counts 200 macro steps x 10 rk4 steps = 2000, 5 % from
    either limit: moving t_end and the macro step by a few ulps keeps it."""
    for k in range(-3, 4):
        t_end = 0.02
        step = 1e-4
        for _ in range(abs(k)):
            t_end = np.nextafter(t_end, math.copysign(1.0, k))
            step = np.nextafter(step, -math.copysign(1.0, k))
        over = [f"t_end={float(t_end)!r}", f"scheme.macro_step={float(step)!r}",
                f"guard.max_steps={limit}"]
        if refused:
            with pytest.raises(SceneError, match=r"`scheme\.macro_step` is .* at most 2e\+03"):
                load(SPRING_DROP, *over)
        else:
            assert load(SPRING_DROP, *over).work().steps == 2000


def test_the_limit_must_be_positive():
    with pytest.raises(SceneError, match=r"`guard\.max_steps` must be > 0, got -1"):
        load(SPRING_DROP, "guard.max_steps=-1")


def test_estimate_without_the_sides_counts_the_scheme_alone():
    from cosim.scene.specs import resolve_scheme
    spec = resolve_scheme("jacobi", {"macro_step": 1e-3, "substeps": {"a": 4}}, {},
                          file="s.toml", t_end=1.0)
    assert estimate_work(spec, 1.0).steps == 1000 * 4


# ------------------------------------------------------------ tolerances
@pytest.mark.parametrize("key,scheme", [("tolerance", "implicit"),
                                        ("interface_tolerance", None)])
def test_a_tolerance_float64_cannot_meet_is_refused(key, scheme):
    with pytest.raises(SceneError) as exc:
        load(THREE_MASS, f"scheme.{key}=5e-324", scheme=scheme)
    assert exc.value.key == f"scheme.{key}"
    assert f"must be >= {MIN_RELATIVE_TOLERANCE:.3g} (relative" in str(exc.value)
    assert str(exc.value).endswith("got 5e-324")
    assert MIN_RELATIVE_TOLERANCE == np.finfo(float).eps
    load(THREE_MASS, f"scheme.{key}={MIN_RELATIVE_TOLERANCE!r}", scheme=scheme)   # the floor


def test_the_spinning_implicit_run_is_refused_at_load(tmp_path):
    code, _, err, wall = cosim("run", THREE_MASS, "--scheme", "implicit", "--set",
                               "scheme.tolerance=5e-324", "--set",
                               "scheme.max_iterations=1000000000", "--out", tmp_path / "run",
                               "--quiet", cwd=tmp_path)
    assert code == 2 and "`scheme.tolerance` must be >= 2.22e-16" in err, err
    assert wall < 30 and not (tmp_path / "run").exists()


# ------------------------------------------------------------ echoed values
@pytest.mark.parametrize("value", ['"' + "x" * 120_000 + '"',
                                   '"a\\nerror: all checks passed\\u001b[31m\\r"'])
def test_an_echoed_value_is_capped_and_escaped(tmp_path, value):
    text = THREE_MASS.read_text().replace("t_end = 0.25 ", f"t_end = {value} ", 1)
    assert text != THREE_MASS.read_text()
    file = tmp_path / "bad.toml"
    file.write_text(text)
    code, out, err, _ = cosim("run", file, "--out", tmp_path / "run", cwd=tmp_path)
    assert code == 2
    assert err.startswith(f"error: {file}: `t_end` must be a number [s], got a string '")
    assert len(err) < 400 + len(str(file)), len(err)
    assert not any(c in err[:-1] for c in "\n\r\x1b"), err     # one line, no escape sequence
    if "x" * 100 in value:
        assert err.endswith("... (120002 characters)\n"), err[-80:]
    else:
        assert "'a\\nerror: all checks passed\\x1b[31m\\r'" in err, err


def test_an_echoed_key_is_escaped_too(tmp_path):
    file = tmp_path / "bad.toml"
    file.write_text(THREE_MASS.read_text() + '\n["ab\\ncd"]\nx = 1\n')
    with pytest.raises(SceneError) as exc:
        load(file)
    assert "`ab\\ncd` is not a known key" in str(exc.value) and "\n" not in str(exc.value)


# ------------------------------------------------------------ drive tables, modes
@pytest.mark.parametrize("drive,key", [
    ('{type="table", times=[0.0, 1.0, 2.0, 3.0], torques=[0.0, 0.0, 1.0, nan]}',
     f"{DRIVE}.torques[3]"),
    ('{type="table", times=[0.0, nan], torques=[0.0, 1.0]}', f"{DRIVE}.times[1]"),
    ('{type="pd", kp=1.0, kd=0.0, reference={type="table", times=[0.0, 1.0], '
     'values=[0.0, inf]}}', f"{DRIVE}.reference.values[1]"),
])
def test_a_non_finite_drive_entry_names_its_key(drive, key):
    with pytest.raises(SceneError) as exc:
        load(SPRING_DROP, f"{DRIVE}={drive}")
    assert exc.value.key == key, str(exc.value)
    assert str(exc.value).endswith(f"`{key}` must be finite, got "
                                   + ("inf" if "inf" in drive else "nan"))


@pytest.mark.parametrize("case,side,lowest", [(THREE_MASS, "chain", "73.1535"),
                                              (CASES / "beam_impact.toml", "beam", "23.4533")])
def test_a_cutoff_that_keeps_no_mode_says_so(tmp_path, case, side, lowest):
    scene = load(case, f"subsystems.{side}.modes={{cutoff_hz=1.0}}")
    with pytest.raises(SceneError) as exc:
        scene.build()
    assert exc.value.key == f"subsystems.{side}.modes.cutoff_hz"
    assert str(exc.value).endswith(
        f"keeps no mode: it is 1 Hz, and the lowest natural frequency is {lowest} Hz; give "
        f"a cutoff above it")
    code, _, err, _ = cosim("run", case, "--set", f"subsystems.{side}.modes={{cutoff_hz=1.0}}",
                            "--out", tmp_path / "run", cwd=tmp_path)
    assert code == 2 and "keeps no mode" in err and "zero-size" not in err, err


@pytest.mark.parametrize("method", ["RK23", "RK45", "DOP853"])
def test_the_stability_reach_of_each_explicit_method(method):
    """The reach along the real or imaginary axis of each method's stability
    region, from its Butcher table: |R(z)| <= 1 up to it, > 1 just past it."""
    from scipy.integrate._ivp import rk

    from cosim.core.preflight import EXPLICIT_STABILITY

    cls = getattr(rk, method)
    b = np.asarray(cls.B, float)
    s = b.size
    table = np.asarray(cls.A, float)[:s, :s]      # RK45 stores one column fewer
    a = np.zeros((s, s))
    a[:, :table.shape[1]] = table

    def growth(z):
        return abs(1.0 + z * b @ np.linalg.solve(np.eye(s) - z * a, np.ones(s)))

    def reach(direction):
        ys = np.linspace(1e-3, 8.0, 8001)
        g = np.array([growth(direction * y) for y in ys])
        return ys[np.argmax(g > 1.0 + 1e-9)]

    found = max(reach(-1.0), reach(1j))
    assert EXPLICIT_STABILITY[method] == pytest.approx(found, abs=0.01)


@pytest.mark.parametrize("case,overrides,key", [
    (THREE_MASS, ["t_end=1e308"], "scheme.macro_step"),                 # t_end / H is inf
    (THREE_MASS, ["scheme.macro_step=5e-324"], "scheme.macro_step"),    # a subnormal step
    (THREE_MASS, ["scheme.contact_step=5e-324"], "scheme.contact_step"),
    (THREE_MASS, [DAMPED, "subsystems.chain.integrator.contact_step=5e-324"],
     "subsystems.chain.integrator.contact_step"),
    # rk4's step in free flight, shorter than its max_step
    (SPRING_DROP, ["subsystems.body.integrator.free_step=5e-324"],
     "subsystems.body.integrator.free_step"),
])
def test_a_count_past_the_doubles_is_refused_not_a_traceback(tmp_path, case, overrides, key):
    with pytest.raises(SceneError) as exc:
        load(case, *overrides)
    assert exc.value.key == key and "at most inf integrator steps" in str(exc.value)
    sets = [a for o in overrides for a in ("--set", o)]
    code, _, err, _ = cosim("info", case, *sets, cwd=tmp_path)
    assert code == 2 and err.startswith("error: ") and "Traceback" not in err, err


def test_a_structure_stepped_in_closed_form_counts_one_step_per_sub_step():
    """beam_impact's beam is stepped exactly, undamped, with a linear
    contact: its closed contacts are stepped in closed form and its RK4
    `contact_step` is never used, however small (the size series sets
    1e-15 s); damped, it steps at its `contact_step` while the contact is
    closed, and the count says so."""
    beam = CASES / "beam_impact.toml"
    exact = load(beam).work()
    tiny = load(beam, "subsystems.beam.integrator.contact_step=1e-15").work()
    assert tiny.steps == exact.steps == 2600 * (1 + 1)
    damped = load(beam, "subsystems.beam.rayleigh=[0.0, 1e-6]").work()
    assert damped.steps == 2600 * (50 + 1)

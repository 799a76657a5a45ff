"""The scripts in ``examples/`` run as a user runs them, on a short ``--t-end``.

Each is started in a fresh process (``python examples/NAME.py --t-end T --out DIR``) from an
empty working directory, must exit 0 and write its figure, a PNG of 800 x 500 px, and the
numbers it printed as ``DIR/NAME.json``, which the test checks against physics: one claim per
example, each with its tolerance justified where it is asserted.
"""
import json
import math
import os
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES = ROOT / "examples"
NAMES = ["robot_on_beam", "compare_schemes", "sweep_stiffness", "read_run", "custom_law"]
#: examples run by another test file, which needs what they need (an FMU built
#: with a C compiler): script -> that file
TESTED_ELSEWHERE = {"fmu_arm_on_beam": "test_fmu.py"}


def _env():
    """The environment of a user's shell, with this tree's packages first on the path."""
    env = dict(os.environ)
    paths = [str(ROOT / "src"), env.get("PYTHONPATH", "")]
    env["PYTHONPATH"] = os.pathsep.join(p for p in paths if p)
    env.setdefault("MPLBACKEND", "Agg")
    return env


def run_example(name, t_end, tmp_path, *extra):
    """Run ``examples/NAME.py`` in ``tmp_path``; return the numbers it saved."""
    out = tmp_path / "out"
    proc = subprocess.run([sys.executable, str(EXAMPLES / f"{name}.py"), "--t-end", str(t_end),
                           "--out", str(out), *extra],
                          capture_output=True, text=True, cwd=tmp_path, env=_env(), timeout=300)
    assert proc.returncode == 0, f"{name} exited {proc.returncode}:\n{proc.stderr}"
    png = (out / f"{name}.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n", f"{name}.png is not a PNG"
    assert struct.unpack(">II", png[16:24]) == (800, 500), f"{name}.png is not 800 x 500 px"
    return json.loads((out / f"{name}.json").read_text())


def test_every_script_is_tested_and_documented():
    assert sorted(p.stem for p in EXAMPLES.glob("*.py")) == sorted([*NAMES, *TESTED_ELSEWHERE])
    for name, test in TESTED_ELSEWHERE.items():
        assert f"examples/{name}.py" in (ROOT / "tests" / test).read_text() or \
            f'"{name}.py"' in (ROOT / "tests" / test).read_text(), f"{name}: not run by {test}"
    for name in NAMES:
        text = (EXAMPLES / f"{name}.py").read_text()
        assert f"python examples/{name}.py" in text, f"{name}: no command for its figure"
        assert (ROOT / "docs" / "_static" / "examples" / f"{name}.png").is_file()


def test_robot_on_beam(tmp_path):
    r = run_example("robot_on_beam", 0.107, tmp_path)
    # before C strikes the beam rests at its sag under its own weight; between the nodes the
    # Hermite cubics miss the quartic static curve by at most q h^4 / (384 E I) = 1.1e-10 m
    # for h = 1/32 m, 1.9e-7 of the sag (measured 1.7e-7)
    assert r["sag"] == pytest.approx(r["sag_closed_form"], rel=1e-6)
    assert len(r["intervals"]) == 1 and 0.100 < r["intervals"][0][0] < 0.105
    assert r["peak_force"] > 0 and r["lowest_deflection"] < 10 * r["sag"]   # pushed down


def test_compare_schemes(tmp_path):
    rows = run_example("compare_schemes", 0.11, tmp_path)
    assert list(rows) == ["monolithic", "jacobi", "gauss_seidel", "implicit"]
    ref = np.array(rows["monolithic"]["intervals"])
    assert len(ref) >= 3, ref                       # a train of contacts by 0.11 s
    for name, r in rows.items():
        assert len(r["intervals"]) == len(ref), name
    # implicit iterates the interface to agreement: C's times and peak as the reference's
    # (measured 2.7e-8 s and 8.5e-7); the explicit schemes lag by the extrapolation over a
    # 30 us contact step: the scene documents +0.12 % on the peak, measured 0.36 % for jacobi
    assert np.abs(np.array(rows["implicit"]["intervals"]) - ref).max() < 1e-6
    assert abs(rows["implicit"]["peak_error"]) < 1e-5
    for name in ("jacobi", "gauss_seidel"):
        assert abs(rows[name]["peak_error"]) < 0.01, (name, rows[name]["peak_error"])


def test_sweep_stiffness(tmp_path):
    t_end = 0.014
    r = {k: np.array(v, dtype=float) for k, v in run_example("sweep_stiffness", t_end,
                                                              tmp_path).items()}
    ended = 0.010 + r["exact_time"] < t_end         # touch at 10 ms; only those left the wall
    assert ended.sum() == 5 and np.array_equal(~np.isnan(r["contact_time"]), ended)
    # RK4 at 10 us on the undamped spring, the contact located inside the step: the stiffest
    # point (omega h = 0.1) is off by 2.4e-6, the others by less than 3e-8
    np.testing.assert_allclose(r["contact_time"][ended], r["exact_time"][ended], rtol=1e-5)
    np.testing.assert_allclose(r["peak_force"][ended], r["exact_force"][ended], rtol=1e-5)


def test_read_run(tmp_path):
    r = run_example("read_run", 0.12, tmp_path)
    # a contact interval runs while the force is non-zero (DESIGN.md): the series agrees
    assert r["forced_outside"] == 0 and r["forced_inside"] > 0
    assert r["energy_first_sample"] == pytest.approx(r["energy_initial"], rel=1e-12)


def test_read_run_reads_a_cli_run_without_cosim(tmp_path):
    """The docstring's command makes the folder; the reading part imports no cosim."""
    run = tmp_path / "run"
    subprocess.run([sys.executable, "-m", "cosim.cli", "run",
                    str(ROOT / "cases" / "three_mass.toml"), "--variant", "f100",
                    "--set", "t_end=0.11", "--out", str(run), "--quiet"],
                   check=True, capture_output=True, cwd=tmp_path, env=_env(), timeout=300)
    code = ("import runpy, sys\n"
            "for m in ('cosim', 'couplers', 'multibody', 'fem'): sys.modules[m] = None\n"
            f"sys.argv = ['read_run.py', '--run', {str(run)!r}, '--out', 'o']\n"
            f"runpy.run_path({str(EXAMPLES / 'read_run.py')!r}, run_name='__main__')\n")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          cwd=tmp_path, env=_env(), timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert json.loads((tmp_path / "o" / "read_run.json").read_text())["forced_outside"] == 0


def test_custom_law(tmp_path):
    r = run_example("custom_law", 0.018, tmp_path)
    ref = r["closed form"]
    for name in ("sphere_on_flat", "built-in hertz"):
        assert r[name]["count"] == 1, name
        # RK4 at 10 us over a 7.4 ms contact, touch and release located: measured 2.5e-9
        for key in ("in_touch_time", "peak_penetration"):
            assert r[name][key] == pytest.approx(ref[key], rel=1e-6), (name, key)
    # the same force function in the same integrator: the two laws differ by round-off only
    for key in ("in_touch_time", "peak_penetration"):
        assert r["sphere_on_flat"][key] == pytest.approx(r["built-in hertz"][key], rel=1e-9)
    assert math.isfinite(ref["in_touch_time"])


def test_custom_law_is_checked_like_a_built_in_one(tmp_path):
    """A bad parameter of the registered law is a scene error naming its key path."""
    code = ("import sys, cosim\n"
            f"sys.path.insert(0, {str(EXAMPLES)!r})\n"
            "import custom_law\n"
            "try:\n"
            f"    cosim.load_scene({str(ROOT / 'cases' / 'spring_drop.toml')!r}, overrides=[\n"
            "        'contacts.wall.law={type=\"sphere_on_flat\", youngs_modulus=1e7, '\n"
            "        'poisson_ratio=0.7, radius=0.05}'])\n"
            "except cosim.SceneError as exc:\n"
            "    print(exc)\n")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          cwd=tmp_path, env=_env(), timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "`contacts.wall.law.poisson_ratio` must be in (-1, 0.5], got 0.7" in proc.stdout

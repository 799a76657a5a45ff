"""benchmarks/peers: scene 5 side by side (cosim, the paper's RK45, Exudyn).

The driver runs on its short setting (``--quick``: 0.106 s, C's first two
contacts, one run each); no timing is asserted, only that the CPU figures
are there and consistent and that every peer meets the 1 % criterion against
the bench's reference on that window.  The Exudyn model is checked against
cosim's monolithic run in free flight before it is compared anywhere.
"""
import importlib.util
import json
import math
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
PEERS = ROOT / "benchmarks" / "peers"
SCENE = ROOT / "cases" / "three_mass.toml"


def _module(name):
    spec = importlib.util.spec_from_file_location(f"peers_{name}", PEERS / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def driver():
    return _module("run")


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    """One reference cache for the module: the quick reference runs once."""
    return tmp_path_factory.mktemp("bench-cache")


def _quick(peers, out, cache):
    proc = subprocess.run([sys.executable, str(PEERS / "run.py"), "--quick", "--peers", peers,
                           "--out", str(out), "--cache-dir", str(cache)],
                          capture_output=True, text=True, cwd=ROOT, timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert proc.stdout.startswith("machine: "), proc.stdout[:200]
    report = json.loads((out / "peers.json").read_text())
    assert (out / "peers.csv").read_text().startswith("peer,method,solve_cpu_s,process_cpu_s")
    assert "| peer | solve CPU [s] | whole process CPU [s]" in (out / "peers.md").read_text()
    return report


def _check_row(row, ref):
    assert row["status"] == "finished"
    assert row["solve_cpu_s"] > 0
    # the whole process contains the solve: interpreter, imports and output on top
    assert row["process_cpu_s"] > row["solve_cpu_s"], row
    assert row["count"] == ref["count"] == 2
    assert row["err_count"] == 0
    for k in ("err_peak_steps", "err_peak_interp", "err_exit_velocity"):
        assert row[k] < 0.01, (row["peer"], k, row[k])
    assert row["meets_1pc"] is True


def test_intervals_and_peaks_of_a_sampled_sine(driver):
    """Contacts, their edges and the peak of a penetration known in closed
    form, sampled on steps that miss every crest: the samples' peak falls
    short, the Hermite interpolant recovers it, each edge is found to within
    the straight line's error."""
    amp, omega, phase = 1e-3, 2 * math.pi * 50.0, 0.3
    t = np.linspace(0.0, 0.095, 39)                      # 8 samples a period
    p = amp * np.sin(omega * t + phase)
    v = amp * omega * np.cos(omega * t + phase)
    iv = driver.intervals(t, p)
    # positive half-waves: the one open at t = 0, then one per period, all closed
    assert len(iv) == 5
    assert iv[0][0] == 0.0
    starts = (2 * math.pi * np.arange(1, 5) - phase) / omega
    ends = (math.pi * (2 * np.arange(0, 5) + 1) - phase) / omega
    assert np.allclose([s for s, _ in iv[1:]], starts, atol=2e-5, rtol=0)
    assert np.allclose([e for _, e in iv], ends, atol=2e-5, rtol=0)
    assert p.max() < 0.97 * amp                          # the samples miss the crests
    assert abs(driver.hermite_peak(t, p, v) - amp) < 2e-3 * amp
    m = driver.series_metrics({"t": t, "gap/C": -p, "gap_rate/C": -v,
                               "dq/robot/arm": 3.0 + t})
    assert m["count"] == 5 and m["peak_steps"] == p.max()
    # the rate at the last release, linear between the samples around it
    assert m["exit_velocity"] == pytest.approx(3.0 + iv[-1][1], rel=1e-12)


def test_intervals_of_a_contact_open_at_both_ends(driver):
    t = np.linspace(0.0, 1.0, 11)
    assert driver.intervals(t, np.ones_like(t)) == [[0.0, 1.0]]
    assert driver.intervals(t, -np.ones_like(t)) == []


def test_errors_and_the_one_percent_criterion(driver):
    ref = {"count": 9, "peak": 1.0, "exit_velocity": -10.0}
    ok = {"count": 9, "peak_steps": 0.995, "peak": 1.002, "exit_velocity": -10.05}
    e = driver.errors(ok, ref)
    assert e["err_count"] == 0 and e["meets_1pc"]
    assert e["err_peak_steps"] == pytest.approx(0.005)
    assert e["err_exit_velocity"] == pytest.approx(0.005)
    assert not driver.errors({**ok, "count": 10}, ref)["meets_1pc"]
    assert not driver.errors({**ok, "peak_steps": 0.98}, ref)["meets_1pc"]   # samples count too
    assert not driver.errors({**ok, "exit_velocity": -9.8}, ref)["meets_1pc"]


def test_paper_command_is_the_bench_row(driver):
    from cosim.studies.bench import PAPER_RK45

    args = driver.paper_args()
    assert args[:2] == ["--scheme", "monolithic"]
    sets = dict(a.split("=", 1) for a in args[3::2])
    assert {k.rsplit(".", 1)[1]: json.loads(v) for k, v in sets.items()} == PAPER_RK45


def test_cosim_and_paper_quick(tmp_path, cache):
    """The cosim and paper rows, without exudyn."""
    report = _quick("cosim,paper_rk45", tmp_path, cache)
    rows = {r["peer"]: r for r in report["rows"]}
    assert set(rows) == {"cosim", "paper_rk45"}
    assert report["t_end"] == pytest.approx(0.106)
    assert rows["cosim"]["method"] == "cosim run (gauss_seidel)"
    for row in rows.values():
        _check_row(row, report["reference"])


def test_cosim_default_does_not_hang_on_round_off(tmp_path, driver):
    """The default scheme's steps do not depend on round-off: lifting the
    robot by 1e-15 m (what moves Exudyn's adaptive steps, see the README)
    leaves C's intervals and the arm's exit rate as they were."""
    runs = []
    for q0 in ("0.09994114", "0.099941140000001"):
        out = tmp_path / q0
        proc = subprocess.run([sys.executable, str(PEERS / "cosim_three_mass.py"), "--out",
                               str(out), "--t-end", "0.106", "--", "--set",
                               f"subsystems.robot.bodies.slider_y.joint.q0={q0}"],
                              capture_output=True, text=True, cwd=ROOT, timeout=600)
        assert proc.returncode == 0, proc.stdout + proc.stderr
        runs.append(driver.run_dir_metrics(out))
        runs[-1]["intervals"] = json.loads((out / "summary.json").read_text())["contacts"]["C"][
            "intervals"]
    a, b = runs
    assert a["count"] == b["count"] == 2
    assert np.allclose(a["intervals"], b["intervals"], rtol=0, atol=1e-12)
    assert b["exit_velocity"] == pytest.approx(a["exit_velocity"], rel=1e-9)
    assert b["peak"] == pytest.approx(a["peak"], rel=1e-9)


def test_exudyn_quick(tmp_path, cache):
    pytest.importorskip("exudyn", reason="the Exudyn peer needs the `peers` extra")
    report = _quick("exudyn", tmp_path, cache)
    (row,) = report["rows"]
    assert row["method"] == "Exudyn 1.13.6 TrapezoidalIndex2"
    _check_row(row, report["reference"])


def test_exudyn_model_flies_as_cosim_before_c_strikes():
    """Up to 0.1 s (C first touches at 0.1027 s) the robot meets only A and B
    on the ground: the Exudyn model's joint coordinates and C's gap follow
    cosim's monolithic reference, to the trapezoidal rule's error at 0.5 ms
    steps through A's contact (omega h about 0.2)."""
    exu = pytest.importorskip("exudyn", reason="the Exudyn peer needs the `peers` extra")
    import cosim

    mod = _module("exudyn_three_mass")
    t_end = 0.1
    n = mod.scene_numbers(SCENE, "f100")
    assert n["k"] == {"A": 1e6, "B": 1e6, "C": 1.6e7}
    assert n["chain_masses"] == [0.15] * 3
    mbs, settings, sensors, geometry = mod.build(exu, n, t_end)
    exu.SolveDynamic(mbs, settings, solverType=exu.DynamicSolverType.TrapezoidalIndex2)
    s = mod.series(mbs, sensors, geometry)
    assert s["t"][-1] == pytest.approx(t_end)
    assert s["gap/C"].min() > 0                     # C has not touched yet
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ref = cosim.simulate(cosim.load_scene(SCENE, "f100", [f"t_end={t_end}"], "monolithic"))
    final = ref.summary["final_state"]["robot"]
    assert abs(s["q/robot/x"][-1] - final["x"]["q"]) < 2e-5
    assert abs(s["q/robot/y"][-1] - final["y"]["q"]) < 2e-5
    for j in ("body", "arm"):
        assert abs(s[f"q/robot/{j}"][-1] - final[j]["q"]) < 1e-3, j        # [rad]
    for j in ("x", "y", "body", "arm"):
        scale = max(1.0, abs(final[j]["dq"]))
        assert abs(s[f"dq/robot/{j}"][-1] - final[j]["dq"]) < 1e-3 * scale, j
    assert abs(s["gap/C"][-1] - ref.series["gap/C"][-1]) < 2e-5

"""benchmarks/peers: scene 5 side by side (cosim, the paper's RK45, Exudyn, MuJoCo).

The driver runs on its short setting (``--quick``: 0.106 s, C's first two
contacts, one run each); no timing is asserted, only that the CPU figures
are there and consistent and that every peer meets the 1 % criterion against
the bench's reference on that window.  The Exudyn and MuJoCo models are
checked against cosim's monolithic run in free flight before they are
compared anywhere; the MuJoCo model's mapping of the scene file (its MJCF
text, initial state and C's gap) is checked without mujoco.
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
    # the peers' models import the scene's numbers from their own directory
    if str(PEERS) not in sys.path:
        sys.path.insert(0, str(PEERS))
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


def _quick(peers, out, cache, extra=()):
    proc = subprocess.run([sys.executable, str(PEERS / "run.py"), "--quick", "--peers", peers,
                           "--out", str(out), "--cache-dir", str(cache), *extra],
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
        ref = cosim.simulate(cosim.load_scene(SCENE, "f100", [f"t_end={t_end}"], "monolithic"),
                             estimate=False)
    final = ref.summary["final_state"]["robot"]
    assert abs(s["q/robot/x"][-1] - final["x"]["q"]) < 2e-5
    assert abs(s["q/robot/y"][-1] - final["y"]["q"]) < 2e-5
    for j in ("body", "arm"):
        assert abs(s[f"q/robot/{j}"][-1] - final[j]["q"]) < 1e-3, j        # [rad]
    for j in ("x", "y", "body", "arm"):
        scale = max(1.0, abs(final[j]["dq"]))
        assert abs(s[f"dq/robot/{j}"][-1] - final[j]["dq"]) < 1e-3 * scale, j
    assert abs(s["gap/C"][-1] - ref.series["gap/C"][-1]) < 2e-5


# --- the MuJoCo model -------------------------------------------------------------------------

@pytest.fixture(scope="module")
def mj():
    return _module("mujoco_three_mass")


def _mjcf_tree(mj, n, step=2.5e-5, integrator="Euler"):
    import xml.etree.ElementTree as ET

    return ET.fromstring(mj.mjcf(n, step, integrator))


def _floats(text):
    return [float(v) for v in text.split()]


def test_mujoco_mjcf_maps_the_scene_file(mj):
    """Every number of the MJCF text is the scene file's, exactly (``repr``
    round-trips them): masses, inertias, points, chain springs, contact
    stiffnesses (the actuators' bias), gravity; contacts switched off."""
    n = mj.scene_numbers(SCENE, "f100")
    root = _mjcf_tree(mj, n)
    opt = root.find("option")
    assert _floats(opt.get("gravity")) == [0.0, -9.81, 0.0]
    assert opt.get("integrator") == "Euler" and float(opt.get("timestep")) == 2.5e-5
    assert opt.find("flag").get("contact") == "disable"
    bodies = {b.get("name"): b for b in root.iter("body")}
    inertial = {k: b.find("inertial") for k, b in bodies.items()}
    assert float(inertial["main"].get("mass")) == 10.0
    assert _floats(inertial["main"].get("pos")) == [0.0, 0.0, 0.0]
    assert _floats(inertial["main"].get("diaginertia"))[2] == 0.1
    assert float(inertial["arm"].get("mass")) == 2.0
    assert _floats(inertial["arm"].get("diaginertia"))[2] == 0.043
    assert _floats(inertial["arm"].get("pos")) == [0.2, -0.08, 0.0]
    assert _floats(bodies["arm"].get("pos")) == [0.15, 0.1, 0.0]
    sites = {st.get("name"): _floats(st.get("pos", "0 0 0")) for st in root.iter("site")}
    assert sites["A"] == [-0.2, -0.1, 0.0] and sites["B"] == [0.2, -0.1, 0.0]
    assert sites["C"] == [0.3, -0.2, 0.0] and sites["ground"] == [0.0, 0.0, 0.0]
    assert [j.get("name") for j in root.iter("joint") if j.get("type")] == list(mj.JOINTS)
    for i in (1, 2, 3):
        assert float(inertial[f"m{i}"].get("mass")) == 0.15
        assert _floats(bodies[f"m{i}"].get("pos")) == [0.4733, 5.518125e-05, 0.0]
    # the ground spring on the bottom slide, the other two as tendons m1-m2, m2-m3
    joints = {j.get("name"): j for j in root.iter("joint") if j.get("type")}
    assert float(joints["m3"].get("stiffness")) == 1.6e5 and joints["m3"].get("springref") == "0"
    assert all(joints[f"m{i}"].get("stiffness") is None for i in (1, 2))
    tendons = {t.get("name"): t for t in root.iter("fixed")}
    assert set(tendons) == {"m1-m2", "m2-m3"}
    for name, t in tendons.items():
        a, b = name.split("-")
        assert float(t.get("stiffness")) == 1.6e5 and float(t.get("springlength")) == 0.0
        assert [(j.get("joint"), float(j.get("coef"))) for j in t] == [(a, 1.0), (b, -1.0)]
    acts = {a.get("name"): a for a in root.iter("general")}
    for c, ref, k in (("A", "ground", 1e6), ("B", "ground", 1e6), ("C", "top", 1.6e7)):
        a = acts[c]
        assert (a.get("site"), a.get("refsite")) == (c, ref)
        assert _floats(a.get("gear")) == [0, 1, 0, 0, 0, 0]
        assert float(a.get("gainprm")) == 0.0 and a.get("biastype") == "affine"
        assert _floats(a.get("biasprm")) == [0.0, -k, -0.0]
        assert _floats(a.get("forcerange"))[0] == 0.0 and _floats(a.get("forcerange"))[1] >= 1e30
    # another variant changes C's stiffness only
    f1 = {a.get("name"): a for a in _mjcf_tree(mj, mj.scene_numbers(SCENE, "f1")).iter("general")}
    assert _floats(f1["C"].get("biasprm"))[1] == -1.6e5
    assert _floats(f1["A"].get("biasprm"))[1] == -1e6


def _scene_copy(tmp_path, law):
    text = SCENE.read_text().replace(
        'law = { type = "linear", contact_stiffness = 1.6e5 }   # c13 = f c_ref', law)
    assert text != SCENE.read_text()
    path = tmp_path / "three_mass.toml"
    path.write_text(text)
    return path


def test_mujoco_mjcf_damping_and_refused_laws(mj, tmp_path):
    """A Kelvin-Voigt law's damping goes into the actuator's bias (its rate
    term); a law the models cannot reproduce is refused, named."""
    path = _scene_copy(tmp_path, 'law = { type = "kelvin_voigt", contact_stiffness = 1.6e5, '
                                 'contact_damping = 12.5 }')
    n = mj.scene_numbers(path, "f1")
    assert n["damping"] == {"A": 0.0, "B": 0.0, "C": 12.5}
    acts = {a.get("name"): a for a in _mjcf_tree(mj, n).iter("general")}
    assert _floats(acts["C"].get("biasprm")) == [0.0, -1.6e5, -12.5]
    exu = _module("exudyn_three_mass")
    with pytest.raises(ValueError, match="Exudyn model's contacts are undamped"):
        exu.build(None, n, 0.1)
    path = _scene_copy(tmp_path, 'law = { type = "hertz", contact_stiffness = 1.6e5, '
                                 'exponent = 1.5 }')
    with pytest.raises(ValueError, match=r"`contacts.C.law.type` must be one of"):
        mj.scene_numbers(path, "f1")
    with pytest.raises(ValueError, match="`integrator` must be one of"):
        mj.mjcf(mj.scene_numbers(SCENE, "f1"), 1e-5, "Verlet")


def test_mujoco_initial_state_and_gap(mj):
    """The run starts where the scene does: the body at its height, the arm
    at its angle and rate, the chain in static equilibrium with its top at
    y = 0; C's gap from the joint coordinates is the one the plane
    rotations of the arm's points give (an independent computation, equal
    to round-off: 1e-12 m on lengths of 0.5 m)."""
    n = mj.scene_numbers(SCENE, "f100")
    qpos, qvel = mj.initial_state(n, lift=1e-15)
    assert qpos[1] == 0.09994114 + 1e-15 and qpos[3] == 2.0 and qvel[3] == -20.0
    assert not qpos[[0, 2]].any() and not qvel[[0, 1, 2, 4, 5, 6]].any()
    u = qpos[4:]
    m, k, g = 0.15, 1.6e5, 9.81
    # each spring carries the weight above it:
    # k (u1 - u2) = -m g, k (u2 - u3) = -2 m g, k u3 = -3 m g
    assert k * (u[0] - u[1]) == pytest.approx(-m * g, rel=1e-12)
    assert k * (u[1] - u[2]) == pytest.approx(-2 * m * g, rel=1e-12)
    assert k * u[2] == pytest.approx(-3 * m * g, rel=1e-12)
    assert abs(n["chain_origin_y"] + u[0]) < 1e-12            # the top level with the ground
    rng = np.random.default_rng(5)
    q = np.tile(qpos, (6, 1)) + rng.normal(0, 0.3, (6, 7))
    dq = rng.normal(0, 5.0, (6, 7))
    s = mj.series(n, np.arange(6.0), q, dq)
    for i in range(6):
        joint = np.array([q[i, 0], q[i, 1]]) + mj_rot(q[i, 2], n["joint"])
        c = joint + mj_rot(q[i, 2] + q[i, 3], n["C"])
        assert abs(s["gap/C"][i] - (c[1] - n["chain_origin_y"] - q[i, 4])) < 1e-12
        # the rate: the derivative of the same expression, by a central difference
        eps = 1e-7
        plus = mj.series(n, [0.0], (q[i] + eps * dq[i])[None], dq[i][None])["gap/C"][0]
        minus = mj.series(n, [0.0], (q[i] - eps * dq[i])[None], dq[i][None])["gap/C"][0]
        assert abs(s["gap_rate/C"][i] - (plus - minus) / (2 * eps)) < 1e-6 * (1 + abs(dq[i]).max())
    assert np.array_equal(s["q/robot/arm"], q[:, 3]) and np.array_equal(s["dq/robot/y"], dq[:, 1])


def mj_rot(phi, v):
    c, s = np.cos(phi), np.sin(phi)
    return np.array([c * v[0] - s * v[1], s * v[0] + c * v[1]])


def test_mujoco_steps_end_at_t_end(mj):
    assert mj.steps(0.25, 2.5e-5) == (10000, 2.5e-5)
    n, h = mj.steps(0.25, 3e-5)
    assert n == 8334 and h <= 3e-5 and n * h == pytest.approx(0.25, rel=1e-15)
    with pytest.raises(ValueError, match="`--step` must be > 0"):
        mj.steps(0.25, 0.0)


def test_cheapest_mujoco_setting_needs_every_smaller_step(driver):
    """A step that meets 1 % while a smaller one of its integrator misses it
    is not chosen, however cheap."""
    rows = [{"integrator": "Euler", "step": h, "solve_cpu_s": 1 / h, "meets_1pc": ok}
            for h, ok in ((1e-5, True), (2e-5, True), (3e-5, False), (4e-5, True))]
    rows += [{"integrator": "RK4", "step": h, "solve_cpu_s": 2 / h, "meets_1pc": ok}
             for h, ok in ((1e-5, True), (3e-5, True), (4e-5, False))]
    best = driver.cheapest(rows)
    assert (best["integrator"], best["step"]) == ("Euler", 2e-5)
    rows[1]["solve_cpu_s"] = 1e9
    assert (driver.cheapest(rows)["integrator"], driver.cheapest(rows)["step"]) == ("RK4", 3e-5)
    assert driver.cheapest([{**r, "meets_1pc": False} for r in rows]) is None


def test_mujoco_model_is_the_scene_in_mujoco():
    """The compiled model's masses and inertias are the scene's; its
    actuator lengths and rates are the gaps (C's as :func:`series` has it);
    the actuator force is the unilateral spring; the chain and the robot's
    robot's weight balance where the scene says they do."""
    mujoco = pytest.importorskip("mujoco", reason="the MuJoCo peer needs the `peers` extra")
    mj = _module("mujoco_three_mass")
    n = mj.scene_numbers(SCENE, "f100")
    model = mujoco.MjModel.from_xml_string(mj.mjcf(n))
    data = mujoco.MjData(model)
    body = {model.body(i).name: i for i in range(model.nbody)}
    assert model.body_mass[body["main"]] == 10.0 and model.body_mass[body["arm"]] == 2.0
    assert model.body_inertia[body["arm"]][2] == pytest.approx(0.043, rel=1e-12)
    assert model.body_inertia[body["main"]][2] == pytest.approx(0.1, rel=1e-12)
    assert [model.joint(i).name for i in range(model.njnt)] == list(mj.JOINTS)
    qpos, qvel = mj.initial_state(n)
    rng = np.random.default_rng(7)
    for trial in range(5):
        data.qpos[:] = qpos + (rng.normal(0, 0.05, 7) if trial else 0.0)
        data.qvel[:] = qvel + (rng.normal(0, 2.0, 7) if trial else 0.0)
        mujoco.mj_forward(model, data)
        s = mj.series(n, [0.0], data.qpos[None], data.qvel[None])
        # lengths of ~0.5 m: equal to round-off
        assert abs(data.actuator_length[2] - s["gap/C"][0]) < 1e-12
        assert abs(data.actuator_velocity[2] - s["gap_rate/C"][0]) < 1e-10 * (
            1 + abs(data.qvel).max())
        for i, c in enumerate("AB"):
            p = data.qpos[:2] + mj_rot(data.qpos[2], n[c])
            assert abs(data.actuator_length[i] - p[1]) < 1e-12
            k = n["k"][c]
            assert data.actuator_force[i] == pytest.approx(max(0.0, -k * p[1]), rel=1e-12,
                                                           abs=1e-9)
        assert data.actuator_force[2] == pytest.approx(max(0.0, -1.6e7 * s["gap/C"][0]),
                                                       rel=1e-12, abs=1e-9)
    # C pressed 1 mm in: the spring pushes C up and the top down, k x 1 mm each
    data.qpos[:], data.qvel[:] = qpos, 0.0
    mujoco.mj_forward(model, data)
    data.qpos[4] += data.actuator_length[2] + 1e-3
    mujoco.mj_forward(model, data)
    assert data.actuator_force[2] == pytest.approx(1.6e4, rel=1e-9)
    # at the initial state the chain and the body (on A and B) are in equilibrium
    data.qpos[:], data.qvel[:] = qpos, 0.0
    mujoco.mj_forward(model, data)
    assert np.all(np.abs(data.qacc[4:]) < 1e-9 * 9.81 * 1e3)   # chain: round-off of k u
    # A and B carry the robot's weight: y0 = 0.1 - d0, d0 = (m3 + m4) g / (kA + kB)
    assert data.actuator_force[0] + data.actuator_force[1] == pytest.approx(12.0 * 9.81,
                                                                            rel=1e-9)


def test_mujoco_model_flies_as_cosim_before_c_strikes():
    """Up to 0.1 s (C first touches at 0.1027 s) the robot meets only A and B:
    the MuJoCo model, run by RK4 at 1e-5 s so that the comparison measures
    the model and not the integrator, follows cosim's monolithic reference
    to within its own step's error."""
    mujoco = pytest.importorskip("mujoco", reason="the MuJoCo peer needs the `peers` extra")
    import cosim

    mj = _module("mujoco_three_mass")
    t_end = 0.1
    n = mj.scene_numbers(SCENE, "f100")
    r = mj.solve(mujoco, n, t_end, 1e-5, "RK4")
    s = mj.series(n, r["t"], r["qpos"], r["qvel"])
    assert r["steps"] == 10000 and s["t"][-1] == pytest.approx(t_end, rel=1e-9)
    assert r["solve_cpu_s"] > 0
    assert s["gap/C"].min() > 0                     # C has not touched yet
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ref = cosim.simulate(cosim.load_scene(SCENE, "f100", [f"t_end={t_end}"], "monolithic"),
                             estimate=False)
    final = ref.summary["final_state"]["robot"]
    for j in ("x", "y", "body", "arm"):
        assert abs(s[f"q/robot/{j}"][-1] - final[j]["q"]) < 1e-6, j
        scale = max(1.0, abs(final[j]["dq"]))
        assert abs(s[f"dq/robot/{j}"][-1] - final[j]["dq"]) < 1e-5 * scale, j
    assert abs(s["gap/C"][-1] - ref.series["gap/C"][-1]) < 1e-6


def test_mujoco_quick(tmp_path, cache):
    pytest.importorskip("mujoco", reason="the MuJoCo peer needs the `peers` extra")
    report = _quick("mujoco", tmp_path, cache,
                    ["--mujoco-steps", "2.5e-5,1.25e-5", "--mujoco-integrators", "Euler,RK4"])
    (row,) = report["rows"]
    assert row["method"] == "MuJoCo 4.0.0 Euler, h = 2.5e-05 s"
    assert row["steps"] == 4240                     # 0.106 s / 2.5e-5 s
    _check_row(row, report["reference"])
    sweep = report["mujoco_steps"]
    # the steps that end exactly at 0.106 s: h = 0.106 / n, equal to h to round-off
    assert [(r["integrator"], r["steps"]) for r in sweep] == [
        ("Euler", 4240), ("Euler", 8480), ("RK4", 4240), ("RK4", 8480)]
    assert [r["step"] for r in sweep] == pytest.approx([2.5e-5, 1.25e-5] * 2, rel=1e-12)
    # the same run as the row's, repeated: the same errors
    for k in ("err_count", "err_peak_steps", "err_peak_interp", "err_exit_velocity"):
        assert sweep[0][k] == row[k]
    assert all(r["meets_1pc"] for r in sweep)
    assert [r["cheapest"] for r in sweep].count(True) == 1
    md = (tmp_path / "peers.md").read_text()
    assert "| integrator | h [s] | steps | solve CPU [s] |" in md


@pytest.mark.parametrize("t_end, count", [(0.106, 2), (0.25, 9)])
def test_mujoco_count_holds_under_round_off(driver, t_end, count):
    """The MuJoCo row's count of C's contacts (the reference's: 2 in the
    quick window, 9 over the scene) at its chosen setting, with the robot
    lifted by a few ulp of its height (1e-17 m is 1 ulp of 0.1 m): the fixed
    steps do not move, the count does not either."""
    mujoco = pytest.importorskip("mujoco", reason="the MuJoCo peer needs the `peers` extra")
    mj = _module("mujoco_three_mass")
    n = mj.scene_numbers(SCENE, "f100")
    for lift in (0.0, 2e-17, -4e-17, 1e-15):
        r = mj.solve(mujoco, n, t_end, lift=lift)
        assert driver.series_metrics(mj.series(n, r["t"], r["qpos"], r["qvel"]))["count"] == count


def test_a_peer_package_not_installed_is_left_out_with_a_note(driver, tmp_path, cache,
                                                              monkeypatch, capsys):
    """Without mujoco (or exudyn) its row and its sweep are left out, said in
    one line, and the rest of the table is written."""
    real = driver.machine

    def without(*packages):
        def machine():
            m = real()
            m["versions"] = {k: v for k, v in m["versions"].items() if k not in packages}
            return m
        return machine

    monkeypatch.setattr(driver, "machine", without("mujoco", "exudyn"))
    assert driver.main(["--quick", "--peers", "mujoco,exudyn", "--mujoco-steps", "2.5e-5",
                        "--out", str(tmp_path), "--cache-dir", str(cache)]) == 0
    out = capsys.readouterr().out
    assert 'mujoco is not installed (pip install ".[peers]"): its row is left out' in out
    assert 'exudyn is not installed (pip install ".[peers]"): its row is left out' in out
    report = json.loads((tmp_path / "peers.json").read_text())
    assert report["rows"] == [] and report["mujoco_steps"] == []

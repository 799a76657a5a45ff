"""manipulator_wall (CASES.md section 3): rigid impact with friction, and the
penalty contact's rigid limit."""
import math
import warnings

import numpy as np
import pytest

import cosim
from conftest import CASES
from cosim.studies.analytic import kelvin_voigt_clipped
from roundoff import assert_robust

SCENE = CASES / "manipulator_wall.toml"
L = 0.17


def run(variant="mu0", scheme=None, overrides=()):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = cosim.load_scene(SCENE, variant, list(overrides), scheme)
    res = cosim.simulate(scene, estimate=False)
    assert res.success, res.message
    return res.summary


@pytest.fixture(scope="module")
def impact_state():
    """Free motion to the wall, independently of the scene: q, dq, M, W."""
    from scipy.integrate import solve_ivp
    from multibody import Body, Joint, TreeModel
    tree = TreeModel([Body(f"l{i}", 0.3341, 0.0011388, (L / 2, 0)) for i in range(10)],
                     [Joint(f"q{i}", "revolute", i - 1, (0, 0) if i == 0 else (L, 0))
                      for i in range(10)])

    def f(t, y):
        _, M, F, _ = tree.dynamics(y[:10], y[10:])
        return np.concatenate([y[10:], np.linalg.solve(M, -F)])
    y = solve_ivp(f, (0, 0.39), np.r_[np.full(10, -0.25), np.full(10, -0.2)], method="DOP853",
                  rtol=1e-12, atol=1e-12).y[:, -1]
    _, M, _, pk = tree.dynamics(y[:10], y[10:], None, np.array([9]), np.array([[L, 0.0]]))
    J = pk.jacobian[0]
    return {"x": pk.position[0], "v": pk.velocity[0], "M": M, "jn": J[0], "jt": J[1],
            "dq": y[10:], "tree": tree}


def test_tip_reaches_the_wall_at_0_390_s(impact_state):
    """CASES.md: x = -0.254463 m at t = 0.390 s (6 digits: 1e-6 m / 1.1257 m/s)."""
    assert impact_state["x"][0] == pytest.approx(-0.254463, abs=5e-7)
    assert impact_state["v"] == pytest.approx([-1.1257, 0.4118], abs=1e-4)
    s = run()
    (imp,) = s["impacts"]
    assert imp["time"] == pytest.approx(0.390, abs=1e-6)
    # one impact, and no re-contact up to t_end, for the round-off copies too
    assert_robust(cosim.load_scene(SCENE), lambda r: (
        r.status, len(r.summary["impacts"]), r.summary["contacts"]["tip"]["count"]),
        ("finished", 1, 1))


def test_frictionless_impact_against_closed_form(impact_state):
    """Single contact, Poisson: P = (1 + e)(-v_n)/W_nn, v_n+ = -e v_n- (eqs. 10-12),
    evaluated at the pose and velocities the run recorded at the impact."""
    tree = impact_state["tree"]
    imp = run()["impacts"][0]
    q = np.array(list(imp["q"].values()))
    dq = np.array(list(imp["dq_before"].values()))
    _, M, _, pk = tree.dynamics(q, dq, None, np.array([9]), np.array([[L, 0.0]]))
    st = {"M": M, "jn": pk.jacobian[0][0], "dq": dq}
    W = st["jn"] @ np.linalg.solve(st["M"], st["jn"])
    vn = st["jn"] @ st["dq"]
    assert imp["normal_impulse"] == pytest.approx(1.5 * -vn / W, rel=1e-7)
    assert imp["compression_impulse"] == pytest.approx(-vn / W, rel=1e-7)
    assert imp["normal_velocity"][1] == pytest.approx(-0.5 * vn, rel=1e-7)
    dq_plus = st["dq"] + np.linalg.solve(st["M"], st["jn"]) * 1.5 * -vn / W
    assert list(imp["dq_after"].values()) == pytest.approx(list(dq_plus), rel=1e-6, abs=1e-9)


def test_stick_threshold_is_the_ratio_of_the_contact_compliances(impact_state):
    """Stick is possible iff mu >= |W_nt / W_tt| = 0.0535 (CASES.md: about 0.0535)."""
    st = impact_state
    Mi_jn = np.linalg.solve(st["M"], st["jn"])
    Mi_jt = np.linalg.solve(st["M"], st["jt"])
    r = abs((st["jt"] @ Mi_jn) / (st["jt"] @ Mi_jt))
    assert r == pytest.approx(0.0535, abs=5e-5)
    below = run(overrides=[f"contacts.tip.law.friction={r - 1e-3}", "t_end=0.4"])["impacts"][0]
    above = run(overrides=[f"contacts.tip.law.friction={r + 1e-3}", "t_end=0.4"])["impacts"][0]
    assert below["slip_end"] == "reversed" and above["slip_end"] == "stuck"
    # above the threshold the slip stops before compression ends
    assert above["slip_history"][0][1] < above["compression_impulse"]


def test_friction_branches_of_the_paper_variants():
    s003, s015, s035 = (run(v) for v in ("mu0.03", "mu0.15", "mu0.35"))
    i003 = s003["impacts"][0]
    assert [m for *_, m in i003["slip_history"]] == ["slip+", "slip-"]
    assert i003["slip_end"] == "reversed"
    # the slip reverses before compression ends
    assert i003["slip_history"][0][1] < i003["compression_impulse"]
    for s in (s015, s035):
        assert s["impacts"][0]["slip_end"] == "stuck"
        assert s["impacts"][0]["tangential_velocity"][1] == pytest.approx(0.0, abs=1e-12)
    # 0.15 and 0.35 end in the same state; only the slip history differs
    for j in s015["final_state"]["robot"]:
        assert s015["final_state"]["robot"][j]["dq"] == pytest.approx(
            s035["final_state"]["robot"][j]["dq"], abs=1e-10)
    assert s015["impacts"][0]["slip_history"] != s035["impacts"][0]["slip_history"]


@pytest.mark.parametrize("variant", ["mu0", "mu0.03", "mu0.15", "mu0.35"])
def test_impact_never_adds_energy_and_ledger_closes(variant):
    s = run(variant)
    imp = s["impacts"][0]
    assert imp["energy_loss"] > 0
    e = s["energy"]
    assert e["dissipated"] == pytest.approx(imp["energy_loss"], rel=1e-12)
    assert abs(e["initial"] - e["final"] - e["dissipated"]) < 1e-9 * e["initial"]


@pytest.mark.parametrize("scheme", ["monolithic", "jacobi", "implicit"])
def test_every_scheme_resolves_the_same_impact(scheme):
    ref = run("mu0.03")
    got = run("mu0.03", scheme)
    assert got["impacts"][0]["time"] == pytest.approx(ref["impacts"][0]["time"], abs=1e-9)
    assert got["impacts"][0]["normal_impulse"] == pytest.approx(
        ref["impacts"][0]["normal_impulse"], rel=1e-8)
    assert got["final_state"]["robot"]["q10"]["dq"] == pytest.approx(
        ref["final_state"]["robot"]["q10"]["dq"], rel=1e-7)


def test_penalty_contact_approaches_the_rigid_law():
    """Kelvin-Voigt contacts whose dashpot gives the same restitution 0.5 for
    the tip's reduced mass (1.3628 kg, zeta = 0.25528): as the stiffness rises
    1e5 -> 1e6 -> 1e7 N/m, the joint velocities after the contact approach the
    rigid impact's (compared at t = 0.45 s, after every contact has ended)."""
    m_red, zeta = 1.3628298735, 0.2552756376
    assert kelvin_voigt_clipped(1.0, 1.0, 2 * zeta)[1] == pytest.approx(0.5, abs=1e-9)
    rigid = run(overrides=["t_end=0.45"])["final_state"]["robot"]
    ref = np.array([rigid[j]["dq"] for j in rigid])
    errs = []
    for k in (1e5, 1e6, 1e7):
        c = 2 * zeta * math.sqrt(k * m_red)
        s = run("penalty", overrides=["t_end=0.45", f"contacts.tip.law.contact_stiffness={k}",
                                      f"contacts.tip.law.contact_damping={c}"])
        assert s["contacts"]["tip"]["count"] == 1
        fs = s["final_state"]["robot"]
        errs.append(np.linalg.norm(np.array([fs[j]["dq"] for j in fs]) - ref))
    assert errs[0] > errs[1] > errs[2], errs
    assert errs[2] < 0.25 * errs[0]


def test_cli_prints_the_impact(tmp_path, capsys):
    from cosim import cli
    assert cli.main(["run", str(SCENE), "--variant", "mu0.03", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "impact tip at t = 0.39 s" in out and "slip: slip+ -> slip- (reversed)" in out
    assert "joint velocities after" in out

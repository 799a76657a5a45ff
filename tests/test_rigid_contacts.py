"""Event-driven rigid contacts: simultaneous impacts and refusals."""
import pytest

import cosim
from roundoff import assert_robust

BAR = """
t_end = 0.2
[scheme]
name = "gauss_seidel"
macro_step = 1e-3
[subsystems.bar]
type = "multibody"
integrator = {{ method = "dop853", rtol = 1e-10, atol = 1e-12 }}
[subsystems.bar.bodies.sx]
mass = 0.0
joint = {{ name = "x", type = "prismatic", axis = [1.0, 0.0], dq0 = 0.3 }}
[subsystems.bar.bodies.sy]
mass = 0.0
joint = {{ name = "y", type = "prismatic", parent = "sx", axis = [0.0, 1.0], q0 = 0.1, dq0 = -1.0 }}
[subsystems.bar.bodies.rod]
mass = 2.0
inertia = 0.1666667
points = {{ left = [-0.5, 0.0], right = [0.5, 0.0] }}
joint = {{ name = "theta", type = "revolute", parent = "sy", q0 = {theta} }}
[subsystems.ground]
type = "rigid"
points = {{ surface = [0.0, 0.0] }}
[contacts.L]
a = "bar.left"
b = "ground.surface"
normal = [0.0, 1.0]
law = {{ type = "rigid", restitution = 0.5, friction = {mu} }}
[contacts.R]
a = "bar.right"
b = "ground.surface"
normal = [0.0, 1.0]
law = {{ type = "rigid", restitution = 0.5, friction = {mu} }}
"""


def bar(tmp_path, theta=0.0, mu=0.0, scheme=None):
    p = tmp_path / "bar.toml"
    p.write_text(BAR.format(theta=theta, mu=mu))
    return cosim.simulate(cosim.load_scene(p, scheme=scheme))


@pytest.mark.parametrize("scheme", [None, "monolithic"])
def test_flat_landing_on_two_points_is_one_impact(tmp_path, scheme):
    """Symmetric: equal impulses (1+e) m v / 2 = 1.5 N s each, no spin,
    v_y+ = e |v_y-|, the sliding speed untouched."""
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = bar(tmp_path, scheme=scheme)
    assert res.success, res.message
    imps = res.summary["impacts"]
    assert sorted(i["contact"] for i in imps) == ["L", "R"]
    assert imps[0]["time"] == pytest.approx(0.1, abs=1e-9) == imps[1]["time"]
    for i in imps:
        assert i["normal_impulse"] == pytest.approx(1.5, rel=1e-8)
        assert i["simultaneous_with"] == ["R" if i["contact"] == "L" else "L"]
    fs = res.summary["final_state"]["bar"]
    assert fs["y"]["dq"] == pytest.approx(0.5, rel=1e-8)
    assert fs["theta"]["dq"] == pytest.approx(0.0, abs=1e-8)
    assert fs["x"]["dq"] == pytest.approx(0.3, rel=1e-12)
    for c in ("L", "R"):
        assert res.summary["contacts"][c]["count"] == 1
    # one simultaneous impact for the round-off copies too (they move the height
    # and the speeds; the angle 0 stays 0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = cosim.load_scene(tmp_path / "bar.toml", scheme=scheme)
    assert_robust(scene, lambda r: (r.status, sorted(
        (i["contact"], i["simultaneous_with"]) for i in r.summary["impacts"])),
        ("finished", [("L", ["R"]), ("R", ["L"])]), scheme=scheme)
    e = res.summary["energy"]
    assert e["dissipated"] == pytest.approx(0.5 * 2.0 * (1 - 0.25), rel=1e-8)


def test_tilted_bar_strikes_with_one_end_and_spins(tmp_path):
    res = bar(tmp_path, theta=0.05)
    assert res.success, res.message
    first = res.summary["impacts"][0]
    assert first["contact"] == "L" and first["simultaneous_with"] == []
    assert first["normal_velocity"][1] == pytest.approx(-0.5 * first["normal_velocity"][0])


def test_simultaneous_frictional_impacts_are_refused_with_a_reason(tmp_path):
    res = bar(tmp_path, mu=0.2)
    assert not res.success and res.status == "failed"
    assert "rigid contacts ['L', 'R'] strike at once at t = 0.1 s with friction" in res.message


def test_zero_restitution_is_refused_at_load_not_stuck(tmp_path):
    """At restitution 0 the contact would stay closed after its impact, which
    a rigid law does not model: the scene is refused before it runs."""
    p = tmp_path / "bar.toml"
    p.write_text(BAR.format(theta=0.05, mu=0.0).replace("restitution = 0.5", "restitution = 0.0"))
    with pytest.raises(cosim.SceneError, match=r"`contacts\.L\.law\.restitution` must be in "
                                               r"\(0, 1\], got 0\.0: the contact would stay "
                                               r"closed after its first impact"):
        cosim.load_scene(p)

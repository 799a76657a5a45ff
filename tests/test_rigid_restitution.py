"""A rigid law's restitution: required, in (0, 1].

A rigid contact is an impulse (Poisson restitution): at restitution 0 the
contact stays closed after its impact, and sustained rigid contact is not
modelled, so the run failed at the first impact.  The law once defaulted its
restitution to 0, so a scene that left it out failed that way too.  Now the
key is required and 0 is refused, both at load, naming the key and why.
"""
import pytest

from conftest import CASES
from cosim import cli
from cosim.scene import keys
from cosim.scene.load import SceneError, load_scene
from couplers import RigidLaw
from roundoff import assert_robust

SPRING_DROP = CASES / "spring_drop.toml"
KEY = "contacts.wall.law.restitution"


@pytest.mark.parametrize("law,rule", [
    ('{type="rigid"}', r"is required by law `rigid`: Poisson's coefficient sets the rebound "
                       r"of every impact and no value is a neutral default \(0 would leave the "
                       r"contact closed after its first impact"),
    ('{type="rigid", friction=0.2}', r"is required by law `rigid`"),
    ('{type="rigid", restitution=0.0}', r"must be in \(0, 1\], got 0\.0: the contact would "
                                        r"stay closed after its first impact"),
    ('{type="rigid", restitution=0}', r"must be in \(0, 1\], got 0\.0"),
    ('{type="rigid", restitution=1.5}', r"must be in \(0, 1\], got 1\.5"),
])
def test_a_rigid_law_without_a_usable_restitution_is_refused_at_load(law, rule, tmp_path,
                                                                      capsys):
    out = tmp_path / "x"
    assert cli.main(["run", str(SPRING_DROP), "--set", f"contacts.wall.law={law}",
                     "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err
    assert err.startswith(f"error: {SPRING_DROP}: `{KEY}` "), err
    import re
    assert re.search(rule, err), err
    assert not out.exists()
    with pytest.raises(SceneError, match=rf"`{re.escape(KEY)}` {rule}"):
        load_scene(SPRING_DROP, overrides=[f"contacts.wall.law={law}"])


def test_the_law_itself_requires_it_and_refuses_zero():
    with pytest.raises(TypeError, match="restitution"):
        RigidLaw()
    with pytest.raises(ValueError, match=r"`restitution` must be in \(0, 1\], got 0\.0: "):
        RigidLaw(0.0)
    assert RigidLaw(1e-3).restitution == 1e-3 and RigidLaw(1.0).friction == 0.0


@pytest.mark.parametrize("e", [1e-3, 0.5, 1.0])
def test_a_small_restitution_runs_and_rebounds_by_poisson(e):
    """1 kg at -1 m/s on a rigid wall: one impact, rebound at +e m/s (Poisson,
    frictionless: exact up to the rounding of the impulse), finished; for
    the scene and its round-off copies."""
    scene = load_scene(SPRING_DROP, overrides=[f"contacts.wall.law={{type=\"rigid\", "
                                               f"restitution={e!r}}}"])
    status, n, v = assert_robust(scene, lambda r: (
        r.status, len(r.summary["impacts"]),
        round(r.summary["final_state"]["body"]["x"]["dq"] / e, 9)))
    assert (status, n, v) == ("finished", 1, 1.0)


def test_the_key_table_says_required_and_why():
    row = keys.law_section("rigid").find("restitution")
    assert row.default is keys.REQUIRED
    assert row.check.startswith("in (0, 1]: 0 would leave the contact closed")
    md = keys.reference_markdown()
    assert ("| `restitution` | - | required | in (0, 1]: 0 would leave the contact closed, "
            "which is not modelled |") in md

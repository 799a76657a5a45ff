"""Which contact and joint the studies read: named by the caller and checked
against the scene, or chosen by the scene when it leaves one choice; no
function of the studies carries one scene's names as defaults."""
import inspect

import pytest

from conftest import CASES, ROOT
from cosim import cli
from cosim.scene.load import SceneError, load_scene
from cosim.studies import bench, metrics
from cosim.studies import sweep as sw
from cosim.studies.strike import find_strike


@pytest.mark.parametrize("scene, expected", [
    ("three_mass", ("C", "robot/arm")),        # A and B stand on rigid ground, C strikes the chain
    ("beam_impact", ("C", "robot/arm")),       # C strikes the beam
    ("spring_drop", ("wall", "body/x")),       # the only contact
    ("manipulator_wall", ("tip", "robot/q10")),  # the tip is on the tenth link
])
def test_the_scene_chooses_when_it_leaves_one_choice(scene, expected):
    assert find_strike(CASES / f"{scene}.toml") == expected
    assert find_strike(load_scene(CASES / f"{scene}.toml")) == expected


def test_a_named_contact_gets_the_joint_of_the_body_that_carries_its_point():
    assert find_strike(CASES / "three_mass.toml", "A") == ("A", "robot/body")
    assert find_strike(CASES / "three_mass.toml", joint="robot/y") == ("C", "robot/y")


def test_names_the_scene_lacks_are_refused_with_the_choices():
    path = CASES / "three_mass.toml"
    with pytest.raises(SceneError, match=r"three_mass.toml: `contact` must be one of the "
                                         r"scene's \[contacts\] \(`A`, `B`, `C`\), got 'D'"):
        find_strike(path, "D")
    with pytest.raises(SceneError, match=r"`joint` must be SUBSYSTEM/JOINT of a multibody of "
                                         r"the scene \(`robot/x`, `robot/y`, `robot/body`, "
                                         r"`robot/arm`\), got 'robot/elbow'"):
        find_strike(path, joint="robot/elbow", required=False)


def test_a_scene_with_no_single_choice_says_so_or_gives_none():
    path = CASES / "brachiation.toml"
    with pytest.raises(SceneError, match=r"brachiation.toml: `contact` must be given: of the "
                                         r"scene's \[contacts\] \(`gripper1`, `gripper2`\), 2 "
                                         r"join a multibody to a structure, not one"):
        find_strike(path)
    assert find_strike(path, required=False) is None
    assert find_strike(path, "gripper2") == ("gripper2", "robot/elbow")
    rod = CASES / "rod_impact.toml"
    with pytest.raises(SceneError, match=r"`joint` must be given: contact `wall` joins `rod` "
                                         r"and `wall`, neither a multibody"):
        find_strike(rod)
    assert find_strike(rod, required=False) is None


def test_no_study_function_defaults_to_one_scenes_names():
    """The names of the impact scenes (CASES.md) are no default of the
    studies' functions: they are given, or chosen by the scene."""
    funcs = [sw.sweep, sw.plot_sweep, sw.strike_names, bench.run_bench, bench.reference,
             metrics.impact_regime, metrics.impact_metrics, find_strike]
    for f in funcs:
        for p in inspect.signature(f).parameters.values():
            assert p.default not in ("C", "robot/arm"), (f.__qualname__, p.name)
    for field in ("contact", "joint"):
        assert sw.Study.__dataclass_fields__[field].default is None


def test_a_sweep_of_another_scene_reads_its_own_contact_and_joint(tmp_path):
    """spring_drop's only contact is `wall`, struck by `body/x`: the mass comes
    in at -1 m/s and leaves at +1 m/s after one contact (CASES.md section 1)."""
    rows = sw.sweep(CASES / "spring_drop.toml", workers=1)
    assert rows[0]["status"] == "finished"
    assert rows[0]["impact.regime"] == "backward"
    assert rows[0]["impact.rate_at_touch"] == pytest.approx(-1.0, rel=1e-3)
    assert rows[0]["impact.exit_velocity"] == pytest.approx(1.0, rel=1e-2)
    # a scene with no single strike (two grippers on the cable) runs, with no
    # impact columns
    rows = sw.sweep(CASES / "brachiation.toml", grid={"t_end": [0.002]})
    assert rows[0]["status"] == "finished" and rows[0]["contacts.gripper1.count"] == 1
    assert not [k for k in rows[0] if k.startswith("impact.")]
    # a contact named by the caller, its joint chosen by the scene: the main
    # body rests on its corner A from the start, so A's first contact lasts
    # the whole run, and the body's rotation starts at rest
    rows = sw.sweep(CASES / "three_mass.toml", variants=["f1"], grid={"t_end": [0.002]},
                    contact="A")
    assert rows[0]["contacts.A.intervals"] == [[0.0, 0.002]]
    assert rows[0]["impact.regime"] == "open-ended" and rows[0]["impact.rate_at_touch"] == 0.0


def test_a_sweep_refuses_a_name_the_scene_lacks_before_anything_runs(tmp_path):
    out = tmp_path / "never"
    with pytest.raises(SceneError, match=r"`contact` must be one of the scene's \[contacts\] "
                                         r"\(`wall`\), got 'C'"):
        sw.sweep(CASES / "spring_drop.toml", contact="C", out=out)
    assert not out.exists()
    assert sw.strike_names(CASES / "spring_drop.toml") == ("wall", "body/x")
    assert sw.strike_names(CASES / "brachiation.toml") == (None, None)
    # a variant that does not load leaves the names as given (its points are refused)
    assert sw.strike_names(CASES / "spring_drop.toml", ["no_such"], "x", None) == ("x", None)


def test_the_plot_refuses_a_contact_the_table_lacks(tmp_path):
    rows = [{"set.t_end": 0.1, "variant": None, "point": "p", "status": "finished",
             "message": "", "contacts.wall.count": 1}]
    with pytest.raises(ValueError, match=r"`contact` must be one of the table's contacts "
                                         r"\(wall\), got 'C'"):
        sw.plot_sweep(rows, tmp_path / "x.png", contact="C")
    assert not (tmp_path / "x.png").exists()


def test_bench_refuses_a_name_the_scene_lacks_before_it_runs(tmp_path):
    with pytest.raises(SceneError, match=r"`contact` must be one of the scene's \[contacts\] "
                                         r"\(`wall`\), got 'C'"):
        bench.reference(CASES / "spring_drop.toml", contact="C", cache_dir=tmp_path)
    with pytest.raises(SceneError, match=r"`contact` must be given"):
        bench.run_bench(CASES / "brachiation.toml", cache_dir=tmp_path)
    assert not list(tmp_path.iterdir())


def test_cli_sweep_reads_the_scenes_own_contact(tmp_path, capsys):
    out = tmp_path / "s"
    assert cli.main(["sweep", str(CASES / "spring_drop.toml"), "--workers", "1", "--no-plot",
                     "--out", str(out)]) == 0
    assert "wall: 1 contact(s), backward" in capsys.readouterr().out
    assert cli.main(["sweep", str(CASES / "spring_drop.toml"), "--contact", "C",
                     "--no-plot", "--out", str(tmp_path / "t")]) == 2
    assert "`contact` must be one of the scene's [contacts] (`wall`), got 'C'" in (
        capsys.readouterr().err)
    assert not (tmp_path / "t").exists()


def test_a_study_without_names_reads_the_scenes_strike(tmp_path):
    study = tmp_path / "s.toml"
    study.write_text(f'scene = "{(ROOT / "cases" / "three_mass.toml").as_posix()}"\n'
                     'variants = ["f1"]\n')
    s = sw.load_study(study)
    assert (s.contact, s.joint) == (None, None)
    assert sw.strike_names(s.scene, s.variants, s.contact, s.joint) == ("C", "robot/arm")

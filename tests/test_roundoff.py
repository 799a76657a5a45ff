"""The round-off copies of a scene (cosim.studies.roundoff) that the tests
of discrete outcomes and ``cosim bench --spread`` share."""
import math

import pytest

import cosim
from conftest import CASES
from cosim.studies.roundoff import OFFSETS, nudge, perturbed, perturbed_overrides, spread


def test_nudge_moves_by_whole_ulps_and_leaves_zero():
    assert nudge(1.0, 1) == 1.0 + 2.0 ** -52
    assert nudge(1.0, -1) == 1.0 - 2.0 ** -53             # below 1 the ulp halves
    assert nudge(-20.0, 2) == -20.0 + 2 * math.ulp(20.0)   # toward +inf
    assert nudge(0.0, 3) == 0.0 and nudge(math.inf, 1) == math.inf
    assert nudge(0.1, 0) == 0.1


def _state(scene):
    j = scene.data["subsystems"]["robot"]["bodies"]["arm"]["joint"]
    return j["q0"], j["dq0"]


def test_copies_differ_by_their_offsets_only():
    scene = cosim.load_scene(CASES / "three_mass.toml", variant="f100")
    copies = spread(scene, 5)
    assert copies[0] is scene and len(copies) == 5
    for k, c in zip(OFFSETS, copies[1:]):
        q0, dq0 = _state(c)
        assert (q0, dq0) == (nudge(2.0, k), nudge(-20.0, k))
        assert c.contacts == scene.contacts and c.t_end == scene.t_end
        assert c.variant == "f100"


def test_overrides_make_the_same_copy_from_the_command_line():
    scene = cosim.load_scene(CASES / "three_mass.toml", variant="f100")
    again = cosim.load_scene(CASES / "three_mass.toml", variant="f100",
                             overrides=perturbed_overrides(scene, -2))
    assert _state(again) == _state(perturbed(scene, -2))
    assert _state(again) != _state(scene)


def test_a_scene_at_rest_has_nothing_to_move():
    scene = cosim.load_scene(CASES / "spring_drop.toml",
                             overrides=["subsystems.body.bodies.mass.joint.q0=0",
                                        "subsystems.body.bodies.mass.joint.dq0=0"])
    with pytest.raises(ValueError, match="no nonzero initial"):
        perturbed(scene, 1)
    with pytest.raises(ValueError, match="copies must be between 1 and"):
        spread(scene, 0)

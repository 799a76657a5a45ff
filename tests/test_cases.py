"""Every scene in cases/ loads and runs, each variant, at a coarse setting."""
import tomllib
import warnings

import pytest

import cosim
from conftest import CASES

SCENES = sorted(CASES.glob("*.toml"))


def _variants(path):
    data = tomllib.loads(path.read_text())
    return [None] + sorted(data.get("variants", {}))


@pytest.mark.parametrize("path,variant", [(p, v) for p in SCENES for v in _variants(p)],
                         ids=lambda x: getattr(x, "stem", x))
def test_scene_runs(path, variant):
    scene = cosim.load_scene(path, variant)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        res = cosim.simulate(scene)
    assert res.success, res.message
    assert res.summary["scene"] == path.stem
    if variant is None:         # a shipped default run is accurate: no warning (issue 18)
        assert res.summary["warnings"] == [], res.summary["warnings"]


def test_spring_drop_names_follow_cases_md():
    scene = cosim.load_scene(CASES / "spring_drop.toml")
    assert [s["name"] for s in scene.subsystems] == ["body", "wall"]
    assert [c["name"] for c in scene.contacts] == ["wall"]
    assert scene.subsystems[0]["joints"][0]["name"] == "x"
    assert set(_variants(CASES / "spring_drop.toml")) == {None, "undamped", "kelvin_voigt"}
    assert scene.variant == "undamped"

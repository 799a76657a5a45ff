"""Every SceneError of the scene loader and of the build step.

Each error must name the file, the key path (in backticks) and the rule that
was broken; the cases below pin all three.  Most are reached with ``--set``
style overrides on ``cases/spring_drop.toml``; what an override cannot do
(delete a key, break the TOML, touch ``variants``) goes through the
``scene_file`` fixture, which writes an edited copy of the scene.
"""
import dataclasses
import json
import re
import tomllib
import warnings

import pytest

from conftest import CASES
from cosim.core.ode import INTEGRATORS
from cosim.scene.load import SUBSYSTEM_TYPES, SceneError, load_scene, parse_override
from couplers import CONTACT_LAWS, KelvinVoigtLaw, LinearLaw

SPRING_DROP = CASES / "spring_drop.toml"


#: the rule of a solver's rtol (scipy raises one below 100 eps silently)
RTOL_RULE = "must be >= 2.22e-14 (100 machine epsilons: scipy's solvers raise a smaller rtol to it)"


def at(key: str, essence: str) -> str:
    """Regex for "`key` essence" (both literal)."""
    return re.escape(f"`{key}` {essence}")


# ------------------------------------------------------------ a tiny writer
def _toml(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(v)                      # nan, inf, -inf are TOML too
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, list):
        return "[" + ", ".join(_toml(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{json.dumps(k)} = {_toml(x)}" for k, x in v.items()) + "}"
    raise TypeError(v)


def dump_toml(data: dict) -> str:
    return "".join(f"{json.dumps(k)} = {_toml(v)}\n" for k, v in data.items())


@pytest.fixture
def scene_file(tmp_path):
    """``make(drop=[...], put={...}, text=None)``: write spring_drop.toml with
    the dotted keys in ``drop`` deleted and those in ``put`` set, or ``text``
    verbatim; return the new file's path."""
    def make(drop=(), put=None, text=None):
        path = tmp_path / "scene.toml"
        if text is None:
            data = tomllib.loads(SPRING_DROP.read_text())
            for key in drop:
                *parents, last = key.split(".")
                node = data
                for p in parents:
                    node = node[p]
                del node[last]
            for key, value in (put or {}).items():
                *parents, last = key.split(".")
                node = data
                for p in parents:
                    node = node.setdefault(p, {})
                node[last] = value
            text = dump_toml(data)
        path.write_text(text)
        return path
    return make


# ---------------------------------------------------------------- valid use
def test_valid_scene_loads_with_the_right_names():
    s = load_scene(SPRING_DROP)
    assert s.name == "spring_drop" and s.path == str(SPRING_DROP)
    assert s.variant == "undamped"                       # the default_variant
    assert s.scheme == "gauss_seidel" and s.scheme_options == {"macro_step": 1e-4}
    assert s.t_end == 0.02 and s.output_every == 1 and s.gravity is None
    assert [sub["name"] for sub in s.subsystems] == ["body", "wall"]
    assert [sub["type"] for sub in s.subsystems] == ["multibody", "rigid"]
    body = s.subsystems[0]
    assert body["integrator"] == "rk4" and body["max_step"] == 1e-5
    assert [b["name"] for b in body["bodies"]] == ["mass"]
    assert body["joints"][0]["name"] == "x" and body["joints"][0]["kind"] == "prismatic"
    (c,) = s.contacts
    assert c["name"] == "wall" and c["a"] == ("body", "tip") and c["b"] == ("wall", "surface")
    assert c["placement"] == "embedded" and c["normal"] == (1.0, 0.0)
    assert type(c["law"]) is LinearLaw and c["law"].contact_stiffness == 1e6
    system, scheme = s.build()
    assert scheme.name == "gauss_seidel" and scheme.macro_step == 1e-4


def test_the_writer_round_trips(scene_file):
    a, b = load_scene(SPRING_DROP), load_scene(scene_file())
    assert a.data == b.data and a.contacts == b.contacts and a.subsystems == b.subsystems


def test_variant_merges_into_the_scene():
    s = load_scene(SPRING_DROP, variant="kelvin_voigt")
    law = s.contacts[0]["law"]
    assert s.variant == "kelvin_voigt" and type(law) is KelvinVoigtLaw
    assert law.contact_damping == 200.0 and law.contact_stiffness == 1e6


def test_override_applies_after_the_variant():
    s = load_scene(SPRING_DROP, variant="kelvin_voigt",
                   overrides=["contacts.wall.law.contact_damping=50", "t_end=0.015"])
    assert s.contacts[0]["law"].contact_damping == 50.0 and s.t_end == 0.015
    # (path, value) pairs are accepted as well as strings
    s = load_scene(SPRING_DROP, overrides=[(["scheme", "macro_step"], 2e-4)])
    assert s.scheme_options["macro_step"] == 2e-4


def test_parse_override_reads_toml_values_else_strings():
    assert parse_override("a.b = 1e-3") == (["a", "b"], 1e-3)
    assert parse_override("scheme.name=jacobi") == (["scheme", "name"], "jacobi")
    assert parse_override('x=[1, 2]') == (["x"], [1, 2])


def test_two_moving_subsystems_default_to_a_coupler():
    s = load_scene(SPRING_DROP, overrides=[ARM, "contacts.wall.b=arm.hand"])
    assert s.contacts[0]["placement"] == "coupler"


def test_option_of_another_scheme_warns_and_is_dropped():
    with pytest.warns(UserWarning,
                      match=re.escape("scheme `gauss_seidel` ignores the options "
                                      "['max_iterations']")):
        s = load_scene(SPRING_DROP, overrides=["scheme.max_iterations=10"])
    assert s.scheme_options == {"macro_step": 1e-4}


def test_scheme_argument_replaces_the_scheme(caplog):
    """A scheme the caller chose runs without the scene's options for the
    others: no warning (no fault of the scene), one line at info level."""
    import logging
    s = load_scene(SPRING_DROP, scheme="implicit")
    assert s.scheme == "implicit" and s.scheme_options == {"macro_step": 1e-4}
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with caplog.at_level(logging.INFO, logger="cosim.scene.specs"):
            s = load_scene(SPRING_DROP, scheme="monolithic")
    assert s.scheme == "monolithic" and s.scheme_options == {}
    assert [r.getMessage() for r in caplog.records] == [
        f"{SPRING_DROP}: scheme `monolithic` runs without the scene's options ['macro_step'] "
        f"(for other schemes)"]


# ---------------------------------------------------- file-level and --set
def test_error_names_file_and_key():
    with pytest.raises(SceneError) as exc:
        load_scene(SPRING_DROP, overrides=["t_end=-1"])
    assert exc.value.file == str(SPRING_DROP) and exc.value.key == "t_end"
    assert str(exc.value) == f"{SPRING_DROP}: `t_end` must be > 0 s, got -1.0"


def test_unreadable_file(tmp_path):
    path = tmp_path / "no" / "such.toml"
    with pytest.raises(SceneError, match=re.escape(f"{path}: cannot be read: No such file")):
        load_scene(path)


def test_broken_toml(scene_file):
    path = scene_file(text='name = "x"\nt_end = \n')
    with pytest.raises(SceneError, match=re.escape(f"{path}: is not valid TOML")):
        load_scene(path)


@pytest.mark.parametrize("put", [{"variants": 1}, {"variants.undamped": 1},
                                 {"variants": {"a": {}, "b": [1]}}], ids=str)
def test_variants_must_be_a_table_of_tables(scene_file, put):
    with pytest.raises(SceneError, match=at("variants", "must be a table of tables")):
        load_scene(scene_file(put=put))


def test_unknown_variant(scene_file):
    with pytest.raises(SceneError, match=at("variants", "names no variant 'nope'; variants "
                                                        "are ['kelvin_voigt', 'undamped']")):
        load_scene(SPRING_DROP, variant="nope")
    # a default_variant naming no variant is reported under `default_variant`
    with pytest.raises(SceneError, match=at("default_variant", "names no variant 'gone'")):
        load_scene(scene_file(put={"default_variant": "gone"}))


@pytest.mark.parametrize("override,match", [
    ("t_end", re.escape("override 't_end' must read key.path=value")),
    ("t_end.x=1", at("t_end", "is a number, so --set cannot reach `t_end.x` inside it")),
    ("contacts.wall.a.x=1", at("contacts.wall.a", "is a string, so --set cannot reach "
                                                  "`contacts.wall.a.x` inside it")),
    ("a..b=1", at("a..b", "override 'a..b=1' has an empty key")),
    ("=1", re.escape("override '=1' has an empty key")),
], ids=["no =", "through a number", "through a string", "empty part", "empty key"])
def test_bad_override(override, match):
    with pytest.raises(SceneError, match=re.escape(f"{SPRING_DROP}: ") + match):
        load_scene(SPRING_DROP, overrides=[override])


# ------------------------------------------------------------ missing keys
B = "subsystems.body"
M = "subsystems.body.bodies.mass"
C = "contacts.wall"


MISSING = [
    ("t_end", at("t_end", "is required but missing")),
    ("scheme", at("scheme", "is required but missing")),
    ("scheme.name", at("scheme.name", "is required but missing")),
    ("scheme.macro_step", at("scheme.macro_step", "is required by scheme `gauss_seidel` [s]")),
    ("subsystems", at("subsystems", "is required but missing")),
    (f"{B}.type", at(f"{B}.type", "is required but missing")),
    (f"{B}.bodies", at(f"{B}.bodies", "is required but missing")),
    (f"{M}.mass", at(f"{M}.mass", "is required but missing")),
    (f"{M}.joint", at(f"{M}.joint", "is required but missing")),
    (f"{M}.joint.name", at(f"{M}.joint.name", "is required but missing")),
    (f"{M}.joint.type", at(f"{M}.joint.type", "is required but missing")),
    ("subsystems.wall.points", at("subsystems.wall.points", "is required but missing")),
    (f"{C}.a", at(f"{C}.a", "is required but missing")),
    (f"{C}.b", at(f"{C}.b", "is required but missing")),
    (f"{C}.law", at(f"{C}.law", "is required but missing")),
    (f"{C}.normal", at(f"{C}.normal", "is required but missing")),
    (f"{C}.law.type", at(f"{C}.law.type", "is required but missing")),
    (f"{C}.law.contact_stiffness",
     at(f"{C}.law.contact_stiffness", "is required by law `linear`")),
]


@pytest.mark.parametrize("drop,match", MISSING, ids=[d for d, _ in MISSING])
def test_missing_key(scene_file, drop, match):
    with pytest.raises(SceneError, match=match):
        load_scene(scene_file(drop=[drop]))


# ------------------------------------------------------- override errors
SCHEMES = "['gauss_seidel', 'implicit', 'jacobi', 'monolithic']"
#: a second moving subsystem with a point `hand`
ARM = ('subsystems.arm={type="multibody", bodies={link={mass=1.0, points={hand=[0.0, 0.0]}, '
       'joint={name="y", type="prismatic", axis=[-1.0, 0.0]}}}}')
#: a second body in `body`, child of `mass`
B2 = (f'{B}.bodies.b2={{mass=1.0, joint={{name="y", type="prismatic", axis=[0.0, 1.0], '
      'parent="mass"}}')

CASES_BAD = [
    # ---- top level
    (["t_end=-1"], at("t_end", "must be > 0 s, got -1.0")),
    (["t_end=0"], at("t_end", "must be > 0 s, got 0.0")),
    (["t_end=nan"], at("t_end", "must be finite, got nan")),
    (["t_end=inf"], at("t_end", "must be finite, got inf")),
    (["t_end=-inf"], at("t_end", "must be finite, got -inf")),
    (['t_end="0.02"'], at("t_end", "must be a number [s], got a string '0.02'")),
    (["t_end=true"], at("t_end", "must be a number [s], got a boolean True")),
    (["t_end=[0.02]"], at("t_end", "must be a number [s], got an array [0.02]")),
    (["name=1"], at("name", "must be a string, got an integer 1")),
    (["description=false"], at("description", "must be a string, got a boolean False")),
    (["solver=1"], at("solver", "is not a known key of the top level; known keys are")),
    # ---- scheme
    (["scheme=1"], at("scheme", "must be a table, got an integer 1")),
    (["scheme.name=1"], at("scheme.name", "must be a string, got an integer 1")),
    (["scheme.name=nope"], at("scheme.name", f"must be one of {SCHEMES}, got 'nope'")),
    (["scheme.nope=1"], at("scheme.nope", "is not an option of any scheme; options of "
                                          "`gauss_seidel` are ['accept_unsafe_step',")),
    (["scheme.extrapolation_order=3"], at("scheme.extrapolation_order", "must be 0, 1 or 2, "
                                                                        "got 3")),
    (["scheme.extrapolation_order=1.0"], at("scheme.extrapolation_order",
                                            "must be an integer, got a number 1.0")),
    (["scheme.macro_step=-1"], at("scheme.macro_step", "must be > 0 s, got -1.0")),
    (["scheme.macro_step=0"], at("scheme.macro_step", "must be > 0 s, got 0.0")),
    (["scheme.macro_step=nan"], at("scheme.macro_step", "must be finite, got nan")),
    (['scheme.macro_step="1e-4"'], at("scheme.macro_step", "must be a number, got a string")),
    (["scheme.max_energy_gain=-0.1"], at("scheme.max_energy_gain", "must be >= 0, got -0.1")),
    (["scheme.accept_unsafe_step=1"], at("scheme.accept_unsafe_step",
                                         "must be true or false, got an integer 1")),
    (["scheme.sequence=body"], at("scheme.sequence", "must be an array, got 'body'")),
    (["scheme.sequence=[1]"], at("scheme.sequence", "must be a list of subsystem names, "
                                                    "got [1]")),
    (['scheme={name="jacobi"}'], at("scheme.macro_step", "is required by scheme `jacobi` [s]")),
    (["scheme.name=implicit", "scheme.relaxation=1.5"],
     at("scheme.relaxation", "must be in (0, 1], got 1.5")),
    (["scheme.name=implicit", "scheme.max_iterations=0"],
     at("scheme.max_iterations", "must be >= 1, got 0")),
    (['scheme={name="monolithic", method="Euler"}'],
     at("scheme.method", "must be one of RK45, RK23, DOP853, Radau, BDF, LSODA, got 'Euler'")),
    (['scheme={name="monolithic", rtol=0.0}'], at("scheme.rtol", f"{RTOL_RULE}, got 0.0")),
    # ---- output, effects
    (["output=1"], at("output", "must be a table, got an integer 1")),
    (["output.every=0"], at("output.every", "must be >= 1, got 0")),
    (["output.every=1.5"], at("output.every", "must be an integer, got a number 1.5")),
    (["output.format=csv"], at("output.format", "is not a known key of output; "
                                                "known keys are ['estimate', 'every', 'export', "
                                                "'export_every']")),
    (["effects.gravity=0"], at("effects.gravity", "must be > 0 m/s^2, got 0.0")),
    (["effects.gravity=down"], at("effects.gravity", "must be a number [m/s^2], "
                                                     "got a string 'down'")),
    (["effects.gravity=[0.0]"], at("effects.gravity", "must be an array of two numbers "
                                                      "[m/s^2], got [0.0]")),
    (["effects.gravity=[nan, -9.81]"], at("effects.gravity", "must be finite")),
    (["effects.wind=1"], at("effects.wind", "is not a known key of effects")),
    # ---- subsystems
    (["subsystems=1"], at("subsystems", "must be a table, got an integer 1")),
    (["subsystems={}"], at("subsystems", "must declare at least one subsystem")),
    ([f"{B}=1"], at(B, "must be a table, got an integer 1")),
    ([f"{B}.type=fem"], at(f"{B}.type", f"must be one of {sorted(SUBSYSTEM_TYPES)}, "
                                        "got 'fem'")),
    ([f"{B}.type=1"], at(f"{B}.type", "must be a string, got an integer 1")),
    ([f"{B}.damping=1"], at(f"{B}.damping", f"is not a known key of {B}")),
    ([f"{B}.integrator=rk4"], at(f"{B}.integrator", "must be a table, got a string 'rk4'")),
    ([f"{B}.integrator.method=euler"], at(f"{B}.integrator.method",
                                          f"must be one of {sorted(INTEGRATORS)}, got 'euler'")),
    ([f"{B}.integrator.max_step=0"], at(f"{B}.integrator.max_step", "must be > 0 s, got 0.0")),
    ([f"{B}.integrator.max_step=-1e-5"], at(f"{B}.integrator.max_step",
                                            "must be > 0 s, got -1e-05")),
    ([f"{B}.integrator.max_step=inf"], at(f"{B}.integrator.max_step", "must be finite")),
    ([f"{B}.integrator.order=4"], at(f"{B}.integrator.order",
                                     f"is not a known key of {B}.integrator")),
    ([f"{B}.bodies=1"], at(f"{B}.bodies", "must be a table, got an integer 1")),
    ([f"{B}.bodies={{}}"], at(f"{B}.bodies", "must declare at least one body")),
    ([f"{M}=1"], at(M, "must be a table, got an integer 1")),
    ([f"{M}.mass=-1"], at(f"{M}.mass", "must be >= 0 kg, got -1.0")),
    ([f"{M}.mass=nan"], at(f"{M}.mass", "must be finite, got nan")),
    ([f'{M}.mass="1 kg"'], at(f"{M}.mass", "must be a number [kg], got a string '1 kg'")),
    ([f"{M}.mass=true"], at(f"{M}.mass", "must be a number [kg], got a boolean True")),
    ([f"{M}.inertia=-1"], at(f"{M}.inertia", "must be >= 0 kg m^2, got -1.0")),
    ([f"{M}.com=[0.0]"], at(f"{M}.com", "must be an array of two numbers [m], got [0.0]")),
    ([f"{M}.color=red"], at(f"{M}.color", f"is not a known key of {M}")),
    ([f"{M}.points=1"], at(f"{M}.points", "must be a table, got an integer 1")),
    ([f"{M}.points.tip=[0.0, 0.0, 0.0]"], at(f"{M}.points.tip", "must be an array of two "
                                                               "numbers [m], got [0.0, 0.0, 0.0]")),
    ([f"{M}.points.tip=[0.0, true]"], at(f"{M}.points.tip", "must be an array of two numbers")),
    ([f"{M}.points.tip=[inf, 0.0]"], at(f"{M}.points.tip", "must be finite, got [inf, 0.0]")),
    ([f"{M}.joint=1"], at(f"{M}.joint", "must be a table, got an integer 1")),
    ([f"{M}.joint.name=1"], at(f"{M}.joint.name", "must be a string, got an integer 1")),
    ([f"{M}.joint.type=slider"], at(f"{M}.joint.type", "must be one of ['prismatic', "
                                                       "'revolute'], got 'slider'")),
    ([f"{M}.joint.parent=nope"], at(f"{M}.joint.parent", "must be `ground` or a body "
                                                         "declared before `mass`; declared "
                                                         "so far: []")),
    ([f"{M}.joint.parent=mass"], at(f"{M}.joint.parent", "must be `ground` or a body "
                                                         "declared before `mass`")),
    ([f"{M}.joint.axis=[0.0, 0.0]"], at(f"{M}.joint.axis", "must be a non-zero vector")),
    ([f"{M}.joint.offset=[1.0, 2.0, 3.0]"], at(f"{M}.joint.offset",
                                               "must be an array of two numbers")),
    ([f"{M}.joint.angle=inf"], at(f"{M}.joint.angle", "must be finite, got inf")),
    ([f"{M}.joint.q0=nan"], at(f"{M}.joint.q0", "must be finite, got nan")),
    ([f"{M}.joint.dq0=fast"], at(f"{M}.joint.dq0", "must be a number, got a string 'fast'")),
    ([f"{M}.joint.stiffness=1"], at(f"{M}.joint.stiffness", f"is not a known key of {M}.joint")),
    # a joint's parent must be a body declared before it
    ([f'{B}.bodies.b2={{mass=1.0, joint={{name="y", type="revolute", parent="b3"}}}}'],
     at(f"{B}.bodies.b2.joint.parent", "must be `ground` or a body declared before `b2`; "
                                       "declared so far: ['mass']")),
    # point names are unique across the bodies of one subsystem
    ([B2[:-1] + ', points={tip=[0.0, 1.0]}}'],
     at(f"{B}.bodies.b2.points.tip", "names a point already declared on body `mass`; point "
                                     "names must be unique in subsystem `body`")),
    (["subsystems.wall.points=[0.0, 0.0]"], at("subsystems.wall.points",
                                               "must be a table, got an array")),
    (["subsystems.wall.points={}"], at("subsystems.wall.points", "must name at least one point")),
    (["subsystems.wall.points.surface=[0.0]"], at("subsystems.wall.points.surface",
                                                  "must be an array of two numbers [m]")),
    (["subsystems.wall.integrator={}"], at("subsystems.wall.integrator",
                                           "is not a known key of subsystems.wall")),
    # ---- contacts
    (["contacts=1"], at("contacts", "must be a table, got an integer 1")),
    ([f"{C}=1"], at(C, "must be a table, got an integer 1")),
    ([f"{C}.a=1"], at(f"{C}.a", "must be a string, got an integer 1")),
    ([f"{C}.a=bodytip"], at(f"{C}.a", "must read SUBSYSTEM.POINT with a declared subsystem "
                                      "(['body', 'wall']), got 'bodytip'")),
    ([f"{C}.a=robot.tip"], at(f"{C}.a", "must read SUBSYSTEM.POINT with a declared subsystem "
                                        "(['body', 'wall']), got 'robot.tip'")),
    ([f"{C}.a=body."], at(f"{C}.a", "must read SUBSYSTEM.POINT")),
    ([f"{C}.a=body.heel"], at(f"{C}.a", "names no point of subsystem `body`; its points "
                                        "are ['tip']")),
    ([f"{C}.b=wall.edge"], at(f"{C}.b", "names no point of subsystem `wall`; its points "
                                        "are ['surface']")),
    ([f"{C}.b=body.tip"], at(f"{C}.b", "must be on another subsystem than `a`, "
                                       "got 'body' twice")),
    ([f"{C}.law=linear"], at(f"{C}.law", "must be a table, got a string 'linear'")),
    ([f"{C}.law.type=hertzz"], at(f"{C}.law.type", f"must be one of {sorted(CONTACT_LAWS)}, "
                                                   "got 'hertzz'")),
    ([f"{C}.law.contact_stiffness=0"], at(f"{C}.law.contact_stiffness", "must be > 0 N/m, "
                                                                        "got 0.0")),
    ([f"{C}.law.contact_stiffness=-1e6"], at(f"{C}.law.contact_stiffness", "must be > 0 "
                                                                           "N/m, got -1000000.0")),
    ([f"{C}.law.contact_stiffness=nan"], at(f"{C}.law.contact_stiffness", "must be finite")),
    ([f"{C}.law.contact_stiffness=stiff"], at(f"{C}.law.contact_stiffness",
                                              "must be a number, got a string 'stiff'")),
    ([f"{C}.law.contact_damping=10"], at(f"{C}.law.contact_damping",
                                         f"is not a known key of {C}.law")),
    ([f"{C}.law.type=kelvin_voigt", f"{C}.law.contact_damping=-1"],
     at(f"{C}.law.contact_damping", "must be >= 0 N s/m, got -1.0")),
    ([f"{C}.normal=[0.0, 0.0]"], at(f"{C}.normal", "must be a non-zero vector, got [0.0, 0.0]")),
    ([f"{C}.normal=[1.0]"], at(f"{C}.normal", "must be an array of two numbers [1]")),
    ([f"{C}.normal=[nan, 1.0]"], at(f"{C}.normal", "must be finite")),
    ([f"{C}.offset=x"], at(f"{C}.offset", "must be a number [m], got a string 'x'")),
    ([f"{C}.placement=inside"], at(f"{C}.placement", "must be one of ['coupler', 'embedded'], "
                                                     "got 'inside'")),
    # friction is a table since connections (coefficient, slip_velocity)
    ([f"{C}.friction=0.3"], at(f"{C}.friction", "must be a table, got a number 0.3")),
    (['subsystems.wall2={type="rigid", points={p=[0.0, 0.0]}}', f"{C}.a=wall2.p"],
     at(f"{C}.b", "a contact between two rigid subsystems has nothing to simulate")),
    ([ARM, f"{C}.b=arm.hand", f"{C}.placement=embedded", f'{C}.host="wall"'],
     at(f"{C}.host", "must be one of ['arm', 'body'], got 'wall'")),
    ([ARM, f"{C}.b=arm.hand", f"{C}.placement=embedded",
      f"{C}.friction={{coefficient=0.3, slip_velocity=1e-3}}"],
     at(f"{C}.placement", "a grasp or friction between two moving sides is exchanged by the "
                          "scheme, not hosted by one side; set placement `coupler`")),
    ([f'{C}.host="body"'],
     at(f"{C}.host", "names the side that integrates an `embedded` contact between two "
                     "moving sides; here there is nothing to choose")),
    ([f'{C}.law={{type="rigid", restitution=0.5}}', ARM, f"{C}.b=arm.hand",
      f"{C}.placement=embedded"],
     at(f"{C}.placement", "a `rigid` law is resolved inside its moving side's integrator")),
]


@pytest.mark.parametrize("overrides,match", CASES_BAD,
                         ids=[" ".join(o)[:70] for o, _ in CASES_BAD])
def test_invalid_value(overrides, match):
    with pytest.raises(SceneError, match=re.escape(f"{SPRING_DROP}: ") + match):
        load_scene(SPRING_DROP, overrides=overrides)


def test_scheme_argument_errors():
    with pytest.raises(SceneError, match=at("scheme.name", f"must be one of {SCHEMES}, "
                                                           "got 'nope'")):
        load_scene(SPRING_DROP, scheme="nope")
    with pytest.raises(SceneError, match=at("scheme", "must be a table, got an integer 1")):
        load_scene(SPRING_DROP, scheme="jacobi", overrides=["scheme=1"])


# -------------------------------------------------------------- build time
def test_integrator_step_too_large_for_embedded_contact():
    s = load_scene(SPRING_DROP, overrides=[f"{B}.integrator.max_step=0.01"])
    with pytest.raises(SceneError, match=at(f"{B}.integrator.max_step",
                                            "is 0.01 s, too large for contact `wall` "
                                            "(omega = 1000 rad/s)")):
        s.build()


def test_default_integrator_step_too_large_for_a_stiff_contact():
    """Without max_step the step is min(macro_step, 1e-4); the error still names
    the key that fixes it."""
    s = load_scene(SPRING_DROP, overrides=[f"{B}.integrator={{}}",
                                           f"{C}.law.contact_stiffness=1e10"])
    with pytest.raises(SceneError, match=at(f"{B}.integrator.max_step",
                                            "is 0.0001 s, too large for contact `wall`")):
        s.build()


def test_a_second_body_builds():
    """The control of the two model errors below."""
    load_scene(SPRING_DROP, overrides=[B2]).build()


@pytest.mark.parametrize("overrides,match", [
    ([f"{M}.mass=0"], at(B, "the tree's mass matrix is singular")),
], ids=["zero mass"])
def test_model_errors_at_build(overrides, match):
    s = load_scene(SPRING_DROP, overrides=overrides)      # loads: checked at build
    with pytest.raises(SceneError, match=re.escape(f"{SPRING_DROP}: ") + match):
        s.build()


def test_other_scheme_at_build_needs_macro_step():
    with warnings.catch_warnings():         # another scheme chosen: no warning
        warnings.simplefilter("error")
        s = load_scene(SPRING_DROP, scheme="monolithic")
        with pytest.raises(SceneError, match=at("scheme.macro_step",
                                                "is required by scheme `jacobi` [s]")):
            s.build("jacobi")
        load_scene(SPRING_DROP).build("monolithic")


def test_scheme_constructor_error_is_a_scene_error():
    """Only a hand-made Scene reaches it: the loader checks the same rules."""
    s = dataclasses.replace(load_scene(SPRING_DROP), scheme_options={"macro_step": -1.0})
    with pytest.raises(SceneError, match=at("scheme", "`macro_step` of scheme `gauss_seidel` "
                                                      "must be > 0 s, got -1.0")):
        s.build()


def test_duplicate_joint_name_is_found_at_load():
    with pytest.raises(SceneError, match=re.escape("joint.name` repeats joint 'x'; joint names "
                                                   "must be unique in subsystem `body`")):
        load_scene(SPRING_DROP, overrides=[B2.replace('name="y"', 'name="x"')])


def test_set_cannot_reach_variants():
    for ov in ("default_variant=kelvin_voigt", "variants.x.t_end=1"):
        with pytest.raises(SceneError, match="is chosen with --variant, not with --set"):
            load_scene(SPRING_DROP, overrides=[ov])


def test_option_of_another_scheme_is_still_checked():
    with pytest.raises(SceneError, match=at("scheme.rtol", f"{RTOL_RULE}, got -1.0")):
        load_scene(SPRING_DROP, overrides=["scheme.rtol=-1.0"])


# ------------------------------------------------ defects found and fixed
def test_default_variant_must_be_a_string(scene_file):
    with pytest.raises(SceneError, match=re.escape("`default_variant`")):
        load_scene(scene_file(put={"default_variant": ["undamped"]}))


@pytest.mark.parametrize("override,key", [("t_end=1" + "0" * 400, "t_end"),
                                          (f"{C}.normal=[1, 1{'0' * 400}]", f"{C}.normal")],
                         ids=["number", "vec2"])
def test_huge_integer_is_a_scene_error(override, key):
    with pytest.raises(SceneError, match=at(key, "must be")):
        load_scene(SPRING_DROP, overrides=[override])


@pytest.mark.parametrize("seq", ['["nope"]', '["wall"]'])
def test_sequence_names_the_moving_subsystems(seq):
    with pytest.raises(SceneError, match=re.escape("`scheme.sequence`")):
        load_scene(SPRING_DROP, overrides=[f"scheme.sequence={seq}"]).build()


# ------------------------------------------- a misspelt key names the nearest
MISSPELT = [
    ("beam_impact", 'law = { type = "linear", contact_stiffness = 1.6e6 }',
     'law = { type = "linear", contact_stifness = 1.6e6 }',
     at("contacts.C.law.contact_stiffness", "is required by law `linear`")
     + r".*\(found `contact_stifness`: a misspelling\?\)"),
    ("beam_impact", "youngs_modulus = 210e9", "youngs_modulos = 210e9",
     at("subsystems.beam.youngs_modulus", "is required but missing")
     + r" \(found `youngs_modulos`: a misspelling\?\)"),
    ("beam_impact", "t_end = 0.13", "tend = 0.13",
     at("t_end", "is required but missing") + r" \(found `tend`: a misspelling\?\)"),
    ("beam_impact", "elements = 32", "elements = 32\nlenght = 1.0",
     at("subsystems.beam.lenght", "is not a known key of subsystems.beam")
     + r" \(did you mean `length`\?\)"),
    ("beam_impact", "macro_step = 1e-3 ", "macro_stp = 1e-3 ",
     at("scheme.macro_stp", "is not an option of any scheme")
     + r" \(did you mean `macro_step`\?\)"),
    ("spring_drop", "[scheme]", "[output]\nevry = 1\n\n[scheme]",
     at("output.evry", "is not a known key of output") + r" \(did you mean `every`\?\)"),
]


@pytest.mark.parametrize("case,old,new,match", MISSPELT, ids=[m[2][:16] for m in MISSPELT])
def test_a_misspelt_key_is_named_with_the_nearest_known_key(tmp_path, case, old, new, match):
    """The file, the key path and the spelling the file has; exit 2 from the CLI."""
    text = (CASES / f"{case}.toml").read_text()
    assert old in text
    path = tmp_path / f"{case}.toml"
    path.write_text(text.replace(old, new, 1))
    with pytest.raises(SceneError, match=re.escape(str(path)) + ": " + match):
        load_scene(path)


def test_a_misspelling_exits_2_with_the_nearest_key(tmp_path):
    import subprocess
    import sys
    path = tmp_path / "scene.toml"
    path.write_text((CASES / "beam_impact.toml").read_text().replace("t_end = 0.13", "tend = 0.13"))
    proc = subprocess.run([sys.executable, "-m", "cosim.cli", "run", str(path), "--out",
                           str(tmp_path / "run")], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2, proc.stderr
    assert "`t_end` is required but missing (found `tend`: a misspelling?)" in proc.stderr
    assert "Traceback" not in proc.stderr and not (tmp_path / "run").exists()


def test_nothing_near_is_offered():
    """A key far from every known key is refused without a guess."""
    from cosim.scene.checks import nearest
    assert nearest("tend", ["t_end", "name"]) == "t_end"
    assert nearest("zzzz", ["t_end", "name"]) is None
    assert nearest("name", ["NAME", "POINT"]) is None       # placeholders are no spelling


# ------------------------------------- a side's step refusal advises a value that builds
SIDE_STEPS = [
    (SPRING_DROP, [f"{B}.integrator.max_step=0.01"], f"{B}.integrator.max_step"),
    (CASES / "beam_impact.toml", ['subsystems.beam.integrator.method="central_difference"'],
     "scheme.macro_step"),
]


@pytest.mark.parametrize("path,overrides,key", SIDE_STEPS, ids=["max_step", "stable_step"])
def test_a_side_step_refusal_advises_a_value_that_builds(path, overrides, key):
    """The value the refusal prints passes its check, as printed and nudged a few ulps."""
    from roundoff import COPIES
    from cosim.studies.roundoff import OFFSETS, nudge
    with pytest.raises(SceneError) as info:
        load_scene(path, overrides=overrides).build()
    m = re.search(r"set (?:it|`([\w.]+)`) to ([0-9.e+-]+) s or less", str(info.value))
    assert m, str(info.value)
    assert (m[1] or key) == key
    h = float(m[2])
    for k in (0,) + OFFSETS[:COPIES - 1]:
        load_scene(path, overrides=overrides + [f"{key}={nudge(h, k)!r}"]).build()
